/* railfmu: contract between the shared FMI 2.0 Co-Simulation runtime (fmi2_runtime.c) and
 * one model's code (generated from models/ by fmus/generate/codegen.py, or hand-written with a test
 * that proves it equals the Python definition).
 *
 * Every variable lives in one array per FMI type, indexed by its value reference
 * (FMI 2 value references are per type). Real value reference 0 is `time`.
 * Continuous states live in r[] at model_state_vrs[]; the runtime integrates them inside
 * fmi2DoStep with fixed RK4 sub-steps no longer than r[VR_INTEGRATOR_STEP].
 */
#ifndef RAILFMU_MODEL_H
#define RAILFMU_MODEL_H

#include <stddef.h>
#include "fmi2Functions.h"
#include "model_config.h" /* generated: MODEL_IDENTIFIER, MODEL_GUID, N_REAL, N_INTEGER,
                             N_BOOLEAN, N_STRING, N_STATES, VR_INTEGRATOR_STEP */

typedef enum {
    CAUSALITY_PARAMETER,
    CAUSALITY_CALCULATED_PARAMETER,
    CAUSALITY_INPUT,
    CAUSALITY_OUTPUT,
    CAUSALITY_LOCAL,
    CAUSALITY_INDEPENDENT
} Causality;

typedef enum {
    VARIABILITY_CONSTANT,
    VARIABILITY_FIXED,
    VARIABILITY_TUNABLE,
    VARIABILITY_DISCRETE,
    VARIABILITY_CONTINUOUS
} Variability;

typedef struct {
    const char *name;
    Causality causality;
    Variability variability;
} VariableInfo;

/* Runtime state machine (FMI 2.0 CS, figure in section 4.3 of the standard). */
typedef enum {
    STATE_INSTANTIATED = 1 << 0,
    STATE_INITIALIZATION_MODE = 1 << 1,
    STATE_STEP_COMPLETE = 1 << 2,
    STATE_STEP_FAILED = 1 << 3,
    STATE_TERMINATED = 1 << 4,
    STATE_ERROR = 1 << 5,
    STATE_FATAL = 1 << 6
} ModelState;

typedef struct ModelInstance {
    /* set by the runtime */
    char *instanceName;
    char *resourceLocation;  /* file URI of the FMU's resources/ folder, may be NULL */
    const fmi2CallbackFunctions *functions;
    fmi2Boolean loggingOn;
    ModelState state;
    double startTime;
    double stopTime;
    fmi2Boolean stopTimeDefined;
    double lastSuccessfulTime;
    /* time at which the inputs were last set: inputs with a rate input are extrapolated
       from here, u(t) = u + u_rate (t - inputTime), in derivatives and outputs alike */
    double inputTime;
    /* the communication step h of the fmi2DoStep that ended at r[0]; 0 in initialisation
       mode. A model that samples or switches at given times counts a boundary as reached at
       r[0] when it lies within STEP_TOLERANCE * stepSize after it (see below). */
    double stepSize;

    /* the variables, by value reference; r[0] is time (the start of the current
       communication step while a step is being computed) */
    fmi2Real r[N_REAL];
#if N_INTEGER > 0
    fmi2Integer i[N_INTEGER];
#endif
#if N_BOOLEAN > 0
    fmi2Boolean b[N_BOOLEAN];
#endif
#if N_STRING > 0
    char *s[N_STRING];
#endif

    /* model-owned memory derived from parameters in model_initialize (tables etc.);
       not part of the serialized FMU state, rebuilt by model_state_restored */
    void *modelData;
} ModelInstance;

/* A master may compute its communication points as t = k h or accumulate t += h (FMI does
   not say which): after 1e6 steps the two differ by up to 2.2e-5 h, after 1e7 steps by
   1.8e-3 h (measured, h = 1 ms and 0.1 ms). A time within this fraction of the
   communication step is the same communication point: for the runtime's matching of
   currentCommunicationPoint and stopTime, and for a model's sample and switching instants
   (models/base.py STEP_TOLERANCE, the same value). */
#define STEP_TOLERANCE 1e-2

/* ---- implemented per model ---------------------------------------------------------- */
extern const VariableInfo model_real_info[N_REAL];
extern const fmi2Real model_real_start[N_REAL];
#if N_INTEGER > 0
extern const VariableInfo model_integer_info[N_INTEGER];
extern const fmi2Integer model_integer_start[N_INTEGER];
#endif
#if N_BOOLEAN > 0
extern const VariableInfo model_boolean_info[N_BOOLEAN];
extern const fmi2Boolean model_boolean_start[N_BOOLEAN];
#endif
#if N_STRING > 0
extern const VariableInfo model_string_info[N_STRING];
extern const char *const model_string_start[N_STRING];
#endif
#if N_STATES > 0
extern const fmi2ValueReference model_state_vrs[N_STATES];
#endif

/* Check parameters before initialisation ends; on a bad value call model_error() naming
   the parameter and return non-zero. */
int model_check_parameters(ModelInstance *m);
/* Called when initialisation ends (after the check): allocate tables, compute calculated
   parameters, then the outputs at the start time. Non-zero = error (already logged). */
int model_initialize(ModelInstance *m);
/* State derivatives at time t in [r[0], r[0] + h]; inputs are held over the step, or
   extrapolated from m->inputTime with their rate input where the model declares one
   (first-order hold). */
void model_derivatives(ModelInstance *m, double t, const double *x, double *dx);
/* Outputs (and locals) from the states, inputs and parameters in r[] at time r[0] (inputs
   with a rate extrapolated from m->inputTime, as in model_derivatives). Also called in
   initialisation mode, after model_initialize, so the importer reads consistent initial
   outputs (FMI 2.0.4, 4.2.4 InitialUnknowns). */
int model_outputs(ModelInstance *m);
#if defined(MODEL_STEP_BEGIN) && MODEL_STEP_BEGIN
/* Optional (MODEL_STEP_BEGIN 1 in model_config.h): called by fmi2DoStep before it integrates,
   with the step's inputs set; a model may take its states from inputs here (a process
   model's sigma point). Non-zero = error, already logged, nothing changed: the step is
   refused with fmi2Error and the instance stays usable. */
int model_step_begin(ModelInstance *m);
#endif
/* After fmi2SetFMUstate: rebuild modelData from the restored parameters. */
int model_state_restored(ModelInstance *m);
void model_free(ModelInstance *m);

/* ---- provided by the runtime -------------------------------------------------------- */
void model_log(ModelInstance *m, fmi2Status status, const char *category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
#define model_error(m, ...) model_log((m), fmi2Error, "logStatusError", __VA_ARGS__)
/* End the simulation (FMI 2.0.4, 4.2.3): the model has computed its outputs at `time` and
   can go no further. Called from model_outputs:
     - during fmi2DoStep from t0 to t0 + h, with time in [t0, t0 + h] (clamped): the runtime
       sets r[0] = fmi2LastSuccessfulTime = time and fmi2DoStep returns fmi2Discard. A model
       with continuous states has integrated them to t0 + h and must pass r[0]; a model
       without states (a table that ends inside the step) may pass the time it reached;
     - at initialisation (or a get after a set): the next fmi2DoStep computes nothing and
       returns fmi2Discard at the current time.
   From then on fmi2GetBooleanStatus(fmi2Terminated) is fmi2True and the outputs stay
   readable; a master ends the co-simulation there. `fmt` (printf-style, may be NULL) says
   why, logged in category logEvents. */
void model_terminate(ModelInstance *m, double time, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* Resolve a path given by a String parameter: absolute paths as they are, relative ones
   against the resources folder. Returns a malloc'ed string (caller frees) or NULL. */
char *model_resolve_path(ModelInstance *m, const char *path);

#endif
