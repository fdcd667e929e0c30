"""`railfmu export --fmi 3` runs in OMSimulator 3.0 like the FMI 2 export.

The FMI 3 FMUs compile the same model code and runtime as the FMI 2 ones, so OMSimulator's
results for the two archives must be the same numbers, row by row (it reads them through
fmi3GetFloat64/fmi3DoStep instead of fmi2GetReal/fmi2DoStep). How OMSimulator's FMI 2 results
compare with railfmu's own masters is tests/interop/test_omsimulator.py. OMSimulator exits 0
even when it logs ``error:`` lines, so its output is read. The replays' String values (a
table's file and columns) travel as start values in each table component's own FMU copy
(FMI 3: ``<Start value=...>`` children, read by the runtime from the unpacked
modelDescription.xml, under an instantiationToken with a suffix the runtime accepts).

Needs OMSimulator: the environment variable RAILFMU_OMSIMULATOR (its binary) or
``OMSimulator`` on PATH; otherwise skipped.
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

OMS = os.environ.get("RAILFMU_OMSIMULATOR") or shutil.which("OMSimulator")
pytestmark = [pytest.mark.interop,
              pytest.mark.skipif(not OMS or not Path(OMS).is_file(),
                                 reason="OMSimulator not found (set RAILFMU_OMSIMULATOR or PATH)")]

STOP = 2.0  # s
STOP_OF = {"train_resistance_measured": 30.0}  # its replay steps at the 10 s GNSS fixes
# with and without loops; the replays (measured tables: String values in the FMU copies)
CASES = [("track_wheelset", "harmonic"), ("lateral_alignment", "standard"),
         ("suspension_fault", "step_fault"), ("train_resistance", "standard"),
         ("alignment_replay", "measured"), ("suspension_replay", "recorded"),
         ("train_resistance_measured", "measured"), ("trolley_imu_replay", "recorded"),
         ("trolley_survey_replay", "example")]


def _export(experiment: str, variant: str, fmi: int, out: Path) -> Path:
    stop = STOP_OF.get(experiment, STOP)
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "export", experiment,
                          "--variant", variant, "--fmi", str(fmi), "--stop-time", f"{stop:g}", "-o", str(out)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return out


def _omsimulator(ssp: Path, stop: float = STOP) -> tuple[list[str], np.ndarray]:
    result = ssp.with_suffix(".csv")
    res = subprocess.run([OMS, f"--stopTime={stop:g}", f"--resultFile={result}", str(ssp)],
                         capture_output=True, text=True, timeout=600, cwd=ssp.parent)
    log = res.stdout + res.stderr
    errors = [line for line in log.splitlines() if "error" in line.lower()]
    assert not errors, f"{ssp.name}: OMSimulator logged {errors[:3]}"
    with open(result, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


@pytest.mark.parametrize("experiment,variant", CASES)
def test_fmi3_export_runs_in_omsimulator_as_the_fmi2_export(experiment, variant, tmp_path):
    ssp3 = _export(experiment, variant, 3, tmp_path / f"{experiment}_fmi3.ssp")
    with zipfile.ZipFile(ssp3) as z:
        fmus = [n for n in z.namelist() if n.endswith(".fmu")]
        for name in fmus:
            with zipfile.ZipFile(z.open(name)) as fmu:
                assert b'fmiVersion="3.0"' in fmu.read("modelDescription.xml")[:400], name
    ssp2 = _export(experiment, variant, 2, tmp_path / f"{experiment}_fmi2.ssp")
    stop = STOP_OF.get(experiment, STOP)
    head3, data3 = _omsimulator(ssp3, stop)
    head2, data2 = _omsimulator(ssp2, stop)
    assert head3 == head2 and data3.shape == data2.shape and len(data3) > 2
    # the same binaries' arithmetic behind both interfaces: equal, not close
    assert np.array_equal(data3, data2), f"max difference {np.max(np.abs(data3 - data2))}"
