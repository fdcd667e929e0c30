/* railfmu: what differs between the C libraries the FMUs are built for (glibc on linux64,
 * msvcrt through mingw-w64 on win64). Everything else the runtime and models call is C99.
 *
 * portable_fopen: a path decoded from the resource URI is UTF-8 (RFC 3986 percent-encodes
 * UTF-8 bytes), and so is a path a user sets in a String parameter (FMI 2 strings are
 * UTF-8). glibc's fopen takes the bytes as they are; msvcrt's fopen reads them in the ANSI
 * code page, so a folder named "Müller" would not open. On Windows the path goes through
 * _wfopen; a path that is not valid UTF-8 (an ANSI path) goes to fopen as it is.
 */
#ifndef RAILFMU_PORTABLE_H
#define RAILFMU_PORTABLE_H

#include <stdio.h>

#ifdef _WIN32
#define WIN32_LEAN_AND_MEAN
#include <stdlib.h>
#include <wchar.h>
#include <windows.h>

static inline FILE *portable_fopen(const char *path, const char *mode) {
    wchar_t wmode[8];
    wchar_t *wpath;
    FILE *f;
    int n = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, path, -1, NULL, 0);
    if (n <= 0 || MultiByteToWideChar(CP_UTF8, 0, mode, -1, wmode, 8) <= 0) return fopen(path, mode);
    wpath = (wchar_t *)malloc((size_t)n * sizeof(wchar_t));
    if (!wpath) return NULL;
    MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, path, -1, wpath, n);
    f = _wfopen(wpath, wmode);
    free(wpath);
    return f;
}
#else
static inline FILE *portable_fopen(const char *path, const char *mode) { return fopen(path, mode); }
#endif

#endif
