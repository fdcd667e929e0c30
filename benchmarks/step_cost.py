"""Cost of one communication step of each FMU, in microseconds, through three hosts.

  FMPy    FMPy's ``FMU2Slave.doStep`` called from a Python loop (what a Python master pays
          per FMU and step before it reads or writes any variable); also with the I/O a
          master does every step (set the inputs, step, read four outputs).
  ctypes  the FMU's ``fmi2DoStep`` called directly through ctypes with prebuilt arguments:
          what is left of the Python overhead without FMPy's status checks and wrappers.
  C       the same steps from ``benchmarks/c_loop.c``, a plain C host that dlopen()s the
          binary: the FMU's own cost.

Every path runs the same experiment (1 ms steps from t = 0, the same parameters), with a
fresh instance per repeat, and reports the fastest repeat; afterwards one output is compared
between the three paths (they must agree bit for bit). The wheelset integrates with RK4
sub-steps of at most ``integrator_step``: it is measured with the default (1e-4 s: 10
sub-steps per 1 ms step) and with the sub-step equal to the communication step.

    python benchmarks/step_cost.py [--steps N] [--quick] [--fmu-dir DIR] [--out FILE]

Writes build/benchmarks/step_cost.json (build/ is not tracked).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

import fmpy  # noqa: E402
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from railfmu.fmus.generate.build import build_all, fmi_header_dir  # noqa: E402

STEP = 1e-3  # communication step, s
MAX_SIM_TIME = 300.0  # s; the wheelset's free decay reaches denormal numbers after ~600 s,
#                       which would slow the arithmetic down and falsify the timing


@dataclass
class Case:
    label: str
    fmu: str  # model identifier
    parameters: dict = field(default_factory=dict)
    inputs: tuple[str, ...] = ()  # set every step in the "FMPy + I/O" path (to 0: no effect)
    outputs: tuple[str, ...] = ()  # read every step in the "FMPy + I/O" path
    check: str = ""  # output compared between the paths after the last step


def cases() -> list[Case]:
    from railfmu.models.vehicle.wheelset import WHEELSET

    h_int = WHEELSET.integrator_step
    n_sub = math.ceil(STEP / h_int - 1e-9)
    ws_io = dict(inputs=("xi", "xi_rate"), outputs=("y", "psi", "dy_f", "ddy"), check="y")
    return [
        Case("TrackIrregularity", "TrackIrregularity",
             {"psd_level": 1, "seed": 7, "harmonic_lateral_amplitude": 1e-3, "harmonic_wavelength": 15.66},
             outputs=("alignment_1", "alignment_rate_1", "vertical_left_1", "vertical_right_1"),
             check="alignment_1"),
        Case(f"WheelsetLateral ({n_sub} RK4 sub-steps)", "WheelsetLateral", {"y": 1e-3}, **ws_io),
        Case("WheelsetLateral (1 RK4 sub-step)", "WheelsetLateral", {"y": 1e-3, "integrator_step": STEP},
             **ws_io),
    ]


class Unpacked:
    """An extracted FMU: its model description and folder."""

    def __init__(self, path: Path):
        self.path = path
        self.md = read_model_description(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.dir = extract(str(path))
        self.binary = Path(self.dir, "binaries", "linux64", f"{self.md.coSimulation.modelIdentifier}.so")

    def vr(self, name: str) -> int:
        return self.vars[name].valueReference

    def slave(self, parameters: dict) -> FMU2Slave:
        """Instantiated (FMPy's default logger prints), parameters set, initialised at t = 0."""
        fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                        modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="bench")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        for name, value in parameters.items():
            if self.vars[name].type == "Integer":
                fmu.setInteger([self.vr(name)], [int(value)])
            else:
                fmu.setReal([self.vr(name)], [float(value)])
        fmu.exitInitializationMode()
        return fmu

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


def _finish(fmu: FMU2Slave, vr: int) -> float:
    value = fmu.getReal([vr])[0]
    fmu.terminate()
    fmu.freeInstance()
    return value


def time_fmpy(u: Unpacked, case: Case, steps: int, repeats: int, with_io: bool) -> tuple[float, float]:
    """Best µs per step of FMU2Slave.doStep in a Python loop; and the check output."""
    times = [k * STEP for k in range(steps)]
    in_vrs = [u.vr(n) for n in case.inputs]
    zeros = [0.0] * len(in_vrs)
    out_vrs = [u.vr(n) for n in case.outputs]
    best, check = math.inf, math.nan
    for _ in range(repeats):
        fmu = u.slave(case.parameters)
        do_step, set_real, get_real = fmu.doStep, fmu.setReal, fmu.getReal
        t0 = time.perf_counter()
        if with_io:
            for t in times:
                if in_vrs:
                    set_real(in_vrs, zeros)
                do_step(t, STEP)
                get_real(out_vrs)
        else:
            for t in times:
                do_step(t, STEP)
        best = min(best, (time.perf_counter() - t0) / steps * 1e6)
        check = _finish(fmu, u.vr(case.check))
    return best, check


def time_ctypes(u: Unpacked, case: Case, steps: int, repeats: int) -> tuple[float, float]:
    """Best µs per step of the raw fmi2DoStep through ctypes (prebuilt arguments)."""
    times = [ctypes.c_double(k * STEP) for k in range(steps)]
    h, no_set_prior = ctypes.c_double(STEP), ctypes.c_int(1)
    best, check = math.inf, math.nan
    for _ in range(repeats):
        fmu = u.slave(case.parameters)
        do_step = fmu.dll["fmi2DoStep"]  # a fresh function object: FMPy's keeps its own argtypes
        do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        do_step.restype = ctypes.c_int
        comp = ctypes.c_void_p(fmu.component)
        bad = 0
        t0 = time.perf_counter()
        for t in times:
            bad |= do_step(comp, t, h, no_set_prior)
        best = min(best, (time.perf_counter() - t0) / steps * 1e6)
        if bad:
            raise RuntimeError(f"{case.label}: fmi2DoStep failed (ctypes loop)")
        check = _finish(fmu, u.vr(case.check))
    return best, check


def compile_c_loop(out_dir: Path) -> Path:
    exe = out_dir / "c_loop"
    cmd = [os.environ.get("CC", "gcc"), "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror",
           "-I", str(fmi_header_dir()), str(ROOT / "benchmarks" / "c_loop.c"), "-o", str(exe), "-ldl"]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        sys.exit(f"step_cost: compiling benchmarks/c_loop.c failed:\n{res.stderr.strip()}")
    return exe


def time_c(exe: Path, u: Unpacked, case: Case, steps: int, repeats: int) -> tuple[float, float, float]:
    """Best and median µs per step in the C host; and the check output."""
    args = [str(exe), str(u.binary), u.md.guid, Path(u.dir, "resources").as_uri(), str(steps),
            repr(STEP), str(repeats), str(u.vr(case.check))]
    for name, value in case.parameters.items():
        kind = "i" if u.vars[name].type == "Integer" else "r"
        args.append(f"{kind}:{u.vr(name)}={value!r}")
    res = subprocess.run(args, capture_output=True, text=True)
    if res.returncode != 0:
        sys.exit(f"step_cost: c_loop failed for {case.label}:\n{res.stderr.strip()}")
    fields = dict(item.split("=", 1) for item in res.stdout.split())
    return float(fields["best_ns"]) / 1e3, float(fields["median_ns"]) / 1e3, float(fields["check"])


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _gcc_version() -> str:
    try:
        out = subprocess.run([os.environ.get("CC", "gcc"), "--version"], capture_output=True, text=True)
        return out.stdout.splitlines()[0]
    except (OSError, IndexError):
        return "?"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=None,
                    help="communication steps per timed run (default 20000, --quick 2000)")
    ap.add_argument("--quick", action="store_true", help="fewer steps and repeats (a smoke run)")
    ap.add_argument("--fmu-dir", type=Path, default=None,
                    help="folder with the built FMUs (default: build them into the per-user cache)")
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "step_cost.json")
    args = ap.parse_args(argv)
    steps = args.steps if args.steps is not None else (2000 if args.quick else 20000)
    if steps < 1:
        ap.error("--steps must be >= 1")
    if steps * STEP > MAX_SIM_TIME:
        ap.error(f"--steps {steps} simulates {steps * STEP:g} s per run; keep it <= {MAX_SIM_TIME:g} s "
                 f"({int(MAX_SIM_TIME / STEP)} steps): the wheelset's decaying states would reach "
                 "denormal numbers, which are slow and would falsify the timing")
    py_repeats, c_repeats = (2, 5) if args.quick else (5, 15)

    if args.fmu_dir is None:
        fmu_dir = ROOT / "build" / "fmus"
        build_all(fmu_dir)  # a no-op when the FMUs are up to date
    else:
        fmu_dir = args.fmu_dir
    args.out.parent.mkdir(parents=True, exist_ok=True)
    exe = compile_c_loop(args.out.parent)

    t_start = time.perf_counter()
    rows = []
    mismatches = []
    unpacked: dict[str, Unpacked] = {}
    try:
        for case in cases():
            path = fmu_dir / f"{case.fmu}.fmu"
            if not path.is_file():
                sys.exit(f"step_cost: {path} not found (run `railfmu build` or pass --fmu-dir)")
            u = unpacked.get(case.fmu) or unpacked.setdefault(case.fmu, Unpacked(path))
            us_fmpy, chk_fmpy = time_fmpy(u, case, steps, py_repeats, with_io=False)
            us_io, _ = time_fmpy(u, case, steps, py_repeats, with_io=True)
            us_ctypes, chk_ctypes = time_ctypes(u, case, steps, py_repeats)
            us_c, us_c_median, chk_c = time_c(exe, u, case, steps, c_repeats)
            if not (chk_fmpy == chk_ctypes == chk_c):
                mismatches.append(f"{case.label}: {case.check} after {steps} steps: FMPy {chk_fmpy!r}, "
                                  f"ctypes {chk_ctypes!r}, C {chk_c!r}")
            rows.append({
                "fmu": case.fmu, "label": case.label, "parameters": case.parameters,
                "us_per_step_fmpy": us_fmpy, "us_per_step_fmpy_io": us_io,
                "us_per_step_ctypes": us_ctypes, "us_per_step_c": us_c, "us_per_step_c_median": us_c_median,
                "ratio_fmpy_over_c": us_fmpy / us_c,
                "check": {"variable": case.check, "fmpy": chk_fmpy, "ctypes": chk_ctypes, "c": chk_c},
            })
    finally:
        for u in unpacked.values():
            u.close()

    head = ("FMU", "us/step FMPy", "us/step ctypes", "us/step C", "ratio FMPy/C", "FMPy +I/O")
    table = [head] + [(r["label"], f"{r['us_per_step_fmpy']:.2f}", f"{r['us_per_step_ctypes']:.2f}",
                       f"{r['us_per_step_c']:.3f}", f"{r['ratio_fmpy_over_c']:.1f}",
                       f"{r['us_per_step_fmpy_io']:.2f}") for r in rows]
    widths = [max(len(line[i]) for line in table) for i in range(len(head))]
    print(f"one {STEP * 1e3:g} ms communication step, best of {py_repeats} (Python) / {c_repeats} (C) "
          f"runs of {steps} steps")
    for i, line in enumerate(table):
        print("  ".join(c.ljust(w) if j == 0 else c.rjust(w) for j, (c, w) in enumerate(zip(line, widths))))
        if i == 0:
            print("  ".join("-" * w for w in widths))
    print("FMPy +I/O: set the inputs, doStep, read four outputs (FMU2Slave.setReal/getReal)")

    result = {
        "benchmark": "step_cost", "step_size": STEP, "steps": steps,
        "repeats_python": py_repeats, "repeats_c": c_repeats, "statistic": "best of repeats",
        "machine": {"platform": platform.platform(), "processor": _cpu_model(),
                    "cpus": os.cpu_count(), "python": platform.python_version(),
                    "fmpy": fmpy.__version__, "compiler": _gcc_version()},
        "elapsed_s": time.perf_counter() - t_start,
        "results": rows, "mismatches": mismatches,
    }
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"results written to {args.out}")
    if mismatches:
        print("the paths disagree (they should be bit-identical):", *mismatches, sep="\n  ", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
