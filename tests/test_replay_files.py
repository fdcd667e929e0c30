"""A user's own files in the replay experiments (experiments/engine/replay.py, fmus/ssp/reader.py):
relative paths from the current folder, runs shaped by the file, and the checks that catch a
wrong file (one line, exit 2) or warn about a suspicious one (heading, report, metrics.json)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import railfmu
from railfmu.models.errors import UserError

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "experiments" / "train_resistance_measured" / "resources" / "example_run.csv"
LINE = ROOT / "experiments" / "train_resistance_measured" / "resources" / "line.csv"
IMU = ROOT / "experiments" / "trolley_imu_replay" / "resources" / "imu.csv"
TRUTH = ROOT / "experiments" / "trolley_imu_replay" / "resources" / "truth.csv"


def cli(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=900)


def errors(res) -> list[str]:
    return [ln for ln in res.stderr.splitlines() if ln.startswith("railfmu: error:")]


def gnss(tmp_path: Path, name: str, frame: pd.DataFrame) -> Path:
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def baseline():
    return railfmu.run("train_resistance_measured").metrics


# -- 1. paths as a user means them ---------------------------------------------------------------

def test_relative_paths_in_run_from_a_folder_outside_the_repository(tmp_path, fmu_dir):
    (tmp_path / "RUN.csv").write_bytes(RUN.read_bytes())
    (tmp_path / "LINE.csv").write_bytes(LINE.read_bytes())
    res = cli("run", "train_resistance_measured", "--set", "replay.file=RUN.csv", "--set", "line.file=LINE.csv",
              "--out", "o", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert f"  replay.file = {tmp_path / 'RUN.csv'} (--set: RUN.csv relative to {tmp_path})" in res.stderr
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["parameters"]["replay"]["file"] == str(tmp_path / "RUN.csv")
    assert m["parameters"]["train"]["line_file"] == str(tmp_path / "LINE.csv")
    assert m["observer_settings"]["improved"]["line_file"] == str(tmp_path / "LINE.csv")
    assert m["replay"]["given"]["line.file"]["path"] == str(tmp_path / "LINE.csv")
    res = cli("run", "train_resistance_measured", "--set", "replay.file=NOPE.csv", "--out", "o", cwd=tmp_path)
    assert res.returncode == 2 and errors(res) == [
        f"railfmu: error: --set replay.file: NOPE.csv: no such file ({tmp_path / 'NOPE.csv'}, relative to the "
        "current directory)"]


def test_relative_paths_through_the_python_api(tmp_path, monkeypatch, fmu_dir):
    (tmp_path / "RUN.csv").write_bytes(RUN.read_bytes())
    monkeypatch.chdir(tmp_path)
    r = railfmu.run("train_resistance_measured", parameters={"replay.file": "RUN.csv"})
    assert r.metrics["parameters"]["replay"]["file"] == str(tmp_path / "RUN.csv")


def test_relative_paths_in_study_on_a_local_cluster(tmp_path, fmu_dir):
    (tmp_path / "RUN.csv").write_bytes(RUN.read_bytes())
    res = cli("study", "train_resistance_measured", "--variant", "measured", "--workers", "1",
              "--set", "replay.file=RUN.csv", "--out", "s", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    table = json.loads((tmp_path / "s" / "table.json").read_text())
    assert table["measured"]["parameters"]["replay"]["file"] == str(tmp_path / "RUN.csv")


# -- 2. replays shaped by their data -------------------------------------------------------------

def test_a_log_starting_late_is_shifted_and_gives_the_same_estimates(tmp_path, baseline, fmu_dir):
    f = pd.read_csv(RUN)
    f["time_s"] += 36000.0
    r = railfmu.run("train_resistance_measured", parameters={"replay.file": gnss(tmp_path, "late.csv", f)})
    m = r.metrics
    assert m["stop_time_s"] == 1350.0 and m["early_end"] is None
    assert any("starts at t = 36000 s: shifted to start at 0 s" in n for n in m["replay"]["derived"])
    assert m["top_speed_kmh"] == baseline["top_speed_kmh"] > 0
    assert m["improved"]["r0_final"] == pytest.approx(baseline["improved"]["r0_final"], rel=1e-9)


def test_a_1_hz_log_is_sampled_every_second(tmp_path, fmu_dir):
    f = pd.read_csv(RUN)
    t = np.arange(0.0, f.time_s.iloc[-1] + 0.5, 1.0)
    one = pd.DataFrame({"time_s": t, "position_m": np.interp(t, f.time_s, f.position_m),
                        "speed_kmh": np.interp(t, f.time_s, f.speed_kmh)})
    m = railfmu.run("train_resistance_measured", parameters={"replay.file": gnss(tmp_path, "1hz.csv", one)}).metrics
    assert m["step_size_s"] == 1.0 and m["fixes"] == len(t) == 1351
    assert m["observers"]["ukf_paper"]["steps"] == 1351
    assert any("observer ukf_paper samples every 1 s" in n for n in m["replay"]["derived"])


def test_the_shipped_replays_end_at_their_last_row(fmu_dir):
    m = railfmu.run("trolley_imu_replay").metrics
    assert (m["stop_time_s"], m["step_size_s"], m["early_end"]) == (15.0, 0.005, None)


# -- 3. checks that catch a wrong file -----------------------------------------------------------

def test_positions_in_km_are_named(tmp_path, fmu_dir):
    f = pd.read_csv(RUN)
    f["position_m"] /= 1000.0
    path = gnss(tmp_path, "km.csv", f)
    with pytest.raises(UserError, match=r"column 'position_m' against column 'speed_kmh': .*positions look like km"):
        railfmu.run("train_resistance_measured", parameters={"replay.file": path})


def test_speeds_in_m_per_s_under_kmh_are_named(tmp_path, fmu_dir):
    f = pd.read_csv(RUN)
    f["speed_kmh"] /= 3.6
    with pytest.raises(UserError, match=r"the speeds look like m/s where km/h is expected"):
        railfmu.run("train_resistance_measured", parameters={"replay.file": gnss(tmp_path, "ms.csv", f)})


@pytest.mark.parametrize("text, tail", [
    ("time_s,position_m,speed_kmh\n0,0,0\n10,100,30\n10,200,40\n",
     "line 4, column 'time_s': repeats the previous row's time 10 s (a duplicated row?)"),
    ("time_s;position_m;speed_kmh\n0;0,5;0\n10;100,5;30\n",
     "line 1: the separator is a semicolon (;) and the numbers have decimal commas; railfmu reads comma-separated "
     "tables with decimal points (e.g. 0.5,12.3): export the file so")])
def test_duplicated_times_and_semicolons_are_one_line_exit_2(text, tail, tmp_path, fmu_dir):
    (tmp_path / "bad.csv").write_text(text)
    res = cli("run", "train_resistance_measured", "--set", "replay.file=bad.csv", "--out", "o", cwd=tmp_path)
    assert res.returncode == 2 and errors(res) == [f"railfmu: error: replay.file {tmp_path / 'bad.csv'} {tail}"]


def _imu_100hz(tmp_path: Path) -> Path:
    f = pd.read_csv(IMU)
    body = f.iloc[1:].reset_index(drop=True)  # increments over (t - 5 ms, t]; summed in pairs: 10 ms
    pairs = body.groupby(body.index // 2).sum()
    pairs["time_s"] = body["time_s"].iloc[1::2].to_numpy()
    out = pd.concat([f.iloc[:1], pairs], ignore_index=True)
    path = tmp_path / "imu.csv"
    out.to_csv(path, index=False, float_format="%.17g")
    return path


def test_a_100_hz_imu_runs_at_its_own_interval_and_at_5_ms_is_named(tmp_path, fmu_dir):
    path = _imu_100hz(tmp_path)
    m = railfmu.run("trolley_imu_replay", parameters={"imu.file": path}).metrics
    assert m["step_size_s"] == 0.01 and m["ins_position_error_max_mm"] < 50.0  # not 17.6 km
    with pytest.raises(UserError, match=r"imu.file .* columns dv_x, dv_y, dv_z: increments .* fit a [0-9.]+ ms interval.*"
                                        r"system step is 5 ms: 2 times the expected increment"):
        railfmu.run("trolley_imu_replay", parameters={"imu.file": path}, step_size=0.005)


def test_a_one_row_truth_scores_nothing(tmp_path, fmu_dir):
    path = tmp_path / "truth.csv"
    path.write_text("".join(TRUTH.read_text().splitlines(keepends=True)[:2]))
    r = railfmu.run("trolley_imu_replay", parameters={"truth.file": path}, out=tmp_path / "o")
    m = r.metrics
    assert m["ins_position_error_max_mm"] is None and m["observers"]["ins"]["latitude"]["rms_error"] is None
    assert any("has 1 row(s), fewer than the 2 a score needs" in w for w in m["warnings"])
    report = (tmp_path / "o" / "report.md").read_text()
    assert "**Warnings**" in report.split("## System")[0] and "| - |" in report


def test_an_estimator_that_learned_nothing_says_so_in_the_heading_and_report(tmp_path, fmu_dir):
    t = np.arange(0.0, 1210.0, 10.0)
    v = np.minimum(t / 200.0, 1.0) * 80.0  # up to 80 km/h, then cruising: no coasting at all
    s = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 / 3.6 * 10.0)])
    path = gnss(tmp_path, "cruise.csv", pd.DataFrame({"time_s": t, "position_m": s, "speed_kmh": v}))
    res = cli("run", "train_resistance_measured", "--set", f"replay.file={path}", "--out", "o", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    line = ("railfmu: warning: observer improved found no coasting segment in the data: its resistance is its prior "
            "(coasting_segments = 0)")
    assert line in res.stderr.splitlines()
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert line.removeprefix("railfmu: warning: ") in m["warnings"]
    head = (tmp_path / "o" / "report.md").read_text().split("## System")[0]
    assert "found no coasting segment" in head


# -- 4. parameters that belong together -----------------------------------------------------------

def test_the_run_speed_is_one_parameter(fmu_dir):
    with pytest.raises(UserError, match=r"--set track.V: track.V is one of the targets of the system parameter run.V "
                                        r"\(track.V, wheelset.V, alignment.V\), which must agree; set --set run.V=30"):
        railfmu.read_ssp("track_wheelset", parameters={"track.V": 30})
    s = railfmu.read_ssp("track_wheelset", parameters={"run.V": 30})
    assert s.component("track").parameters["V"] == s.component("wheelset").parameters["V"] == 30.0
    assert next(o for o in s.observers if o.name == "alignment").settings["V"] == 30
