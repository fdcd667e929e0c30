"""railfmu command line (contract in docs/architecture.md, "Command line").

Every user error (missing file, bad parameter, bad --set) is one line on stderr and exit
code 2; no traceback. Without ``--master``, ``run`` and ``study`` use the master the
experiment prefers (``<rf:FixedStep stepSize="..." master="container"/>`` in its SSD's
``org.railfmu.experiment`` annotation), else jacobi.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

# The estimators multiply small matrices (14 x 14) every step: BLAS threads only fight over
# them (measured: 2-20x slower on 2 cores). Set before numpy loads; Dask workers inherit it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from railfmu.experiments.engine.registry import DeprecatedEstimatorPath  # noqa: E402
from railfmu.fmus.generate.build import BuildError  # noqa: E402
from railfmu.models.errors import UserError  # noqa: E402


def cmd_build(args) -> int:
    from railfmu.fmus.generate.build import build_all, validate

    t0 = time.monotonic()
    paths = build_all(args.out, force=args.force)
    for p in paths:
        problems = validate(p)
        print(f"{p}  ({'valid' if not problems else f'{len(problems)} problems'})")
        for pr in problems:
            print(f"  - {pr}")
    print(f"built {len(paths)} FMUs in {time.monotonic() - t0:.1f} s")
    return 0


def cmd_validate(args) -> int:
    from railfmu.fmus.generate.build import build_all, default_out, validate
    from railfmu.fmus.ssp import validate_ssp

    path = Path(args.path)
    if not path.exists():
        raise UserError(f"{path}: no such file or directory")
    if path.is_dir() and not (path / "SystemStructure.ssd").is_file():
        targets = sorted(path.glob("*.fmu")) + sorted(path.glob("*.ssp"))
        if not targets:
            raise UserError(f"{path}: no .fmu, .ssp or SystemStructure.ssd in this folder")
    else:
        targets = [path]
    bad = 0
    for t in targets:
        if t.suffix == ".fmu":
            problems = validate(t)
        elif t.suffix in (".ssp", ".ssd") or t.is_dir():
            if t.suffix != ".ssp":  # an experiment folder: its FMUs come from the build
                build_all(default_out())
            problems = validate_ssp(t, fmu_dirs=[default_out()])
        else:
            raise UserError(f"{t}: not an FMU or SSP (.fmu, .ssp, .ssd or a folder)")
        bad += bool(problems)
        print(f"{t}: {'OK' if not problems else f'{len(problems)} problems'}")
        for pr in problems:
            print(f"  - {pr}")
    return 1 if bad else 0


def cmd_list(args) -> int:
    from railfmu.experiments.engine.runner import experiment_names, find_experiment

    for name in experiment_names():
        exp = find_experiment(name)
        print(f"{name}: {exp.description}")
        for v in exp.variants:
            print(f"  {v}{' (default)' if v == exp.default_variant else ''}")
    return 0


def _parse_set(items: list[str]) -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for item in items:
        key, sep, value = item.partition("=")
        comp, dot, param = key.partition(".")
        if not sep or not dot or not comp or not param or not value:
            raise UserError(f"--set {item!r}: expected COMPONENT.PARAM=VALUE")
        out.setdefault(comp, {})[param] = value  # text: converted to the variable's FMI type by the reader
    return out


def _overrides(args) -> dict:
    return {"sets": _parse_set(args.set or []), "seed": args.seed, "stop_time": args.stop_time,
            "step_size": args.step_size}


def cmd_run(args) -> int:
    from railfmu.experiments.engine.runner import run_experiment

    run_experiment(args.experiment, args.variant, args.out, master=args.master, **_overrides(args))
    return 0


def cmd_study(args) -> int:
    from railfmu.experiments.engine.study import run_study

    run_study(args.experiment, args.out, scheduler=args.scheduler, master=args.master,
              workers=args.workers, variants=args.variant, runs=args.runs, keep_runs=args.keep_runs,
              **_overrides(args))
    return 0


def cmd_export(args) -> int:
    from railfmu.fmus.ssp import write_ssp

    from railfmu.experiments.engine.runner import find_experiment, load_system

    exp = find_experiment(args.experiment)
    system = load_system(exp, args.variant or exp.default_variant, **_overrides(args))
    out = Path(args.output)
    if out.suffix != ".ssp":
        raise UserError(f"-o {out}: the archive name must end in .ssp")
    if out.is_dir():
        raise UserError(f"-o {out}: a folder of that name exists; give a file name")
    write_ssp(system, out)
    print(f"wrote {out} ({exp.name}/{args.variant or exp.default_variant}, "
          f"{len(system.components)} FMUs inside)")
    return 0


def _add_overrides(p) -> None:
    p.add_argument("--set", action="append", metavar="COMPONENT.PARAM=VALUE",
                   help="override a parameter (repeatable)")
    p.add_argument("--seed", type=int, help="seed of every random source (track, sensor noise)")
    p.add_argument("--stop-time", type=float,
                   help="override the stop time [s] (the variant's experiment.stopTime, else the SSD's "
                        "DefaultExperiment)")
    p.add_argument("--step-size", type=float,
                   help="the communication step [s] (default: the SSD's step annotation, else the smallest "
                        "DefaultExperiment stepSize of the FMUs)")


MASTER_HELP = ("jacobi, gauss-seidel or container (default: the experiment's own choice, the master attribute "
               "of rf:FixedStep in its SSD, else jacobi)")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line and exit 2, like every other user error
        print(f"railfmu: error: {self.prog}: {message}", file=sys.stderr)
        sys.exit(2)


def _show_warning(message, category, filename, lineno, file=None, line=None, _default=warnings.showwarning):
    """Our deprecations as one line, like every other user-facing message; others as Python shows them."""
    if issubclass(category, DeprecatedEstimatorPath):
        print(f"railfmu: warning: {message}", file=sys.stderr)
    else:
        _default(message, category, filename, lineno, file, line)


def main(argv: list[str] | None = None) -> int:
    warnings.simplefilter("default", DeprecatedEstimatorPath)  # Python hides DeprecationWarnings outside __main__
    warnings.showwarning = _show_warning
    ap = _Parser(prog="railfmu", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("build", help="compile all FMUs")
    p.add_argument("--out", default=None, help="output folder (default: the per-user cache, ~/.cache/railfmu/fmus/KEY)")
    p.add_argument("--force", action="store_true", help="rebuild even if unchanged")
    p.set_defaults(fn=cmd_build)
    p = sub.add_parser("validate", help="validate an FMU, an SSP (.ssp, .ssd, folder) or every FMU/SSP in a folder")
    p.add_argument("path")
    p.set_defaults(fn=cmd_validate)
    p = sub.add_parser("list", help="experiments and their variants")
    p.set_defaults(fn=cmd_list)
    p = sub.add_parser("run", help="run one experiment (a name from `list`, or the path of an SSP)")
    p.add_argument("experiment")
    p.add_argument("--variant")
    p.add_argument("--out", help="output folder (default out/EXP/VARIANT)")
    p.add_argument("--master", default=None, help=MASTER_HELP)
    _add_overrides(p)
    p.set_defaults(fn=cmd_run)
    p = sub.add_parser("study", help="variants x seeds of an experiment, in parallel (Dask) -> table")
    p.add_argument("experiment")
    p.add_argument("--variant", action="extend", nargs="+", metavar="V",
                   help="run only these variants (default all)")
    p.add_argument("--runs", type=int, default=1, metavar="N",
                   help="Monte Carlo: N runs per variant with seeds S, S+1, ... (--seed S, default 1)")
    p.add_argument("--keep-runs", action="store_true",
                   help="with --runs N > 1: keep each run's CSVs, plots and report (default: metrics only)")
    p.add_argument("--out", help="output folder (default out/EXP_study)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, help="local cluster size (default: min(runs in all, 2))")
    p.add_argument("--master", default=None, help=MASTER_HELP)
    _add_overrides(p)
    p.set_defaults(fn=cmd_study)
    p = sub.add_parser("export", help="a self-contained .ssp (SSD + parameters + FMUs) of one variant")
    p.add_argument("experiment")
    p.add_argument("--variant")
    p.add_argument("-o", "--output", required=True, metavar="FILE.ssp")
    _add_overrides(p)
    p.set_defaults(fn=cmd_export)
    args = ap.parse_args(argv)
    if args.command == "build" and args.out is None:
        from railfmu.fmus.generate.build import default_out

        args.out = default_out()
    try:
        return args.fn(args)
    except UserError as exc:
        print(f"railfmu: error: {exc}", file=sys.stderr)
        return 2
    except BuildError as exc:  # our generated C or the machine's compiler: not the user's input
        print(f"railfmu: build failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("railfmu: interrupted (complete rows written so far stay in the output folder)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
