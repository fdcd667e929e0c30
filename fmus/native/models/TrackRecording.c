/* railfmu: TrackRecording, hand-written model code (the equations are in models/track/recording.py,
 * whose docstring is this model's documentation; tests/test_track_recording.py proves this C
 * equals the Python).
 *
 *   y_j = z(j Delta + delta) + sigma w(j)          the file's samples (left, right rail)
 *   out = Catmull-Rom Hermite of y_j at s_i = s_start + V t - axle_position_i, rate V d/ds
 *
 * z: the ERRI B176 random vertical profile and cross-level of TrackIrregularity (same lines,
 * amplitudes and SplitMix64 phases), summed line by line at each sample (no table: a sample
 * is needed once per Delta of travel). w and delta: counter-based draws of rng.h (streams
 * 1001-1003), pure functions of (seed, j), so the FMU state needs nothing beyond the
 * parameters; modelData holds the lines and a cache of samples, both rebuilt on restore.
 *
 * The variable tables (model_real_info, ...) are generated from the Python definition into
 * a separate file; the VR_/VRI_ defines come from the generated model_config.h.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "erri_b176.h"
#include "model.h"
#include "rng.h"

#define N_BOGIES 2
#define STREAM_LEFT 1001u
#define STREAM_RIGHT 1002u
#define STREAM_OFFSET 1003u
#define CACHE 256 /* samples kept: both bogies' four neighbours with room to spare */

static const double PI = 3.14159265358979323846; /* == Python's math.pi */

static const fmi2ValueReference VR_LEFT[N_BOGIES] = {VR_vertical_left_1, VR_vertical_left_2};
static const fmi2ValueReference VR_RIGHT[N_BOGIES] = {VR_vertical_right_1, VR_vertical_right_2};
static const fmi2ValueReference VR_LEFT_RATE[N_BOGIES] = {VR_vertical_left_rate_1, VR_vertical_left_rate_2};
static const fmi2ValueReference VR_RIGHT_RATE[N_BOGIES] = {VR_vertical_right_rate_1, VR_vertical_right_rate_2};
static const fmi2ValueReference VR_EXACT_LEFT[N_BOGIES] = {VR_exact_left_1, VR_exact_left_2};
static const fmi2ValueReference VR_EXACT_RIGHT[N_BOGIES] = {VR_exact_right_1, VR_exact_right_2};
static const fmi2ValueReference VR_EXACT_LEFT_RATE[N_BOGIES] = {VR_exact_left_rate_1, VR_exact_left_rate_2};
static const fmi2ValueReference VR_EXACT_RIGHT_RATE[N_BOGIES] = {VR_exact_right_rate_1, VR_exact_right_rate_2};
static const fmi2ValueReference VR_AXLE[N_BOGIES] = {VR_axle_position_1, VR_axle_position_2};

typedef struct {
    long n;                       /* lines */
    double L, offset;
    double *omega, *a_vp, *ph_vp, *a_cl, *ph_cl;
    int64_t key[CACHE];
    unsigned char valid[CACHE];
    double left[CACHE], right[CACHE];
} RecordingData;

static double psd_shape(double o2) {
    return ERRI_OMEGA_C * ERRI_OMEGA_C / ((o2 + ERRI_OMEGA_R * ERRI_OMEGA_R) * (o2 + ERRI_OMEGA_C * ERRI_OMEGA_C));
}

static void free_data(RecordingData *d) {
    if (!d) return;
    free(d->omega);
    free(d->a_vp);
    free(d->ph_vp);
    free(d->a_cl);
    free(d->ph_cl);
    free(d);
}

/* lines as railfmu.models.track.irregularity.spectral_lines: k = ceil(L/lambda_max) (>= 1) ..
   floor(L/lambda_min); phases of all alignment lines first (skipped here), then vertical
   profile, then cross-level */
static int build(ModelInstance *m) {
    const double *r = m->r;
    const int level = m->i[VRI_psd_level];
    const double L = r[VR_period_length], d_omega = 2.0 * PI / L, b = r[VR_half_contact_width];
    const double scale = r[VR_psd_scale] * r[VR_psd_vertical_scale];
    RecordingData *d = (RecordingData *)calloc(1, sizeof(RecordingData));
    double k_lo, k_hi;
    long k;
    uint64_t rng = (uint64_t)(int64_t)m->i[VRI_seed];
    model_free(m);
    if (!d) {
        model_error(m, "out of memory");
        return -1;
    }
    d->L = L;
    d->offset = r[VR_offset_max] *
                (2.0 * rng_uniform2((uint64_t)(int64_t)m->i[VRI_seed], STREAM_OFFSET, 0) - 1.0);
    k_lo = ceil(L / r[VR_lambda_max]);
    if (k_lo < 1.0) k_lo = 1.0;
    k_hi = floor(L / r[VR_lambda_min]);
    if (level != 0 && k_hi >= k_lo) {
        const long n = (long)(k_hi - k_lo) + 1;
        d->n = n;
        d->omega = (double *)malloc(sizeof(double) * (size_t)n);
        d->a_vp = (double *)malloc(sizeof(double) * (size_t)n);
        d->ph_vp = (double *)malloc(sizeof(double) * (size_t)n);
        d->a_cl = (double *)malloc(sizeof(double) * (size_t)n);
        d->ph_cl = (double *)malloc(sizeof(double) * (size_t)n);
        if (!d->omega || !d->a_vp || !d->ph_vp || !d->a_cl || !d->ph_cl) {
            free_data(d);
            model_error(m, "out of memory for %ld spectral lines", n);
            return -1;
        }
        for (k = 0; k < n; k++) (void)rng_uniform(&rng); /* the alignment's phases */
        for (k = 0; k < n; k++) {
            const double omega = (k_lo + (double)k) * d_omega, o2 = omega * omega;
            const double S = ERRI_A_VERTICAL[level] * psd_shape(o2);
            d->omega[k] = omega;
            d->a_vp[k] = scale * sqrt(2.0 * S * d_omega);
            d->ph_vp[k] = 2.0 * PI * rng_uniform(&rng);
        }
        for (k = 0; k < n; k++) {
            const double omega = d->omega[k], o2 = omega * omega;
            const double S = (ERRI_A_VERTICAL[level] / (b * b)) * (ERRI_OMEGA_C * ERRI_OMEGA_C) * o2 /
                             ((o2 + ERRI_OMEGA_R * ERRI_OMEGA_R) * (o2 + ERRI_OMEGA_C * ERRI_OMEGA_C) *
                              (o2 + ERRI_OMEGA_S * ERRI_OMEGA_S));
            d->a_cl[k] = scale * sqrt(2.0 * S * d_omega);
            d->ph_cl[k] = 2.0 * PI * rng_uniform(&rng);
        }
    }
    m->modelData = d;
    return 0;
}

/* sample j of the file: left and right rail (m), from the cache or computed */
static void sample(ModelInstance *m, RecordingData *d, int64_t j, double *left, double *right) {
    const size_t slot = (size_t)((uint64_t)j % CACHE);
    if (!d->valid[slot] || d->key[slot] != j) {
        const double x = (double)j * m->r[VR_sample_spacing] + d->offset;
        const double u = fmod(x, d->L), xs = u < 0 ? u + d->L : u; /* Omega_k L = 2 pi k */
        const double b = m->r[VR_half_contact_width], sigma = m->r[VR_noise_sigma];
        const uint64_t seed = (uint64_t)(int64_t)m->i[VRI_seed];
        double vp = 0.0, th = 0.0;
        long k;
        for (k = 0; k < d->n; k++) {
            const double arg = d->omega[k] * xs;
            vp += d->a_vp[k] * cos(arg + d->ph_vp[k]);
            th += d->a_cl[k] * cos(arg + d->ph_cl[k]);
        }
        d->left[slot] = vp + b * th;
        d->right[slot] = vp - b * th;
        if (sigma > 0) {
            d->left[slot] += sigma * rng_normal(seed, STREAM_LEFT, (uint64_t)j);
            d->right[slot] += sigma * rng_normal(seed, STREAM_RIGHT, (uint64_t)j);
        }
        d->key[slot] = j;
        d->valid[slot] = 1;
    }
    *left = d->left[slot];
    *right = d->right[slot];
}

/* Cubic Hermite on [0, h] at t in [0, 1]: value and d/ds (as railfmu.models.track.irregularity._hermite). */
static void hermite(double t, double h, double y0, double m0, double y1, double m1,
                    double *value, double *slope) {
    const double t2 = t * t, t3 = t2 * t;
    const double h00 = 2.0 * t3 - 3.0 * t2 + 1.0, h10 = t3 - 2.0 * t2 + t;
    const double h01 = -2.0 * t3 + 3.0 * t2, h11 = t3 - t2;
    const double d00 = 6.0 * t2 - 6.0 * t, d10 = 3.0 * t2 - 4.0 * t + 1.0;
    const double d01 = -6.0 * t2 + 6.0 * t, d11 = 3.0 * t2 - 2.0 * t;
    *value = h00 * y0 + h10 * h * m0 + h01 * y1 + h11 * h * m1;
    *slope = (d00 * y0 + d01 * y1) / h + d10 * m0 + d11 * m1;
}

/* ---- model.h ---- */
int model_check_parameters(ModelInstance *m) {
    static const struct { const char *name; fmi2ValueReference vr; } reals[] = {
        {"V", VR_V}, {"s_start", VR_s_start}, {"axle_position_1", VR_axle_position_1},
        {"axle_position_2", VR_axle_position_2}, {"psd_scale", VR_psd_scale},
        {"psd_vertical_scale", VR_psd_vertical_scale}, {"lambda_min", VR_lambda_min},
        {"lambda_max", VR_lambda_max}, {"period_length", VR_period_length},
        {"half_contact_width", VR_half_contact_width}, {"sample_spacing", VR_sample_spacing},
        {"noise_sigma", VR_noise_sigma}, {"offset_max", VR_offset_max}};
    const double *r = m->r;
    size_t j;
    for (j = 0; j < sizeof reals / sizeof reals[0]; j++) {
        if (!isfinite(r[reals[j].vr])) {
            model_error(m, "parameter %s = %g must be finite", reals[j].name, r[reals[j].vr]);
            return -1;
        }
    }
    if (m->i[VRI_psd_level] < 0 || m->i[VRI_psd_level] > 2) {
        model_error(m, "parameter psd_level = %d must be 0, 1 or 2", m->i[VRI_psd_level]);
        return -1;
    }
    if (!(r[VR_lambda_max] > r[VR_lambda_min])) {
        model_error(m, "parameter lambda_max = %g must be > lambda_min = %g", r[VR_lambda_max],
                    r[VR_lambda_min]);
        return -1;
    }
    /* the positive/min checks of the definition are the runtime's; the line count bounds the
       work per sample */
    if (floor(r[VR_period_length] / r[VR_lambda_min]) > 1e6) {
        model_error(m, "parameter period_length / lambda_min = %g: more than 1e6 spectral lines",
                    r[VR_period_length] / r[VR_lambda_min]);
        return -1;
    }
    return 0;
}

int model_initialize(ModelInstance *m) {
    if (build(m) != 0) return -1;
    return model_outputs(m);
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m; (void)t; (void)x; (void)dx; /* no states */
}

int model_outputs(ModelInstance *m) {
    RecordingData *d = (RecordingData *)m->modelData;
    double *r = m->r;
    const double V = r[VR_V], delta = r[VR_sample_spacing];
    const double front = r[VR_s_start] + V * r[0];
    int i;
    if (!d) {
        model_error(m, "TrackRecording: outputs requested before initialisation");
        return -1;
    }
    r[VR_position] = front - r[VR_AXLE[0]];
    r[VR_offset] = d->offset;
    if (!m->b[VRB_enabled]) { /* the exact track passed through */
        for (i = 0; i < N_BOGIES; i++) {
            r[VR_LEFT[i]] = r[VR_EXACT_LEFT[i]];
            r[VR_RIGHT[i]] = r[VR_EXACT_RIGHT[i]];
            r[VR_LEFT_RATE[i]] = r[VR_EXACT_LEFT_RATE[i]];
            r[VR_RIGHT_RATE[i]] = r[VR_EXACT_RIGHT_RATE[i]];
        }
        return 0;
    }
    for (i = 0; i < N_BOGIES; i++) {
        const double u = (front - r[VR_AXLE[i]]) / delta, jf = floor(u), tau = u - jf;
        int64_t j;
        double yl[4], yr[4], zl, zl_d, zr, zr_d;
        int q;
        if (!(fabs(jf) < 4.0e15)) { /* a sample index must fit an int64 exactly (and not be NaN) */
            model_error(m, "TrackRecording: position %g m is beyond the recording's %g m samples' range",
                        front - r[VR_AXLE[i]], delta);
            return -1;
        }
        j = (int64_t)jf;
        for (q = 0; q < 4; q++) sample(m, d, j - 1 + q, &yl[q], &yr[q]);
        hermite(tau, delta, yl[1], (yl[2] - yl[0]) / (2.0 * delta), yl[2], (yl[3] - yl[1]) / (2.0 * delta),
                &zl, &zl_d);
        hermite(tau, delta, yr[1], (yr[2] - yr[0]) / (2.0 * delta), yr[2], (yr[3] - yr[1]) / (2.0 * delta),
                &zr, &zr_d);
        r[VR_LEFT[i]] = zl;
        r[VR_RIGHT[i]] = zr;
        r[VR_LEFT_RATE[i]] = V * zl_d;
        r[VR_RIGHT_RATE[i]] = V * zr_d;
    }
    return 0;
}

/* The runtime drops modelData before restoring a state; lines and offset depend only on the
   restored parameters, the cache is refilled on demand. */
int model_state_restored(ModelInstance *m) { return build(m); }

void model_free(ModelInstance *m) {
    free_data((RecordingData *)m->modelData);
    m->modelData = NULL;
}
