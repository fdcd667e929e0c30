/* railfmu: FMI 3.0 Co-Simulation layer over the shared FMI 2.0 runtime.
 *
 * One translation unit: this file includes fmi2_runtime.c (the state machine, get/set
 * rules, RK4 stepping, FMU state with its typed and checksummed serialization) with its
 * fmi2* functions kept out of the binary's exports, and maps each fmi3 function onto it.
 * The model code (model.h) is the same as for FMI 2, so both versions compute the same
 * numbers. Build: gcc ... fmi3_runtime.c <model>.c (not fmi2_runtime.c on its own).
 *
 * What changes from FMI 2 to 3 here:
 *   - value references are unique across types (FMI 3.0, 2.4.7.3): Float64 keeps the FMI 2
 *     Real numbers (time is 0), Int32 follow at N_REAL, Boolean at N_REAL + N_INTEGER,
 *     String at N_REAL + N_INTEGER + N_BOOLEAN (fmus/generate/codegen.py writes the same);
 *   - fmi3Boolean is bool, fmi2Boolean int: converted element by element;
 *   - the resource path is a directory path ending in a separator, not a URI (the runtime
 *     takes a plain path as it is);
 *   - fmi3EnterInitializationMode carries the experiment (fmi2SetupExperiment);
 *   - fmi3DoStep returns the terminate request and the last successful time itself: a model
 *     that ends the simulation (model_terminate) gives fmi3Discard, terminateSimulation =
 *     true and the time it reached, as fmi2Discard + fmi2Terminated do in FMI 2.
 * Model Exchange, Scheduled Execution, event mode, clocks, Float32 and the 8/16/64-bit
 * integer types, Binary, derivatives and configuration mode are not provided: they are
 * exported (importers such as FMPy bind every function when they load the library) and
 * return fmi3Error with a log line naming the function. Messages of the FMI 2 layer reach
 * the fmi3 logger with the FMI 3 function names.
 */

/* The FMI 2 layer is compiled in without its exported declarations (fmi2Functions.h as
   shipped by FMPy always exports): defined without a visible declaration and inside the
   hidden-visibility pragma, its functions stay out of the binary's exports, also when an
   importer rebuilds the FMU from sources/buildDescription.xml without -fvisibility=hidden. */
#include <float.h> /* the C library's headers outside the pragma: its functions keep */
#include <math.h>  /* their default visibility */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#define fmi2Functions_h
#include "fmi2TypesPlatform.h"
#include "fmi2FunctionTypes.h"
#define fmi2Version "2.0"
#if defined(__GNUC__)
#pragma GCC visibility push(hidden)
#endif
#include "fmi2_runtime.c"
#if defined(__GNUC__)
#pragma GCC visibility pop
#endif

#include "fmi3Functions.h"

#define F3_N_INT_BASE ((fmi3ValueReference)N_REAL)
#define F3_N_BOOL_BASE ((fmi3ValueReference)(N_REAL + N_INTEGER))
#define F3_N_STRING_BASE ((fmi3ValueReference)(N_REAL + N_INTEGER + N_BOOLEAN))
#define F3_N_ALL ((fmi3ValueReference)(N_REAL + N_INTEGER + N_BOOLEAN + N_STRING))

/* What fmi3Instance points to: the FMI 2 instance and the importer's logger. */
typedef struct {
    fmi2Component c;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logMessage;
} Instance3;

/* FMI 2 names in the FMI 2 layer's messages, as the FMI 3 importer calls them */
static const char *const f3_renames[][2] = {
    {"fmi2GetReal", "fmi3GetFloat64"},       {"fmi2SetReal", "fmi3SetFloat64"},
    {"fmi2GetInteger", "fmi3GetInt32"},      {"fmi2SetInteger", "fmi3SetInt32"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"},
    {"fmi2GetFMUstate", "fmi3GetFMUState"},  {"fmi2SetFMUstate", "fmi3SetFMUState"},
    {"fmi2FreeFMUstate", "fmi3FreeFMUState"},
    {"fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"},
    {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"},
    {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"},
    {"fmi2Instantiate", "fmi3InstantiateCoSimulation"},
    {"fmi2", "fmi3"},
};

/* The FMI 2 logger the runtime calls: the message is finished text with '%' doubled
   (fmi2_runtime.c vlog); the fmi3 logger takes it verbatim, so '%%' becomes '%'. */
static void f3_logger(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status,
                      fmi2String category, fmi2String message, ...) {
    Instance3 *w = (Instance3 *)env;
    const size_t n_renames = sizeof f3_renames / sizeof f3_renames[0];
    const char *p;
    char *out, *o;
    size_t k;
    (void)instanceName;
    if (!w || !w->logMessage || !message) return;
    /* a rename never makes a name longer by more than 20 characters */
    out = (char *)malloc(strlen(message) * 6 + 1);
    if (!out) {
        w->logMessage(w->env, (fmi3Status)status, category, message);
        return;
    }
    for (p = message, o = out; *p;) {
        if (p[0] == '%' && p[1] == '%') {
            *o++ = '%';
            p += 2;
            continue;
        }
        for (k = 0; k < n_renames; k++) {
            const size_t len = strlen(f3_renames[k][0]);
            if (strncmp(p, f3_renames[k][0], len) == 0) {
                strcpy(o, f3_renames[k][1]);
                o += strlen(f3_renames[k][1]);
                p += len;
                break;
            }
        }
        if (k == n_renames) *o++ = *p++;
    }
    *o = '\0';
    w->logMessage(w->env, (fmi3Status)status, category, out);
    free(out);
}

static ModelInstance *f3_model(fmi3Instance instance) {
    return instance ? (ModelInstance *)((Instance3 *)instance)->c : NULL;
}

/* A function this FMU does not provide: fmi3Error and one line naming it. */
static fmi3Status f3_unsupported(fmi3Instance instance, const char *function, const char *why) {
    ModelInstance *m = f3_model(instance);
    if (m) model_error(m, "%s: not provided by this FMU (%s)", function, why);
    return fmi3Error;
}

#define F3_C(instance) (((Instance3 *)(instance))->c)
#define F3_CHECK(instance, function)                                                       \
    do {                                                                                   \
        if (!(instance)) return fmi3Error;                                                 \
    } while (0)

/* ---- common functions --------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    F3_CHECK(instance, "fmi3SetDebugLogging");
    return (fmi3Status)fmi2SetDebugLogging(F3_C(instance), loggingOn ? fmi2True : fmi2False,
                                           nCategories, categories);
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Instance3 *w;
    fmi2CallbackFunctions cb;
    (void)earlyReturnAllowed, (void)requiredIntermediateVariables, (void)intermediateUpdate;
    (void)nRequiredIntermediateVariables; /* no intermediate updates: nothing is required */

    w = (Instance3 *)calloc(1, sizeof *w);
    if (!w) return NULL;
    w->env = instanceEnvironment;
    w->logMessage = logMessage;
    cb.logger = f3_logger;
    cb.allocateMemory = calloc; /* never called: the runtime uses calloc/free itself */
    cb.freeMemory = free;
    cb.stepFinished = NULL;
    cb.componentEnvironment = w;
    if (eventModeUsed) {
        log_early(instanceName, &cb, "fmi3InstantiateCoSimulation: %s has no event mode "
                                     "(hasEventMode = false), eventModeUsed must be false",
                  MODEL_NAME);
        free(w);
        return NULL;
    }
    w->c = fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken, resourcePath,
                           &cb, visible ? fmi2True : fmi2False, loggingOn ? fmi2True : fmi2False);
    if (!w->c) {
        free(w);
        return NULL;
    }
    return (fmi3Instance)w;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange: " MODEL_NAME " supports Co-Simulation only");
    (void)instanceName;
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible;
    (void)loggingOn, (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: " MODEL_NAME
                   " supports Co-Simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    if (!instance) return;
    fmi2FreeInstance(F3_C(instance));
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    fmi2Status s;
    F3_CHECK(instance, "fmi3EnterInitializationMode");
    s = fmi2SetupExperiment(F3_C(instance), toleranceDefined ? fmi2True : fmi2False, tolerance,
                            startTime, stopTimeDefined ? fmi2True : fmi2False, stopTime);
    if (s > fmi2Warning) return (fmi3Status)s;
    return (fmi3Status)fmi2EnterInitializationMode(F3_C(instance));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    F3_CHECK(instance, "fmi3ExitInitializationMode");
    return (fmi3Status)fmi2ExitInitializationMode(F3_C(instance));
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    F3_CHECK(instance, "fmi3Terminate");
    return (fmi3Status)fmi2Terminate(F3_C(instance));
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    F3_CHECK(instance, "fmi3Reset");
    return (fmi3Status)fmi2Reset(F3_C(instance));
}

/* ---- variables ---------------------------------------------------------------------- */

/* nValues must equal nValueReferences: every variable is a scalar */
static int f3_scalars(fmi3Instance instance, const char *function, size_t nvr, size_t nValues) {
    if (nvr == nValues) return 1;
    model_error(f3_model(instance), "%s: nValues = %lu but %lu value references: this FMU has "
                                    "scalar variables only",
                function, (unsigned long)nValues, (unsigned long)nvr);
    return 0;
}

/* FMI 3 value references of one type -> the FMI 2 ones (malloc'ed; NULL and a logged error
   when one is not a variable of that type) */
static fmi2ValueReference *f3_vrs(fmi3Instance instance, const char *function, const char *type,
                                  const fmi3ValueReference vr[], size_t nvr,
                                  fmi3ValueReference base, size_t count) {
    fmi2ValueReference *out;
    size_t k;
    if (nvr && !vr) {
        model_error(f3_model(instance), "%s: valueReferences is NULL", function);
        return NULL;
    }
    out = (fmi2ValueReference *)malloc((nvr ? nvr : 1) * sizeof *out);
    if (!out) {
        model_error(f3_model(instance), "%s: out of memory", function);
        return NULL;
    }
    for (k = 0; k < nvr; k++) {
        if (vr[k] < base || vr[k] - base >= count) {
            model_error(f3_model(instance), "%s: value reference %lu is not a %s variable of "
                                            "this FMU",
                        function, (unsigned long)vr[k], type);
            free(out);
            return NULL;
        }
        out[k] = (fmi2ValueReference)(vr[k] - base);
    }
    return out;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Status s;
    F3_CHECK(instance, "fmi3GetFloat64");
    if (!f3_scalars(instance, "fmi3GetFloat64", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3GetFloat64", "Float64", vr, nvr, 0, N_REAL);
    if (!v) return fmi3Error;
    s = fmi2GetReal(F3_C(instance), v, nvr, values);
    free(v);
    return (fmi3Status)s;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Status s;
    F3_CHECK(instance, "fmi3SetFloat64");
    if (!f3_scalars(instance, "fmi3SetFloat64", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3SetFloat64", "Float64", vr, nvr, 0, N_REAL);
    if (!v) return fmi3Error;
    s = fmi2SetReal(F3_C(instance), v, nvr, values);
    free(v);
    return (fmi3Status)s;
}

#if N_INTEGER > 0
typedef char f3_int32_is_fmi2Integer[sizeof(fmi3Int32) == sizeof(fmi2Integer) ? 1 : -1];
#endif

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Int32 values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Status s;
    F3_CHECK(instance, "fmi3GetInt32");
    if (!f3_scalars(instance, "fmi3GetInt32", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3GetInt32", "Int32", vr, nvr, F3_N_INT_BASE, N_INTEGER);
    if (!v) return fmi3Error;
    s = fmi2GetInteger(F3_C(instance), v, nvr, (fmi2Integer *)values);
    free(v);
    return (fmi3Status)s;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Int32 values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Status s;
    F3_CHECK(instance, "fmi3SetInt32");
    if (!f3_scalars(instance, "fmi3SetInt32", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3SetInt32", "Int32", vr, nvr, F3_N_INT_BASE, N_INTEGER);
    if (!v) return fmi3Error;
    s = fmi2SetInteger(F3_C(instance), v, nvr, (const fmi2Integer *)values);
    free(v);
    return (fmi3Status)s;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Boolean values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Boolean *b;
    fmi2Status s;
    size_t k;
    F3_CHECK(instance, "fmi3GetBoolean");
    if (!f3_scalars(instance, "fmi3GetBoolean", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3GetBoolean", "Boolean", vr, nvr, F3_N_BOOL_BASE, N_BOOLEAN);
    if (!v) return fmi3Error;
    b = (fmi2Boolean *)calloc(nvr ? nvr : 1, sizeof *b);
    if (!b) {
        free(v);
        return fmi3Error;
    }
    s = fmi2GetBoolean(F3_C(instance), v, nvr, b);
    if (s <= fmi2Warning)
        for (k = 0; k < nvr; k++) values[k] = b[k] ? fmi3True : fmi3False;
    free(b);
    free(v);
    return (fmi3Status)s;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Boolean *b;
    fmi2Status s;
    size_t k;
    F3_CHECK(instance, "fmi3SetBoolean");
    if (!f3_scalars(instance, "fmi3SetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr && !values) return fmi3Error;
    v = f3_vrs(instance, "fmi3SetBoolean", "Boolean", vr, nvr, F3_N_BOOL_BASE, N_BOOLEAN);
    if (!v) return fmi3Error;
    b = (fmi2Boolean *)calloc(nvr ? nvr : 1, sizeof *b);
    if (!b) {
        free(v);
        return fmi3Error;
    }
    for (k = 0; k < nvr; k++) b[k] = values[k] ? fmi2True : fmi2False;
    s = fmi2SetBoolean(F3_C(instance), v, nvr, b);
    free(b);
    free(v);
    return (fmi3Status)s;
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         fmi3String values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Status s;
    F3_CHECK(instance, "fmi3GetString");
    if (!f3_scalars(instance, "fmi3GetString", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3GetString", "String", vr, nvr, F3_N_STRING_BASE, N_STRING);
    if (!v) return fmi3Error;
    s = fmi2GetString(F3_C(instance), v, nvr, values);
    free(v);
    return (fmi3Status)s;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3String values[], size_t nValues) {
    fmi2ValueReference *v;
    fmi2Status s;
    F3_CHECK(instance, "fmi3SetString");
    if (!f3_scalars(instance, "fmi3SetString", nvr, nValues)) return fmi3Error;
    v = f3_vrs(instance, "fmi3SetString", "String", vr, nvr, F3_N_STRING_BASE, N_STRING);
    if (!v) return fmi3Error;
    s = fmi2SetString(F3_C(instance), v, nvr, values);
    free(v);
    return (fmi3Status)s;
}

/* Types this FMU has no variables of: an empty call is fine, any value reference is not. */
#define F3_NO_TYPE(NAME, CTYPE, CONST)                                                     \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference vr[],          \
                             size_t nvr, CTYPE values[], size_t nValues) {                 \
        (void)vr, (void)values, (void)nValues;                                             \
        if (nvr == 0) return fmi3OK;                                                       \
        return f3_unsupported(instance, "fmi3Get" #NAME, "it has no " #NAME " variables");  \
    }                                                                                      \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference vr[],          \
                             size_t nvr, CONST CTYPE values[], size_t nValues) {           \
        (void)vr, (void)values, (void)nValues;                                             \
        if (nvr == 0) return fmi3OK;                                                       \
        return f3_unsupported(instance, "fmi3Set" #NAME, "it has no " #NAME " variables");  \
    }
F3_NO_TYPE(Float32, fmi3Float32, const)
F3_NO_TYPE(Int8, fmi3Int8, const)
F3_NO_TYPE(UInt8, fmi3UInt8, const)
F3_NO_TYPE(Int16, fmi3Int16, const)
F3_NO_TYPE(UInt16, fmi3UInt16, const)
F3_NO_TYPE(UInt32, fmi3UInt32, const)
F3_NO_TYPE(Int64, fmi3Int64, const)
F3_NO_TYPE(UInt64, fmi3UInt64, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)vr, (void)valueSizes, (void)values, (void)nValues;
    if (nvr == 0) return fmi3OK;
    return f3_unsupported(instance, "fmi3GetBinary", "it has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)vr, (void)valueSizes, (void)values, (void)nValues;
    if (nvr == 0) return fmi3OK;
    return f3_unsupported(instance, "fmi3SetBinary", "it has no Binary variables");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Clock values[]) {
    (void)vr, (void)nvr, (void)values;
    return f3_unsupported(instance, "fmi3GetClock", "it has no clocks");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[]) {
    (void)vr, (void)nvr, (void)values;
    return f3_unsupported(instance, "fmi3SetClock", "it has no clocks");
}

/* ---- dependencies, FMU state, derivatives ------------------------------------------- */

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference, (void)nDependencies;
    return f3_unsupported(instance, "fmi3GetNumberOfVariableDependencies",
                          "the dependencies are in modelDescription.xml <ModelStructure>");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent, (void)elementIndicesOfDependent, (void)independents;
    (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
    return f3_unsupported(instance, "fmi3GetVariableDependencies",
                          "the dependencies are in modelDescription.xml <ModelStructure>");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    F3_CHECK(instance, "fmi3GetFMUState");
    return (fmi3Status)fmi2GetFMUstate(F3_C(instance), (fmi2FMUstate *)FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    F3_CHECK(instance, "fmi3SetFMUState");
    return (fmi3Status)fmi2SetFMUstate(F3_C(instance), (fmi2FMUstate)FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    F3_CHECK(instance, "fmi3FreeFMUState");
    return (fmi3Status)fmi2FreeFMUstate(F3_C(instance), (fmi2FMUstate *)FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    F3_CHECK(instance, "fmi3SerializedFMUStateSize");
    return (fmi3Status)fmi2SerializedFMUstateSize(F3_C(instance), (fmi2FMUstate)FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    F3_CHECK(instance, "fmi3SerializeFMUState");
    return (fmi3Status)fmi2SerializeFMUstate(F3_C(instance), (fmi2FMUstate)FMUState,
                                             (fmi2Byte *)serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    F3_CHECK(instance, "fmi3DeserializeFMUState");
    return (fmi3Status)fmi2DeSerializeFMUstate(F3_C(instance), (const fmi2Byte *)serializedState,
                                               size, (fmi2FMUstate *)FMUState);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;
    (void)sensitivity, (void)nSensitivity;
    return f3_unsupported(instance, "fmi3GetDirectionalDerivative",
                          "providesDirectionalDerivatives = false");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;
    (void)sensitivity, (void)nSensitivity;
    return f3_unsupported(instance, "fmi3GetAdjointDerivative",
                          "providesAdjointDerivatives = false");
}

/* ---- modes, clocks and Model Exchange: not provided ---------------------------------- */

#define F3_NO_MODE(NAME, WHY)                                                              \
    fmi3Status NAME(fmi3Instance instance) { return f3_unsupported(instance, #NAME, WHY); }
F3_NO_MODE(fmi3EnterEventMode, "hasEventMode = false")
F3_NO_MODE(fmi3EnterConfigurationMode, "it has no structural parameters")
F3_NO_MODE(fmi3ExitConfigurationMode, "it has no structural parameters")
F3_NO_MODE(fmi3EvaluateDiscreteStates, "Co-Simulation without event mode")
F3_NO_MODE(fmi3EnterContinuousTimeMode, "Co-Simulation only")
F3_NO_MODE(fmi3EnterStepMode, "hasEventMode = false: it is in step mode after initialisation")

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)nvr, (void)intervals, (void)qualifiers;
    return f3_unsupported(instance, "fmi3GetIntervalDecimal", "it has no clocks");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
    return f3_unsupported(instance, "fmi3GetIntervalFraction", "it has no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr, (void)nvr, (void)shifts;
    return f3_unsupported(instance, "fmi3GetShiftDecimal", "it has no clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return f3_unsupported(instance, "fmi3GetShiftFraction", "it has no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, const fmi3Float64 intervals[]) {
    (void)vr, (void)nvr, (void)intervals;
    return f3_unsupported(instance, "fmi3SetIntervalDecimal", "it has no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return f3_unsupported(instance, "fmi3SetIntervalFraction", "it has no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr, (void)nvr, (void)shifts;
    return f3_unsupported(instance, "fmi3SetShiftDecimal", "it has no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return f3_unsupported(instance, "fmi3SetShiftFraction", "it has no clocks");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate, (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged, (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined, (void)nextEventTime;
    return f3_unsupported(instance, "fmi3UpdateDiscreteStates", "Co-Simulation without event mode");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return f3_unsupported(instance, "fmi3CompletedIntegratorStep", "Co-Simulation only");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    return f3_unsupported(instance, "fmi3SetTime", "Co-Simulation only");
}

#define F3_NO_ME_ARRAY(NAME, CONST)                                                        \
    fmi3Status NAME(fmi3Instance instance, CONST fmi3Float64 values[], size_t n) {         \
        (void)values, (void)n;                                                             \
        return f3_unsupported(instance, #NAME, "Co-Simulation only");                      \
    }
F3_NO_ME_ARRAY(fmi3SetContinuousStates, const)
F3_NO_ME_ARRAY(fmi3GetContinuousStateDerivatives, )
F3_NO_ME_ARRAY(fmi3GetEventIndicators, )
F3_NO_ME_ARRAY(fmi3GetContinuousStates, )
F3_NO_ME_ARRAY(fmi3GetNominalsOfContinuousStates, )

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    (void)nEventIndicators;
    return f3_unsupported(instance, "fmi3GetNumberOfEventIndicators", "Co-Simulation only");
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    (void)nContinuousStates;
    return f3_unsupported(instance, "fmi3GetNumberOfContinuousStates", "Co-Simulation only");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[],
                                    size_t nvr, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)vr, (void)nvr, (void)orders, (void)values, (void)nValues;
    return f3_unsupported(instance, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder = 0");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference, (void)activationTime;
    return f3_unsupported(instance, "fmi3ActivateModelPartition", "Co-Simulation only");
}

/* ---- stepping ----------------------------------------------------------------------- */

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    fmi2Status s;
    fmi2Boolean terminated = fmi2False;
    fmi2Real reached = currentCommunicationPoint;
    F3_CHECK(instance, "fmi3DoStep");
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime) {
        model_error(f3_model(instance), "fmi3DoStep: an output argument is NULL");
        return fmi3Error;
    }
    s = fmi2DoStep(F3_C(instance), currentCommunicationPoint, communicationStepSize,
                   noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False);
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    if (s == fmi2OK || s == fmi2Warning || s == fmi2Discard) {
        /* the state (StepComplete or StepFailed) allows the status queries */
        if (s == fmi2Discard)
            fmi2GetBooleanStatus(F3_C(instance), fmi2Terminated, &terminated);
        fmi2GetRealStatus(F3_C(instance), fmi2LastSuccessfulTime, &reached);
    }
    *terminateSimulation = terminated ? fmi3True : fmi3False;
    *lastSuccessfulTime = reached;
    return (fmi3Status)s;
}
