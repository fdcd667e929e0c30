"""One experiment run: SSP -> system -> master + recorder + observers -> metrics, plots, report.

An experiment is a folder under ``experiments/`` with ``SystemStructure.ssd`` and
``variants/*.ssv``; its ``__init__.py`` exports ``STUDY``, its
:class:`railfmu.experiments.engine.study_protocol.Study` (signal roles, default variant, metrics, figures,
report section, study table). ``railfmu run`` also accepts any SSP (a ``.ssp`` archive, an
``.ssd`` file or a folder), which gets the default ``Study()``: every recorded signal plotted,
every observer's raw error reported.
"""

from __future__ import annotations

import difflib
import sys
import time
import warnings as _warnings
from collections.abc import Callable
from pathlib import Path
from typing import TextIO


from railfmu.estimators.track.metrics import rms
from railfmu.models.errors import UserError

from railfmu.experiments.engine.files import check_seed, check_times, ensure_folder
from railfmu.experiments.engine.result import Run, abandon_ahead, figures_ahead, json_default as _json_default
from railfmu.experiments.engine.studies import HERE, Experiment, experiment_names, study_named, study_names
from railfmu.experiments.engine.study_protocol import RunData, Study

__all__ = ["Experiment", "experiment_names", "find_experiment", "load_system", "execute", "run_experiment",
           "HERE", "_json_default"]

DEFAULT_MASTER = "jacobi"  # when neither the command line nor the experiment (rf:FixedStep master=) names one


def find_experiment(name: str | Path) -> Experiment:
    """An experiment by name (a folder of experiments/) or by path to any SSP; its study is
    the one its SSD names (:mod:`railfmu.experiments.engine.studies`), else ``Study()``."""
    from railfmu.fmus.ssp import list_variants

    if str(name) in experiment_names():
        exp = Experiment(str(name), HERE / str(name), packaged=True)
    elif Path(name).exists():
        path = Path(name)
        # named after what holds the SSD: experiments/x/SystemStructure.ssd is "x", a.ssp is "a"
        label = path.resolve().parent.name if path.name == "SystemStructure.ssd" else path.stem
        exp = Experiment(label or path.stem, path)
    else:
        known = ", ".join(experiment_names())
        close = difflib.get_close_matches(str(name), experiment_names(), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UserError(f"unknown experiment {str(name)!r}{hint}; known: {known} (or give the path of an .ssp/.ssd)")
    exp.variants = list_variants(exp.path)
    exp.study, exp.study_name, exp.warnings = _study_of(exp.path)
    return exp


def _study_of(path: Path) -> tuple[Study, str | None, list[str]]:
    """The study the SSD at ``path`` names, its name, and a warning when there is none."""
    from railfmu.fmus.ssp import study_name

    name = study_name(path)
    if name is None and Path(path).suffix.lower() == ".fmu":
        return Study(), None, []  # a single FMU names no study: plain metrics, nothing to warn about
    if name is None:
        return Study(), None, [f"{path}: the SSD names no study (no org.railfmu.study annotation): "
                               "plain SSP metrics only"]
    study = study_named(name)
    if study is None:
        return Study(), None, [f"{path}: the SSD names study {name!r}, which is not registered (known: "
                               f"{', '.join(study_names())}): plain SSP metrics only"]
    return study, name, []


def load_system(exp: Experiment, variant: str | None, sets: dict | None = None, seed: int | None = None,
                stop_time: float | None = None, step_size: float | None = None, fmi_version: int = 2):
    """The experiment's system with its FMUs built (FMI ``fmi_version``, 2 or 3), the variant
    applied and command-line overrides."""
    from railfmu.fmus.generate.build import build_all, default_out
    from railfmu.fmus.ssp import read_system

    if variant is not None and variant not in exp.variants:
        close = difflib.get_close_matches(variant, exp.variants, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UserError(f"experiment {exp.name}: unknown variant {variant!r}{hint}; "
                        f"known: {', '.join(exp.variants) or '(none)'}")
    check_seed(seed)
    check_times(stop_time, step_size)
    if fmi_version not in (2, 3):
        raise UserError(f"--fmi {fmi_version!r}: railfmu builds FMI 2.0 and 3.0 FMUs (2 or 3)")
    build_all(default_out(fmi_version), fmi_version=fmi_version)
    overrides = {c: dict(p) for c, p in (sets or {}).items()}
    system = read_system(exp.path, variant=variant, fmu_dirs=[default_out(fmi_version)], overrides=overrides,
                         stop_time=stop_time, step_size=step_size)
    if seed is not None:  # every random source of the system (track profile, sensor noise) takes it
        seeded = [c for c in system.components if "seed" in c.variables]
        if not seeded:
            raise UserError(f"--seed: no component of {exp.name} has a 'seed' parameter")
        for c in seeded:
            c.parameters["seed"] = seed
    system.warnings[:0] = exp.warnings  # printed with the reader's, kept in metrics.json and the report
    from railfmu.experiments.engine.replay import shape_replays

    # a replay's file sets the stop time, step, time shift and observer periods (unless the user did)
    system.replay = shape_replays(system, exp.study)
    return system


def execute(name: str | Path, variant: str | None = None, out: Path | str | None = None,
            master: str | None = None, sets: dict | None = None, seed: int | None = None,
            stop_time: float | None = None, step_size: float | None = None, progress: bool = True,
            log: TextIO | None = sys.stderr, warn: Callable[[str], None] | None = None,
            series: bool = False, verbose: bool = False, fmi_version: int = 2,
            record_format: str = "csv", sampling: str = "after-transfer", figures: bool = False) -> Run:
    """Run one variant in memory and return the :class:`Run`. ``out``: stream signals.csv and
    estimates.csv into that folder as the run goes (an interrupted run keeps its complete
    rows); the other files are :meth:`Run.save`'s. ``log``: the progress lines (None: none);
    ``warn``: each warning line (default: printed to ``log``, else :func:`warnings.warn`).
    ``series``: keep the study's per-run arrays (:meth:`Study.series`) in ``Run.series``.
    ``master`` None: the one the experiment prefers (``<rf:FixedStep master=...>``), else jacobi.
    ``fmi_version``: run railfmu's own FMUs as FMI 2.0 (default) or 3.0 builds; an SSP's
    packed FMUs run as they are. ``record_format``: csv, parquet or mat for the signals and
    estimates (:mod:`railfmu.experiments.engine.records`). ``sampling``: when the rows are
    read (:func:`railfmu.fmus.cosim.masters.run`). ``figures``: the caller will
    :meth:`Run.save` the run; a running figure worker draws the engine's figures while the
    study scores the run (:func:`railfmu.experiments.engine.result.figures_ahead`)."""
    from railfmu.fmus.cosim.masters import MASTERS, SAMPLINGS, run
    from railfmu.experiments.engine import records

    from railfmu.experiments.engine.observer_bank import ObserverBank

    if warn is None:
        warn = (lambda line: print(line, file=log)) if log is not None else _python_warning
    say = (lambda line: print(line, file=log)) if log is not None else (lambda line: None)
    t_setup = time.perf_counter()
    records.check_format(record_format)
    if master is not None and master not in MASTERS:
        raise UserError(f"--master {master!r}: choose one of {', '.join(MASTERS)}")
    if sampling not in SAMPLINGS:
        raise UserError(f"--sampling {sampling!r}: choose one of {', '.join(SAMPLINGS)}")
    if sampling != "after-transfer" and master not in (None, "jacobi"):
        raise UserError(f"--sampling {sampling}: only the Jacobi master reads its rows before the transfer "
                        f"(the {master} master samples after it); use --master jacobi")
    exp = find_experiment(name)
    if figures and exp.study.figures_from_run:  # the figure worker imports them while the run steps
        from railfmu.experiments.engine.figure_worker import prefetch

        prefetch((*exp.study.figure_imports, type(exp.study).__module__))
    variant = variant or exp.default_variant
    out = Path(out) if out is not None else None
    if out is not None and out.exists() and not out.is_dir():
        raise UserError(f"--out {out}: a file of that name exists; give a folder")
    system = load_system(exp, variant, sets, seed, stop_time, step_size, fmi_version)
    # the rows read before the transfer are the Jacobi master's alone, whatever the SSD prefers
    master = master or ("jacobi" if sampling != "after-transfer" else system.master) or DEFAULT_MASTER
    roles = exp.study.bind(system)
    if out is not None:
        ensure_folder(out)
    for w in system.warnings:
        warn(f"railfmu: warning: {w}")
    until = f" (to {system.stop_time:g} s from {system.stop_time_from})" if system.stop_time_from != "ssd:DefaultExperiment" else ""
    say(f"running {_what_runs(exp, system, variant)}: {system.stop_time - system.start_time:g} s{until} at "
        f"{system.step_size:g} s (from {system.step_size_from}), {master} master"
        + (f" -> {out}" if out is not None else ""))
    for name, (path, how) in system.files.items():
        say(f"  {name} = {path} ({how})")
    for note in system.notes:
        say(f"  {note}")
    if verbose:
        say(f"  study: {exp.study_name or '(plain SSP)'} ({type(exp.study).__name__}); SSD {exp.path}")
        for c in system.components:
            say(f"  component {c.name}: {c.fmu}; {len(c.parameters)} parameters set")
        for o in system.observers:
            say(f"  observer {o.name}: {o.cls}{' (offline)' if o.offline else ''}"
                f"{'' if o.enabled else ' (switched off)'}")

    signals_file = records.record_path(out, "signals", record_format) if out is not None else None
    recorder = records.recorder(signals_file, record_format, types=system.signal_types()) if out is not None else None
    bank = ObserverBank(system, records.record_path(out, "estimates", record_format) if out is not None else None,
                        record_format)
    setup_s = time.perf_counter() - t_setup
    try:
        result = run(system, master=master, sinks=[s for s in (recorder, bank) if s is not None], progress=progress,
                     sampling=sampling)
    except UserError as exc:
        if recorder is None or recorder.rows_written == 0:  # nothing (or a bare header) written: cite no file
            raise
        raise UserError(f"{exc} (partial results: {signals_file}, {recorder.rows_written} rows "
                        f"up to t = {recorder.last_time:g} s)") from None
    except KeyboardInterrupt:
        if recorder is not None:
            t = recorder.last_time
            warn(f"railfmu: interrupted at t = {t if t is not None else 0:g} s; {signals_file} "
                 f"holds {recorder.rows_written} complete rows")
        raise

    if result.master != master:  # the container hands systems it cannot take to jacobi: say why
        say(f"  {result.notes[0]}")
    signals = {c: result.data[:, j] for j, c in enumerate(result.columns)}
    observers = bank.estimators()
    t_est, est = bank.arrays()
    estimates = {"time": t_est, **{c: est[:, j] for j, c in enumerate(bank.columns)}, **bank.offline_estimates()}
    early_end, notes = result.early_end, list(system.notes) + list(result.notes)
    if sampling != "after-transfer":
        notes.append(f"sampling {sampling}: each row read right after the step, before the connections are copied")
    ends = [c for c, f in (getattr(system, "replay", None) or {}).get("files", {}).items() if f["ends_run"]]
    if early_end and any(f"({c})" in early_end for c in ends):  # a replay's last row: its normal end
        notes = [n for n in notes if n != early_end] + [f"the run ended at the replay's last row: {early_end}"]
        early_end = None
    if early_end:
        kept = f"; {signals_file} holds every row up to t = {result.end_time:g} s" if recorder else ""
        warn(f"railfmu: early end: {result.early_end}{kept}")
    simulated = result.end_time - system.start_time
    metrics = {
        "experiment": exp.name, "variant": variant, "master": master, "seed": seed,
        "start_time_s": system.start_time, "stop_time_s": system.stop_time, "step_size_s": system.step_size,
        "step_size_from": system.step_size_from, "stop_time_from": system.stop_time_from,
        "end_time_s": result.end_time, "early_end": early_end,
        "simulated_seconds": simulated,
        "wall_time_s": result.wall_time_s,
        "realtime_factor": simulated / result.wall_time_s,
        "parameters": {c.name: c.parameters for c in system.components},
        "observer_settings": {o.name: o.settings for o in system.observers},
        "rms": {k: rms(v) for k, v in signals.items() if k != "time"},
        "observers": bank.metrics(signals),
        "roles": roles,  # what the study read where (study_protocol.Role)
        "warnings": system.warnings,
        "notes": notes,
    }
    if getattr(system, "replay", None):
        metrics["replay"] = {**system.replay, "given": {k: {"path": p, "how": h} for k, (p, h) in system.files.items()},
                             "derived": list(system.notes)}
        _unscore(metrics["observers"], system, system.replay.get("unscored", []))
    elif system.files:
        metrics["files"] = {k: {"path": p, "how": h} for k, (p, h) in system.files.items()}
    data = RunData(signals, estimates, metrics, roles, observers)
    ahead = figures_ahead(exp, system, data, bank) if figures else None
    t_study = time.perf_counter()
    try:
        metrics.update(exp.study.metrics(data))
    except BaseException:  # no Run will take the figures handed ahead: the worker's replies are not kept
        abandon_ahead(ahead)
        raise
    from railfmu.experiments.engine.replay import learned_nothing

    for w in learned_nothing(metrics["observers"]):  # said in the heading's warnings, not only deep in the JSON
        metrics["warnings"].append(w)
        warn(f"railfmu: warning: {w}")
    # where a run's time goes (benchmarks/overhead.py): stepping includes the online observers
    metrics["timing_s"] = {"setup": setup_s, "stepping": result.wall_time_s,
                           "study_metrics": time.perf_counter() - t_study}
    arrays = exp.study.series(RunData(signals, estimates, metrics, roles, observers)) if series else {}
    if verbose:
        say(f"  timing: setup {setup_s:.2f} s, stepping {result.wall_time_s:.2f} s, study metrics "
            f"{metrics['timing_s']['study_metrics']:.2f} s")
    return Run(exp, system, variant, master, result.columns, result.data, bank, data, arrays, streamed=out,
               record_format=record_format, ahead=ahead)


def _unscore(observers: dict, system, unscored: list[str]) -> None:
    """Null every score against a truth signal of a replay too short for one."""
    for spec in system.observers:
        m = observers.get(spec.name)
        if m is None:
            continue
        for est, sig in spec.truth.items():
            if sig.partition(".")[0] in unscored and isinstance(m.get(est), dict):
                m[est] = {k: None for k in m[est]} | {"unscored": f"{sig.partition('.')[0]}.file is too short"}


def _python_warning(line: str) -> None:
    _warnings.warn(line.removeprefix("railfmu: warning: ").removeprefix("railfmu: "), RuntimeWarning, stacklevel=4)


def run_experiment(name: str, variant: str | None = None, out: Path | str | None = None,
                   master: str | None = None, sets: dict | None = None, seed: int | None = None,
                   stop_time: float | None = None, step_size: float | None = None,
                   progress: bool = True, log=sys.stderr, write_files: bool = True,
                   series: bool = False) -> dict:
    """Run one variant; writes signals.csv, estimates.csv, metrics.json, plots, report.md into
    ``out`` (default ``out/EXP/VARIANT``) and returns the metrics. With ``write_files=False``
    (a Monte Carlo member) it writes nothing and imports no plotting: the metrics are the
    result. ``series``: the returned metrics carry the study's per-run arrays under
    ``"series"`` (not in metrics.json) for its Monte Carlo figures (:meth:`Study.series`).
    The engine of :func:`railfmu.run` (:func:`execute`) with the command line's defaults."""
    if write_files and out is None:
        exp = find_experiment(name)
        out = Path("out") / exp.name / (variant or exp.default_variant or "default")
    if write_files:  # the figures' worker imports matplotlib while the run sets up and steps
        from railfmu.experiments.engine.figure_worker import start

        start()
    r = execute(name, variant, out if write_files else None, master, sets, seed, stop_time, step_size,
                progress=progress, log=log, series=series, figures=write_files)
    if write_files:
        r.save(out, log=log)
    return {**r.metrics, "series": r.series} if r.series else r.metrics

def _what_runs(exp: Experiment, system, variant: str | None) -> str:
    """``track_wheelset, variant psd`` for an experiment of experiments/; for an SSP given by
    path its system's name and the path."""
    what = exp.name if exp.packaged else f"system {system.name!r} of {exp.path}"
    return f"{what}, {f'variant {variant}' if variant else 'no variant'}"
