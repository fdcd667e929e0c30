"""Hostile files for every table-reading FMU (the C readers: fmus/native/common/csv_table.c and
its users). Each file of the corpus (tests/data/hostile, expected.csv says what each must do)
either reads as the clean table of its format, outputs equal bit for bit (a BOM, CRLF, blank
lines, blanks around cells, lines of thousands of characters), or fails initialisation with
one message naming the parameter, the file and the line at fault; never a crash, never a
table silently cut short (a NUL byte used to end it).

Then a bounded, seeded fuzz of the same readers: random mutations of the clean tables
(RAILFMU_FUZZ_SEED, RAILFMU_FUZZ_CASES per reader), each read or refused in one message naming
the file. `make sanitize` runs both against FMUs built with ASan + UBSan.
"""

from __future__ import annotations

import csv
import os
import random
import re
from pathlib import Path

import pytest

from railfmu.fmus.cosim.slave import FMUError, Slave

CORPUS = Path(__file__).parent / "data" / "hostile"
SEED = int(os.environ.get("RAILFMU_FUZZ_SEED", "0"))
CASES = int(os.environ.get("RAILFMU_FUZZ_CASES", "60"))
H = 0.05
# format -> (FMU, parameter, other parameters, seconds simulated when the table is read)
READERS = {
    "signal": [("SignalTable", "file", {"column_1": "x", "boolean_column_1": "flag", "integer_column_1": "n"},
                1.6)],
    "profile": [("TrackIrregularity", "profile_file", {"psd_level": 0}, 1.0),
                ("Trolley", "irregularity_file", {"track_file": str(CORPUS / "track" / "clean.csv")}, 0.5)],
    "line": [("TrainLongitudinal", "line_file", {}, 0.5), ("Driver", "line_file", {}, 0.5)],
    "track": [("Trolley", "track_file", {}, 0.5)],
}
PAIRS = [(fmt, *r) for fmt, rs in READERS.items() for r in rs]
EXPECTED = {row["file"]: row["expected"] for row in csv.DictReader(open(CORPUS / "expected.csv"))}


def read(fmu_dir, ident: str, param: str, path: Path, extra: dict, seconds: float):
    """(outputs at every step, None) when the FMU takes the table, else (None, its errors)."""
    with Slave(fmu_dir / f"{ident}.fmu", ident) as s:
        outputs = [v.valueReference for v in s.md.modelVariables if v.causality == "output" and v.type == "Real"]
        try:
            s.initialize(0.0, None, {**extra, param: str(path)})
        except FMUError:
            return None, [m for st, _, m in s.messages if st in ("Error", "Fatal")]
        rows = []
        for k in range(round(seconds / H)):
            s.do_step(k * H, H)
            rows.append(s.fmu.getReal(outputs))
        return rows, []


@pytest.fixture(scope="module")
def clean(fmu_dir):
    out = {}
    for fmt, ident, param, extra, seconds in PAIRS:
        rows, errors = read(fmu_dir, ident, param, CORPUS / fmt / "clean.csv", extra, seconds)
        assert rows is not None, errors
        out[ident, param] = rows
    return out


def test_the_corpus_covers_every_format_and_outcome():
    for fmt in READERS:
        files = {f.split("/")[1] for f in EXPECTED if f.startswith(f"{fmt}/")}
        assert {f.name for f in (CORPUS / fmt).glob("*.csv")} == files | {"clean.csv"}
        assert {"ok_bom.csv", "ok_crlf.csv", "bad_nul_byte.csv", "bad_hex_float.csv", "badfile_empty.csv",
                "badfile_header_only.csv", "bad_truncated_last_line.csv", "bad_non_monotonic.csv"} <= files


@pytest.mark.parametrize("fmt,ident,param,extra,seconds", PAIRS, ids=[f"{p[1]}.{p[2]}" for p in PAIRS])
def test_every_hostile_file_reads_as_clean_or_fails_naming_file_and_line(fmu_dir, clean, fmt, ident, param,
                                                                       extra, seconds):
    problems = []
    for name, expected in EXPECTED.items():
        if name.startswith(f"{fmt}/"):
            path = CORPUS / name
            rows, errors = read(fmu_dir, ident, param, path, extra, seconds)
            problem = _judge(expected, rows, errors, clean[ident, param], param, path)
            if problem:
                problems.append(f"{name}: {problem}")
    assert not problems, "\n".join(problems)


def _judge(expected, rows, errors, clean_rows, param, path) -> str | None:
    if expected == "ok":
        return None if rows == clean_rows else f"not read as the clean table: {errors or 'other numbers'}"
    if expected == "any":
        return None if rows is not None or (errors and errors[0].startswith(f"{param} {path}")) else str(errors)
    if rows is not None:
        return "accepted"
    if len(errors) != 1 or not errors[0].startswith(f"{param} {path}"):
        return f"not one message naming {param} and the file: {errors}"
    where = errors[0][len(f"{param} {path}"):]
    if expected.startswith("line "):
        line = int(expected.split()[1])
        if not re.match(rf"(:{line}:|, line {line}\b)", where):
            return f"not located at line {line}: {errors[0]}"
    elif not re.match(r"(: |:1: |, line [12]\b)", where):  # the file as a whole, or its header
        return f"not about the whole file: {errors[0]}"
    if len(where.split(":", 2)[-1].strip()) < 5:
        return f"does not say what is wrong: {errors[0]}"
    return None


def _mutate(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op, i = rng.randrange(8), rng.randrange(len(b) + 1)
        if op == 0 and b:  # flip a bit
            i = min(i, len(b) - 1)
            b[i] ^= 1 << rng.randrange(8)
        elif op == 1:  # a byte that means something to a reader
            b[i:i] = rng.choice([b"\0", b"\r", b"\n", b",", b" ", b"\xef\xbb\xbf", b"-", b"e", b".", b"\xff"])
        elif op == 2:  # cut
            del b[i:]
        elif op == 3:  # delete a run
            del b[i:i + rng.randint(1, 8)]
        elif op == 4:  # a number from the edges of what a double holds
            b[i:i] = rng.choice([b"1e308", b"-1e308", b"1e999", b"4.9e-324", b"nan", b"inf", b"0x1p3", b"9" * 400,
                                 b"2147483648", b"-0"])
        elif op == 5:  # repeat a line
            lines = bytes(b).split(b"\n")
            k = rng.randrange(len(lines))
            lines.insert(k, lines[k])
            b = bytearray(b"\n".join(lines))
        elif op == 6:  # a long line
            b[i:i] = rng.choice([b" ", b"0", b",", b"x"]) * rng.choice([10, 4096, 5000])
        else:  # swap two lines
            lines = bytes(b).split(b"\n")
            j, k = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[j], lines[k] = lines[k], lines[j]
            b = bytearray(b"\n".join(lines))
    return bytes(b)


@pytest.mark.parametrize("fmt,ident,param,extra,seconds", PAIRS, ids=[f"{p[1]}.{p[2]}" for p in PAIRS])
def test_mutated_tables_are_read_or_refused_in_one_line(fmu_dir, tmp_path, fmt, ident, param, extra, seconds):
    rng = random.Random(f"{SEED} {ident} {param}")
    base = (CORPUS / fmt / "clean.csv").read_bytes()
    refused = 0
    for case in range(CASES):
        path = tmp_path / f"case{case}.csv"
        path.write_bytes(_mutate(rng, base))
        rows, errors = read(fmu_dir, ident, param, path, extra, 0.2)
        if rows is None:
            refused += 1
            assert errors and errors[0].startswith(f"{param} {path}"), (path.read_bytes()[:300], errors)
    assert 0 < refused < CASES or CASES < 10  # the mutations reach both outcomes
