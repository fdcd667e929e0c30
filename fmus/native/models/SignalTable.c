/* SignalTable: replay of a time-indexed CSV table (models/sources/signal_table.py states the
 * semantics; tests/test_signal_table.py proves this code equals its Python twin there).
 *
 * The file is read once in model_initialize: only the bound columns are kept, one row of
 * doubles (Real channels), fmi2Boolean and fmi2Integer per table row. Every problem in it is
 * one model_error naming the file, the line and the column; fmi2ExitInitializationMode then
 * fails with that message alone.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "csv_table.h"
#include "model.h"

#define TIME_TOLERANCE 1e-9 /* relative, with max(1, |tau|) */
#define GAP_FRACTION 1e-3   /* ... and at most this fraction of the smallest row step */

/* the channels' value references are consecutive (fmus/generate/codegen.py numbers the
   variables in declaration order) */
#define VR_Y(k) (VR_y_1 + (k))
#define VRB_OUT(k) (VRB_boolean_1 + (k))
#define VRI_OUT(k) (VRI_integer_1 + (k))
#define VRS_REAL_COL(k) (VRS_column_1 + (k))
#define VRS_BOOL_COL(k) (VRS_boolean_column_1 + (k))
#define VRS_INT_COL(k) (VRS_integer_column_1 + (k))

typedef struct {
    size_t n;                /* rows */
    double *time;            /* n table times (s), strictly increasing */
    double *y;               /* n x nr values of the bound Real channels */
    fmi2Boolean *b;          /* n x nb */
    fmi2Integer *i;          /* n x ni */
    size_t nr, nb, ni;       /* bound channels of each type */
    int real_slot[N_REAL_CHANNELS]; /* channel -> column of y, or -1 when unbound */
    int bool_slot[N_BOOLEAN_CHANNELS];
    int int_slot[N_INTEGER_CHANNELS];
    double min_gap;          /* smallest tau_k+1 - tau_k (s); HUGE_VAL for one row */
    size_t cursor;           /* row of the previous lookup: a hint, not part of the FMU state */
} Table;

static void free_table(Table *d) {
    if (!d) return;
    free(d->time);
    free(d->y);
    free(d->b);
    free(d->i);
    free(d);
}

/* ---- parsing (csv_table.h) ---- */

static const char *param_string(const ModelInstance *m, size_t vr) {
    return m->s[vr] ? m->s[vr] : "";
}

/* Column index of a bound name in the header, or -1 after logging which parameter named a
   missing column. */
static int find_column(const CsvTable *t, const char *name, const char *param) {
    char **header = t->header;
    const size_t nh = t->ncol;
    size_t j;
    for (j = 1; j < nh; j++)
        if (strcmp(header[j], name) == 0) return (int)j;
    {
        char list[400];
        size_t used = 0;
        list[0] = '\0';
        for (j = 0; j < nh && used + 4 < sizeof list; j++) {
            int w = snprintf(list + used, sizeof list - used, "%s%s", j ? ", " : "", header[j]);
            if (w < 0) break;
            used += (size_t)w;
            if (used >= sizeof list) {
                strcpy(list + sizeof list - 4, "...");
                break;
            }
        }
        csv_fail(t, 1, 0, "no column '%s' (named by parameter %s); the header has: %s", name, param, list);
    }
    return -1;
}

#define MAX_FIELDS 4096

typedef struct {
    int column;  /* header index */
    int kind;    /* 0 Real, 1 Boolean, 2 Integer */
    size_t slot; /* index in the row of its type */
} Binding;

static int load(ModelInstance *m, Table *d, const char *file) {
    CsvTable t;
    char **header;
    Binding bind[N_REAL_CHANNELS + N_BOOLEAN_CHANNELS + N_INTEGER_CHANNELS];
    size_t nh, nbind = 0, cap = 0, k, j;
    int ok = -1, rc;

    if (csv_open(&t, m, "file", file, CSV_SKIP_BOM)) return -1;
    header = t.header;
    nh = t.ncol;
    if (nh == 0) {
        csv_fail(&t, 1, 0, "empty file (expected a header line starting with 'time')");
        goto done;
    }
    if (nh > MAX_FIELDS) {
        csv_fail(&t, 1, 0, "more than %d columns", MAX_FIELDS);
        goto done;
    }
    for (j = 0; j < nh; j++) { /* "name" -> name */
        size_t L = strlen(header[j]);
        if (L >= 2 && header[j][0] == '"' && header[j][L - 1] == '"') {
            header[j][L - 1] = '\0';
            header[j]++;
        }
        if (!*header[j]) { /* e.g. a trailing comma: rows would then be blamed for it */
            csv_fail(&t, 1, j + 1, "column %lu has no name", (unsigned long)j + 1);
            goto done;
        }
    }
    /* "time_s": the trolley survey's standard imu.csv and truth.csv */
    if (strcmp(header[0], "time") != 0 && strcmp(header[0], "time_s") != 0) {
        csv_fail(&t, 1, 1, "the first column must be 'time' or 'time_s' (s), not '%s'", header[0]);
        goto done;
    }
    for (j = 1; j < nh; j++) {
        for (k = 0; k < j; k++) {
            if (strcmp(header[j], header[k]) == 0) {
                csv_fail(&t, 1, j + 1, "column name '%s' repeats column %lu", header[j], (unsigned long)k + 1);
                goto done;
            }
        }
    }

    /* bind the channels: parameter order, so slots follow the channel numbers */
    for (k = 0; k < N_REAL_CHANNELS + N_BOOLEAN_CHANNELS + N_INTEGER_CHANNELS; k++) {
        const int kind = k < N_REAL_CHANNELS ? 0 : (k < N_REAL_CHANNELS + N_BOOLEAN_CHANNELS ? 1 : 2);
        const size_t c = kind == 0 ? k : (kind == 1 ? k - N_REAL_CHANNELS
                                                    : k - N_REAL_CHANNELS - N_BOOLEAN_CHANNELS);
        const size_t vr = kind == 0 ? VRS_REAL_COL(c) : (kind == 1 ? VRS_BOOL_COL(c) : VRS_INT_COL(c));
        const char *name = param_string(m, vr);
        int col;
        if (!*name) continue;
        col = find_column(&t, name, model_string_info[vr].name);
        if (col < 0) goto done;
        bind[nbind].column = col;
        bind[nbind].kind = kind;
        if (kind == 0) {
            d->real_slot[c] = (int)d->nr;
            bind[nbind].slot = d->nr++;
        } else if (kind == 1) {
            d->bool_slot[c] = (int)d->nb;
            bind[nbind].slot = d->nb++;
        } else {
            d->int_slot[c] = (int)d->ni;
            bind[nbind].slot = d->ni++;
        }
        nbind++;
    }

    while ((rc = csv_next_row(&t)) > 0) {
        char **fields = t.cell;
        const long lineno = t.line;
        double tk;
        if (t.ncell != nh) {
            csv_fail(&t, lineno, 0, "%lu fields, but the header has %lu columns", (unsigned long)t.ncell,
                     (unsigned long)nh);
            goto done;
        }
        if (d->n == cap) {
            const size_t nc = cap ? 2 * cap : 1024;
            double *nt = (double *)realloc(d->time, nc * sizeof *nt);
            double *ny = nt ? (double *)realloc(d->y, nc * (d->nr ? d->nr : 1) * sizeof *ny) : NULL;
            fmi2Boolean *nb = NULL;
            fmi2Integer *ni = NULL;
            if (nt) d->time = nt;
            if (ny) d->y = ny;
            if (ny) nb = (fmi2Boolean *)realloc(d->b, nc * (d->nb ? d->nb : 1) * sizeof *nb);
            if (nb) d->b = nb;
            if (nb) ni = (fmi2Integer *)realloc(d->i, nc * (d->ni ? d->ni : 1) * sizeof *ni);
            if (!ni) {
                csv_fail(&t, lineno, 0, "out of memory");
                goto done;
            }
            d->i = ni;
            cap = nc;
        }
        rc = csv_number(fields[0], &tk);
        if (rc) {
            csv_fail(&t, lineno, 1, "'%s' is not a %snumber", fields[0], rc == CSV_NOT_FINITE ? "finite " : "");
            goto done;
        }
        if (d->n > 0 && !(tk > d->time[d->n - 1])) {
            csv_fail(&t, lineno, 1, "%.17g %s the previous row's time %.17g (times must increase strictly)",
                     tk, tk == d->time[d->n - 1] ? "repeats" : "is before", d->time[d->n - 1]);
            goto done;
        }
        d->time[d->n] = tk;
        for (j = 0; j < nbind; j++) {
            const char *f = fields[bind[j].column];
            const size_t cno = (size_t)bind[j].column + 1;
            if (bind[j].kind == 0) {
                rc = csv_number(f, &d->y[d->n * d->nr + bind[j].slot]);
                if (rc) {
                    csv_fail(&t, lineno, cno, "'%s' is not a %snumber", f, rc == CSV_NOT_FINITE ? "finite " : "");
                    goto done;
                }
            } else if (bind[j].kind == 1) {
                double v;
                if (csv_number(f, &v) || (v != 0.0 && v != 1.0)) {
                    csv_fail(&t, lineno, cno, "'%s' is not 0 or 1", f);
                    goto done;
                }
                d->b[d->n * d->nb + bind[j].slot] = v != 0.0 ? fmi2True : fmi2False;
            } else {
                if (csv_integer(f, &d->i[d->n * d->ni + bind[j].slot])) {
                    csv_fail(&t, lineno, cno, "'%s' is not an integer", f);
                    goto done;
                }
            }
        }
        d->n++;
    }
    if (rc < 0) goto done;
    if (d->n == 0) {
        csv_fail(&t, 2, 0, "no data rows after the header");
        goto done;
    }
    d->min_gap = HUGE_VAL;
    for (k = 1; k < d->n; k++)
        if (d->time[k] - d->time[k - 1] < d->min_gap) d->min_gap = d->time[k] - d->time[k - 1];
    ok = 0;
done:
    csv_close(&t);
    return ok;
}

/* ---- lookup ---- */

static double tolerance(const Table *d, double tau) {
    const double a = TIME_TOLERANCE * (fabs(tau) > 1.0 ? fabs(tau) : 1.0);
    const double b = GAP_FRACTION * d->min_gap;
    return a < b ? a : b;
}

/* The last row k with tau_k <= limit, or -1: from the previous row when the time moved by
   at most one row (every step of a replay), by bisection otherwise. */
static long find_row(Table *d, double limit) {
    const size_t c = d->cursor, n = d->n;
    size_t lo = 0, hi = n;
    if (c < n && d->time[c] <= limit) {
        if (c + 1 == n || d->time[c + 1] > limit) return (long)c;
        if (c + 2 == n || d->time[c + 2] > limit) {
            d->cursor = c + 1;
            return (long)c + 1;
        }
    }
    while (lo < hi) { /* first row with tau > limit */
        const size_t mid = lo + (hi - lo) / 2;
        if (d->time[mid] <= limit) lo = mid + 1;
        else hi = mid;
    }
    if (lo == 0) return -1;
    d->cursor = lo - 1;
    return (long)lo - 1;
}

/* ---- model.h ---- */

int model_check_parameters(ModelInstance *m) {
    if (m->i[VRI_interpolation] != 0 && m->i[VRI_interpolation] != 1) {
        model_error(m, "parameter interpolation = %d must be 0 (hold) or 1 (linear)",
                    (int)m->i[VRI_interpolation]);
        return 1;
    }
    if (m->i[VRI_after_end] != 0 && m->i[VRI_after_end] != 1) {
        model_error(m, "parameter after_end = %d must be 0 (hold the last row) or 1 (end the "
                       "simulation)", (int)m->i[VRI_after_end]);
        return 1;
    }
    return 0;
}

static int build_table(ModelInstance *m) {
    const char *file = param_string(m, VRS_file);
    Table *d;
    size_t k;
    model_free(m);
    if (!*file) {
        /* no table and nothing bound: a source of zeros (a placeholder channel); a bound
           column without a file is an importer that dropped the file: never zeros, unless the
           table is declared optional */
        if (m->b[VRB_optional]) return 0;
        for (k = 0; k < N_REAL_CHANNELS + N_BOOLEAN_CHANNELS + N_INTEGER_CHANNELS; k++) {
            const size_t vr = k < N_REAL_CHANNELS ? VRS_REAL_COL(k)
                              : k < N_REAL_CHANNELS + N_BOOLEAN_CHANNELS ? VRS_BOOL_COL(k - N_REAL_CHANNELS)
                              : VRS_INT_COL(k - N_REAL_CHANNELS - N_BOOLEAN_CHANNELS);
            if (*param_string(m, vr)) {
                model_error(m, "parameter file is empty, but %s = '%s' asks for a column of it",
                            model_string_info[vr].name, param_string(m, vr));
                return 1;
            }
        }
        return 0;
    }
    d = (Table *)calloc(1, sizeof *d);
    if (!d) {
        model_error(m, "file %s: out of memory", file);
        return 1;
    }
    for (k = 0; k < N_REAL_CHANNELS; k++) d->real_slot[k] = -1;
    for (k = 0; k < N_BOOLEAN_CHANNELS; k++) d->bool_slot[k] = -1;
    for (k = 0; k < N_INTEGER_CHANNELS; k++) d->int_slot[k] = -1;
    if (load(m, d, file) != 0) {
        free_table(d);
        return 1;
    }
    m->modelData = d;
    return 0;
}

int model_initialize(ModelInstance *m) { return build_table(m); }

int model_outputs(ModelInstance *m) {
    Table *d = (Table *)m->modelData;
    size_t c;
    long k;
    double tau, tol, w = 0.0;
    int exact, ended;
    const fmi2Real *y0, *y1;

    if (!d) { /* no table */
        for (c = 0; c < N_REAL_CHANNELS; c++) m->r[VR_Y(c)] = 0.0;
        for (c = 0; c < N_BOOLEAN_CHANNELS; c++) m->b[VRB_OUT(c)] = fmi2False;
        for (c = 0; c < N_INTEGER_CHANNELS; c++) m->i[VRI_OUT(c)] = 0;
        return 0;
    }
    tau = m->r[0] - m->r[VR_time_offset]; /* r[0]: time */
    tol = tolerance(d, tau);
    k = find_row(d, tau + tol);
    ended = k == (long)d->n - 1 && tau > d->time[d->n - 1] + tol;
    if (k < 0) k = 0; /* before the first row: hold it */
    exact = k == (long)d->n - 1 || fabs(tau - d->time[k]) <= tol || tau < d->time[k] ||
            m->i[VRI_interpolation] == 0;
    if (!exact) w = (tau - d->time[k]) / (d->time[k + 1] - d->time[k]);
    y0 = d->y + (size_t)k * d->nr;
    y1 = exact ? y0 : y0 + d->nr;
    for (c = 0; c < N_REAL_CHANNELS; c++) {
        const int s = d->real_slot[c];
        if (s < 0) m->r[VR_Y(c)] = 0.0;
        else if (exact) m->r[VR_Y(c)] = y0[s];
        else m->r[VR_Y(c)] = y0[s] + (y1[s] - y0[s]) * w;
    }
    for (c = 0; c < N_BOOLEAN_CHANNELS; c++) {
        const int s = d->bool_slot[c];
        m->b[VRB_OUT(c)] = s < 0 ? fmi2False : d->b[(size_t)k * d->nb + (size_t)s];
    }
    for (c = 0; c < N_INTEGER_CHANNELS; c++) {
        const int s = d->int_slot[c];
        m->i[VRI_OUT(c)] = s < 0 ? 0 : d->i[(size_t)k * d->ni + (size_t)s];
    }
    if (ended && m->i[VRI_after_end] == 1)
        model_terminate(m, d->time[d->n - 1] + m->r[VR_time_offset],
                        "%s: the table ends at its time %.17g (simulation time %.17g)",
                        param_string(m, VRS_file), d->time[d->n - 1],
                        d->time[d->n - 1] + m->r[VR_time_offset]);
    return 0;
}

/* The derivatives of a model without states: never called. */
void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {
    (void)m, (void)t, (void)x, (void)dx;
}

/* modelData is not part of the FMU state: read the table again from the restored
   parameters (the cursor is only a hint). */
int model_state_restored(ModelInstance *m) { return build_table(m); }

void model_free(ModelInstance *m) {
    free_table((Table *)m->modelData);
    m->modelData = NULL;
}
