"""Compile and zip the self-contained test FMU of tests/data/stair/ (like Reference-FMUs'
Stair: Integer and Boolean signals, an early end by fmi2Discard + fmi2Terminated)."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy

DATA = Path(__file__).resolve().parent / "data" / "stair"
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
CFLAGS = ["-std=c99", "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror"]


def build_stair(out_dir: Path, binary: bool = True) -> Path:
    """``out_dir/stair.fmu`` with ``sources/`` and, if ``binary``, ``binaries/linux64/stair.so``."""
    out_dir = Path(out_dir)
    work = out_dir / "stair_build"
    shutil.rmtree(work, ignore_errors=True)
    (work / "binaries" / "linux64").mkdir(parents=True)
    (work / "sources").mkdir()
    shutil.copy(DATA / "modelDescription.xml", work)
    shutil.copy(DATA / "stair.c", work / "sources")
    if binary:
        res = subprocess.run(["gcc", *CFLAGS, f"-I{FMI_HEADERS}", str(DATA / "stair.c"), "-o",
                              str(work / "binaries" / "linux64" / "stair.so"), "-lm"],
                             capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"compiling stair.c failed (warnings are errors):\n{res.stderr}")
    fmu = out_dir / "stair.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(work.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(work).as_posix())
    shutil.rmtree(work)
    return fmu
