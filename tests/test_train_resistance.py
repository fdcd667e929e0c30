"""Experiments train_resistance and train_resistance_measured (Cunillera et al. (2022)) through
the CLI: the run's true resistance is the published one times the seeded per-run factors (a
closed form of the SensorNoise stream), the metrics are recomputed here from the CSVs, the
Monte Carlo study brings its figures back from members that write nothing, and a measured
run replayed from CSV gives the simulated run's estimates; bad measured input is one line,
exit 2."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import fmpy
import numpy as np
import pytest

from railfmu.models.track.line_profile import DEFAULT_LINE
from railfmu.models.sources.sensors import noise
from railfmu.models.train.longitudinal import R0, R1, R2, davis_specific

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64",
                                reason="needs gcc on linux64")

ROOT = Path(__file__).resolve().parents[1]
MEASURED = ROOT / "experiments" / "train_resistance_measured"
EXAMPLE = MEASURED / "resources" / "example_run.csv"
KMH = 1 / 3.6
SEED = 3


def railfmu(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True, text=True,
                          cwd=cwd)


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {c: np.array([float(r[j]) for r in rows[1:]]) for j, c in enumerate(rows[0])}


def factors(seed: int) -> np.ndarray:
    """The run's resistance factors 1 + 0.1 w: SensorNoise channels 4-6 at sample 0."""
    return np.array([1.0 + 0.1 * float(noise(seed, i, [0])[0]) for i in (4, 5, 6)])


@pytest.fixture(scope="module")
def standard(tmp_path_factory, fmu_dir):
    out = tmp_path_factory.mktemp("standard")
    res = railfmu("run", "train_resistance", "--seed", str(SEED), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out, json.loads((out / "metrics.json").read_text())


def test_standard_run_end_to_end(standard):
    out, m = standard
    sig, est = read_csv(out / "signals.csv"), read_csv(out / "estimates.csv")
    # the driver ended the run at the station; the true resistance is the published one times
    # the seeded factors, constant over the run (bias + sigma w of the SensorNoise, exactly)
    assert m["early_end"] and sig["train.v"][-1] == 0.0 and abs(sig["train.s"][-1] - 32103) < 5
    r_pub = np.array([R0, R1, R2])
    r_true = np.array([sig[f"resistance.y_{4 + k}"][-1] for k in range(3)])
    np.testing.assert_allclose(r_true, r_pub * factors(SEED), rtol=1e-14)
    for k in range(3):
        assert np.ptp(sig[f"resistance.y_{4 + k}"]) == 0.0
    assert m["truth"]["r0"] == r_true[0]

    # metrics recomputed from the CSVs: at the GNSS fixes after the first
    fixes = np.flatnonzero(sig["gnss.valid"] == 1)[1:]
    assert np.array_equal(sig["time"][fixes], np.arange(10.0, sig["time"][-1] + 1e-9, 10.0))
    e = m["ukf_paper"]
    ev = (est["ukf_paper.v"][fixes] - sig["train.v"][fixes]) / KMH
    es = est["ukf_paper.s"][fixes] - sig["train.s"][fixes]
    assert e["speed_rmse_kmh"] == pytest.approx(np.sqrt(np.mean(ev ** 2)), rel=1e-12)
    assert e["position_rmse_m"] == pytest.approx(np.sqrt(np.mean(es ** 2)), rel=1e-12)
    r_hat = np.array([est[f"ukf_paper.r{k}"][-1] for k in range(3)])
    v = np.linspace(40, 140, 101) * KMH
    rel = np.polyval(r_hat[::-1], v) / np.polyval(r_true[::-1], v) - 1
    assert e["resistance_rel_error"] == pytest.approx(np.sqrt(np.mean(rel ** 2)), rel=1e-12)
    for k in range(3):
        assert e[f"r{k}_rel_error"] == pytest.approx(r_hat[k] / r_true[k] - 1, rel=1e-12, abs=1e-15)
    # bounds a wrong model breaks: the paper's UKF follows the speed within the 1 km/h
    # resolution and the position within the 4 m noise; it hardly moves from the published
    # values (Table 1 sigmas, Q = 0), so its resistance error is the run's scatter
    assert e["speed_rmse_kmh"] < 1.0 and e["position_rmse_m"] < 8.0
    assert e["resistance_rel_error"] < 0.3 and 0 < e["seconds"] < 5
    # regimes and features: the study's wiring equals railfmu.estimators.train.recognisers.score on the CSVs
    from railfmu.estimators.train.recognisers import score

    every = np.flatnonzero(sig["gnss.valid"] == 1)
    style = {k: sig[f"driver.{k}"][0] for k in ("cruise_target", "traction_fraction",
                                                *(f"brake_rate_{j}" for j in range(1, 6)))}
    train = {"max_power": 2388e3, "max_traction_force": 226e3, "tare_mass": 297e3, "load_mass": 15960.0,
             "rotating_mass_factor": 1.06}
    ref, feats = score(sig["time"][every], est["ukf_paper.v"][every], est["ukf_paper.acceleration"][every],
                       est["ukf_paper.effort"][every], sig["time"], sig["train.v"], sig["train.effort_specific"],
                       style, train)
    for k in ("regime_accuracy", "max_power_rel_error", "max_effort_rel_error", "cruise_speed_error_kmh"):
        assert e[k] == pytest.approx(ref[k], rel=1e-12), k
    assert [x is None for x in e["brake_rate_error"]] == [x is None for x in ref["brake_rate_error"]]
    assert [x for x in e["brake_rate_error"] if x is not None] == pytest.approx(
        [x for x in ref["brake_rate_error"] if x is not None], rel=1e-12)
    assert e["features"]["cruise_speed_kmh"] == pytest.approx(feats["cruise_speed"] * 3.6, rel=1e-12)
    # each estimator is read by its own recogniser: `improved` by the HMM over the run
    assert (e["regime_recogniser"], m["improved"]["regime_recogniser"]) == ("paper", "hmm")
    ours, _ = score(sig["time"][every], est["improved.v"][every], est["improved.acceleration"][every],
                    est["improved.effort"][every], sig["time"], sig["train.v"], sig["train.effort_specific"],
                    style, train, "hmm")
    assert m["improved"]["regime_accuracy"] == pytest.approx(ours["regime_accuracy"], rel=1e-12)
    assert m["improved"]["regime_accuracy"] >= 0.95 > e["regime_accuracy"]
    # what the paper's UKF gives on this run (a wrong effort or acceleration breaks these)
    assert e["regime_accuracy"] > 0.75 and e["max_power_rel_error"] < 0.1 and e["cruise_speed_error_kmh"] < 3
    assert sum(e["regime_share"].values()) == pytest.approx(1.0)
    # the truth: shares of the running time add up to 1, the durations from the driver's steps
    tr = m["truth"]
    assert 120 <= tr["cruise_target_kmh"] <= 140 and 0 < tr["final_brake_s"] < tr["final_coast_min"] * 60
    assert sum(tr[f"share_{r}"] for r in ("traction", "cruising", "coasting", "braking")) == pytest.approx(1.0)
    for f in ("fig3_run.png", "fig5_resistance_terms.png", "fig6_regimes.png", "report.md"):
        assert (out / f).is_file(), f
    assert "The run beside the paper's Fig. 3 run" in (out / "report.md").read_text()


def test_variants_set_the_truth_they_name(tmp_path, fmu_dir):
    """heavy_load: the truth is the 100 %-load mass-specific Davis law; resistance_drift: r2
    rises on the headwind table (0.36 R2 at 1800 s, linear) on top of the factors; gnss_1hz:
    the observer samples every second."""
    f = factors(1)
    runs = {}
    for variant in ("heavy_load", "resistance_drift", "gnss_1hz"):
        res = railfmu("run", "train_resistance", "--variant", variant, "--out", str(tmp_path / variant))
        assert res.returncode == 0, res.stderr
        runs[variant] = read_csv(tmp_path / variant / "signals.csv"), json.loads(
            (tmp_path / variant / "metrics.json").read_text())
    sig, m = runs["heavy_load"]
    heavy = np.array(davis_specific(1.06 * (297e3 + 570 * 80.0)))
    np.testing.assert_allclose([sig[f"resistance.y_{4 + k}"][-1] for k in range(3)], heavy * f, rtol=1e-14)
    assert m["parameters"]["train"]["load_mass"] == 45600.0
    sig, m = runs["resistance_drift"]
    # the truth: the resistance source's output at t (the train steps on it from t)
    t = sig["time"]
    np.testing.assert_allclose(sig["resistance.y_6"], R2 * f[2] + 0.36 * R2 * t / 1800.0, rtol=1e-12)
    assert m["truth"]["r2"] == pytest.approx(R2 * (f[2] + 0.3 * t[-1] / 1500.0), rel=1e-12)
    sig, m = runs["gnss_1hz"]
    assert np.all(sig["gnss.valid"] == 1)
    assert m["observers"]["ukf_paper"]["steps"] == len(sig["time"])
    assert m["ukf_paper"]["speed_rmse_kmh"] < 1.0


def test_line_file_is_one_system_parameter(tmp_path, fmu_dir):
    """`--set line.file=...` reaches the train, the driver and every observer; a bad one is one line."""
    from railfmu.experiments.engine.runner import find_experiment, load_system

    line = tmp_path / "my line.csv"
    shutil.copy(DEFAULT_LINE, line)
    system = load_system(find_experiment("train_resistance"), "standard", {"line": {"file": str(line)}})
    assert system.component("train").parameters["line_file"] == str(line)
    assert system.component("driver").parameters["line_file"] == str(line)
    assert system.observers[0].settings["line_file"] == str(line)
    system = load_system(find_experiment("train_resistance_measured"), "measured")
    assert system.observers[0].settings["line_file"] == str(MEASURED / "resources" / "line.csv")
    res = railfmu("run", "train_resistance_measured", "--set", f"line.file={tmp_path / 'none.csv'}",
                  "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines()[-1] == (f"railfmu: error: --set line.file: {tmp_path / 'none.csv'}: "
                                                   f"no such file ({tmp_path / 'none.csv'})")


def test_four_run_study_with_summary_and_figures(tmp_path, fmu_dir):
    out = tmp_path / "study"
    res = railfmu("study", "train_resistance", "--variant", "standard", "--runs", "4", "--out", str(out))
    assert res.returncode == 0, res.stderr
    table = json.loads((out / "table.json").read_text())["standard"]
    assert sorted(table["runs"]) == ["1", "2", "3", "4"]
    assert all("series" not in m for m in table["runs"].values())  # the figures' arrays stay out
    s = table["summary"]
    speeds = [m["ukf_paper"]["speed_rmse_kmh"] for m in table["runs"].values()]
    assert s["ukf_paper.speed_rmse_kmh"]["p50"] == pytest.approx(np.median(speeds))
    assert s["ukf_paper.speed_rmse_kmh"]["max"] < 1.0
    # each member's truth is its own seed's
    for seed, m in table["runs"].items():
        assert m["truth"]["r2"] == pytest.approx(R2 * factors(int(seed))[2], rel=1e-14)
    md = (out / "table.md").read_text()
    assert "Beside Cunillera et al. (2022)" in md and "CV of the final brake time" in md
    for fig in ("fig2_speed_profiles", "fig4_resistance", "fig7_driving_style", "fig8_brake_rates",
                "fig9_traction_power"):
        assert (out / f"{fig}_standard.png").is_file() and f"{fig}_standard.png" in md


@pytest.fixture(scope="module")
def replayed(tmp_path_factory, fmu_dir):
    out = tmp_path_factory.mktemp("measured")
    res = railfmu("run", "train_resistance_measured", "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out, json.loads((out / "metrics.json").read_text())


def test_measured_replay_of_the_shipped_example(replayed, tmp_path):
    """The example is seed 1 of train_resistance at its fixes (position to 0.1 m, speed to
    1 km/h, as the GNSS reads it): replayed, the UKF ends where it ended in the simulation."""
    out, m = replayed
    rows = read_csv(EXAMPLE)
    assert np.all(np.diff(rows["time_s"]) == 10.0)
    assert m["fixes"] == len(rows["time_s"]) and m["run_time_s"] == rows["time_s"][-1]
    res = railfmu("run", "train_resistance", "--seed", "1", "--out", str(tmp_path / "sim"))
    assert res.returncode == 0, res.stderr
    sim = json.loads((tmp_path / "sim" / "metrics.json").read_text())["ukf_paper"]
    for k in range(3):
        assert m["ukf_paper"][f"r{k}_final"] == pytest.approx(sim[f"r{k}_final"], rel=1e-6)
    assert m["ukf_paper"]["speed_residual_kmh"] < 0.1 and m["ukf_paper"]["position_residual_m"] < 10
    assert "speed_rmse_kmh" not in m["ukf_paper"]  # no truth in a measured run
    # the features of the replay are the simulated run's
    got, want = m["ukf_paper"]["features"], sim["features"]
    assert got["final_coast_min"] == want["final_coast_min"] and got["final_brake_s"] == want["final_brake_s"]
    assert got["cruise_speed_kmh"] == pytest.approx(want["cruise_speed_kmh"], abs=0.05)
    assert [x is None for x in got["brake_rates"]] == [x is None for x in want["brake_rates"]]
    assert [x for x in got["brake_rates"] if x] == pytest.approx([x for x in want["brake_rates"] if x], abs=1e-3)
    assert got["max_power_w_per_kg"] * 1.06 * (297e3 + 15960) == pytest.approx(want["max_power_w"], rel=1e-3)


BAD = {  # file text -> the one error line's tail
    "missing-column": ("time_s,position_m\n0,0\n10,100\n",
                       "line 1: no column 'speed_kmh' (named by parameter column_2); the header has: time_s, position_m"),

    "nan": ("time_s,position_m,speed_kmh\n0,0,0\n10,nan,30\n",
            "line 3, column 2 (position_m): 'nan' is not a finite number"),
    "text": ("time_s,position_m,speed_kmh\n0,0,0\n10,12 m,30\n",
             "line 3, column 2 (position_m): '12 m' is not a number"),
    "wrong-time-column": ("t,position_m,speed_kmh\n0,0,0\n10,100,30\n",
                          "line 1, column 1: the first column must be 'time' or 'time_s' (s), not 't'"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_measured_run_is_one_line_and_exit_2(case, tmp_path, fmu_dir):
    text, tail = BAD[case]
    run = tmp_path / "run.csv"
    run.write_text(text)
    res = railfmu("run", "train_resistance_measured", "--set", f"replay.file={run}", "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("railfmu: error:")]
    assert errors == [f"railfmu: error: SignalTable.fmu (replay): fmi2ExitInitializationMode failed: "
                      f"file {run}, {tail}"], res.stderr


def test_times_that_go_back_are_named_before_the_run(tmp_path, fmu_dir):
    """The engine's replay check (experiments/engine/replay.py) reads the table first: the line, the column."""
    run = tmp_path / "run.csv"
    run.write_text("time_s,position_m,speed_kmh\n0,0,0\n10,100,30\n5,200,40\n")
    res = railfmu("run", "train_resistance_measured", "--set", f"replay.file={run}", "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and res.stderr.strip().splitlines() == [
        f"railfmu: error: replay.file {run} line 4, column 'time_s': 5 s is before the previous row's time 10 s "
        "(the times go back: sort the file by time)"]


# the observers sample at the log's interval (5 s here) unless told: 10 s, so that the run is shorter than one sample
PERIOD_10 = [x for o in ("ukf_paper", "improved", "ukf_fmu") for x in ("--set", f"{o}.samplePeriod=10")]


@pytest.mark.parametrize("text, span", [("time_s,position_m,speed_kmh\n0,0,0\n5,10,7\n", 5),
                                        ("time_s,position_m,speed_kmh\n0,0,0\n", 0)])
def test_a_run_shorter_than_one_gnss_sample_is_a_clear_error(text, span, tmp_path, fmu_dir):
    run = tmp_path / "short.csv"
    run.write_text(text)
    res = railfmu("run", "train_resistance_measured", "--set", f"replay.file={run}", *PERIOD_10,
                  "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines() == [
        f"railfmu: error: replay.file {run}: the run lasts {span} s, shorter than one GNSS sample (10 s, the "
        "observers' sample period): nothing to estimate"]


@pytest.mark.slow
def test_the_67_run_study(tmp_path, fmu_dir):
    """`railfmu study train_resistance --variant standard --runs 67`: the paper's 67 runs in at
    most 60 s on two workers (measured 25 s), and the study's targets on the medians: `improved`
    resistance_rel_error <= 0.05 (measured 0.0043) and speed_rmse_kmh <= 1.0 (0.23);
    max_power_rel_error <= 0.05 (ukf_paper 0.018, improved 0.015). regime_accuracy >= 0.95
    for `improved`, read by its hidden Markov model over the run (estimators/train/regime_decoding.py):
    measured 0.978; the paper's UKF read by the paper's rules as it comes out, 0.934 (the
    rules on the exact signals sampled every 10 s: 0.947, the mixed intervals of the cruise
    cycles). The paper's UKF: resistance_rel_error 0.050, speed 0.28 km/h; `ukf_fmu` (the FMU
    as its process model) the same to 1e-4."""
    t0 = time.monotonic()
    res = railfmu("study", "train_resistance", "--variant", "standard", "--runs", "67", "--out", str(tmp_path))
    wall = time.monotonic() - t0
    assert res.returncode == 0, res.stderr
    s = json.loads((tmp_path / "table.json").read_text())["standard"]["summary"]
    p50 = {k: v["p50"] for k, v in s.items()}
    assert p50["improved.resistance_rel_error"] <= 0.05 and p50["improved.speed_rmse_kmh"] <= 1.0
    assert p50["improved.resistance_rel_error"] < p50["ukf_paper.resistance_rel_error"] / 5
    assert p50["ukf_paper.speed_rmse_kmh"] <= 1.0
    assert p50["ukf_paper.max_power_rel_error"] <= 0.05 and p50["improved.max_power_rel_error"] <= 0.05
    assert p50["ukf_paper.regime_accuracy"] >= 0.92 and p50["improved.regime_accuracy"] >= 0.95
    assert abs(p50["ukf_fmu.resistance_rel_error"] - p50["ukf_paper.resistance_rel_error"]) < 1e-4
    # the 60 s is a speed goal, measured by the command and reported, not asserted
    # here (a loaded machine is not a slow implementation)
    print(f"railfmu study train_resistance --variant standard --runs 67: {wall:.1f} s wall")


@pytest.mark.parametrize("edit, message", [
    (('connector="driver.line_file"', 'connector="driver.nope"'), "Target 'driver.nope': Driver.fmu has no variable 'nope'"),
    (('name="line.file"', 'name="train.file"'), "the name must be group.parameter and the group no component or observer"),
    (('setting="ukf_paper.line_file"', 'setting="nobody.line_file"'), "Target setting 'nobody.line_file': no Observer 'nobody'"),
])
def test_a_bad_system_parameter_is_one_line(edit, message, tmp_path, fmu_dir):
    from railfmu.models.errors import UserError
    from railfmu.fmus.ssp import read_system

    exp = tmp_path / "exp"
    shutil.copytree(ROOT / "experiments" / "train_resistance", exp)
    ssd = exp / "SystemStructure.ssd"
    ssd.write_text(ssd.read_text().replace(*edit))
    with pytest.raises(UserError, match=message.replace("(", r"\(").replace(")", r"\)")):
        read_system(exp, fmu_dirs=[fmu_dir])


def test_observers_must_sample_at_the_gnss_period(tmp_path, fmu_dir):
    res = railfmu("run", "train_resistance", "--set", "gnss.sample_period=5", "--out", str(tmp_path))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines()[-1].endswith(
        "Observer 'ukf_paper' samples every 10 s but the GNSS fixes come every 5 s: set ukf_paper.samplePeriod=5 too")


@pytest.mark.slow
def test_the_unknown_stock_study(tmp_path, fmu_dir):
    """`railfmu study train_resistance --variant unknown_stock --runs 67 --seed 1000`: true
    coefficients log-uniform in [0.5, 2] x the published values and the load uniform over
    0-100 % per run, the estimators starting from the published ones and not told the load.
    The recommended `em` (resistance_coasting_em): resistance_rel_error median <= 0.03 and
    p95 <= 0.08 (measured 0.0059 / 0.0166), regime_accuracy median >= 0.95 (0.983); the
    prior-gated `improved` and the paper's UKF beside it (measured medians 0.026 and 0.24, p95
    0.43 and 0.50)."""
    res = railfmu("study", "train_resistance", "--variant", "unknown_stock", "--runs", "67", "--seed", "1000",
                  "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    s = json.loads((tmp_path / "table.json").read_text())["unknown_stock"]["summary"]
    assert s["em.resistance_rel_error"]["p50"] <= 0.03 and s["em.resistance_rel_error"]["p95"] <= 0.08
    assert s["em.regime_accuracy"]["p50"] >= 0.95
    assert s["em.resistance_rel_error"]["p50"] < s["ukf_paper.resistance_rel_error"]["p50"] / 5


def test_unknown_stock_with_the_load_drawn(tmp_path, fmu_dir):
    """The reduced unknown_stock study (2 runs; the 67-run one is slow): each run's load is its
    own uniform draw (SensorNoise channel 7, u2 at sample 0: seed 1003 carries 89 %, seed 1004
    7 % of the 45.6 t rated load) and its coefficients their log-uniform draws; nobody tells the
    estimators either. `em` recovers the mass-specific resistance within the 67-run p95 target
    0.08 per run and the median target 0.03 over both (measured 0.003 and 0.010: the load acts
    only through the traction, f_t = F_t / (gamma m), not through coasting); the paper's UKF
    stays on the published values, more than 3x further off."""
    from railfmu.models.sources.sensors import log_uniform_factor, uniforms

    res = railfmu("study", "train_resistance", "--variant", "unknown_stock", "--runs", "2", "--seed", "1003",
                  "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    runs = json.loads((tmp_path / "table.json").read_text())["unknown_stock"]["runs"]
    loads, errs = [], []
    for seed, m in runs.items():
        load = float(uniforms(int(seed), 7, [0])[1][0])
        loads.append(load)
        assert m["truth"]["mass_kg"] == pytest.approx(297e3 + 45600.0 * load, rel=1e-14)
        r_true = [b * float(log_uniform_factor(int(seed), i, [0], np.log(2.0))[0])
                  for b, i in zip((R0, R1, R2), (4, 5, 6))]
        assert [m["truth"][f"r{k}"] for k in range(3)] == pytest.approx(r_true, rel=1e-14)
        e = m["em"]["resistance_rel_error"]
        errs.append(e)
        assert e <= 0.08, (seed, load, e)
        assert m["em"]["regime_accuracy"] >= 0.9, (seed, m["em"]["regime_accuracy"])
        assert m["ukf_paper"]["resistance_rel_error"] > 3 * e
    assert max(loads) > 0.8 and min(loads) < 0.1  # both ends of the load range are exercised
    assert np.median(errs) <= 0.03


def test_a_run_shorter_than_the_gnss_interval_is_refused_in_one_line(tmp_path):
    """3 s of a run whose fixes come every 10 s hold only the initial fix: no estimate and no score,
    so the run is refused before it starts (it ended in a numpy traceback)."""
    res = railfmu("run", "train_resistance", "--stop-time", "3", "--out", str(tmp_path / "short"))
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "ends before its first GNSS fix" in lines[0] and "Traceback" not in res.stderr
    res = railfmu("run", "train_resistance", "--stop-time", "10", "-q", "--out", str(tmp_path / "one_fix"))
    assert res.returncode == 0, res.stderr  # one fix after the start is enough to score
