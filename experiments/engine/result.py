"""The result of one run, in memory: :class:`Run` (signals, estimates, metrics, system) and
what it writes (:meth:`Run.save`: the files of ``railfmu run --out``)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from railfmu.experiments.engine.study_protocol import RunData

if TYPE_CHECKING:  # typing only
    from railfmu.experiments.engine.observer_bank import ObserverBank
    from railfmu.experiments.engine.studies import Experiment
    from railfmu.fmus.cosim.system import System

#: metrics that differ between two identical runs (wall clock)
TIMING_KEYS = ("wall_time_s", "realtime_factor", "timing_s")


def json_default(x):
    """``json.dumps`` of numpy scalars and arrays (metrics.json)."""
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(type(x))


class Run:
    """One finished run of an experiment, held in memory.

    Returned by :func:`railfmu.run`; :meth:`save` writes what ``railfmu run --out`` writes.

    Attributes
    ----------
    experiment : str
        The experiment's name (a folder of ``experiments/``, or the stem of the SSP's path).
    variant : str or None
        The variant run (None: the SSD as it is).
    master : str
        The co-simulation master used (``jacobi``, ``gauss-seidel`` or ``container``).
    system : railfmu.fmus.cosim.system.System
        The resolved system: components with their final parameters, connections, times,
        recorder and observers.
    signals : dict of str to numpy.ndarray
        ``"time"`` and every recorded signal ``"component.variable"`` (one value per
        communication step; columns of signals.csv).
    estimates : dict of str to dict of str to numpy.ndarray
        Per observer, ``"time"`` and each of its estimates, e.g.
        ``estimates["alignment"]["xi"]`` (online: estimates.csv; offline:
        estimates_NAME.csv).
    metrics : dict
        What metrics.json holds: run settings, rms of every signal, each observer's error
        against its truth and the study's metrics.
    """

    def __init__(self, exp: Experiment, system: System, variant: str | None, master: str,
                 columns: list[str], data: np.ndarray, bank: ObserverBank, run_data: RunData,
                 series: dict[str, np.ndarray] | None = None, streamed: Path | None = None,
                 record_format: str = "csv", ahead: tuple | None = None):
        self.experiment: str = exp.name
        self.variant = variant
        self.master = master
        self.system = system
        self.signals: dict[str, np.ndarray] = run_data.signals
        self.metrics: dict[str, Any] = run_data.base
        self.series = series or {}  # the study's per-run arrays (Monte Carlo figures), not saved
        self._exp, self._columns, self._data, self._bank = exp, columns, data, bank
        self._run_data = run_data
        self._streamed = streamed  # the folder signals.csv and estimates.csv were written to while running
        self.record_format = record_format  # the format they were streamed in
        self._plots: list[str] = []
        self._ahead = ahead  # (batch, file names): the engine's figures, in the worker since the stepping ended

    def __repr__(self) -> str:
        n = len(self.signals.get("time", ()))
        return (f"<Run {self.experiment}/{self.variant or 'no variant'}: {n} samples, "
                f"{len(self.signals) - 1} signals, observers {sorted(self.estimates) or '(none)'}>")

    @property
    def estimates(self) -> dict[str, dict[str, np.ndarray]]:
        """Each observer's estimates by name, with its ``"time"``; what the study added too."""
        flat = self._run_data.estimates
        bank = self._bank
        out: dict[str, dict[str, np.ndarray]] = {}
        for spec in bank.specs:
            out[spec.name] = {"time": flat["time"]}
        for name, (t, _) in bank.results.items():
            out[name] = {"time": t}
        for key, values in flat.items():
            owner, dot, est = key.partition(".")
            if dot:
                out.setdefault(owner, {})[est] = values
        return out

    def to_pandas(self) -> dict[str, Any]:
        """The signals and each observer's estimates as pandas DataFrames indexed by time.

        Returns
        -------
        dict of str to pandas.DataFrame
            ``"signals"`` and one entry per observer.

        Raises
        ------
        ImportError
            When pandas is not installed.
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("Run.to_pandas() needs pandas: pip install pandas") from None

        def frame(table: Mapping[str, np.ndarray]):
            cols = {k: v for k, v in table.items() if k != "time" and len(v) == len(table["time"])}
            return pd.DataFrame(cols, index=pd.Index(table["time"], name="time"))

        return {"signals": frame(self.signals),
                **{name: frame(t) for name, t in self.estimates.items() if "time" in t}}

    def report(self) -> str:
        """The run's report.md as markdown (figures linked once :meth:`save` has drawn them)."""
        return report_md(self._exp, self.system, self.metrics, self._plots)

    def save(self, folder: str | Path, log: TextIO | None = None, format: str | None = None) -> list[str]:
        """Write the run's files into ``folder``, as ``railfmu run --out`` does.

        Parameters
        ----------
        folder : str or pathlib.Path
            Created if missing.
        format : str, optional
            ``"csv"``, ``"parquet"`` or ``"mat"`` for the signals and estimates (default: the
            format the run streamed in, else csv); read back with :func:`railfmu.read_signals`.
        log : file, optional
            Where the ``wrote ...`` line goes (default: nowhere).

        Returns
        -------
        list of str
            The file names written: signals.csv, estimates.csv, estimates_NAME.csv of each
            offline observer, the study's data files, metrics.json, report.md, PNG figures.
            Every one exists on return (the figures are drawn by the process's figure worker,
            :mod:`railfmu.experiments.engine.figure_worker`, when one runs or starts).
        """
        from railfmu.experiments.engine.files import ensure_folder, write_atomic

        from railfmu.experiments.engine.records import check_format

        fmt = check_format(format or self.record_format)
        out = ensure_folder(folder)
        if (self._streamed is None or self._streamed.resolve() != out.resolve()
                or fmt != self.record_format):
            self._write_csvs(out, fmt)
        exp, system, metrics, bank = self._exp, self.system, self.metrics, self._bank
        # atomic: a run killed while writing leaves no metrics.json rather than half of one
        write_atomic(out / "metrics.json", json.dumps(metrics, indent=2, default=json_default) + "\n")
        base = {**metrics, "series": self.series} if self.series else metrics  # as the study's hooks saw it
        rd = self._run_data
        data = RunData(rd.signals, rd.estimates, base, rd.roles, rd.observers)
        files = exp.study.files(data, out)

        from railfmu.experiments.engine.figure_worker import batch

        with batch() as figures:  # the figure worker draws them while the report is written; all written at the end
            study_job = None
            if self._ahead is not None:  # handed to the worker as the run ended (figures_ahead)
                (early, engine, study_job), self._ahead = self._ahead, None
                figures.take(early, out)
            else:
                engine = engine_figures(exp, system, rd.signals, rd.roles, bank, out)
            self._plots = engine + self._study_figures(study_job, base, out)
            write_atomic(out / "report.md", self.report())
        offline = [f"estimates_{name}.{fmt}" for name in bank.results]
        written = [f"signals.{fmt}", f"estimates.{fmt}", *offline, *files, "metrics.json", "report.md", *self._plots]
        if log is not None:
            print(f"wrote {out}/: {', '.join(written)}", file=log)
        return written

    def _study_figures(self, job: int | None, base: dict, out: Path) -> list[str]:
        """The study's figures: the worker's PNGs of ``job`` (:func:`figures_ahead`) written into
        ``out``, else drawn here (no job, or the worker failed: its error is then raised here)."""
        from railfmu.experiments.engine.figure_png import write_png
        from railfmu.experiments.engine.figure_worker import study_pngs

        pngs = study_pngs(job) if job is not None else None
        if pngs is None:
            rd = self._run_data
            return self._exp.study.figures(RunData(rd.signals, rd.estimates, base, rd.roles, rd.observers), out)
        for name, png in pngs:
            write_png(out / name, png)
        return [name for name, _ in pngs]

    def _write_csvs(self, out: Path, fmt: str = "csv") -> None:
        """The signals and estimates from memory in ``fmt``, with the writer of a streamed run."""
        from railfmu.experiments.engine.records import record_path, write_table

        write_table(record_path(out, "signals", fmt), self._columns, self._data, fmt, self.system.signal_types())
        bank = self._bank
        t, est = bank.arrays()
        write_table(record_path(out, "estimates", fmt), ["time", *bank.columns], np.column_stack([t, est]), fmt)
        outputs = {name: obs.outputs for name, obs in bank.estimators().items()}
        for name, (t_off, X) in bank.results.items():
            write_table(record_path(out, f"estimates_{name}", fmt), ["time", *(f"{name}.{o}" for o in outputs[name])],
                        np.column_stack([t_off, X]), fmt)


def engine_figures(exp: Experiment, system: System, signals: dict[str, np.ndarray], roles: dict,
                   bank: ObserverBank, out: Path) -> list[str]:
    """The figures every run has: the study's signal figures and each observer's estimates
    over their truth (:mod:`railfmu.experiments.engine.plots`)."""
    from railfmu.experiments.engine.plots import columns_of, plot_estimates, plot_signals, units_of

    position = roles.get(exp.study.x_axis) if exp.study.x_axis != "time" else None
    if position is not None and position not in signals:  # a speed setting: distance = V t
        position = float(position)
    units, columns = units_of(system), columns_of(system)
    return (plot_signals(exp.study.figures_of_signals, signals, roles, units, out, position, columns)
            + plot_estimates(bank, signals, units, out, position, columns, exp.study.quantities))


def figures_ahead(exp: Experiment, system: System, run: RunData, bank: ObserverBank) -> tuple | None:
    """:func:`engine_figures` handed to the running figure worker now (they need nothing the
    study computes), and the study's own when it draws them from the run alone
    (``Study.figures_from_run``), for :meth:`Run.save` to write: the worker draws them while
    the study scores the run. ``(batch, engine figure names, study job or None)``; None when
    no worker runs."""
    from railfmu.experiments.engine.figure_worker import ahead, submit_study

    with ahead() as early:
        if early is None:
            return None
        engine = engine_figures(exp, system, run.signals, run.roles, bank, Path())
    job = None
    if exp.study.figures_from_run:  # a copy of the run: the study's metrics add to the base later
        job = submit_study(exp.study, RunData(run.signals, run.estimates, dict(run.base), run.roles, {}))
    return early, engine, job


def abandon_ahead(ahead: tuple | None) -> None:
    """Figures handed ahead that no :meth:`Run.save` will take: their replies are not kept."""
    if ahead is not None:
        from railfmu.experiments.engine.figure_worker import drop

        early, _, job = ahead
        early.abandon()
        if job is not None:
            drop([job])


def report_md(exp: Experiment, system: System, metrics: dict, plots: list[str]) -> str:
    """report.md: the run, the system, the study's section, rms of the signals, notes, figures."""
    L = [f"# {exp.name} / {metrics['variant'] or 'no variant'}", "", exp.description, "",
         (f"{metrics['simulated_seconds']:g} s at a {system.step_size:g} s communication step "
          f"(from {system.step_size_from}), "
          f"{metrics['master']} master, {metrics['wall_time_s']:.2f} s wall time "
          f"({metrics['realtime_factor']:.1f}x real time)."), ""]
    if metrics["warnings"]:  # what looks wrong comes first, not at the end of the report
        L += ["**Warnings**", "", *[f"- {w}" for w in metrics["warnings"]], ""]
    derived = (metrics.get("replay") or {}).get("derived", [])
    given = (metrics.get("replay") or {}).get("given") or metrics.get("files") or {}
    if given or derived:
        L += ["Files and what the data set:", "", *[f"- {k} = {v['path']} ({v['how']})" for k, v in given.items()],
              *[f"- {n}" for n in derived], ""]
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
    if metrics["notes"]:
        L += ["", "## Notes", ""] + [f"- {w}" for w in metrics["notes"]]
    L += ["", *[f"![{p}]({p})" for p in plots]]
    return "\n".join(L) + "\n"
