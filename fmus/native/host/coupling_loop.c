/* railfmu: the container master's coupling loop, over the member FMUs' own fmi2 functions.
 *
 * Built by fmus/cosim/native_loop.py at first use (gcc -std=c99 -O2 -ffp-contract=off -Wall
 * -Wextra -Werror -shared) and called through ctypes with the FMUs' instances and the addresses
 * of their fmi2DoStep / fmi2Get* / fmi2Set* (FMI 2.0 only; instantiated, parameterised and
 * initialised in Python exactly as the Jacobi master does it).
 *
 * Row k (grid index k, t = start + k h, the master's arithmetic) is what the Jacobi master
 * samples at t: every link copied in order (one get and one set per run of consecutive
 * connections of one source/destination pair and type; dst = factor * src + offset where a map
 * is not the identity, Real only, rounded as Python rounds it: no contraction to an fma), then
 * the recorded signals read into the row (Real straight into it, Integer as its value, Boolean
 * as 0/1), then, unless k is the last grid index, every component stepped from t in order.
 *
 * It stops at the first failure and says where: a status worse than fmi2Warning from a link's
 * get or set, a signal read or a doStep (the caller turns it into the Jacobi master's error,
 * or into an early end after fmi2Discard + fmi2Terminated), or a non-finite value in a row.
 */

#include <math.h>
#include <stddef.h>
#include <string.h>

typedef int (*do_step_fn)(void *c, double t, double h, int no_set_prior);
typedef int (*get_set_fn)(void *c, const unsigned int vr[], size_t nvr, void *value);

enum { FMI2_WARNING = 1 };
enum {
    LOOP_OK = 0,
    LOOP_GET_FAILED = 1,    /* where: the link */
    LOOP_SET_FAILED = 2,    /* where: the link */
    LOOP_SAMPLE_FAILED = 3, /* where: the run of recorded signals */
    LOOP_NON_FINITE = 4,    /* the row after the done ones holds a NaN or an inf */
    LOOP_STEP_FAILED = 5    /* where: the component; its row is sampled (counted in done) */
};

typedef struct {
    void *instance;
    do_step_fn do_step;
} Component;

typedef struct {
    get_set_fn get, set;
    void *src, *dst; /* instances */
    const unsigned int *src_vrs, *dst_vrs;
    size_t n;
    void *src_buf, *dst_buf; /* the same buffer unless a map converts (then doubles) */
    size_t n_maps;
    const size_t *map_index;
    const double *factor, *offset;
} Link;

enum { RUN_REAL = 0, RUN_INTEGER = 1, RUN_BOOLEAN = 2 };

typedef struct {
    get_set_fn get;
    void *instance;
    const unsigned int *vrs;
    size_t n;
    size_t col; /* the column of its first signal; the others follow */
    int kind;
    int *buf; /* n ints for Integer and Boolean */
} Run;

typedef struct {
    const Component *components;
    size_t n_components;
    const Link *links;
    size_t n_links;
    const Run *runs;
    size_t n_runs;
    double start, h;
    long last; /* the last grid index: its row is sampled, nothing is stepped from it */
    size_t ncols;
} Loop;

/* Rows k0 .. k0 + m - 1 into rows[0 ..]. Returns a LOOP_* code; *done = rows completely
 * sampled, *where and *status say which call failed and how. */
int railfmu_coupled_rows(const Loop *L, long k0, long m, double *rows, long *done, long *where,
                         int *status)
{
    long i;
    size_t j, q;
    *done = 0;
    *where = -1;
    *status = 0;
    for (i = 0; i < m; i++) {
        const long k = k0 + i;
        const double t = L->start + (double)k * L->h;
        double *row = rows + (size_t)i * L->ncols;
        int st;
        for (j = 0; j < L->n_links; j++) {
            const Link *l = &L->links[j];
            st = l->get(l->src, l->src_vrs, l->n, l->src_buf);
            if (st > FMI2_WARNING) {
                *where = (long)j;
                *status = st;
                return LOOP_GET_FAILED;
            }
            if (l->dst_buf != l->src_buf) {
                const double *s = (const double *)l->src_buf;
                double *d = (double *)l->dst_buf;
                memcpy(d, s, l->n * sizeof *d);
                for (q = 0; q < l->n_maps; q++) {
                    const size_t x = l->map_index[q];
                    d[x] = l->factor[q] * s[x] + l->offset[q];
                }
            }
            st = l->set(l->dst, l->dst_vrs, l->n, l->dst_buf);
            if (st > FMI2_WARNING) {
                *where = (long)j;
                *status = st;
                return LOOP_SET_FAILED;
            }
        }
        for (j = 0; j < L->n_runs; j++) {
            const Run *r = &L->runs[j];
            st = r->get(r->instance, r->vrs, r->n, r->kind == RUN_REAL ? (void *)(row + r->col) : (void *)r->buf);
            if (st > FMI2_WARNING) {
                *where = (long)j;
                *status = st;
                return LOOP_SAMPLE_FAILED;
            }
            if (r->kind == RUN_INTEGER)
                for (q = 0; q < r->n; q++) row[r->col + q] = (double)r->buf[q];
            else if (r->kind == RUN_BOOLEAN)
                for (q = 0; q < r->n; q++) row[r->col + q] = r->buf[q] ? 1.0 : 0.0;
        }
        row[0] = t;
        for (j = 1; j < L->ncols; j++)
            if (!isfinite(row[j])) return LOOP_NON_FINITE;
        *done = i + 1;
        if (k >= L->last) break;
        for (j = 0; j < L->n_components; j++) {
            const Component *c = &L->components[j];
            st = c->do_step(c->instance, t, L->h, 1);
            if (st > FMI2_WARNING) {
                *where = (long)j;
                *status = st;
                return LOOP_STEP_FAILED;
            }
        }
    }
    return LOOP_OK;
}
