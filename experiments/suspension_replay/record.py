"""Write the replay files of ``suspension_replay`` from a finished ``suspension_fault`` run:
``coach.csv`` (its noisy sensors ``sensors.y_1..7`` under the channel names, and the odometer's
``distance_m``, ``speed_m_s`` from the track position) and
``geometry.csv`` (the rails under bogie 1 and 2 by position as a recording car delivers them:
bogie 2's rows for the 19 m behind the start, then bogie 1's). Shipped: ``suspension_fault
--variant step_fault --seed 1``.

    python -m railfmu.experiments.suspension_replay.record [--from RUN] [--to DIR] [--digits 10]
"""

from __future__ import annotations

import argparse
import io
import tempfile
from pathlib import Path

import numpy as np

RESOURCES = Path(__file__).resolve().parent / "resources"
CHANNELS = ("ddz_c", "dtheta_c", "dphi_c", "ddz_b1", "dphi_b1", "ddz_b2", "dphi_b2")
BOGIE_SPACING = 19.0  # m, the suspension_fault track's axle_position_2


def prepare(run: Path, dst: Path, digits: int | None = None) -> None:
    """coach.csv and geometry.csv from ``run`` (a suspension_fault output folder) into ``dst``."""
    import pandas as pd

    dst.mkdir(parents=True, exist_ok=True)
    s = pd.read_csv(run / "signals.csv")
    fmt = None if digits is None else f"%.{digits}g"
    pos = s["track.position"].to_numpy()
    # the odometer (variant odometer): distance since the first row, speed as its central difference
    # (exact for a constant speed; at 10 ms rows within 1e-5 m/s of a speed that changes by 5 m/s in 5 s)
    odometer = {"distance_m": pos - pos[0], "speed_m_s": np.gradient(pos, s["time"].to_numpy(), edge_order=2)}
    coach = pd.DataFrame({"time_s": s["time"], **{c: s[f"sensors.y_{k}"] for k, c in enumerate(CHANNELS, 1)},
                          **odometer})
    coach.to_csv(dst / "coach.csv", index=False, float_format=fmt)
    behind = pos - BOGIE_SPACING < pos[0]
    geo = np.concatenate([
        np.column_stack([pos[behind] - BOGIE_SPACING, s["track.vertical_left_2"][behind], s["track.vertical_right_2"][behind]]),
        np.column_stack([pos, s["track.vertical_left_1"], s["track.vertical_right_1"]])])
    pd.DataFrame(geo, columns=["position_m", "vertical_left_m", "vertical_right_m"]).to_csv(
        dst / "geometry.csv", index=False, float_format=fmt)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="run", type=Path, default=None)
    ap.add_argument("--to", type=Path, default=RESOURCES)
    ap.add_argument("--digits", type=int, default=10)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run
        if run is None:
            from railfmu.experiments.engine.runner import run_experiment
            run = Path(tmp) / "run"
            run_experiment("suspension_fault", "step_fault", out=run, seed=1, progress=False, log=io.StringIO())
        prepare(run, args.to, args.digits)
    for name in ("coach.csv", "geometry.csv"):
        print(f"{args.to / name}: {(args.to / name).stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
