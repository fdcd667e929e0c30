/* railfmu: TrackIrregularity, hand-written model code (the equations are in models/track/irregularity.py,
 * whose docstring is this model's documentation; tests/test_track.py proves this C equals
 * the Python).
 *
 * Random part: ERRI B176 spectra on the lines Omega_k = k 2 pi / L with SplitMix64 phases.
 * At initialisation every channel's values AND slopes d/ds are tabulated on a periodic grid
 * of M = 2^n points by one complex inverse FFT per channel (value in the real part, slope
 * in the imaginary part); the outputs interpolate the table with cubic Hermite polynomials.
 * Deterministic parts: harmonic, step, measured profile table (CSV, Catmull-Rom Hermite).
 * Run-in (run_in_length > 0): the sum times a raised-cosine weight of s, rates by the product
 * rule (as railfmu.models.track.irregularity.run_in_weight and TrackIrregularity.rails).
 * Position: s_1 = s_start + V t at constant speed, or s_start + distance with the speed v
 * from the inputs (distance_input = true); rates d/dt = v d/ds. The step counts as reached
 * within STEP_TOLERANCE |v| h of a communication point (model.h).
 *
 * The variable tables (model_real_info, ...) are generated from the Python definition into
 * a separate file; the VR_/VRI_/VRS_ defines come from the generated model_config.h.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "ProfileTable.h"
#include "erri_b176.h"
#include "model.h"
#include "rng.h"

#define N_WHEELSETS 4
#define MAX_GRID_POINTS (1L << 22) /* 48 bytes per point: at most 192 MiB of tables */

static const double PI = 3.14159265358979323846; /* == Python's math.pi */

static const fmi2ValueReference VR_ALIGNMENT[N_WHEELSETS] = {
    VR_alignment_1, VR_alignment_2, VR_alignment_3, VR_alignment_4};
static const fmi2ValueReference VR_ALIGNMENT_RATE[N_WHEELSETS] = {
    VR_alignment_rate_1, VR_alignment_rate_2, VR_alignment_rate_3, VR_alignment_rate_4};
static const fmi2ValueReference VR_LEFT[N_WHEELSETS] = {
    VR_vertical_left_1, VR_vertical_left_2, VR_vertical_left_3, VR_vertical_left_4};
static const fmi2ValueReference VR_RIGHT[N_WHEELSETS] = {
    VR_vertical_right_1, VR_vertical_right_2, VR_vertical_right_3, VR_vertical_right_4};
static const fmi2ValueReference VR_LEFT_RATE[N_WHEELSETS] = {
    VR_vertical_left_rate_1, VR_vertical_left_rate_2, VR_vertical_left_rate_3,
    VR_vertical_left_rate_4};
static const fmi2ValueReference VR_RIGHT_RATE[N_WHEELSETS] = {
    VR_vertical_right_rate_1, VR_vertical_right_rate_2, VR_vertical_right_rate_3,
    VR_vertical_right_rate_4};
static const fmi2ValueReference VR_AXLE[N_WHEELSETS] = {
    VR_axle_position_1, VR_axle_position_2, VR_axle_position_3, VR_axle_position_4};

typedef struct {
    /* random part: NULL when there are no lines; per grid point n the 6 doubles
       value[3] (alignment m, vertical profile m, cross-level angle rad) then slope[3] */
    double *grid;
    long M;
    double L, h;
    ProfileTable profile; /* measured; n == 0 when none */
} TrackData;

/* ---- spectra (same operation order as models/track/irregularity.py) ---- */
static double psd_shape(double o2) {
    return ERRI_OMEGA_C * ERRI_OMEGA_C / ((o2 + ERRI_OMEGA_R * ERRI_OMEGA_R) * (o2 + ERRI_OMEGA_C * ERRI_OMEGA_C));
}

static double psd_channel(int channel, int level, double omega, double b) {
    const double o2 = omega * omega;
    switch (channel) {
    case 0: return ERRI_A_ALIGNMENT[level] * psd_shape(o2);
    case 1: return ERRI_A_VERTICAL[level] * psd_shape(o2);
    default:
        return (ERRI_A_VERTICAL[level] / (b * b)) * (ERRI_OMEGA_C * ERRI_OMEGA_C) * o2 /
               ((o2 + ERRI_OMEGA_R * ERRI_OMEGA_R) * (o2 + ERRI_OMEGA_C * ERRI_OMEGA_C) * (o2 + ERRI_OMEGA_S * ERRI_OMEGA_S));
    }
}

/* ---- grid size: as railfmu.models.track.irregularity.grid_size ---- */
static void line_range(double L, double lambda_min, double lambda_max, double *k_lo, double *k_hi) {
    *k_lo = ceil(L / lambda_max);
    if (*k_lo < 1.0) *k_lo = 1.0; /* no mean (k = 0) line */
    *k_hi = floor(L / lambda_min);
}

/* The smallest power of two with L/M <= grid_step and M > 2 k_max; 0 if above the limit. */
static long grid_size(double L, double grid_step, double k_hi) {
    long M = 1;
    while (L / (double)M > grid_step || (double)M <= 2.0 * k_hi) {
        if (M >= MAX_GRID_POINTS) return 0;
        M *= 2;
    }
    return M;
}

/* ---- in-place iterative radix-2 complex FFT, sign +1 (inverse, unnormalised):
        z[n] <- sum_j z[j] exp(+2 pi i j n / M); z interleaved re, im; M a power of two;
        w[2j], w[2j+1] = cos, sin(2 pi j / M) for j < M/2 ---- */
static void fft_twiddles(double *w, long M) {
    long j;
    for (j = 0; j < M / 2; j++) {
        const double a = 2.0 * PI * (double)j / (double)M;
        w[2 * j] = cos(a);
        w[2 * j + 1] = sin(a);
    }
}

static void fft_inverse(double *z, const double *w, long M) {
    long i, j, len, k, half;
    for (i = 1, j = 0; i < M; i++) { /* bit reversal */
        long bit = M >> 1;
        for (; j & bit; bit >>= 1) j ^= bit;
        j ^= bit;
        if (i < j) {
            double t = z[2 * i]; z[2 * i] = z[2 * j]; z[2 * j] = t;
            t = z[2 * i + 1]; z[2 * i + 1] = z[2 * j + 1]; z[2 * j + 1] = t;
        }
    }
    for (len = 2; len <= M; len <<= 1) {
        const long stride = M / len;
        half = len >> 1;
        for (i = 0; i < M; i += len) {
            for (k = 0; k < half; k++) {
                const double wr = w[2 * k * stride], wi = w[2 * k * stride + 1];
                double *a = z + 2 * (i + k), *b = z + 2 * (i + k + half);
                const double tr = b[0] * wr - b[1] * wi, ti = b[0] * wi + b[1] * wr;
                b[0] = a[0] - tr;
                b[1] = a[1] - ti;
                a[0] += tr;
                a[1] += ti;
            }
        }
    }
}

/* ---- random part ---- */
static int build_random(ModelInstance *m, TrackData *d) {
    const int level = m->i[VRI_psd_level];
    const double L = m->r[VR_period_length], scale = m->r[VR_psd_scale];
    /* alignment, vertical profile, cross-level: the phases are drawn for every channel, so a
       channel's scale changes nothing in the others */
    const double channel_scale[3] = {m->r[VR_psd_lateral_scale], m->r[VR_psd_vertical_scale],
                                     m->r[VR_psd_vertical_scale]};
    const double b = m->r[VR_half_contact_width], d_omega = 2.0 * PI / L;
    double k_lo, k_hi;
    long M, k, n, n_lines;
    int c;
    uint64_t rng = (uint64_t)(int64_t)m->i[VRI_seed];
    double *z, *w;

    if (level == 0) return 0;
    if (level < 0 || level > 2) {
        model_error(m, "parameter psd_level = %d must be 0, 1 or 2", level);
        return -1;
    }
    line_range(L, m->r[VR_lambda_min], m->r[VR_lambda_max], &k_lo, &k_hi);
    if (k_hi < k_lo) return 0;
    M = grid_size(L, m->r[VR_grid_step], k_hi);
    if (M == 0) { /* model_check_parameters already refuses this */
        model_error(m, "parameter grid_step = %g: too many grid points", m->r[VR_grid_step]);
        return -1;
    }
    n_lines = (long)(k_hi - k_lo) + 1;
    d->M = M;
    d->L = L;
    d->h = L / (double)M;
    d->grid = (double *)malloc(sizeof(double) * 6 * (size_t)M);
    z = (double *)malloc(sizeof(double) * 2 * (size_t)M);
    w = (double *)malloc(sizeof(double) * (size_t)M);
    if (!d->grid || !z || !w) {
        free(z);
        free(w);
        model_error(m, "out of memory for the track table (%ld points)", M);
        return -1;
    }
    fft_twiddles(w, M);
    for (c = 0; c < 3; c++) {
        /* X_k = a_k/2 e^{i phi_k}, X_{M-k} = conj; slope spectrum D = i Omega X. Packing
           Z = X + i D gives z = x + i dx/ds, both real signals. */
        memset(z, 0, sizeof(double) * 2 * (size_t)M);
        for (k = (long)k_lo; k < (long)k_lo + n_lines; k++) {
            const double omega = (double)k * d_omega;
            const double a = scale * channel_scale[c] * sqrt(2.0 * psd_channel(c, level, omega, b) * d_omega);
            const double phi = 2.0 * PI * rng_uniform(&rng);
            const double xr = 0.5 * a * cos(phi), xi = 0.5 * a * sin(phi);
            z[2 * k] = xr * (1.0 - omega);       /* X + i (i Omega X) = X (1 - Omega) */
            z[2 * k + 1] = xi * (1.0 - omega);
            z[2 * (M - k)] = xr * (1.0 + omega); /* conj(X) + i conj(i Omega X) */
            z[2 * (M - k) + 1] = -xi * (1.0 + omega);
        }
        fft_inverse(z, w, M);
        for (n = 0; n < M; n++) {
            d->grid[6 * n + c] = z[2 * n];
            d->grid[6 * n + 3 + c] = z[2 * n + 1];
        }
    }
    free(z);
    free(w);
    return 0;
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

/* Random part at s: v[3], dv[3] (alignment, vertical profile, cross-level angle). */
static void eval_random(const TrackData *d, double s, double *v, double *dv) {
    double u, x, t;
    long n, n1;
    int c;
    if (!d->grid) {
        for (c = 0; c < 3; c++) v[c] = dv[c] = 0.0;
        return;
    }
    u = fmod(s, d->L);
    if (u < 0) u += d->L;
    x = u / d->h;
    t = floor(x);
    n = (long)t;
    t = x - t;
    if (n >= d->M) n -= d->M;
    n1 = (n + 1 == d->M) ? 0 : n + 1;
    for (c = 0; c < 3; c++)
        hermite(t, d->h, d->grid[6 * n + c], d->grid[6 * n + 3 + c], d->grid[6 * n1 + c],
                d->grid[6 * n1 + 3 + c], &v[c], &dv[c]);
}

/* ---- measured profile table (ProfileTable.h) ---- */
/* Table at s: v[3], dv[3] (alignment, vertical_left, vertical_right); 0 outside its range. */
static void eval_profile(const TrackData *d, double s, double *v, double *dv) {
    size_t lo, hi;
    int c;
    const ProfileTable *p = &d->profile;
    const size_t n = p->n;
    if (n == 0 || !(s >= p->s[0] && s <= p->s[n - 1])) {
        for (c = 0; c < 3; c++) v[c] = dv[c] = 0.0;
        return;
    }
    lo = 0; /* the largest i <= n - 2 with s_i <= s */
    hi = n - 1;
    while (hi - lo > 1) {
        const size_t mid = lo + (hi - lo) / 2;
        if (p->s[mid] <= s) lo = mid;
        else hi = mid;
    }
    {
        const double h = p->s[lo + 1] - p->s[lo], t = (s - p->s[lo]) / h;
        for (c = 0; c < 3; c++)
            hermite(t, h, p->y[3 * lo + c], p->dy[3 * lo + c], p->y[3 * (lo + 1) + c],
                    p->dy[3 * (lo + 1) + c], &v[c], &dv[c]);
    }
}

/* ---- run-in: weight w and dw/ds at s for length > 0 (as railfmu.models.track.irregularity.run_in_weight) ---- */
static void run_in_weight(double s, double length, double *w, double *w_d) {
    if (s <= 0.0) {
        *w = *w_d = 0.0;
    } else if (s >= length) {
        *w = 1.0;
        *w_d = 0.0;
    } else {
        const double arg = PI * s / length;
        *w = 0.5 * (1.0 - cos(arg));
        *w_d = (PI / (2.0 * length)) * sin(arg);
    }
}

/* ---- tables: build, compare, free ---- */
static const char *profile_file(ModelInstance *m) {
    return m->s[VRS_profile_file] ? m->s[VRS_profile_file] : "";
}

static void free_data(TrackData *d) {
    if (!d) return;
    free(d->grid);
    profile_free(&d->profile);
    free(d);
}

static int build_tables(ModelInstance *m) {
    const char *file = profile_file(m);
    TrackData *d = (TrackData *)calloc(1, sizeof(TrackData));
    model_free(m);
    if (!d) {
        model_error(m, "out of memory");
        return -1;
    }
    if (build_random(m, d) != 0) {
        free_data(d);
        return -1;
    }
    if (*file && profile_read(m, "profile_file", file, &d->profile) != 0) {
        free_data(d);
        return -1;
    }
    m->modelData = d;
    return 0;
}

/* ---- model.h ---- */
#define CHECK(cond, name, value, rule)                                                        \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            model_error(m, "parameter %s = %g must be %s", name, (double)(value), rule);      \
            return -1;                                                                        \
        }                                                                                     \
    } while (0)

int model_check_parameters(ModelInstance *m) {
    static const struct { const char *name; fmi2ValueReference vr; } reals[] = {
        {"V", VR_V}, {"s_start", VR_s_start}, {"axle_position_1", VR_axle_position_1},
        {"axle_position_2", VR_axle_position_2}, {"axle_position_3", VR_axle_position_3},
        {"axle_position_4", VR_axle_position_4}, {"psd_scale", VR_psd_scale},
        {"psd_lateral_scale", VR_psd_lateral_scale}, {"psd_vertical_scale", VR_psd_vertical_scale},
        {"lambda_min", VR_lambda_min}, {"lambda_max", VR_lambda_max},
        {"period_length", VR_period_length}, {"grid_step", VR_grid_step},
        {"half_contact_width", VR_half_contact_width},
        {"harmonic_lateral_amplitude", VR_harmonic_lateral_amplitude},
        {"harmonic_vertical_amplitude", VR_harmonic_vertical_amplitude},
        {"harmonic_wavelength", VR_harmonic_wavelength}, {"harmonic_phase", VR_harmonic_phase},
        {"step_lateral", VR_step_lateral}, {"step_vertical", VR_step_vertical},
        {"step_position", VR_step_position}, {"profile_scale", VR_profile_scale},
        {"run_in_length", VR_run_in_length}};
    const double *r = m->r;
    size_t j;
    for (j = 0; j < sizeof reals / sizeof reals[0]; j++)
        CHECK(isfinite(r[reals[j].vr]), reals[j].name, r[reals[j].vr], "finite");
    CHECK(r[VR_V] >= 0, "V", r[VR_V], ">= 0");
    CHECK(m->i[VRI_psd_level] >= 0 && m->i[VRI_psd_level] <= 2, "psd_level", m->i[VRI_psd_level],
          "0, 1 or 2");
    CHECK(r[VR_psd_scale] >= 0, "psd_scale", r[VR_psd_scale], ">= 0");
    CHECK(r[VR_psd_lateral_scale] >= 0, "psd_lateral_scale", r[VR_psd_lateral_scale], ">= 0");
    CHECK(r[VR_psd_vertical_scale] >= 0, "psd_vertical_scale", r[VR_psd_vertical_scale], ">= 0");
    CHECK(r[VR_lambda_min] > 0, "lambda_min", r[VR_lambda_min], "> 0");
    if (!(r[VR_lambda_max] > r[VR_lambda_min])) {
        model_error(m, "parameter lambda_max = %g must be > lambda_min = %g", r[VR_lambda_max],
                    r[VR_lambda_min]);
        return -1;
    }
    CHECK(r[VR_period_length] > 0, "period_length", r[VR_period_length], "> 0");
    CHECK(r[VR_grid_step] > 0, "grid_step", r[VR_grid_step], "> 0");
    CHECK(r[VR_half_contact_width] > 0, "half_contact_width", r[VR_half_contact_width], "> 0");
    CHECK(r[VR_harmonic_wavelength] > 0, "harmonic_wavelength", r[VR_harmonic_wavelength], "> 0");
    CHECK(r[VR_run_in_length] >= 0, "run_in_length", r[VR_run_in_length], ">= 0");
    if (m->i[VRI_psd_level] != 0) {
        double k_lo, k_hi;
        line_range(r[VR_period_length], r[VR_lambda_min], r[VR_lambda_max], &k_lo, &k_hi);
        if (grid_size(r[VR_period_length], r[VR_grid_step], k_hi) == 0) {
            model_error(m, "parameter grid_step = %g with period_length = %g and lambda_min = %g "
                        "needs more than %ld grid points", r[VR_grid_step], r[VR_period_length],
                        r[VR_lambda_min], MAX_GRID_POINTS);
            return -1;
        }
    }
    return 0;
}

int model_initialize(ModelInstance *m) {
    if (build_tables(m) != 0) return -1;
    return model_outputs(m);
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m; (void)t; (void)x; (void)dx; /* no states */
}

int model_outputs(ModelInstance *m) {
    const TrackData *d = (const TrackData *)m->modelData;
    double *r = m->r;
    const double b = r[VR_half_contact_width];
    const double kh = 2.0 * PI / r[VR_harmonic_wavelength];
    const double Ay = r[VR_harmonic_lateral_amplitude], Az = r[VR_harmonic_vertical_amplitude];
    const double g = r[VR_profile_scale], run_in = r[VR_run_in_length];
    double speed, front, step_at; /* speed: v of the docs (v[] is taken below) */
    int i;
    if (!d) {
        model_error(m, "TrackIrregularity: outputs requested before initialisation");
        return -1;
    }
    if (m->b[VRB_distance_input]) {
        /* distance and speed as set at inputTime; read after a step, before new inputs,
           the distance is extrapolated with the speed (first-order hold) */
        const double tau = r[0] - m->inputTime;
        speed = r[VR_speed];
        front = r[VR_s_start] + (tau != 0.0 ? r[VR_distance] + speed * tau : r[VR_distance]);
    } else {
        speed = r[VR_V];
        front = r[VR_s_start] + speed * r[0];
    }
    /* a step within STEP_TOLERANCE of the last step's travel ahead is reached (model.h) */
    step_at = r[VR_step_position] - STEP_TOLERANCE * fabs(speed) * m->stepSize;
    r[VR_position] = front - r[VR_AXLE[0]];
    for (i = 0; i < N_WHEELSETS; i++) {
        const double s = front - r[VR_AXLE[i]];
        double v[3], dv[3], ali, ali_d, zl, zl_d, zr, zr_d;
        eval_random(d, s, v, dv);
        ali = v[0];
        ali_d = dv[0];
        zl = v[1] + b * v[2];
        zl_d = dv[1] + b * dv[2];
        zr = v[1] - b * v[2];
        zr_d = dv[1] - b * dv[2];
        {
            const double arg = kh * s + r[VR_harmonic_phase], sn = sin(arg), cs = cos(arg);
            ali += Ay * sn;
            ali_d += Ay * kh * cs;
            zl += Az * sn;
            zl_d += Az * kh * cs;
            zr += Az * sn;
            zr_d += Az * kh * cs;
        }
        if (s >= step_at) { /* the Dirac derivative of the step is ignored */
            ali += r[VR_step_lateral];
            zl += r[VR_step_vertical];
            zr += r[VR_step_vertical];
        }
        if (d->profile.n) {
            eval_profile(d, s, v, dv);
            ali += g * v[0];
            zl += g * v[1];
            zr += g * v[2];
            ali_d += g * dv[0];
            zl_d += g * dv[1];
            zr_d += g * dv[2];
        }
        if (run_in > 0.0) { /* the total deviation times w(s); slopes by the product rule */
            double w, w_d;
            run_in_weight(s, run_in, &w, &w_d);
            ali_d = w * ali_d + ali * w_d;
            zl_d = w * zl_d + zl * w_d;
            zr_d = w * zr_d + zr * w_d;
            ali = w * ali;
            zl = w * zl;
            zr = w * zr;
        }
        r[VR_ALIGNMENT[i]] = ali;
        r[VR_ALIGNMENT_RATE[i]] = speed * ali_d;
        r[VR_LEFT[i]] = zl;
        r[VR_RIGHT[i]] = zr;
        r[VR_LEFT_RATE[i]] = speed * zl_d;
        r[VR_RIGHT_RATE[i]] = speed * zr_d;
    }
    return 0;
}

/* The runtime drops modelData before restoring a state; the tables depend only on the
   restored parameters. */
int model_state_restored(ModelInstance *m) { return build_tables(m); }

void model_free(ModelInstance *m) {
    free_data((TrackData *)m->modelData);
    m->modelData = NULL;
}
