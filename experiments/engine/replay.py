"""Replays shaped by their data, and the checks that catch a wrong file.

A *replay* is a component of the system whose FMU is the ``SignalTable`` (a measured CSV
played as outputs, ``models/sources/signal_table.py``) with a ``file``. Before a run,
:func:`shape_replays` reads each replay's file once and

* **checks it** (one-line :class:`UserError` naming file, line or column and what looks
  wrong, exit 2): a ``;`` separator or decimal commas, a time that is not a number, times that
  repeat or go back; positions that disagree with the integral of the speeds by a unit factor
  (km for m, km/h for m/s; by the units of the connectors the observers read). Then the
  study's own plausibility checks (:attr:`Study.replay_checks`, e.g. :func:`imu_increments`)
  run: each raises a UserError or returns warnings (the heading, the report and
  ``metrics.json["warnings"]``);
* **shapes the run** after the replay that ends it (``after_end = 1``), unless the user set
  them: the stop time is its last row, the communication step its row interval (the median
  of its time differences; ``--step-size`` given: the interval must be a whole number of
  steps), a table whose time starts late (or early) is shifted to start at 0 (every replay's
  ``time_offset``, so that tables recorded together stay together), and an observer whose
  measurements (or known inputs) all come from one replay samples at that replay's interval
  (a 1 Hz GNSS log: every fix, not every 10th) unless a variant or ``--set`` gave its
  ``samplePeriod``;
* **marks short truth**: an observer's truth signals on a replay of fewer than
  :data:`MIN_TRUTH_ROWS` rows are not scored (``null`` metrics, a warning).

What was derived is in ``System.notes`` (the run heading, the report, ``metrics.json["replay"]``).
A replay's end is the normal end of its run (the runner reports no "early end" for it).
"""

from __future__ import annotations

import csv
import io
import math
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from railfmu.models.errors import UserError

SIGNAL_TABLE = "SignalTable"
MIN_TRUTH_ROWS = 2  # a score compares an estimate with a truth that moves: one row is a start point
G = 9.80665
#: unit factors a wrong file shows between its positions and the integral of its speeds
FACTORS = ((1000.0, "positions look like km where m is expected (1000 times too small?)"),
           (1e-3, "positions look like mm or the speeds like km/s (1000 times too large?)"),
           (3.6, "the speeds look like km/h where m/s is expected"),
           (1 / 3.6, "the speeds look like m/s where km/h is expected"))


@dataclass
class ReplayFile:
    """One replay's file as read before the run: ``time`` as in the file (s), ``columns``
    the bound Real columns by channel (``y_1`` -> values), ``names`` channel -> column name,
    ``units`` channel -> the unit of the signal the observers read (or None)."""
    component: str
    path: Path
    header: list[str]
    time: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    names: dict[str, str] = field(default_factory=dict)
    units: dict[str, object] = field(default_factory=dict)
    ends_run: bool = False

    @property
    def label(self) -> str:
        return f"{self.component}.file {self.path}"

    @property
    def interval(self) -> float | None:
        """The median row interval (s), None for one row."""
        if self.time.size < 2:
            return None
        return float(np.median(np.diff(self.time)))

    def column_label(self, channel: str) -> str:
        return f"column {self.names.get(channel, channel)!r}"


ReplayCheck = Callable[[ReplayFile, object], list[str]]


def replays_of(system) -> list[tuple[object, str]]:
    """(component, file) of every SignalTable component with a file."""
    out = []
    for c in system.components:
        model = getattr(c, "model", None)
        ident = getattr(getattr(model, "coSimulation", None), "modelIdentifier", None) or Path(str(c.fmu)).stem
        if ident == SIGNAL_TABLE and str(c.parameters.get("file") or ""):
            out.append((c, str(c.parameters["file"])))
    return out


def read_replay(component, file: str, units: dict) -> ReplayFile:
    path = Path(file)
    label = f"{component.name}.file {path}"
    try:
        text = _text(path, component)
        lines = text.splitlines()
        _separator(label, lines[0] if lines else "", lines[1] if len(lines) > 1 else "")
        rows = [r for r in csv.reader(io.StringIO(text, newline="")) if any(c.strip() for c in r)]
    except OSError as exc:
        raise UserError(f"{label}: cannot open ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise UserError(f"{label}: not a UTF-8 text file (a CSV table is expected)") from None
    if not rows:
        raise UserError(f"{label}: empty file (expected a header line starting with 'time')")
    header = [h.strip().strip('"') for h in rows[0]]
    tname = header[0] if header else "time"
    times = []
    for i, r in enumerate(rows[1:], 2):
        try:
            t = float(r[0])
        except (ValueError, IndexError):
            raise UserError(f"{label} line {i}, column {tname!r}: {r[0] if r else ''!r} is not a number") from None
        if not math.isfinite(t):
            raise UserError(f"{label} line {i}, column {tname!r}: {r[0]!r} is not a finite number")
        if times and t <= times[-1]:
            what = (f"repeats the previous row's time {times[-1]:g} s (a duplicated row?)" if t == times[-1]
                    else f"{t:g} s is before the previous row's time {times[-1]:g} s (the times go back: sort the "
                         "file by time)")
            raise UserError(f"{label} line {i}, column {tname!r}: {what}")
        times.append(t)
    out = ReplayFile(component.name, path, header, np.array(times),
                     ends_run=int(component.parameters.get("after_end", 0) or 0) == 1)
    for k in range(1, 17):
        name = str(component.parameters.get(f"column_{k}") or "")
        if name and name in header:
            j = header.index(name)
            vals = []
            for r in rows[1:]:
                try:
                    vals.append(float(r[j]))
                except (ValueError, IndexError):
                    vals.append(math.nan)  # the FMU names line and column
            out.columns[f"y_{k}"] = np.array(vals)
            out.names[f"y_{k}"] = name
            unit = units.get(f"{component.name}.y_{k}")
            if unit is not None:
                out.units[f"y_{k}"] = unit
    return out


_BINARY = (".parquet", ".mat", ".spool")


def _binary_to_csv(system, component, file: str) -> None:
    """A replay's Parquet or .mat table (or a killed run's spool): the SignalTable FMU's C reader
    reads CSV, so the table is written once as a CSV (``repr`` floats: the same values bit for
    bit) into a temporary folder removed when the process ends, and the component plays that."""
    path = Path(file)
    if path.suffix.lower() not in _BINARY or not path.is_file():
        return
    import atexit
    import shutil
    import tempfile

    from railfmu.experiments.engine.records import read_table, write_table

    try:
        columns, data = read_table(path)
    except ValueError as exc:
        raise UserError(f"{component.name}.file {exc}") from None
    folder = Path(tempfile.mkdtemp(prefix="railfmu-replay-"))
    atexit.register(shutil.rmtree, folder, True)
    csv_path = folder / f"{path.stem}.csv"
    write_table(csv_path, columns, data, "csv")
    component.parameters["file"] = str(csv_path)
    system.notes.append(f"{component.name}.file {path} is {path.suffix[1:]}: played as the CSV table {csv_path} "
                        "(the SignalTable FMU reads CSV)")


def _text(path: Path, component) -> str:
    """The file's text; a relative path is the FMU's own ``resources/`` (an exported .ssp)."""
    if not path.is_absolute() and not path.is_file():
        fmu = Path(str(component.fmu))
        if (fmu / "resources" / path).is_file():
            path = fmu / "resources" / path
        elif zipfile.is_zipfile(fmu):
            with zipfile.ZipFile(fmu) as z:
                try:
                    return z.read(f"resources/{path.as_posix()}").decode("utf-8-sig")
                except KeyError:
                    pass
    return path.read_text(encoding="utf-8-sig")


def _separator(label: str, first: str, second: str) -> None:
    """A table exported with ``;`` (and decimal commas), or with tabs: named as such."""
    if "," in first:
        return
    for sep, name in ((";", "a semicolon (;)"), ("\t", "a tab")):
        if sep in first:
            comma = bool(re.search(r"\d,\d", second))
            raise UserError(f"{label} line 1: the separator is {name}{' and the numbers have decimal commas' if comma else ''}"
                            f"; railfmu reads comma-separated tables with decimal points (e.g. 0.5,12.3): "
                            "export the file so")


# -- generic checks ---------------------------------------------------------------------------

def _dims(unit) -> tuple | None:
    return tuple(unit.exponents) if unit is not None else None


def positions_vs_speeds(rf: ReplayFile, system) -> list[str]:
    """The position column against the integral of the speed column (one channel of each, by
    their units): a unit factor between them (km for m, km/h for m/s) is a UserError."""
    from railfmu.fmus.ssp.units import OURS

    length, speed = _dims(OURS.get("m")), _dims(OURS.get("m/s"))
    pos = [c for c, u in rf.units.items() if _dims(u) == length]
    vel = [c for c, u in rf.units.items() if _dims(u) == speed]
    if len(pos) != 1 or len(vel) != 1 or rf.time.size < 3:
        return []
    p, v = pos[0], vel[0]
    s = rf.columns[p] * rf.units[p].factor
    w = rf.columns[v] * rf.units[v].factor
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(w))):
        return []
    travelled = float(np.trapezoid(w, rf.time)) if hasattr(np, "trapezoid") else float(np.trapz(w, rf.time))
    moved = float(s[-1] - s[0])
    if abs(travelled) < 10.0 * max(1e-9, float(np.median(np.abs(np.diff(s)))) if s.size > 1 else 1.0):
        return []
    ratio = moved / travelled
    if abs(ratio - 1.0) <= 0.25:
        return []
    what = f"{rf.label}, {rf.column_label(p)} against {rf.column_label(v)}"
    for factor, why in FACTORS:
        if abs(ratio * factor - 1.0) <= 0.25:
            raise UserError(f"{what}: the positions advance {moved:.4g} m but the speeds integrate to "
                            f"{travelled:.4g} m (a factor {1 / ratio:.4g}): {why}")
    return [f"{what}: the positions advance {moved:.4g} m but the speeds integrate to {travelled:.4g} m "
            f"(a factor {1 / ratio:.3g}, no unit factor): check both columns"]


GENERIC_CHECKS: tuple[ReplayCheck, ...] = (positions_vs_speeds,)


def imu_increments(component: str, dv: tuple[str, str, str] = ("y_4", "y_5", "y_6"),
                   tolerance: float = 0.3) -> ReplayCheck:
    """A study's check of an IMU increment table (``dv`` the channels of the velocity
    increments, m/s per row): at railway dynamics the specific force is about g, so
    |Δv| ≈ g × the interval a row spans. Increments that fit another interval than the
    system's step (a 100 Hz file at a 5 ms step: twice the expected increment, each counting
    twice) are a UserError."""
    def check(rf: ReplayFile, system) -> list[str]:
        if rf.component != component or not all(c in rf.columns for c in dv) or rf.time.size < 3:
            return []
        n = np.linalg.norm(np.column_stack([rf.columns[c] for c in dv]), axis=1)
        n = n[np.isfinite(n) & (n > 0)]
        if n.size < 2:
            return []
        per_row = float(np.median(n))
        fits = per_row / G
        step, rows = system.step_size, rf.interval
        cols = ", ".join(rf.names.get(c, c) for c in dv)
        what = f"{rf.label}, columns {cols}"
        if abs(per_row / (G * step) - 1.0) <= tolerance:
            return []
        if rows is not None and abs(fits / rows - 1.0) <= tolerance:
            times = rows / step
            raise UserError(f"{what}: increments |Δv| ≈ {per_row:.4g} m/s per row fit a {1e3 * fits:.3g} ms "
                            f"interval (g × interval), the file's rows are {1e3 * rows:.3g} ms apart, but the "
                            f"system step is {1e3 * step:.3g} ms: {times:.3g} times the expected increment per step; "
                            "leave the step to the file (no --step-size)")
        raise UserError(f"{what}: increments |Δv| ≈ {per_row:.4g} m/s per row fit a {1e3 * fits:.3g} ms interval "
                        f"(g × interval), but the file's rows are {1e3 * (rows or 0):.3g} ms apart and the step is "
                        f"{1e3 * step:.3g} ms: a time column in other units, or increments of another rate?")
    check.__name__ = f"imu_increments({component})"
    return check


# -- shaping ----------------------------------------------------------------------------------

def shape_replays(system, study=None) -> dict:
    """Check every replay's file and shape the run after them (module docstring); returns
    ``metrics.json["replay"]``: per replay its file, rows, first and last time and interval,
    and ``unscored`` (the replays too short for a score)."""
    from railfmu.fmus.cosim.system import n_steps

    found = replays_of(system)
    if not found:
        return {}
    for c, f in found:
        _binary_to_csv(system, c, f)
    found = replays_of(system)
    units = {s: u for o in system.observers for s, u in o.units.items()}
    files = [read_replay(c, f, units) for c, f in found]
    info: dict = {"files": {}, "unscored": []}
    driver = next((rf for rf in files if rf.ends_run), None)
    # the time shift: the driving table's first row plays at the start
    if driver is not None and driver.time[0] != 0.0:
        t0 = float(driver.time[0])
        for c, _ in found:
            if "time_offset" not in c.parameters:  # an SSV or --set that gives it wins
                c.parameters["time_offset"] = system.start_time - t0
        system.notes.append(f"{driver.label} starts at t = {t0:g} s: shifted to start at {system.start_time:g} s "
                            f"(time_offset = {system.start_time - t0:g} s on every replay)")
    offsets = {c.name: float(c.parameters.get("time_offset", 0.0) or 0.0) for c, _ in found}
    if driver is not None:
        h = driver.interval
        if h is not None and h > 0:
            if system.step_size_from == "--step-size":
                k = round(h / system.step_size)
                if k < 1 or abs(k * system.step_size - h) > 1e-6 * h:
                    raise UserError(f"{driver.label}: its rows are {h:g} s apart, not a whole number of system steps "
                                    f"(--step-size {system.step_size:g} s)")
            else:
                system.step_size = float(f"{h:.12g}")
                system.step_size_from = f"the row interval of {driver.component}.file"
        if system.stop_time_from == "ssd:DefaultExperiment":
            end = float(driver.time[-1]) + offsets[driver.component]
            span = end - system.start_time
            n = max(1, math.ceil(span / system.step_size - 1e-9))
            system.stop_time = system.start_time + n * system.step_size
            system.stop_time_from = f"the last row of {driver.component}.file"
        n_steps(system.start_time, system.stop_time, system.step_size, str(system.source or system.name))
    by_comp = {rf.component: rf for rf in files}
    for spec in system.observers:
        bound = list(spec.measurements.values()) or list(spec.inputs.values())
        comps = {s.partition(".")[0] for s in bound}
        if len(comps) != 1 or next(iter(comps)) not in by_comp or spec.period_from != "ssd":
            continue
        rf = by_comp[next(iter(comps))]
        h = rf.interval
        if h is None or h < system.step_size * (1 - 1e-9):
            continue
        k = round(h / system.step_size)
        if abs(k * system.step_size - h) > 1e-6 * h:
            raise UserError(f"{rf.label}: its rows are {h:g} s apart, not a whole number of system steps "
                            f"({system.step_size:g} s), so observer {spec.name!r} cannot sample each row")
        period = k * system.step_size
        old = spec.period if spec.period is not None else system.step_size
        if abs(old - period) > 1e-9 * period:
            system.notes.append(f"observer {spec.name} samples every {period:g} s, the row interval of {rf.component}.file "
                                f"(the SSD says {old:g} s)")
        spec.period = period if spec.period is not None or k != 1 else None
    for rf in files:
        info["files"][rf.component] = {"file": str(rf.path), "rows": int(rf.time.size),
                                       "first_time_s": float(rf.time[0]) if rf.time.size else None,
                                       "last_time_s": float(rf.time[-1]) if rf.time.size else None,
                                       "interval_s": rf.interval, "ends_run": rf.ends_run}
        truth_of = [o.name for o in system.observers if any(s.partition(".")[0] == rf.component for s in o.truth.values())]
        if truth_of and rf.time.size < MIN_TRUTH_ROWS:
            info["unscored"].append(rf.component)
            system.warnings.append(f"{rf.label} has {rf.time.size} row(s), fewer than the {MIN_TRUTH_ROWS} a score "
                                   f"needs: the scores against it ({', '.join(truth_of)}) are null")
        for check in (*GENERIC_CHECKS, *(getattr(study, "replay_checks", ()) or ())):
            system.warnings.extend(check(rf, system))
    return info


#: counters in an estimator's diagnostics (``finish()``) that say it used the data: 0 = it learned nothing
EVIDENCE = {"coasting_segments": "found no coasting segment in the data: its resistance is its prior",
            "zupt_updates": "made no ZUPT update", "updates": "made no measurement update",
            "steps": "got no sample"}


def learned_nothing(observers: dict) -> list[str]:
    """A warning for each observer whose diagnostics say it learned nothing from the data."""
    out = []
    for name, m in observers.items():
        for key, why in EVIDENCE.items():
            if isinstance(m.get(key), (int, float)) and not isinstance(m.get(key), bool) and m[key] == 0:
                out.append(f"observer {name} {why} ({key} = 0)")
                break
    return out
