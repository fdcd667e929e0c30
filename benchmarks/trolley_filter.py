"""The ZUPT-aided INS's filter + smoother cost per IMU sample, beside python-ins's feedback filter
on the same data.

Data: ``railfmu run trolley_survey --variant navigation_grade`` to 80 s (10 s at rest, the
60 m run at 1 m/s, the stop at 60 m: 16,000 samples at 5 ms), its ``imu.csv`` and ``truth.csv``.

Timed (fastest of --repeat; the initial state from the truth's first row, the navigation
grade's noise and biases in both filters):

  ours, paper12 / full15   ``AidedInsSmoother.run``: the strapdown at the IMU rate, the
                           error-state filter at 0.05 s epochs with a ZUPT (sigma 1e-4 m/s) at
                           every epoch the ``stopped`` flag is set, the RTS smoother over the
                           run; split by the observer's own timers into strapdown, filter and
                           smoother
  python-ins               ``pyins.filters.run_feedback_filter``: its strapdown and feedback
                           EKF (9 navigation states + gyro and accelerometer biases: 15),
                           covariance steps of 0.05 s, the same ZUPTs as ``NedVelocity``
                           measurements of (0, 0, 0) with sd 1e-4 m/s; a filter only (python-ins
                           has no smoother); compiled (numba) before timing, timed once (its
                           loop over epochs grows a pandas trajectory: minutes)

and the largest horizontal and vertical position error of each against the truth.

    python benchmarks/trolley_filter.py [--stop-time 80] [--repeat 3] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from railfmu.estimators.inertial.aided_ins import AidedInsSmoother  # noqa: E402
from railfmu.models import earth  # noqa: E402
from railfmu.models.inertial.imu_errors import (
    GM_SIGMA_PER_B,
    GRADES,
    GYRO_BIAS_SI,
    GYRO_NOISE_SI,
    ACCEL_SI,
)  # noqa: E402

DT = 0.005
ZUPT_SIGMA = 1e-4     # m/s
EPOCH = 0.05          # s
DEG = math.pi / 180
AXES = ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")


def survey(stop_time: float, out: Path) -> tuple[np.ndarray, np.ndarray, pd.DataFrame]:
    """(t, increments (n, 6), truth) of the navigation-grade survey run to ``stop_time``."""
    from railfmu.experiments.engine.runner import run_experiment
    run_experiment("trolley_survey", "navigation_grade", out=out, stop_time=stop_time, step_size=DT,
                   master="container", progress=False, log=io.StringIO())
    imu = pd.read_csv(out / "imu.csv")
    return imu.time_s.to_numpy(), imu[list(AXES)].to_numpy(), pd.read_csv(out / "truth.csv")


def position_errors(lat, lon, h, truth: pd.DataFrame) -> tuple[float, float]:
    """Largest horizontal and vertical position error (m) against the truth's rows."""
    tl, tn, th = (truth.lat_deg.to_numpy() * DEG, truth.lon_deg.to_numpy() * DEG, truth.height_m.to_numpy())
    rn, re = earth.principal_radii(tl, th)
    north, east = (lat - tl) * rn, (lon - tn) * re * np.cos(tl)
    return float(np.hypot(north, east).max()), float(np.abs(h - th).max())


def ours(t, inc, truth, error_model: str) -> tuple[dict, np.ndarray]:
    r = truth.iloc[0]
    obs = AidedInsSmoother(DT, latitude=r.lat_deg * DEG, longitude=r.lon_deg * DEG, height=r.height_m,
                           roll=r.roll_deg * DEG, pitch=r.pitch_deg * DEG, heading=r.heading_deg * DEG,
                           error_model=error_model, filter_period=EPOCH, zupt_sigma=ZUPT_SIGMA)
    Z = np.full((t.size, 5), np.nan)
    Z[:, 0] = truth.stopped.to_numpy()
    t0 = time.perf_counter()
    est = obs.run(t, Z, inc)
    total = time.perf_counter() - t0
    return {"seconds": total, "strapdown_s": obs.strapdown_seconds, "filter_s": obs.filter_seconds,
            "smoother_s": obs.smoother_seconds}, est


def pyins_inputs(t, inc, truth):
    """python-ins's initial PVA, increments, sensor models and ZUPT measurements."""
    from pyins import inertial_sensor, measurements, strapdown
    r = truth.iloc[0]
    pva = pd.Series({"lat": r.lat_deg, "lon": r.lon_deg, "alt": r.height_m, "VN": r.vn, "VE": r.ve, "VD": r.vd,
                     "roll": r.roll_deg, "pitch": r.pitch_deg, "heading": r.heading_deg}, name=t[0])
    imu = pd.DataFrame({f"gyro_{a}": inc[:, i] for i, a in enumerate("xyz")}
                       | {f"accel_{a}": inc[:, 3 + i] for i, a in enumerate("xyz")}, index=t)
    increments = strapdown.compute_increments_from_imu(imu, "increment")
    g = GRADES["navigation_grade"]
    gyro = inertial_sensor.EstimationModel(
        bias_sd=GM_SIGMA_PER_B * g["gyro_bias_instability_deg_h"] * GYRO_BIAS_SI,
        noise=g["gyro_arw_deg_sqrt_h"] * GYRO_NOISE_SI)
    accel = inertial_sensor.EstimationModel(
        bias_sd=GM_SIGMA_PER_B * g["accel_bias_instability_ug"] * ACCEL_SI,
        noise=g["accel_noise_ug_sqrt_hz"] * ACCEL_SI)
    epochs = np.round(t / EPOCH, 6) == np.round(t / EPOCH)   # the same epochs as ours
    at = t[epochs & (truth.stopped.to_numpy() == 1)]
    at = at[at > t[0]]
    zupt = measurements.NedVelocity(pd.DataFrame(0.0, index=at, columns=["VN", "VE", "VD"]), ZUPT_SIGMA)
    return pva, increments, gyro, accel, [zupt]


def theirs(pva, increments, gyro, accel, meas):
    from pyins import filters
    t0 = time.perf_counter()
    res = filters.run_feedback_filter(pva, 0.1, 1e-4, 0.006, 0.06, increments, gyro, accel, meas, time_step=EPOCH)
    return time.perf_counter() - t0, res


def best(fn, repeat: int):
    runs = [fn() for _ in range(repeat)]
    return min(runs, key=lambda r: r[0]["seconds"] if isinstance(r[0], dict) else r[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop-time", type=float, default=80.0, help="simulated seconds (default 80: the 60 m run)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "trolley_filter.json")
    args = ap.parse_args(argv)
    t, inc, truth = survey(args.stop_time, ROOT / "build" / "benchmarks" / "trolley_filter_run")
    n = t.size - 1   # intervals integrated (row 0: the interval before the start)
    rows = {}
    ours(t[:400], inc[:400], truth.iloc[:400], "paper12")   # numba's cache, imports
    for model in ("paper12", "full15"):
        timing, est = best(lambda: ours(t, inc, truth, model), args.repeat)
        horiz, vert = position_errors(est[:, 0], est[:, 1], est[:, 2], truth)
        rows[f"ours, {model}"] = {**timing, "us_per_sample": timing["seconds"] / n * 1e6,
                                  "position_error_horizontal_m": horiz, "position_error_vertical_m": vert}
    inputs = pyins_inputs(t, inc, truth)
    theirs(inputs[0], inputs[1].iloc[:200], *inputs[2:])    # numba compiles here
    seconds, res = theirs(*inputs)
    tr = res.trajectory.reindex(t[1:], method="nearest")
    horiz, vert = position_errors(tr.lat.to_numpy() * DEG, tr.lon.to_numpy() * DEG, tr.alt.to_numpy(),
                                  truth.iloc[1:])
    rows["python-ins"] = {"seconds": seconds, "us_per_sample": seconds / n * 1e6,
                          "position_error_horizontal_m": horiz, "position_error_vertical_m": vert}
    print(f"ZUPT-aided INS, {n} IMU samples ({args.stop_time:g} s at {1 / DT:g} Hz, navigation grade, "
          f"{int(truth.stopped.sum())} samples stopped); ours fastest of {args.repeat}, python-ins once")
    print(f"{'':18s} {'s':>7s} {'us/sample':>10s} {'strapdown':>10s} {'filter':>8s} {'smoother':>9s} "
          f"{'horiz err m':>12s} {'vert err m':>11s}")
    for name, r in rows.items():
        parts = (f"{r['strapdown_s']:10.3f} {r['filter_s']:8.3f} {r['smoother_s']:9.3f}" if "filter_s" in r
                 else f"{'':10s} {'':8s} {'':9s}")
        print(f"{name:18s} {r['seconds']:7.3f} {r['us_per_sample']:10.1f} {parts} "
              f"{r['position_error_horizontal_m']:12.2e} {r['position_error_vertical_m']:11.2e}")
    for model in ("paper12", "full15"):
        print(f"python-ins / ours, {model}: {rows['python-ins']['seconds'] / rows[f'ours, {model}']['seconds']:.1f}x")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": platform.platform(), "python": platform.python_version(),
                                    "samples": n, "dt": DT, "stop_time_s": args.stop_time, "results": rows},
                                   indent=2))
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
