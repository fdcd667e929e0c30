"""Compile and zip the FMI 1.0 Co-Simulation test FMU of tests/data/fmi1_integrator/ (no FMI 1.0
CS FMU ships with FMPy or the Reference-FMUs' pip builds)."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy

DATA = Path(__file__).resolve().parent / "data" / "fmi1_integrator"
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
CFLAGS = ["-std=c99", "-shared", "-fPIC", "-O2", "-fvisibility=hidden", "-Wall", "-Wextra", "-Werror"]


def build_fmi1_integrator(out_dir: Path) -> Path:
    """``out_dir/integrator.fmu`` (FMI 1.0 CS, ``binaries/linux64/integrator.so``)."""
    out_dir = Path(out_dir)
    work = out_dir / "integrator_build"
    shutil.rmtree(work, ignore_errors=True)
    (work / "binaries" / "linux64").mkdir(parents=True)
    shutil.copy(DATA / "modelDescription.xml", work)
    res = subprocess.run(["gcc", *CFLAGS, f"-I{FMI_HEADERS}", str(DATA / "integrator.c"), "-o",
                          str(work / "binaries" / "linux64" / "integrator.so")], capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"compiling integrator.c failed (warnings are errors):\n{res.stderr}")
    fmu = out_dir / "integrator.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(work.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(work).as_posix())
    shutil.rmtree(work)
    return fmu
