"""Writes the hostile-file corpus for the FMUs' C table readers (fmus/native/common/csv_table.c
and its users) beside this script, and expected.csv: for each file what a reader must do.

    ok        reads as the clean table of its format (same outputs, bit for bit)
    line N    fails initialisation with one message naming the file and line N
    file      fails initialisation with one message naming the file (as a whole, or its header)
    any       reads or fails (a finite but extreme number): never a crash

Rerun after changing it: python tests/data/hostile/make_corpus.py
"""

from __future__ import annotations

import csv
from pathlib import Path

HERE = Path(__file__).resolve().parent

# clean tables, one per format; (line, column) of a number cell to damage (1-based, data rows)
CLEAN = {
    "signal": ("time,x,flag,n\n0.0,1.0,0,1\n0.5,2.0,1,2\n1.0,3.0,1,3\n1.5,2.5,0,4\n", (3, 2)),
    "profile": ("s,alignment,vertical_left,vertical_right\n0,0,0,0\n10,1e-3,2e-3,-1e-3\n20,0,0,0\n"
                "400,-2e-3,1e-3,0\n", (3, 2)),
    "line": ("position_m,gradient_permille,speed_limit_kmh\n0,0.0,40\n1200,0.0,140\n3000,0.8,140\n"
             "6500,-0.6,140\n", (3, 2)),
    "track": ("kind,start_m,end_m,radius_m,cant_mm,gradient_permille\nstraight,0,80,,,\n"
              "curve_right,80,240,400,100,\nstraight,240,400,,,\ngrade,0,400,,,1.5\n", (3, 4)),
}
BOM = b"\xef\xbb\xbf"


def _cell(text: str, line: int, col: int, value: str) -> str:
    lines = text.split("\n")
    cells = lines[line - 1].split(",")
    cells[col - 1] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines)


def _line(text: str, line: int, new: str) -> str:
    lines = text.split("\n")
    lines[line - 1] = new
    return "\n".join(lines)


def cases(fmt: str) -> dict[str, tuple[bytes, str]]:
    clean, (ln, col) = CLEAN[fmt]
    lines = clean.rstrip("\n").split("\n")
    header, last = lines[0], len(lines)
    b = clean.encode()
    original = lines[ln - 1].split(",")[col - 1]
    c: dict[str, tuple[bytes, str]] = {
        "ok_bom": (BOM + b, "ok"),
        "ok_crlf": (b.replace(b"\n", b"\r\n"), "ok"),
        "ok_bom_crlf": (BOM + b.replace(b"\n", b"\r\n"), "ok"),
        "ok_blank_lines": (b.replace(b"\n", b"\n\n  \n\t\n", 2) + b"\n\n", "ok"),
        "ok_no_final_newline": (b.rstrip(b"\n"), "ok"),
        "ok_blanks_around_cells": (b.replace(b",", b" ,\t"), "ok"),
        # lines of 5000+ characters: one row each (the old 4096-character buffers split them)
        "ok_long_number": (_cell(clean, ln, col, "0" * 5000 + original).encode(), "ok"),
        "ok_long_trailing_blanks": (_line(clean, ln, lines[ln - 1] + " " * 6000).encode(), "ok"),
        "bad_nul_byte": (_cell(clean, ln, col, original[:1] + "\0" + original[1:]).encode(), f"line {ln}"),
        "bad_utf16": (clean.encode("utf-16"), "line 1"),
        "bad_hex_float": (_cell(clean, ln, col, "0x1p-3").encode(), f"line {ln}"),
        "bad_nan": (_cell(clean, ln, col, "nan").encode(), f"line {ln}"),
        "bad_inf": (_cell(clean, ln, col, "inf").encode(), f"line {ln}"),
        "bad_minus_infinity": (_cell(clean, ln, col, "-Infinity").encode(), f"line {ln}"),
        "bad_huge": (_cell(clean, ln, col, "1e999").encode(), f"line {ln}"),
        "bad_comma_decimal": (_cell(clean, ln, col, '"1,5"').encode(), f"line {ln}"),
        "bad_not_utf8": (_cell(clean, ln, col, "@").encode().replace(b"@", b"1.0\xe9"), f"line {ln}"),
        "bad_trailing_separator": (_line(clean, ln, lines[ln - 1] + ",").encode(), f"line {ln}"),
        "bad_header_trailing_separator": (_line(clean, 1, header + ",").encode(), "line 1"),
        "bad_truncated_last_line": (("\n".join(lines[:-1]) + "\n" + lines[-1].rsplit(",", 1)[0]).encode(),
                                    f"line {last}"),
        "bad_long_garbage_line": (_line(clean, ln, "x" * 5000).encode(), f"line {ln}"),
        "bad_many_cells": (_line(clean, ln, ",".join(["1"] * 20_000)).encode(), f"line {ln}"),
        "bad_many_columns": (_line(clean, 1, header + "".join(f",c{k}" for k in range(5000))).encode(),
                             "line 1"),
        "bad_lone_cr": (b.replace(b"\n", b"\r"), "line 1"),
        "badfile_empty": (b"", "file"),
        "badfile_bom_only": (BOM, "file"),
        "badfile_blank_lines_only": (b"\n\n  \n\r\n", "file"),
        "badfile_header_only": ((header + "\n").encode(), "file"),
        "any_huge_finite": (_cell(clean, ln, col, "1.7976931348623157e308").encode(), "any"),
        "any_tiny": (_cell(clean, ln, col, "4.9e-324").encode(), "any"),
    }
    # times and distances must increase (the track: each element starts where the last ended)
    c["bad_non_monotonic"] = (_cell(clean, 3, 2, "60") if fmt == "track" else _cell(clean, 3, 1, "-1")).encode(), \
        "line 3"
    c["bad_repeated_row"] = (_line(clean, 3, lines[1]).encode(), "line 3")
    return c


def main() -> None:
    rows = []
    for fmt in CLEAN:
        folder = HERE / fmt
        folder.mkdir(exist_ok=True)
        for old in folder.glob("*.csv"):
            old.unlink()
        (folder / "clean.csv").write_text(CLEAN[fmt][0])
        for name, (data, expected) in cases(fmt).items():
            (folder / f"{name}.csv").write_bytes(data)
            rows.append((f"{fmt}/{name}.csv", expected))
    with open(HERE / "expected.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["file", "expected"])
        w.writerows(rows)


if __name__ == "__main__":
    main()
