/* TrainLongitudinal: the train motion model of Cunillera et al. (2022), eqs. 1-2, with the
 * gradient from a line profile CSV (models/train/longitudinal.py states the equations and is
 * this code's Python twin; tests/test_train.py proves them equal).
 */
#include <math.h>

#include "LineProfile.h"
#include "model.h"

#define G0 9.80665 /* m/s2 */

static double clip(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

static double mass(const ModelInstance *m) { /* m_tare + load_factor m_load (kg) */
    return m->r[VR_tare_mass] + m->r[VR_load_factor] * m->r[VR_load_mass];
}

static double effective_mass(const ModelInstance *m) { /* gamma m (kg) */
    return m->r[VR_rotating_mass_factor] * mass(m);
}

/* The efforts at speed v (m/s) for the command held over the step: traction force (N) and
   mass-specific brake effort (N/kg). */
static void efforts(const ModelInstance *m, double v, double *Ft, double *fb) {
    const double u = clip(m->r[VR_command], -1.0, 1.0);
    const double vp = v > 0 ? v : 0.0;
    double avail = m->r[VR_max_traction_force];
    if (vp * avail > m->r[VR_max_power]) avail = m->r[VR_max_power] / vp;
    *Ft = u > 0 ? u * avail : 0.0;
    *fb = u < 0 ? -u * m->r[VR_max_deceleration] : 0.0;
}

static double gradient_term(ModelInstance *m, double s) { /* g(s): gradient + curve, N/kg */
    LineProfile *p = (LineProfile *)m->modelData;
    const size_t k = line_row(p, s);
    return G0 * (p->gradient[k] / 1000.0 + p->curve[k]) / m->r[VR_rotating_mass_factor];
}

/* The applied mass-specific effort f_t - f_b (N/kg) at speed v: effort_set where
   use_effort_set is true (a process model's known input), else the command's. */
static double applied(const ModelInstance *m, double v) {
    double Ft, fb;
    if (m->b[VRB_use_effort_set]) return m->r[VR_effort_set];
    efforts(m, v, &Ft, &fb);
    return Ft / effective_mass(m) - fb;
}

static double accel(ModelInstance *m, double s, double v) {
    double r;
    const double g = gradient_term(m, s), e = applied(m, v);
    if (v > 0) {
        r = m->r[VR_r0] + m->r[VR_r1] * v + m->r[VR_r2] * v * v;
        return e - r - g;
    }
    /* at rest the brakes and the static resistance r0 hold the train: it starts only when
       the net force is forward */
    r = e - m->r[VR_r0] - g;
    return r > 0 ? r : 0.0;
}

/* the load factor is an input (no parameter check at a set): a step refuses a negative one */
static int check_load_factor(ModelInstance *m) {
    if (!(m->r[VR_load_factor] >= 0)) {
        model_error(m, "input load_factor = %g must be >= 0", m->r[VR_load_factor]);
        return 1;
    }
    return 0;
}

int model_check_parameters(ModelInstance *m) {
    static const fmi2ValueReference pos[] = {VR_tare_mass, VR_rotating_mass_factor,
                                             VR_max_traction_force, VR_max_power,
                                             VR_max_deceleration};
    size_t k;
    for (k = 0; k < sizeof pos / sizeof pos[0]; k++)
        if (!(m->r[pos[k]] > 0) || !isfinite(m->r[pos[k]])) {
            model_error(m, "parameter %s = %g must be > 0 and finite", model_real_info[pos[k]].name,
                        m->r[pos[k]]);
            return 1;
        }
    if (!(m->r[VR_load_mass] >= 0)) {
        model_error(m, "parameter load_mass = %g must be >= 0", m->r[VR_load_mass]);
        return 1;
    }
    return 0;
}

static int load(ModelInstance *m) {
    model_free(m);
    m->modelData = line_load(m, m->s[VRS_line_file] ? m->s[VRS_line_file] : "");
    return m->modelData ? 0 : 1;
}

int model_initialize(ModelInstance *m) { return load(m); }

/* set_state: the step starts from (s_set, v_set), a process model's sigma point (the runtime
   refuses non-finite inputs when they are set) */
int model_step_begin(ModelInstance *m) {
    if (check_load_factor(m) != 0) return 1;
    if (m->b[VRB_set_state]) {
        m->r[VR_s] = m->r[VR_s_set];
        m->r[VR_v] = m->r[VR_v_set];
    }
    return 0;
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = x[1] > 0 ? x[1] : 0.0; /* ds/dt = v */
    dx[1] = accel(m, x[0], x[1]);
}

int model_outputs(ModelInstance *m) {
    LineProfile *p = (LineProfile *)m->modelData;
    double Ft, fb, v;
    size_t k;
    /* an RK4 step that brakes through v = 0 ends slightly below it: the train stands */
    if (m->r[VR_v] < 0) m->r[VR_v] = 0.0;
    v = m->r[VR_v];
    k = line_row(p, m->r[VR_s]);
    efforts(m, v, &Ft, &fb);
    m->r[VR_acceleration] = accel(m, m->r[VR_s], v);
    m->r[VR_effort] = Ft - fb * effective_mass(m);
    m->r[VR_effort_specific] = Ft / effective_mass(m) - fb;
    if (m->b[VRB_use_effort_set]) {
        m->r[VR_effort] = m->r[VR_effort_set] * effective_mass(m);
        m->r[VR_effort_specific] = m->r[VR_effort_set];
    }
    m->r[VR_power] = m->r[VR_effort] * v;
    m->r[VR_resistance_specific] = m->r[VR_r0] + m->r[VR_r1] * v + m->r[VR_r2] * v * v;
    m->r[VR_gradient] = p->gradient[k];
    m->r[VR_gradient_specific] = gradient_term(m, m->r[VR_s]);
    m->r[VR_speed_limit] = p->limit[k];
    m->r[VR_mass] = mass(m);
    return 0;
}

int model_state_restored(ModelInstance *m) { return load(m); }

void model_free(ModelInstance *m) {
    line_free((LineProfile *)m->modelData);
    m->modelData = NULL;
}
