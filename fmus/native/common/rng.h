/* SplitMix64 (Steele, Lea & Flood 2014) and the deviates drawn from it: the one C copy of
 * railfmu.models.track.irregularity.SplitMix64 and railfmu.models.sources.sensors.noise,
 * bit for bit (the Python twins' tests compare outputs exactly). */
#ifndef RAILFMU_RNG_H
#define RAILFMU_RNG_H

#include <math.h>
#include <stdint.h>

#define RNG_GAMMA UINT64_C(0x9E3779B97F4A7C15)
#define RNG_PI 3.14159265358979323846 /* == Python's math.pi */

/* the output function */
static inline uint64_t rng_mix64(uint64_t z) {
    z = (z ^ (z >> 30)) * UINT64_C(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94D049BB133111EB);
    return z ^ (z >> 31);
}

/* the next output of the generator whose state is *state */
static inline uint64_t rng_next(uint64_t *state) { return rng_mix64(*state += RNG_GAMMA); }

/* [0, 1) from the top 53 bits */
static inline double rng_unit(uint64_t z) { return (double)(z >> 11) * 0x1.0p-53; }

static inline double rng_uniform(uint64_t *state) { return rng_unit(rng_next(state)); }

/* output j + 1 of the generator seeded with seed, as a uniform: counter-based, no state */
static inline double rng_uniform_at(uint64_t seed, uint64_t j) {
    return rng_unit(rng_mix64(seed + (j + 1) * RNG_GAMMA));
}

/* Standard normal k of stream s of a seed, counter-based (a pure function, so FMU state
   get/set and any step size give the same noise): outputs 2k+1 and 2k+2 of the stream
   seeded with mix64(seed + s G), then Box-Muller (cosine branch). */
static inline double rng_normal(uint64_t seed, uint64_t stream, uint64_t k) {
    const uint64_t c = rng_mix64(seed + stream * RNG_GAMMA);
    const uint64_t n = 2 * k + 1;
    const uint64_t z1 = rng_mix64(c + n * RNG_GAMMA), z2 = rng_mix64(c + (n + 1) * RNG_GAMMA);
    const double u1 = (double)((z1 >> 11) + 1) * 0x1.0p-53; /* (0, 1]: log finite */
    const double u2 = rng_unit(z2);                          /* [0, 1) */
    return sqrt(-2.0 * log(u1)) * cos(2.0 * RNG_PI * u2);
}

/* u2 of rng_normal(seed, stream, k), [0, 1): the uniform a log-uniform draw reads */
static inline double rng_uniform2(uint64_t seed, uint64_t stream, uint64_t k) {
    const uint64_t c = rng_mix64(seed + stream * RNG_GAMMA);
    return rng_unit(rng_mix64(c + (2 * k + 2) * RNG_GAMMA));
}

#endif
