"""A user's field data, end to end: railfmu installed from its wheel (not editable, the
``installed`` fixture), run from a folder outside the repository with relative paths only.
Each of the four field-data studies runs on its shipped example file and on a file made by
``railfmu run`` of its simulated study (turned into the user's format by the study's
``record.py --from RUN``), and gives the simulated run's estimates within a stated tolerance.
Every figure of a replay reads like the data: the file's column names and the connectors' units
on the axes (no ``[-]``, ``[SI]`` or ``y_1``), legends off the data, distance along the track
where the study is along the track.

The default version keeps each run short (one venv for the module, the four studies two at a
time); the slow one replays the whole shipped examples and longer simulated runs.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import fmpy
import numpy as np
import pandas as pd
import pytest

from railfmu.experiments.engine.plots import figure_labels

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64",
                                reason="needs gcc on linux64")

#: relative tolerances of the replay's estimates against the simulated run's (why: at each study)
TOLERANCE = {
    # the table holds signals.csv's cells as text (repr floats): the filter sees the same doubles
    "alignment": 1e-12,  # m, absolute: measured 0
    # the coach file holds 10 digits, the geometry file the rails every 0.2 m whose rates the track
    # FMU takes from Catmull-Rom slopes (the simulation: exact rates); k1 after 5 s, measured on
    # 12 s: 0.3 % paper_wls, 1.0 % joint EKF (on 150 s: 1.1 %, 2.0 %)
    "suspension": 0.03,
    # the log holds the fixes as the receiver reports them (position to 0.1 m, speed to 1 km/h),
    # which is what the simulated observers read; measured on 1350 s: 4e-8 ukf_paper, 1.3e-6 improved
    "train": 1e-5,
    # the simulated smoother starts from drawn attitude errors, the replay from its own levelling and
    # finds its stops with the detector instead of the stopped flag: one 85 s survey, measured
    # 6.9 % alignment, 10.2 % level (up to 20 % on one short run; over six seeds within 10 %,
    # tests/test_trolley_survey_replay.py)
    "trolley": 0.20,
}

#: per study: the commands run in its own folder (railfmu CLI or ``python -m``), relative paths only;
#: ``{stop}`` style keys are the default (CI) and slow lengths
STUDIES = {
    "alignment": {
        "shipped": ["run", "alignment_replay", "--out", "shipped"],
        "simulate": ["run", "track_wheelset", "--out", "sim"],
        "record": ["-m", "railfmu.experiments.alignment_replay.record", "--from", "sim", "--to", "axlebox.csv"],
        "replay": ["run", "alignment_replay", "--set", "replay.file=axlebox.csv", "--out", "replay"],
        "stop": {"shipped": (1.0, None), "simulate": (1.0, 3.0)},
    },
    "suspension": {
        "shipped": ["run", "suspension_replay", "--out", "shipped"],
        "simulate": ["run", "suspension_fault", "--variant", "step_fault", "--seed", "1", "--out", "sim"],
        "record": ["-m", "railfmu.experiments.suspension_replay.record", "--from", "sim", "--to", "."],
        "replay": ["run", "suspension_replay", "--set", "coach.file=coach.csv",
                   "--set", "track.profile_file=geometry.csv", "--out", "replay"],
        "stop": {"shipped": (5.0, None), "simulate": (12.0, 40.0)},
    },
    "train": {
        "shipped": ["run", "train_resistance_measured", "--out", "shipped"],
        # ukf_fmu off in the simulation: it is not compared (see check_train) and costs most of the run
        "simulate": ["run", "train_resistance", "--variant", "standard", "--seed", "1",
                     "--set", "ukf_fmu.enabled=false", "--out", "sim"],
        "record": ["-m", "railfmu.experiments.train_resistance_measured.record", "--from", "sim", "--to", "run.csv"],
        "replay": ["run", "train_resistance_measured", "--set", "replay.file=run.csv", "--out", "replay"],
        "stop": {"shipped": (300.0, None), "simulate": (900.0, None)},
    },
    "trolley": {
        "shipped": ["run", "trolley_survey_replay", "--out", "shipped"],
        "simulate": ["run", "trolley_survey", "--variant", "navigation_grade", "--seed", "1", "--out", "sim"],
        "record": ["-m", "railfmu.experiments.trolley_survey_replay.record", "--from", "sim", "--to", ".",
                   "--duration", "85"],
        "replay": ["run", "trolley_survey_replay", "--variant", "navigation_grade", "--set", "imu.file=imu.csv",
                   "--set", "imu.column_7=odometer_m", "--set", "start.file=start.csv",
                   "--set", "reference.file=reference.csv", "--set", "reference.boolean_column_1=stopped",
                   "--out", "replay"],
        "stop": {"shipped": (50.0, None), "simulate": (85.0, 85.0)},
    },
}
#: replay outputs whose x-axis is the distance along the track (figure -> axis label start)
ALONG_TRACK = {"alignment": ("sensors.png", "estimates_alignment.png"), "suspension": ("rails.png",),
               "trolley": ("chords.png",)}
BAD_LABEL = re.compile(r"\[-\]|\[SI\]|\by_\d+\b|unit not given")


def _pipeline(study: str, python: Path, folder: Path, slow: bool) -> dict[str, subprocess.CompletedProcess]:
    """The study's four commands in ``folder`` (outside the repository), in order."""
    folder.mkdir()
    spec, done = STUDIES[study], {}
    for step in ("shipped", "simulate", "record", "replay"):
        args = list(spec[step])
        stop = spec["stop"].get(step, (None, None))[1 if slow else 0]
        if stop is not None:
            args += ["--stop-time", f"{stop:g}"]
        cmd = [str(python), *args] if step == "record" else [str(python.parent / "railfmu"), *args]
        t0 = time.perf_counter()
        done[step] = res = subprocess.run(cmd, cwd=folder, capture_output=True, text=True)
        res.seconds = time.perf_counter() - t0
        if res.returncode != 0:
            break
    return done


def _outside(installed, tmp_path_factory, slow: bool) -> tuple[Path, dict]:
    python, _ = installed
    base = tmp_path_factory.mktemp("field_data")
    assert ROOT not in base.parents
    with ThreadPoolExecutor(2) as pool:  # two cores: two studies at a time
        runs = dict(zip(STUDIES, pool.map(lambda s: _pipeline(s, python, base / s, slow), STUDIES)))
    return base, runs


@pytest.fixture(scope="module")
def outside(installed, tmp_path_factory, fmu_dir):
    return _outside(installed, tmp_path_factory, slow=False)


def _metrics(folder: Path) -> dict:
    return json.loads((folder / "metrics.json").read_text())


def _check_figures(folder: Path, study: str) -> int:
    """Every PNG of a replay says what it plots in the data's words; the number checked."""
    pngs = sorted(folder.glob("*.png"))
    assert pngs, folder
    for png in pngs:
        axes = figure_labels(png)
        assert axes, f"{png.name}: no axis labels recorded"
        for ax in axes:
            assert ax["y"] and not BAD_LABEL.search(ax["y"] + " " + ax["x"]), (png.name, ax)
            assert re.search(r"\[[^\]]+\]$", ax["y"]), (png.name, ax["y"])  # the quantity, then its unit
            assert not any(BAD_LABEL.search(s) for s in ax["legend"]), (png.name, ax["legend"])
            assert not ax["legend_over_data"], (png.name, ax["legend"])
        if png.name in ALONG_TRACK.get(study, ()):
            assert axes[-1]["x"].startswith("distance along the track [m]"), (png.name, axes[-1]["x"])
    return len(pngs)


def _ran(runs: dict, study: str) -> dict:
    done = runs[study]
    for step, res in done.items():
        assert res.returncode == 0, f"{study} {step}: {res.args}\n{res.stderr[-3000:]}"
    assert len(done) == 4
    for step in ("shipped", "replay", "simulate"):
        assert "Traceback" not in done[step].stderr
    return done


def check_alignment(folder: Path, slow: bool) -> dict:
    shipped = _metrics(folder / "shipped")
    assert shipped["end_time_s"] == pytest.approx(3.0 if slow else 1.0)
    # m: the filter tracks the shipped run's alignment (rms 1.7 mm) to a fifth of it (Muñoz et al.)
    assert shipped["observers"]["alignment"]["xi"]["rms_error"] < 0.6e-3
    sim = pd.read_csv(folder / "sim" / "estimates.csv")
    rep = pd.read_csv(folder / "replay" / "estimates.csv")
    assert len(rep) == len(sim)
    diff = float(np.max(np.abs(rep["alignment.xi"].to_numpy() - sim["alignment.xi"].to_numpy())))
    assert diff <= TOLERANCE["alignment"]
    a, b = _metrics(folder / "sim")["observers"]["alignment"]["xi"], _metrics(folder / "replay")["observers"]["alignment"]["xi"]
    assert b["rms_error"] == pytest.approx(a["rms_error"], abs=TOLERANCE["alignment"])
    return {"max |xi replay - xi simulated| [m]": diff}


def check_suspension(folder: Path, slow: bool) -> dict:
    shipped = _metrics(folder / "shipped")
    for name in ("paper_wls", "improved"):
        if slow:  # the whole example: k1 from ~430 kN/m to ~215 kN/m, the fault seen after its 20 s
            assert shipped[name]["k1_final_N_m"] == pytest.approx(215e3, rel=0.06)
            assert 20.0 < shipped[name]["detection_time_s"] < 26.0
        else:  # 5 s: the estimators start at 330 kN/m and climb towards the example's ~430 kN/m
            assert 330e3 < shipped[name]["k1_final_N_m"] < 480e3, shipped[name]
    sim = pd.read_csv(folder / "sim" / "estimates.csv")
    rep = pd.read_csv(folder / "replay" / "k1.csv")
    assert len(rep) == len(sim)
    t, out = rep.time_s.to_numpy(), {}
    late = t >= 5.0  # after the estimators' start from their prior
    for name in ("paper_wls", "improved"):
        a, b = sim[f"{name}.k1"].to_numpy()[late], rep[f"{name}_k1_N_m"].to_numpy()[late]
        out[f"{name} max relative k1 difference after 5 s"] = rel = float(np.max(np.abs(b - a) / a))
        assert rel < TOLERANCE["suspension"], (name, rel)
    return out


def check_train(folder: Path, slow: bool) -> dict:
    shipped = _metrics(folder / "shipped")
    rows = pd.read_csv(ROOT / "experiments" / "train_resistance_measured" / "resources" / "example_run.csv")
    assert shipped["fixes"] == (len(rows) if slow else 31)  # default: --stop-time 300 at 10 s fixes
    sim, rep, out = _metrics(folder / "sim"), _metrics(folder / "replay"), {}
    assert rep["fixes"] == len(pd.read_csv(folder / "run.csv"))
    # ukf_fmu is left out: the simulated one is told the driver's effort, the measured one is not
    for name in ("ukf_paper", "improved"):
        rel = max(abs(rep[name][f"r{k}_final"] / sim[name][f"r{k}_final"] - 1.0) for k in range(3))
        out[f"{name} max relative r0..r2 difference"] = rel
        assert rel < TOLERANCE["train"], (name, rel)
    # a comparison of priors would prove nothing: the improved estimator has learned from the coasting
    # (its r0 1 % from its prior, which it still holds at 300 s of the shipped run)
    if not slow:
        assert abs(rep["improved"]["r0_final"] / shipped["improved"]["r0_final"] - 1.0) > 1e-3
    return out


def check_trolley(folder: Path, slow: bool) -> dict:
    shipped = _metrics(folder / "shipped")
    assert shipped["chords_surveyed"] == (2 if slow else 1) and shipped["detector_missed_stops"] == 0
    assert shipped["detector_false_alarms"] == 0
    sim, rep, out = _metrics(folder / "sim"), _metrics(folder / "replay"), {}
    assert rep["chord_points"] == sim["chord_points"] > 0
    for kind in ("alignment", "level"):
        key = f"chord_{kind}_max_error_mm"
        out[f"{kind}: max chord error replay / simulated - 1"] = rel = rep[key] / sim[key] - 1.0
        assert abs(rel) < TOLERANCE["trolley"], (kind, rep[key], sim[key])
    return out


CHECKS = {"alignment": check_alignment, "suspension": check_suspension, "train": check_train,
          "trolley": check_trolley}


@pytest.mark.parametrize("study", list(STUDIES))
def test_a_study_on_its_example_and_on_a_simulated_run_from_outside_the_repository(outside, study):
    """Shipped example and a file made by ``railfmu run`` of the simulated study, both through the
    installed CLI from a folder outside the repository with relative paths; the replay gives the
    simulated run's estimates within :data:`TOLERANCE`; its figures read like the data."""
    base, runs = outside
    _ran(runs, study)
    print(f"{study}: {CHECKS[study](base / study, False)}")  # the measured differences (pytest -s)
    for run in ("shipped", "replay"):
        _check_figures(base / study / run, study)
    heading = runs[study]["replay"].stdout + runs[study]["replay"].stderr
    assert str(base / study) in heading  # the relative file names were resolved against the folder


@pytest.mark.slow
def test_the_whole_examples_and_longer_simulated_runs(installed, tmp_path_factory, fmu_dir):
    """The same with the shipped examples replayed whole and longer simulated runs."""
    base, runs = _outside(installed, tmp_path_factory, slow=True)
    for study in STUDIES:
        _ran(runs, study)
        print(f"{study}: {CHECKS[study](base / study, True)}")
        for run in ("shipped", "replay"):
            _check_figures(base / study / run, study)

