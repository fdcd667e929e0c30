"""Speed of the three masters of railfmu.fmus.cosim.masters against FMPy's own SSP simulator.

The experiment experiments/track_wheelset, variant psd (ERRI B176 low-level track into the
wheelset + suspended frame, 11 recorded signals), 20 s at 1 ms, through

  jacobi        railfmu.fmus.cosim.masters.run(system, "jacobi")        (Python loop, raw ctypes calls)
  gauss-seidel  railfmu.fmus.cosim.masters.run(system, "gauss-seidel")
  container     railfmu.fmus.cosim.masters.run(system, "container")     (FMPy container FMU + C driver)
  simulate_ssp  fmpy.ssp.simulation.simulate_ssp on the same system written as a .ssp
                (railfmu.fmus.ssp.write_ssp; it ignores parameter bindings, which here equal the
                FMU defaults, so it runs the same system)

Each is timed end to end (load, initialise, run, free: what a user waits for) and on a
0.1 s run; the difference over the difference in steps is the cost of one step without
setup. Best of --repeat runs. No sinks: the masters fill their result array only.

    python benchmarks/masters.py [--stop-time 20] [--repeat 3] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import fmpy
import numpy as np
from fmpy.ssp.simulation import simulate_ssp

from railfmu.fmus.generate.build import build_all
from railfmu.fmus.cosim.masters import MASTERS, run
from railfmu.fmus.ssp import read_system, write_ssp

SHORT = 0.1  # s, the run that measures setup


def timed(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop-time", type=float, default=20.0, help="simulated time per run, s (default 20)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per case; the fastest counts (default 3)")
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "masters.json")
    args = ap.parse_args(argv)
    if not args.stop_time > SHORT or args.repeat < 1:
        ap.error(f"--stop-time must be > {SHORT} s and --repeat >= 1")

    fmu_dir = ROOT / "build" / "fmus"
    build_all(fmu_dir)  # a no-op when up to date
    system = read_system(ROOT / "experiments" / "track_wheelset", variant="psd", fmu_dirs=[fmu_dir],
                         stop_time=args.stop_time)
    short = read_system(ROOT / "experiments" / "track_wheelset", variant="psd", fmu_dirs=[fmu_dir],
                        stop_time=SHORT)
    h = system.step_size
    n_long, n_short = system.n_steps, short.n_steps

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        ssp = write_ssp(system, Path(tmp) / "track_wheelset.ssp")
        cases = {m: (lambda s, m=m: run(s, m, progress=False)) for m in MASTERS}
        cases["simulate_ssp"] = lambda s: simulate_ssp(str(ssp), start_time=s.start_time, stop_time=s.stop_time,
                                                       step_size=h)
        run(short, "container", progress=False)  # compiles the C driver once (cached)
        outputs = {}
        for name, fn in cases.items():
            outputs[name] = fn(system)
            t_long = timed(lambda fn=fn: fn(system), args.repeat)
            t_short = timed(lambda fn=fn: fn(short), args.repeat)
            results[name] = {
                "wall_s": t_long, "steps_per_s": n_long / t_long,
                "setup_s": max(t_short - (t_long - t_short) / (n_long - n_short) * n_short, 0.0),
                "us_per_step": (t_long - t_short) / (n_long - n_short) * 1e6,
            }
    same = bool(np.array_equal(outputs["container"].data, outputs["jacobi"].data))

    ref = results["simulate_ssp"]
    print(f"track_wheelset (psd), {args.stop_time:g} s at {h * 1e3:g} ms = {n_long} steps, "
          f"{len(system.record)} recorded signals; best of {args.repeat}")
    head = ("master", "wall s", "steps/s", "x simulate_ssp", "us/step (no setup)", "x", "setup s")
    rows = [head]
    for name, r in results.items():
        rows.append((name, f"{r['wall_s']:.3f}", f"{r['steps_per_s']:,.0f}", f"{ref['wall_s'] / r['wall_s']:.1f}",
                     f"{r['us_per_step']:.2f}", f"{ref['us_per_step'] / r['us_per_step']:.1f}",
                     f"{r['setup_s']:.3f}"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    for i, r in enumerate(rows):
        print("  ".join(c.ljust(w) if j == 0 else c.rjust(w) for j, (c, w) in enumerate(zip(r, widths))))
        if i == 0:
            print("  ".join("-" * w for w in widths))
    print(f"container samples == jacobi samples (bit for bit): {same}")

    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "benchmark": "masters", "experiment": "track_wheelset/psd", "stop_time": args.stop_time,
        "step_size": h, "steps": n_long, "repeat": args.repeat, "statistic": "best of repeats",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                    "fmpy": fmpy.__version__},
        "results": results, "container_equals_jacobi": same,
    }, indent=2) + "\n")
    print(f"results written to {args.out}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
