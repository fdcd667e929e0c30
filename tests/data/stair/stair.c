/* stair: a self-contained FMI 2.0 co-simulation test FMU (no railfmu runtime), like the
 * Modelica Reference-FMUs' Stair, for the masters' Integer/Boolean signals and FMI status
 * handling (tests/test_signals.py).
 *
 *   counter = floor(t)           Integer output, steps every second
 *   level   = counter            Real output
 *   sum     = counter + offset   Integer output; offset an Integer input
 *   odd     = counter is odd     Boolean output
 *   gated   = odd and enable     Boolean output; enable a Boolean input
 *   y       = u                  Real output; u a Real input
 *
 * fmi2DoStep(t, h) returns fmi2Discard with fmi2GetBooleanStatus(fmi2Terminated) = true once
 * t + h passes stop_time (the step is not taken), fmi2Error once it passes error_time and
 * fmi2Discard (not terminated) once it passes discard_time; the last two log nothing, so a
 * master must name the status itself.
 */

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

enum { R_STOP_TIME, R_ERROR_TIME, R_DISCARD_TIME, R_LEVEL, R_U, R_Y, N_REAL };
enum { I_COUNTER, I_OFFSET, I_SUM, N_INTEGER };
enum { B_ODD, B_ENABLE, B_GATED, N_BOOLEAN };

typedef struct {
    double r[N_REAL];
    int i[N_INTEGER];
    int b[N_BOOLEAN];
    double time;
    int terminated;
    fmi2CallbackFunctions cb;
    char name[64];
} Stair;

static void update(Stair *s)
{
    s->i[I_COUNTER] = (int)floor(s->time + 1e-9);
    s->r[R_LEVEL] = s->i[I_COUNTER];
    s->i[I_SUM] = s->i[I_COUNTER] + s->i[I_OFFSET];
    s->b[B_ODD] = s->i[I_COUNTER] % 2 != 0;
    s->b[B_GATED] = s->b[B_ODD] && s->b[B_ENABLE];
    s->r[R_Y] = s->r[R_U];
}

static int past(double t, double limit)
{
    return limit >= 0 && t > limit + 1e-9;
}

/* -- inquire, instantiate, free ---------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[])
{
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    Stair *s;
    (void)resources; (void)visible; (void)loggingOn;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, "{c3a1f0d2-railfmu-test-stair-0001}") != 0)
        return NULL;
    s = (Stair *)calloc(1, sizeof(Stair));
    if (!s) return NULL;
    if (functions) s->cb = *functions;
    strncpy(s->name, name ? name : "stair", sizeof(s->name) - 1);
    s->r[R_STOP_TIME] = 9.0;
    s->r[R_ERROR_TIME] = -1.0;
    s->r[R_DISCARD_TIME] = -1.0;
    update(s);
    return s;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop)
{
    Stair *s = (Stair *)c;
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    s->time = start;
    update(s);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { update((Stair *)c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }

/* -- get and set -------------------------------------------------------------------------- */

#define ACCESS(fn, T, table, n, dir)                                                     \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, T value[]) \
    {                                                                                    \
        Stair *s = (Stair *)c;                                                           \
        size_t k;                                                                        \
        for (k = 0; k < nvr; k++) {                                                      \
            if (vr[k] >= n) return fmi2Error;                                            \
            dir;                                                                         \
        }                                                                                \
        update(s);                                                                       \
        return fmi2OK;                                                                   \
    }

ACCESS(fmi2GetReal, fmi2Real, r, N_REAL, value[k] = s->r[vr[k]])
ACCESS(fmi2GetInteger, fmi2Integer, i, N_INTEGER, value[k] = s->i[vr[k]])
ACCESS(fmi2GetBoolean, fmi2Boolean, b, N_BOOLEAN, value[k] = s->b[vr[k]])

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    Stair *s = (Stair *)c;
    size_t k;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= N_REAL || vr[k] == R_LEVEL || vr[k] == R_Y) return fmi2Error;
        s->r[vr[k]] = value[k];
    }
    update(s);
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    Stair *s = (Stair *)c;
    size_t k;
    for (k = 0; k < nvr; k++) {
        if (vr[k] != I_OFFSET) return fmi2Error;
        s->i[I_OFFSET] = value[k];
    }
    update(s);
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    Stair *s = (Stair *)c;
    size_t k;
    for (k = 0; k < nvr; k++) {
        if (vr[k] != B_ENABLE) return fmi2Error;
        s->b[B_ENABLE] = value[k] != fmi2False;
    }
    update(s);
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)c; (void)vr; (void)value;
    return nvr ? fmi2Error : fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)c; (void)vr; (void)value;
    return nvr ? fmi2Error : fmi2OK;
}

/* -- not supported ------------------------------------------------------------------------ */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *st) { (void)c; (void)st; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate st) { (void)c; (void)st; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *st) { (void)c; (void)st; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate st, size_t *n)
{
    (void)c; (void)st; (void)n;
    return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate st, fmi2Byte b[], size_t n)
{
    (void)c; (void)st; (void)b; (void)n;
    return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *st)
{
    (void)c; (void)b; (void)n; (void)st;
    return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dz[],
                                        fmi2Real du[])
{
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dz; (void)du;
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

/* -- stepping and status ------------------------------------------------------------------ */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePrior)
{
    Stair *s = (Stair *)c;
    (void)noSetFMUStatePrior;
    if (s->terminated) return fmi2Error;
    if (past(t + h, s->r[R_STOP_TIME])) {
        s->terminated = 1;
        return fmi2Discard;
    }
    if (past(t + h, s->r[R_ERROR_TIME])) return fmi2Error;
    if (past(t + h, s->r[R_DISCARD_TIME])) return fmi2Discard;
    s->time = t + h;
    update(s);
    return fmi2OK;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v)
{
    (void)c; (void)k; (void)v;
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v)
{
    Stair *s = (Stair *)c;
    if (k != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = s->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v)
{
    (void)c; (void)k; (void)v;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v)
{
    Stair *s = (Stair *)c;
    if (k != fmi2Terminated) return fmi2Discard;
    *v = s->terminated ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v)
{
    (void)c; (void)k; (void)v;
    return fmi2Discard;
}
