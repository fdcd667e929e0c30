"""Speed of the three masters of railfmu.fmus.cosim.masters against FMPy's own SSP simulator.

The experiment experiments/track_wheelset, variant psd (ERRI B176 low-level track into the
wheelset + suspended frame, 11 recorded signals), 20 s at 1 ms, through

  jacobi        railfmu.fmus.cosim.masters.run(system, "jacobi")        (Python loop, raw ctypes calls)
  gauss-seidel  railfmu.fmus.cosim.masters.run(system, "gauss-seidel")
  container     railfmu.fmus.cosim.masters.run(system, "container")     (our C coupling loop over the FMUs)
  fmpy-container  the container master's previous path, still taken by systems with FMI 3.0
                components: FMPy's container FMU stepped by a C driver (masters._run_container)
  simulate_ssp  fmpy.ssp.simulation.simulate_ssp on the same system written as a .ssp
                (railfmu.fmus.ssp.write_ssp; it ignores parameter bindings, which here equal the
                FMU defaults, so it runs the same system)

Each is timed end to end (load, initialise, run, free: what a user waits for) and on a
0.1 s run; the difference over the difference in steps is the cost of one step without
setup. Best of --repeat runs. No sinks: the masters fill their result array only.

The peer of the container master is the plain C loop: benchmarks/c_loop.c (the host of
step_cost.py) steps each FMU of the system alone, with the system's parameter values, for the
same number of steps (best of 15); the sum over the FMUs is the FMUs' own cost of one system
step, without any coupling. The ratio container / C loop is printed from the same run.

    python benchmarks/masters.py [--stop-time 20] [--repeat 3] [--set COMP.PARAM=VALUE] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import fmpy
import numpy as np
from fmpy import extract
from fmpy.ssp.simulation import simulate_ssp

from railfmu.fmus.cosim.masters import MASTERS, _run_container, run
from railfmu.fmus.cosim.system import System, recorded_signals
from railfmu.fmus.generate.build import build_all
from railfmu.fmus.ssp import read_system, write_ssp

SHORT = 0.1  # s, the run that measures setup
C_REPEATS = 15


def c_loop_cost(system: System, exe: Path, container) -> tuple[float, dict, list[str]]:
    """us per system step of the FMUs alone: c_loop.c on each component with its parameters
    for the system's steps, best of C_REPEATS, summed; the per-component numbers; and
    mismatches: a component no connection feeds computes in c_loop what it computes in the
    system, so its first recorded Real signal after the last step must equal the container's
    last row bit for bit."""
    fed = {c.dst for c in system.connections}
    record = recorded_signals(system)
    total, parts, mismatches = 0.0, {}, []
    for comp in system.components:
        md = comp.md
        var = {v.name: v for v in md.modelVariables}
        mine = [s.split(".", 1)[1] for s in record if s.startswith(comp.name + ".")]
        check = next((v for v in mine if var[v].type == "Real"), None) or next(
            v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real")
        unzipped = Path(extract(str(comp.fmu)))
        try:
            args = [str(exe), str(unzipped / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"),
                    md.guid, (unzipped / "resources").as_uri(), str(system.n_steps), repr(system.step_size),
                    str(C_REPEATS), str(var[check].valueReference)]
            for name, value in comp.parameters.items():
                kind = {"Real": "r", "Integer": "i", "Enumeration": "i"}.get(var[name].type)
                if kind is None:
                    sys.exit(f"masters: c_loop.c sets Real and Integer parameters only, not {comp.name}.{name}")
                args.append(f"{kind}:{var[name].valueReference}={value!r}")
            res = subprocess.run(args, capture_output=True, text=True)
        finally:
            shutil.rmtree(unzipped, ignore_errors=True)
        if res.returncode != 0:
            sys.exit(f"masters: c_loop failed for {comp.name}:\n{res.stderr.strip()}")
        fields = dict(item.split("=", 1) for item in res.stdout.split())
        parts[comp.name] = float(fields["best_ns"]) / 1e3
        total += parts[comp.name]
        signal = f"{comp.name}.{check}"
        if comp.name not in fed and signal in container.columns:
            got = float(container.data[-1, container.columns.index(signal)])
            if got != float(fields["check"]):
                mismatches.append(f"{signal} after {system.n_steps} steps: c_loop {fields['check']}, container {got!r}")
    return total, parts, mismatches


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
    ap.add_argument("--set", action="append", default=[], metavar="COMP.PARAM=VALUE",
                    help="a parameter value of the system (as railfmu run --set), e.g. "
                         "wheelset.integrator_step=1e-3: one RK4 sub-step, so the coupling's own cost shows")
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "masters.json")
    args = ap.parse_args(argv)
    overrides: dict[str, dict[str, str]] = {}
    for item in args.set:
        target, eq, value = item.partition("=")
        comp, dot, param = target.partition(".")
        if not (eq and dot and comp and param):
            ap.error(f"--set {item}: expected COMP.PARAM=VALUE")
        overrides.setdefault(comp, {})[param] = value
    if not args.stop_time > SHORT or args.repeat < 1:
        ap.error(f"--stop-time must be > {SHORT} s and --repeat >= 1")

    fmu_dir = ROOT / "build" / "fmus"
    build_all(fmu_dir)  # a no-op when up to date
    system = read_system(ROOT / "experiments" / "track_wheelset", variant="psd", fmu_dirs=[fmu_dir],
                         stop_time=args.stop_time, overrides=overrides)
    short = read_system(ROOT / "experiments" / "track_wheelset", variant="psd", fmu_dirs=[fmu_dir],
                        stop_time=SHORT, overrides=overrides)
    h = system.step_size
    n_long, n_short = system.n_steps, short.n_steps

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        ssp = write_ssp(system, Path(tmp) / "track_wheelset.ssp")
        cases = {m: (lambda s, m=m: run(s, m, progress=False)) for m in MASTERS}
        cases["fmpy-container"] = lambda s: _run_container(s, (), False)
        cases["simulate_ssp"] = lambda s: simulate_ssp(str(ssp), start_time=s.start_time, stop_time=s.stop_time,
                                                       step_size=h)
        run(short, "container", progress=False)  # compiles the C loop once (cached)
        _run_container(short, (), False)  # and FMPy's container's driver
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
    same = all(np.array_equal(outputs[name].data, outputs["jacobi"].data) for name in ("container", "fmpy-container"))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from step_cost import compile_c_loop

    args.out.parent.mkdir(parents=True, exist_ok=True)
    c_us, c_parts, c_mismatches = c_loop_cost(system, compile_c_loop(args.out.parent), outputs["container"])

    ref = results["simulate_ssp"]
    print(f"track_wheelset (psd{''.join(', ' + x for x in args.set)}), {args.stop_time:g} s at {h * 1e3:g} ms = "
          f"{n_long} steps, {len(system.record)} recorded signals; best of {args.repeat}")
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
    print(f"container and fmpy-container samples == jacobi samples (bit for bit): {same}")
    print(f"C loop (c_loop.c, each FMU alone, best of {C_REPEATS}): {c_us:.3f} us per step = "
          + " + ".join(f"{name} {us:.3f}" for name, us in c_parts.items()))
    ratio = {name: results[name]["us_per_step"] / c_us for name in ("container", "fmpy-container", "jacobi")}
    print("per step, x the C loop: " + ", ".join(f"{name} {x:.2f}" for name, x in ratio.items()))
    for m in c_mismatches:
        print(f"c_loop ran another experiment than the system: {m}", file=sys.stderr)

    args.out.write_text(json.dumps({
        "benchmark": "masters", "experiment": "track_wheelset/psd", "set": args.set, "stop_time": args.stop_time,
        "step_size": h, "steps": n_long, "repeat": args.repeat, "statistic": "best of repeats",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                    "fmpy": fmpy.__version__},
        "results": results, "container_equals_jacobi": same,
        "c_loop": {"us_per_step": c_us, "components": c_parts, "repeats": C_REPEATS, "mismatches": c_mismatches},
        "ratio_to_c_loop": ratio,
    }, indent=2) + "\n")
    print(f"results written to {args.out}")
    return 0 if same and not c_mismatches else 1


if __name__ == "__main__":
    sys.exit(main())
