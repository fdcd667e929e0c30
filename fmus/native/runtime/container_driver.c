/* railfmu: run N fixed communication steps of one FMI 2.0 co-simulation FMU (the FMPy
 * container FMU of a system) and sample it after every step, without returning to Python.
 *
 * Built by fmus/cosim/container.py at first use (gcc -std=c99 -O2 -Wall -Wextra -Werror -shared)
 * and called through ctypes with the addresses of the FMU's fmi2DoStep, fmi2GetReal,
 * fmi2GetInteger, fmi2GetBoolean and fmi2GetBooleanStatus (may be NULL).
 * A Python loop pays ~0.5 us per ctypes call; this loop pays nothing on top of the FMU.
 *
 * Row i of `rows` (ncols doubles) gets the grid time start + (k0 + i + 1) * h (the master's
 * time arithmetic, t = start + k h) and the recorded values after step k0 + i: Real ones in
 * columns rcols[] (NULL: columns 1..nr, read straight into the row), Integer ones in icols[],
 * Boolean ones (0/1) in bcols[]. The FMU's own time is read back after every step (vr 0 of the
 * container, which adds h to its clock each step) and passed as the next
 * currentCommunicationPoint, so the container never sees a time that differs from its own.
 *
 * FMI 2.0 semantics of fmi2DoStep: fmi2OK/fmi2Warning go on; fmi2Discard followed by
 * fmi2GetBooleanStatus(fmi2Terminated) = true ends the run normally at the current
 * communication point (DRIVER_TERMINATED); any other fmi2Discard, fmi2Error or fmi2Fatal is a
 * failure (DRIVER_DO_STEP_FAILED with the status).
 */

#include <math.h>
#include <stddef.h>

typedef int (*do_step_fn)(void *c, double t, double h, int no_set_prior);
typedef int (*get_real_fn)(void *c, const unsigned int vr[], size_t nvr, double value[]);
typedef int (*get_int_fn)(void *c, const unsigned int vr[], size_t nvr, int value[]);
typedef int (*get_boolean_status_fn)(void *c, int kind, int *value);

enum { FMI2_WARNING = 1, FMI2_DISCARD = 2, FMI2_TERMINATED_KIND = 3 };
enum {
    DRIVER_OK = 0,
    DRIVER_DO_STEP_FAILED = 1,
    DRIVER_GET_FAILED = 2,
    DRIVER_NON_FINITE = 3,
    DRIVER_TERMINATED = 4
};

typedef struct {
    do_step_fn do_step;
    get_real_fn get_real;
    get_int_fn get_integer;
    get_int_fn get_boolean;
    get_boolean_status_fn get_boolean_status; /* NULL: the FMU cannot say it terminated */
    const unsigned int *rvrs, *ivrs, *bvrs;
    const size_t *rcols, *icols, *bcols; /* rcols NULL: Real columns are 1..nr */
    size_t nr, ni, nb;
    double *rbuf; /* nr doubles when rcols is set */
    int *ibuf;    /* max(ni, nb) ints */
} Signals;

static int sample(const Signals *s, void *c, double *row)
{
    size_t j;
    int st = 0;
    if (s->nr > 0) {
        st = s->get_real(c, s->rvrs, s->nr, s->rcols ? s->rbuf : row + 1);
        if (st > FMI2_WARNING) return st;
        if (s->rcols)
            for (j = 0; j < s->nr; j++) row[s->rcols[j]] = s->rbuf[j];
    }
    if (s->ni > 0) {
        st = s->get_integer(c, s->ivrs, s->ni, s->ibuf);
        if (st > FMI2_WARNING) return st;
        for (j = 0; j < s->ni; j++) row[s->icols[j]] = (double)s->ibuf[j];
    }
    if (s->nb > 0) {
        st = s->get_boolean(c, s->bvrs, s->nb, s->ibuf);
        if (st > FMI2_WARNING) return st;
        for (j = 0; j < s->nb; j++) row[s->bcols[j]] = s->ibuf[j] ? 1.0 : 0.0;
    }
    return 0;
}

/* Returns one of the DRIVER_* codes; *done = rows completely written before the code (a
 * non-finite row is written but not counted); *status = the failing call's fmi2Status;
 * *t_fmu = the FMU's time after the last step taken. */
int railfmu_run_steps(const Signals *s, void *c, double *t_fmu, double h, double start, long k0,
                      long n, double *rows, size_t ncols, long *done, int *status)
{
    const unsigned int time_vr = 0;
    long i;
    size_t j;
    *done = 0;
    *status = 0;
    for (i = 0; i < n; i++) {
        double *row = rows + (size_t)i * ncols;
        int st = s->do_step(c, *t_fmu, h, 1);
        if (st > FMI2_WARNING) {
            int terminated = 0;
            *status = st;
            if (st == FMI2_DISCARD && s->get_boolean_status &&
                s->get_boolean_status(c, FMI2_TERMINATED_KIND, &terminated) <= FMI2_WARNING && terminated)
                return DRIVER_TERMINATED;
            return DRIVER_DO_STEP_FAILED;
        }
        st = s->get_real(c, &time_vr, 1, t_fmu);
        if (st <= FMI2_WARNING) st = sample(s, c, row);
        if (st > FMI2_WARNING) {
            *status = st;
            return DRIVER_GET_FAILED;
        }
        row[0] = start + (double)(k0 + i + 1) * h;
        for (j = 1; j < ncols; j++) {
            if (!isfinite(row[j])) return DRIVER_NON_FINITE;
        }
        *done = i + 1;
    }
    return DRIVER_OK;
}
