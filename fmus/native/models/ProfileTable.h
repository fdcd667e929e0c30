/* ProfileTable: a measured irregularity profile, s,alignment,vertical_left,vertical_right
 * (TrackIrregularity's profile_file, Trolley's irregularity_file), with its Catmull-Rom
 * slopes; or a recording car's rail heights position_m,vertical_left_m,vertical_right_m
 * (alignment 0). railfmu.models.track.irregularity.ProfileTable.from_csv is the Python twin: it
 * words the errors, so they keep the "file:line:" form. Each model evaluates the table its
 * own way. Included (static) by TrackIrregularity.c and TrackGeometry.h.
 */
#ifndef RAILFMU_PROFILE_TABLE_H
#define RAILFMU_PROFILE_TABLE_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "csv_table.h"
#include "model.h"

typedef struct {
    size_t n;                /* rows; 0: no table */
    double *s;               /* n, strictly increasing */
    double *y, *dy;          /* 3 n: alignment, vertical_left, vertical_right and slopes d/ds */
} ProfileTable;

static void profile_free(ProfileTable *p) {
    free(p->s);
    free(p->y);
    free(p->dy);
    memset(p, 0, sizeof *p);
}

/* Reads file into p (empty before); 1 after one model_error. label: the parameter. */
static int profile_read(ModelInstance *m, const char *label, const char *file, ProfileTable *p) {
    static const char *const header[4] = {"s", "alignment", "vertical_left", "vertical_right"};
    static const char *const car[3] = {"position_m", "vertical_left_m", "vertical_right_m"};
    CsvTable t;
    size_t cap = 0, n = 0, i;
    int c, rc, ncol = 4, skip = 0; /* skip: the alignment column is absent (set to 0) */
    if (csv_open(&t, m, label, file, CSV_COLON | CSV_SKIP_BOM)) return 1;
    for (c = 0; c < 4 && t.ncol == 4; c++)
        if (strcmp(t.header[c], header[c]) != 0) break;
    if (t.ncol == 3) {
        for (c = 0; c < 3; c++)
            if (strcmp(t.header[c], car[c]) != 0) break;
        if (c == 3) c = 4, ncol = 3, skip = 1;
    }
    if (c != 4 || t.ncol != (size_t)ncol) {
        csv_fail(&t, 1, 0, "header must be s,alignment,vertical_left,vertical_right or "
                 "position_m,vertical_left_m,vertical_right_m");
        goto fail;
    }
    while ((rc = csv_next_row(&t)) > 0) {
        if (t.ncell != (size_t)ncol) {
            csv_fail(&t, t.line, 0, "expected %d comma-separated numbers", ncol);
            goto fail;
        }
        if (n == cap) {
            const size_t nc = cap ? 2 * cap : 256;
            double *a = (double *)realloc(p->s, nc * sizeof(double)), *b;
            if (a) p->s = a;
            b = a ? (double *)realloc(p->y, 3 * nc * sizeof(double)) : NULL;
            if (!b) {
                csv_fail(&t, 0, 0, "out of memory");
                goto fail;
            }
            p->y = b;
            cap = nc;
        }
        if (skip) p->y[3 * n] = 0.0;
        for (c = 0; c < ncol; c++) {
            double x;
            if (csv_number(t.cell[c], &x) != CSV_OK) {
                csv_fail(&t, t.line, 0, "not a number: '%s'", t.cell[c]);
                goto fail;
            }
            if (c == 0) p->s[n] = x;
            else p->y[3 * n + c - 1 + skip] = x;
        }
        if (n > 0 && !(p->s[n] > p->s[n - 1])) {
            csv_fail(&t, t.line, 0, "s = %g is not greater than the previous s = %g", p->s[n], p->s[n - 1]);
            goto fail;
        }
        n++;
    }
    if (rc < 0) goto fail;
    if (n < 2) {
        csv_fail(&t, 0, 0, "needs at least two data rows");
        goto fail;
    }
    p->dy = (double *)malloc(3 * n * sizeof(double));
    if (!p->dy) {
        csv_fail(&t, 0, 0, "out of memory");
        goto fail;
    }
    for (c = 0; c < 3; c++) { /* Catmull-Rom: central differences, one-sided at the ends */
        const double *S = p->s, *Y = p->y;
        p->dy[c] = (Y[3 + c] - Y[c]) / (S[1] - S[0]);
        for (i = 1; i + 1 < n; i++)
            p->dy[3 * i + c] = (Y[3 * (i + 1) + c] - Y[3 * (i - 1) + c]) / (S[i + 1] - S[i - 1]);
        p->dy[3 * (n - 1) + c] = (Y[3 * (n - 1) + c] - Y[3 * (n - 2) + c]) / (S[n - 1] - S[n - 2]);
    }
    for (i = 0; i < 3 * n; i++) /* finite numbers whose differences are not (near 1e308) */
        if (!isfinite(p->dy[i]) || !isfinite(p->y[i] + p->dy[i] * (p->s[n - 1] - p->s[0]))) {
            csv_fail(&t, 0, 0, "%s near s = %g: values too large for a profile (its slope is not finite)",
                     header[i % 3 + 1], p->s[i / 3]);
            goto fail;
        }
    p->n = n;
    csv_close(&t);
    return 0;
fail:
    csv_close(&t);
    profile_free(p);
    return 1;
}

#endif
