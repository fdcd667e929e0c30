"""Write ``start.csv`` for ``trolley_survey_replay`` from an imu.csv: roll and pitch levelled
over the record's initial rest (the detector's first run of rest), position and heading given.

    python -m railfmu.experiments.trolley_survey_replay.start IMU_CSV --lat DEG --lon DEG
        --height M --heading DEG [--out start.csv]

Levelling (body forward-right-down, at rest ``f = (g sin(pitch), -g sin(roll) cos(pitch),
-g cos(roll) cos(pitch))``): ``roll = atan2(-f_y, -f_z)``, ``pitch = atan2(f_x, |f_yz|)`` of
the mean specific force; its error is the accelerometer bias over g (50 ug: 0.003 deg).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

COLUMNS = ("time_s", "lat_deg", "lon_deg", "height_m", "roll_deg", "pitch_deg", "heading_deg")


def level(increments: np.ndarray, dt: float) -> tuple[float, float]:
    """(roll, pitch) in rad from (n, 6) increments (rad, m/s) over their initial rest (the
    first run of :func:`~railfmu.estimators.inertial.zupt_detector.detect_stationary`; the
    first 50 samples when it finds none at the start)."""
    from railfmu.estimators.inertial.zupt_detector import _runs, detect_stationary

    inc = np.asarray(increments, dtype=float)
    runs = _runs(detect_stationary(inc, dt))
    a, b = (runs[0] if len(runs) and runs[0][0] < 100 else (0, min(50, len(inc))))
    a = max(a, 1)  # the first row may be the initial time's zeros
    f = inc[a:b, 3:].mean(axis=0) / dt
    return math.atan2(-f[1], -f[2]), math.atan2(f[0], math.hypot(f[1], f[2]))


def write_start(path: Path, lat_deg: float, lon_deg: float, height_m: float, roll: float, pitch: float,
                heading_deg: float) -> None:
    with open(path, "w") as f:
        f.write(",".join(COLUMNS) + "\n")
        f.write(",".join(repr(float(x)) for x in (0.0, lat_deg, lon_deg, height_m, math.degrees(roll),
                                                  math.degrees(pitch), heading_deg)) + "\n")


def main(argv=None) -> int:
    import pandas as pd

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("imu", type=Path)
    for k in ("lat", "lon", "height", "heading"):
        ap.add_argument(f"--{k}", type=float, required=True)
    ap.add_argument("--out", type=Path, default=Path("start.csv"))
    args = ap.parse_args(argv)
    df = pd.read_csv(args.imu)
    t = df["time_s"].to_numpy()
    roll, pitch = level(df[["dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z"]].to_numpy(),
                        float(np.median(np.diff(t))))
    write_start(args.out, args.lat, args.lon, args.height, roll, pitch, args.heading)
    print(f"{args.out}: roll {math.degrees(roll):.5f} deg, pitch {math.degrees(pitch):.5f} deg")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
