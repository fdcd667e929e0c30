"""The study protocol and the Monte Carlo study: summary statistics on known numbers, nested
metric names, roles bound from the SSD, the default study of a plain SSP, and small real
studies through `railfmu study` (one run per variant keeps its format; --runs N gives each
seed its own track)."""

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from railfmu.experiments.engine.study import flatten, statistics, summarise
from railfmu.experiments.engine.study_protocol import (
    STATISTICS,
    bind_role,
    measurement,
    observer_input,
    output,
    parameter,
    setting,
    truth,
)
from railfmu.models.errors import UserError

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def railfmu(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True, text=True, cwd=cwd)


def test_statistics_of_known_numbers():
    s = statistics([4.0, 1.0, 3.0, 2.0])
    assert list(s) == list(STATISTICS)
    assert s["mean"] == 2.5
    assert s["std"] == pytest.approx(math.sqrt(5 / 3), rel=1e-15)  # sum of squared deviations 5, N - 1 = 3
    assert s["rms"] == pytest.approx(math.sqrt(30 / 4), rel=1e-15)
    assert (s["min"], s["p50"], s["max"]) == (1.0, 2.5, 4.0)
    assert s["p95"] == pytest.approx(3.85, rel=1e-15)  # rank 0.95 * 3 = 2.85: 3 + 0.85 * (4 - 3)
    one = statistics([-2.0])
    assert one == {"mean": -2.0, "std": 0.0, "rms": 2.0, "min": -2.0, "p50": -2.0, "p95": -2.0, "max": -2.0}


def test_flatten_joins_nested_keys_and_keeps_numbers_only():
    m = {"a": {"b": 1, "c": {"d": 2.5}}, "flag": True, "name": "x", "none": None, "nan": float("nan"),
         "n": np.int64(3), "x": np.float64(0.5), "list": [1, 2]}
    assert flatten(m) == {"a.b": 1.0, "a.c.d": 2.5, "n": 3.0, "x": 0.5}


def test_summary_over_runs_skips_the_runs_inputs_and_counts_runs_that_have_a_metric():
    runs = {1: {"seed": 1, "parameters": {"track": {"seed": 1}}, "J": {"whole": 0.1}, "delay_s": 2.0},
            2: {"seed": 2, "parameters": {"track": {"seed": 2}}, "J": {"whole": 0.3}, "delay_s": None}}
    s = summarise(runs)
    assert set(s) == {"J.whole", "delay_s"}
    assert s["J.whole"]["mean"] == pytest.approx(0.2) and s["J.whole"]["max"] == 0.3
    assert s["delay_s"] == statistics([2.0])


def test_roles_are_bound_from_the_ssd(fmu_dir):
    from railfmu.experiments import lateral_alignment, suspension_fault
    from railfmu.fmus.ssp import read_system

    system = read_system(EXPERIMENTS / "suspension_fault", variant="step_fault", fmu_dirs=[fmu_dir])
    roles = suspension_fault.STUDY.bind(system)
    assert roles == {"k1": "fault.y", "k1_before": 430e3, "k1_after": 215e3, "fault_time": 20.0,
                     "recorded": False, "recording_offset": "recording.offset"}  # step_fault reads the exact track
    system = read_system(EXPERIMENTS / "lateral_alignment", variant="standard", fmu_dirs=[fmu_dir],
                         overrides={"run": {"V": "25"}})
    roles = lateral_alignment.STUDY.bind(system)
    assert (roles["ddy"], roles["dpsi"], roles["ddy_f"]) == ("sensors.y_1", "sensors.y_2", "sensors.y_3")
    assert roles["alignment"] == "track.alignment_1" and roles["position"] == "track.position"
    assert roles["speed"] == 25.0  # a --set reaches the study: nothing repeated in Python
    tw = read_system(EXPERIMENTS / "track_wheelset", fmu_dirs=[fmu_dir])
    assert bind_role(tw, parameter("wheelset", "integrator_step")) == 1e-4  # not bound: the FMU's start value
    assert bind_role(tw, setting("alignment", "V")) == 20.0
    for role, message in ((truth("smoother", "xi"), "Observer 'smoother'"),
                          (observer_input("alignment", "xi"), "no Input 'xi'"),
                          (measurement("alignment", "xi"), "no Measurement 'xi'"),
                          (parameter("vehicle", "V"), "component 'vehicle'"),
                          (output("wheelset", "no_such"), "'wheelset.no_such'")):
        with pytest.raises(UserError, match=message):
            bind_role(tw, role)


def test_a_member_writes_nothing_loads_no_plotting_and_derives_no_model(tmp_path):
    code = ("import io, sys; from railfmu.experiments.engine.runner import run_experiment; "
            "m = run_experiment('track_wheelset', 'psd', 'member', seed=3, stop_time=0.2, progress=False, "
            "log=io.StringIO(), write_files=False); "
            "print(m['seed'], m['parameters']['track']['seed'], sorted(m['timing_s']), "
            "'railfmu.experiments.engine.plots' in sys.modules, 'railfmu.models.vehicle.vehicle_lateral' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                         env={"PYTHONPATH": str(EXPERIMENTS.parent), "PATH": ""})
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["3", "3", "['setup',", "'stepping',", "'study_metrics']", "False", "False"]
    assert list(tmp_path.iterdir()) == []


def test_one_run_per_variant_keeps_its_format_and_variant_selects(tmp_path):
    out = tmp_path / "study"
    res = railfmu("study", "track_wheelset", "--variant", "harmonic", "--stop-time", "0.5", "--out", str(out))
    assert res.returncode == 0, res.stderr
    table = json.loads((out / "table.json").read_text())
    assert list(table) == ["harmonic"]  # {variant: metrics}, as before
    assert table["harmonic"]["variant"] == "harmonic" and "rms" in table["harmonic"]
    assert (out / "harmonic" / "signals.csv").is_file() and not (out / "psd").exists()
    md = (out / "table.md").read_text()
    assert "| harmonic |" in md and "rms error of the raw estimate" in md
    res = railfmu("study", "track_wheelset", "--variant", "no_such", "--out", str(out))
    assert res.returncode == 2 and "unknown variant 'no_such'" in res.stderr


def test_monte_carlo_runs_each_seed_and_summarises(tmp_path):
    out = tmp_path / "mc"
    res = railfmu("study", "track_wheelset", "--variant", "psd", "--runs", "3", "--seed", "5", "--stop-time", "0.5",
                  "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "[3/3]" in res.stderr and "left" in res.stderr
    table = json.loads((out / "table.json").read_text())
    assert list(table) == ["psd"] and set(table["psd"]) == {"runs", "summary"}
    runs, summary = table["psd"]["runs"], table["psd"]["summary"]
    assert sorted(runs) == ["5", "6", "7"]
    assert [runs[s]["parameters"]["track"]["seed"] for s in ("5", "6", "7")] == [5, 6, 7]
    rms = [runs[s]["rms"]["track.alignment_1"] for s in ("5", "6", "7")]
    assert len(set(rms)) == 3  # each seed its own track
    assert summary["rms.track.alignment_1"] == statistics(rms)
    err = [runs[s]["observers"]["alignment"]["xi"]["rms_error"] for s in runs]
    assert summary["observers.alignment.xi.rms_error"]["max"] == max(err)
    assert "parameters.track.seed" not in summary and "seed" not in summary
    md = (out / "table.md").read_text()
    assert "Summary over 3 seeds" in md and "| psd | observers.alignment.xi.rms_error |" in md
    assert not (out / "psd").exists()  # members write no files unless --keep-runs


def test_monte_carlo_keep_runs_writes_each_member(tmp_path):
    out = tmp_path / "mc"
    res = railfmu("study", "track_wheelset", "--variant", "harmonic", "--runs", "2", "--stop-time", "0.2",
                  "--keep-runs", "--out", str(out))
    assert res.returncode == 0, res.stderr
    for seed in (1, 2):  # the default first seed is 1
        assert (out / "harmonic" / f"seed_{seed}" / "signals.csv").is_file()
        assert (out / "harmonic" / f"seed_{seed}" / "report.md").is_file()


def test_an_ssp_given_by_path_gets_the_default_study_when_its_ssd_names_none(tmp_path):
    exp = tmp_path / "exp"
    shutil.copytree(EXPERIMENTS / "track_wheelset", exp, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    ssd = exp / "SystemStructure.ssd"
    text = ssd.read_text()
    start = text.index('<ssc:Annotation type="org.railfmu.study">')
    ssd.write_text(text[:start] + text[text.index("</ssc:Annotation>", start) + len("</ssc:Annotation>"):])
    out = tmp_path / "run"
    res = railfmu("run", str(exp), "--stop-time", "0.3", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "railfmu: warning: " in res.stderr and "names no study" in res.stderr
    report = (out / "report.md").read_text()
    assert "## Observer `alignment`: raw estimate against its truth" in report
    assert "| xi |" in report and "rms error of the raw estimate" in report
    assert (out / "signals.png").is_file() and (out / "estimates_alignment.png").is_file()
    assert not (out / "track_input.png").exists()  # the package's figures belong to its study
    # the SSD as shipped names its study: a copy keeps its figures, whatever the folder's name
    shutil.copy(EXPERIMENTS / "track_wheelset" / "SystemStructure.ssd", ssd)
    res = railfmu("run", str(exp), "--stop-time", "0.3", "--out", str(tmp_path / "named"))
    assert res.returncode == 0 and "warning" not in res.stderr, res.stderr
    assert (tmp_path / "named" / "track_input.png").is_file()
