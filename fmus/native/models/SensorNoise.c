/* railfmu: SensorNoise, hand-written model code (the equations are in models/sources/sensors.py,
 * whose docstring is this model's documentation; tests/test_sensors.py proves this C equals
 * the Python bit for bit).
 *
 *   k   = floor((t - t0) / T + STEP_TOLERANCE min(h / T, 1))    T = sample_period
 *   y_i = gain_i u_i + bias_i + sigma_i w_i(k)      (y_i = u_i when enabled is false)
 *   y_i = gain_i u_i + bias_i exp(sigma_i (2 u2_i(k) - 1))   distribution_i = 1 (log-uniform)
 *   y_i = gain_i u_i + bias_i + sigma_i (2 u2_i(k) - 1)      distribution_i = 2 (uniform)
 *
 * w_i(k) is counter-based Gaussian white noise: a pure function of (seed, i, k) built from
 * the SplitMix64 output function and Box-Muller, so it needs no generator state (FMU state
 * get/set, any importer and any step size give the same noise) and no model data. h is the
 * communication step that ended at t (0 in initialisation mode): a sample instant within
 * STEP_TOLERANCE min(h, T) after t counts as reached, so k is the same whether the master
 * computes t = t0 + n h or accumulates t += h (model.h).
 *
 * The variable tables (model_real_info, ...) are generated from the Python definition into
 * a separate file; the VR_/VRI_/VRB_ defines come from the generated model_config.h.
 */
#include <math.h>
#include <stdint.h>

#include "model.h"
#include "rng.h"

#define N_CHANNELS 8
#define MAX_SAMPLE 9007199254740992.0 /* 2^53: sample indices stay exact doubles */


static const fmi2ValueReference VR_U[N_CHANNELS] = {VR_u_1, VR_u_2, VR_u_3, VR_u_4,
                                                    VR_u_5, VR_u_6, VR_u_7, VR_u_8};
static const fmi2ValueReference VR_Y[N_CHANNELS] = {VR_y_1, VR_y_2, VR_y_3, VR_y_4,
                                                    VR_y_5, VR_y_6, VR_y_7, VR_y_8};
static const fmi2ValueReference VR_SIGMA[N_CHANNELS] = {
    VR_sigma_1, VR_sigma_2, VR_sigma_3, VR_sigma_4, VR_sigma_5, VR_sigma_6, VR_sigma_7, VR_sigma_8};
static const fmi2ValueReference VR_GAIN[N_CHANNELS] = {
    VR_gain_1, VR_gain_2, VR_gain_3, VR_gain_4, VR_gain_5, VR_gain_6, VR_gain_7, VR_gain_8};
static const fmi2ValueReference VRI_DIST[N_CHANNELS] = {
    VRI_distribution_1, VRI_distribution_2, VRI_distribution_3, VRI_distribution_4,
    VRI_distribution_5, VRI_distribution_6, VRI_distribution_7, VRI_distribution_8};
static const fmi2ValueReference VR_BIAS[N_CHANNELS] = {
    VR_bias_1, VR_bias_2, VR_bias_3, VR_bias_4, VR_bias_5, VR_bias_6, VR_bias_7, VR_bias_8};

/* ---- model interface (model.h) ---- */

int model_check_parameters(ModelInstance *m) {
    const double *r = m->r;
    int j;
    for (j = 0; j < N_CHANNELS; j++) {
        const fmi2ValueReference vrs[3] = {VR_SIGMA[j], VR_GAIN[j], VR_BIAS[j]};
        int q;
        for (q = 0; q < 3; q++) {
            if (!isfinite(r[vrs[q]])) {
                model_error(m, "parameter %s = %g is not finite", model_real_info[vrs[q]].name,
                            r[vrs[q]]);
                return -1;
            }
        }
        if (!(r[VR_SIGMA[j]] >= 0)) {
            model_error(m, "parameter %s = %g must be >= 0", model_real_info[VR_SIGMA[j]].name,
                        r[VR_SIGMA[j]]);
            return -1;
        }
    }
    if (!(r[VR_sample_period] > 0) || !isfinite(r[VR_sample_period])) {
        model_error(m, "parameter sample_period = %g must be > 0 and finite", r[VR_sample_period]);
        return -1;
    }
    return 0;
}

int model_initialize(ModelInstance *m) {
    (void)m; /* nothing derived from parameters: the noise is a function of (seed, i, k) */
    return 0;
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m; (void)t; (void)x; (void)dx; /* no states */
}

int model_outputs(ModelInstance *m) {
    double *r = m->r;
    double T, kd;
    uint64_t k, seed;
    int j;
    if (!m->b[VRB_enabled]) {
        for (j = 0; j < N_CHANNELS; j++) r[VR_Y[j]] = r[VR_U[j]];
        return 0;
    }
    T = r[VR_sample_period];
    kd = floor((r[0] - m->startTime) / T + STEP_TOLERANCE * fmin(m->stepSize / T, 1.0));
    if (kd < 0) kd = 0; /* not before the start */
    if (!(kd < MAX_SAMPLE)) {
        model_error(m, "SensorNoise: t = %.17g is more than 2^53 samples of sample_period = %g "
                       "after the start",
                    r[0], r[VR_sample_period]);
        return -1;
    }
    k = (uint64_t)kd;
    seed = (uint64_t)(int64_t)m->i[VRI_seed]; /* two's complement, as the Python */
    for (j = 0; j < N_CHANNELS; j++) {
        const double sigma = r[VR_SIGMA[j]];
        if (m->i[VRI_DIST[j]] == 1) { /* log-uniform scatter of the bias: u2 of the stream */
            const double f = sigma != 0 ? exp(sigma * (2.0 * rng_uniform2(seed, (uint64_t)(j + 1), k) - 1.0))
                                        : 1.0;
            r[VR_Y[j]] = r[VR_GAIN[j]] * r[VR_U[j]] + r[VR_BIAS[j]] * f;
        } else if (m->i[VRI_DIST[j]] == 2) { /* uniform about the bias: the same u2 */
            const double d = sigma != 0 ? sigma * (2.0 * rng_uniform2(seed, (uint64_t)(j + 1), k) - 1.0) : 0.0;
            r[VR_Y[j]] = r[VR_GAIN[j]] * r[VR_U[j]] + r[VR_BIAS[j]] + d;
        } else {
            const double w = sigma != 0 ? rng_normal(seed, (uint64_t)(j + 1), k) : 0.0;
            r[VR_Y[j]] = r[VR_GAIN[j]] * r[VR_U[j]] + r[VR_BIAS[j]] + sigma * w;
        }
    }
    return 0;
}

int model_state_restored(ModelInstance *m) {
    (void)m; /* no model data */
    return 0;
}

void model_free(ModelInstance *m) {
    (void)m;
}
