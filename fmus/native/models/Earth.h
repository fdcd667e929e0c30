/* Earth: WGS-84, Earth rate and Somigliana normal gravity, the C mirror of models/earth.py
 * (same constants and formulas, those of python-ins; tests/test_trolley.py compares them),
 * plus ECEF -> geodetic (models/track/geometry.py ecef_to_lla, the same iteration).
 * Angles in radians, lengths in metres. Header-only (static functions).
 */
#ifndef RAILFMU_EARTH_H
#define RAILFMU_EARTH_H

#include <math.h>

#if defined(__GNUC__)
#define EARTH_MAYBE_UNUSED __attribute__((unused))
#else
#define EARTH_MAYBE_UNUSED
#endif

#define EARTH_RATE 7.292115e-5     /* rad/s, python-ins's Omega */
#define EARTH_A 6378137.0          /* m, WGS-84 semi-major axis */
#define EARTH_E2 6.6943799901413e-3 /* WGS-84 first eccentricity squared */
#define EARTH_GE 9.7803253359      /* m/s2, normal gravity at the equator */
#define EARTH_GP 9.8321849378      /* m/s2, normal gravity at the poles */

/* Somigliana's k = sqrt(1 - e^2) g_p / g_e - 1 */
static double earth_k(void) { return sqrt(1.0 - EARTH_E2) * EARTH_GP / EARTH_GE - 1.0; }

/* R_N + h, R_E + h (m) */
EARTH_MAYBE_UNUSED static void earth_radii(double lat, double h, double *rn, double *re) {
    const double s = sin(lat), x = 1.0 - EARTH_E2 * s * s, r = EARTH_A / sqrt(x);
    *rn = r * (1.0 - EARTH_E2) / x + h;
    *re = r + h;
}

/* normal gravity gamma(L, h) (m/s2, down in NED) */
EARTH_MAYBE_UNUSED static double earth_gravity(double lat, double h) {
    const double s2 = sin(lat) * sin(lat);
    return EARTH_GE * (1.0 + earth_k() * s2) / sqrt(1.0 - EARTH_E2 * s2) * (1.0 - 2.0 * h / EARTH_A);
}

EARTH_MAYBE_UNUSED static void earth_lla_to_ecef(double lat, double lon, double h, double r[3]) {
    const double s = sin(lat), c = cos(lat), re = EARTH_A / sqrt(1.0 - EARTH_E2 * s * s);
    r[0] = (re + h) * c * cos(lon);
    r[1] = (re + h) * c * sin(lon);
    r[2] = (re * (1.0 - EARTH_E2) + h) * s;
}

/* C_e^n: rotates an ECEF vector into NED at (lat, lon), row-major */
EARTH_MAYBE_UNUSED static void earth_ecef_to_ned(double lat, double lon, double C[3][3]) {
    const double sL = sin(lat), cL = cos(lat), sl = sin(lon), cl = cos(lon);
    C[0][0] = -sL * cl; C[0][1] = -sL * sl; C[0][2] = cL;
    C[1][0] = -sl;      C[1][1] = cl;       C[1][2] = 0.0;
    C[2][0] = -cL * cl; C[2][1] = -cL * sl; C[2][2] = -sL;
}

/* ECEF -> latitude, longitude (rad), height (m): fixed-point iteration on the latitude,
   5 iterations (converged to round-off near the ellipsoid, away from the poles) */
EARTH_MAYBE_UNUSED static void earth_ecef_to_lla(const double r[3], double *lat, double *lon,
                                                 double *h) {
    const double p = hypot(r[0], r[1]);
    double L = atan2(r[2], p * (1.0 - EARTH_E2)), s, N, hh;
    int k;
    *lon = atan2(r[1], r[0]);
    for (k = 0; k < 5; k++) {
        s = sin(L);
        N = EARTH_A / sqrt(1.0 - EARTH_E2 * s * s);
        hh = p / cos(L) - N;
        L = atan2(r[2], p * (1.0 - EARTH_E2 * N / (N + hh)));
    }
    s = sin(L);
    N = EARTH_A / sqrt(1.0 - EARTH_E2 * s * s);
    *lat = L;
    *h = p / cos(L) - N;
}

#endif
