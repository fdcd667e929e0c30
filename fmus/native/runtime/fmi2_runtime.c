/* railfmu: shared FMI 2.0 Co-Simulation runtime.
 *
 * Compiled together with one model's code (see model.h) into <MODEL_IDENTIFIER>.so:
 *
 *   gcc -std=c99 -shared -fPIC -O2 -Wall -Wextra -Werror -I<fmi2 headers> \
 *       -I<dir with model_config.h> -I<this dir> fmi2_runtime.c <model>.c -o <id>.so
 *
 * What it does:
 *   - the FMI 2.0 Co-Simulation state machine (FMI 2.0.4, section 4.2.4, table of allowed
 *     calls per state); every illegal call returns fmi2Error and logs a message
 *     (category "logStatusError") naming the function and the current state;
 *   - get/set of variables by value reference, with the settability rules of
 *     section 2.2.7 (causality/variability/initial) and the per-state footnotes of 4.2.4;
 *   - fmi2DoStep integrates the continuous states with classic fixed-step RK4: the
 *     communication step h is split into n = ceil(h / r[VR_INTEGRATOR_STEP] - 1e-9) equal
 *     sub-steps, so every step lands exactly on t + h;
 *   - a model may end the simulation (model_terminate, model.h): fmi2DoStep then returns
 *     fmi2Discard and fmi2GetBooleanStatus(fmi2Terminated) gives fmi2True (FMI 2.0.4, 4.2.3);
 *   - errors are fmi2Error (never fmi2Fatal); the instance stays usable after a refused
 *     call that changed nothing (wrong state, bad argument, bad parameter at
 *     fmi2ExitInitializationMode: the model's own message is the only one logged, so an
 *     importer that shows the last message shows it) and goes to state Error when a
 *     step failed half-way (non-finite state or output), from where fmi2SetFMUstate or
 *     fmi2Reset bring it back;
 *   - FMU state get/set/serialize (canGetAndSetFMUstate, canSerializeFMUstate).
 *
 * No global mutable state: everything lives in the instance, so several instances of the
 * same FMU can run in one process. All memory comes from the C library (calloc/free), never
 * from the allocateMemory/freeMemory callbacks (some importers pass NULL): the
 * modelDescription.xml must therefore declare canNotUseMemoryManagementFunctions="true"
 * (FMI 2.0.4, section 4.3.1), as well as canGetAndSetFMUstate="true",
 * canSerializeFMUstate="true" and canHandleVariableCommunicationStepSize="true".
 */

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <float.h>
#include <math.h>

#include "model.h"

#if N_REAL < 1
#error "N_REAL must be at least 1: real value reference 0 is time"
#endif
#if N_STATES > 0 && !defined(VR_INTEGRATOR_STEP)
#error "a model with states must define VR_INTEGRATOR_STEP"
#endif

#define STRINGIFY_(x) #x
#define STRINGIFY(x) STRINGIFY_(x)
#define MODEL_NAME STRINGIFY(MODEL_IDENTIFIER)

/* ---- the instance ------------------------------------------------------------------- */

/* Log categories declared in modelDescription.xml (<LogCategories>), as bits. */
enum {
    LOG_STATUS_ERROR = 1u << 0,
    LOG_STATUS_WARNING = 1u << 1,
    LOG_EVENTS = 1u << 2,
    LOG_ALL = 1u << 3,
    LOG_CATEGORIES_ALL = (1u << 4) - 1u
};

static const struct {
    const char *name;
    unsigned bit;
} log_categories[] = {
    {"logStatusError", LOG_STATUS_ERROR},
    {"logStatusWarning", LOG_STATUS_WARNING},
    {"logEvents", LOG_EVENTS},
    {"logAll", LOG_ALL},
};
#define N_LOG_CATEGORIES (sizeof(log_categories) / sizeof(log_categories[0]))

/* What fmi2Component points to. The model only sees the ModelInstance (first member, so a
   ModelInstance* from the model converts back); the rest is private to the runtime. */
typedef struct {
    ModelInstance m;
    fmi2CallbackFunctions callbacks; /* a copy: the importer's struct may not outlive us */
    unsigned logMask;                /* enabled LOG_* categories (errors are always logged) */
    int outputsStale;                /* an input or tunable parameter changed since the outputs
                                        were computed: recompute before the next get */
    unsigned long errorsLogged;      /* fmi2Error/fmi2Fatal messages passed to the logger: a
                                        generic message is added only if the model said nothing */
    int terminateRequested;          /* the model called model_terminate (part of the FMU state) */
    double terminateTime;            /* ... and reached this time */
#if N_STRING > 0
    char *stringStart[N_STRING];     /* start values from the unpacked modelDescription.xml
                                        (NULL: the compiled one); see md_string_starts */
#endif
} Instance;

/* A saved FMU state (fmi2GetFMUstate). Everything a continuation depends on: modelData is
   derived from parameters and rebuilt by model_state_restored (see model.h).
   Every railfmu FMU shares the header layout, so a state handed to the wrong FMU (same
   magic) is recognised from the header alone, before anything of its own size is read:
   the payload layout differs per model and copying it would overrun the heap. */
#define SNAPSHOT_MAGIC 0x52464d53u /* "RFMS" */
#define SNAPSHOT_VERSION 0x52460002u /* unlike any ModelState: a pre-header state (its state after the magic) fails here */
#define ID_CHARS 64 /* GUID and identifier fields, NUL-padded */
#define STR_(x) #x
#define STR(x) STR_(x)
#define MODEL_IDENTIFIER_STRING STR(MODEL_IDENTIFIER)
typedef struct {
    uint32_t magic;
    uint32_t version;
    uint64_t size;            /* sizeof(Snapshot) of the FMU that saved it */
    char guid[ID_CHARS];
    char identifier[ID_CHARS];
    uint32_t checksum;        /* FNV-1a of the payload (string pointers included) ... */
    uint32_t strings_checksum; /* ... and of the strings, checked once the pointers are
                                  trusted: a stray write or a reused block is refused */
} SnapshotHeader;

typedef struct {
    ModelState state;
    double startTime;
    double stopTime;
    fmi2Boolean stopTimeDefined;
    double lastSuccessfulTime;
    double inputTime;
    double stepSize;
    int terminateRequested;
    double terminateTime;
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
} SnapshotPayload;

typedef struct {
    SnapshotHeader h; /* first: readable whichever FMU made the state */
    SnapshotPayload p;
} Snapshot;

/* compile-time check that GUID and identifier fit their fields (C99: no _Static_assert) */
typedef char guid_fits[sizeof(MODEL_GUID) <= ID_CHARS ? 1 : -1];
typedef char identifier_fits[sizeof(MODEL_IDENTIFIER_STRING) <= ID_CHARS ? 1 : -1];

/* ---- small helpers ------------------------------------------------------------------ */

static double abs_d(double x) { return x < 0 ? -x : x; }
static double max_d(double a, double b) { return a > b ? a : b; }

/* a and b are the same communication point of steps of size h: within STEP_TOLERANCE h
   (model.h; importers compute time as k h, as t += h or in integer nanoseconds), or
   within a few ulps of their magnitude (an h too small to resolve at that time). Tied to
   h, not to |t|: a relative 1e-9 of t = 1e7 s would accept a point ten 1 ms steps off. */
static int same_time(double a, double b, double h) {
    return abs_d(a - b) <= STEP_TOLERANCE * h + 8.0 * DBL_EPSILON * max_d(abs_d(a), abs_d(b));
}

/* strdup is POSIX, not C99 */
static char *dup_string(const char *s) {
    size_t n;
    char *d;
    if (!s) s = "";
    n = strlen(s) + 1;
    d = (char *)malloc(n);
    if (d) memcpy(d, s, n);
    return d;
}

static const char *state_name(ModelState s) {
    switch (s) {
    case STATE_INSTANTIATED: return "Instantiated";
    case STATE_INITIALIZATION_MODE: return "InitializationMode";
    case STATE_STEP_COMPLETE: return "StepComplete";
    case STATE_STEP_FAILED: return "StepFailed";
    case STATE_TERMINATED: return "Terminated";
    case STATE_ERROR: return "Error";
    case STATE_FATAL: return "Fatal";
    }
    return "?";
}

static const char *causality_name(Causality c) {
    switch (c) {
    case CAUSALITY_PARAMETER: return "parameter";
    case CAUSALITY_CALCULATED_PARAMETER: return "calculatedParameter";
    case CAUSALITY_INPUT: return "input";
    case CAUSALITY_OUTPUT: return "output";
    case CAUSALITY_LOCAL: return "local";
    case CAUSALITY_INDEPENDENT: return "independent";
    }
    return "?";
}

static int is_valid_state(int s) {
    return s == STATE_INSTANTIATED || s == STATE_INITIALIZATION_MODE ||
           s == STATE_STEP_COMPLETE || s == STATE_STEP_FAILED || s == STATE_TERMINATED ||
           s == STATE_ERROR || s == STATE_FATAL;
}

/* ---- logging (provided to the model, see model.h) ----------------------------------- */

static unsigned category_bit(const char *category) {
    size_t k;
    if (category) {
        for (k = 0; k < N_LOG_CATEGORIES; k++) {
            if (strcmp(category, log_categories[k].name) == 0) return log_categories[k].bit;
        }
    }
    return LOG_ALL; /* an undeclared category is only shown with logAll */
}

static void vlog(const char *instanceName, const fmi2CallbackFunctions *functions,
                 fmi2Status status, const char *category, const char *fmt, va_list ap) {
    char small[512];
    char *buf = small;
    int n;
    va_list ap2;

    if (!functions || !functions->logger) return; /* no logger: be silent */
    va_copy(ap2, ap);
    n = vsnprintf(small, sizeof small, fmt, ap);
    if (n >= (int)sizeof small) {
        buf = (char *)malloc((size_t)n + 1);
        if (buf) {
            vsnprintf(buf, (size_t)n + 1, fmt, ap2);
        } else {
            buf = small; /* truncated message rather than none */
        }
    } else if (n < 0) {
        strcpy(small, "(message formatting failed)");
    }
    va_end(ap2);
    /* The logger treats its message argument as a printf format (FMI 2.0.4, 2.1.5). We pass
       the finished text, with '%' doubled and no variadic arguments: importers that format
       print it as it is, and those that cannot read varargs (ctypes loggers) still get it. */
    {
        size_t len = strlen(buf), pct = 0, j = 0, k;
        char *esc;
        for (k = 0; k < len; k++) pct += buf[k] == '%';
        esc = pct ? (char *)malloc(len + pct + 1) : buf;
        if (esc) {
            if (pct) {
                for (k = 0; k < len; k++) {
                    esc[j++] = buf[k];
                    if (buf[k] == '%') esc[j++] = '%';
                }
                esc[j] = '\0';
            }
            functions->logger(functions->componentEnvironment, instanceName ? instanceName : "",
                              status, category ? category : "logAll", esc);
            if (esc != buf) free(esc);
        }
    }
    if (buf != small) free(buf);
}

void model_log(ModelInstance *m, fmi2Status status, const char *category, const char *fmt, ...) {
    Instance *inst = (Instance *)m;
    va_list ap;

    if (!m) return;
    /* errors are always passed on; everything else only with debug logging on for the
       category (FMI 2.0.4, 2.1.5: fmi2SetDebugLogging) */
    if (status < fmi2Error) {
        if (!m->loggingOn || !(inst->logMask & category_bit(category))) return;
    } else {
        inst->errorsLogged++;
    }
    va_start(ap, fmt);
    vlog(m->instanceName, m->functions, status, category, fmt, ap);
    va_end(ap);
}

void model_terminate(ModelInstance *m, double time, const char *fmt, ...) {
    Instance *inst = (Instance *)m;
    va_list ap;

    if (!m) return;
    /* several requests in one step: the earliest time counts */
    if (!inst->terminateRequested || time < inst->terminateTime) inst->terminateTime = time;
    inst->terminateRequested = 1;
    if (!fmt || !m->loggingOn || !(inst->logMask & category_bit("logEvents"))) return;
    va_start(ap, fmt);
    vlog(m->instanceName, m->functions, fmi2OK, "logEvents", fmt, ap);
    va_end(ap);
}

/* before an instance exists (fmi2Instantiate) */
static void log_early(const char *instanceName, const fmi2CallbackFunctions *functions,
                      const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
static void log_early(const char *instanceName, const fmi2CallbackFunctions *functions,
                      const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(instanceName, functions, fmi2Error, "logStatusError", fmt, ap);
    va_end(ap);
}

/* ---- resource paths (provided to the model, see model.h) ---------------------------- */

static int hex_value(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

static int is_absolute_path(const char *p) {
    if (p[0] == '/' || p[0] == '\\') return 1;
    /* Windows drive letter "C:\..." or "C:/..." */
    if (((p[0] >= 'a' && p[0] <= 'z') || (p[0] >= 'A' && p[0] <= 'Z')) && p[1] == ':' &&
        (p[2] == '/' || p[2] == '\\'))
        return 1;
    return 0;
}

/* The resource location is a URI (FMI 2.0.4, 2.1.5: "file:///C:/a/b/resources" or
   "file:/tmp/x/resources"; importers differ in the number of slashes and may add the host
   "localhost"). Returns the decoded file system path (malloc'ed), or NULL. */
static char *resource_dir(const char *uri) {
    const char *p = uri;
    char *out, *o;

    if (strncmp(p, "file:", 5) == 0) {
        p += 5;
        if (strncmp(p, "//", 2) == 0) {
            p += 2; /* authority follows: empty ("file:///x") or "localhost" */
            if (strncmp(p, "localhost", 9) == 0) p += 9;
            if (*p != '/') return NULL; /* a remote host: not a local file */
        }
        /* "/C:/x" -> "C:/x" on Windows */
        if (p[0] == '/' && p[1] && p[2] == ':' &&
            ((p[1] >= 'a' && p[1] <= 'z') || (p[1] >= 'A' && p[1] <= 'Z')))
            p++;
    }
    /* else: some importers pass a plain path; take it as it is */

    out = (char *)malloc(strlen(p) + 1);
    if (!out) return NULL;
    for (o = out; *p; p++) {
        int hi, lo;
        if (*p == '%' && (hi = hex_value(p[1])) >= 0 && (lo = hex_value(p[2])) >= 0) {
            *o++ = (char)(hi * 16 + lo);
            p += 2;
        } else {
            *o++ = *p;
        }
    }
    *o = '\0';
    return out;
}

char *model_resolve_path(ModelInstance *m, const char *path) {
    char *dir, *out;
    size_t nd, np;
    int slash;

    if (!m || !path || !*path) return NULL;
    if (is_absolute_path(path)) return dup_string(path);
    if (!m->resourceLocation || !*m->resourceLocation) return NULL;
    dir = resource_dir(m->resourceLocation);
    if (!dir) return NULL;
    nd = strlen(dir);
    np = strlen(path);
    slash = nd > 0 && (dir[nd - 1] == '/' || dir[nd - 1] == '\\');
    out = (char *)malloc(nd + np + 2);
    if (out) {
        memcpy(out, dir, nd);
        if (!slash) out[nd++] = '/';
        memcpy(out + nd, path, np + 1);
    }
    free(dir);
    return out;
}

/* ---- String start values of a per-instance copy -------------------------------------
   `railfmu export` gives a component with String parameters (a table's file, now in the
   copy's resources/, and its column names) its own copy of the FMU whose
   modelDescription.xml has them as start values, for importers that set no String
   parameter (OMSimulator 3.0 reads no ssv:String). The binary is the same, so it takes
   its String start values from the modelDescription.xml of the unpacked FMU, beside
   resources/ (what the compiled defaults are when nothing is found): FMI 2.0's
   <String start=...> and FMI 3.0's <Start value=...> child. Such a copy's GUID is
   this binary's followed by "-" and a suffix: importers that unpack an FMU once per GUID
   (libcosim) keep the copies apart. */

static int guid_matches(const char *guid) {
    size_t n = strlen(MODEL_GUID);
    return guid && strncmp(guid, MODEL_GUID, n) == 0 && (guid[n] == '\0' || (guid[n] == '-' && guid[n + 1]));
}

#if N_STRING > 0
static const char *skip_space(const char *p, const char *end) {
    while (p < end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')) p++;
    return p;
}

/* the end ('>') of the tag starting at p, quotes respected; NULL if none */
static const char *tag_end(const char *p) {
    char q = 0;
    for (; *p; p++) {
        if (q) {
            if (*p == q) q = 0;
        } else if (*p == '"' || *p == '\'') {
            q = *p;
        } else if (*p == '>') {
            return p;
        }
    }
    return NULL;
}

/* [p, end) with the XML entities decoded (malloc'ed) */
static char *xml_text(const char *p, const char *end) {
    char *out = (char *)malloc((size_t)(end - p) + 1), *o = out;
    if (!out) return NULL;
    while (p < end) {
        static const char *const names[] = {"&lt;", "&gt;", "&amp;", "&quot;", "&apos;"};
        static const char chars[] = "<>&\"'";
        size_t k, done = 0;
        for (k = 0; k < 5 && !done; k++) {
            size_t n = strlen(names[k]);
            if ((size_t)(end - p) >= n && strncmp(p, names[k], n) == 0) {
                *o++ = chars[k];
                p += n;
                done = 1;
            }
        }
        if (!done && p[0] == '&' && p + 2 < end && p[1] == '#') {
            char *stop;
            unsigned long c = p[2] == 'x' ? strtoul(p + 3, &stop, 16) : strtoul(p + 2, &stop, 10);
            if (stop < end && *stop == ';' && c > 0 && c <= 0x10FFFF) { /* as UTF-8 */
                if (c < 0x80) {
                    *o++ = (char)c;
                } else if (c < 0x800) {
                    *o++ = (char)(0xC0 | (c >> 6)), *o++ = (char)(0x80 | (c & 0x3F));
                } else if (c < 0x10000) {
                    *o++ = (char)(0xE0 | (c >> 12)), *o++ = (char)(0x80 | ((c >> 6) & 0x3F));
                    *o++ = (char)(0x80 | (c & 0x3F));
                } else {
                    *o++ = (char)(0xF0 | (c >> 18)), *o++ = (char)(0x80 | ((c >> 12) & 0x3F));
                    *o++ = (char)(0x80 | ((c >> 6) & 0x3F)), *o++ = (char)(0x80 | (c & 0x3F));
                }
                p = stop + 1;
                done = 1;
            }
        }
        if (!done) *o++ = *p++;
    }
    *o = '\0';
    return out;
}

/* the decoded value of attribute `name` of the tag [p, end) (p at '<'), or NULL */
static char *xml_attribute(const char *p, const char *end, const char *name) {
    while (p < end && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\n') p++; /* the tag's name */
    for (;;) {
        const char *a = skip_space(p, end), *a_end, *v;
        char q;
        for (p = a; p < end && *p != '=' && *p != ' ' && *p != '>' && *p != '/'; p++) {}
        a_end = p;
        if (a_end == a) return NULL;
        v = skip_space(p, end);
        if (v >= end || *v != '=') return NULL;
        v = skip_space(v + 1, end);
        if (v >= end || (*v != '"' && *v != '\'')) return NULL;
        q = *v++;
        for (p = v; p < end && *p != q; p++) {}
        if (p >= end) return NULL;
        if ((size_t)(a_end - a) == strlen(name) && strncmp(a, name, (size_t)(a_end - a)) == 0)
            return xml_text(v, p);
        p++;
    }
}

static char *read_text_file(const char *path) {
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    long size;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (size = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (buf = (char *)malloc((size_t)size + 1)) != NULL) {
        if (fread(buf, 1, (size_t)size, f) != (size_t)size) {
            free(buf);
            buf = NULL;
        } else {
            buf[size] = '\0';
        }
    }
    fclose(f);
    return buf;
}

/* inst->stringStart from <resources>/../modelDescription.xml (left NULL where not found) */
static void md_string_starts(Instance *inst) {
    static const char md_name[] = "/../modelDescription.xml";
    char *dir, *path, *text;
    const char *p;
    size_t nd;
    if (!inst->m.resourceLocation || !(dir = resource_dir(inst->m.resourceLocation))) return;
    nd = strlen(dir);
    while (nd > 0 && (dir[nd - 1] == '/' || dir[nd - 1] == '\\')) nd--;
    path = (char *)malloc(nd + sizeof md_name);
    if (path) {
        memcpy(path, dir, nd);
        memcpy(path + nd, md_name, sizeof md_name);
    }
    free(dir);
    text = path ? read_text_file(path) : NULL;
    free(path);
    if (!text) return;
    for (p = strstr(text, "<ScalarVariable"); p; p = strstr(p, "<ScalarVariable")) {
        const char *end = tag_end(p), *body, *s;
        char *name;
        size_t k;
        if (!end) break;
        body = strstr(end, "</ScalarVariable");
        if (end[-1] == '/' || !body) { /* no type element */
            p = end;
            continue;
        }
        s = strstr(end, "<String");
        name = xml_attribute(p, end, "name");
        if (name && s && s < body && (s[7] == ' ' || s[7] == '/' || s[7] == '>' || s[7] == '\n')) {
            const char *s_end = tag_end(s);
            for (k = 0; k < N_STRING && s_end; k++) {
                if (strcmp(model_string_info[k].name, name) == 0 && !inst->stringStart[k])
                    inst->stringStart[k] = xml_attribute(s, s_end, "start");
            }
        }
        free(name);
        p = body;
    }
    /* FMI 3.0: <String name="..." ...><Start value="..."/></String> (a scalar: its first Start) */
    for (p = strstr(text, "<ScalarVariable") ? NULL : strstr(text, "<String"); p; p = strstr(p, "<String")) {
        const char *end = tag_end(p), *body, *s;
        char *name;
        size_t k;
        if (!end) break;
        if (p[7] != ' ' && p[7] != '\t' && p[7] != '\r' && p[7] != '\n') { /* <StringType ...> */
            p = end;
            continue;
        }
        body = end[-1] == '/' ? NULL : strstr(end, "</String");
        s = body ? strstr(end, "<Start") : NULL;
        name = s && s < body ? xml_attribute(p, end, "name") : NULL;
        if (name) {
            const char *s_end = tag_end(s);
            for (k = 0; k < N_STRING && s_end; k++) {
                if (strcmp(model_string_info[k].name, name) == 0 && !inst->stringStart[k])
                    inst->stringStart[k] = xml_attribute(s, s_end, "value");
            }
        }
        free(name);
        p = body ? body + 1 : end;
    }
    free(text);
}
#endif

/* ---- state machine ------------------------------------------------------------------ */

/* Allowed states per function: FMI 2.0.4, section 4.2.4, state table of the slave. */
#define ANY_BUT_FATAL                                                                      \
    (STATE_INSTANTIATED | STATE_INITIALIZATION_MODE | STATE_STEP_COMPLETE |                \
     STATE_STEP_FAILED | STATE_TERMINATED | STATE_ERROR)
#define MASK_SetDebugLogging ANY_BUT_FATAL
#define MASK_SetupExperiment STATE_INSTANTIATED
#define MASK_EnterInitializationMode STATE_INSTANTIATED
#define MASK_ExitInitializationMode STATE_INITIALIZATION_MODE
#define MASK_Terminate (STATE_STEP_COMPLETE | STATE_STEP_FAILED)
#define MASK_Reset ANY_BUT_FATAL
/* fmi2GetXXX: not in Instantiated (nothing is computed yet); in Error "for debugging" */
#define MASK_Get                                                                           \
    (STATE_INITIALIZATION_MODE | STATE_STEP_COMPLETE | STATE_STEP_FAILED |                 \
     STATE_TERMINATED | STATE_ERROR)
/* fmi2SetXXX: which variables may be set in which state is checked per variable */
#define MASK_Set (STATE_INSTANTIATED | STATE_INITIALIZATION_MODE | STATE_STEP_COMPLETE)
#define MASK_FMUstate ANY_BUT_FATAL
#define MASK_DoStep STATE_STEP_COMPLETE
#define MASK_Status (STATE_STEP_COMPLETE | STATE_STEP_FAILED | STATE_TERMINATED)

static int allowed(Instance *inst, unsigned mask, const char *function) {
    if (!(inst->m.state & mask)) {
        model_error(&inst->m, "%s: illegal call sequence: not allowed in state %s", function,
                    state_name(inst->m.state));
        return 0;
    }
    return 1;
}

/* Common prologue: NULL instance -> fmi2Error (nothing to log to), wrong state -> fmi2Error. */
#define ENTER(fn, mask)                                                                    \
    Instance *inst = (Instance *)c;                                                        \
    ModelInstance *m;                                                                      \
    if (!inst) return fmi2Error;                                                           \
    m = &inst->m;                                                                          \
    if (!allowed(inst, (mask), (fn))) return fmi2Error;                                    \
    (void)m

static int null_arg(ModelInstance *m, const char *function, const char *arg, const void *p) {
    if (!p) {
        model_error(m, "%s: argument %s is NULL", function, arg);
        return 1;
    }
    return 0;
}

/* ---- start values ------------------------------------------------------------------- */

#if N_STRING > 0
/* the N_STRING strings of an instance or a snapshot */
static void free_string_array(char **s) {
    size_t k;
    for (k = 0; k < N_STRING; k++) {
        free(s[k]);
        s[k] = NULL;
    }
}
#endif

static void free_strings(ModelInstance *m) {
#if N_STRING > 0
    free_string_array(m->s);
#else
    (void)m;
#endif
}

static void free_string_starts(Instance *inst) {
#if N_STRING > 0
    free_string_array(inst->stringStart);
#else
    (void)inst;
#endif
}

static int set_start_values(ModelInstance *m) {
    memcpy(m->r, model_real_start, sizeof m->r);
    m->r[0] = 0.0; /* time */
#if N_INTEGER > 0
    memcpy(m->i, model_integer_start, sizeof m->i);
#endif
#if N_BOOLEAN > 0
    memcpy(m->b, model_boolean_start, sizeof m->b);
#endif
#if N_STRING > 0
    {
        size_t k;
        free_strings(m);
        for (k = 0; k < N_STRING; k++) {
            const char *start = ((Instance *)m)->stringStart[k];
            m->s[k] = dup_string(start ? start : model_string_start[k]);
            if (!m->s[k]) return 0;
        }
    }
#endif
    m->startTime = 0.0;
    m->stopTime = 0.0;
    m->stopTimeDefined = fmi2False;
    m->lastSuccessfulTime = 0.0;
    m->inputTime = 0.0;
    m->stepSize = 0.0;
    ((Instance *)m)->terminateRequested = 0;
    ((Instance *)m)->terminateTime = 0.0;
    return 1;
}

static void release_model_data(ModelInstance *m) {
    model_free(m);
    m->modelData = NULL; /* model_free need not reset it */
}

/* ---- common functions (FMI 2.0.4, section 2.1) -------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    size_t k, j;
    unsigned mask;
    ENTER("fmi2SetDebugLogging", MASK_SetDebugLogging);

    /* nCategories == 0: loggingOn applies to all categories; otherwise only to the ones
       listed, which must be declared in <LogCategories> (FMI 2.0.4, 2.1.5) */
    if (nCategories == 0) {
        mask = loggingOn ? LOG_CATEGORIES_ALL : 0u;
    } else {
        if (null_arg(m, "fmi2SetDebugLogging", "categories[]", categories)) return fmi2Error;
        mask = inst->logMask;
        for (k = 0; k < nCategories; k++) {
            unsigned bit = 0;
            for (j = 0; j < N_LOG_CATEGORIES; j++) {
                if (categories[k] && strcmp(categories[k], log_categories[j].name) == 0) {
                    bit = log_categories[j].bit;
                }
            }
            if (!bit) {
                model_error(m, "fmi2SetDebugLogging: unknown log category \"%s\" (declared: "
                               "logStatusError, logStatusWarning, logEvents, logAll)",
                            categories[k] ? categories[k] : "(null)");
                return fmi2Error;
            }
            mask = loggingOn ? (mask | bit) : (mask & ~bit);
        }
    }
    inst->logMask = mask;
    m->loggingOn = mask ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Instance *inst;
    ModelInstance *m;
    (void)visible;

    if (!functions) return NULL; /* nobody to tell */
    if (!instanceName || !*instanceName) {
        log_early(instanceName, functions, "fmi2Instantiate: instanceName must be non-empty");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        log_early(instanceName, functions,
                  "fmi2Instantiate: %s supports Co-Simulation only (fmuType = %d)",
                  MODEL_NAME, (int)fmuType);
        return NULL;
    }
    if (!guid_matches(fmuGUID)) {
        log_early(instanceName, functions,
                  "fmi2Instantiate: GUID \"%s\" does not match this binary's \"%s\" "
                  "(modelDescription.xml and binary from different builds?)",
                  fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        return NULL;
    }

    inst = (Instance *)calloc(1, sizeof *inst);
    if (!inst) {
        log_early(instanceName, functions, "fmi2Instantiate: out of memory");
        return NULL;
    }
    m = &inst->m;
    memcpy(&inst->callbacks, functions, sizeof inst->callbacks);
    m->functions = &inst->callbacks;
    m->instanceName = dup_string(instanceName);
    m->resourceLocation = fmuResourceLocation ? dup_string(fmuResourceLocation) : NULL;
    inst->logMask = loggingOn ? LOG_CATEGORIES_ALL : 0u;
    m->loggingOn = loggingOn ? fmi2True : fmi2False;
    m->modelData = NULL;
    m->state = STATE_INSTANTIATED;
#if N_STRING > 0
    md_string_starts(inst);
#endif
    if (!m->instanceName || (fmuResourceLocation && !m->resourceLocation) ||
        !set_start_values(m)) {
        log_early(instanceName, functions, "fmi2Instantiate: out of memory");
        free_strings(m);
        free_string_starts(inst);
        free(m->instanceName);
        free(m->resourceLocation);
        free(inst);
        return NULL;
    }
    return (fmi2Component)inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    release_model_data(&inst->m);
    free_strings(&inst->m);
    free_string_starts(inst);
    free(inst->m.instanceName);
    free(inst->m.resourceLocation);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined,
                               fmi2Real stopTime) {
    ENTER("fmi2SetupExperiment", MASK_SetupExperiment);
    (void)toleranceDefined; /* fixed-step RK4: the step is the parameter, not a tolerance */
    (void)tolerance;

    if (!isfinite(startTime)) {
        model_error(m, "fmi2SetupExperiment: startTime is not finite");
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        model_error(m, "fmi2SetupExperiment: stopTime %.17g is before startTime %.17g",
                    stopTime, startTime);
        return fmi2Error;
    }
    m->startTime = startTime;
    m->stopTimeDefined = stopTimeDefined ? fmi2True : fmi2False;
    m->stopTime = stopTimeDefined ? stopTime : 0.0;
    m->r[0] = startTime;
    m->lastSuccessfulTime = startTime;
    m->inputTime = startTime;
    m->stepSize = 0.0; /* initialisation mode: no step yet */
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ENTER("fmi2EnterInitializationMode", MASK_EnterInitializationMode);
    m->state = STATE_INITIALIZATION_MODE;
    inst->outputsStale = 1; /* initial outputs are computed at the first get */
    return fmi2OK;
}

/* Outputs (states included) must be finite after every step; returns 1 if they are. */
static int outputs_finite(ModelInstance *m, const char *function) {
    size_t k;
    for (k = 0; k < N_REAL; k++) {
        if (model_real_info[k].causality == CAUSALITY_OUTPUT && !isfinite(m->r[k])) {
            model_error(m, "%s: output %s is not finite (%g) at t = %.17g", function,
                        model_real_info[k].name, m->r[k], m->r[0]);
            return 0;
        }
    }
    return 1;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    unsigned long errors;
    ENTER("fmi2ExitInitializationMode", MASK_ExitInitializationMode);

    /* Every failure here leaves the instance in InitializationMode without model data:
       the model has logged which parameter is wrong, and the importer may correct it and
       call fmi2ExitInitializationMode again, or reset / free the instance. */
    if (model_check_parameters(m) != 0) return fmi2Error; /* the model said which parameter */
#if N_STATES > 0
    if (!(m->r[VR_INTEGRATOR_STEP] > 0.0) || !isfinite(m->r[VR_INTEGRATOR_STEP])) {
        model_error(m, "fmi2ExitInitializationMode: parameter %s = %g must be > 0 and finite",
                    model_real_info[VR_INTEGRATOR_STEP].name, m->r[VR_INTEGRATOR_STEP]);
        return fmi2Error;
    }
#endif
    release_model_data(m); /* a get in initialisation mode may have built it already */
    inst->terminateRequested = 0; /* a get in initialisation mode may have asked already */
    errors = inst->errorsLogged;
    if (model_initialize(m) != 0) {
        release_model_data(m);
        /* the model's own message (a bad table line, say) is the one the user needs */
        if (inst->errorsLogged == errors)
            model_error(m, "fmi2ExitInitializationMode: model initialisation failed");
        return fmi2Error;
    }
    if (model_outputs(m) != 0) {
        release_model_data(m);
        if (inst->errorsLogged == errors)
            model_error(m, "fmi2ExitInitializationMode: computing the initial outputs failed");
        return fmi2Error;
    }
    if (!outputs_finite(m, "fmi2ExitInitializationMode")) {
        release_model_data(m);
        return fmi2Error;
    }
    m->lastSuccessfulTime = m->r[0];
    m->state = STATE_STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ENTER("fmi2Terminate", MASK_Terminate);
    m->state = STATE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    ENTER("fmi2Reset", MASK_Reset);
    /* back to the state right after fmi2Instantiate (FMI 2.0.4, 2.1.6); the debug logging
       settings are kept */
    release_model_data(m);
    if (!set_start_values(m)) {
        model_error(m, "fmi2Reset: out of memory");
        m->state = STATE_ERROR;
        return fmi2Error;
    }
    m->state = STATE_INSTANTIATED;
    return fmi2OK;
}

/* ---- getting and setting variables (FMI 2.0.4, 2.1.7) ------------------------------- */

static int vr_in_range(ModelInstance *m, const char *function, fmi2ValueReference vr, size_t n) {
    if ((size_t)vr >= n) {
        model_error(m, "%s: value reference %u is out of range (this FMU has %u)", function,
                    (unsigned)vr, (unsigned)n);
        return 0;
    }
    return 1;
}

#if N_STATES > 0
static int is_state_vr(fmi2ValueReference vr) {
    size_t k;
    for (k = 0; k < N_STATES; k++) {
        if (model_state_vrs[k] == vr) return 1;
    }
    return 0;
}
#endif

/* Whether a variable may be set in the current state. Before the end of initialisation
   (Instantiated, InitializationMode): variables with initial = exact/approx or inputs,
   i.e. parameters (fixed/tunable), inputs and states (outputs with initial = exact).
   In StepComplete: inputs and tunable parameters only (FMI 2.0.4, 4.2.4, footnotes of the
   state table). Never: time (independent), constants, calculated parameters, locals and
   outputs computed by the model. Logs and returns 0 if not allowed. */
static int settable(ModelInstance *m, const char *function, const VariableInfo *info,
                    int isState) {
    const char *why = NULL;
    int ok;

    if (info->variability == VARIABILITY_CONSTANT) {
        why = "it is a constant";
    } else if (m->state == STATE_STEP_COMPLETE) {
        ok = info->causality == CAUSALITY_INPUT ||
             (info->causality == CAUSALITY_PARAMETER &&
              info->variability == VARIABILITY_TUNABLE);
        if (!ok) why = "after initialisation only inputs and tunable parameters may be set";
    } else {
        ok = info->causality == CAUSALITY_PARAMETER || info->causality == CAUSALITY_INPUT ||
             (info->causality == CAUSALITY_OUTPUT && isState);
        if (!ok) why = "it is computed by the FMU";
    }
    if (why) {
        model_error(m, "%s: variable %s (%s) cannot be set in state %s: %s", function,
                    info->name, causality_name(info->causality), state_name(m->state), why);
        return 0;
    }
    return 1;
}

/* After initialisation a tunable parameter may change: re-check the parameters so a value
   outside [min, max] is refused as it would have been at initialisation. */
static int tunable_parameter(const VariableInfo *info) {
    return info->causality == CAUSALITY_PARAMETER && info->variability == VARIABILITY_TUNABLE;
}

/* Outputs with direct feedthrough must reflect inputs set after the last step (FMI 2.0.4,
   4.2.1: fmi2GetXXX returns values computed with the actual inputs), so a set marks the
   outputs stale and the next get recomputes them. */
static void mark_outputs_stale(ModelInstance *m) {
    if (m->state & (STATE_STEP_COMPLETE | STATE_INITIALIZATION_MODE))
        ((Instance *)m)->outputsStale = 1;
}

/* In initialisation mode the outputs need the model data too: check the parameters and
   build it now (fmi2ExitInitializationMode builds it again from the final parameters). */
static int refresh_outputs(ModelInstance *m, const char *function) {
    Instance *inst = (Instance *)m;
    const unsigned long errors = inst->errorsLogged;
    if (!inst->outputsStale || !(m->state & (STATE_STEP_COMPLETE | STATE_INITIALIZATION_MODE)))
        return 1;
    if (m->state == STATE_INITIALIZATION_MODE) {
        if (model_check_parameters(m) != 0) return 0;
        release_model_data(m);
        if (model_initialize(m) != 0) {
            release_model_data(m);
            if (inst->errorsLogged == errors)
                model_error(m, "%s: model initialisation failed", function);
            return 0;
        }
    }
    inst->outputsStale = 0;
    if (model_outputs(m) != 0) {
        if (inst->errorsLogged == errors) model_error(m, "%s: computing the outputs failed", function);
        return 0;
    }
    return 1;
}

/* One get and one set for the four types: a view of a type's variables (values, infos,
   sizes) and the same checks and messages for each. */
typedef enum { VT_REAL, VT_INTEGER, VT_BOOLEAN, VT_STRING } VarType;

static const char *const GET_NAME[4] = {"fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean",
                                        "fmi2GetString"};
static const char *const SET_NAME[4] = {"fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean",
                                        "fmi2SetString"};

typedef struct {
    size_t n, size;            /* variables of the type, bytes per value */
    char *values;              /* m->r, m->i, m->b or m->s (NULL when n == 0) */
    const VariableInfo *info;
} TypeView;

static TypeView type_view(ModelInstance *m, VarType t) {
    TypeView v = {0, 0, NULL, NULL};
    switch (t) {
    case VT_REAL:
        v.n = N_REAL, v.size = sizeof(fmi2Real), v.values = (char *)m->r, v.info = model_real_info;
        break;
    case VT_INTEGER:
        v.size = sizeof(fmi2Integer);
#if N_INTEGER > 0
        v.n = N_INTEGER, v.values = (char *)m->i, v.info = model_integer_info;
#endif
        break;
    case VT_BOOLEAN:
        v.size = sizeof(fmi2Boolean);
#if N_BOOLEAN > 0
        v.n = N_BOOLEAN, v.values = (char *)m->b, v.info = model_boolean_info;
#endif
        break;
    case VT_STRING:
        v.size = sizeof(char *);
#if N_STRING > 0
        v.n = N_STRING, v.values = (char *)m->s, v.info = model_string_info;
#endif
        break;
    }
    return v;
}

static int is_state(VarType t, fmi2ValueReference vr) {
#if N_STATES > 0
    return t == VT_REAL && is_state_vr(vr);
#else
    (void)t, (void)vr;
    return 0;
#endif
}

/* Strings belong to the instance: copy all first, so running out of memory changes
   nothing. 0 after one model_error. */
static int set_strings(ModelInstance *m, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2String value[]) {
#if N_STRING > 0
    size_t k;
    char **copies = (char **)calloc(nvr, sizeof *copies);
    int failed = copies == NULL;
    for (k = 0; k < nvr && !failed; k++) {
        copies[k] = dup_string(value[k]);
        failed = copies[k] == NULL;
    }
    if (failed) {
        if (copies) {
            for (k = 0; k < nvr; k++) free(copies[k]);
            free(copies);
        }
        model_error(m, "fmi2SetString: out of memory");
        return 0;
    }
    for (k = 0; k < nvr; k++) {
        free(m->s[vr[k]]);
        m->s[vr[k]] = copies[k];
    }
    free(copies);
#else
    (void)m, (void)vr, (void)nvr, (void)value;
#endif
    return 1;
}

/* The returned strings belong to the instance; they stay valid until the variable is set
   again, the instance is reset or freed (FMI 2.0.4, 2.1.7). */
static fmi2Status get_values(fmi2Component c, VarType t, const fmi2ValueReference vr[], size_t nvr,
                             void *value) {
    const char *fn = GET_NAME[t];
    size_t k;
    TypeView v;
    ENTER(fn, MASK_Get);
    if (nvr == 0) return fmi2OK;
    if (!refresh_outputs(m, fn)) return fmi2Error;
    if (null_arg(m, fn, "vr[]", vr) || null_arg(m, fn, "value[]", value)) return fmi2Error;
    v = type_view(m, t);
    for (k = 0; k < nvr; k++) {
        if (!vr_in_range(m, fn, vr[k], v.n)) return fmi2Error;
        memcpy((char *)value + k * v.size, v.values + vr[k] * v.size, v.size);
    }
    return fmi2OK;
}

/* Checks every (vr, value) first and changes nothing unless all are acceptable, so a
   refused call leaves the instance as it was; a tunable parameter set during the run is
   checked again (model_check_parameters) and undone on failure. */
static fmi2Status set_values(fmi2Component c, VarType t, const fmi2ValueReference vr[], size_t nvr,
                             const void *value) {
    const char *fn = SET_NAME[t];
    size_t k;
    int tunableChanged = 0, inputChanged = 0;
    char *old = NULL;
    TypeView v;
    ENTER(fn, MASK_Set);
    if (nvr == 0) return fmi2OK;
    mark_outputs_stale(m);
    if (null_arg(m, fn, "vr[]", vr) || null_arg(m, fn, "value[]", value)) return fmi2Error;
    v = type_view(m, t);
    for (k = 0; k < nvr; k++) {
        const VariableInfo *info;
        if (!vr_in_range(m, fn, vr[k], v.n)) return fmi2Error;
        info = &v.info[vr[k]];
        if (!settable(m, fn, info, is_state(t, vr[k]))) return fmi2Error;
        if (t == VT_REAL && !isfinite(((const fmi2Real *)value)[k])) {
            model_error(m, "%s: value %g for %s is not finite", fn, ((const fmi2Real *)value)[k],
                        info->name);
            return fmi2Error;
        }
        if (t == VT_STRING && !((const fmi2String *)value)[k]) {
            model_error(m, "%s: value for %s is NULL", fn, info->name);
            return fmi2Error;
        }
        tunableChanged |= m->state == STATE_STEP_COMPLETE && tunable_parameter(info);
        inputChanged |= info->causality == CAUSALITY_INPUT;
    }
    if (t == VT_STRING) /* no string parameter is checked by the models */
        return set_strings(m, vr, nvr, (const fmi2String *)value) ? fmi2OK : fmi2Error;
    if (tunableChanged) {
        old = (char *)malloc(nvr * v.size);
        if (!old) {
            model_error(m, "%s: out of memory", fn);
            return fmi2Error;
        }
        for (k = 0; k < nvr; k++) memcpy(old + k * v.size, v.values + vr[k] * v.size, v.size);
    }
    for (k = 0; k < nvr; k++) {
        if (t == VT_BOOLEAN) {
            const fmi2Boolean b = ((const fmi2Boolean *)value)[k] ? fmi2True : fmi2False;
            memcpy(v.values + vr[k] * v.size, &b, v.size);
        } else {
            memcpy(v.values + vr[k] * v.size, (const char *)value + k * v.size, v.size);
        }
    }
    if (tunableChanged && model_check_parameters(m) != 0) {
        for (k = nvr; k-- > 0;) /* reverse: repeated vrs */
            memcpy(v.values + vr[k] * v.size, old + k * v.size, v.size);
        free(old);
        return fmi2Error;
    }
    free(old);
    if (t == VT_REAL && inputChanged) m->inputTime = m->r[0]; /* a first-order hold restarts from now */
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    return get_values(c, VT_REAL, vr, nvr, value);
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    return get_values(c, VT_INTEGER, vr, nvr, value);
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    return get_values(c, VT_BOOLEAN, vr, nvr, value);
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    return get_values(c, VT_STRING, vr, nvr, (void *)value);
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    return set_values(c, VT_REAL, vr, nvr, value);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    return set_values(c, VT_INTEGER, vr, nvr, value);
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    return set_values(c, VT_BOOLEAN, vr, nvr, value);
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    return set_values(c, VT_STRING, vr, nvr, (const void *)value);
}

/* ---- FMU state (FMI 2.0.4, 2.1.8) --------------------------------------------------- */

static void snapshot_free_strings(SnapshotPayload *p) {
#if N_STRING > 0
    free_string_array(p->s);
#else
    (void)p;
#endif
}

#define FNV_OFFSET 2166136261u
static uint32_t fnv1a(uint32_t h, const void *data, size_t n) {
    const unsigned char *b = (const unsigned char *)data;
    size_t k;
    for (k = 0; k < n; k++) h = (h ^ b[k]) * 16777619u;
    return h;
}

static uint32_t payload_checksum(const SnapshotPayload *p) {
    return fnv1a(FNV_OFFSET, p, sizeof *p);
}

static uint32_t strings_checksum(const SnapshotPayload *p) {
    uint32_t h = FNV_OFFSET;
#if N_STRING > 0
    size_t k;
    for (k = 0; k < N_STRING; k++)
        if (p->s[k]) h = fnv1a(h, p->s[k], strlen(p->s[k]) + 1);
#else
    (void)p;
#endif
    return h;
}

static void seal(Snapshot *st) {
    st->h.checksum = payload_checksum(&st->p);
    st->h.strings_checksum = strings_checksum(&st->p);
}

/* A NUL-padded field of a header that may come from anywhere: printable, bounded. */
static void field_text(char out[ID_CHARS], const char *field) {
    size_t k;
    for (k = 0; k + 1 < ID_CHARS && field[k]; k++)
        out[k] = (field[k] >= 32 && field[k] < 127) ? field[k] : '?';
    out[k] = '\0';
}

static void fill_header(SnapshotHeader *h) {
    h->magic = SNAPSHOT_MAGIC;
    h->version = SNAPSHOT_VERSION;
    h->size = (uint64_t)sizeof(Snapshot);
    memset(h->guid, 0, ID_CHARS);
    memcpy(h->guid, MODEL_GUID, sizeof MODEL_GUID);
    memset(h->identifier, 0, ID_CHARS);
    memcpy(h->identifier, MODEL_IDENTIFIER_STRING, sizeof MODEL_IDENTIFIER_STRING);
}

/* The state if it is one of this FMU's, intact; else NULL with the reason logged. The
   header is checked before the payload is touched (a foreign state may be smaller). */
static Snapshot *as_snapshot(ModelInstance *m, const char *function, fmi2FMUstate ptr) {
    Snapshot *st = (Snapshot *)ptr;
    SnapshotHeader own;
    char guid[ID_CHARS];
    if (!st) {
        model_error(m, "%s: FMUstate is NULL", function);
        return NULL;
    }
    if (st->h.magic != SNAPSHOT_MAGIC) {
        model_error(m, "%s: FMUstate was not created by a railfmu FMU (or was freed)", function);
        return NULL;
    }
    if (st->h.version != SNAPSHOT_VERSION) {
        model_error(m, "%s: FMUstate has format version %lu, this FMU uses %lu", function,
                    (unsigned long)st->h.version, (unsigned long)SNAPSHOT_VERSION);
        return NULL;
    }
    fill_header(&own); /* whole fields, padding included: nothing unchecked in the header */
    if (memcmp(st->h.guid, own.guid, ID_CHARS) != 0 ||
        memcmp(st->h.identifier, own.identifier, ID_CHARS) != 0) {
        char ident[ID_CHARS];
        field_text(ident, st->h.identifier);
        field_text(guid, st->h.guid);
        model_error(m, "%s: FMUstate was saved by another FMU (%s, GUID %s), not by %s (GUID %s)",
                    function, ident, guid, MODEL_IDENTIFIER_STRING, MODEL_GUID);
        return NULL;
    }
    if (st->h.size != (uint64_t)sizeof(Snapshot)) {
        model_error(m, "%s: FMUstate has %lu bytes, this FMU's have %lu", function,
                    (unsigned long)st->h.size, (unsigned long)sizeof(Snapshot));
        return NULL;
    }
    if (st->h.checksum != payload_checksum(&st->p) ||
        st->h.strings_checksum != strings_checksum(&st->p)) {
        model_error(m, "%s: FMUstate is damaged (checksum mismatch)", function);
        return NULL;
    }
    return st;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    Snapshot *st;
    SnapshotPayload *p;
    ENTER("fmi2GetFMUstate", MASK_FMUstate);
    if (null_arg(m, "fmi2GetFMUstate", "FMUstate", FMUstate)) return fmi2Error;

    /* *FMUstate != NULL: a state returned before and not freed, to be overwritten */
    if (*FMUstate) {
        st = as_snapshot(m, "fmi2GetFMUstate", *FMUstate);
        if (!st) return fmi2Error;
        snapshot_free_strings(&st->p);
    } else {
        st = (Snapshot *)calloc(1, sizeof *st);
        if (!st) {
            model_error(m, "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
        fill_header(&st->h);
    }
    p = &st->p;
    p->state = m->state;
    p->startTime = m->startTime;
    p->stopTime = m->stopTime;
    p->stopTimeDefined = m->stopTimeDefined;
    p->lastSuccessfulTime = m->lastSuccessfulTime;
    p->inputTime = m->inputTime;
    p->stepSize = m->stepSize;
    p->terminateRequested = inst->terminateRequested;
    p->terminateTime = inst->terminateTime;
    memcpy(p->r, m->r, sizeof p->r);
#if N_INTEGER > 0
    memcpy(p->i, m->i, sizeof p->i);
#endif
#if N_BOOLEAN > 0
    memcpy(p->b, m->b, sizeof p->b);
#endif
#if N_STRING > 0
    {
        size_t k;
        for (k = 0; k < N_STRING; k++) {
            p->s[k] = dup_string(m->s[k]);
            if (!p->s[k]) {
                snapshot_free_strings(p);
                st->h.magic = 0;
                free(st);
                *FMUstate = NULL;
                model_error(m, "fmi2GetFMUstate: out of memory");
                return fmi2Error;
            }
        }
    }
#endif
    seal(st);
    *FMUstate = (fmi2FMUstate)st;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    const Snapshot *st;
    const SnapshotPayload *p;
    ENTER("fmi2SetFMUstate", MASK_FMUstate);
    st = as_snapshot(m, "fmi2SetFMUstate", FMUstate);
    if (!st) return fmi2Error; /* nothing changed: the instance goes on as before */
    p = &st->p;

#if N_STRING > 0
    {
        /* copy the strings first, so running out of memory changes nothing */
        char *copies[N_STRING];
        size_t k;
        int failed = 0;
        for (k = 0; k < N_STRING; k++) {
            copies[k] = failed ? NULL : dup_string(p->s[k]);
            if (!copies[k]) failed = 1;
        }
        if (failed) {
            for (k = 0; k < N_STRING; k++) free(copies[k]);
            model_error(m, "fmi2SetFMUstate: out of memory");
            return fmi2Error;
        }
        free_strings(m);
        for (k = 0; k < N_STRING; k++) m->s[k] = copies[k];
    }
#endif
    memcpy(m->r, p->r, sizeof m->r);
#if N_INTEGER > 0
    memcpy(m->i, p->i, sizeof m->i);
#endif
#if N_BOOLEAN > 0
    memcpy(m->b, p->b, sizeof m->b);
#endif
    m->startTime = p->startTime;
    m->stopTime = p->stopTime;
    m->stopTimeDefined = p->stopTimeDefined;
    m->lastSuccessfulTime = p->lastSuccessfulTime;
    m->inputTime = p->inputTime;
    m->stepSize = p->stepSize;
    inst->terminateRequested = p->terminateRequested;
    inst->terminateTime = p->terminateTime;
    m->state = p->state;

    /* modelData is not part of the state: drop it, and rebuild it from the restored
       parameters if the restored state is past initialisation (before that,
       fmi2ExitInitializationMode builds it with model_initialize). */
    release_model_data(m);
    if (m->state & (STATE_STEP_COMPLETE | STATE_STEP_FAILED | STATE_TERMINATED)) {
        if (model_state_restored(m) != 0) {
            release_model_data(m);
            model_error(m, "fmi2SetFMUstate: rebuilding the model data failed");
            m->state = STATE_ERROR;
            return fmi2Error;
        }
    }
    mark_outputs_stale(m); /* the state may have been saved with inputs set after a step */
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    Snapshot *st;
    ENTER("fmi2FreeFMUstate", MASK_FMUstate);
    if (null_arg(m, "fmi2FreeFMUstate", "FMUstate", FMUstate)) return fmi2Error;
    if (!*FMUstate) return fmi2OK; /* like free(NULL) */
    st = as_snapshot(m, "fmi2FreeFMUstate", *FMUstate);
    if (!st) return fmi2Error;
    snapshot_free_strings(&st->p);
    st->h.magic = 0; /* a second free is caught (as long as the memory is not reused) */
    free(st);
    *FMUstate = NULL;
    return fmi2OK;
}

/* Serialized layout, native byte order (a state is restored on the platform that saved it;
   the version word read back in the wrong byte order fails the header check):
     "RFMU"  uint32 format version  uint32 total size in bytes (this header to the CRC)
     uint32 strlen(MODEL_IDENTIFIER)  identifier bytes  uint32 strlen(MODEL_GUID)  GUID bytes
     uint32 N_REAL N_INTEGER N_BOOLEAN N_STRING
     int32 state  int32 stopTimeDefined  double startTime stopTime lastSuccessfulTime inputTime
     stepSize  int32 terminateRequested  double terminateTime
     double r[N_REAL]  int32 i[N_INTEGER]  int32 b[N_BOOLEAN]
     per string: uint32 length, bytes (no terminator)
     uint32 CRC-32 (IEEE, as zlib.crc32) of every byte before it
   The size and CRC come first in the checks: a truncated or damaged blob is refused before
   any of its fields is believed. */
#define SER_MAGIC "RFMU"
#define SER_VERSION 3u /* 2: stepSize, the terminate request; 3: size, identifier, CRC-32 */

/* CRC-32, four bits at a time: a 16-entry constant table (no global mutable state) */
static uint32_t crc32_update(uint32_t crc, const unsigned char *b, size_t n) {
    static const uint32_t t[16] = {
        0x00000000u, 0x1db71064u, 0x3b6e20c8u, 0x26d930acu, 0x76dc4190u, 0x6b6b51f4u,
        0x4db26158u, 0x5005713cu, 0xedb88320u, 0xf00f9344u, 0xd6d6a3e8u, 0xcb61b38cu,
        0x9b64c2b0u, 0x86d3d2d4u, 0xa00ae278u, 0xbdbdf21cu};
    size_t k;
    crc = ~crc;
    for (k = 0; k < n; k++) {
        crc ^= b[k];
        crc = (crc >> 4) ^ t[crc & 15u];
        crc = (crc >> 4) ^ t[crc & 15u];
    }
    return ~crc;
}

typedef struct {
    unsigned char *w;       /* writing: destination (NULL: only count) */
    const unsigned char *r; /* reading: source */
    size_t pos, size;       /* bytes done, bytes available when reading */
    int ok;
} Cursor;

static void put(Cursor *cu, const void *p, size_t n) {
    if (cu->w) memcpy(cu->w + cu->pos, p, n);
    cu->pos += n;
}

static void get(Cursor *cu, void *p, size_t n) {
    if (!cu->ok || n > cu->size - cu->pos) {
        cu->ok = 0;
        memset(p, 0, n);
        return;
    }
    memcpy(p, cu->r + cu->pos, n);
    cu->pos += n;
}

static void put_u32(Cursor *cu, uint32_t v) { put(cu, &v, sizeof v); }
static void put_i32(Cursor *cu, int32_t v) { put(cu, &v, sizeof v); }
static uint32_t get_u32(Cursor *cu) {
    uint32_t v;
    get(cu, &v, sizeof v);
    return v;
}
static int32_t get_i32(Cursor *cu) {
    int32_t v;
    get(cu, &v, sizeof v);
    return v;
}

/* total: the whole blob's size (0 while counting) */
static void write_header(Cursor *cu, uint32_t total) {
    put(cu, SER_MAGIC, 4);
    put_u32(cu, SER_VERSION);
    put_u32(cu, total);
    put_u32(cu, (uint32_t)strlen(MODEL_IDENTIFIER_STRING));
    put(cu, MODEL_IDENTIFIER_STRING, strlen(MODEL_IDENTIFIER_STRING));
    put_u32(cu, (uint32_t)strlen(MODEL_GUID));
    put(cu, MODEL_GUID, strlen(MODEL_GUID));
    put_u32(cu, (uint32_t)N_REAL);
    put_u32(cu, (uint32_t)N_INTEGER);
    put_u32(cu, (uint32_t)N_BOOLEAN);
    put_u32(cu, (uint32_t)N_STRING);
}

/* With cu->w == NULL this only counts the bytes (the CRC included). */
static void write_snapshot(Cursor *cu, const SnapshotPayload *st, uint32_t total) {
    size_t k;
    write_header(cu, total);
    put_i32(cu, (int32_t)st->state);
    put_i32(cu, (int32_t)st->stopTimeDefined);
    put(cu, &st->startTime, sizeof(double));
    put(cu, &st->stopTime, sizeof(double));
    put(cu, &st->lastSuccessfulTime, sizeof(double));
    put(cu, &st->inputTime, sizeof(double));
    put(cu, &st->stepSize, sizeof(double));
    put_i32(cu, (int32_t)st->terminateRequested);
    put(cu, &st->terminateTime, sizeof(double));
    put(cu, st->r, sizeof st->r);
    (void)k;
#if N_INTEGER > 0
    for (k = 0; k < N_INTEGER; k++) put_i32(cu, (int32_t)st->i[k]);
#endif
#if N_BOOLEAN > 0
    for (k = 0; k < N_BOOLEAN; k++) put_i32(cu, (int32_t)st->b[k]);
#endif
#if N_STRING > 0
    for (k = 0; k < N_STRING; k++) {
        size_t n = st->s[k] ? strlen(st->s[k]) : 0;
        put_u32(cu, (uint32_t)n);
        if (n) put(cu, st->s[k], n);
    }
#endif
    put_u32(cu, cu->w ? crc32_update(0, cu->w, cu->pos) : 0u);
}

static size_t serialized_size(const SnapshotPayload *st) {
    Cursor cu = {NULL, NULL, 0, 0, 1};
    write_snapshot(&cu, st, 0);
    return cu.pos;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    const Snapshot *st;
    ENTER("fmi2SerializedFMUstateSize", MASK_FMUstate);
    st = as_snapshot(m, "fmi2SerializedFMUstateSize", FMUstate);
    if (!st || null_arg(m, "fmi2SerializedFMUstateSize", "size", size)) return fmi2Error;
    *size = serialized_size(&st->p);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    const Snapshot *st;
    size_t needed;
    Cursor cu = {NULL, NULL, 0, 0, 1};
    ENTER("fmi2SerializeFMUstate", MASK_FMUstate);
    st = as_snapshot(m, "fmi2SerializeFMUstate", FMUstate);
    if (!st || null_arg(m, "fmi2SerializeFMUstate", "serializedState", serializedState))
        return fmi2Error;
    needed = serialized_size(&st->p);
    if (size < needed) {
        model_error(m, "fmi2SerializeFMUstate: buffer of %lu bytes is too small (%lu needed, "
                       "see fmi2SerializedFMUstateSize)",
                    (unsigned long)size, (unsigned long)needed);
        return fmi2Error;
    }
    if (needed > 0xffffffffu) {
        model_error(m, "fmi2SerializeFMUstate: the state is larger than 4 GiB");
        return fmi2Error;
    }
    cu.w = (unsigned char *)serializedState;
    write_snapshot(&cu, &st->p, (uint32_t)needed);
    return fmi2OK;
}

static int deser_fail(ModelInstance *m, const char *what) {
    model_error(m, "fmi2DeSerializeFMUstate: %s", what);
    return 0;
}

/* Reads a serialized state into st (strings malloc'ed). Returns 1 on success. */
static int read_snapshot(ModelInstance *m, Cursor *cu, SnapshotPayload *st) {
    char magic[4];
    uint32_t version, total, nr, ni, nb, ns, nid, nguid, crc;
    char guid[sizeof MODEL_GUID];
    char ident[sizeof MODEL_IDENTIFIER_STRING];
    size_t k;
    int32_t state;

    get(cu, magic, 4);
    if (!cu->ok || memcmp(magic, SER_MAGIC, 4) != 0)
        return deser_fail(m, "not a serialized railfmu FMU state (bad magic)");
    version = get_u32(cu);
    if (!cu->ok || version != SER_VERSION) {
        model_error(m, "fmi2DeSerializeFMUstate: format version %lu or other byte order; this "
                       "FMU reads version %lu", (unsigned long)version, (unsigned long)SER_VERSION);
        return 0;
    }
    total = get_u32(cu);
    if (!cu->ok || total != cu->size) {
        model_error(m, "fmi2DeSerializeFMUstate: %lu bytes given, the state says it has %lu "
                       "(truncated or with trailing bytes)",
                    (unsigned long)cu->size, (unsigned long)total);
        return 0;
    }
    if (cu->size < 16) return deser_fail(m, "truncated data");
    memcpy(&crc, cu->r + cu->size - 4, 4);
    if (crc != crc32_update(0, cu->r, cu->size - 4))
        return deser_fail(m, "the state is damaged (CRC-32 mismatch)");
    cu->size -= 4; /* the payload ends before the CRC */

    nid = get_u32(cu);
    if (!cu->ok || nid != strlen(MODEL_IDENTIFIER_STRING))
        return deser_fail(m, "the state was saved by another FMU (model identifier differs)");
    get(cu, ident, nid);
    if (!cu->ok || memcmp(ident, MODEL_IDENTIFIER_STRING, nid) != 0)
        return deser_fail(m, "the state was saved by another FMU (model identifier differs)");
    nguid = get_u32(cu);
    if (!cu->ok || nguid != strlen(MODEL_GUID))
        return deser_fail(m, "the state was saved by another FMU (GUID differs)");
    get(cu, guid, nguid);
    if (!cu->ok || memcmp(guid, MODEL_GUID, nguid) != 0)
        return deser_fail(m, "the state was saved by another FMU (GUID differs)");
    nr = get_u32(cu);
    ni = get_u32(cu);
    nb = get_u32(cu);
    ns = get_u32(cu);
    if (!cu->ok || nr != N_REAL || ni != N_INTEGER || nb != N_BOOLEAN || ns != N_STRING)
        return deser_fail(m, "the state has other variable counts than this FMU");

    state = get_i32(cu);
    if (!cu->ok || !is_valid_state(state)) return deser_fail(m, "invalid instance state");
    st->state = (ModelState)state;
    st->stopTimeDefined = get_i32(cu) ? fmi2True : fmi2False;
    get(cu, &st->startTime, sizeof(double));
    get(cu, &st->stopTime, sizeof(double));
    get(cu, &st->lastSuccessfulTime, sizeof(double));
    get(cu, &st->inputTime, sizeof(double));
    get(cu, &st->stepSize, sizeof(double));
    st->terminateRequested = get_i32(cu) != 0;
    get(cu, &st->terminateTime, sizeof(double));
    get(cu, st->r, sizeof st->r);
    (void)k;
#if N_INTEGER > 0
    for (k = 0; k < N_INTEGER; k++) st->i[k] = (fmi2Integer)get_i32(cu);
#endif
#if N_BOOLEAN > 0
    for (k = 0; k < N_BOOLEAN; k++) st->b[k] = get_i32(cu) ? fmi2True : fmi2False;
#endif
#if N_STRING > 0
    for (k = 0; k < N_STRING; k++) {
        uint32_t n = get_u32(cu);
        if (!cu->ok || n > cu->size - cu->pos) return deser_fail(m, "truncated data");
        st->s[k] = (char *)malloc((size_t)n + 1);
        if (!st->s[k]) return deser_fail(m, "out of memory");
        get(cu, st->s[k], n);
        st->s[k][n] = '\0';
    }
#endif
    if (!cu->ok) return deser_fail(m, "truncated data");
    if (cu->pos != cu->size) return deser_fail(m, "trailing bytes after the state");
    return 1;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    Snapshot *st;
    Cursor cu = {NULL, NULL, 0, 0, 1};
    ENTER("fmi2DeSerializeFMUstate", MASK_FMUstate);
    if (null_arg(m, "fmi2DeSerializeFMUstate", "serializedState", serializedState) ||
        null_arg(m, "fmi2DeSerializeFMUstate", "FMUstate", FMUstate))
        return fmi2Error;

    /* always a new state object (FMI 2.0.4, 2.1.8: "constructs a copy of the FMU state");
       *FMUstate on entry is not looked at */
    st = (Snapshot *)calloc(1, sizeof *st);
    if (!st) {
        model_error(m, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    cu.r = (const unsigned char *)serializedState;
    cu.size = size;
    if (!read_snapshot(m, &cu, &st->p)) {
        snapshot_free_strings(&st->p);
        free(st);
        return fmi2Error;
    }
    fill_header(&st->h);
    seal(st);
    *FMUstate = (fmi2FMUstate)st;
    return fmi2OK;
}

/* ---- partial derivatives, input/output derivatives: not provided -------------------- */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    Instance *inst = (Instance *)c;
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown;
    (void)dvUnknown;
    if (inst)
        model_error(&inst->m, "fmi2GetDirectionalDerivative: not provided by this FMU "
                              "(providesDirectionalDerivative = false)");
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    (void)vr, (void)nvr, (void)order, (void)value;
    if (inst)
        model_error(&inst->m, "fmi2SetRealInputDerivatives: not supported by this FMU "
                              "(canInterpolateInputs = false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    (void)vr, (void)nvr, (void)order, (void)value;
    if (inst)
        model_error(&inst->m, "fmi2GetRealOutputDerivatives: not supported by this FMU "
                              "(MaxOutputDerivativeOrder = 0)");
    return fmi2Error;
}

/* ---- stepping (FMI 2.0.4, 4.2.2) ---------------------------------------------------- */

#if N_STATES > 0
/* One classic RK4 step of size dt from time t: x <- x + dt/6 (k1 + 2 k2 + 2 k3 + k4). */
static void rk4_step(ModelInstance *m, double t, double dt, double *x) {
    double k1[N_STATES], k2[N_STATES], k3[N_STATES], k4[N_STATES], xt[N_STATES];
    size_t j;

    model_derivatives(m, t, x, k1);
    for (j = 0; j < N_STATES; j++) xt[j] = x[j] + 0.5 * dt * k1[j];
    model_derivatives(m, t + 0.5 * dt, xt, k2);
    for (j = 0; j < N_STATES; j++) xt[j] = x[j] + 0.5 * dt * k2[j];
    model_derivatives(m, t + 0.5 * dt, xt, k3);
    for (j = 0; j < N_STATES; j++) xt[j] = x[j] + dt * k3[j];
    model_derivatives(m, t + dt, xt, k4);
    for (j = 0; j < N_STATES; j++)
        x[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
}

/* Integrates the states over [t0, t0 + h] in n equal sub-steps. Returns 1 on success. */
static int integrate(ModelInstance *m, double t0, double h) {
    const double hmax = m->r[VR_INTEGRATOR_STEP];
    double x[N_STATES];
    double q, dt;
    unsigned long n, step;
    size_t j;

    /* n = ceil(h / hmax - 1e-9), at least 1 (the 1e-9 keeps h = k * hmax from becoming
       k + 1 sub-steps through rounding); computed without libm */
    q = h / hmax - 1e-9;
    if (!(q < 1e9)) {
        model_error(m, "fmi2DoStep: step %g needs more than 1e9 internal steps of %s = %g", h,
                    model_real_info[VR_INTEGRATOR_STEP].name, hmax);
        return 0;
    }
    n = q > 0 ? (unsigned long)q : 0;
    if ((double)n < q) n++;
    if (n < 1) n = 1;
    dt = h / (double)n;

    for (j = 0; j < N_STATES; j++) x[j] = m->r[model_state_vrs[j]];
    for (step = 0; step < n; step++) {
        const double t = t0 + (double)step * dt;
        rk4_step(m, t, dt, x);
        for (j = 0; j < N_STATES; j++) {
            if (!isfinite(x[j])) {
                model_error(m, "fmi2DoStep: state %s became %g in the internal step from "
                               "t = %.17g to %.17g",
                            model_real_info[model_state_vrs[j]].name, x[j], t, t + dt);
                /* leave the non-finite value visible for debugging (fmi2GetReal is
                   allowed in state Error) */
                for (j = 0; j < N_STATES; j++) m->r[model_state_vrs[j]] = x[j];
                return 0;
            }
        }
    }
    for (j = 0; j < N_STATES; j++) m->r[model_state_vrs[j]] = x[j];
    return 1;
}
#endif

/* The model called model_terminate: the step ends at r[0] with fmi2Discard, and
   fmi2GetBooleanStatus(fmi2Terminated) says why (FMI 2.0.4, 4.2.3). State StepFailed
   allows exactly what the master needs next: get outputs and status, fmi2Terminate. */
static fmi2Status end_simulation(ModelInstance *m, const char *function) {
    m->lastSuccessfulTime = m->r[0];
    m->state = STATE_STEP_FAILED;
    model_log(m, fmi2Discard, "logEvents",
              "%s: the model ended the simulation at t = %.17g (fmi2Discard, terminated)",
              function, m->r[0]);
    return fmi2Discard;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    const double t0 = currentCommunicationPoint, h = communicationStepSize;
    ENTER("fmi2DoStep", MASK_DoStep);
    (void)noSetFMUStatePriorToCurrentPoint; /* states are cheap to keep */

    /* Argument errors change nothing: the instance stays in StepComplete. */
    if (!(h > 0.0) || !isfinite(h)) {
        model_error(m, "fmi2DoStep: communicationStepSize %g must be > 0", h);
        return fmi2Error;
    }
    if (!isfinite(t0) || !same_time(t0, m->r[0], h)) {
        model_error(m, "fmi2DoStep: currentCommunicationPoint %.17g differs from the FMU time "
                       "%.17g (steps must follow each other)",
                    t0, m->r[0]);
        return fmi2Error;
    }
    if (m->stopTimeDefined && t0 + h > m->stopTime && !same_time(t0 + h, m->stopTime, h)) {
        model_error(m, "fmi2DoStep: step to t = %.17g goes past stopTime %.17g", t0 + h,
                    m->stopTime);
        return fmi2Error;
    }

    /* the model asked to end before this step (at initialisation, or at a get after a
       set): nothing is computed, the FMU stays at r[0] */
    if (inst->terminateRequested) return end_simulation(m, "fmi2DoStep");
#if defined(MODEL_STEP_BEGIN) && MODEL_STEP_BEGIN
    if (model_step_begin(m) != 0) return fmi2Error;
#endif

    /* r[0] stays t0 during the integration (model.h: inputs with first-order hold use
       t - r[0]); a failure below leaves the instance in state Error. */
#if N_STATES > 0
    if (!integrate(m, t0, h)) {
        m->state = STATE_ERROR;
        return fmi2Error;
    }
#endif
    m->r[0] = t0 + h; /* not r[0] += h: no drift from the FMU's own time */
    m->stepSize = h;
    if (model_outputs(m) != 0) {
        model_error(m, "fmi2DoStep: computing the outputs at t = %.17g failed", m->r[0]);
        m->state = STATE_ERROR;
        return fmi2Error;
    }
    if (inst->terminateRequested) {
        /* the model reached terminateTime (in [t0, t0 + h]) and computed its outputs there */
        const double te = inst->terminateTime;
        m->r[0] = te < t0 ? t0 : (te > t0 + h ? t0 + h : te);
    }
    if (!outputs_finite(m, "fmi2DoStep")) {
        m->state = STATE_ERROR;
        return fmi2Error;
    }
    inst->outputsStale = 0;
    if (inst->terminateRequested) return end_simulation(m, "fmi2DoStep");
    m->lastSuccessfulTime = m->r[0];
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst)
        model_error(&inst->m, "fmi2CancelStep: this FMU does not step asynchronously "
                              "(canRunAsynchronuously = false), there is nothing to cancel");
    return fmi2Error;
}

/* ---- status (FMI 2.0.4, 4.2.3) ------------------------------------------------------ */

/* A status kind a function does not deliver: fmi2Discard, as the standard says. */
static fmi2Status unsupported_kind(ModelInstance *m, const char *function, fmi2StatusKind s) {
    model_log(m, fmi2Discard, "logStatusWarning",
              "%s: status kind %d is not provided by this function", function, (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    ENTER("fmi2GetStatus", MASK_Status);
    if (null_arg(m, "fmi2GetStatus", "value", value)) return fmi2Error;
    /* fmi2DoStepStatus only has a meaning after fmi2DoStep returned fmi2Pending, which this
       FMU never does */
    return unsupported_kind(m, "fmi2GetStatus", s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    ENTER("fmi2GetRealStatus", MASK_Status);
    if (null_arg(m, "fmi2GetRealStatus", "value", value)) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = m->lastSuccessfulTime;
        return fmi2OK;
    }
    return unsupported_kind(m, "fmi2GetRealStatus", s);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    ENTER("fmi2GetIntegerStatus", MASK_Status);
    if (null_arg(m, "fmi2GetIntegerStatus", "value", value)) return fmi2Error;
    return unsupported_kind(m, "fmi2GetIntegerStatus", s); /* no integer status kinds */
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    ENTER("fmi2GetBooleanStatus", MASK_Status);
    if (null_arg(m, "fmi2GetBooleanStatus", "value", value)) return fmi2Error;
    if (s == fmi2Terminated) {
        /* true once the model asked to end (model_terminate); fmi2DoStep returned or will
           return fmi2Discard */
        *value = inst->terminateRequested ? fmi2True : fmi2False;
        return fmi2OK;
    }
    return unsupported_kind(m, "fmi2GetBooleanStatus", s);
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    ENTER("fmi2GetStringStatus", MASK_Status);
    if (null_arg(m, "fmi2GetStringStatus", "value", value)) return fmi2Error;
    /* fmi2PendingStatus: only while fmi2DoStep is pending, which never happens */
    return unsupported_kind(m, "fmi2GetStringStatus", s);
}
