/* CsvTable (csv_table.h). */
#include "csv_table.h"
#include "portable.h"

#include <errno.h>
#include <limits.h>
#include <locale.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char *csv_trim(char *s) {
    char *e;
    while (*s == ' ' || *s == '\t' || *s == '\r') s++;
    e = s + strlen(s);
    while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r')) *--e = '\0';
    return s;
}

/* Splits s in place at its commas into trimmed cells, growing *cells; the count, or
   (size_t)-1 out of memory. */
static size_t csv_split(char *s, char ***cells, size_t *cap) {
    size_t n = 1, k = 0;
    const char *q;
    for (q = s; *q; q++) n += *q == ',';
    if (n > *cap) {
        char **a = (char **)realloc(*cells, n * sizeof *a);
        if (!a) return (size_t)-1;
        *cells = a;
        *cap = n;
    }
    for (;;) {
        char *c = strchr(s, ',');
        if (c) *c = '\0';
        (*cells)[k++] = csv_trim(s);
        if (!c) return n;
        s = c + 1;
    }
}

/* The next line (without its '\n') or NULL at the end; counts it. */
static char *csv_line(CsvTable *t) {
    char *line = t->rest, *nl;
    if (!*line) return NULL;
    nl = strchr(line, '\n');
    if (nl) {
        *nl = '\0';
        t->rest = nl + 1;
    } else {
        t->rest = line + strlen(line);
    }
    t->line++;
    return line;
}

static void csv_vfail(const CsvTable *t, long line, size_t column, const char *fmt, va_list ap) {
    char small[512], *msg = small;
    va_list ap2;
    int n;
    va_copy(ap2, ap);
    n = vsnprintf(small, sizeof small, fmt, ap);
    if (n >= (int)sizeof small && (msg = (char *)malloc((size_t)n + 1)) != NULL)
        vsnprintf(msg, (size_t)n + 1, fmt, ap2);
    else if (n >= (int)sizeof small)
        msg = small; /* truncated rather than none */
    va_end(ap2);
    if (line <= 0)
        model_error(t->m, "%s %s: %s", t->label, t->path, msg);
    else if (t->flags & CSV_COLON)
        model_error(t->m, "%s %s:%ld: %s", t->label, t->path, line, msg);
    else if (column == 0)
        model_error(t->m, "%s %s, line %ld: %s", t->label, t->path, line, msg);
    else if (line == 1 || column > t->ncol)
        model_error(t->m, "%s %s, line %ld, column %lu: %s", t->label, t->path, line,
                    (unsigned long)column, msg);
    else
        model_error(t->m, "%s %s, line %ld, column %lu (%s): %s", t->label, t->path, line,
                    (unsigned long)column, t->header[column - 1], msg);
    if (msg != small) free(msg);
}

void csv_fail(const CsvTable *t, long line, size_t column, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    csv_vfail(t, line, column, fmt, ap);
    va_end(ap);
}

void csv_close(CsvTable *t) {
    free(t->path);
    free(t->text);
    free(t->header);
    free(t->cell);
    memset(t, 0, sizeof *t);
}

/* The whole file, NUL-terminated; NULL after one message. */
static char *csv_read_file(CsvTable *t) {
    FILE *f = portable_fopen(t->path, "rb");
    char *buf = NULL;
    size_t cap = 0, len = 0;
    if (!f) {
        csv_fail(t, 0, 0, "cannot open (%s)", strerror(errno));
        return NULL;
    }
    for (;;) {
        size_t got;
        if (cap - len < 65536) {
            const size_t nc = cap ? 2 * cap : 65536 + 1;
            char *nb = (char *)realloc(buf, nc);
            if (!nb) {
                csv_fail(t, 0, 0, "out of memory");
                free(buf);
                fclose(f);
                return NULL;
            }
            buf = nb;
            cap = nc;
        }
        got = fread(buf + len, 1, cap - len - 1, f);
        len += got;
        if (got == 0) break;
    }
    if (ferror(f)) {
        csv_fail(t, 0, 0, "read error");
        free(buf);
        fclose(f);
        return NULL;
    }
    fclose(f);
    buf[len] = '\0';
    {   /* a NUL would end the text early: the rows after it would be lost unseen */
        const char *nul = (const char *)memchr(buf, '\0', len), *q, *start = buf;
        long line = 1;
        if (nul) {
            for (q = buf; q < nul; q++)
                if (*q == '\n') line++, start = q + 1;
            csv_fail(t, line, 0, "NUL byte at character %lu (a binary or UTF-16 file?)",
                     (unsigned long)(nul - start) + 1);
            free(buf);
            return NULL;
        }
    }
    return buf;
}

int csv_open(CsvTable *t, ModelInstance *m, const char *label, const char *file, unsigned flags) {
    char *line;
    size_t cap = 0;
    memset(t, 0, sizeof *t);
    t->m = m;
    t->label = label;
    t->flags = flags;
    t->path = model_resolve_path(m, file);
    if (!t->path) {
        model_error(m, "%s %s: a relative path needs the FMU's resources folder, which the "
                       "importer did not give (use an absolute path)", label, file);
        return 1;
    }
    t->text = t->rest = csv_read_file(t);
    if (!t->text) goto fail;
    if ((flags & CSV_SKIP_BOM) && (unsigned char)t->rest[0] == 0xEF &&
        (unsigned char)t->rest[1] == 0xBB && (unsigned char)t->rest[2] == 0xBF)
        t->rest += 3;
    line = csv_line(t);
    if (!line) return 0; /* empty: ncol 0, the loader says what it expected */
    t->ncol = csv_split(line, &t->header, &cap);
    if (t->ncol == (size_t)-1) {
        csv_fail(t, 0, 0, "out of memory");
        goto fail;
    }
    return 0;
fail:
    csv_close(t);
    return 1;
}

int csv_next_row(CsvTable *t) {
    char *line;
    while ((line = csv_line(t)) != NULL) {
        if (*csv_trim(line) == '\0') continue;
        t->ncell = csv_split(line, &t->cell, &t->cap);
        if (t->ncell == (size_t)-1) {
            t->ncell = 0;
            csv_fail(t, t->line, 0, "out of memory");
            return -1;
        }
        return 1;
    }
    return 0;
}

int csv_number(const char *f, double *x) {
    const char dp = localeconv()->decimal_point[0];
    char *copy = NULL, *end;
    const char *s = f;
    int rc;
    if (!*f) return CSV_NOT_A_NUMBER;
    if (dp != '.') { /* the importer's locale: strtod wants its decimal point */
        char *q;
        copy = (char *)malloc(strlen(f) + 1);
        if (!copy) return CSV_NOT_A_NUMBER;
        strcpy(copy, f);
        for (q = copy; *q; q++)
            if (*q == '.') *q = dp;
        s = copy;
    }
    *x = strtod(s, &end);
    if (end == s || *end != '\0') rc = CSV_NOT_A_NUMBER;
    else if (!isfinite(*x)) rc = CSV_NOT_FINITE; /* nan, inf, 1e999 */
    else if (strspn(f, "0123456789eE.+-") != strlen(f)) rc = CSV_NOT_A_NUMBER; /* hex */
    else rc = CSV_OK;
    free(copy);
    return rc;
}

int csv_integer(const char *f, fmi2Integer *v) {
    char *end;
    long x;
    if (!*f) return 1;
    errno = 0;
    x = strtol(f, &end, 10);
    if (end == f || *end != '\0' || errno == ERANGE || x < INT_MIN || x > INT_MAX) return 1;
    *v = (fmi2Integer)x;
    return 0;
}
