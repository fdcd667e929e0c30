"""Write the shipped record of ``trolley_imu_replay``: the first seconds of ``imu.csv`` and
``truth.csv`` of a ``trolley_survey`` run (ideal IMU: 10 s at rest, then the start of the
first run to the 60 m stop).

    python -m railfmu.experiments.trolley_imu_replay.record [--duration 15] [--from DIR]

``--from`` a finished run's folder (default: run ``trolley_survey`` for ``--duration`` s).
"""

from __future__ import annotations

import argparse
import io
import tempfile
from pathlib import Path

RESOURCES = Path(__file__).resolve().parent / "resources"


def head(src: Path, dst: Path, duration: float) -> int:
    """Copy the header and the rows with ``time_s <= duration`` of ``src`` (text unchanged)."""
    n = 0
    with open(src) as f, open(dst, "w") as g:
        g.write(f.readline())
        for line in f:
            if float(line.split(",", 1)[0]) > duration + 1e-9:
                break
            g.write(line)
            n += 1
    return n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--from", dest="run", type=Path, default=None)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run
        if run is None:
            from railfmu.experiments.engine.runner import run_experiment
            run = Path(tmp) / "run"
            run_experiment("trolley_survey", "ideal_imu", out=run, stop_time=args.duration, progress=False,
                           log=io.StringIO())
        for name in ("imu.csv", "truth.csv"):
            print(f"{RESOURCES / name}: {head(run / name, RESOURCES / name, args.duration)} rows")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
