/* CsvTable: the one reader of the CSV files our FMUs load (line profiles, track element
 * tables, irregularity profiles, signal tables). It reads the whole file, takes line 1 as
 * the header, skips blank lines (a trailing newline or two), splits at commas into cells
 * trimmed of blanks and CR (CRLF files), and parses numbers whatever locale the importer
 * set. No quoting and no comment lines: no loader had them and their Python twins'
 * csv.reader would disagree on both. What a column means stays with each loader; the
 * messages go through model_error naming the file, line and column. */
#ifndef RAILFMU_CSV_TABLE_H
#define RAILFMU_CSV_TABLE_H

#include <stddef.h>

#include "model.h"

enum {
    CSV_SKIP_BOM = 1, /* drop a UTF-8 byte order mark (spreadsheet exports), as utf-8-sig */
    CSV_COLON = 2     /* locations as "path:line:", the profile format's (its Python twin's) */
};

enum { CSV_OK = 0, CSV_NOT_A_NUMBER = 1, CSV_NOT_FINITE = 2 };

typedef struct {
    ModelInstance *m;
    const char *label; /* the parameter naming the file, first word of every message */
    char *path;        /* resolved */
    unsigned flags;
    char *text, *rest; /* the file; what is not read yet */
    long line;         /* the line read last: 1 is the header */
    char **header;     /* line 1's cells; ncol == 0 for an empty file */
    size_t ncol;
    char **cell; /* the row read last */
    size_t ncell, cap;
} CsvTable;

/* Resolves file (relative: in the FMU's resources), reads it and its header; 1 after one
   model_error (the table is then closed). */
int csv_open(CsvTable *t, ModelInstance *m, const char *label, const char *file, unsigned flags);

/* The next non-blank line into t->cell: 1, 0 at the end, -1 after one model_error. */
int csv_next_row(CsvTable *t);

/* A whole cell as a decimal number (digits, sign, '.', exponent: what the loaders' Python
   twins' float() reads too; no hex): CSV_OK, CSV_NOT_A_NUMBER or CSV_NOT_FINITE. */
int csv_number(const char *cell, double *x);

/* A whole cell as a base-10 fmi2Integer; 0 = ok. */
int csv_integer(const char *cell, fmi2Integer *v);

/* model_error "<label> <path>: ..." located at a line (0: the file) and, in the default
   style, a column (1-based, 0: none; named after the header on data lines). */
void csv_fail(const CsvTable *t, long line, size_t column, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

void csv_close(CsvTable *t);

#endif
