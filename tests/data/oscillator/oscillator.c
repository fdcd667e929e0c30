/* Hand-written test model for the shared runtime (tests/test_runtime_c.py).
 *
 *   dx/dt = v
 *   dv/dt = -k x - c v + u(t),   u(t) = u + du (t - inputTime)  (first-order hold, du = rate of u)
 *   a     = dv/dt at the communication point
 *
 * Test hooks: nan_mode = 1 makes dv/dt NaN from t >= nan_time, nan_mode = 2 makes the output
 * a NaN from t >= nan_time; nan_mode = 3 ends the simulation (model_terminate) at the first
 * communication point t >= nan_time, nan_mode = 4 at nan_time itself (as a table without
 * states that ends inside a step would). data_path (calculated parameter) is data_file resolved with
 * model_resolve_path, so the test can check the resource location handling.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "model.h"

const VariableInfo model_real_info[N_REAL] = {
    [VR_time] = {"time", CAUSALITY_INDEPENDENT, VARIABILITY_CONTINUOUS},
    [VR_k] = {"k", CAUSALITY_PARAMETER, VARIABILITY_FIXED},
    [VR_c] = {"c", CAUSALITY_PARAMETER, VARIABILITY_TUNABLE},
    [VR_u] = {"u", CAUSALITY_INPUT, VARIABILITY_CONTINUOUS},
    [VR_du] = {"du", CAUSALITY_INPUT, VARIABILITY_CONTINUOUS},
    [VR_x] = {"x", CAUSALITY_OUTPUT, VARIABILITY_CONTINUOUS},
    [VR_v] = {"v", CAUSALITY_OUTPUT, VARIABILITY_CONTINUOUS},
    [VR_a] = {"a", CAUSALITY_OUTPUT, VARIABILITY_CONTINUOUS},
    [VR_integrator_step] = {"integrator_step", CAUSALITY_PARAMETER, VARIABILITY_FIXED},
    [VR_nan_time] = {"nan_time", CAUSALITY_PARAMETER, VARIABILITY_FIXED},
};
const fmi2Real model_real_start[N_REAL] = {
    [VR_time] = 0.0, [VR_k] = 4.0, [VR_c] = 0.4, [VR_u] = 0.0, [VR_du] = 0.0,
    [VR_x] = 1.0, [VR_v] = 0.0, [VR_a] = 0.0, [VR_integrator_step] = 1e-3,
    [VR_nan_time] = 1e30,
};

const VariableInfo model_integer_info[N_INTEGER] = {
    [VRI_nan_mode] = {"nan_mode", CAUSALITY_PARAMETER, VARIABILITY_FIXED},
};
const fmi2Integer model_integer_start[N_INTEGER] = {[VRI_nan_mode] = 0};

const VariableInfo model_boolean_info[N_BOOLEAN] = {
    [VRB_damping_on] = {"damping_on", CAUSALITY_PARAMETER, VARIABILITY_TUNABLE},
};
const fmi2Boolean model_boolean_start[N_BOOLEAN] = {[VRB_damping_on] = fmi2True};

const VariableInfo model_string_info[N_STRING] = {
    [VRS_data_file] = {"data_file", CAUSALITY_PARAMETER, VARIABILITY_FIXED},
    [VRS_data_path] = {"data_path", CAUSALITY_CALCULATED_PARAMETER, VARIABILITY_FIXED},
};
const char *const model_string_start[N_STRING] = {
    [VRS_data_file] = "table.csv",
    [VRS_data_path] = "",
};

const fmi2ValueReference model_state_vrs[N_STATES] = {VR_x, VR_v};

/* model-owned data derived from parameters (here: a copy of the resolved path) */
typedef struct {
    char *path;
} OscData;

int model_check_parameters(ModelInstance *m) {
    if (!(m->r[VR_k] >= 0.0)) {
        model_error(m, "parameter k = %g is below its minimum 0", m->r[VR_k]);
        return 1;
    }
    if (!(m->r[VR_c] >= 0.0)) {
        model_error(m, "parameter c = %g is below its minimum 0", m->r[VR_c]);
        return 1;
    }
    return 0;
}

static double damping(const ModelInstance *m) { return m->b[VRB_damping_on] ? m->r[VR_c] : 0.0; }

static int build_data(ModelInstance *m) {
    OscData *d = (OscData *)calloc(1, sizeof *d);
    char *p;
    if (!d) return 1;
    d->path = model_resolve_path(m, m->s[VRS_data_file]);
    m->modelData = d;
    /* strings in s[] are owned by the runtime and released with free() */
    p = (char *)malloc(d->path ? strlen(d->path) + 1 : 1);
    if (!p) return 1;
    strcpy(p, d->path ? d->path : "");
    free(m->s[VRS_data_path]);
    m->s[VRS_data_path] = p;
    return 0;
}

int model_initialize(ModelInstance *m) {
    if (build_data(m)) return 1;
    return 0; /* the runtime calls model_outputs next */
}

void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    const double u = m->r[VR_u] + m->r[VR_du] * (t - m->inputTime);
    dx[0] = x[1];
    dx[1] = -m->r[VR_k] * x[0] - damping(m) * x[1] + u;
    if (m->i[VRI_nan_mode] == 1 && t >= m->r[VR_nan_time]) dx[1] = NAN;
}

int model_outputs(ModelInstance *m) {
    const double u = m->r[VR_u] + m->r[VR_du] * (m->r[VR_time] - m->inputTime);
    m->r[VR_a] = -m->r[VR_k] * m->r[VR_x] - damping(m) * m->r[VR_v] + u;
    if (m->i[VRI_nan_mode] == 2 && m->r[VR_time] >= m->r[VR_nan_time]) m->r[VR_a] = NAN;
    if (m->i[VRI_nan_mode] == 3 && m->r[VR_time] >= m->r[VR_nan_time])
        model_terminate(m, m->r[VR_time], "oscillator: t = %g reached nan_time", m->r[VR_time]);
    if (m->i[VRI_nan_mode] == 4 && m->r[VR_time] >= m->r[VR_nan_time])
        model_terminate(m, m->r[VR_nan_time], NULL);
    return 0;
}

int model_state_restored(ModelInstance *m) { return build_data(m); }

void model_free(ModelInstance *m) {
    OscData *d = (OscData *)m->modelData;
    if (d) {
        free(d->path);
        free(d);
    }
    m->modelData = NULL;
}
