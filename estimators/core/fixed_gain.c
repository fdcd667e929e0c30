/* The fixed-gain filter recursion of estimators/core/fixed_gain.py over a block of samples:
 *
 *     x^-_k = F x^+_{k-1},    x^+_k = x^-_k + K (z_k - H x^-_k)
 *
 * Each matrix-vector product is a call of numpy's own cblas_dgemv (its address is passed in),
 * with the arguments numpy's `@` gives it; the differences and sums are single IEEE operations
 * in numpy's order. So the result equals the numpy loop bit for bit (fixed_gain.py checks it).
 * No contraction of a*b+c is possible here (no products outside the BLAS), and
 * -ffp-contract=off says so anyway. Returns 0, or -1 when the scratch memory is not there. */
#include <stdint.h>
#include <stdlib.h>

#define TRANS 112 /* CblasTrans */

/* The matrices of one filter, set once (fixed_gain.BlockFilter); order and lda as numpy's `@`
 * passes them for the array's layout. */
struct railfmu_fixed_gain {
    void (*gemv)(void); /* numpy's cblas_dgemv, called as the BLASINT variant below */
    const double *F;
    int fo;
    long fl;
    const double *H;
    int ho;
    long hl;
    const double *K;
    int ko;
    long kl;
    long n, m; /* states, rows of H */
};

#define FIXED_GAIN(NAME, BLASINT)                                                                    \
    typedef void (*NAME##_gemv)(int, int, BLASINT, BLASINT, double, const double *, BLASINT,         \
                                const double *, BLASINT, double, double *, BLASINT);                 \
    int NAME(const struct railfmu_fixed_gain *c, double *x, const double *Z, long rows, long nz,     \
             double *out, long out_row, long out_col)                                                \
    {                                                                                                \
        NAME##_gemv mv = (NAME##_gemv)c->gemv;                                                       \
        long n = c->n, m = c->m;                                                                     \
        double *xp = malloc(sizeof(double) * (size_t)(2 * n + 3 * m + 1));                           \
        if (xp == NULL)                                                                              \
            return -1;                                                                               \
        double *kn = xp + n, *hx = kn + n, *nu = hx + m, *zb = nu + m;                               \
        for (long j = 0; j < m; j++)                                                                 \
            zb[j] = 0.0; /* rows beyond Z's columns: a virtual reading of 0 */                       \
        for (long k = 0; k < rows; k++) {                                                            \
            mv(c->fo, TRANS, (BLASINT)n, (BLASINT)n, 1.0, c->F, (BLASINT)c->fl, x, 1, 0.0, xp, 1);   \
            for (long j = 0; j < nz; j++)                                                            \
                zb[j] = Z[k * nz + j];                                                               \
            mv(c->ho, TRANS, (BLASINT)n, (BLASINT)m, 1.0, c->H, (BLASINT)c->hl, xp, 1, 0.0, hx, 1);  \
            for (long j = 0; j < m; j++)                                                             \
                nu[j] = zb[j] - hx[j];                                                               \
            mv(c->ko, TRANS, (BLASINT)m, (BLASINT)n, 1.0, c->K, (BLASINT)c->kl, nu, 1, 0.0, kn, 1);  \
            double *o = out + k * out_row;                                                           \
            for (long j = 0; j < n; j++) {                                                           \
                x[j] = xp[j] + kn[j];                                                                \
                o[j * out_col] = x[j];                                                               \
            }                                                                                        \
        }                                                                                            \
        free(xp);                                                                                    \
        return 0;                                                                                    \
    }

FIXED_GAIN(railfmu_fixed_gain64, int64_t)
FIXED_GAIN(railfmu_fixed_gain32, int32_t)
