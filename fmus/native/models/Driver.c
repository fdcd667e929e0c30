/* Driver: manual driving of one interstation run as Cunillera et al. (2022) §4 describes it
 * (models/train/driver.py states the rules, the modes and the style draw, and is this code's Python
 * twin; tests/test_driver.py proves them equal).
 *
 * The memory of the driver is in its outputs (so fmi2GetFMUstate saves it): `mode` decided
 * at the current communication point, `mode_before` the mode of the previous one and
 * `decision_time` the point it was decided at. A get after a set at the same point decides
 * again from `mode_before`: the decision is a function of that point's inputs only.
 */
#include <math.h>
#include <stdint.h>

#include "LineProfile.h"
#include "model.h"
#include "rng.h"

enum { WAIT, ACCELERATE, HOLD, CYCLE_TRACTION, CYCLE_COAST, COAST, BRAKE_LIMIT, BRAKE_STOP, STOPPED };
static const int REGIME[] = {0, 1, 2, 1, 3, 3, 4, 4, 0};

#define KMH (1.0 / 3.6)
#define ANTICIPATION 2.0 /* s */
#define CYCLE_BAND_LOW (5.0 * KMH)
#define DWELL_TOLERANCE 1e-6 /* s */
/* the j-th uniform in [0, 1) of the seed: output j + 1 of SplitMix64(seed) */
static double uniform(fmi2Integer seed, unsigned j) { return rng_uniform_at((uint64_t)(int64_t)seed, j); }

static void draw_style(ModelInstance *m) {
    const fmi2Integer seed = m->i[VRI_seed];
    double *r = m->r;
    r[VR_cruise_target] = (120.0 + 20.0 * uniform(seed, 0)) * KMH;
    r[VR_coasting_point] = ((LineProfile *)m->modelData)->position[((LineProfile *)m->modelData)->n - 1] -
                           (5000.0 + 9000.0 * uniform(seed, 1));
    r[VR_traction_fraction] = 0.7 + 0.3 * uniform(seed, 2);
    m->b[VRB_cycles] = uniform(seed, 3) < 0.5;
    r[VR_brake_rate_1] = 0.30 + 0.15 * uniform(seed, 4);
    r[VR_brake_rate_2] = 0.30 + 0.15 * uniform(seed, 5);
    r[VR_brake_rate_3] = 0.40 + 0.15 * uniform(seed, 6);
    r[VR_brake_rate_4] = 0.40 + 0.15 * uniform(seed, 7);
    r[VR_brake_rate_5] = 0.45 + 0.25 * uniform(seed, 8);
}

/* ATB-EG speed steps: > 130, 130-80, 80-60, 60-40, < 40 km/h */
static const double STEP_LOW[5] = {130.0 * KMH, 80.0 * KMH, 60.0 * KMH, 40.0 * KMH, 0.0};

static double rate(const ModelInstance *m, int k) { return m->r[VR_brake_rate_1 + k]; }

static double brake_rate_at(const ModelInstance *m, double v) {
    int k;
    for (k = 0; k < 4; k++)
        if (v > STEP_LOW[k]) return rate(m, k);
    return rate(m, 4);
}

/* distance (m) to brake from v to vt (m/s) at the style's rate in each speed step */
static double brake_distance(const ModelInstance *m, double v, double vt) {
    double d = 0.0, hi = HUGE_VAL;
    int k;
    for (k = 0; k < 5; k++) {
        const double a = v < hi ? v : hi, b = vt > STEP_LOW[k] ? vt : STEP_LOW[k];
        if (a > b) d += (a * a - b * b) / (2.0 * rate(m, k));
        hi = STEP_LOW[k];
    }
    return d;
}

/* rho = braking distance / distance left, largest over the lower limits ahead (*limit) and
   the stop at the line's end (*stop) */
static void braking_need(ModelInstance *m, double s, double v, double *limit, double *stop) {
    const LineProfile *p = (const LineProfile *)m->modelData;
    const double L = p->position[p->n - 1];
    size_t j;
    *limit = 0.0;
    *stop = 0.0;
    if (!(v > 0)) return;
    for (j = 0; j + 1 < p->n; j++) {
        if (p->position[j] > s && v > p->limit[j] + 0.05) {
            /* reaching the limit ANTICIPATION s before its start covers the driver's and the
               master's delay */
            const double left = p->position[j] - s - ANTICIPATION * v;
            const double rho = left > 0.01 ? brake_distance(m, v, p->limit[j]) / left : 1e6;
            if (rho > *limit) *limit = rho;
        }
    }
    *stop = L - s > 0.01 ? brake_distance(m, v, 0.0) / (L - s) : 1e6;
}

static int cruise_mode(const ModelInstance *m) { return m->b[VRB_cycles] ? CYCLE_COAST : HOLD; }

static int decide(ModelInstance *m, int before, double s, double v, double limit) {
    double rl, rs;
    const double target = m->r[VR_cruise_target] < limit ? m->r[VR_cruise_target] : limit;
    const int past_coast = s >= m->r[VR_coasting_point];
    if (before == STOPPED) return STOPPED;
    if (before == BRAKE_STOP) return v > 0 ? BRAKE_STOP : STOPPED;
    braking_need(m, s, v, &rl, &rs);
    if (rs >= 1.0) return BRAKE_STOP;
    if (before == BRAKE_LIMIT) {
        if (rl >= 0.1) return BRAKE_LIMIT; /* until the limit is reached */
        return past_coast ? COAST : cruise_mode(m);
    }
    if (rl >= 1.0) return BRAKE_LIMIT;
    switch (before) {
    case WAIT:
        return ACCELERATE;
    case ACCELERATE:
        if (past_coast) return COAST;
        if (v >= m->r[VR_cruise_target] - 1.0 * KMH && limit >= m->r[VR_cruise_target])
            return m->b[VRB_cycles] ? CYCLE_TRACTION : HOLD;
        return ACCELERATE;
    case HOLD:
        return past_coast ? COAST : HOLD;
    case CYCLE_TRACTION:
        if (past_coast) return COAST;
        return v >= target + 2.0 * KMH ? CYCLE_COAST : CYCLE_TRACTION;
    case CYCLE_COAST:
        if (past_coast) return COAST;
        return v <= target - CYCLE_BAND_LOW ? CYCLE_TRACTION : CYCLE_COAST;
    default:
        return COAST;
    }
}

static double clip(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

static double command(ModelInstance *m, int mode, double s, double v, double limit) {
    const double target = m->r[VR_cruise_target] < limit ? m->r[VR_cruise_target] : limit;
    const double bmax = m->r[VR_max_deceleration];
    double rl, rs, gentle;
    switch (mode) {
    case ACCELERATE:
        gentle = clip(0.3 + 0.7 * v / (10.0 * KMH), 0.0, 1.0);
        /* traction reduced to reach a limit below the cruise target (the 40 km/h zone) */
        if (limit < m->r[VR_cruise_target]) gentle *= clip((target - v) / (5.0 * KMH), 0.0, 1.0);
        return m->r[VR_traction_fraction] * gentle;
    case HOLD:
        return clip((target - v) / KMH, 0.0, 1.0);
    case CYCLE_TRACTION:
        return m->r[VR_traction_fraction];
    case BRAKE_LIMIT:
    case BRAKE_STOP:
        braking_need(m, s, v, &rl, &rs);
        if (mode == BRAKE_LIMIT && rl < 1.0) rl = 1.0; /* at least the step's rate: under the
                                                          limit by its start */
        if (mode == BRAKE_STOP && rl < rs) rl = rs;
        return -clip(brake_rate_at(m, v) * rl, 0.0, bmax) / bmax;
    case STOPPED:
        return -clip(rate(m, 4), 0.0, bmax) / bmax;
    default:
        return 0.0;
    }
}

int model_check_parameters(ModelInstance *m) {
    if (!(m->r[VR_max_deceleration] > 0) || !isfinite(m->r[VR_max_deceleration])) {
        model_error(m, "parameter max_deceleration = %g must be > 0 and finite", m->r[VR_max_deceleration]);
        return 1;
    }
    return 0;
}

static int load(ModelInstance *m) {
    model_free(m);
    m->modelData = line_load(m, m->s[VRS_line_file] ? m->s[VRS_line_file] : "");
    return m->modelData ? 0 : 1;
}

int model_initialize(ModelInstance *m) {
    if (load(m)) return 1;
    draw_style(m);
    m->r[VR_stop_position] = ((LineProfile *)m->modelData)->position[((LineProfile *)m->modelData)->n - 1];
    return 0;
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m, (void)t, (void)x, (void)dx;
}

int model_outputs(ModelInstance *m) {
    double *r = m->r;
    const double s = r[VR_s], v = r[VR_v], limit = r[VR_speed_limit];
    int mode;
    if (r[0] != r[VR_decision_time]) { /* a new communication point */
        m->i[VRI_mode_before] = m->i[VRI_mode];
        r[VR_decision_time] = r[0];
    }
    mode = decide(m, (int)m->i[VRI_mode_before], s, v, limit);
    m->i[VRI_mode] = mode;
    m->i[VRI_regime] = REGIME[mode];
    r[VR_command] = command(m, mode, s, v, limit);
    if (mode == STOPPED && m->i[VRI_mode_before] != STOPPED) r[VR_stop_time] = r[0];
    if (mode == STOPPED && r[0] - r[VR_stop_time] >= r[VR_dwell_time] - DWELL_TOLERANCE)
        model_terminate(m, r[0], "Driver: stopped at s = %.3f m (stopping point %.3f m) at t = %.3f s",
                        s, r[VR_stop_position], r[VR_stop_time]);
    return 0;
}

int model_state_restored(ModelInstance *m) { return load(m); }

void model_free(ModelInstance *m) {
    line_free((LineProfile *)m->modelData);
    m->modelData = NULL;
}
