"""Compact records (experiments/engine/records.py): a run's signals and estimates as Parquet
and MATLAB .mat read back bit for bit through the API, and a killed run's spool keeps its
complete rows."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import railfmu
from railfmu.experiments.engine.runner import execute


@pytest.mark.parametrize("fmt", ["parquet", "mat"])
def test_binary_records_round_trip_bit_for_bit(fmu_dir, tmp_path, fmt):
    # streamed as the run goes (no plots: execute is railfmu.run before Run.save)
    r = execute("lateral_alignment", seed=1, stop_time=1.0, out=tmp_path, record_format=fmt, progress=False, log=None)
    signals = railfmu.read_signals(tmp_path / f"signals.{fmt}")
    assert signals.keys() == r.signals.keys()
    for k, v in r.signals.items():
        assert np.array_equal(signals[k], v), k
    for name, prefix in (("estimates", "alignment"), ("estimates_smoother", "smoother")):
        back = railfmu.read_signals(tmp_path / f"{name}.{fmt}")
        for k, v in r.estimates[prefix].items():
            assert np.array_equal(back[k if k == "time" else f"{prefix}.{k}"], v), (name, k)
    assert not list(tmp_path.glob("*.spool")) and not (tmp_path / "signals.csv").exists()
    # written from memory (Run.save's writer) in the other binary format: equal too
    other = "mat" if fmt == "parquet" else "parquet"
    r._write_csvs(tmp_path, other)
    again = railfmu.read_signals(tmp_path / f"signals.{other}")
    assert all(np.array_equal(again[k], v) for k, v in r.signals.items())


@pytest.mark.parametrize("how", [signal.SIGKILL, pytest.param(signal.SIGINT, marks=pytest.mark.slow)])
def test_killed_binary_run_keeps_complete_rows(fmu_dir, tmp_path, how):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "track_wheelset",
                             "--seed", "1", "--stop-time", "2000", "--format", "parquet",
                             "--out", str(out), "-q"], stderr=subprocess.PIPE, text=True)
    spool = out / "signals.parquet.spool"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (not spool.exists() or spool.stat().st_size < 200_000):
        time.sleep(0.2)
    assert spool.exists(), proc.stderr.read() if proc.poll() is not None else "no spool"
    proc.send_signal(how)
    proc.wait(60)
    # SIGKILL: the spool stays with whole rows; SIGINT: the run closes it into the Parquet file
    left = spool if how == signal.SIGKILL else out / "signals.parquet"
    assert left.exists()
    rec = railfmu.read_signals(left)
    t = rec["time"]
    assert t.size > 100 and np.all(np.isfinite(np.column_stack(list(rec.values()))))
    assert np.allclose(np.diff(t), np.diff(t)[0], rtol=1e-9, atol=1e-12)  # no row lost or cut in between


def test_replay_plays_parquet_and_mat_tables_bit_for_bit(fmu_dir, tmp_path):
    """trolley_imu_replay on its example imu.csv/truth.csv, and on the same tables as Parquet and
    .mat: the same signals and estimates (the tables reach the SignalTable FMU as CSV)."""
    from railfmu.experiments.engine.records import read_table, write_table
    from railfmu.experiments.engine.studies import HERE

    resources = HERE / "trolley_imu_replay" / "resources"
    for name, fmt in (("imu", "parquet"), ("truth", "mat")):
        write_table(tmp_path / f"{name}.{fmt}", *read_table(resources / f"{name}.csv"))
    ref = railfmu.run("trolley_imu_replay")
    binary = railfmu.run("trolley_imu_replay", parameters={"imu.file": str(tmp_path / "imu.parquet"),
                                                           "truth.file": str(tmp_path / "truth.mat")})
    assert any("imu.parquet is parquet" in n for n in binary.metrics["notes"])
    for k, v in ref.signals.items():
        assert np.array_equal(binary.signals[k], v), k
    for k, v in ref.estimates["ins"].items():
        assert np.array_equal(binary.estimates["ins"][k], v), k
