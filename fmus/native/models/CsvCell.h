/* The cells of the CSV tables our FMUs read (line profiles, track element tables): trimmed and
 * parsed as numbers the same way everywhere, whatever locale the importer has set. */
#ifndef CSV_CELL_H
#define CSV_CELL_H

#include <locale.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* the cell without leading blanks and trailing blanks or CR (in place) */
static char *csv_trim(char *s) {
    char *e;
    while (*s == ' ' || *s == '\t') s++;
    e = s + strlen(s);
    while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r')) *--e = '\0';
    return s;
}

/* strtod in the "C" locale sense (the importer may have set a comma locale); 1 = not a
 * finite number */
static int csv_number(const char *f, double *x) {
    char buf[128], *end, *q;
    const char dp = localeconv()->decimal_point[0];
    if (!*f || strlen(f) >= sizeof buf) return 1;
    strcpy(buf, f);
    if (dp != '.')
        for (q = buf; *q; q++)
            if (*q == '.') *q = dp;
    *x = strtod(buf, &end);
    return end == buf || *end != '\0' || !isfinite(*x);
}

/* splits a line (in place) at its commas into trimmed fields: the first `max` go to `fld`;
 * returns the number of fields, which may exceed `max` (a row with too many fields) */
static size_t csv_split(char *s, char **fld, size_t max) {
    size_t nf = 0;
    char *c;
    for (;;) {
        c = strchr(s, ',');
        if (c) *c = '\0';
        if (nf < max) fld[nf] = csv_trim(s);
        nf++;
        if (!c) return nf;
        s = c + 1;
    }
}

#endif
