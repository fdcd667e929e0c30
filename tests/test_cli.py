"""The railfmu command line: the main job's outputs, and one-line errors with exit code 2."""

import csv
import json
import subprocess
import sys

import pytest


def railfmu(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "experiments.cli", *args], capture_output=True,
                          text=True, cwd=cwd)


def test_run_writes_signals_metrics_report_and_plots(tmp_path):
    out = tmp_path / "run"
    res = railfmu("run", "track_wheelset", "--variant", "harmonic", "--stop-time", "2",
                  "--out", str(out))
    assert res.returncode == 0, res.stderr
    for f in ("signals.csv", "metrics.json", "report.md", "track_input.png", "sensors.png"):
        assert (out / f).is_file(), f
    rows = list(csv.DictReader(open(out / "signals.csv")))
    assert len(rows) == 2001 and float(rows[-1]["time"]) == pytest.approx(2.0)
    metrics = json.loads((out / "metrics.json").read_text())
    # 1 mm harmonic alignment: rms 1/sqrt(2) mm under the leading wheelset
    assert metrics["rms"]["track.alignment_1"] == pytest.approx(1e-3 / 2**0.5, rel=0.01)


@pytest.mark.parametrize("args, message", [
    (["run", "no_such_experiment"], "unknown experiment 'no_such_experiment'"),
    (["run", "track_wheelset", "--variant", "nope"], "unknown variant 'nope'"),
    (["run", "track_wheelset", "--set", "wheelset.m"], "expected COMPONENT.PARAM=VALUE"),
    (["run", "track_wheelset", "--set", "bogie.m=1"], "unknown component 'bogie'"),
    (["run", "track_wheelset", "--set", "wheelset.mass=1"], "no variable 'mass'"),
    (["run", "track_wheelset", "--set", "wheelset.m=-1"], "parameter m = -1 must be > 0"),
    (["run", "track_wheelset", "--set", "track.profile_file=/nonexistent/p.csv"], "p.csv: cannot open"),
    (["run", "track_wheelset", "--stop-time", "1", "--step-size", "0.3"], "does not divide"),
    (["run", "track_wheelset", "--stop-time", "0"], "--stop-time 0: must be a positive"),
    (["run", "track_wheelset", "--step-size", "nan"], "--step-size nan: must be a positive"),
    (["validate", "/nonexistent.fmu"], "no such file"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, message):
    res = railfmu(*args, "--out", str(tmp_path)) if args[0] == "run" else railfmu(*args)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert message in lines[-1]
    assert "Traceback" not in res.stderr
    assert all(line.startswith(("railfmu: error:", "running ")) for line in lines), res.stderr


def test_validate_reports_problems_of_a_broken_fmu(tmp_path):
    bad = tmp_path / "Broken.fmu"
    bad.write_bytes(b"not a zip")
    res = railfmu("validate", str(bad))
    assert res.returncode == 1
    assert "problems" in res.stdout
