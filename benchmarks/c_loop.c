/* railfmu benchmark: the cost of fmi2DoStep with no importer in between.
 *
 * A minimal FMI 2.0 Co-Simulation host: dlopen()s an FMU's binary, instantiates it with a
 * logger that prints, sets parameters, initialises and calls fmi2DoStep STEPS times with a
 * fixed step, timing only that loop (clock_gettime, CLOCK_MONOTONIC). It does this REPEATS
 * times, each with a fresh instance (so the simulated time, and the size of the states,
 * are the same in every repeat), and reports the fastest repeat: on a shared machine the
 * minimum is the least disturbed measurement.
 *
 *   c_loop BINARY GUID RESOURCE_URI STEPS STEP_SIZE REPEATS CHECK_VR [r:VR=VALUE | i:VR=VALUE ...]
 *
 * Output (stdout, one line):  best_ns=<ns per step> median_ns=<ns per step> check=<value>
 * where check is the Real with value reference CHECK_VR after the last step of the last
 * repeat (the caller compares it with the same run through FMPy). Exit status 1 on any
 * failed FMI call.
 *
 * Build: gcc -std=c99 -O2 -I <dir of fmi2Functions.h> c_loop.c -o c_loop -ldl
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define MAX_PARAMS 64

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *freeInstance;
    fmi2SetupExperimentTYPE *setupExperiment;
    fmi2EnterInitializationModeTYPE *enterInitializationMode;
    fmi2ExitInitializationModeTYPE *exitInitializationMode;
    fmi2SetRealTYPE *setReal;
    fmi2SetIntegerTYPE *setInteger;
    fmi2GetRealTYPE *getReal;
    fmi2DoStepTYPE *doStep;
    fmi2TerminateTYPE *terminate;
} Api;

typedef struct {
    char type; /* 'r' or 'i' */
    fmi2ValueReference vr;
    double value;
} Param;

static void logger(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s] status %d, %s: ", instanceName ? instanceName : "?", (int)status,
            category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message ? message : "", ap);
    va_end(ap);
    fputc('\n', stderr);
}

static void *symbol(void *lib, const char *name) {
    void *p = dlsym(lib, name);
    if (!p) {
        fprintf(stderr, "c_loop: %s not exported by the FMU binary\n", name);
        exit(1);
    }
    return p;
}

static double now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

#define CHECK(call, what)                                                                  \
    do {                                                                                   \
        if ((call) != fmi2OK) {                                                            \
            fprintf(stderr, "c_loop: %s failed\n", what);                                  \
            return 1;                                                                      \
        }                                                                                  \
    } while (0)

int main(int argc, char **argv) {
    void *lib;
    Api api;
    Param params[MAX_PARAMS];
    int n_params = 0, k;
    long steps, repeats, rep, n;
    double h, *per_step, check = 0.0;
    fmi2ValueReference check_vr;
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

    if (argc < 8) {
        fprintf(stderr, "usage: %s BINARY GUID RESOURCE_URI STEPS STEP_SIZE REPEATS CHECK_VR "
                        "[r:VR=VALUE | i:VR=VALUE ...]\n", argv[0]);
        return 2;
    }
    steps = strtol(argv[4], NULL, 10);
    h = strtod(argv[5], NULL);
    repeats = strtol(argv[6], NULL, 10);
    check_vr = (fmi2ValueReference)strtoul(argv[7], NULL, 10);
    if (steps < 1 || repeats < 1 || !(h > 0)) {
        fprintf(stderr, "c_loop: STEPS, REPEATS and STEP_SIZE must be positive\n");
        return 2;
    }
    for (k = 8; k < argc; k++) {
        unsigned vr;
        char type;
        double value;
        if (n_params == MAX_PARAMS || sscanf(argv[k], "%c:%u=%lf", &type, &vr, &value) != 3 ||
            (type != 'r' && type != 'i')) {
            fprintf(stderr, "c_loop: bad parameter argument '%s' (r:VR=VALUE or i:VR=VALUE)\n",
                    argv[k]);
            return 2;
        }
        params[n_params].type = type;
        params[n_params].vr = vr;
        params[n_params].value = value;
        n_params++;
    }

    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "c_loop: %s\n", dlerror());
        return 1;
    }
    /* dlsym returns void*; POSIX guarantees the conversion to a function pointer works */
    *(void **)&api.instantiate = symbol(lib, "fmi2Instantiate");
    *(void **)&api.freeInstance = symbol(lib, "fmi2FreeInstance");
    *(void **)&api.setupExperiment = symbol(lib, "fmi2SetupExperiment");
    *(void **)&api.enterInitializationMode = symbol(lib, "fmi2EnterInitializationMode");
    *(void **)&api.exitInitializationMode = symbol(lib, "fmi2ExitInitializationMode");
    *(void **)&api.setReal = symbol(lib, "fmi2SetReal");
    *(void **)&api.setInteger = symbol(lib, "fmi2SetInteger");
    *(void **)&api.getReal = symbol(lib, "fmi2GetReal");
    *(void **)&api.doStep = symbol(lib, "fmi2DoStep");
    *(void **)&api.terminate = symbol(lib, "fmi2Terminate");

    per_step = (double *)malloc((size_t)repeats * sizeof *per_step);
    if (!per_step) return 1;
    for (rep = 0; rep < repeats; rep++) {
        double t0, t1;
        int bad = fmi2OK;
        fmi2Component c = api.instantiate("bench", fmi2CoSimulation, argv[2], argv[3],
                                          &callbacks, fmi2False, fmi2False);
        if (!c) {
            fprintf(stderr, "c_loop: fmi2Instantiate failed\n");
            return 1;
        }
        CHECK(api.setupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), "fmi2SetupExperiment");
        CHECK(api.enterInitializationMode(c), "fmi2EnterInitializationMode");
        for (k = 0; k < n_params; k++) {
            if (params[k].type == 'r') {
                CHECK(api.setReal(c, &params[k].vr, 1, &params[k].value), "fmi2SetReal");
            } else {
                const fmi2Integer v = (fmi2Integer)params[k].value;
                CHECK(api.setInteger(c, &params[k].vr, 1, &v), "fmi2SetInteger");
            }
        }
        CHECK(api.exitInitializationMode(c), "fmi2ExitInitializationMode");

        t0 = now_ns();
        for (n = 0; n < steps; n++) bad |= api.doStep(c, (double)n * h, h, fmi2True);
        t1 = now_ns();
        if (bad != fmi2OK) {
            fprintf(stderr, "c_loop: fmi2DoStep failed\n");
            return 1;
        }
        per_step[rep] = (t1 - t0) / (double)steps;
        CHECK(api.getReal(c, &check_vr, 1, &check), "fmi2GetReal");
        CHECK(api.terminate(c), "fmi2Terminate");
        api.freeInstance(c);
    }
    qsort(per_step, (size_t)repeats, sizeof *per_step, cmp_double);
    printf("best_ns=%.3f median_ns=%.3f check=%.17g\n", per_step[0], per_step[repeats / 2], check);
    free(per_step);
    dlclose(lib);
    return 0;
}
