/* LineProfile: a line's gradient and speed limit by position, read from a CSV
 * (models/line_profile.py states the format and semantics and is this code's Python twin):
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

#include <errno.h>
#include <locale.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "CsvCell.h"
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
    char *path = model_resolve_path(m, file), line[4096];
    FILE *f;
    LineProfile *p;
    size_t cap = 0, ncol = 3;
    long lineno = 0;
    if (!*file) {
        model_error(m, "parameter line_file is empty: a line profile CSV (%s,%s,%s) is needed",
                    LINE_COLUMNS[0], LINE_COLUMNS[1], LINE_COLUMNS[2]);
        free(path);
        return NULL;
    }
    if (!path) {
        model_error(m, "line_file %s: a relative path needs the FMU's resources folder (use an "
                       "absolute path)", file);
        return NULL;
    }
    f = fopen(path, "rb");
    if (!f) {
        model_error(m, "line_file %s: cannot open (%s)", path, strerror(errno));
        free(path);
        return NULL;
    }
    p = (LineProfile *)calloc(1, sizeof *p);
    while (p && fgets(line, sizeof line, f)) {
        char *fld[5], *s = line;
        size_t nf, j;
        double v[4] = {0, 0, 0, 0};
        lineno++;
        if (lineno == 1 && (unsigned char)s[0] == 0xEF && (unsigned char)s[1] == 0xBB &&
            (unsigned char)s[2] == 0xBF)
            s += 3;
        s[strcspn(s, "\n")] = '\0';
        if (*csv_trim(s) == '\0') continue;
        nf = csv_split(s, fld, 5);
        if (lineno == 1 && nf == 4) ncol = 4;
        if (nf != ncol) {
            model_error(m, "line_file %s, line %ld: %lu fields, expected %lu (%s,%s,%s[,%s])", path,
                        lineno, (unsigned long)nf, (unsigned long)ncol, LINE_COLUMNS[0],
                        LINE_COLUMNS[1], LINE_COLUMNS[2], LINE_COLUMNS[3]);
            goto fail;
        }
        if (lineno == 1) {
            for (j = 0; j < ncol; j++)
                if (strcmp(fld[j], LINE_COLUMNS[j]) != 0) {
                    model_error(m, "line_file %s, line 1, column %lu: header '%s', expected '%s'", path,
                                (unsigned long)j + 1, fld[j], LINE_COLUMNS[j]);
                    goto fail;
                }
            continue;
        }
        for (j = 0; j < ncol; j++)
            if (csv_number(fld[j], &v[j])) {
                model_error(m, "line_file %s, line %ld, column %lu (%s): '%s' is not a finite number",
                            path, lineno, (unsigned long)j + 1, LINE_COLUMNS[j], fld[j]);
                goto fail;
            }
        if (p->n > 0 && !(v[0] > p->position[p->n - 1])) {
            model_error(m, "line_file %s, line %ld, column 1 (position_m): %.17g does not increase "
                           "on the previous row's %.17g", path, lineno, v[0], p->position[p->n - 1]);
            goto fail;
        }
        if (ncol == 4 && v[3] != 0 && !(fabs(v[3]) > 55.0)) {
            model_error(m, "line_file %s, line %ld, column 4 (curve_radius_m): %.17g must be 0 "
                           "(straight) or beyond 55 m", path, lineno, v[3]);
            goto fail;
        }
        if (!(v[2] > 0)) {
            model_error(m, "line_file %s, line %ld, column 3 (speed_limit_kmh): %.17g must be > 0",
                        path, lineno, v[2]);
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
                model_error(m, "line_file %s: out of memory", path);
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
    if (!p) {
        model_error(m, "line_file %s: out of memory", path);
        goto fail;
    }
    if (lineno == 0 || p->n == 0) {
        model_error(m, "line_file %s: no data rows (header %s,%s,%s, then one row per change)", path,
                    LINE_COLUMNS[0], LINE_COLUMNS[1], LINE_COLUMNS[2]);
        goto fail;
    }
    fclose(f);
    free(path);
    return p;
fail:
    fclose(f);
    free(path);
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
