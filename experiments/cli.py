"""railfmu command line (contract in DESIGN.md "Command line").

Every user error (missing file, bad parameter, bad --set) is one line on stderr and exit
code 2; no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
import time
from pathlib import Path

from fmus.build import BuildError
from fmus.errors import UserError

EXPERIMENTS = ["track_wheelset"]


def _experiment(name: str):
    if name not in EXPERIMENTS:
        raise UserError(f"unknown experiment {name!r}; known: {', '.join(EXPERIMENTS)}")
    return importlib.import_module(f"experiments.{name}")


def cmd_build(args) -> int:
    from fmus.build import build_all, validate

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
    from fmus.build import validate

    path = Path(args.path)
    if not path.exists():
        raise UserError(f"{path}: no such file or directory")
    targets = sorted(path.glob("*.fmu")) if path.is_dir() else [path]
    if not targets:
        raise UserError(f"{path}: no .fmu files in this folder")
    bad = 0
    for t in targets:
        if t.suffix != ".fmu":
            raise UserError(f"{t}: not an FMU (.ssp validation comes with the SSP reader)")
        problems = validate(t)
        bad += bool(problems)
        print(f"{t}: {'OK' if not problems else f'{len(problems)} problems'}")
        for pr in problems:
            print(f"  - {pr}")
    return 1 if bad else 0


def cmd_list(args) -> int:
    for name in EXPERIMENTS:
        exp = _experiment(name)
        print(f"{name}: {exp.DESCRIPTION}")
        for v in exp.VARIANTS:
            print(f"  {v}{' (default)' if v == exp.DEFAULT_VARIANT else ''}")
    return 0


def _parse_set(items: list[str]) -> dict[str, dict[str, float | str]]:
    out: dict[str, dict[str, float | str]] = {}
    for item in items:
        key, sep, value = item.partition("=")
        comp, dot, param = key.partition(".")
        if not sep or not dot or not comp or not param or not value:
            raise UserError(f"--set {item!r}: expected COMPONENT.PARAM=VALUE")
        try:
            parsed: float | str = float(value)
        except ValueError:
            parsed = value
        out.setdefault(comp, {})[param] = parsed
    return out


def cmd_run(args) -> int:
    from fmus.build import DEFAULT_OUT, build_all
    from fmus.cosim import simulate

    exp = _experiment(args.experiment)
    variant = args.variant or exp.DEFAULT_VARIANT
    if variant not in exp.VARIANTS:
        raise UserError(f"experiment {args.experiment}: unknown variant {variant!r}; "
                        f"known: {', '.join(exp.VARIANTS)}")
    build_all(DEFAULT_OUT)
    components, connections, record = exp.system(DEFAULT_OUT, variant)
    by_name = {c.name: c for c in components}
    for comp, params in _parse_set(args.set or []).items():
        if comp not in by_name:
            raise UserError(f"--set: unknown component {comp!r}; components: {', '.join(by_name)}")
        by_name[comp].parameters.update(params)
    if args.seed is not None:
        by_name["track"].parameters["seed"] = args.seed
    stop = exp.STOP_TIME if args.stop_time is None else args.stop_time
    step = exp.STEP_SIZE if args.step_size is None else args.step_size
    for flag, value in (("--stop-time", stop), ("--step-size", step)):
        if not (value > 0 and math.isfinite(value)):
            raise UserError(f"{flag} {value:g}: must be a positive number of seconds")
    out = Path(args.out or f"out/{args.experiment}/{variant}")
    out.mkdir(parents=True, exist_ok=True)
    print(f"running {args.experiment}/{variant}: {stop:g} s at {step:g} s -> {out}", file=sys.stderr)
    t0 = time.monotonic()
    data = simulate(components, connections, stop, step, out_csv=out / "signals.csv", record=record)
    wall = time.monotonic() - t0
    metrics = {"experiment": args.experiment, "variant": variant, "stop_time_s": stop, "step_size_s": step,
               "wall_time_s": wall, "realtime_factor": stop / wall,
               "rms": {k: math.sqrt(sum(x * x for x in v) / len(v)) for k, v in data.items() if k != "time"}}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    _plot(exp, data, out)
    lines = [f"# {args.experiment} / {variant}", "", exp.DESCRIPTION, "",
             f"{stop:g} s at a {step:g} s communication step, Jacobi master, {wall:.2f} s wall time.", "",
             "| signal | rms |", "|---|---|"]
    lines += [f"| {k} | {v:.4g} |" for k, v in metrics["rms"].items()]
    lines += ["", *[f"![{f}]({f})" for f in exp.PLOTS]]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out}/signals.csv, metrics.json, report.md, {', '.join(exp.PLOTS)}")
    return 0


def _plot(exp, data, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for fname, (title, axes_spec) in exp.PLOTS.items():
        fig, axes = plt.subplots(len(axes_spec), 1, figsize=(9, 2.4 * len(axes_spec)), sharex=True,
                                 squeeze=False)
        for ax, signals in zip(axes[:, 0], axes_spec):
            for sig, label in signals:
                ax.plot(data["time"], data[sig], lw=0.8, label=label)
            if len(signals) > 1:
                ax.legend(fontsize=8, loc="upper right")
                ax.set_ylabel(f"[{_unit(sig)}]", fontsize=8)
            else:
                ax.set_ylabel(signals[0][1], fontsize=8)
            ax.grid(alpha=0.3)
        axes[0, 0].set_title(title)
        axes[-1, 0].set_xlabel("time [s]")
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)


def _unit(signal: str) -> str:
    """Unit of 'component.variable' from the model definitions (for axis labels)."""
    from models import all_models

    var = signal.split(".", 1)[1]
    for model in all_models():
        try:
            return model.variable(var).unit or "-"
        except KeyError:
            continue
    return "?"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="railfmu", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("build", help="compile all FMUs")
    p.add_argument("--out", default=None, help="output folder (default build/fmus)")
    p.add_argument("--force", action="store_true", help="rebuild even if unchanged")
    p.set_defaults(fn=cmd_build)
    p = sub.add_parser("validate", help="validate an FMU (or every FMU in a folder)")
    p.add_argument("path")
    p.set_defaults(fn=cmd_validate)
    p = sub.add_parser("list", help="experiments and their variants")
    p.set_defaults(fn=cmd_list)
    p = sub.add_parser("run", help="run one experiment")
    p.add_argument("experiment")
    p.add_argument("--variant")
    p.add_argument("--out")
    p.add_argument("--set", action="append", metavar="COMPONENT.PARAM=VALUE")
    p.add_argument("--seed", type=int)
    p.add_argument("--stop-time", type=float)
    p.add_argument("--step-size", type=float)
    p.set_defaults(fn=cmd_run)
    args = ap.parse_args(argv)
    if args.command == "build" and args.out is None:
        from fmus.build import DEFAULT_OUT

        args.out = DEFAULT_OUT
    try:
        return args.fn(args)
    except UserError as exc:
        print(f"railfmu: error: {exc}", file=sys.stderr)
        return 2
    except BuildError as exc:  # our generated C or the machine's compiler: not the user's input
        print(f"railfmu: build failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("railfmu: interrupted (partial results stay in the output folder)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
