"""A study survives kill -9: each finished run is saved atomically as it finishes
(out/runs/<variant>/<seed>.json), `--resume` runs only the missing ones, and the resumed
table equals an uninterrupted one (the wall-clock keys aside, which differ between any two
runs)."""

import json
import os
import signal
import subprocess
import sys
import time

from railfmu.experiments.engine.result import TIMING_KEYS

# per-observer wall-clock figures, besides the run's own (TIMING_KEYS)
CLOCK = set(TIMING_KEYS) | {"seconds", "process_seconds", "process_us_per_call"}
STUDY = ["study", "track_wheelset", "--variant", "psd", "--runs", "6", "--seed", "3", "--stop-time", "0.5",
         "--workers", "1"]


def railfmu(*args, **kw):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args],
                          capture_output=True, text=True, **kw)


def without_clock(x):
    if isinstance(x, dict):
        return {k: without_clock(v) for k, v in x.items()
                if k not in CLOCK and not CLOCK & set(k.split("."))}
    if isinstance(x, list):
        return [without_clock(v) for v in x]
    return x


def test_a_killed_study_resumes_to_the_uninterrupted_table(tmp_path):
    whole, killed = tmp_path / "whole", tmp_path / "killed"
    res = railfmu(*STUDY, "--out", str(whole))
    assert res.returncode == 0, res.stderr
    expected = json.loads((whole / "table.json").read_text())
    assert sorted(p.name for p in (whole / "runs" / "psd").iterdir()) == [f"{s}.json" for s in range(3, 9)]

    proc = subprocess.Popen([sys.executable, "-m", "railfmu.experiments.engine.cli", *STUDY, "--out", str(killed)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    runs = killed / "runs" / "psd"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if runs.is_dir() and len(list(runs.glob("*.json"))) >= 2:
            break
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the study and its Dask workers, as kill -9 would
    proc.wait()
    done = sorted(runs.glob("*.json"))
    assert 2 <= len(done) < 6, "the study finished before it could be killed"
    assert not (killed / "table.json").exists()
    for p in done:  # whole files only (write-then-rename)
        json.loads(p.read_text())

    res = railfmu(*STUDY, "--out", str(killed), "--resume")
    assert res.returncode == 0, res.stderr
    assert f"{len(done)} of 6 runs already in" in res.stderr
    assert f"[{len(done) + 1}/6]" in res.stderr and "[1/6]" not in res.stderr  # only the missing ones ran
    resumed = json.loads((killed / "table.json").read_text())
    assert json.dumps(without_clock(resumed)) == json.dumps(without_clock(expected))  # bit for bit
    for p in done:  # the runs kept were not run again
        assert (runs / p.name).read_text() == p.read_text()

    # nothing missing: resuming again runs nothing and writes the same table
    res = railfmu(*STUDY, "--out", str(killed), "--resume")
    assert res.returncode == 0 and "6 of 6 runs already in" in res.stderr and "[" not in res.stderr
    assert json.loads((killed / "table.json").read_text()) == resumed


def test_resume_refuses_runs_made_with_other_settings(tmp_path):
    out = tmp_path / "s"
    small = ["study", "track_wheelset", "--variant", "psd", "--runs", "2", "--stop-time", "0.2", "--out", str(out)]
    assert railfmu(*small).returncode == 0
    res = railfmu(*small, "--resume", "--set", "track.psd_scale=0.5")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "--resume" in res.stderr and "overrides" in res.stderr
    # more seeds with the same settings: only the new ones run
    res = railfmu(*small[:-4], "--runs", "3", "--stop-time", "0.2", "--out", str(out), "--resume")
    assert res.returncode == 0 and "2 of 3 runs already in" in res.stderr, res.stderr


def test_a_killed_run_leaves_whole_rows_and_no_half_metrics(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "track_wheelset",
                             "--stop-time", "600", "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    csv = out / "signals.csv"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if csv.is_file() and csv.stat().st_size > 100_000:
            break
        time.sleep(0.02)
    # The size was seen growing, i.e. during one of the once-a-second writes: kill between two
    # of them. A SIGKILL inside the write() itself can cut it at a page boundary (the kernel
    # stops copying on a fatal signal), a limit of appending to a file that no writer avoids.
    time.sleep(0.4)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    text = csv.read_text()
    assert text.endswith("\n")
    lines = text.splitlines()
    assert len(lines) > 10 and len({line.count(",") for line in lines}) == 1  # whole rows only
    assert not (out / "metrics.json").exists()  # written (atomically) only when the run ends
