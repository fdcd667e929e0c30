"""One experiment run: SSP -> system -> master + recorder + observers -> metrics, plots, report.

An experiment is a folder under ``experiments/`` with ``SystemStructure.ssd`` and
``variants/*.ssv``; its ``__init__.py`` may add plots (``PLOTS``), a default variant
(``DEFAULT_VARIANT``), study metrics (``metrics(signals, estimates, base) -> dict``; it may add
offline estimates, e.g. a smoother's, to ``estimates`` for the figures), its own
figures (``plots(signals, estimates, out, metrics) -> [files]``), a report section
(``report_md(metrics) -> str``) and a study table (``table_md(table) -> str``).
``railfmu run`` also accepts any SSP (a ``.ssp`` archive, an ``.ssd`` file or a folder):
then every recorded signal is plotted.
"""

from __future__ import annotations

import importlib
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from fmus.errors import UserError

HERE = Path(__file__).resolve().parent


def experiment_names() -> list[str]:
    return sorted(p.parent.name for p in HERE.glob("*/SystemStructure.ssd"))


@dataclass
class Experiment:
    name: str
    path: Path  # folder, .ssd or .ssp
    module: ModuleType | None = None
    variants: list[str] = field(default_factory=list)

    @property
    def default_variant(self) -> str | None:
        # an SSP given by path runs as its SSD says unless a variant is asked for
        return getattr(self.module, "DEFAULT_VARIANT", None)

    @property
    def description(self) -> str:
        doc = (self.module.__doc__ or "").strip() if self.module else ""
        return doc.splitlines()[0] if doc else self.name


def find_experiment(name: str) -> Experiment:
    """An experiment by name (a folder of experiments/) or by path to any SSP."""
    from fmus.ssp import list_variants

    if name in experiment_names():
        module = importlib.import_module(f"experiments.{name}")
        return Experiment(name, HERE / name, module, list_variants(HERE / name))
    path = Path(name)
    if path.exists():
        # named after what holds the SSD: experiments/x/SystemStructure.ssd is "x", a.ssp is "a"
        label = path.resolve().parent.name if path.name == "SystemStructure.ssd" else path.stem
        return Experiment(label or path.stem, path, None, list_variants(path))
    known = ", ".join(experiment_names())
    raise UserError(f"unknown experiment {name!r}; known: {known} (or give the path of an .ssp/.ssd)")


def load_system(exp: Experiment, variant: str | None, sets: dict | None = None, seed: int | None = None,
                stop_time: float | None = None, step_size: float | None = None):
    """The experiment's system with its FMUs built, the variant applied and command-line overrides."""
    from fmus.generate.build import DEFAULT_OUT, build_all
    from fmus.ssp import read_system

    if variant is not None and variant not in exp.variants:
        raise UserError(f"experiment {exp.name}: unknown variant {variant!r}; "
                        f"known: {', '.join(exp.variants) or '(none)'}")
    for flag, value in (("--stop-time", stop_time), ("--step-size", step_size)):
        if value is not None and not (value > 0 and math.isfinite(value)):
            raise UserError(f"{flag} {value:g}: must be a positive number of seconds")
    build_all(DEFAULT_OUT)
    overrides = {c: dict(p) for c, p in (sets or {}).items()}
    system = read_system(exp.path, variant=variant, fmu_dirs=[DEFAULT_OUT], overrides=overrides,
                         stop_time=stop_time, step_size=step_size)
    if seed is not None:  # every random source of the system (track profile, sensor noise) takes it
        seeded = [c for c in system.components if "seed" in c.variables]
        if not seeded:
            raise UserError(f"--seed: no component of {exp.name} has a 'seed' parameter")
        for c in seeded:
            c.parameters["seed"] = seed
    return system


def run_experiment(name: str, variant: str | None = None, out: Path | str | None = None,
                   master: str = "jacobi", sets: dict | None = None, seed: int | None = None,
                   stop_time: float | None = None, step_size: float | None = None,
                   progress: bool = True, log=sys.stderr) -> dict:
    """Run one variant; writes signals.csv, estimates.csv, metrics.json, plots, report.md into
    ``out`` and returns the metrics."""
    from fmus.cosim.masters import MASTERS, run
    from fmus.cosim.recorder import CsvRecorder

    from .observers import ObserverBank

    if master not in MASTERS:
        raise UserError(f"--master {master!r}: choose one of {', '.join(MASTERS)}")
    exp = find_experiment(name)
    variant = variant or exp.default_variant
    out = Path(out or Path("out") / exp.name / (variant or "default"))
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out}: a file of that name exists; give a folder")
    system = load_system(exp, variant, sets, seed, stop_time, step_size)
    out.mkdir(parents=True, exist_ok=True)
    for w in system.warnings:
        print(f"railfmu: warning: {w}", file=log)
    print(f"running {_what_runs(exp, system, variant)}: {system.stop_time - system.start_time:g} s at "
          f"{system.step_size:g} s (from {system.step_size_from}), {master} master -> {out}", file=log)

    recorder = CsvRecorder(out / "signals.csv", types=system.signal_types())
    bank = ObserverBank(system, out / "estimates.csv")
    try:
        result = run(system, master=master, sinks=[recorder, bank], progress=progress)
    except UserError as exc:
        if recorder.rows_written == 0:  # nothing (or a bare header) written: cite no file
            raise
        raise UserError(f"{exc} (partial results: {out / 'signals.csv'}, {recorder.rows_written} rows "
                        f"up to t = {recorder.last_time:g} s)") from None
    except KeyboardInterrupt:
        t = recorder.last_time
        print(f"railfmu: interrupted at t = {t if t is not None else 0:g} s; {out / 'signals.csv'} "
              f"holds {recorder.rows_written} complete rows", file=log)
        raise

    signals = {c: result.data[:, j] for j, c in enumerate(result.columns)}
    t_est, est = bank.arrays()
    estimates = {"time": t_est, **{c: est[:, j] for j, c in enumerate(bank.columns)}}
    if result.early_end:
        print(f"railfmu: early end: {result.early_end}; {out / 'signals.csv'} holds every row up to "
              f"t = {result.end_time:g} s", file=log)
    simulated = result.end_time - system.start_time
    metrics = {
        "experiment": exp.name, "variant": variant, "master": master,
        "start_time_s": system.start_time, "stop_time_s": system.stop_time, "step_size_s": system.step_size,
        "step_size_from": system.step_size_from,
        "end_time_s": result.end_time, "early_end": result.early_end,
        "simulated_seconds": simulated,
        "wall_time_s": result.wall_time_s,
        "realtime_factor": simulated / result.wall_time_s,
        "parameters": {c.name: c.parameters for c in system.components},
        "observer_settings": {o.name: o.settings for o in system.observers},
        "rms": {k: float(np.sqrt(np.mean(v ** 2))) for k, v in signals.items() if k != "time"},
        "observers": bank.metrics(signals),
        "warnings": system.warnings,
        "notes": result.notes,
    }
    if exp.module is not None and hasattr(exp.module, "metrics"):
        metrics.update(exp.module.metrics(signals, estimates, metrics))
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, default=_json_default) + "\n")

    from .plots import plot_estimates, plot_signals

    plots = plot_signals(exp.module, signals, out) + plot_estimates(system, bank, signals, out)
    if exp.module is not None and hasattr(exp.module, "plots"):  # the study's own figures
        plots += exp.module.plots(signals, estimates, out, metrics)
    _report(exp, system, metrics, plots, out)
    print(f"wrote {out}/: signals.csv, estimates.csv, metrics.json, report.md, {', '.join(plots)}", file=log)
    return metrics


def _what_runs(exp: Experiment, system, variant: str | None) -> str:
    """``track_wheelset, variant psd`` for an experiment of experiments/; for an SSP given by
    path its system's name and the path."""
    what = exp.name if exp.module is not None else f"system {system.name!r} of {exp.path}"
    return f"{what}, {f'variant {variant}' if variant else 'no variant'}"


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(type(x))


def _report(exp: Experiment, system, metrics: dict, plots: list[str], out: Path) -> None:
    L = [f"# {exp.name} / {metrics['variant'] or 'no variant'}", "", exp.description, "",
         (f"{metrics['simulated_seconds']:g} s at a {system.step_size:g} s communication step "
          f"(from {system.step_size_from}), "
          f"{metrics['master']} master, {metrics['wall_time_s']:.2f} s wall time "
          f"({metrics['realtime_factor']:.1f}x real time)."), ""]
    if metrics["early_end"]:
        L += [f"**Early end** at t = {metrics['end_time_s']:g} s of {system.stop_time:g} s: "
              f"{metrics['early_end']}. Every row up to that time is recorded.", ""]
    L += ["## System", "",
         "| component | FMU | parameters set |", "|---|---|---|"]
    for c in system.components:
        params = ", ".join(f"{k} = {v}" for k, v in c.parameters.items()) or "(defaults)"
        L.append(f"| {c.name} | {c.fmu.name} | {params} |")
    L += ["", "| connection | map |", "|---|---|"]
    for c in system.connections:
        L.append(f"| {c} | {'identity' if c.identity else f'{c.factor:g} x + {c.offset:g}'} |")
    if exp.module is not None and hasattr(exp.module, "report_md"):
        L += ["", exp.module.report_md(metrics)]
    for name, m in metrics["observers"].items():
        L += ["", f"## Observer `{name}`", "", "| estimate | rms error | rms truth | relative |", "|---|---|---|---|"]
        for est, v in m.items():
            if isinstance(v, dict) and "rms_error" in v:
                rel = f"{v['rel_error']:.3f}" if v["rel_error"] is not None else "-"
                L.append(f"| {est} | {v['rms_error']:.4g} | {v['rms_truth']:.4g} | {rel} |")
        L.append(f"\nErrors after t = {next((v['from_time_s'] for v in m.values() if isinstance(v, dict)), 0):g} s "
                 "(the first 10 % of the run is the filter's transient).")
    L += ["", "## Signals (rms)", "", "| signal | rms |", "|---|---|"]
    L += [f"| {k} | {v:.4g} |" for k, v in metrics["rms"].items()]
    if metrics["warnings"] or metrics["notes"]:
        L += ["", "## Notes", ""] + [f"- {w}" for w in metrics["warnings"] + metrics["notes"]]
    L += ["", *[f"![{p}]({p})" for p in plots]]
    (out / "report.md").write_text("\n".join(L) + "\n")
