"""railfmu: run, study and export railway monitoring experiments (SSP systems of FMUs, with estimators as observers).

The command line is a thin layer over the Python API (:mod:`railfmu.experiments.engine.api`,
re-exported as ``railfmu.run`` & co.); its contract is in the repository's docs/cli.md.

Every user error (missing file, bad parameter, bad --set) is one line on stderr and exit
code 2; no traceback. Without ``--master``, ``run`` and ``study`` use the master the
experiment prefers (``<rf:FixedStep stepSize="..." master="container"/>`` in its SSD's
``org.railfmu.experiment`` annotation), else jacobi. ``-q`` drops progress lines (warnings and
errors stay), ``-v`` adds detail; both go before or after the subcommand.
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

import railfmu  # noqa: E402  (its __version__: one place, the installed metadata)
from railfmu.experiments.engine.registry import DeprecatedEstimatorPath  # noqa: E402
from railfmu.fmus.generate.build import BuildError  # noqa: E402
from railfmu.models.errors import UserError  # noqa: E402


def cmd_build(args) -> int:
    from railfmu.fmus.generate.build import build_all, validate

    from railfmu.experiments.engine.files import ensure_folder

    t0 = time.monotonic()
    ensure_folder(args.out)
    paths = build_all(args.out, force=args.force, fmi_version=args.fmi, platforms=args.platform)
    for p in paths:
        problems = validate(p)
        print(f"{p}  ({'valid' if not problems else f'{len(problems)} problems'})")
        for pr in problems:
            print(f"  - {pr}")
    print(f"built {len(paths)} FMUs in {time.monotonic() - t0:.1f} s")
    return 0


def cmd_validate(args) -> int:
    from railfmu.fmus.generate.build import build_all, default_out, describe, validate
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
        what = ""
        if t.suffix == ".fmu":
            problems = validate(t, packaging=args.packaging or None)
            what = f" ({describe(t)})"
        elif t.suffix in (".ssp", ".ssd") or t.is_dir():
            if t.suffix != ".ssp":  # an experiment folder: its FMUs come from the build
                build_all(default_out())
            problems = validate_ssp(t, fmu_dirs=[default_out()], packaging=args.packaging or None)
        else:
            raise UserError(f"{t}: not an FMU or SSP (.fmu, .ssp, .ssd or a folder)")
        bad += bool(problems)
        print(f"{t}: {'OK' if not problems else f'{len(problems)} problems'}{what}")
        for pr in problems:
            print(f"  - {pr}")
    return 1 if bad else 0


def cmd_list(args) -> int:
    from railfmu.experiments.engine.api import list_experiments

    for name, exp in list_experiments().items():
        print(f"{name}: {exp['description']}")
        for v in exp["variants"]:
            print(f"  {v}{' (default)' if v == exp['default_variant'] else ''}")
    return 0


def _parse_set(items: list[str]) -> dict[str, str]:
    """``--set C.P=V`` items -> ``{"C.P": "V"}`` (text: the reader converts it to the variable's FMI type)."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        comp, dot, param = key.partition(".")
        if not sep or not dot or not comp or not param or not value:
            raise UserError(f"--set {item!r}: expected COMPONENT.PARAM=VALUE")
        out[key] = value
    return out


def _overrides(args) -> dict:
    return {"parameters": _parse_set(args.set or []), "seed": args.seed, "stop_time": args.stop_time,
            "step_size": args.step_size}


def _log(args):
    """Where progress lines go: stderr, none with -q (warnings and errors still do)."""
    return None if args.quiet else sys.stderr


def cmd_run(args) -> int:
    from railfmu.experiments.engine import figure_worker

    figure_worker.start()  # first: its matplotlib import runs on another core while the run sets up and steps
    from railfmu.experiments.engine.api import run
    from railfmu.experiments.engine.runner import find_experiment

    out = args.out
    if out is None:  # out/EXP/VARIANT, as before the API
        exp = find_experiment(args.experiment)
        out = Path("out") / exp.name / (args.variant or exp.default_variant or "default")
    log = _log(args)
    run(args.experiment, args.variant, master=args.master, out=out, progress=not args.quiet,
        log=log if log is not None else _Quiet(), verbose=args.verbose, fmi_version=args.fmi,
        record_format=args.format, sampling=args.sampling, **_overrides(args))
    return 0


class _Quiet:
    """A log that drops progress lines but lets warnings (``railfmu: ...``) through to stderr."""

    def write(self, text: str) -> int:
        if text.startswith("railfmu: "):
            sys.stderr.write(text + ("" if text.endswith("\n") else "\n"))
        return len(text)

    def flush(self) -> None:
        sys.stderr.flush()


def cmd_study(args) -> int:
    from railfmu.experiments.engine.api import study

    study(args.experiment, args.variant, out=args.out, scheduler=args.scheduler, master=args.master,
          workers=args.workers, runs=args.runs, keep_runs=args.keep_runs, resume=args.resume,
          log=_log(args) or _Quiet(), **_overrides(args))
    return 0


def cmd_export(args) -> int:
    from railfmu.experiments.engine.api import export_system
    from railfmu.experiments.engine.runner import find_experiment

    from railfmu.experiments.engine.files import ensure_folder

    exp = find_experiment(args.experiment)
    ensure_folder(Path(args.output).absolute().parent, f"-o {args.output}: its folder")
    out, system = export_system(args.experiment, args.output, args.variant, fmi_version=args.fmi,
                                ssp_version=args.ssp, **_overrides(args))
    print(f"wrote {out} ({exp.name}/{args.variant or exp.default_variant}, "
          f"{len(system.components)} FMUs inside)")
    return 0


def cmd_parameters(args) -> int:
    from railfmu.experiments.engine.api import parameters
    from railfmu.experiments.engine.runner import find_experiment

    exp = find_experiment(args.experiment)
    params = parameters(args.experiment, args.variant)
    variant = args.variant or exp.default_variant
    print(f"{exp.name}, {f'variant {variant}' if variant else 'no variant'}: {len(params)} settable names "
          "(--set NAME=VALUE)")
    rows = [(p.name, p.type, p.unit or "-", _show(p.value),
             "" if p.kind == "setting" or p.value == p.default else f"(default {_show(p.default)})",
             p.description if args.verbose else "") for p in params]
    widths = [max((len(r[i]) for r in rows), default=0) for i in range(4)]
    print(f"  {'name':<{widths[0]}}  {'type':<{widths[1]}}  {'unit':<{widths[2]}}  value")
    for r in rows:
        print(("  " + "  ".join(f"{c:<{w}}" for c, w in zip(r[:4], widths)) + "  "
               + "  ".join(c for c in r[4:] if c)).rstrip())
    return 0


def _show(value) -> str:
    return repr(value) if isinstance(value, str) else "true" if value is True else "false" if value is False \
        else f"{value:g}" if isinstance(value, float) else str(value)


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


def _add_fmi(p, text: str) -> None:
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2, metavar="{2,3}", help=text)


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


def _verbosity(defaults: bool) -> argparse.ArgumentParser:
    """-q/-v, accepted before and after the subcommand (the subcommand's copy must not reset
    what was given before it: no defaults there)."""
    p = argparse.ArgumentParser(add_help=False)
    d = {} if defaults else {"default": argparse.SUPPRESS}
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", help="no progress lines (warnings and errors stay)", **d)
    g.add_argument("-v", "--verbose", action="store_true", help="more detail (study, components, timing)", **d)
    return p


class _SubParsers(argparse._SubParsersAction):
    def add_parser(self, name, **kwargs):  # every subcommand takes -q/-v too
        return super().add_parser(name, parents=[_verbosity(False)], **kwargs)


def main(argv: list[str] | None = None) -> int:
    warnings.simplefilter("default", DeprecatedEstimatorPath)  # Python hides DeprecationWarnings outside __main__
    warnings.showwarning = _show_warning
    ap = _Parser(prog="railfmu", description=__doc__.splitlines()[0], parents=[_verbosity(True)])
    ap.add_argument("--version", action="version", version=f"railfmu {railfmu.__version__}")
    ap.register("action", "parsers", _SubParsers)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("build", help="compile all FMUs")
    p.add_argument("--out", default=None, help="output folder (default: the per-user cache, ~/.cache/railfmu/fmus/KEY)")
    p.add_argument("--force", action="store_true", help="rebuild even if unchanged")
    p.add_argument("--platform", action="append", choices=["linux64", "win64"],
                   help="binaries to build, repeatable (default: linux64, and win64 where mingw-w64 is installed)")
    _add_fmi(p, "build FMI 2.0 (default) or FMI 3.0 Co-Simulation FMUs (3: into KEY-fmi3)")
    p.set_defaults(fn=cmd_build)
    p = sub.add_parser("validate", help="validate an FMU, an SSP (.ssp, .ssd, folder) or every FMU/SSP in a folder")
    p.add_argument("path")
    p.add_argument("--packaging", action="store_true",
                   help="apply railfmu's packaging rules (linux64 binary, C sources) to every FMU, not only "
                        "to those railfmu built")
    p.set_defaults(fn=cmd_validate)
    p = sub.add_parser("list", help="experiments and their variants")
    p.set_defaults(fn=cmd_list)
    p = sub.add_parser("run", help="run one experiment (a name from `list`, or the path of an SSP)")
    p.add_argument("experiment")
    p.add_argument("--variant")
    p.add_argument("--out", help="output folder (default out/EXP/VARIANT)")
    p.add_argument("--master", default=None, help=MASTER_HELP)
    _add_fmi(p, "run railfmu's FMUs as their FMI 2.0 (default) or FMI 3.0 builds")
    p.add_argument("--format", default="csv", choices=("csv", "parquet", "mat"),
                   help="signals and estimates as CSV (default), Parquet or MATLAB .mat (compact)")
    p.add_argument("--sampling", default="after-transfer", choices=("after-transfer", "before-transfer"),
                   help="read each row after the connections are copied (default), or right after the step, "
                        "before any input is set (libcosim's order; Jacobi master only)")
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
    p.add_argument("--resume", action="store_true",
                   help="keep the runs a killed or finished study into --out finished (out/runs) and "
                        "run only the missing ones")
    p.add_argument("--scheduler", help="address of a running Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, help="local cluster size (default: min(runs in all, 2))")
    p.add_argument("--master", default=None, help=MASTER_HELP)
    _add_overrides(p)
    p.set_defaults(fn=cmd_study)
    p = sub.add_parser("parameters", help="what --set can change in an experiment: units, defaults, values")
    p.add_argument("experiment")
    p.add_argument("--variant")
    p.set_defaults(fn=cmd_parameters)
    p = sub.add_parser("export", help="a self-contained .ssp (SSD + parameters + FMUs) of one variant")
    p.add_argument("experiment")
    p.add_argument("--variant")
    p.add_argument("-o", "--output", required=True, metavar="FILE.ssp")
    _add_fmi(p, "pack the FMI 2.0 (default) or FMI 3.0 builds of the FMUs")
    p.add_argument("--ssp", choices=("1.0", "2.0"), default="1.0", type=lambda x: {"1": "1.0", "2": "2.0"}.get(x, x),
                   help="write the SSD as SSP 1.0 (default) or SSP 2.0")
    _add_overrides(p)
    p.set_defaults(fn=cmd_export)
    args = ap.parse_args(argv)
    if argv is None:  # the process's own command: it ends with the command
        import atexit
        import gc

        # everything the command built (sympy's expression trees, the modules, the run's arrays) dies
        # with the process: the interpreter's final collection need not traverse it (~1.5 s)
        atexit.register(gc.freeze)
    if args.command == "build" and args.out is None:
        from railfmu.fmus.generate.build import default_out

        args.out = default_out(args.fmi)
    try:
        return args.fn(args)
    except UserError as exc:
        print(f"railfmu: error: {exc}", file=sys.stderr)
        return 2
    except BuildError as exc:  # our generated C or the machine's compiler: not the user's input
        print(f"railfmu: build failed: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # `railfmu list | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("railfmu: interrupted (complete rows written so far stay in the output folder)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
