/* A minimal FMI 2.0 Co-Simulation host: runs a fixed scenario on each FMU binary it is given
 * and writes the outputs, so the win64 DLL (under wine) and the linux64 .so of one FMU can
 * be compared number by number (tests/test_win64.py). The same file compiles natively
 * (dlopen) and with mingw-w64 (LoadLibrary/GetProcAddress); all FMUs run in one process,
 * because starting wine is what costs time.
 *
 *   win64_host SCENARIO
 *
 * SCENARIO (text, one item a line; doubles as the 16 hex digits of their IEEE bits, so
 * both hosts read exactly the same numbers):
 *   fmu LIBRARY IDENTIFIER GUID RESOURCE_URI OUTPUT_FILE
 *   set r|i|b VR HEXBITS|INT    before initialisation (parameters, initial values)
 *   set s VR TEXT               the rest of the line
 *   steps N H_HEXBITS
 *   rollback K                  optional: after step K save the FMU state (serialized and
 *                               read back), after step N restore it and step K+1..N again
 *   in r|i|b VR                 one line per input, in the order of the "u" lines
 *   out r|i|b VR                one line per output
 *   inputs
 *   u HEXBITS...                N lines, the inputs set before step k
 *   end
 * OUTPUT_FILE: rows of doubles (native byte order), one row after initialisation and one
 * after each step (then one per step replayed after the rollback); a step that does not
 * return fmi2OK ends the rows.
 * Exit status: 0, or 1 with a line on stderr.
 */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *symbol(Library lib, const char *name) { return (void *)GetProcAddress(lib, name); }
static void close_library(Library lib) { FreeLibrary(lib); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(Library lib, const char *name) { return dlsym(lib, name); }
static void close_library(Library lib) { dlclose(lib); }
#endif

#define MAX_VARS 256
#define LINE 4096

typedef struct {
    char type; /* r, i or b */
    fmi2ValueReference vr;
} Var;

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setupExperiment;
    fmi2EnterInitializationModeTYPE *enterInitializationMode;
    fmi2ExitInitializationModeTYPE *exitInitializationMode;
    fmi2SetRealTYPE *setReal;
    fmi2SetIntegerTYPE *setInteger;
    fmi2SetBooleanTYPE *setBoolean;
    fmi2SetStringTYPE *setString;
    fmi2GetRealTYPE *getReal;
    fmi2GetIntegerTYPE *getInteger;
    fmi2GetBooleanTYPE *getBoolean;
    fmi2DoStepTYPE *doStep;
    fmi2FreeInstanceTYPE *freeInstance;
    fmi2GetFMUstateTYPE *getFMUstate;
    fmi2SetFMUstateTYPE *setFMUstate;
    fmi2FreeFMUstateTYPE *freeFMUstate;
    fmi2SerializedFMUstateSizeTYPE *serializedFMUstateSize;
    fmi2SerializeFMUstateTYPE *serializeFMUstate;
    fmi2DeSerializeFMUstateTYPE *deSerializeFMUstate;
} Api;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "%s [%s, status %d]: ", name, category, (int)status);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static int fail(const char *fmt, ...) {
    va_list ap;
    fputs("win64_host: ", stderr);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    return 1;
}

static double from_hex(const char *s) {
    uint64_t bits = 0;
    double d;
    int n;
    for (n = 0; n < 16; n++) {
        char c = s[n];
        bits = bits << 4 | (uint64_t)(c <= '9' ? c - '0' : (c | 0x20) - 'a' + 10);
    }
    memcpy(&d, &bits, sizeof d);
    return d;
}

static void chomp(char *s) {
    size_t n = strlen(s);
    while (n > 0 && (s[n - 1] == '\n' || s[n - 1] == '\r')) s[--n] = '\0';
}

static int load(Library lib, Api *api) {
#define LOAD(field, name)                                                                  \
    if (!(*(void **)&api->field = symbol(lib, name))) return fail("no %s in the library", name)
    LOAD(instantiate, "fmi2Instantiate");
    LOAD(setupExperiment, "fmi2SetupExperiment");
    LOAD(enterInitializationMode, "fmi2EnterInitializationMode");
    LOAD(exitInitializationMode, "fmi2ExitInitializationMode");
    LOAD(setReal, "fmi2SetReal");
    LOAD(setInteger, "fmi2SetInteger");
    LOAD(setBoolean, "fmi2SetBoolean");
    LOAD(setString, "fmi2SetString");
    LOAD(getReal, "fmi2GetReal");
    LOAD(getInteger, "fmi2GetInteger");
    LOAD(getBoolean, "fmi2GetBoolean");
    LOAD(doStep, "fmi2DoStep");
    LOAD(freeInstance, "fmi2FreeInstance");
    LOAD(getFMUstate, "fmi2GetFMUstate");
    LOAD(setFMUstate, "fmi2SetFMUstate");
    LOAD(freeFMUstate, "fmi2FreeFMUstate");
    LOAD(serializedFMUstateSize, "fmi2SerializedFMUstateSize");
    LOAD(serializeFMUstate, "fmi2SerializeFMUstate");
    LOAD(deSerializeFMUstate, "fmi2DeSerializeFMUstate");
#undef LOAD
    return 0;
}

/* Sets one variable from its text value (hex bits for r, an integer for i and b). */
static fmi2Status set_var(const Api *api, fmi2Component c, Var v, const char *text) {
    if (v.type == 'r') {
        fmi2Real x = from_hex(text);
        return api->setReal(c, &v.vr, 1, &x);
    }
    if (v.type == 'i') {
        fmi2Integer x = (fmi2Integer)strtol(text, NULL, 10);
        return api->setInteger(c, &v.vr, 1, &x);
    }
    {
        fmi2Boolean x = strtol(text, NULL, 10) != 0;
        return api->setBoolean(c, &v.vr, 1, &x);
    }
}

static int write_row(const Api *api, fmi2Component c, const Var *out, int n_out, FILE *f) {
    double row[MAX_VARS];
    int j;
    for (j = 0; j < n_out; j++) {
        fmi2Status st;
        if (out[j].type == 'r') {
            fmi2Real x;
            st = api->getReal(c, &out[j].vr, 1, &x);
            row[j] = x;
        } else if (out[j].type == 'i') {
            fmi2Integer x;
            st = api->getInteger(c, &out[j].vr, 1, &x);
            row[j] = x;
        } else {
            fmi2Boolean x;
            st = api->getBoolean(c, &out[j].vr, 1, &x);
            row[j] = x;
        }
        if (st != fmi2OK) return fail("get of output %d failed", j);
    }
    return fwrite(row, sizeof(double), (size_t)n_out, f) == (size_t)n_out ? 0 : fail("write failed");
}

/* Steps from..to-1 with the inputs u[k]; 1 when a step did not return fmi2OK (the rows end),
   -1 on an error (logged). */
static int run_steps(const Api *api, fmi2Component c, char **u, long from, long to, double h, const Var *in,
                     int n_in, const Var *out, int n_out, FILE *f) {
    long k;
    for (k = from; k < to; k++) {
        char buf[LINE];
        char *tok;
        int j;
        strcpy(buf, u[k]); /* strtok writes into it: a replay reads the line again */
        tok = strtok(buf + 1, " ");
        for (j = 0; j < n_in; j++, tok = strtok(NULL, " ")) {
            if (!tok || set_var(api, c, in[j], tok) != fmi2OK) return -fail("input %d of step %ld refused", j, k);
        }
        if (api->doStep(c, (double)k * h, h, fmi2True) != fmi2OK) return 1;
        if (write_row(api, c, out, n_out, f)) return -1;
    }
    return 0;
}

/* The FMU state now, through fmi2SerializeFMUstate and back; NULL after a message. */
static fmi2FMUstate saved_state(const Api *api, fmi2Component c) {
    fmi2FMUstate s = NULL, back = NULL;
    size_t size = 0;
    fmi2Byte *bytes = NULL;
    if (api->getFMUstate(c, &s) == fmi2OK && api->serializedFMUstateSize(c, s, &size) == fmi2OK &&
        (bytes = (fmi2Byte *)malloc(size)) && api->serializeFMUstate(c, s, bytes, size) == fmi2OK &&
        api->deSerializeFMUstate(c, bytes, size, &back) != fmi2OK)
        back = NULL;
    if (s) api->freeFMUstate(c, &s);
    free(bytes);
    if (!back) fail("saving the FMU state failed");
    return back;
}

/* One "fmu" block of the scenario, from the line after "fmu" to "end". */
static int run_fmu(FILE *sc, char *header) {
    char lib_path[LINE], ident[LINE], guid[LINE], uri[LINE], out_path[LINE], line[LINE];
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    Var in[MAX_VARS], out[MAX_VARS];
    int n_in = 0, n_out = 0, rc = 1;
    long n_steps = 0, rollback = -1, n_read = 0, k;
    char **u = NULL;
    fmi2FMUstate state = NULL;
    double h = 0.0;
    Library lib;
    Api api;
    fmi2Component c = NULL;
    FILE *f = NULL;

    if (sscanf(header, "fmu %4095s %4095s %4095s %4095s %4095s", lib_path, ident, guid, uri, out_path) != 5)
        return fail("bad fmu line: %s", header);
    line[0] = '\0';
    if (!(lib = open_library(lib_path))) return fail("cannot load %s", lib_path);
    if (load(lib, &api)) goto done;
    c = api.instantiate(ident, fmi2CoSimulation, guid, uri, &cb, fmi2False, fmi2False);
    if (!c) { fail("%s: fmi2Instantiate failed", ident); goto done; }
    while (fgets(line, sizeof line, sc)) {
        char type;
        unsigned vr;
        int pos = 0;
        chomp(line);
        if (sscanf(line, "set %c %u %n", &type, &vr, &pos) == 2 && pos > 0) {
            fmi2Status st;
            if (type == 's') {
                fmi2String s = line + pos;
                fmi2ValueReference v = vr;
                st = api.setString(c, &v, 1, &s);
            } else {
                Var v = {type, vr};
                st = set_var(&api, c, v, line + pos);
            }
            if (st != fmi2OK) { fail("%s: %s refused", ident, line); goto done; }
        } else if (sscanf(line, "steps %ld %n", &n_steps, &pos) == 1 && pos > 0) {
            h = from_hex(line + pos);
        } else if (sscanf(line, "rollback %ld", &rollback) == 1) {
        } else if (sscanf(line, "in %c %u", &type, &vr) == 2 && n_in < MAX_VARS) {
            in[n_in].type = type;
            in[n_in++].vr = vr;
        } else if (sscanf(line, "out %c %u", &type, &vr) == 2 && n_out < MAX_VARS) {
            out[n_out].type = type;
            out[n_out++].vr = vr;
        } else if (strcmp(line, "inputs") == 0) {
            break;
        } else {
            fail("%s: unknown scenario line: %s", ident, line);
            goto done;
        }
    }
    if (n_steps < 0 || rollback > n_steps || !(u = (char **)calloc((size_t)n_steps + 1, sizeof *u))) {
        fail("%s: bad steps or rollback", ident);
        goto done;
    }
    for (n_read = 0; n_read < n_steps; n_read++) {
        if (!fgets(line, sizeof line, sc) || line[0] != 'u' || !(u[n_read] = (char *)malloc(strlen(line) + 1))) {
            fail("%s: missing input line %ld", ident, n_read);
            goto done;
        }
        chomp(line);
        strcpy(u[n_read], line);
    }
    if (api.setupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
        api.enterInitializationMode(c) != fmi2OK || api.exitInitializationMode(c) != fmi2OK) {
        fail("%s: initialisation failed", ident);
        goto done;
    }
    if (!(f = fopen(out_path, "wb"))) { fail("cannot write %s", out_path); goto done; }
    if (write_row(&api, c, out, n_out, f)) goto done;
    {
        int ended = 0;
        for (k = 0; k <= n_steps && !ended; k++) {
            if (k == rollback && !(state = saved_state(&api, c))) goto done;
            if (k < n_steps && (ended = run_steps(&api, c, u, k, k + 1, h, in, n_in, out, n_out, f)) < 0) goto done;
        }
        if (!ended && state) {
            if (api.setFMUstate(c, state) != fmi2OK) { fail("%s: fmi2SetFMUstate refused", ident); goto done; }
            if (run_steps(&api, c, u, rollback, n_steps, h, in, n_in, out, n_out, f) < 0) goto done;
        }
    }
    rc = 0;
done:
    if (f) fclose(f);
    if (state) api.freeFMUstate(c, &state);
    if (c) api.freeInstance(c);
    if (u) {
        for (k = 0; k < n_read; k++) free(u[k]);
        free(u);
    }
    close_library(lib);
    /* skip to this block's end (the inputs of steps not run), so the next FMU still runs */
    while (strcmp(line, "end") != 0 && fgets(line, sizeof line, sc)) chomp(line);
    if (rc) fprintf(stderr, "win64_host: %s failed\n", ident);
    return rc;
}

int main(int argc, char **argv) {
    char line[LINE];
    FILE *sc;
    int failed = 0;
    if (argc != 2) return fail("usage: win64_host SCENARIO");
    if (!(sc = fopen(argv[1], "r"))) return fail("cannot read %s", argv[1]);
    while (fgets(line, sizeof line, sc)) {
        chomp(line);
        if (strncmp(line, "fmu ", 4) == 0) {
            failed |= run_fmu(sc, line);
        } else if (line[0] && strcmp(line, "end") != 0) {
            fclose(sc);
            return fail("unknown scenario line: %s", line);
        }
    }
    fclose(sc);
    return failed;
}
