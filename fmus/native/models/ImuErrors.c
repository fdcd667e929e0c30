/* ImuErrors: measured IMU increments from ideal ones (models/inertial/imu_errors.py states the error
 * model, the exact Gauss-Markov discretisation and the noise streams, and is this code's Python
 * twin; tests/test_imu_errors.py proves them equal bit for bit).
 *
 *   y_i = u_i + s_i u_i + sum_{j != i} m_ij u_j + b_on,i h + int_h b_i dt + N sqrt(h) w_i(k)
 *
 * per axis of the gyro triad (u = dtheta_in, rad) and the accelerometer triad (u = dv_in, m/s).
 * The Gauss-Markov states at t and at the previous communication point are outputs (memory,
 * kept by fmi2GetFMUstate); the constants drawn from the seed (turn-on bias, scale factor,
 * misalignment, state at t0) live in modelData, rebuilt from the parameters.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "model.h"
#include "rng.h"

#define MAX_SAMPLE 9007199254740992.0 /* 2^53: sample indices stay exact doubles */
#define SERIES_BELOW 0.5
#define SERIES_TERMS 30

static const double PI = 3.14159265358979323846; /* == Python's math.pi */
static const double G0 = 9.80665;                   /* m/s2: the g of datasheets */
static const double GM_SIGMA_PER_B = 1.0759975729152142; /* FLICKER_FLOOR / GM_ALLAN_PEAK */
enum { STREAM_WHITE = 4096, STREAM_ETA = 4112, STREAM_ZETA = 4128, STREAM_CONST = 4144 };
enum { K_GM0 = 0, K_TURN_ON = 1, K_SCALE = 2, K_MISALIGNMENT = 3 };

/* the value references of one sensor triad */
typedef struct {
    fmi2ValueReference in[3], out[3], bias[3], gm[3], gm_before[3];
    fmi2ValueReference noise, instability, tc, on_sigma, on[3], sf_sigma, sf[3], mis_sigma;
    fmi2ValueReference mis[3][3]; /* [i][j], i != j */
} Triad;

static const Triad TRIADS[2] = {
    {{VR_dtheta_in_x, VR_dtheta_in_y, VR_dtheta_in_z},
     {VR_dtheta_x, VR_dtheta_y, VR_dtheta_z},
     {VR_gyro_bias_x, VR_gyro_bias_y, VR_gyro_bias_z},
     {VR_gyro_in_run_bias_x, VR_gyro_in_run_bias_y, VR_gyro_in_run_bias_z},
     {VR_gyro_in_run_bias_before_x, VR_gyro_in_run_bias_before_y, VR_gyro_in_run_bias_before_z},
     VR_gyro_arw_deg_sqrt_h, VR_gyro_bias_instability_deg_h, VR_gyro_bias_correlation_time,
     VR_gyro_turn_on_bias_sigma_deg_h,
     {VR_gyro_turn_on_bias_x_deg_h, VR_gyro_turn_on_bias_y_deg_h, VR_gyro_turn_on_bias_z_deg_h},
     VR_gyro_scale_factor_sigma_ppm,
     {VR_gyro_scale_factor_x_ppm, VR_gyro_scale_factor_y_ppm, VR_gyro_scale_factor_z_ppm},
     VR_gyro_misalignment_sigma_urad,
     {{0, VR_gyro_misalignment_xy_urad, VR_gyro_misalignment_xz_urad},
      {VR_gyro_misalignment_yx_urad, 0, VR_gyro_misalignment_yz_urad},
      {VR_gyro_misalignment_zx_urad, VR_gyro_misalignment_zy_urad, 0}}},
    {{VR_dv_in_x, VR_dv_in_y, VR_dv_in_z},
     {VR_dv_x, VR_dv_y, VR_dv_z},
     {VR_accel_bias_x, VR_accel_bias_y, VR_accel_bias_z},
     {VR_accel_in_run_bias_x, VR_accel_in_run_bias_y, VR_accel_in_run_bias_z},
     {VR_accel_in_run_bias_before_x, VR_accel_in_run_bias_before_y, VR_accel_in_run_bias_before_z},
     VR_accel_noise_ug_sqrt_hz, VR_accel_bias_instability_ug, VR_accel_bias_correlation_time,
     VR_accel_turn_on_bias_sigma_ug,
     {VR_accel_turn_on_bias_x_ug, VR_accel_turn_on_bias_y_ug, VR_accel_turn_on_bias_z_ug},
     VR_accel_scale_factor_sigma_ppm,
     {VR_accel_scale_factor_x_ppm, VR_accel_scale_factor_y_ppm, VR_accel_scale_factor_z_ppm},
     VR_accel_misalignment_sigma_urad,
     {{0, VR_accel_misalignment_xy_urad, VR_accel_misalignment_xz_urad},
      {VR_accel_misalignment_yx_urad, 0, VR_accel_misalignment_yz_urad},
      {VR_accel_misalignment_zx_urad, VR_accel_misalignment_zy_urad, 0}}},
};

/* the constants drawn from the seed, in SI, per axis a = 0..5 (gyro x, y, z, accel x, y, z) */
typedef struct {
    double turn_on[6], scale[6], mis[6][3], gm0[6], sigma_b[6];
    double noise_si[2], tc[2]; /* per triad */
} Constants;

/* the noise: rng_normal, as railfmu.models.inertial.imu_errors.gauss */
/* datasheet unit -> SI: (noise density, bias) of triad s */
static double noise_si(int s) { return s == 0 ? PI / 180.0 / 60.0 : 1e-6 * G0; }
static double bias_si(int s) { return s == 0 ? PI / 180.0 / 3600.0 : 1e-6 * G0; }

/* ---- the Gauss-Markov bias over one step (railfmu.models.inertial.imu_errors.gm_f, gm_step) ---- */

/* f(x) = x - 2 (1 - e^-x) + (1 - e^-2x) / 2, summed as its series below SERIES_BELOW */
static double gm_f(double x) {
    double term, p, s, sign;
    int n;
    if (x >= SERIES_BELOW) {
        const double e = expm1(-x);
        return x + e - 0.5 * e * e;
    }
    term = x * x * x / 6.0;
    p = 4.0;
    s = 0.0;
    sign = 1.0;
    for (n = 3; n < 3 + SERIES_TERMS; n++) {
        s += sign * (p - 2.0) * term;
        term *= x / (double)(n + 1);
        p *= 2.0;
        sign = -sign;
    }
    return s;
}

typedef struct {
    double beta, a, s_eta, gain, s_zeta;
} GmStep;

static GmStep gm_step(double h, double tc, double sigma) {
    GmStep g;
    const double x = h / tc, e = expm1(-x), om = -e;
    const double schur = 2.0 * gm_f(x) - om * om * om / (2.0 - om);
    g.beta = 1.0 + e;
    g.s_eta = sigma * sqrt(om * (2.0 - om));
    g.gain = tc * om / (2.0 - om);
    g.s_zeta = sigma * tc * sqrt(schur > 0.0 ? schur : 0.0);
    g.a = tc * om;
    return g;
}

/* ---- model interface (model.h) ---- */

int model_check_parameters(ModelInstance *m) {
    const double *r = m->r;
    size_t k;
    int s, i;
    for (k = 0; k < N_REAL; k++) {
        if (model_real_info[k].causality == CAUSALITY_PARAMETER && !isfinite(r[k])) {
            model_error(m, "parameter %s = %g is not finite", model_real_info[k].name, r[k]);
            return 1;
        }
    }
    for (s = 0; s < 2; s++) {
        const Triad *T = &TRIADS[s];
        const fmi2ValueReference nonneg[5] = {T->noise, T->instability, T->on_sigma, T->sf_sigma,
                                              T->mis_sigma};
        for (i = 0; i < 5; i++) {
            if (!(r[nonneg[i]] >= 0)) {
                model_error(m, "parameter %s = %g must be >= 0", model_real_info[nonneg[i]].name,
                            r[nonneg[i]]);
                return 1;
            }
        }
        if (!(r[T->tc] > 0)) {
            model_error(m, "parameter %s = %g must be > 0", model_real_info[T->tc].name, r[T->tc]);
            return 1;
        }
    }
    return 0;
}

int model_initialize(ModelInstance *m) {
    const double *r = m->r;
    const uint64_t seed = (uint64_t)(int64_t)m->i[VRI_seed]; /* two's complement, as the Python */
    Constants *c;
    int s, i, j;
    model_free(m);
    c = (Constants *)calloc(1, sizeof(Constants));
    if (!c) {
        model_error(m, "ImuErrors: out of memory");
        return 1;
    }
    for (s = 0; s < 2; s++) {
        const Triad *T = &TRIADS[s];
        const double bsi = bias_si(s);
        const double sigma_b = GM_SIGMA_PER_B * (r[T->instability] * bsi);
        c->noise_si[s] = r[T->noise] * noise_si(s);
        c->tc[s] = r[T->tc];
        for (i = 0; i < 3; i++) {
            const int a = 3 * s + i;
            const unsigned stream = STREAM_CONST + (unsigned)a + 1;
            c->turn_on[a] = (r[T->on[i]] + r[T->on_sigma] * rng_normal(seed, stream, K_TURN_ON)) * bsi;
            c->scale[a] = (r[T->sf[i]] + r[T->sf_sigma] * rng_normal(seed, stream, K_SCALE)) * 1e-6;
            for (j = 0; j < 3; j++) {
                c->mis[a][j] = j == i ? 0.0
                                      : (r[T->mis[i][j]] +
                                         r[T->mis_sigma] * rng_normal(seed, stream, (uint64_t)(K_MISALIGNMENT + j))) *
                                            1e-6;
            }
            c->sigma_b[a] = sigma_b;
            c->gm0[a] = sigma_b * rng_normal(seed, stream, K_GM0);
        }
    }
    m->modelData = c;
    return 0;
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m, (void)t, (void)x, (void)dx; /* no continuous states */
}

int model_outputs(ModelInstance *m) {
    double *r = m->r;
    const Constants *c = (const Constants *)m->modelData;
    const double h = m->stepSize;
    const uint64_t seed = (uint64_t)(int64_t)m->i[VRI_seed];
    uint64_t k = 0;
    int s, i, j;
    if (h > 0) {
        if (r[0] != r[VR_sample_time]) { /* a new communication point: advance the memory */
            const double kd = floor((r[0] - m->startTime) / h + STEP_TOLERANCE);
            if (!(kd < MAX_SAMPLE)) {
                model_error(m, "ImuErrors: t = %.17g is more than 2^53 steps of %g s after the start", r[0], h);
                return -1;
            }
            if (!(kd > (double)m->i[VRI_sample])) {
                model_error(m, "ImuErrors: the communication step grew to %g s at t = %.17g: the sample "
                               "index %.0f would repeat a used noise sample (use a constant step)",
                            h, r[0], kd);
                return -1;
            }
            for (s = 0; s < 2; s++)
                for (i = 0; i < 3; i++) r[TRIADS[s].gm_before[i]] = r[TRIADS[s].gm[i]];
            m->i[VRI_sample] = (fmi2Integer)kd;
            r[VR_sample_time] = r[0];
        }
        k = (uint64_t)m->i[VRI_sample];
    } else { /* initialisation mode: the state at t0, no step yet */
        for (s = 0; s < 2; s++)
            for (i = 0; i < 3; i++) r[TRIADS[s].gm[i]] = r[TRIADS[s].gm_before[i]] = c->gm0[3 * s + i];
        m->i[VRI_sample] = 0;
        r[VR_sample_time] = r[0];
    }
    for (s = 0; s < 2; s++) {
        const Triad *T = &TRIADS[s];
        const double s_white = h > 0 ? c->noise_si[s] * sqrt(h) : 0.0;
        /* the three axes of a triad share sigma_b and Tc */
        const GmStep g = h > 0 ? gm_step(h, c->tc[s], c->sigma_b[3 * s]) : (GmStep){0, 0, 0, 0, 0};
        for (i = 0; i < 3; i++) {
            const int a = 3 * s + i;
            const unsigned ax = (unsigned)a + 1;
            const double u = r[T->in[i]];
            double err = c->scale[a] * u;
            for (j = 0; j < 3; j++)
                if (j != i) err = err + c->mis[a][j] * r[T->in[j]];
            if (h > 0) {
                const double b = r[T->gm_before[i]];
                double eta, integral;
                const double w1 = c->sigma_b[a] != 0 ? rng_normal(seed, STREAM_ETA + ax, k) : 0.0;
                const double w2 = c->sigma_b[a] != 0 ? rng_normal(seed, STREAM_ZETA + ax, k) : 0.0;
                const double ws = c->noise_si[s] != 0 ? rng_normal(seed, STREAM_WHITE + ax, k) : 0.0;
                eta = g.s_eta * w1;
                integral = g.a * b + g.gain * eta + g.s_zeta * w2;
                err = err + c->turn_on[a] * h + integral + s_white * ws;
                r[T->gm[i]] = g.beta * b + eta;
            }
            r[T->out[i]] = err != 0.0 ? u + err : u; /* all errors zero: the input bit for bit */
            r[T->bias[i]] = c->turn_on[a] + r[T->gm[i]];
        }
    }
    return 0;
}

int model_state_restored(ModelInstance *m) {
    /* the drawn constants are a function of the restored parameters and seed */
    return model_initialize(m);
}

void model_free(ModelInstance *m) {
    free(m->modelData);
    m->modelData = NULL;
}
