/* GnssReceiver: position and speed fixes every sample_period (models/train/gnss.py states the
 * measurement equation and is this code's Python twin; tests/test_gnss.py proves them equal).
 * Stateless: every output is a function of the time, the step that reached it and the inputs,
 * so a get after a set, a restored FMU state or any importer give the same fixes.
 */
#include <math.h>
#include <stdint.h>

#include "model.h"
#include "rng.h"

#define MAX_SAMPLE 9007199254740992.0 /* 2^53 */


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
                                               rng_normal((uint64_t)(int64_t)m->i[VRI_seed], 1u, (uint64_t)k)
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
