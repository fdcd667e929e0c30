"""Write the replay files of ``trolley_survey_replay`` from a finished ``trolley_survey`` run:
``imu.csv`` with the odometer (``odometer_m``, from signals.csv), ``start.csv`` (the truth's
first position and heading, roll and pitch levelled from the IMU: what a surveyor knows) and
``reference.csv`` (the simulated truth's position and stopped flag, every ``--every``-th row: a
total station's stand-in). Shipped example: the first 85 s of ``trolley_survey --variant
navigation_grade --seed 1``, the reference at 10 Hz.

    python -m railfmu.experiments.trolley_survey_replay.record [--from RUN] [--to DIR]
        [--duration 85] [--every 20] [--digits 10]
"""

from __future__ import annotations

import argparse
import io
import tempfile
from pathlib import Path

import numpy as np

RESOURCES = Path(__file__).resolve().parent / "resources"
INCREMENTS = ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")


def prepare(run: Path, dst: Path, duration: float | None = None, every: int = 1, digits: int | None = None) -> None:
    """The three files from ``run`` (a trolley_survey output folder) into ``dst``."""
    import pandas as pd

    from railfmu.experiments.trolley_survey_replay.start import level, write_start

    dst.mkdir(parents=True, exist_ok=True)
    imu = pd.read_csv(run / "imu.csv")
    truth = pd.read_csv(run / "truth.csv")
    odo = pd.read_csv(run / "signals.csv", usecols=["time", "trolley.odometer"])["trolley.odometer"].to_numpy()
    keep = slice(None) if duration is None else imu.time_s.to_numpy() <= duration + 1e-9
    imu, truth, odo = imu[keep], truth[keep], odo[keep]
    imu = imu.assign(odometer_m=odo)
    fmt = None if digits is None else f"%.{digits}g"
    imu.to_csv(dst / "imu.csv", index=False, float_format=fmt)
    t = imu.time_s.to_numpy()
    roll, pitch = level(imu[list(INCREMENTS)].to_numpy(), float(np.median(np.diff(t))))
    r0 = truth.iloc[0]
    write_start(dst / "start.csv", r0.lat_deg, r0.lon_deg, r0.height_m, roll, pitch, r0.heading_deg)
    truth[["time_s", "lat_deg", "lon_deg", "height_m", "stopped"]].iloc[::every].to_csv(
        dst / "reference.csv", index=False)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="run", type=Path, default=None)
    ap.add_argument("--to", type=Path, default=RESOURCES)
    ap.add_argument("--duration", type=float, default=85.0)
    ap.add_argument("--every", type=int, default=20)
    ap.add_argument("--digits", type=int, default=10)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run
        if run is None:
            from railfmu.experiments.engine.runner import run_experiment
            run = Path(tmp) / "run"
            run_experiment("trolley_survey", "navigation_grade", out=run, seed=1, stop_time=args.duration,
                           progress=False, log=io.StringIO())
        prepare(run, args.to, args.duration, args.every, args.digits)
    for name in ("imu.csv", "start.csv", "reference.csv"):
        print(f"{args.to / name}: {(args.to / name).stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
