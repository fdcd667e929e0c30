/* TrackGeometry: 3-D design alignment on WGS-84 with alignment/level irregularities and a
 * body wobble, the C mirror of models/track/geometry.py (which states the element table,
 * the frames and the equations; tests/test_trolley.py proves the two equal).
 * Included (static) by Trolley.c.
 */
#ifndef RAILFMU_TRACK_GEOMETRY_H
#define RAILFMU_TRACK_GEOMETRY_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "Earth.h"
#include "ProfileTable.h"
#include "csv_table.h"
#include "erri_b176.h"
#include "model.h"
#include "rng.h"

#define TG_PI 3.14159265358979323846
#define TG_RAIL_BASE 1.5      /* m between the rail centres: roll = asin(cant / b) */
#define TG_MAX_CANT_MM 200.0
#define TG_MAX_GRADIENT 100.0 /* per mille */

static const double TG_GL16_X[8] = {0.09501250983763744, 0.2816035507792589, 0.45801677765722737,
                                    0.6178762444026438,  0.755404408355003,  0.8656312023878318,
                                    0.9445750230732326,  0.9894009349916499};
static const double TG_GL16_W[8] = {0.18945061045506864, 0.18260341504492364, 0.16915651939500265,
                                    0.1495959888165767,  0.12462897125553407, 0.0951585116824926,
                                    0.062253523938647456, 0.027152459411754176};

typedef struct {
    size_t nh, nv, np;
    double *hs, *k0, *k1, *c0, *c1, *chi; /* hs, chi: nh + 1 */
    double *vs, *g0, *g1;                 /* vs: nv + 1 */
    int *hshape, *vshape;                 /* transition shape per element: 0 linear, 1 bloss */
    double *pieces, *P;                   /* np + 1 piece ends, P: 3 (np + 1) */
    int nlines;
    double *omega, *ay, *az, *cpy, *spy, *cpz, *spz; /* cos, sin of the phases */
    double harm_y, harm_z, harm_w, wob_y, wob_z, wob_w;
    ProfileTable table;           /* measured (table.n == 0: none) */
    double *kinks;                /* element ends and table rows inside (0, length) */
    size_t nk;
    double r0e[3], Cen0[3][3], omega_n0[3];
} TrackGeom;

typedef struct {
    double r[3], r1[3], r2[3], q[3];
    /* attitude in n0 as cosines and sines (C_b^n0 = R3(psi) R2(theta) R1(phi)), no trig */
    double cpsi, spsi, cth, sth, cphi, sphi, dpsi, dtheta, dphi;
} TrackPoint;

static void tg_free(TrackGeom *g) {
    if (!g) return;
    free(g->hs), free(g->k0), free(g->k1), free(g->c0), free(g->c1), free(g->chi);
    free(g->vs), free(g->g0), free(g->g1), free(g->pieces), free(g->P), free(g->hshape), free(g->vshape);
    free(g->omega), free(g->ay), free(g->az), free(g->cpy), free(g->spy), free(g->cpz), free(g->spz);
    profile_free(&g->table), free(g->kinks);
    memset(g, 0, sizeof *g);
}

/* ---- the element table ------------------------------------------------------------------- */

static const char *const TG_COLUMNS[7] = {"kind", "start_m", "end_m", "radius_m", "cant_mm",
                                          "gradient_permille", "transition"};
static const char *const TG_SHAPES[2] = {"linear", "bloss"};
enum { TG_STRAIGHT, TG_CLOTHOID, TG_CURVE_LEFT, TG_CURVE_RIGHT, TG_GRADE, TG_VCURVE };
static const char *const TG_KINDS[6] = {"straight", "clothoid", "curve_left", "curve_right",
                                        "grade", "vertical_curve"};

typedef struct {
    long line;
    int kind, shape;
    double start, end, radius, cant, grad;
} TgRow;


static int tg_push(TgRow **rows, size_t *n, size_t *cap, const TgRow *r) {
    if (*n == *cap) {
        size_t nc = *cap ? 2 * *cap : 32;
        TgRow *a = (TgRow *)realloc(*rows, nc * sizeof *a);
        if (!a) return 1;
        *rows = a;
        *cap = nc;
    }
    (*rows)[(*n)++] = *r;
    return 0;
}

#define TG_FAIL(...)                    \
    do {                                \
        csv_fail(&t, __VA_ARGS__);      \
        goto fail;                      \
    } while (0)

/* Reads and checks the table into g (alignment part); 1 after one model_error. */
static int tg_read(ModelInstance *m, TrackGeom *g, const char *file) {
    CsvTable t;
    TgRow *H = NULL, *V = NULL, r;
    size_t nh = 0, nv = 0, ch = 0, cv = 0, i, j, ncol = 6;
    int rc;
    if (!*file) {
        model_error(m, "parameter track_file is empty: a track element table CSV (%s,...) is needed",
                    TG_COLUMNS[0]);
        return 1;
    }
    if (csv_open(&t, m, "track_file", file, CSV_SKIP_BOM)) return 1;
    for (j = 0; j < t.ncol; j++)
        if ((t.ncol != 6 && t.ncol != 7) || strcmp(t.header[j], TG_COLUMNS[j]) != 0)
            TG_FAIL(1, 0, "header must be kind,start_m,end_m,radius_m,cant_mm,gradient_permille (and "
                    "optionally ,transition)");
    if (t.ncol) ncol = t.ncol;
    while ((rc = csv_next_row(&t)) > 0) {
        char **fld = t.cell;
        const long lineno = t.line;
        double v[5];
        int has[5];
        if (t.ncell != ncol)
            TG_FAIL(lineno, 0, "%lu fields, expected %lu", (unsigned long)t.ncell, (unsigned long)ncol);
        r.line = lineno;
        r.kind = -1;
        for (j = 0; j < 6; j++)
            if (strcmp(fld[0], TG_KINDS[j]) == 0) r.kind = (int)j;
        if (r.kind < 0)
            TG_FAIL(lineno, 1, "'%s' is not one of straight, clothoid, curve_left, curve_right, grade, "
                    "vertical_curve", fld[0]);
        for (j = 0; j < 5; j++) {
            has[j] = *fld[j + 1] != '\0';
            v[j] = 0.0;
            if (has[j] && csv_number(fld[j + 1], &v[j]) != CSV_OK)
                TG_FAIL(lineno, j + 2, "'%s' is not a finite number", fld[j + 1]);
        }
        if (!has[0] || !has[1]) TG_FAIL(lineno, has[0] ? 3 : 2, "missing");
        r.start = v[0], r.end = v[1], r.radius = v[2], r.cant = v[3], r.grad = v[4];
        r.shape = 0;
        if (ncol == 7 && *fld[6]) {
            r.shape = -1;
            for (j = 0; j < 2; j++)
                if (strcmp(fld[6], TG_SHAPES[j]) == 0) r.shape = (int)j;
            if (r.shape < 0) TG_FAIL(lineno, 7, "'%s' is not one of linear, bloss", fld[6]);
            if (r.kind != TG_CLOTHOID && r.kind != TG_VCURVE)
                TG_FAIL(lineno, 7, "only clothoid and vertical_curve rows take a transition shape, not a %s",
                        TG_KINDS[r.kind]);
        }
        {
            const int horizontal = r.kind <= TG_CURVE_RIGHT;
            const size_t n = horizontal ? nh : nv;
            const double expected = n ? (horizontal ? H : V)[n - 1].end : 0.0;
            if (!(r.end > r.start))
                TG_FAIL(lineno, 3, "%g is not greater than start_m %g (distances must increase)", r.end,
                        r.start);
            if (fabs(r.start - expected) > 1e-9 * (fabs(expected) > 1.0 ? fabs(expected) : 1.0))
                TG_FAIL(lineno, 2, "%g must equal %g, where the previous %s element ends (no gaps or "
                        "overlaps, distances increasing)", r.start, expected,
                        horizontal ? "horizontal" : "vertical");
            r.start = expected;
            if (r.kind == TG_CURVE_LEFT || r.kind == TG_CURVE_RIGHT) {
                if (!has[2] || !(r.radius > 0))
                    TG_FAIL(lineno, 4, "a %s needs a radius > 0 m", TG_KINDS[r.kind]);
                if (!(r.cant >= 0 && r.cant < TG_MAX_CANT_MM))
                    TG_FAIL(lineno, 5, "%g must be in [0, %g) mm", r.cant, TG_MAX_CANT_MM);
            }
            if (r.kind == TG_GRADE && (!has[4] || !(fabs(r.grad) < TG_MAX_GRADIENT)))
                TG_FAIL(lineno, 6, "a grade needs a gradient below %g per mille in size", TG_MAX_GRADIENT);
            if (horizontal ? tg_push(&H, &nh, &ch, &r) : tg_push(&V, &nv, &cv, &r))
                TG_FAIL(0, 0, "out of memory");
        }
    }
    if (rc < 0) goto fail;
    if (!nh || !nv)
        TG_FAIL(0, 0, "needs horizontal (straight, clothoid, curve_left, curve_right) and vertical (grade, "
                "vertical_curve) elements");
    if (fabs(H[nh - 1].end - V[nv - 1].end) > 1e-9 * H[nh - 1].end)
        TG_FAIL(0, 0, "the horizontal elements end at %g m, the vertical ones at %g m: both must cover the "
                "same length", H[nh - 1].end, V[nv - 1].end);
    g->nh = nh, g->nv = nv;
    g->hs = (double *)calloc(nh + 1, sizeof(double));
    g->chi = (double *)calloc(nh + 1, sizeof(double));
    g->k0 = (double *)calloc(nh, sizeof(double)), g->k1 = (double *)calloc(nh, sizeof(double));
    g->c0 = (double *)calloc(nh, sizeof(double)), g->c1 = (double *)calloc(nh, sizeof(double));
    g->vs = (double *)calloc(nv + 1, sizeof(double));
    g->g0 = (double *)calloc(nv, sizeof(double)), g->g1 = (double *)calloc(nv, sizeof(double));
    g->hshape = (int *)calloc(nh, sizeof(int)), g->vshape = (int *)calloc(nv, sizeof(int));
    if (!g->hs || !g->chi || !g->k0 || !g->k1 || !g->c0 || !g->c1 || !g->vs || !g->g0 || !g->g1 ||
        !g->hshape || !g->vshape)
        TG_FAIL(0, 0, "out of memory");
    for (i = 0; i < nh; i++) {
        /* curvature and signed cant at the element's ends */
        double k = 0.0, c = 0.0;
        const TgRow *e = &H[i];
        g->hs[i + 1] = e->end;
        g->hshape[i] = e->shape;
        if (e->kind == TG_CLOTHOID) {
            const TgRow *a = i ? &H[i - 1] : NULL, *b = i + 1 < nh ? &H[i + 1] : NULL;
            double ka, kb, ca, cb;
            if (!a || !b || a->kind == TG_CLOTHOID || b->kind == TG_CLOTHOID)
                TG_FAIL(e->line, 1, "a clothoid needs a straight or curve on both sides");
            ka = a->kind == TG_STRAIGHT ? 0.0 : (a->kind == TG_CURVE_RIGHT ? 1.0 : -1.0) / a->radius;
            kb = b->kind == TG_STRAIGHT ? 0.0 : (b->kind == TG_CURVE_RIGHT ? 1.0 : -1.0) / b->radius;
            ca = a->kind == TG_STRAIGHT ? 0.0 : (a->kind == TG_CURVE_RIGHT ? 1.0 : -1.0) * a->cant * 1e-3;
            cb = b->kind == TG_STRAIGHT ? 0.0 : (b->kind == TG_CURVE_RIGHT ? 1.0 : -1.0) * b->cant * 1e-3;
            g->k0[i] = ka, g->k1[i] = kb, g->c0[i] = ca, g->c1[i] = cb;
            continue;
        }
        if (e->kind != TG_STRAIGHT) {
            const double sign = e->kind == TG_CURVE_RIGHT ? 1.0 : -1.0;
            k = sign / e->radius;
            c = sign * e->cant * 1e-3;
        }
        g->k0[i] = g->k1[i] = k;
        g->c0[i] = g->c1[i] = c;
    }
    for (i = 0; i < nv; i++) {
        const TgRow *e = &V[i];
        g->vs[i + 1] = e->end;
        g->vshape[i] = e->shape;
        if (e->kind == TG_VCURVE) {
            if (!i || i + 1 >= nv || V[i - 1].kind != TG_GRADE || V[i + 1].kind != TG_GRADE)
                TG_FAIL(e->line, 1, "a vertical_curve needs a grade on both sides");
            g->g0[i] = V[i - 1].grad * 1e-3, g->g1[i] = V[i + 1].grad * 1e-3;
        } else {
            g->g0[i] = g->g1[i] = e->grad * 1e-3;
        }
    }
    g->vs[nv] = g->hs[nh];
    csv_close(&t);
    free(H), free(V);
    return 0;
fail:
    csv_close(&t);
    free(H), free(V);
    return 1;
}

static size_t tg_find(const double *x, size_t n, double s);

/* The measured table (models/track/geometry.py: the TrackIrregularity profile_file format);
   after tg_read (it must cover 0..length). 1 after one model_error. */
static int tg_read_table(ModelInstance *m, TrackGeom *g, const char *file) {
    const ProfileTable *p = &g->table;
    if (!*file) return 0;
    if (profile_read(m, "irregularity_file", file, &g->table)) return 1;
    if (p->s[0] > 0.0 || p->s[p->n - 1] < g->hs[g->nh]) {
        char *path = model_resolve_path(m, file);
        model_error(m, "irregularity_file %s: covers s = %g..%g m, the track needs 0..%g m", path ? path : file,
                    p->s[0], p->s[p->n - 1], g->hs[g->nh]);
        free(path);
        return 1;
    }
    return 0;
}

/* value, d/ds, d2/ds2 of the table's three columns at s (o[3 c + k]) */
static void tg_table(const TrackGeom *G, double s, double o[9]) {
    const size_t i = tg_find(G->table.s, G->table.n - 1, s);
    const double h = G->table.s[i + 1] - G->table.s[i], t = (s - G->table.s[i]) / h, t2 = t * t;
    int c;
    for (c = 0; c < 3; c++) {
        const double y0 = G->table.y[3 * i + c], y1 = G->table.y[3 * (i + 1) + c], m0 = G->table.dy[3 * i + c],
                     m1 = G->table.dy[3 * (i + 1) + c];
        o[3 * c] = (2.0 * t2 * t - 3.0 * t2 + 1.0) * y0 + (t2 * t - 2.0 * t2 + t) * h * m0 +
                   (-2.0 * t2 * t + 3.0 * t2) * y1 + (t2 * t - t2) * h * m1;
        o[3 * c + 1] = ((6.0 * t2 - 6.0 * t) * y0 + (-6.0 * t2 + 6.0 * t) * y1) / h +
                       (3.0 * t2 - 4.0 * t + 1.0) * m0 + (3.0 * t2 - 2.0 * t) * m1;
        o[3 * c + 2] = ((12.0 * t - 6.0) * y0 + (6.0 - 12.0 * t) * y1) / (h * h) +
                       ((6.0 * t - 4.0) * m0 + (6.0 * t - 2.0) * m1) / h;
    }
}

/* ---- evaluation --------------------------------------------------------------------------- */

/* element index: hs[i] <= s < hs[i + 1], clamped */
static size_t tg_find(const double *x, size_t n, double s) {
    size_t lo = 0, hi = n + 1; /* first index with x > s in x[0..n] */
    while (lo < hi) {
        const size_t mid = lo + (hi - lo) / 2;
        if (x[mid] <= s) lo = mid + 1;
        else hi = mid;
    }
    if (lo == 0) return 0;
    return lo - 1 < n ? lo - 1 : n - 1;
}

typedef struct {
    double chi, k, dk, g, dg, c, dc;
} TgAngles;

/* the shapes of models/track/geometry.py, in the same arithmetic */
static void tg_angles(const TrackGeom *G, double s, TgAngles *a) {
    const size_t i = tg_find(G->hs, G->nh, s), j = tg_find(G->vs, G->nv, s);
    const double L = G->hs[i + 1] - G->hs[i], u = s - G->hs[i], Lv = G->vs[j + 1] - G->vs[j];
    if (G->hshape[i]) { /* bloss: f = x^2 (3 - 2 x), f' = 6 x (1 - x) / L */
        const double x = u / L, f = x * x * (3.0 - 2.0 * x), f1 = 6.0 * x * (1.0 - x) / L;
        const double Dk = G->k1[i] - G->k0[i], Dc = G->c1[i] - G->c0[i];
        a->chi = G->chi[i] + u * G->k0[i] + Dk * L * (x * x * x * (1.0 - 0.5 * x));
        a->k = G->k0[i] + Dk * f, a->dk = Dk * f1;
        a->c = G->c0[i] + Dc * f, a->dc = Dc * f1;
    } else {
        a->dk = (G->k1[i] - G->k0[i]) / L;
        a->chi = G->chi[i] + u * (G->k0[i] + 0.5 * a->dk * u);
        a->k = G->k0[i] + a->dk * u;
        a->dc = (G->c1[i] - G->c0[i]) / L;
        a->c = G->c0[i] + a->dc * u;
    }
    if (G->vshape[j]) {
        const double x = (s - G->vs[j]) / Lv, Dg = G->g1[j] - G->g0[j];
        a->g = G->g0[j] + Dg * (x * x * (3.0 - 2.0 * x));
        a->dg = Dg * (6.0 * x * (1.0 - x) / Lv);
    } else {
        a->dg = (G->g1[j] - G->g0[j]) / Lv;
        a->g = G->g0[j] + a->dg * (s - G->vs[j]);
    }
}

static void tg_tangent(const TrackGeom *G, double s, double T[3]) {
    TgAngles a;
    double ct;
    tg_angles(G, s, &a);
    ct = 1.0 / sqrt(1.0 + a.g * a.g);
    T[0] = ct * cos(a.chi);
    T[1] = ct * sin(a.chi);
    T[2] = -a.g * ct;
}

static void tg_integrate(const TrackGeom *G, double a, double b, double d[3]) {
    const double m = 0.5 * (a + b), h = 0.5 * (b - a);
    double acc[3] = {0.0, 0.0, 0.0}, t1[3], t2[3];
    int k, i;
    for (k = 0; k < 8; k++) {
        tg_tangent(G, m - h * TG_GL16_X[k], t1);
        tg_tangent(G, m + h * TG_GL16_X[k], t2);
        for (i = 0; i < 3; i++) acc[i] += TG_GL16_W[k] * (t1[i] + t2[i]);
    }
    for (i = 0; i < 3; i++) d[i] = h * acc[i];
}

static void tg_design_position(const TrackGeom *G, double s, double p[3]) {
    const size_t k = tg_find(G->pieces, G->np, s);
    double d[3];
    int i;
    tg_integrate(G, G->pieces[k], s, d);
    for (i = 0; i < 3; i++) p[i] = G->P[3 * k + i] + d[i];
}

/* y, y', y'', z, z', z'' of the irregularities at s */
static void tg_offsets(const TrackGeom *G, double s, double o[6]) {
    int k;
    memset(o, 0, 6 * sizeof(double));
    for (k = 0; k < G->nlines; k++) {
        /* sin(w s + phi) = sin(w s) cos(phi) + cos(w s) sin(phi): one sincos per line */
        const double w = G->omega[k], ay = G->ay[k], az = G->az[k], sn = sin(w * s), cs = cos(w * s);
        const double sy = sn * G->cpy[k] + cs * G->spy[k], cy = cs * G->cpy[k] - sn * G->spy[k];
        const double sz = sn * G->cpz[k] + cs * G->spz[k], cz = cs * G->cpz[k] - sn * G->spz[k];
        o[0] += ay * sy;
        o[1] += ay * w * cy;
        o[2] -= ay * w * w * sy;
        o[3] += az * sz;
        o[4] += az * w * cz;
        o[5] -= az * w * w * sz;
    }
    if (G->harm_y != 0.0 || G->harm_z != 0.0) {
        const double w = G->harm_w, sn = sin(w * s), cs = cos(w * s);
        o[0] += G->harm_y * sn, o[1] += G->harm_y * w * cs, o[2] -= G->harm_y * w * w * sn;
        o[3] += G->harm_z * sn, o[4] += G->harm_z * w * cs, o[5] -= G->harm_z * w * w * sn;
    }
    if (G->table.n) {
        double tb[9];
        tg_table(G, s, tb);
        o[0] += tb[0], o[1] += tb[1], o[2] += tb[2];
        o[3] += 0.5 * (tb[3] + tb[6]), o[4] += 0.5 * (tb[4] + tb[7]), o[5] += 0.5 * (tb[5] + tb[8]);
    }
}

#define TG_ADD(dst, f, v) (dst)[0] += (f) * (v)[0], (dst)[1] += (f) * (v)[1], (dst)[2] += (f) * (v)[2]

/* body point derivatives, rail tangent and attitude at s; the position too if position != 0 */
static void tg_point(const TrackGeom *G, double s, int position, TrackPoint *P) {
    TgAngles a;
    double den, ct, st, th1, sc, cc, H[3], Y[3], T[3], Z[3], T1[3], Y1[3], Y2[3];
    double o[6], w[6] = {0, 0, 0, 0, 0, 0}, q1[3], hh, h, dh, nq;
    int i;
    tg_angles(G, s, &a);
    den = 1.0 + a.g * a.g;
    ct = 1.0 / sqrt(den);
    st = a.g * ct;
    th1 = a.dg / den;
    sc = sin(a.chi), cc = cos(a.chi);
    H[0] = cc, H[1] = sc, H[2] = 0.0;
    Y[0] = -sc, Y[1] = cc, Y[2] = 0.0;
    T[0] = ct * cc, T[1] = ct * sc, T[2] = -st;
    Z[0] = st * cc, Z[1] = st * sc, Z[2] = ct; /* the normal of T in the vertical plane */
    for (i = 0; i < 3; i++) {
        T1[i] = -th1 * Z[i] + ct * a.k * Y[i];
        Y1[i] = -a.k * H[i];
        Y2[i] = -a.dk * H[i] - a.k * a.k * Y[i];
    }
    /* offsets: y along Y (turns with the heading), z along the fixed vertical D of n0 */
    tg_offsets(G, s, o);
    for (i = 0; i < 3; i++) {
        P->q[i] = T[i] + o[1] * Y[i] + o[0] * Y1[i];
        q1[i] = T1[i] + o[2] * Y[i] + 2.0 * o[1] * Y1[i] + o[0] * Y2[i];
    }
    P->q[2] += o[4];
    q1[2] += o[5];
    if (G->wob_y != 0.0 || G->wob_z != 0.0) {
        const double k = G->wob_w, sn = sin(k * s), cs = cos(k * s);
        w[0] = G->wob_y * sn, w[1] = G->wob_y * k * cs, w[2] = -G->wob_y * k * k * sn;
        w[3] = G->wob_z * sn, w[4] = G->wob_z * k * cs, w[5] = -G->wob_z * k * k * sn;
    }
    for (i = 0; i < 3; i++) {
        P->r1[i] = P->q[i] + w[1] * Y[i] + w[0] * Y1[i];
        P->r2[i] = q1[i] + w[2] * Y[i] + 2.0 * w[1] * Y1[i] + w[0] * Y2[i];
    }
    P->r1[2] += w[4];
    P->r2[2] += w[5];
    if (position) {
        tg_design_position(G, s, P->r);
        TG_ADD(P->r, o[0] + w[0], Y);
        P->r[2] += o[3] + w[3];
    }
    hh = P->q[0] * P->q[0] + P->q[1] * P->q[1];
    h = sqrt(hh);
    nq = sqrt(hh + P->q[2] * P->q[2]);
    P->cpsi = P->q[0] / h, P->spsi = P->q[1] / h;
    P->cth = h / nq, P->sth = -P->q[2] / nq;
    P->dpsi = (P->q[0] * q1[1] - P->q[1] * q1[0]) / hh;
    dh = (P->q[0] * q1[0] + P->q[1] * q1[1]) / h;
    P->dtheta = (-h * q1[2] + P->q[2] * dh) / (hh + P->q[2] * P->q[2]);
    P->sphi = a.c / TG_RAIL_BASE;
    P->cphi = sqrt(1.0 - P->sphi * P->sphi);
    P->dphi = a.dc / (TG_RAIL_BASE * P->cphi);
}

/* ---- setup -------------------------------------------------------------------------------- */

/* ERRI B176 (models/track/irregularity.py): A Oc^2 / ((O^2 + Or^2)(O^2 + Oc^2)) */
static double tg_psd(double A, double omega) {
    const double oc = ERRI_OMEGA_C, orr = ERRI_OMEGA_R, o2 = omega * omega;
    return A * oc * oc / ((o2 + orr * orr) * (o2 + oc * oc));
}

static int tg_cmp(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* After tg_read: headings, piece ends and positions, irregularity lines, placement. */
static int tg_setup(ModelInstance *m, TrackGeom *G, double lat0, double lon0, double h0, double azimuth,
                    int level, double scale, int nlines, double lmin, double lmax, int seed,
                    double harm_y, double harm_z, double harm_l, double wob_y, double wob_z,
                    double wob_l) {
    const double *const AA = ERRI_A_ALIGNMENT, *const AV = ERRI_A_VERTICAL;
    size_t i, j, n = 0;
    double *all;
    double C[3][3];
    G->chi[0] = azimuth;
    for (i = 0; i < G->nh; i++)
        G->chi[i + 1] = G->chi[i] + 0.5 * (G->k0[i] + G->k1[i]) * (G->hs[i + 1] - G->hs[i]);
    all = (double *)malloc((G->nh + G->nv + 2) * sizeof(double));
    if (!all) goto oom;
    for (i = 1; i < G->nh; i++) all[n++] = G->hs[i];
    for (i = 1; i < G->nv; i++) all[n++] = G->vs[i];
    qsort(all, n, sizeof(double), tg_cmp);
    G->pieces = (double *)malloc((n + 2) * sizeof(double));
    if (!G->pieces) {
        free(all);
        goto oom;
    }
    G->pieces[0] = 0.0;
    G->np = 0;
    for (i = 0; i < n; i++)
        if (all[i] != G->pieces[G->np]) G->pieces[++G->np] = all[i];
    free(all);
    G->pieces[++G->np] = G->hs[G->nh];
    /* kinks: the piece ends inside (0, length) and the table rows there, sorted, unique */
    G->kinks = (double *)malloc((G->np + G->table.n + 1) * sizeof(double));
    if (!G->kinks) goto oom;
    n = 0;
    for (i = 1; i < G->np; i++) G->kinks[n++] = G->pieces[i];
    for (i = 0; i < G->table.n; i++)
        if (G->table.s[i] > 0.0 && G->table.s[i] < G->hs[G->nh]) G->kinks[n++] = G->table.s[i];
    qsort(G->kinks, n, sizeof(double), tg_cmp);
    G->nk = 0;
    for (i = 0; i < n; i++)
        if (G->nk == 0 || G->kinks[i] != G->kinks[G->nk - 1]) G->kinks[G->nk++] = G->kinks[i];
    G->P = (double *)calloc(3 * (G->np + 1), sizeof(double));
    if (!G->P) goto oom;
    for (i = 0; i < G->np; i++) {
        double d[3];
        tg_integrate(G, G->pieces[i], G->pieces[i + 1], d);
        for (j = 0; j < 3; j++) G->P[3 * (i + 1) + j] = G->P[3 * i + j] + d[j];
    }
    G->nlines = level == 0 ? 0 : nlines;
    if (G->nlines > 0) {
        uint64_t rng = (uint64_t)(int64_t)seed;
        const double W0 = 2.0 * TG_PI / lmax, ratio = lmax / lmin;
        G->omega = (double *)malloc(G->nlines * sizeof(double));
        G->ay = (double *)malloc(G->nlines * sizeof(double));
        G->az = (double *)malloc(G->nlines * sizeof(double));
        G->cpy = (double *)malloc(G->nlines * sizeof(double));
        G->spy = (double *)malloc(G->nlines * sizeof(double));
        G->cpz = (double *)malloc(G->nlines * sizeof(double));
        G->spz = (double *)malloc(G->nlines * sizeof(double));
        if (!G->omega || !G->ay || !G->az || !G->cpy || !G->spy || !G->cpz || !G->spz) goto oom;
        for (i = 0; i < (size_t)G->nlines; i++) {
            const double wa = W0 * pow(ratio, (double)i / G->nlines);
            const double wb = W0 * pow(ratio, (double)(i + 1) / G->nlines);
            const double w = sqrt(wa * wb);
            G->omega[i] = w;
            G->ay[i] = scale * sqrt(2.0 * tg_psd(AA[level], w) * (wb - wa));
            G->az[i] = scale * sqrt(2.0 * tg_psd(AV[level], w) * (wb - wa));
        }
        for (i = 0; i < (size_t)G->nlines; i++) {
            const double phi = 2.0 * TG_PI * rng_uniform(&rng);
            G->cpy[i] = cos(phi), G->spy[i] = sin(phi);
        }
        for (i = 0; i < (size_t)G->nlines; i++) {
            const double phi = 2.0 * TG_PI * rng_uniform(&rng);
            G->cpz[i] = cos(phi), G->spz[i] = sin(phi);
        }
    }
    G->harm_y = harm_y, G->harm_z = harm_z, G->harm_w = 2.0 * TG_PI / harm_l;
    G->wob_y = wob_y, G->wob_z = wob_z, G->wob_w = 2.0 * TG_PI / wob_l;
    earth_lla_to_ecef(lat0, lon0, h0, G->r0e);
    earth_ecef_to_ned(lat0, lon0, C);
    memcpy(G->Cen0, C, sizeof C);
    G->omega_n0[0] = EARTH_RATE * cos(lat0);
    G->omega_n0[1] = 0.0;
    G->omega_n0[2] = -EARTH_RATE * sin(lat0);
    return 0;
oom:
    model_error(m, "Trolley: out of memory setting up the track");
    return 1;
}

#endif
