"""The trolley survey end to end: a 600 m, 200 Hz run simulated and processed by the INS.

Split (each the fastest of --repeat):

  simulation   Trolley -> ImuErrors stepped by the container master (the native fast path),
               700 s at 5 ms = 140,000 steps, the recorded signals in memory (no observer,
               no CSV); the system is read and its FMUs loaded before timing
  INS          ``StrapdownINS.step_block`` on blocks of 1000 samples (as the observer bank feeds
               the experiment's online INS), and ``StrapdownINS.run`` (one ``Observer.step``
               per sample, the same numbers bit for bit), on the measured increments, from the
               trolley's state at t = 0
  python-ins   ``pyins.strapdown`` (numba, compiled before timing) on the same increments

and, for reference, what ``railfmu run trolley_survey --master container`` adds around them
(the online observer bank, signals.csv / estimates.csv / imu.csv / truth.csv, plots):
its ``timing_s`` from metrics.json with ``--full``. The INS's position and attitude error
against the trolley's truth is printed beside each INS.

    python benchmarks/trolley_survey.py [--variant ideal_imu] [--step-size 0.005] [--repeat 2]
                                        [--full] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from railfmu.estimators.inertial.ins_observer import StrapdownINS  # noqa: E402
from railfmu.experiments.trolley_survey import INCREMENTS, NAV, navigation_errors  # noqa: E402

BAR_S = 10.0  # the goal: simulated and processed by the INS in <= 10 s wall


def simulate(variant: str, step: float | None):
    """One container run of the survey's FMUs: (seconds, columns -> arrays)."""
    from railfmu.experiments.engine.runner import find_experiment, load_system
    from railfmu.fmus.cosim.masters import run

    system = load_system(find_experiment("trolley_survey"), variant, step_size=step)
    system.observers = []  # the INS is timed on its own below
    t0 = time.perf_counter()
    result = run(system, master="container", progress=False)
    seconds = time.perf_counter() - t0
    return seconds, {c: result.data[:, j] for j, c in enumerate(result.columns)}, system.step_size


def errors(nav: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    e = navigation_errors(nav, truth)
    return (float(np.linalg.norm(e["position"], axis=1).max()),
            float(np.linalg.norm(e["attitude"], axis=1).max()))


def best(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variant", default="ideal_imu")
    ap.add_argument("--step-size", type=float, default=None, help="s (default the SSD's 5 ms)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--full", action="store_true", help="also time `railfmu run` with its files")
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "trolley_survey.json")
    args = ap.parse_args(argv)
    from railfmu.fmus.generate.build import build_all, default_out
    build_all(default_out())

    sim_s, sig, dt = min((simulate(args.variant, args.step_size) for _ in range(args.repeat)), key=lambda r: r[0])
    t = sig["time"]
    n = t.size - 1
    inc = np.column_stack([sig[f"imu.{k}"] for k in INCREMENTS])
    truth = np.column_stack([sig[f"trolley.{k}"] for k in NAV])
    start = dict(zip(NAV, map(float, truth[0])))

    def blocks():  # as the observer bank feeds the online INS: one step_block per 1000 rows
        ins, Z, out = StrapdownINS(dt, **start), np.empty((t.size, 0)), np.empty((t.size, 9))
        ins.prepare()
        ins.reset(float(t[0]))
        for i in range(0, t.size, 1000):
            ins.step_block(t[i:i + 1000], Z[i:i + 1000], inc[i:i + 1000], out=out[i:i + 1000])
        return out

    ins_s, nav = best(blocks, args.repeat)
    rows_s, nav_rows = best(lambda: StrapdownINS(dt, **start).run(t, np.empty((t.size, 0)), inc), args.repeat)
    assert np.array_equal(nav, nav_rows)  # the block path is the row path, bit for bit
    rows = {"simulation": {"seconds": sim_s, "us_per_step": sim_s / n * 1e6},
            "INS (step_block, as online)": {"seconds": ins_s, "us_per_step": ins_s / n * 1e6,
                                            **dict(zip(("position_m", "attitude_rad"), errors(nav, truth)))},
            "INS (step, row by row)": {"seconds": rows_s, "us_per_step": rows_s / n * 1e6,
                                       **dict(zip(("position_m", "attitude_rad"), errors(nav_rows, truth)))}}
    try:
        import pandas as pd
        from pyins import strapdown
    except ImportError:
        strapdown = None
    if strapdown is not None:
        deg = 180.0 / math.pi
        imu = pd.DataFrame(inc, index=t, columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y",
                                                          "accel_z"])
        pva = pd.Series({"lat": truth[0, 0] * deg, "lon": truth[0, 1] * deg, "alt": truth[0, 2], "VN": truth[0, 3],
                         "VE": truth[0, 4], "VD": truth[0, 5], "roll": truth[0, 6] * deg,
                         "pitch": truth[0, 7] * deg, "heading": truth[0, 8] * deg})

        def theirs():
            return strapdown.Integrator(pva).integrate(strapdown.compute_increments_from_imu(imu, "increment"))

        strapdown.Integrator(pva).integrate(strapdown.compute_increments_from_imu(imu.iloc[:10], "increment"))
        py_s, traj = best(theirs, args.repeat)
        out = traj.to_numpy().copy()
        out[:, [0, 1, 6, 7, 8]] /= deg
        rows["python-ins (numba)"] = {"seconds": py_s, "us_per_step": py_s / n * 1e6,
                                      **dict(zip(("position_m", "attitude_rad"), errors(out, truth)))}
    if args.full:
        from railfmu.experiments.engine.runner import run_experiment
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            m = run_experiment("trolley_survey", args.variant, out=Path(tmp) / "run", master="container",
                               step_size=args.step_size, progress=False, log=io.StringIO())
            obs = m["observers"]
            rows["railfmu run (files, plots)"] = {"seconds": time.perf_counter() - t0, **m["timing_s"],
                                                  "ins_observer_s": obs["ins"]["wall_time_s"],
                                                  "smoother_observer_s": obs.get("smoother", {}).get("wall_time_s")}
    total = sim_s + ins_s
    print(f"trolley_survey {args.variant}: {n} steps ({t[-1]:g} s at {dt:g} s); fastest of {args.repeat}")
    print(f"{'':28s} {'s':>7s} {'us/step':>8s} {'pos err m':>10s} {'att err rad':>12s}")
    for name, r in rows.items():
        print(f"{name:28s} {r['seconds']:7.2f} {r.get('us_per_step', float('nan')):8.1f} "
              f"{r.get('position_m', float('nan')):10.2e} {r.get('attitude_rad', float('nan')):12.2e}")
    print(f"simulation + INS: {total:.2f} s (bar {BAR_S:g} s: {'met' if total <= BAR_S else 'MISSED'})")
    full = rows.get("railfmu run (files, plots)")
    if full:
        rest = full["seconds"] - full["setup"] - full["stepping"] - full["study_metrics"]
        print(f"railfmu run: stepping {full['stepping']:.2f} s (online INS {full['ins_observer_s']:.2f} s, "
              f"offline smoother {full['smoother_observer_s'] or 0.0:.2f} s), metrics {full['study_metrics']:.2f} s, "
              f"files and plots {rest:.2f} s")
    if "python-ins (numba)" in rows:
        print(f"INS (blocks) / python-ins: {ins_s / rows['python-ins (numba)']['seconds']:.2f} (goal <= 1); "
              f"rows / blocks {rows_s / ins_s:.1f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": platform.platform(), "python": platform.python_version(),
                                    "variant": args.variant, "steps": n, "step_size_s": dt,
                                    "simulation_plus_ins_s": total, "results": rows}, indent=2))
    print(f"-> {args.out}")
    return 0 if total <= BAR_S else 1


if __name__ == "__main__":
    sys.exit(main())
