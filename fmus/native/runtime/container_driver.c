/* railfmu: run N fixed communication steps of one FMI 2.0 co-simulation FMU (the FMPy
 * container FMU of a system) and sample it after every step, without returning to Python.
 *
 * Built by fmus/container.py at first use (gcc -std=c99 -O2 -Wall -Wextra -Werror -shared)
 * and called through ctypes with the addresses of the FMU's fmi2DoStep and fmi2GetReal.
 * A Python loop pays ~0.5 us per ctypes call; this loop pays nothing on top of the FMU.
 *
 * Row i of `rows` (ncols doubles) gets the grid time start + (k0 + i + 1) * h (the master's
 * time arithmetic, t = start + k h) and the values of vrs[0..nvr-1] after step k0 + i.
 * The FMU's own time is read back after every step (vr 0 of the container, which adds
 * h to its clock each step) and passed as the next currentCommunicationPoint, so the
 * container never sees a time that differs from its own.
 */

#include <math.h>
#include <stddef.h>

typedef int (*do_step_fn)(void *c, double t, double h, int no_set_prior);
typedef int (*get_real_fn)(void *c, const unsigned int vr[], size_t nvr, double value[]);

enum { DRIVER_OK = 0, DRIVER_DO_STEP_FAILED = 1, DRIVER_GET_REAL_FAILED = 2, DRIVER_NON_FINITE = 3 };

/* Returns one of the DRIVER_* codes; *done = rows completely written before a failure
 * (a non-finite row is written but not counted); *status = the failing call's fmi2Status;
 * *t_fmu = the FMU's time after the last step taken. */
int railfmu_run_steps(do_step_fn do_step, get_real_fn get_real, void *c, double *t_fmu, double h,
                      double start, long k0, long n, const unsigned int *vrs, size_t nvr,
                      double *rows, size_t ncols, long *done, int *status)
{
    const unsigned int time_vr = 0;
    long i;
    size_t j;
    *done = 0;
    *status = 0;
    for (i = 0; i < n; i++) {
        double *row = rows + (size_t)i * ncols;
        int s = do_step(c, *t_fmu, h, 1);
        if (s > 1) { /* worse than fmi2Warning */
            *status = s;
            return DRIVER_DO_STEP_FAILED;
        }
        s = get_real(c, &time_vr, 1, t_fmu);
        if (s <= 1 && nvr > 0) s = get_real(c, vrs, nvr, row + 1);
        if (s > 1) {
            *status = s;
            return DRIVER_GET_REAL_FAILED;
        }
        row[0] = start + (double)(k0 + i + 1) * h;
        for (j = 1; j <= nvr; j++) {
            if (!isfinite(row[j])) return DRIVER_NON_FINITE;
        }
        *done = i + 1;
    }
    return DRIVER_OK;
}
