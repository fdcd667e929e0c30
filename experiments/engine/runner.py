"""One experiment run: SSP -> system -> master + recorder + observers -> metrics, plots, report.

An experiment is a folder under ``experiments/`` with ``SystemStructure.ssd`` and
``variants/*.ssv``; its ``__init__.py`` exports ``STUDY``, its
:class:`railfmu.experiments.engine.study_protocol.Study` (signal roles, default variant, metrics, figures,
report section, study table). ``railfmu run`` also accepts any SSP (a ``.ssp`` archive, an
``.ssd`` file or a folder), which gets the default ``Study()``: every recorded signal plotted,
every observer's raw error reported.
"""

from __future__ import annotations

import importlib
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from railfmu.estimators.track.metrics import rms
from railfmu.models.errors import UserError

from railfmu.experiments.engine.study_protocol import RunData, Study

HERE = Path(__file__).resolve().parents[1]  # experiments/: one folder per study
DEFAULT_MASTER = "jacobi"  # when neither the command line nor the experiment (rf:FixedStep master=) names one


def experiment_names() -> list[str]:
    return sorted(p.parent.name for p in HERE.glob("*/SystemStructure.ssd"))


@dataclass
class Experiment:
    name: str
    path: Path  # folder, .ssd or .ssp
    study: Study = field(default_factory=Study)
    variants: list[str] = field(default_factory=list)
    packaged: bool = False  # a folder of experiments/ (workers find it by name)

    @property
    def default_variant(self) -> str | None:
        # an SSP given by path runs as its SSD says unless a variant is asked for
        return self.study.default_variant

    @property
    def description(self) -> str:
        return self.study.description or self.name


def find_experiment(name: str) -> Experiment:
    """An experiment by name (a folder of experiments/) or by path to any SSP."""
    from railfmu.fmus.ssp import list_variants

    if name in experiment_names():
        study = importlib.import_module(f"railfmu.experiments.{name}").STUDY  # the package's protocol
        return Experiment(name, HERE / name, study, list_variants(HERE / name), packaged=True)
    path = Path(name)
    if path.exists():
        # named after what holds the SSD: experiments/x/SystemStructure.ssd is "x", a.ssp is "a"
        label = path.resolve().parent.name if path.name == "SystemStructure.ssd" else path.stem
        return Experiment(label or path.stem, path, Study(), list_variants(path))
    known = ", ".join(experiment_names())
    raise UserError(f"unknown experiment {name!r}; known: {known} (or give the path of an .ssp/.ssd)")


def load_system(exp: Experiment, variant: str | None, sets: dict | None = None, seed: int | None = None,
                stop_time: float | None = None, step_size: float | None = None):
    """The experiment's system with its FMUs built, the variant applied and command-line overrides."""
    from railfmu.fmus.generate.build import build_all, default_out
    from railfmu.fmus.ssp import read_system

    if variant is not None and variant not in exp.variants:
        raise UserError(f"experiment {exp.name}: unknown variant {variant!r}; "
                        f"known: {', '.join(exp.variants) or '(none)'}")
    for flag, value in (("--stop-time", stop_time), ("--step-size", step_size)):
        if value is not None and not (value > 0 and math.isfinite(value)):
            raise UserError(f"{flag} {value:g}: must be a positive number of seconds")
    build_all(default_out())
    overrides = {c: dict(p) for c, p in (sets or {}).items()}
    system = read_system(exp.path, variant=variant, fmu_dirs=[default_out()], overrides=overrides,
                         stop_time=stop_time, step_size=step_size)
    if seed is not None:  # every random source of the system (track profile, sensor noise) takes it
        seeded = [c for c in system.components if "seed" in c.variables]
        if not seeded:
            raise UserError(f"--seed: no component of {exp.name} has a 'seed' parameter")
        for c in seeded:
            c.parameters["seed"] = seed
    return system


def run_experiment(name: str, variant: str | None = None, out: Path | str | None = None,
                   master: str | None = None, sets: dict | None = None, seed: int | None = None,
                   stop_time: float | None = None, step_size: float | None = None,
                   progress: bool = True, log=sys.stderr, write_files: bool = True,
                   series: bool = False) -> dict:
    """Run one variant; writes signals.csv, estimates.csv, metrics.json, plots, report.md into
    ``out`` and returns the metrics. With ``write_files=False`` (a Monte Carlo member) it
    writes nothing and imports no plotting: the metrics are the result. ``series``: the
    returned metrics carry the study's per-run arrays under ``"series"`` (not in metrics.json)
    for its Monte Carlo figures (:meth:`Study.series`). ``master`` None: the one the experiment
    prefers (``<rf:FixedStep master=...>`` in its SSD, :attr:`System.master`), else ``jacobi``."""
    from railfmu.fmus.cosim.masters import MASTERS, run
    from railfmu.experiments.engine.recorder import CsvRecorder

    from railfmu.experiments.engine.observer_bank import ObserverBank

    t_setup = time.perf_counter()
    if master is not None and master not in MASTERS:
        raise UserError(f"--master {master!r}: choose one of {', '.join(MASTERS)}")
    exp = find_experiment(name)
    variant = variant or exp.default_variant
    out = Path(out or Path("out") / exp.name / (variant or "default"))
    if write_files and out.exists() and not out.is_dir():
        raise UserError(f"--out {out}: a file of that name exists; give a folder")
    system = load_system(exp, variant, sets, seed, stop_time, step_size)
    master = master or system.master or DEFAULT_MASTER
    roles = exp.study.bind(system)
    if write_files:
        out.mkdir(parents=True, exist_ok=True)
    for w in system.warnings:
        print(f"railfmu: warning: {w}", file=log)
    until = f" (to {system.stop_time:g} s from {system.stop_time_from})" if system.stop_time_from != "ssd:DefaultExperiment" else ""
    print(f"running {_what_runs(exp, system, variant)}: {system.stop_time - system.start_time:g} s{until} at "
          f"{system.step_size:g} s (from {system.step_size_from}), {master} master"
          + (f" -> {out}" if write_files else ""), file=log)

    recorder = CsvRecorder(out / "signals.csv", types=system.signal_types()) if write_files else None
    bank = ObserverBank(system, out / "estimates.csv" if write_files else None)
    setup_s = time.perf_counter() - t_setup
    try:
        result = run(system, master=master, sinks=[s for s in (recorder, bank) if s is not None], progress=progress)
    except UserError as exc:
        if recorder is None or recorder.rows_written == 0:  # nothing (or a bare header) written: cite no file
            raise
        raise UserError(f"{exc} (partial results: {out / 'signals.csv'}, {recorder.rows_written} rows "
                        f"up to t = {recorder.last_time:g} s)") from None
    except KeyboardInterrupt:
        if recorder is not None:
            t = recorder.last_time
            print(f"railfmu: interrupted at t = {t if t is not None else 0:g} s; {out / 'signals.csv'} "
                  f"holds {recorder.rows_written} complete rows", file=log)
        raise

    signals = {c: result.data[:, j] for j, c in enumerate(result.columns)}
    observers = bank.estimators()
    t_est, est = bank.arrays()
    estimates = {"time": t_est, **{c: est[:, j] for j, c in enumerate(bank.columns)}, **bank.offline_estimates()}
    if result.early_end:
        kept = f"; {out / 'signals.csv'} holds every row up to t = {result.end_time:g} s" if recorder else ""
        print(f"railfmu: early end: {result.early_end}{kept}", file=log)
    simulated = result.end_time - system.start_time
    metrics = {
        "experiment": exp.name, "variant": variant, "master": master, "seed": seed,
        "start_time_s": system.start_time, "stop_time_s": system.stop_time, "step_size_s": system.step_size,
        "step_size_from": system.step_size_from, "stop_time_from": system.stop_time_from,
        "end_time_s": result.end_time, "early_end": result.early_end,
        "simulated_seconds": simulated,
        "wall_time_s": result.wall_time_s,
        "realtime_factor": simulated / result.wall_time_s,
        "parameters": {c.name: c.parameters for c in system.components},
        "observer_settings": {o.name: o.settings for o in system.observers},
        "rms": {k: rms(v) for k, v in signals.items() if k != "time"},
        "observers": bank.metrics(signals),
        "roles": roles,  # what the study read where (study_protocol.Role)
        "warnings": system.warnings,
        "notes": result.notes,
    }
    t_study = time.perf_counter()
    metrics.update(exp.study.metrics(RunData(signals, estimates, metrics, roles, observers)))
    # where a run's time goes (benchmarks/overhead.py): stepping includes the online observers
    metrics["timing_s"] = {"setup": setup_s, "stepping": result.wall_time_s,
                           "study_metrics": time.perf_counter() - t_study}
    arrays = exp.study.series(RunData(signals, estimates, metrics, roles, observers)) if series else {}
    if write_files:
        (out / "metrics.json").write_text(json.dumps(metrics, indent=2, default=_json_default) + "\n")
    if arrays:
        metrics = {**metrics, "series": arrays}
    if not write_files:
        return metrics
    files = exp.study.files(RunData(signals, estimates, metrics, roles, observers), out)

    from railfmu.experiments.engine.plots import plot_estimates, plot_signals, units_of

    position = roles.get(exp.study.x_axis) if exp.study.x_axis != "time" else None
    units = units_of(system)
    plots = (plot_signals(exp.study.figures_of_signals, signals, roles, units, out, position)
             + plot_estimates(bank, signals, units, out)
             + exp.study.figures(RunData(signals, estimates, metrics, roles, observers), out))
    _report(exp, system, metrics, plots, out)
    offline = [f"estimates_{name}.csv" for name in bank.results]
    print(f"wrote {out}/: {', '.join(['signals.csv', 'estimates.csv', *offline, *files, 'metrics.json', 'report.md', *plots])}",
          file=log)
    return metrics


def _what_runs(exp: Experiment, system, variant: str | None) -> str:
    """``track_wheelset, variant psd`` for an experiment of experiments/; for an SSP given by
    path its system's name and the path."""
    what = exp.name if exp.packaged else f"system {system.name!r} of {exp.path}"
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
    section = exp.study.report_md(metrics)
    if section:
        L += ["", section]
    L += ["", "## Signals (rms)", "", "| signal | rms |", "|---|---|"]
    L += [f"| {k} | {v:.4g} |" for k, v in metrics["rms"].items()]
    if metrics["warnings"] or metrics["notes"]:
        L += ["", "## Notes", ""] + [f"- {w}" for w in metrics["warnings"] + metrics["notes"]]
    L += ["", *[f"![{p}]({p})" for p in plots]]
    (out / "report.md").write_text("\n".join(L) + "\n")
