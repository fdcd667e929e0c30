/* Trolley: a survey trolley pushed along a 3-D track (Jiang et al. 2017) and its ideal IMU
 * increments. models/inertial/trolley.py states the speed profile, the kinematics, the quadrature
 * and the outputs, and is this code's Python twin (tests/test_trolley.py proves them equal);
 * the track is TrackGeometry.h (models/track/geometry.py), the Earth Earth.h
 * (models/earth.py).
 *
 * Memory in outputs (so fmi2GetFMUstate keeps it): interval_start, the previous
 * communication point, and path_start, the path length there. A new communication point
 * (r[0] != the last one) moves them on; a get after a set at the same point recomputes the
 * same interval.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "TrackGeometry.h"
#include "model.h"

enum { REST, ACCELERATE, CRUISE, BRAKE };
#define MAX_PANEL 0.01 /* s: models/inertial/trolley.py MAX_PANEL */
#define MAX_STOPS 1e6  /* models/inertial/trolley.py MAX_STOPS */
/* 3-point Gauss-Legendre on [-1, 1]: nodes 0, +-sqrt(3/5), weights 8/9, 5/9 */
static const double GL3_X = 0.7745966692414834, GL3_W0 = 0.8888888888888888, GL3_W1 = 0.5555555555555556;

typedef struct {
    double t0, s0, v, T;
    int kind;
} Phase;

typedef struct {
    TrackGeom G;
    Phase *ph;
    size_t nph;
    double *splits;
    size_t nsplits;
    double last_end; /* the communication point of the previous model_outputs */
} Trolley;

/* the end point's data that the nodes need */
typedef struct {
    double s, r1[3], r2[3], gam, gam_l, gam_h, rn, re, Cnn0[3][3]; /* Cnn0 = C_n0^n */
} EndPoint;

static void ramp(double tau, double v, double T, double *s, double *sd, double *sdd) {
    const double x = TG_PI * tau / T, sx = sin(x);
    *s = v * (0.5 * tau * tau / T - T * sx * sx / (2.0 * TG_PI * TG_PI));
    *sd = v * (tau / T - sin(2.0 * x) / (2.0 * TG_PI));
    *sdd = 2.0 * v / T * sx * sx;
}

static size_t phase_at(const Trolley *d, double t) {
    size_t lo = 0, hi = d->nph;
    while (lo < hi) {
        const size_t mid = lo + (hi - lo) / 2;
        if (d->ph[mid].t0 <= t) lo = mid + 1;
        else hi = mid;
    }
    return lo ? lo - 1 : 0;
}

static void profile(const Trolley *d, double t, double *s, double *sd, double *sdd) {
    const Phase *p = &d->ph[phase_at(d, t)];
    double tau = t - p->t0, ds;
    switch (p->kind) {
    case REST:
        *s = p->s0, *sd = 0.0, *sdd = 0.0;
        return;
    case CRUISE:
        *s = p->s0 + p->v * tau, *sd = p->v, *sdd = 0.0;
        return;
    case ACCELERATE:
        if (tau > p->T) tau = p->T;
        ramp(tau, p->v, p->T, &ds, sd, sdd);
        *s = p->s0 + ds;
        return;
    default:
        tau = tau < p->T ? p->T - tau : 0.0;
        ramp(tau, p->v, p->T, &ds, sd, sdd);
        *s = p->s0 - ds;
        *sdd = -*sdd;
    }
}

static int stopped(const Trolley *d, double t, double tol) {
    const size_t k = phase_at(d, t);
    if (d->ph[k].kind == REST) return 1;
    if (k + 1 < d->nph && d->ph[k + 1].kind == REST && d->ph[k + 1].t0 - t <= tol) return 1;
    return k > 0 && d->ph[k - 1].kind == REST && t - d->ph[k].t0 <= tol;
}

static int add_phase(Trolley *d, size_t *cap, double t0, int kind, double s0, double v, double T) {
    if (d->nph == *cap) {
        size_t nc = *cap ? 2 * *cap : 64;
        Phase *a = (Phase *)realloc(d->ph, nc * sizeof *a);
        if (!a) return 1;
        d->ph = a;
        *cap = nc;
    }
    d->ph[d->nph].t0 = t0, d->ph[d->nph].kind = kind, d->ph[d->nph].s0 = s0;
    d->ph[d->nph].v = v, d->ph[d->nph].T = T;
    d->nph++;
    return 0;
}

/* the time the trolley passes s while moving; 0 if it does not (a stop's distance) */
static int time_at(const Trolley *d, double s, double *t) {
    size_t k;
    int it;
    for (k = 1; k < d->nph; k++) {
        const Phase *p = &d->ph[k];
        const double half = 0.5 * p->v * p->T;
        if (p->kind == REST) {
            if (s == p->s0) return 0;
            continue;
        }
        if (p->kind == CRUISE) {
            if (p->s0 < s && s < p->s0 + p->v * p->T) {
                *t = p->t0 + (s - p->s0) / p->v;
                return 1;
            }
            continue;
        }
        if ((p->kind == ACCELERATE && p->s0 < s && s < p->s0 + half) ||
            (p->kind == BRAKE && p->s0 - half < s && s < p->s0)) {
            double lo = 0.0, hi = p->T, mid, x, a, b;
            for (it = 0; it < 100; it++) { /* bisection to the last bit: init only */
                mid = 0.5 * (lo + hi);
                if (p->kind == ACCELERATE) {
                    ramp(mid, p->v, p->T, &x, &a, &b);
                    x = p->s0 + x;
                } else {
                    ramp(p->T - mid, p->v, p->T, &x, &a, &b);
                    x = p->s0 - x;
                }
                if (x < s) lo = mid;
                else hi = mid;
            }
            *t = p->t0 + 0.5 * (lo + hi);
            return 1;
        }
    }
    return 0;
}

static int build_profile(ModelInstance *m, Trolley *d) {
    const double *r = m->r, length = d->G.hs[d->G.nh], speed = r[VR_speed], acc = r[VR_acceleration];
    double t = r[VR_static_duration], s = 0.0;
    size_t cap = 0, i, n = 0;
    if (length / r[VR_stop_spacing] > MAX_STOPS) { /* 5e-324 m: s + D == s, a loop without end */
        model_error(m, "Trolley: parameter stop_spacing = %g m gives more than %g stops on the %g m track", r[VR_stop_spacing],
                    MAX_STOPS, length);
        return 1;
    }
    if (add_phase(d, &cap, 0.0, REST, 0.0, 0.0, 0.0)) goto oom;
    while (s < length) {
        double D = r[VR_stop_spacing] < length - s ? r[VR_stop_spacing] : length - s, v, T, cruise;
        if (length - (s + D) < 1e-9 * length) D = length - s;
        v = sqrt(0.5 * D * acc);
        if (speed < v) v = speed;
        T = 2.0 * v / acc;
        cruise = D / v - T;
        if (add_phase(d, &cap, t, ACCELERATE, s, v, T)) goto oom;
        t += T;
        if (cruise > 0) {
            if (add_phase(d, &cap, t, CRUISE, s + 0.5 * v * T, v, cruise)) goto oom;
            t += cruise;
        }
        if (add_phase(d, &cap, t, BRAKE, s + D, v, T)) goto oom;
        t += T;
        s += D;
        if (add_phase(d, &cap, t, REST, s, 0.0, r[VR_stop_duration])) goto oom;
        t += r[VR_stop_duration];
    }
    /* quadrature splits: phase starts and the times element ends are passed, sorted */
    d->splits = (double *)malloc((d->nph + d->G.nk + 1) * sizeof(double));
    if (!d->splits) goto oom;
    for (i = 1; i < d->nph; i++) d->splits[n++] = d->ph[i].t0;
    for (i = 0; i < d->G.nk; i++) {
        double tb;
        if (time_at(d, d->G.kinks[i], &tb)) d->splits[n++] = tb;
    }
    qsort(d->splits, n, sizeof(double), tg_cmp);
    d->nsplits = 0;
    for (i = 0; i < n; i++)
        if (d->nsplits == 0 || d->splits[i] != d->splits[d->nsplits - 1]) d->splits[d->nsplits++] = d->splits[i];
    return 0;
oom:
    model_error(m, "Trolley: out of memory building the speed profile");
    return 1;
}

/* C_b^n0 = R3(psi) R2(theta) R1(phi) from the point's cosines and sines */
static void rot_zyx(const TrackPoint *P, double C[3][3]) {
    const double cp = P->cpsi, sp = P->spsi, ct = P->cth, st = P->sth, cf = P->cphi, sf = P->sphi;
    C[0][0] = cp * ct, C[0][1] = cp * st * sf - sp * cf, C[0][2] = cp * st * cf + sp * sf;
    C[1][0] = sp * ct, C[1][1] = sp * st * sf + cp * cf, C[1][2] = sp * st * cf - cp * sf;
    C[2][0] = -st, C[2][1] = ct * sf, C[2][2] = ct * cf;
}

static void mul_t(const double C[3][3], const double v[3], double o[3]) {
    int i;
    for (i = 0; i < 3; i++) o[i] = C[0][i] * v[0] + C[1][i] * v[1] + C[2][i] * v[2];
}

static void mul(const double C[3][3], const double v[3], double o[3]) {
    int i;
    for (i = 0; i < 3; i++) o[i] = C[i][0] * v[0] + C[i][1] * v[1] + C[i][2] * v[2];
}

/* omega_ib^b, f^b and d(path)/dt at time t */
static void node(const Trolley *d, double t, const EndPoint *e, double wb[3], double fb[3], double *path) {
    const double *om = d->G.omega_n0;
    double s, sd, sdd, v[3], a[3], D, dd[3], dn[3], gn, gned[3], gn0[3], f[3], C[3][3], we[3];
    double sf, cf, st, ct, dphi, dth, dpsi;
    TrackPoint P;
    int i;
    profile(d, t, &s, &sd, &sdd);
    tg_point(&d->G, s, 0, &P);
    for (i = 0; i < 3; i++) {
        v[i] = P.r1[i] * sd;
        a[i] = P.r2[i] * sd * sd + P.r1[i] * sdd;
    }
    D = e->s - s;
    for (i = 0; i < 3; i++) dd[i] = -(0.5 * D * (P.r1[i] + e->r1[i]) + D * D / 12.0 * (P.r2[i] - e->r2[i]));
    mul(e->Cnn0, dd, dn);
    gn = e->gam + e->gam_l * dn[0] / e->rn - e->gam_h * dn[2];
    gned[0] = -gn * dn[0] / e->rn, gned[1] = -gn * dn[1] / e->re, gned[2] = gn;
    mul_t(e->Cnn0, gned, gn0);
    f[0] = a[0] + 2.0 * (om[1] * v[2] - om[2] * v[1]) - gn0[0];
    f[1] = a[1] + 2.0 * (om[2] * v[0] - om[0] * v[2]) - gn0[1];
    f[2] = a[2] + 2.0 * (om[0] * v[1] - om[1] * v[0]) - gn0[2];
    rot_zyx(&P, C);
    mul_t(C, f, fb);
    sf = P.sphi, cf = P.cphi, st = P.sth, ct = P.cth;
    dphi = P.dphi * sd, dth = P.dtheta * sd, dpsi = P.dpsi * sd;
    mul_t(C, om, we);
    wb[0] = dphi - dpsi * st + we[0];
    wb[1] = dth * cf + dpsi * ct * sf + we[1];
    wb[2] = -dth * sf + dpsi * ct * cf + we[2];
    *path = sqrt(P.q[0] * P.q[0] + P.q[1] * P.q[1] + P.q[2] * P.q[2]) * sd;
}

/* the truth at t into the outputs, and the end point for the nodes */
static void end_state(ModelInstance *m, const Trolley *d, double t, EndPoint *e) {
    const TrackGeom *G = &d->G;
    double *r = m->r, s, sd, sdd, re[3], lat, lon, h, Cen[3][3], Cb0[3][3], Cbn[3][3], vn0[3], vn[3];
    double sl, cl, x, RE, RN, k, g0, fh, g0l;
    TrackPoint P;
    int i, j, l;
    profile(d, t, &s, &sd, &sdd);
    tg_point(G, s, 1, &P);
    for (i = 0; i < 3; i++)
        re[i] = G->r0e[i] + G->Cen0[0][i] * P.r[0] + G->Cen0[1][i] * P.r[1] + G->Cen0[2][i] * P.r[2];
    earth_ecef_to_lla(re, &lat, &lon, &h);
    earth_ecef_to_ned(lat, lon, Cen);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            e->Cnn0[i][j] = 0.0;
            for (l = 0; l < 3; l++) e->Cnn0[i][j] += Cen[i][l] * G->Cen0[j][l];
        }
    for (i = 0; i < 3; i++) vn0[i] = P.r1[i] * sd;
    mul(e->Cnn0, vn0, vn);
    rot_zyx(&P, Cb0);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            Cbn[i][j] = 0.0;
            for (l = 0; l < 3; l++) Cbn[i][j] += e->Cnn0[i][l] * Cb0[l][j];
        }
    sl = sin(lat), cl = cos(lat);
    x = 1.0 - EARTH_E2 * sl * sl;
    RE = EARTH_A / sqrt(x);
    RN = RE * (1.0 - EARTH_E2) / x;
    k = earth_k();
    g0 = EARTH_GE * (1.0 + k * sl * sl) / sqrt(x);
    fh = 1.0 - 2.0 * h / EARTH_A;
    g0l = EARTH_GE * sl * cl * (2.0 * k * x + (1.0 + k * sl * sl) * EARTH_E2) / (x * sqrt(x));
    r[VR_latitude] = lat, r[VR_longitude] = lon, r[VR_height] = h;
    r[VR_north] = P.r[0], r[VR_east] = P.r[1], r[VR_down] = P.r[2];
    r[VR_vn] = vn[0], r[VR_ve] = vn[1], r[VR_vd] = vn[2];
    r[VR_roll] = atan2(Cbn[2][1], Cbn[2][2]);
    r[VR_pitch] = asin(-Cbn[2][0] > 1.0 ? 1.0 : (-Cbn[2][0] < -1.0 ? -1.0 : -Cbn[2][0]));
    r[VR_heading] = atan2(Cbn[1][0], Cbn[0][0]);
    r[VR_distance] = s;
    r[VR_speed_along] = sd;
    e->s = s;
    memcpy(e->r1, P.r1, sizeof P.r1);
    memcpy(e->r2, P.r2, sizeof P.r2);
    e->gam = g0 * fh, e->gam_l = g0l * fh, e->gam_h = -2.0 * g0 / EARTH_A;
    e->rn = RN + h, e->re = RE + h;
}

static void increments(const Trolley *d, double ta, double tb, const EndPoint *e, double dth[3],
                       double dv[3], double *path) {
    size_t lo = 0, hi = d->nsplits;
    double a = ta;
    int i;
    memset(dth, 0, 3 * sizeof(double));
    memset(dv, 0, 3 * sizeof(double));
    *path = 0.0;
    while (lo < hi) { /* first split > ta */
        const size_t mid = lo + (hi - lo) / 2;
        if (d->splits[mid] <= ta) lo = mid + 1;
        else hi = mid;
    }
    for (;;) {
        const double b = (lo < d->nsplits && d->splits[lo] < tb) ? d->splits[lo] : tb;
        double q = (b - a) / MAX_PANEL - 1e-9, hp;
        unsigned long n = q > 0 ? (unsigned long)q : 0, j;
        int k;
        if ((double)n < q) n++;
        if (n < 1) n = 1;
        hp = (b - a) / (double)n;
        for (j = 0; j < n; j++) {
            const double mid = a + ((double)j + 0.5) * hp;
            for (k = -1; k <= 1; k++) {
                double wb[3], fb[3], pr;
                const double wq = 0.5 * hp * (k ? GL3_W1 : GL3_W0);
                node(d, mid + k * 0.5 * hp * GL3_X, e, wb, fb, &pr);
                for (i = 0; i < 3; i++) {
                    dth[i] += wq * wb[i];
                    dv[i] += wq * fb[i];
                }
                *path += wq * pr;
            }
        }
        if (b >= tb) break;
        a = b;
        lo++;
    }
}

/* ---- the model interface ------------------------------------------------------------------ */

#define CHECK(ok, name, value, rule)                                           \
    if (!(ok)) {                                                               \
        model_error(m, "Trolley: parameter %s = %g %s", name, (double)(value), rule); \
        return 1;                                                              \
    }

int model_check_parameters(ModelInstance *m) {
    const double *r = m->r;
    CHECK(fabs(r[VR_start_latitude]) < 89.0 * TG_PI / 180.0, "start_latitude", r[VR_start_latitude],
          "must be within 89 deg of the equator (rad)");
    CHECK(isfinite(r[VR_start_longitude]), "start_longitude", r[VR_start_longitude], "must be finite (rad)");
    CHECK(fabs(r[VR_start_height]) < 1e5, "start_height", r[VR_start_height],
          "must be within 100 km of the ellipsoid");
    CHECK(isfinite(r[VR_azimuth]), "azimuth", r[VR_azimuth], "must be finite (rad)");
    CHECK(m->i[VRI_irregularity_level] >= 0 && m->i[VRI_irregularity_level] <= 2, "irregularity_level",
          m->i[VRI_irregularity_level], "must be 0, 1 or 2");
    CHECK(r[VR_irregularity_scale] >= 0, "irregularity_scale", r[VR_irregularity_scale], "must be >= 0");
    CHECK(m->i[VRI_irregularity_lines] >= 0 && m->i[VRI_irregularity_lines] <= 4096, "irregularity_lines",
          m->i[VRI_irregularity_lines], "must be in 0..4096");
    CHECK(r[VR_lambda_min] > 0, "lambda_min", r[VR_lambda_min], "must be > 0 m");
    CHECK(r[VR_lambda_max] > r[VR_lambda_min], "lambda_max", r[VR_lambda_max], "must be greater than lambda_min");
    CHECK(r[VR_harmonic_wavelength] > 0, "harmonic_wavelength", r[VR_harmonic_wavelength], "must be > 0 m");
    CHECK(r[VR_wobble_wavelength] > 0, "wobble_wavelength", r[VR_wobble_wavelength], "must be > 0 m");
    CHECK(fabs(r[VR_harmonic_lateral_amplitude]) < 0.1, "harmonic_lateral_amplitude",
          r[VR_harmonic_lateral_amplitude], "must be below 0.1 m in size");
    CHECK(fabs(r[VR_harmonic_vertical_amplitude]) < 0.1, "harmonic_vertical_amplitude",
          r[VR_harmonic_vertical_amplitude], "must be below 0.1 m in size");
    CHECK(fabs(r[VR_wobble_lateral]) < 0.1, "wobble_lateral", r[VR_wobble_lateral], "must be below 0.1 m in size");
    CHECK(fabs(r[VR_wobble_vertical]) < 0.1, "wobble_vertical", r[VR_wobble_vertical], "must be below 0.1 m in size");
    CHECK(r[VR_speed] > 0 && r[VR_speed] < 50, "speed", r[VR_speed], "must be in (0, 50) m/s");
    CHECK(r[VR_acceleration] > 0 && isfinite(r[VR_acceleration]), "acceleration", r[VR_acceleration], "must be > 0 m/s2");
    CHECK(r[VR_stop_spacing] > 0 && isfinite(r[VR_stop_spacing]), "stop_spacing", r[VR_stop_spacing], "must be > 0 m");
    CHECK(r[VR_stop_duration] >= 0 && isfinite(r[VR_stop_duration]), "stop_duration", r[VR_stop_duration], "must be >= 0 s");
    CHECK(r[VR_static_duration] >= 0 && isfinite(r[VR_static_duration]), "static_duration",
          r[VR_static_duration], "must be >= 0 s");
    CHECK(fabs(r[VR_odometer_scale_ppm]) < 1e5, "odometer_scale_ppm", r[VR_odometer_scale_ppm], "must be below 1e5 in size");
    return 0;
}

static void trolley_free(Trolley *d) {
    if (!d) return;
    tg_free(&d->G);
    free(d->ph);
    free(d->splits);
    free(d);
}

static int load(ModelInstance *m) {
    const double *r = m->r;
    Trolley *d;
    model_free(m);
    d = (Trolley *)calloc(1, sizeof *d);
    if (!d) {
        model_error(m, "Trolley: out of memory");
        return 1;
    }
    if (tg_read(m, &d->G, m->s[VRS_track_file] ? m->s[VRS_track_file] : "") ||
        tg_read_table(m, &d->G, m->s[VRS_irregularity_file] ? m->s[VRS_irregularity_file] : "") ||
        tg_setup(m, &d->G, r[VR_start_latitude], r[VR_start_longitude], r[VR_start_height], r[VR_azimuth],
                 (int)m->i[VRI_irregularity_level], r[VR_irregularity_scale], (int)m->i[VRI_irregularity_lines],
                 r[VR_lambda_min], r[VR_lambda_max], (int)m->i[VRI_irregularity_seed],
                 r[VR_harmonic_lateral_amplitude], r[VR_harmonic_vertical_amplitude], r[VR_harmonic_wavelength],
                 r[VR_wobble_lateral], r[VR_wobble_vertical], r[VR_wobble_wavelength]) ||
        build_profile(m, d)) {
        trolley_free(d);
        return 1;
    }
    m->modelData = d;
    return 0;
}

int model_initialize(ModelInstance *m) {
    if (load(m)) return 1;
    m->r[VR_interval_start] = m->r[0];
    m->r[VR_path_start] = 0.0;
    m->r[VR_path_length] = 0.0;
    ((Trolley *)m->modelData)->last_end = m->r[0];
    return 0;
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m, (void)t, (void)x, (void)dx;
}

int model_outputs(ModelInstance *m) {
    Trolley *d = (Trolley *)m->modelData;
    double *r = m->r, dth[3] = {0, 0, 0}, dv[3] = {0, 0, 0}, path = 0.0;
    EndPoint e;
    const double t = r[0];
    /* the increments integrate in panels of at most MAX_PANEL: a step of 1e300 s would need
       more panels than a counter holds (and never end) */
    if (t - (t != d->last_end ? d->last_end : r[VR_interval_start]) > 1e9 * MAX_PANEL) {
        model_error(m, "Trolley: a step to t = %g s is longer than %g s (1e9 integration panels of %g s)", t,
                    1e9 * MAX_PANEL, MAX_PANEL);
        return 1;
    }
    if (t != d->last_end) { /* a new communication point */
        r[VR_interval_start] = d->last_end;
        r[VR_path_start] = r[VR_path_length];
        d->last_end = t;
    }
    end_state(m, d, t, &e);
    if (t > r[VR_interval_start]) increments(d, r[VR_interval_start], t, &e, dth, dv, &path);
    r[VR_dtheta_x] = dth[0], r[VR_dtheta_y] = dth[1], r[VR_dtheta_z] = dth[2];
    r[VR_dv_x] = dv[0], r[VR_dv_y] = dv[1], r[VR_dv_z] = dv[2];
    r[VR_path_length] = r[VR_path_start] + path;
    r[VR_odometer] = (1.0 + 1e-6 * r[VR_odometer_scale_ppm]) * r[VR_path_length];
    m->b[VRB_stopped] = stopped(d, t, STEP_TOLERANCE * m->stepSize);
    return 0;
}

int model_state_restored(ModelInstance *m) {
    /* the restored point is the last one computed: the next new point starts from it */
    const double t = m->r[0];
    if (load(m)) return 1;
    ((Trolley *)m->modelData)->last_end = t;
    return 0;
}

void model_free(ModelInstance *m) {
    trolley_free((Trolley *)m->modelData);
    m->modelData = NULL;
}
