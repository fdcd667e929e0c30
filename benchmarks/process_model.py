"""Cost of an FMU as a UKF's process model, and how close ``ukf_fmu`` is to the Python ones.

Data: the driven 32 km run of the shipped line (TrainLongitudinal + Driver + GnssReceiver
FMUs, seed 1, 1 s steps, Jacobi), its 131 GNSS fixes (10 s). Measured:

  per sigma point   the FMI calls of one sigma point (TrainLongitudinal, dt = 10 s: 200 RK4
                    sub-steps of 0.05 s): fmi2SetFMUstate (which rebuilds the model data: the
                    line profile is read again), fmi2SetReal of the five state inputs,
                    fmi2DoStep, fmi2GetReal of s and v; called through ctypes as the process
                    model calls them
  per filter step   ``FmuProcessModel(X, u, t, dt)`` on 11 sigma points (snapshot + 11
                    points), beside PaperUKF's Python processes "discrete" (eq. 4) and "ode"
                    (the same RK4, numpy over the 11 points)
  per GNSS step     the whole filter (predict + update) over the run: ukf_fmu (with the
                    paper's effort and with effort="process"), PaperUKF with "ode" and with
                    "discrete"
  agreement         ukf_fmu against PaperUKF "ode" (max |difference| in final standard
                    deviations and relative) and against "discrete" (speed and position rms
                    against the truth, final r0-r2)

Timings are the fastest of ``--repeats`` (the least disturbed on a shared machine).

    python benchmarks/process_model.py [--repeats N] [--quick] [--fmu-dir DIR] [--out FILE]

Writes build/benchmarks/process_model.json (build/ is not tracked).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from fmpy.fmi2 import fmi2False  # noqa: E402

from railfmu.estimators.train.running_resistance import PaperUKF  # noqa: E402
from railfmu.experiments.engine.fmu_process import FmuPaperUKF, process_model  # noqa: E402
from railfmu.fmus.cosim.masters import run  # noqa: E402
from railfmu.fmus.cosim.system import Component, Connection, System  # noqa: E402
from railfmu.fmus.generate.build import build_all, default_out  # noqa: E402

DT = 10.0  # s, the GNSS period


def gnss_run(fmu_dir: Path, seed: int = 1):
    system = System(
        "train_run",
        [Component("train", fmu_dir / "TrainLongitudinal.fmu", {}),
         Component("driver", fmu_dir / "Driver.fmu", {"seed": seed}),
         Component("gnss", fmu_dir / "GnssReceiver.fmu", {"seed": seed})],
        [Connection("driver", "command", "train", "command"),
         Connection("train", "s", "driver", "s"), Connection("train", "v", "driver", "v"),
         Connection("train", "speed_limit", "driver", "speed_limit"),
         Connection("train", "s", "gnss", "s_true"), Connection("train", "v", "gnss", "v_true")],
        stop_time=3000.0, step_size=1.0,
        record=["train.s", "train.v", "gnss.valid", "gnss.position", "gnss.speed"])
    res = run(system, "jacobi", progress=False)
    c = {n: res.data[:, i] for i, n in enumerate(res.columns)}
    fix = c["gnss.valid"] > 0.5
    return (c["time"][fix], np.c_[c["gnss.position"][fix], c["gnss.speed"][fix]],
            c["train.s"][fix], c["train.v"][fix])


def best(fn, repeats: int) -> float:
    """Fastest wall time of ``repeats`` calls of ``fn`` (s)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def ukf_fmu(fmu_dir: Path, effort: str = "paper") -> FmuPaperUKF:
    train = Component("train", fmu_dir / "TrainLongitudinal.fmu", {})
    return FmuPaperUKF(DT, process=process_model(FmuPaperUKF, train, "benchmark", "ukf_fmu"), effort=effort)


def sigma_point_calls(fmu_dir: Path, X: np.ndarray, u: float, n: int, repeats: int) -> dict:
    """µs per call of each FMI function of one sigma point."""
    f = ukf_fmu(fmu_dir)
    pm = f.process
    pm(X, u, 0.0, DT)  # initialised at 0, snapshot at 0, instance at DT
    fmu, c, t_snap = pm.slave.fmu, pm._c, pm._time - DT  # noqa: SLF001 - the process model's own calls
    pm._in[:] = X[0].tolist()  # noqa: SLF001

    def loop(*calls):
        def go():
            for _ in range(n):
                for call in calls:
                    call()
        return go

    restore = lambda: fmu.fmi2SetFMUstate(c, pm._snapshot)  # noqa: E731,SLF001
    set_in = lambda: fmu.fmi2SetReal(c, pm._vr_in, 5, pm._in)  # noqa: E731,SLF001
    step = lambda: fmu.fmi2DoStep(c, t_snap, DT, fmi2False)  # noqa: E731
    get_out = lambda: fmu.fmi2GetReal(c, pm._vr_out, 2, pm._out)  # noqa: E731,SLF001
    out = {"fmi2SetFMUstate": best(loop(restore), repeats),
           "fmi2SetReal (5)": best(loop(restore, set_in), repeats),
           "fmi2DoStep (10 s)": best(loop(restore, set_in, step), repeats),
           "fmi2GetReal (2)": best(loop(restore, set_in, step, get_out), repeats)}
    # each row: the increment of adding that call to the loop
    us = {}
    prev = 0.0
    for k, v in out.items():
        us[k] = 1e6 * (v - prev) / n
        prev = v
    us["one sigma point (sum)"] = 1e6 * prev / n
    f.close()
    return us


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="2 repeats, fewer calls")
    ap.add_argument("--fmu-dir", type=Path)
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "process_model.json")
    args = ap.parse_args()
    repeats = 2 if args.quick else args.repeats
    n_calls = 200 if args.quick else 1000
    fmu_dir = args.fmu_dir or build_all(default_out()) and default_out()
    t, z, s_true, v_true = gnss_run(fmu_dir)

    # sigma points as the filter draws them at a fix in the middle of the run
    probe = PaperUKF(DT, process="discrete")
    probe.run(t[:60], z[:60])
    X = probe.points.sigma_points(probe.x, probe.P) * probe.D
    u = probe.u
    calls = sigma_point_calls(fmu_dir, X, u, n_calls, repeats)

    f = ukf_fmu(fmu_dir)
    pm = f.process
    k = [0]

    def fmu_step():
        pm(X, u, k[0] * DT, DT)
        k[0] += 1

    per_step = {"FMU (FmuProcessModel)": best(lambda: [fmu_step() for _ in range(50)], repeats) / 50}
    for name in ("discrete", "ode"):
        proc = PaperUKF(DT, process=name).process
        m = 50 if name == "discrete" else 5
        per_step[f"Python {name}"] = best(lambda: [proc(X, u, 0.0, DT) for _ in range(m)], repeats) / m
    f.close()

    # the whole filter over the run
    filters = {"ukf_fmu": ukf_fmu(fmu_dir), "ukf_fmu effort=process": ukf_fmu(fmu_dir, "process"),
               "PaperUKF ode": PaperUKF(DT, process="ode"), "PaperUKF discrete": PaperUKF(DT)}
    est, per_gnss = {}, {}
    for name, flt in filters.items():
        r = 1 if name == "PaperUKF ode" else repeats
        per_gnss[name] = best(lambda: est.__setitem__(name, flt.run(t, z)), r) / (len(t) - 1)
    E, O, D, P = est["ukf_fmu"], est["PaperUKF ode"], est["PaperUKF discrete"], est["ukf_fmu effort=process"]
    sigma = np.sqrt(np.diag(filters["PaperUKF ode"].covariance))
    names = ("s", "v", "r0", "r1", "r2")
    diff = np.abs(E - O)[:, :5]

    def rms(x):
        return float(np.sqrt(np.mean(x * x)))

    agreement = {
        "ukf_fmu - ode, max |diff| / final sigma": dict(zip(names, (diff.max(axis=0) / sigma).tolist())),
        "ukf_fmu - ode, max relative": dict(zip(names, (diff / np.maximum(np.abs(O[:, :5]), 1e-300)).max(axis=0).tolist())),
        "ukf_fmu - ode, covariance max relative": float(
            np.max(np.abs(filters["ukf_fmu"].covariance - filters["PaperUKF ode"].covariance)
                   / np.abs(filters["PaperUKF ode"].covariance))),
        "speed rms km/h": {"ukf_fmu": 3.6 * rms(E[:, 1] - v_true), "ode": 3.6 * rms(O[:, 1] - v_true),
                           "discrete": 3.6 * rms(D[:, 1] - v_true),
                           "ukf_fmu effort=process": 3.6 * rms(P[:, 1] - v_true)},
        "position rms m": {"ukf_fmu": rms(E[:, 0] - s_true), "ode": rms(O[:, 0] - s_true),
                           "discrete": rms(D[:, 0] - s_true), "ukf_fmu effort=process": rms(P[:, 0] - s_true)},
        "final r0, r1, r2": {"ukf_fmu": E[-1, 2:5].tolist(), "discrete": D[-1, 2:5].tolist(),
                             "ukf_fmu effort=process": P[-1, 2:5].tolist()},
    }
    filters["ukf_fmu"].close()
    filters["ukf_fmu effort=process"].close()

    print(f"TrainLongitudinal as the process model, dt = {DT:g} s (200 RK4 sub-steps), 11 sigma points")
    print("\nµs per call, one sigma point:")
    for k_, v in calls.items():
        print(f"  {k_:<24} {v:9.1f}")
    print("\nµs per filter step (11 sigma points):")
    for k_, v in per_step.items():
        print(f"  {k_:<24} {1e6 * v:9.1f}")
    print(f"\nms per GNSS step (predict + update), {len(t) - 1} steps:")
    for k_, v in per_gnss.items():
        print(f"  {k_:<24} {1e3 * v:9.3f}")
    print("\nagreement:")
    for k_, v in agreement.items():
        print(f"  {k_}: {v}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine()},
        "gnss_fixes": len(t), "us_per_call_one_sigma_point": calls,
        "us_per_filter_step": {k_: 1e6 * v for k_, v in per_step.items()},
        "ms_per_gnss_step": {k_: 1e3 * v for k_, v in per_gnss.items()}, "agreement": agreement}, indent=2))
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
