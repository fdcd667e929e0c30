/* A minimal FMI 1.0 Co-Simulation FMU (tests only): y' = k u by explicit Euler over each
   communication step with u held, so y(t_n) = k h sum u(t_i) exactly as a master computes
   it; steps counts the steps, positive is y > 0. Every FMI 1.0 CS function is exported. */
#include <stdlib.h>
#include <string.h>
#include "fmi1Functions.h"

#define ID "integrator"
#define GUID "{5f0c6a8e-1b7d-4c51-9a3e-2d8f4b6e7a10}"
#define EXPORT __attribute__((visibility("default")))
#define F(name) integrator_fmi##name

typedef struct {
    double r[3]; /* k, u, y */
    int steps;
    double time;
    int initialized;
    fmi1CallbackFunctions cb;
    char name[64];
} Inst;

static void error(Inst *s, const char *msg) {
    if (s->cb.logger) s->cb.logger((fmi1Component)s, s->name, fmi1Error, "error", "%s", msg);
}

EXPORT const char *F(GetTypesPlatform)(void) { return "standard32"; }
EXPORT const char *F(GetVersion)(void) { return "1.0"; }

EXPORT fmi1Component F(InstantiateSlave)(fmi1String instanceName, fmi1String fmuGUID,
                                         fmi1String fmuLocation, fmi1String mimeType,
                                         fmi1Real timeout, fmi1Boolean visible,
                                         fmi1Boolean interactive, fmi1CallbackFunctions functions,
                                         fmi1Boolean loggingOn) {
    Inst *s;
    (void)fmuLocation, (void)mimeType, (void)timeout, (void)visible, (void)interactive,
        (void)loggingOn;
    if (!fmuGUID || strcmp(fmuGUID, GUID) != 0) return NULL;
    s = (Inst *)calloc(1, sizeof *s);
    if (!s) return NULL;
    s->cb = functions;
    strncpy(s->name, instanceName ? instanceName : "", sizeof s->name - 1);
    s->r[0] = 2.0;
    return (fmi1Component)s;
}

EXPORT fmi1Status F(InitializeSlave)(fmi1Component c, fmi1Real tStart, fmi1Boolean stopTimeDefined,
                                     fmi1Real tStop) {
    Inst *s = (Inst *)c;
    (void)stopTimeDefined, (void)tStop;
    s->time = tStart;
    s->initialized = 1;
    return fmi1OK;
}

EXPORT fmi1Status F(TerminateSlave)(fmi1Component c) { (void)c; return fmi1OK; }
EXPORT fmi1Status F(ResetSlave)(fmi1Component c) {
    Inst *s = (Inst *)c;
    s->r[1] = s->r[2] = 0.0;
    s->steps = 0;
    s->initialized = 0;
    return fmi1OK;
}
EXPORT void F(FreeSlaveInstance)(fmi1Component c) { free(c); }
EXPORT fmi1Status F(SetDebugLogging)(fmi1Component c, fmi1Boolean loggingOn) {
    (void)c, (void)loggingOn;
    return fmi1OK;
}

EXPORT fmi1Status F(SetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                             const fmi1Real value[]) {
    Inst *s = (Inst *)c;
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] > 1) {
            error(s, "fmiSetReal: only k (0) and u (1) can be set");
            return fmi1Error;
        }
        s->r[vr[i]] = value[i];
    }
    return fmi1OK;
}
EXPORT fmi1Status F(GetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                             fmi1Real value[]) {
    Inst *s = (Inst *)c;
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] > 2) return fmi1Error;
        value[i] = s->r[vr[i]];
    }
    return fmi1OK;
}
EXPORT fmi1Status F(GetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                fmi1Integer value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != 0) return fmi1Error;
        value[i] = ((Inst *)c)->steps;
    }
    return fmi1OK;
}
EXPORT fmi1Status F(GetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                fmi1Boolean value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != 0) return fmi1Error;
        value[i] = ((Inst *)c)->r[2] > 0 ? fmi1True : fmi1False;
    }
    return fmi1OK;
}
EXPORT fmi1Status F(GetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                               fmi1String value[]) {
    (void)c, (void)vr, (void)value;
    return nvr ? fmi1Error : fmi1OK;
}
EXPORT fmi1Status F(SetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                const fmi1Integer value[]) {
    (void)c, (void)vr, (void)value;
    return nvr ? fmi1Error : fmi1OK;
}
EXPORT fmi1Status F(SetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                const fmi1Boolean value[]) {
    (void)c, (void)vr, (void)value;
    return nvr ? fmi1Error : fmi1OK;
}
EXPORT fmi1Status F(SetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                               const fmi1String value[]) {
    (void)c, (void)vr, (void)value;
    return nvr ? fmi1Error : fmi1OK;
}

EXPORT fmi1Status F(SetRealInputDerivatives)(fmi1Component c, const fmi1ValueReference vr[],
                                             size_t nvr, const fmi1Integer order[],
                                             const fmi1Real value[]) {
    (void)c, (void)vr, (void)nvr, (void)order, (void)value;
    return fmi1Error;
}
EXPORT fmi1Status F(GetRealOutputDerivatives)(fmi1Component c, const fmi1ValueReference vr[],
                                              size_t nvr, const fmi1Integer order[],
                                              fmi1Real value[]) {
    (void)c, (void)vr, (void)nvr, (void)order, (void)value;
    return fmi1Error;
}
EXPORT fmi1Status F(CancelStep)(fmi1Component c) { (void)c; return fmi1Error; }

EXPORT fmi1Status F(DoStep)(fmi1Component c, fmi1Real t, fmi1Real h, fmi1Boolean newStep) {
    Inst *s = (Inst *)c;
    (void)newStep;
    if (!s->initialized) {
        error(s, "fmiDoStep before fmiInitializeSlave");
        return fmi1Error;
    }
    (void)t;
    s->r[2] += s->r[0] * s->r[1] * h;
    s->steps++;
    s->time += h;
    return fmi1OK;
}

EXPORT fmi1Status F(GetStatus)(fmi1Component c, const fmi1StatusKind k, fmi1Status *v) {
    (void)c, (void)k, (void)v;
    return fmi1Discard;
}
EXPORT fmi1Status F(GetRealStatus)(fmi1Component c, const fmi1StatusKind k, fmi1Real *v) {
    if (k != fmi1LastSuccessfulTime) return fmi1Discard;
    *v = ((Inst *)c)->time;
    return fmi1OK;
}
EXPORT fmi1Status F(GetIntegerStatus)(fmi1Component c, const fmi1StatusKind k, fmi1Integer *v) {
    (void)c, (void)k, (void)v;
    return fmi1Discard;
}
EXPORT fmi1Status F(GetBooleanStatus)(fmi1Component c, const fmi1StatusKind k, fmi1Boolean *v) {
    (void)c, (void)k, (void)v;
    return fmi1Discard;
}
EXPORT fmi1Status F(GetStringStatus)(fmi1Component c, const fmi1StatusKind k, fmi1String *v) {
    (void)c, (void)k, (void)v;
    return fmi1Discard;
}
