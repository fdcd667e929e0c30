/* LineProfile: a line's gradient and speed limit by position, read from a CSV
 * (models/track/line_profile.py states the format and semantics and is this code's Python twin):
 *
 *     position_m,gradient_permille,speed_limit_kmh
 *     0,0.0,40
 *     1200,0.0,140
 *     ...
 *     32103,0.0,40          <- the last row: the stopping point at the end of the line
 *
 * An optional fourth column curve_radius_m (0 = straight) adds Roeckl's curve resistance.
 * Row k applies from position_m[k] up to the next row; before the first row the first row
 * applies, from the last row on the last. Positions increase strictly. Included (static) by
 * TrainLongitudinal.c and Driver.c.
 */
#ifndef RAILFMU_LINE_PROFILE_H
#define RAILFMU_LINE_PROFILE_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "csv_table.h"
#include "model.h"

#if defined(__GNUC__)
#define LINE_MAYBE_UNUSED __attribute__((unused))
#else
#define LINE_MAYBE_UNUSED
#endif

typedef struct {
    size_t n;
    double *position; /* m, strictly increasing */
    double *gradient; /* per mille, positive uphill */
    double *limit;    /* m/s (the file's km/h / 3.6) */
    double *curve;    /* curve resistance per unit weight (Roeckl), 0 on straight track */
    size_t cursor;    /* row of the previous lookup: a hint, not part of the FMU state */
} LineProfile;

static void line_free(LineProfile *p) {
    if (!p) return;
    free(p->position);
    free(p->gradient);
    free(p->limit);
    free(p->curve);
    free(p);
}


static const char *const LINE_COLUMNS[4] = {"position_m", "gradient_permille", "speed_limit_kmh",
                                            "curve_radius_m"};

/* Roeckl's curve resistance per unit weight for a radius R (m, either sign; 0 = straight):
   0.65 / (R - 55) for R >= 300 m, 0.5 / (R - 30) below (standard gauge) */
static double line_curve(double R) {
    R = fabs(R);
    if (R == 0) return 0.0;
    return R >= 300.0 ? 0.65 / (R - 55.0) : 0.5 / (R - 30.0);
}

/* Reads the file; NULL after one model_error naming the file, line and column. */
static LineProfile *line_load(ModelInstance *m, const char *file) {
    CsvTable t;
    LineProfile *p;
    size_t cap = 0, ncol = 3, j;
    int rc;
    if (!*file) {
        model_error(m, "parameter line_file is empty: a line profile CSV (%s,%s,%s) is needed",
                    LINE_COLUMNS[0], LINE_COLUMNS[1], LINE_COLUMNS[2]);
        return NULL;
    }
    if (csv_open(&t, m, "line_file", file, CSV_SKIP_BOM)) return NULL;
    p = (LineProfile *)calloc(1, sizeof *p);
    if (!p) {
        csv_fail(&t, 0, 0, "out of memory");
        goto fail;
    }
    if (t.ncol == 0) {
        csv_fail(&t, 0, 0, "no data rows (header %s,%s,%s, then one row per change)", LINE_COLUMNS[0],
                 LINE_COLUMNS[1], LINE_COLUMNS[2]);
        goto fail;
    }
    if (t.ncol == 4) ncol = 4;
    if (t.ncol != ncol) {
        csv_fail(&t, 1, 0, "%lu fields, expected %lu (%s,%s,%s[,%s])", (unsigned long)t.ncol,
                 (unsigned long)ncol, LINE_COLUMNS[0], LINE_COLUMNS[1], LINE_COLUMNS[2], LINE_COLUMNS[3]);
        goto fail;
    }
    for (j = 0; j < ncol; j++)
        if (strcmp(t.header[j], LINE_COLUMNS[j]) != 0) {
            csv_fail(&t, 1, j + 1, "header '%s', expected '%s'", t.header[j], LINE_COLUMNS[j]);
            goto fail;
        }
    while ((rc = csv_next_row(&t)) > 0) {
        double v[4] = {0, 0, 0, 0};
        if (t.ncell != ncol) {
            csv_fail(&t, t.line, 0, "%lu fields, expected %lu (%s,%s,%s[,%s])", (unsigned long)t.ncell,
                     (unsigned long)ncol, LINE_COLUMNS[0], LINE_COLUMNS[1], LINE_COLUMNS[2], LINE_COLUMNS[3]);
            goto fail;
        }
        for (j = 0; j < ncol; j++)
            if (csv_number(t.cell[j], &v[j]) != CSV_OK) {
                csv_fail(&t, t.line, j + 1, "'%s' is not a finite number", t.cell[j]);
                goto fail;
            }
        if (p->n > 0 && !(v[0] > p->position[p->n - 1])) {
            csv_fail(&t, t.line, 1, "%.17g does not increase on the previous row's %.17g", v[0],
                     p->position[p->n - 1]);
            goto fail;
        }
        if (ncol == 4 && v[3] != 0 && !(fabs(v[3]) > 55.0)) {
            csv_fail(&t, t.line, 4, "%.17g must be 0 (straight) or beyond 55 m", v[3]);
            goto fail;
        }
        if (!(v[2] > 0)) {
            csv_fail(&t, t.line, 3, "%.17g must be > 0", v[2]);
            goto fail;
        }
        if (p->n == cap) {
            size_t nc = cap ? 2 * cap : 64;
            double *a = (double *)realloc(p->position, nc * sizeof *a);
            double *b = a ? (double *)realloc(p->gradient, nc * sizeof *b) : NULL;
            double *d = NULL, *e = NULL;
            if (a) p->position = a;
            if (b) p->gradient = b;
            if (b) d = (double *)realloc(p->limit, nc * sizeof *d);
            if (d) p->limit = d;
            if (d) e = (double *)realloc(p->curve, nc * sizeof *e);
            if (!e) {
                csv_fail(&t, 0, 0, "out of memory");
                goto fail;
            }
            p->curve = e;
            cap = nc;
        }
        p->position[p->n] = v[0];
        p->gradient[p->n] = v[1];
        p->limit[p->n] = v[2] / 3.6;
        p->curve[p->n] = line_curve(v[3]);
        p->n++;
    }
    if (rc < 0) goto fail;
    if (p->n == 0) {
        csv_fail(&t, 0, 0, "no data rows (header %s,%s,%s, then one row per change)", LINE_COLUMNS[0],
                 LINE_COLUMNS[1], LINE_COLUMNS[2]);
        goto fail;
    }
    csv_close(&t);
    return p;
fail:
    csv_close(&t);
    line_free(p);
    return NULL;
}

/* The row that applies at position s (0 before the first row). */
LINE_MAYBE_UNUSED static size_t line_row(LineProfile *p, double s) {
    size_t c = p->cursor, lo = 0, hi = p->n;
    if (c < p->n && p->position[c] <= s && (c + 1 == p->n || p->position[c + 1] > s)) return c;
    while (lo < hi) { /* first row with position > s */
        const size_t mid = lo + (hi - lo) / 2;
        if (p->position[mid] <= s) lo = mid + 1;
        else hi = mid;
    }
    p->cursor = lo ? lo - 1 : 0;
    return p->cursor;
}

#endif
