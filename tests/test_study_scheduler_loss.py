"""A study on a remote Dask scheduler that dies midway keeps the runs it received (in
out/runs, written atomically as they arrive), says in one line that the scheduler was lost and
how to resume, exits with code 2; `--resume` (here on a local cluster) completes the table
equal to an uninterrupted one. The scheduler and its worker are local processes on 127.0.0.1."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from test_study_resume import railfmu, without_clock

BIN = Path(sys.executable).parent
STUDY = ["study", "track_wheelset", "--variant", "psd", "--runs", "4", "--seed", "3", "--stop-time", "0.5"]


def _start(*args, cwd):
    return subprocess.Popen([str(BIN / "dask"), *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


def _stop(proc):
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def test_a_lost_scheduler_keeps_the_runs_received_and_resume_completes_the_table(fmu_dir, tmp_path):
    address_file = tmp_path / "scheduler.json"
    scheduler = _start("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                       "--scheduler-file", str(address_file), cwd=tmp_path)
    worker = None
    try:
        deadline = time.monotonic() + 60
        while not address_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.05)
        address = json.loads(address_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker = _start("worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                        "--no-dashboard", cwd=tmp_path)

        whole = tmp_path / "whole"  # the reference, on the same scheduler before it dies
        res = railfmu(*STUDY, "--scheduler", address, "--out", str(whole), timeout=120)
        assert res.returncode == 0, res.stderr
        expected = json.loads((whole / "table.json").read_text())

        lost = tmp_path / "lost"
        runs = lost / "runs" / "psd"
        study = subprocess.Popen([sys.executable, "-m", "railfmu.experiments.engine.cli", *STUDY,
                                  "--scheduler", address, "--out", str(lost)],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and study.poll() is None:
            if runs.is_dir() and len(list(runs.glob("*.json"))) >= 1:
                break
            time.sleep(0.01)
        _stop(scheduler)
        t_kill = time.monotonic()
        _, err = study.communicate(timeout=60)
        assert time.monotonic() - t_kill < 30  # no hang on the lost connection
    finally:
        _stop(scheduler)
        if worker is not None:
            _stop(worker)

    done = sorted(runs.glob("*.json"))
    assert 1 <= len(done) < 4, f"the study finished before its scheduler was killed: {err}"
    assert study.returncode == 2, err
    line = err.strip().splitlines()[-1]
    assert "Traceback" not in err and " - distributed." not in err and err.count("railfmu: error:") == 1, err
    assert line.startswith(f"railfmu: error: --scheduler {address}: lost the scheduler after {len(done)} of 4 runs"), err
    assert str(lost / "runs") in line and "--resume" in line
    assert not (lost / "table.json").exists()
    kept = {p.name: p.read_text() for p in done}
    for text in kept.values():  # whole files only
        json.loads(text)

    res = railfmu(*STUDY, "--out", str(lost), "--resume", "--workers", "1", timeout=120)
    assert res.returncode == 0, res.stderr
    assert f"{len(done)} of 4 runs already in" in res.stderr
    assert json.dumps(without_clock(json.loads((lost / "table.json").read_text()))) == \
        json.dumps(without_clock(expected))  # bit for bit, the wall-clock keys aside
    assert all((runs / name).read_text() == text for name, text in kept.items())  # not run again
