/* GnssReceiver: position and speed fixes every sample_period (models/gnss.py states the
 * measurement equation and is this code's Python twin; tests/test_gnss.py proves them equal).
 * Stateless: every output is a function of the time, the step that reached it and the inputs,
 * so a get after a set, a restored FMU state or any importer give the same fixes.
 */
#include <math.h>
#include <stdint.h>

#include "model.h"

#define MAX_SAMPLE 9007199254740992.0 /* 2^53 */

static const double PI = 3.14159265358979323846;
static const uint64_t GAMMA = UINT64_C(0x9E3779B97F4A7C15);

/* as SensorNoise.c and railfmu.models.sources.sensors.noise (channel 1 of the seed's stream) */
static uint64_t mix64(uint64_t z) {
    z = (z ^ (z >> 30)) * UINT64_C(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94D049BB133111EB);
    return z ^ (z >> 31);
}

static double noise(uint64_t seed, unsigned channel, uint64_t k) {
    const uint64_t c = mix64(seed + (uint64_t)channel * GAMMA);
    const uint64_t n = 2 * k + 1;
    const uint64_t z1 = mix64(c + n * GAMMA), z2 = mix64(c + (n + 1) * GAMMA);
    const double u1 = (double)((z1 >> 11) + 1) * 0x1.0p-53;
    const double u2 = (double)(z2 >> 11) * 0x1.0p-53;
    return sqrt(-2.0 * log(u1)) * cos(2.0 * PI * u2);
}

int model_check_parameters(ModelInstance *m) {
    if (!(m->r[VR_sample_period] > 0) || !isfinite(m->r[VR_sample_period])) {
        model_error(m, "parameter sample_period = %g must be > 0 and finite", m->r[VR_sample_period]);
        return 1;
    }
    if (!(m->r[VR_position_sigma] >= 0) || !isfinite(m->r[VR_position_sigma])) {
        model_error(m, "parameter position_sigma = %g must be >= 0 and finite", m->r[VR_position_sigma]);
        return 1;
    }
    if (!(m->r[VR_speed_resolution_kmh] >= 0) || !isfinite(m->r[VR_speed_resolution_kmh])) {
        model_error(m, "parameter speed_resolution_kmh = %g must be >= 0 and finite",
                    m->r[VR_speed_resolution_kmh]);
        return 1;
    }
    return 0;
}

int model_initialize(ModelInstance *m) {
    (void)m;
    return 0;
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m, (void)t, (void)x, (void)dx;
}

/* k = floor((t - t0) / T + eps min(h / T, 1)), at least 0 (SensorNoise's sample index) */
static double sample_index(const ModelInstance *m, double t) {
    const double T = m->r[VR_sample_period];
    const double k = floor((t - m->startTime) / T + STEP_TOLERANCE * fmin(m->stepSize / T, 1.0));
    return k > 0 ? k : 0.0;
}

int model_outputs(ModelInstance *m) {
    double *r = m->r;
    const double k = sample_index(m, r[0]);
    const double res = r[VR_speed_resolution_kmh];
    double kmh = r[VR_v_true] * 3.6;
    if (!(k < MAX_SAMPLE)) {
        model_error(m, "GnssReceiver: t = %.17g is more than 2^53 samples after the start", r[0]);
        return -1;
    }
    /* a fix at the start, and at the point where the step reaches a new sample instant */
    m->b[VRB_valid] = m->stepSize == 0 || k > sample_index(m, r[0] - m->stepSize);
    m->i[VRI_sample] = (fmi2Integer)k;
    r[VR_position] = r[VR_s_true] + (r[VR_position_sigma] != 0
                                         ? r[VR_position_sigma] *
                                               noise((uint64_t)(int64_t)m->i[VRI_seed], 1u, (uint64_t)k)
                                         : 0.0);
    if (res > 0) kmh = res * floor(kmh / res + 0.5);
    r[VR_speed_kmh] = kmh;
    r[VR_speed] = kmh / 3.6;
    return 0;
}

int model_state_restored(ModelInstance *m) {
    (void)m;
    return 0;
}

void model_free(ModelInstance *m) { (void)m; }
