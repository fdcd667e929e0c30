"""The study protocol: what an experiment package tells the runner, and what a plain SSP gets.

Each experiment package exports ``STUDY``, an instance of a :class:`Study` subclass; an SSP
given by path runs with ``Study()``. The runner binds the study's signal roles to the system
once (:meth:`Study.bind`), then asks it for metrics, figures, a report section and the study
table; every hook has a default, so a study overrides only what it adds.

Signal roles name what a study needs in the field's words ("alignment truth", "axle-box
lateral acceleration") and say where the SSD holds it: an observer's input or truth
connector, an observer's setting, a component's parameter (its FMU start value unless the
SSP binds one), or a recorded output. Nothing the SSD holds is repeated in Python, so a
variant, a ``--set`` or an edited SSD changes what the study reads.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from railfmu.models.errors import UserError


@dataclass(frozen=True)
class Role:
    """Where the SSD holds one thing a study reads. ``kind`` is one of ``measurement`` (the
    recorded signal an observer's measurement is bound to), ``input`` (the recorded signal an
    observer's known input is bound to), ``truth`` (the recorded signal an estimate
    is scored against), ``setting`` (an observer's setting), ``parameter`` (a component's
    parameter value), ``output`` (a recorded signal ``owner.name``)."""
    kind: str
    owner: str  # observer or component name
    name: str


def measurement(observer: str, name: str) -> Role:
    return Role("measurement", observer, name)


def observer_input(observer: str, name: str) -> Role:
    return Role("input", observer, name)


def truth(observer: str, estimate: str) -> Role:
    return Role("truth", observer, estimate)


def setting(observer: str, name: str) -> Role:
    return Role("setting", observer, name)


def parameter(component: str, name: str) -> Role:
    return Role("parameter", component, name)


def output(component: str, name: str) -> Role:
    return Role("output", component, name)


def _start_value(comp, name: str):
    """A parameter's start value as the component's FMU declares it (typed), or None."""
    v = comp.variables.get(name)
    if v is None or v.start is None:
        return None
    return {"Real": float, "Integer": int, "Boolean": lambda s: str(s).lower() in ("true", "1")}.get(
        v.type, str)(v.start)


def bind_role(system, role: Role):
    """The signal name (``component.variable``) or value that ``role`` names in ``system``;
    a UserError naming the SSD and the missing element when it is not there."""
    where = str(system.source or system.name)
    if role.kind in ("measurement", "input", "truth", "setting"):
        spec = next((o for o in system.observers if o.name == role.owner), None)
        if spec is None:
            raise UserError(f"{where}: the study needs Observer {role.owner!r}, which the SSD does not declare")
        table = {"measurement": spec.measurements, "input": spec.inputs, "truth": spec.truth,
                 "setting": spec.settings}[role.kind]
        if role.name not in table:
            raise UserError(f"{where}: Observer {role.owner!r} has no {role.kind.capitalize()} {role.name!r}, "
                            "which the study needs")
        return table[role.name]
    if role.kind in ("parameter", "output"):
        try:
            comp = system.component(role.owner)
        except KeyError:
            raise UserError(f"{where}: the study needs component {role.owner!r}, which the SSD does not have") \
                from None
        if role.kind == "output":
            signal = f"{role.owner}.{role.name}"
            if system.record and signal not in system.record:
                raise UserError(f"{where}: the study needs signal {signal!r}, which the recorder does not record")
            return signal
        if role.name in comp.parameters:
            return comp.parameters[role.name]
        value = _start_value(comp, role.name)
        if value is None:
            raise UserError(f"{where}: component {role.owner!r} has no parameter {role.name!r}")
        return value
    raise ValueError(f"unknown role kind {role.kind!r}")


@dataclass
class RunData:
    """What a finished run hands the study: recorded signals and estimates (name -> array,
    with ``time``), the run's base metrics, the study's roles bound to this system, and
    ``observers``: each observer's finished estimator object by name (online and offline;
    a switched-off one is absent), for what its per-sample outputs do not carry, e.g.
    ``run.observers["smoother"].error_samples(...)``."""
    signals: dict[str, np.ndarray]
    estimates: dict[str, np.ndarray]
    base: dict
    roles: dict[str, Any] = field(default_factory=dict)
    observers: dict[str, Any] = field(default_factory=dict)


class Study:
    """The default study of a system: every recorded signal plotted, every observer's raw
    error reported. Experiment packages subclass it and export one instance as ``STUDY``."""

    #: variant run when none is asked for; None: the SSD as it is
    default_variant: str | None = None
    #: role name -> :class:`Role`; bound once per run into ``RunData.roles``
    roles: dict[str, Role] = {}
    #: the study's signal figures, ``{file: (title, [[(role or signal, label), ...] per axis])}``;
    #: None plots every recorded signal (at most 8)
    figures_of_signals: dict | None = None
    #: x-axis of those figures and of the estimates': "time", or a role / signal giving the distance
    #: along the track, or a role bound to the run's constant speed (m/s; the distance is speed x time)
    x_axis: str = "time"
    #: estimate name -> the quantity its figure's y-axis names, optionally with a display unit
    #: (``{"xi": "lateral alignment [mm]"}``); default: the truth's file column or the estimate's name
    quantities: dict[str, str] = {}
    #: the study's plausibility checks of each replay's file (``railfmu.experiments.engine.replay``):
    #: ``check(replay_file, system) -> [warning, ...]``, raising a UserError for a file that is wrong;
    #: run after the engine's own (separator, times, positions against speeds)
    replay_checks: tuple = ()
    #: flattened metric names (fnmatch patterns) that the Monte Carlo table.md shows
    summary_metrics: tuple[str, ...] = ("observers.*.rms_error", "wall_time_s")
    #: True when :meth:`figures` reads only the run (signals, estimates, roles, the base metrics;
    #: not the study's own metrics, not ``run.observers``): a figure worker then draws them while
    #: :meth:`metrics` scores the run, from a copy of the run
    figures_from_run: bool = False
    #: modules :meth:`figures` imports, which a figure worker imports while the run steps
    figure_imports: tuple[str, ...] = ()

    def __init__(self, description: str = ""):
        self.description = description

    def bind(self, system) -> dict[str, Any]:
        return {name: bind_role(system, role) for name, role in self.roles.items()}

    def metrics(self, run: RunData) -> dict:
        """Study metrics added to the run's base metrics (default: none). May add offline
        estimates to ``run.estimates`` for :meth:`figures`, which runs next."""
        return {}

    def files(self, run: RunData, out: Path) -> list[str]:
        """Data files the study writes into ``out`` beside signals.csv, in a form other tools
        read (default: none); their file names. Not called for Monte Carlo members."""
        return []

    def figures(self, run: RunData, out: Path) -> list[str]:
        """The study's own figures written into ``out``; their file names."""
        return []

    def monte_carlo_stop_time(self, system) -> float | None:
        """Stop time (s) of every Monte Carlo member (``--runs N > 1``) when ``--stop-time`` is
        not given: a statistic over seeds is only as good as each member's estimate of what it
        scores (e.g. a wavelength band needs several wavelengths per run). ``system`` is the
        variant's system as read. Default None: the SSD's (or the variant's) stop time."""
        return None

    def series(self, run: RunData) -> dict[str, np.ndarray]:
        """Compact per-run arrays a Monte Carlo member hands back for :meth:`study_figures`
        (members write no files): e.g. the speed at each GNSS fix. Default: none. Keep them
        small (float32, at a measurement rate): every member's travel to the client."""
        return {}

    def study_figures(self, table: dict, series: dict[str, dict[int, dict[str, np.ndarray]]],
                      out: Path) -> list[str]:
        """Figures over the Monte Carlo members, written into ``out``: ``table`` is table.json's
        ``{variant: {"runs": {seed: metrics}, "summary": ...}}``, ``series`` each member's
        :meth:`series` as ``{variant: {seed: arrays}}``. Default: none."""
        return []

    def study_tables(self, table: dict, series: dict[str, dict[int, dict[str, np.ndarray]]]) -> str:
        """Markdown the Monte Carlo's table.md adds after the summary, from the members'
        metrics and :meth:`series` (e.g. differences between runs). Default: none."""
        return ""

    def report_md(self, metrics: dict) -> str:
        """The study's section of report.md (default: each observer's raw error)."""
        return observers_md(metrics)

    def table_md(self, table: dict[str, dict]) -> str:
        """The study table of one run per variant (default: raw error per observer estimate)."""
        rows = []
        for variant, m in table.items():
            for obs, est, e in _raw_errors(m):
                rows.append(f"| {variant} | {obs}.{est} | {_num(e['rms_error'], '.4g')} | {_num(e['rms_truth'], '.4g')} | "
                            f"{_num(e['rel_error'], '.3f')} | {m['wall_time_s']:.2f} |")
            if not any(True for _ in _raw_errors(m)):
                rows.append(f"| {variant} | - | - | - | - | {m['wall_time_s']:.2f} |")
        return "\n".join(["| variant | estimate | rms error of the raw estimate | rms truth | relative | wall [s] |",
                          "|---|---|---|---|---|---|", *rows, "", RAW_ERROR_NOTE])

    def summary_md(self, summary: dict[str, dict[str, dict]], runs: int) -> str:
        """The Monte Carlo table: per variant, the summary of the metrics matched by
        :attr:`summary_metrics` over ``runs`` seeds."""
        L = [f"Summary over {runs} seeds per variant (std with N - 1; p50/p95 interpolated).", "",
             "| variant | metric | mean | std | rms | min | p50 | p95 | max |", "|---|---|---|---|---|---|---|---|---|"]
        for variant, stats in summary.items():
            for key, s in stats.items():
                if any(fnmatch.fnmatchcase(key, p) for p in self.summary_metrics):
                    L.append(f"| {variant} | {key} | " + " | ".join(f"{s[k]:.4g}" for k in STATISTICS) + " |")
        return "\n".join(L + ["", "Every numeric metric of every run is in table.json."])


STATISTICS = ("mean", "std", "rms", "min", "p50", "p95", "max")
RAW_ERROR_NOTE = ("rms error of the raw estimate: the estimate minus its truth signal sample by sample, "
                  "unfiltered, after the first 10 % of the run (the filter's transient).")


def _num(x, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def _raw_errors(metrics: dict):
    for obs, m in metrics.get("observers", {}).items():
        for est, e in m.items():
            if isinstance(e, dict) and "rms_error" in e:
                yield obs, est, e


def observers_md(metrics: dict) -> str:
    """Each observer's raw error against its truth signals, as a table that says it is raw."""
    L = []
    for name, m in metrics.get("observers", {}).items():
        rows = [f"| {est} | {_num(e['rms_error'], '.4g')} | {_num(e['rms_truth'], '.4g')} | {_num(e['rel_error'], '.3f')} |"
                for obs, est, e in _raw_errors({"observers": {name: m}})]
        if rows:
            kind = (f"Offline observer `{name}` (run on the whole record after the run, "
                    f"{m['wall_time_s']:.3f} s; estimates_{name}.csv)" if m.get("offline") else f"Observer `{name}`")
            L += [f"## {kind}: raw estimate against its truth", "",
                  "| estimate | rms error of the raw estimate | rms truth | relative |", "|---|---|---|---|",
                  *rows, "", RAW_ERROR_NOTE, ""]
    return "\n".join(L).rstrip()
