"""The strapdown INS's cost per IMU sample, beside python-ins's integrator on the same data.

Data: python-ins's trajectory simulator (``pyins.sim.generate_imu``, increments from a spline
trajectory), the stop-and-go run of ``tests/test_strapdown.py``: 200 Hz, speed
sin^2(pi t / 60) m/s (a stop every 60 s), heading N45E +- 17 deg, grade +- 1 %, roll +- 0.02 rad,
700 s by default (140,000 samples, the length of the trolley survey run).

Timed (fastest of --repeat, on a fresh INS each time):

  ours, mechanisation   ``Strapdown.integrate``: the compiled (numba) kernel writes an (n, 10) array,
                        attitude to roll/pitch/heading vectorised at the end
  ours, observer blocks ``StrapdownINS.step_block`` on blocks of 1000 samples, as the observer bank
                        feeds it in a run (one kernel call per block)
  ours, observer rows   ``StrapdownINS.run``: one ``Observer.step`` per sample
  python-ins            ``compute_increments_from_imu`` + ``Integrator.integrate`` (numba, compiled
                        before timing), to a pandas trajectory

and the largest position, velocity and attitude error of each against the simulator's truth.
Then the JIT warm-up: a fresh process imports :mod:`railfmu.estimators.inertial.strapdown` and integrates 10
samples, once with an empty numba cache (compiling) and once with the cache that run left
(``NUMBA_CACHE_DIR`` pointed at a temporary directory, so the repository's own cache is untouched).

    python benchmarks/strapdown.py [--duration 700] [--dt 0.005] [--repeat 3] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from railfmu.estimators.inertial.attitude import dcm_from_rph  # noqa: E402
from railfmu.estimators.inertial.ins_observer import StrapdownINS  # noqa: E402
from railfmu.estimators.inertial.strapdown import Strapdown  # noqa: E402
from railfmu.models import earth  # noqa: E402

DEG = math.pi / 180
BLOCK = 1000  # rows per step_block: the container's block (the Python masters hand over 500)


def trajectory(duration: float, dt: float):
    from pyins import sim
    t = np.arange(0, duration + dt / 2, dt)
    speed = np.sin(np.pi * t / 60) ** 2
    psi = 45 * DEG + 0.3 * np.sin(2 * np.pi * t / 400)
    theta = 0.01 * np.sin(2 * np.pi * t / 300)
    roll = 0.02 * np.sin(2 * np.pi * t / 250)
    v = speed[:, None] * np.stack([np.cos(psi) * np.cos(theta), np.sin(psi) * np.cos(theta), -np.sin(theta)], 1)
    traj, imu = sim.generate_imu(t, [30.5, 114.3, 25.0], np.rad2deg(np.stack([roll, theta, psi], 1)), v,
                                 sensor_type="increment")
    return t, traj, imu


def errors(nav: np.ndarray, truth: np.ndarray) -> dict:
    """Max position (m), velocity (m/s) and attitude (rad) error of NAV rows against the truth."""
    from scipy.spatial.transform import Rotation
    rn, re = earth.principal_radii(truth[:, 0], truth[:, 2])
    pos = np.stack([(nav[:, 0] - truth[:, 0]) * rn, (nav[:, 1] - truth[:, 1]) * re * np.cos(truth[:, 0]),
                    nav[:, 2] - truth[:, 2]], 1)
    att = Rotation.from_matrix(dcm_from_rph(*nav[:, 6:9].T) @ np.swapaxes(dcm_from_rph(*truth[:, 6:9].T), 1, 2))
    return {"position_m": float(np.linalg.norm(pos, axis=1).max()),
            "velocity_m_s": float(np.abs(nav[:, 3:6] - truth[:, 3:6]).max()),
            "attitude_rad": float(np.linalg.norm(att.as_rotvec(), axis=1).max())}


def best(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
from railfmu.estimators.inertial.strapdown import Strapdown
t1 = time.perf_counter()
Strapdown.from_rph(0.5, 2.0, 30.0, (0, 0, 0), (0, 0, 0), 0.005).integrate(np.zeros((10, 6)))
print(t1 - t0, time.perf_counter() - t1)
"""


def first_call() -> dict:
    """Seconds a fresh process spends importing the INS (numba included) and on its first
    ``integrate``, without and with numba's on-disk cache."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
        for name in ("uncached", "cached"):
            res = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, cwd=ROOT, check=True,
                                 capture_output=True, text=True)
            imp, call = map(float, res.stdout.split())
            out[name] = {"import_s": imp, "first_integrate_s": call}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=700.0, help="simulated seconds (default 700)")
    ap.add_argument("--dt", type=float, default=0.005, help="IMU interval, s (default 0.005)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "strapdown.json")
    args = ap.parse_args(argv)
    from pyins import strapdown as pyins_strapdown

    t0 = time.perf_counter()
    t, traj, imu = trajectory(args.duration, args.dt)
    sim_s = time.perf_counter() - t0
    truth = traj.to_numpy().copy()
    truth[:, [0, 1, 6, 7, 8]] *= DEG
    inc = imu.to_numpy()
    n = inc.shape[0] - 1

    def ours():
        ins = Strapdown.from_rph(*truth[0, :3], truth[0, 3:6], truth[0, 6:9], args.dt)
        ins.prime(inc[0, :3], inc[0, 3:])
        return ins.integrate(inc[1:])

    settings = dict(zip(("latitude", "longitude", "height", "vn", "ve", "vd", "roll", "pitch", "heading"),
                        map(float, truth[0])))

    def observer():
        return StrapdownINS(args.dt, **settings).run(t, np.empty((t.size, 0)), inc)[1:]

    def observer_blocks():  # as the observer bank feeds it: blocks of BLOCK rows, one step_block each
        ins, Z = StrapdownINS(args.dt, **settings), np.empty((t.size, 0))
        ins.prepare()
        ins.reset(float(t[0]))
        out = np.empty((t.size, 9))
        for i in range(0, t.size, BLOCK):
            ins.step_block(t[i:i + BLOCK], Z[i:i + BLOCK], inc[i:i + BLOCK], out=out[i:i + BLOCK])
        return out[1:]

    def theirs():
        increments = pyins_strapdown.compute_increments_from_imu(imu, "increment")
        return pyins_strapdown.Integrator(traj.iloc[0]).integrate(increments)

    pyins_strapdown.Integrator(traj.iloc[0]).integrate(                       # numba compiles here
        pyins_strapdown.compute_increments_from_imu(imu.iloc[:10], "increment"))
    rows = {}
    for name, fn in (("ours, mechanisation", ours), ("ours, observer blocks", observer_blocks),
                     ("ours, observer rows", observer), ("python-ins", theirs)):
        seconds, out = best(fn, args.repeat)
        if name == "python-ins":
            out = out.to_numpy()[1:].copy()
            out[:, [0, 1, 6, 7, 8]] *= DEG
        rows[name] = {"seconds": seconds, "us_per_sample": seconds / n * 1e6, **errors(out, truth[1:])}
    print(f"strapdown INS, {n} samples ({args.duration:g} s at {1 / args.dt:g} Hz), python-ins data "
          f"(simulated in {sim_s:.1f} s); fastest of {args.repeat}")
    print(f"{'':22s} {'s':>7s} {'us/sample':>10s} {'pos err m':>10s} {'vel err m/s':>12s} {'att err rad':>12s}")
    for name, r in rows.items():
        print(f"{name:22s} {r['seconds']:7.2f} {r['us_per_sample']:10.1f} {r['position_m']:10.2e} "
              f"{r['velocity_m_s']:12.2e} {r['attitude_rad']:12.2e}")
    blk, mech, pyins = (rows[k]["seconds"] for k in ("ours, observer blocks", "ours, mechanisation", "python-ins"))
    print(f"ratio observer blocks / mechanisation {blk / mech:.2f} (goal <= 2); "
          f"observer blocks / python-ins {blk / pyins:.2f} (goal <= 1); "
          f"observer rows / observer blocks {rows['ours, observer rows']['seconds'] / blk:.1f}")
    warm = first_call()
    for name, r in warm.items():
        print(f"fresh process, {name} JIT: import {r['import_s']:.2f} s, first integrate {r['first_integrate_s']:.2f} s")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": platform.platform(), "python": platform.python_version(),
                                    "samples": n, "dt": args.dt, "duration_s": args.duration, "results": rows,
                                    "first_call": warm}, indent=2))
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
