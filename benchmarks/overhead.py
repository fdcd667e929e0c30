"""A run's fixed cost: the time outside stepping and estimating, beside the stepping time.

Two cases:

  member    one Monte Carlo member as a Dask worker runs it: ``run_experiment(...,
            write_files=False)`` in a process that has already run one member (imports
            loaded, FMUs built), each repeat with a new seed. Default: suspension_fault /
            static, 150 s at 10 ms, jacobi master (``railfmu study suspension_fault
            --variant static --runs N``).
  main job  ``railfmu run lateral_alignment --master container`` as a user types it: a new
            Python process, timed from outside, everything written (CSVs, plots, report).

Each run records in its metrics ``timing_s``: ``stepping`` (the master's loop with the online
observers), ``study_metrics`` (the study's offline estimators and scores) and ``setup``.
Overhead = wall - stepping - study_metrics: what a run pays besides stepping and estimating
(process start and imports, the FMUs' up-to-date check, reading the SSP, instantiating,
files and plots). Goal: a member's overhead <= 5 % of its stepping time. Median of --repeat.

    python benchmarks/overhead.py [--repeat 3] [--member EXP/VARIANT] [--member-master M]
                                  [--skip-main-job] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI and its Dask workers run
os.environ.setdefault("OMP_NUM_THREADS", "1")

GOAL = 0.05


def _split(wall: float, timing: dict) -> dict:
    overhead = wall - timing["stepping"] - timing["study_metrics"]
    return {"wall_s": wall, "stepping_s": timing["stepping"], "estimating_offline_s": timing["study_metrics"],
            "setup_s": timing["setup"], "overhead_s": overhead, "overhead_per_stepping": overhead / timing["stepping"]}


def member(experiment: str, variant: str, master: str, repeat: int) -> list[dict]:
    from railfmu.experiments.engine.runner import run_experiment

    def once(seed: int) -> dict:
        t0 = time.perf_counter()
        m = run_experiment(experiment, variant, None, master=master, seed=seed, progress=False, log=io.StringIO(),
                           write_files=False)
        return _split(time.perf_counter() - t0, m["timing_s"])

    once(1)  # the worker's first member pays the imports once
    return [once(2 + i) for i in range(repeat)]


def main_job(repeat: int) -> list[dict]:
    rows = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "lateral_alignment", "--master",
                                  "container", "--out", tmp], cwd=ROOT, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if res.returncode != 0:
                sys.exit(f"main job failed: {res.stderr.strip()}")
            rows.append(_split(wall, json.loads((Path(tmp) / "metrics.json").read_text())["timing_s"]))
    return rows


def _median(rows: list[dict]) -> dict:
    return {k: statistics.median(r[k] for r in rows) for k in rows[0]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per case; the median counts (default 3)")
    ap.add_argument("--member", default="suspension_fault/static", metavar="EXP/VARIANT")
    ap.add_argument("--member-master", default="jacobi")
    ap.add_argument("--skip-main-job", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "benchmarks" / "overhead.json")
    args = ap.parse_args(argv)

    from railfmu.fmus.generate.build import build_all

    build_all()  # a no-op when up to date
    exp, _, variant = args.member.partition("/")
    cases = {f"member {args.member} ({args.member_master})": member(exp, variant, args.member_master, args.repeat)}
    if not args.skip_main_job:
        cases["railfmu run lateral_alignment --master container"] = main_job(args.repeat)
    result = {name: _median(rows) for name, rows in cases.items()}

    print(f"{'case':<52} {'wall':>7} {'stepping':>9} {'estim.':>7} {'setup':>6} {'overhead':>9} {'ratio':>7}")
    for name, r in result.items():
        print(f"{name:<52} {r['wall_s']:7.2f} {r['stepping_s']:9.2f} {r['estimating_offline_s']:7.2f} "
              f"{r['setup_s']:6.2f} {r['overhead_s']:9.2f} {100 * r['overhead_per_stepping']:6.1f}%")
    first = next(iter(result.values()))
    print(f"seconds, median of {args.repeat}; ratio = overhead / stepping; member goal <= {100 * GOAL:.0f} %: "
          f"{'met' if first['overhead_per_stepping'] <= GOAL else 'NOT met'}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"cases": cases, "median": result}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
