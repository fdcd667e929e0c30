"""The suspension_fault experiment (Onat et al. 2016) end to end through `railfmu`: SSD wiring (track
under both bogies, the fault source into coach.k1, noisy sensors), both observers, metrics.json
keys, and the improved estimator's targets. CI runs shortened variants; the full 150 s study
is `slow`."""

import json
import subprocess
import sys

import pytest

TARGET_REL_ERROR = 0.02  # the target of the study: improved, final relative error, every variant
TARGET_CONVERGENCE_S = 20.0  # static
TARGET_DETECTION_S = 5.0  # step_fault
KEYS = {"k1_true_final", "k1_est_final", "rel_error_final", "convergence_time_s"}


def run(tmp_path, variant, *extra):
    out = tmp_path / variant
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "suspension_fault", "--variant", variant,
                          "--out", str(out), *extra], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return json.loads((out / "metrics.json").read_text()), out


@pytest.mark.parametrize("variant", ["static", "step_fault_no_noise"])
def test_reduced_run_meets_the_improved_targets(tmp_path, variant):
    metrics, out = run(tmp_path, variant, "--stop-time", "40")
    for name in ("paper_wls", "improved"):
        assert KEYS <= set(metrics[name])
        assert ("detection_delay_s" in metrics[name]) == variant.startswith("step_fault")
    imp = metrics["improved"]
    truth = 215e3 if variant.startswith("step_fault") else 430e3
    assert imp["k1_true_final"] == truth
    assert imp["rel_error_final"] <= TARGET_REL_ERROR
    if variant == "static":
        assert imp["convergence_time_s"] <= TARGET_CONVERGENCE_S
    else:
        assert imp["detection_delay_s"] <= TARGET_DETECTION_S
    # the paper's scheme runs and is reported, not held to the targets
    assert metrics["paper_wls"]["k1_est_final"] > 0
    for f in ("k1_estimates.png", "signals.csv", "estimates.csv", "report.md"):
        assert (out / f).is_file()
    report = (out / "report.md").read_text()
    assert "| improved |" in report and "| paper_wls |" in report


def test_study_table_sets_the_papers_claim_beside_its_scheme():
    """table_md: the last column is headed by the paper and holds its claim on the paper_wls rows only."""
    from railfmu.experiments.suspension_fault import PAPER_CLAIM, STUDY

    e = {"k1_true_final": 430e3, "k1_est_final": 425e3, "rel_error_final": -0.0116, "convergence_time_s": 9.0}
    md = STUDY.table_md({"static": {"paper_wls": e, "improved": e}})
    assert md.splitlines()[0].endswith("| Onat et al. (2016) |")
    assert f"| static | paper_wls | 430 | 425 | -0.0116 | 9 | - | {PAPER_CLAIM} |" in md.splitlines()
    assert "| static | improved | 430 | 425 | -0.0116 | 9 | - |  |" in md.splitlines()
    assert "Fig. 2 of Onat et al. (2016)" in md and "seed" not in md.lower()


def test_noise_comes_from_the_sensors_fmu(tmp_path):
    """With noise, the sensor output differs from the coach's true signal by ~0.01 m/s2 rms;
    without, it is the coach's signal exactly."""
    import csv

    import numpy as np

    for variant, expected in (("static", 0.01), ("static_no_noise", 0.0)):
        _, out = run(tmp_path, variant, "--stop-time", "5")
        rows = list(csv.DictReader(open(out / "signals.csv")))
        diff = np.array([float(r["sensors.y_1"]) - float(r["coach.ddz_c"]) for r in rows])
        assert np.sqrt(np.mean(diff ** 2)) == pytest.approx(expected, rel=0.1, abs=1e-15)


@pytest.mark.slow
def test_full_study_meets_every_target(tmp_path):
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "study", "suspension_fault", "--out",
                          str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    table = json.loads((tmp_path / "table.json").read_text())
    for variant in ("static", "static_no_noise", "step_fault", "step_fault_no_noise"):
        imp = table[variant]["improved"]
        assert imp["rel_error_final"] <= TARGET_REL_ERROR, variant
        if variant.startswith("static"):
            assert imp["convergence_time_s"] <= TARGET_CONVERGENCE_S, variant
        else:
            assert imp["detection_delay_s"] <= TARGET_DETECTION_S, variant
    assert "paper_wls" in (tmp_path / "table.md").read_text()


# the recorded track: the estimators' rails are a recording car's file of the track (TrackRecording)
RECORDED = "step_fault_recorded_track"
TARGET_RECORDED_REL_ERROR = 0.02  # p95 over 20 seeds
TARGET_RECORDED_DETECTION_S = 3.0  # p95 over 20 seeds


def _recorded_study(tmp_path, runs, seed, stop_time=None):
    import railfmu

    return railfmu.study("suspension_fault", [RECORDED], runs=runs, seed=seed, stop_time=stop_time,
                         out=tmp_path)[RECORDED]


def test_recorded_track_reduced_study(tmp_path):
    """Two seeds, 40 s (20 s after the fault): the offset is found to a fraction of the 0.2 m a
    sample covers at 20 m/s, and k1 holds. Looser than the full study's p95 targets: 20 s after
    the fault the estimate still wanders by up to ~3 % (it settles over the 130 s of the full run),
    and two seeds say nothing about a 95th percentile."""
    table = _recorded_study(tmp_path, runs=2, seed=2, stop_time=40)
    for seed, m in table["runs"].items():
        imp = m["improved"]
        assert abs(m["recording_offset_m"]) <= 3.0
        lag = m["observers"]["improved"]["lag_s"]
        assert lag * 20.0 == pytest.approx(m["recording_offset_m"], abs=0.2), seed
        assert imp["rel_error_final"] <= 0.04, seed
        assert imp["detection_delay_s"] is not None and imp["detection_delay_s"] <= 5.0, seed
        assert m["paper_wls"]["k1_est_final"] > 0


@pytest.mark.slow
def test_recorded_track_study_meets_its_targets(tmp_path):
    """The done-when measure: 20 seeds (1000-1019, none used to tune), p95 of improved's final
    error and detection delay; every run detects the fault."""
    table = _recorded_study(tmp_path, runs=20, seed=1000)
    s = table["summary"]
    assert s["improved.rel_error_final"]["p95"] <= TARGET_RECORDED_REL_ERROR
    assert s["improved.detection_delay_s"]["p95"] <= TARGET_RECORDED_DETECTION_S
    assert all(m["improved"]["detection_delay_s"] is not None for m in table["runs"].values())
