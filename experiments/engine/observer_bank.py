"""Observers attached to a run: a recorder sink that feeds each estimator its bound signals.

The SSD declares each observer (``org.railfmu.observers`` annotation, read into
:class:`railfmu.fmus.cosim.system.ObserverSpec`), its ``class`` a registered estimator name
(:mod:`railfmu.experiments.engine.registry`). :class:`ObserverBank` instantiates them and, as a
sink of the master, feeds them the recorded rows in blocks (both the Python masters and the
container hand over blocks: observers are passive, so they see the same samples either way),
each observer its sample rows of a block in one ``step_block`` call, bit for bit what
``step`` row by row gives:

* **units**: every measurement and known input arrives in the unit the observer declares,
  converted from the unit of the signal it is bound to (``dst = a src + b``); incompatible
  units, or a unit on one side only, are a :class:`railfmu.models.errors.UserError`;
* **multi-rate**: an observer with a ``samplePeriod`` of ``m`` system steps gets every
  ``m``-th row, whatever the system step (10 s GNSS in a 0.1 s system);
* **missing channels**: a measurement is missing where it is NaN, where its ``valid`` flag
  is 0, or, for an event-driven observer, where it has not changed since the last sample;
  the observer updates with the channels present (its ``mask``);
* **offline observers** (``offline="true"``: smoothers, batch identification) get the whole
  record once the run has ended and write ``estimates_<name>.csv``;
* **FMU process models**: the setting ``process_component`` names a component whose FMU (one
  more instance, the component's parameters) becomes the observer's ``process``
  (:mod:`railfmu.experiments.engine.fmu_process`); it is freed when the run closes;
* **settings bound to signals** (``rf:Setting name connector``): the observer is created
  again at its first sample with those settings set to the signals' values there, in its
  units (an INS started from the vehicle's true initial state); settings bound to a
  component's parameter (``rf:Setting name parameter``) arrive as the reader resolved them;
* **switched off**: an observer whose setting ``enabled`` is false (a variant or ``--set
  ins.enabled=false``) is not built: it costs nothing and has no estimates nor metrics;
* **after the run** :meth:`ObserverBank.estimators` hands the study each finished estimator
  object (online and offline) by name, for what its per-sample outputs do not carry (a
  smoother's joint covariance, its timings).

``estimates.csv`` (the online estimates, each held between its observer's samples) is
written as the run goes, like ``signals.csv``.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from railfmu.estimators.core.observer import Observer
from railfmu.estimators.track.metrics import rms
from railfmu.experiments.engine import registry
from railfmu.experiments.engine import records
from railfmu.fmus.cosim.system import ObserverSpec, System
from railfmu.models.errors import UserError
from railfmu.fmus.ssp.units import OURS, Units, conversion

_STRIDE_RTOL = 1e-9


def make_observer(spec: ObserverSpec, step_size: float, where: str, system: System | None = None):
    """Load the registered estimator ``spec.cls`` and instantiate it at its sample period with the spec's settings;
    returns ``(estimator, stride)`` (its period in system steps). A UserError if not possible.
    The setting ``process_component`` names a component of ``system`` whose FMU becomes the
    estimator's process model (``process``; :mod:`railfmu.experiments.engine.fmu_process`)."""
    label = f"{where}: Observer {spec.name!r}"
    period = _period(spec, step_size)
    stride = round(period / step_size)
    if stride < 1 or abs(stride * step_size - period) > _STRIDE_RTOL * period:
        raise UserError(f"{label}: samplePeriod {period:g} s is not a whole number of system steps "
                        f"({step_size:g} s)")
    cls = registry.load(spec.cls, label)
    offline = bool(getattr(cls, "offline", False))
    if offline != spec.offline:
        raise UserError(f"{label}: {spec.cls} is an {'offline' if offline else 'online'} estimator; "
                        f"declare it with offline=\"{str(offline).lower()}\"")
    settings = spec.class_settings
    process = None
    if "process_component" in settings:
        process = _process_model(cls, str(settings.pop("process_component")), system, label, spec.name)
        settings["process"] = process
    try:
        obs = cls(period, **settings)
    except (TypeError, ValueError, OSError) as exc:  # OSError: a file a setting names (a line profile)
        if process is not None:
            process.close()
        raise UserError(f"{label}: bad settings: {exc}") from None
    for kind, declared, bound in (("measurements", obs.measurements, spec.measurements),
                                  ("inputs", obs.inputs, spec.inputs)):
        missing = [k for k in declared if k not in bound]
        unknown = [k for k in bound if k not in declared]
        if missing or unknown:
            raise UserError(f"{label}: {kind} must be {', '.join(declared) or '(none)'}"
                            f" ({'missing ' + ', '.join(missing) if missing else 'unknown ' + ', '.join(unknown)})")
    bad_valid = [k for k in spec.valid if k not in obs.measurements]
    if bad_valid:
        raise UserError(f"{label}: valid flag for {bad_valid[0]!r}, which is not one of its measurements")
    bad_truth = [k for k in spec.truth if k not in obs.outputs]
    if bad_truth:
        raise UserError(f"{label}: Truth {bad_truth[0]!r} is not one of its outputs ({', '.join(obs.outputs)})")
    return obs, stride


def _process_model(cls, name: str, system: System | None, label: str, observer: str):
    """An FMU process model on component ``name`` of ``system`` (railfmu.experiments.engine.fmu_process)."""
    from railfmu.experiments.engine.fmu_process import process_model

    try:
        component = system.component(name) if system is not None else None
    except KeyError:
        component = None
    if component is None:
        raise UserError(f"{label}: process_component {name!r} is not a component of the system")
    return process_model(cls, component, label, observer)


def _period(spec: ObserverSpec, step_size: float) -> float:
    return spec.period if spec.period is not None else step_size


def bind_settings(feed: _Feed, row: np.ndarray, columns: list[int], where: str) -> None:
    """Create ``feed``'s observer again with its signal-bound settings set to their values in
    ``row`` (its first sample; ``columns`` their indices in ``row``), in the observer's units."""
    spec = feed.spec
    values = {k: a * float(row[i]) + b for k, i, (a, b) in zip(spec.setting_signals, columns, feed.set_map)}
    settings = spec.class_settings
    if "process_component" in settings:  # the FMU process model of the first instance, kept
        settings.pop("process_component")
        settings["process"] = getattr(feed.obs, "process", None)
    try:
        feed.obs = type(feed.obs)(feed.period, **settings, **values)
    except (TypeError, ValueError) as exc:
        raise UserError(f"{where}: Observer {spec.name!r}: bad settings from signals "
                        f"({', '.join(f'{k} = {spec.setting_signals[k]}' for k in values)}): {exc}") from None
    feed.bound = values


def unit_map(spec: ObserverSpec, obs, kind: str, name: str, signal: str, where: str) -> tuple[float, float]:
    """``(a, b)``: the value in the observer's unit of ``name`` is ``a * signal + b``. A
    UserError naming observer, channel and both units when they cannot be converted."""
    want = obs.units.get(name, "")
    src = spec.units.get(signal)
    have = src.name if src is not None else ""
    label = f"{where}: Observer {spec.name!r}: {kind} {name!r}"
    if want and OURS.get(want) is None:
        raise UserError(f"{label}: unit {want!r} of the observer is not defined in fmus/units.py")
    if not want and not have:
        return 1.0, 0.0
    if not have:
        raise UserError(f"{label} is in {want!r} but {signal} has no unit (give the SSD connector "
                        f"<ssc:Real unit=\"{want}\"/>)")
    if not want:
        if any(src.exponents):
            raise UserError(f"{label} is dimensionless but {signal} is in {have!r}")
        want = have
    try:
        return conversion(have, Units({have: src}).then(OURS), want, OURS)
    except ValueError:
        raise UserError(f"{label} is in {want!r} ({OURS.get(want).dims()}) but {signal} is in {have!r} "
                        f"({src.dims()}): incompatible units") from None


def _affine(maps: list[tuple[float, float]]):
    """The per-channel maps as arrays, or None when every one is the identity (no arithmetic,
    so the samples reach the observer bit for bit)."""
    if all(m == (1.0, 0.0) for m in maps):
        return None
    return np.array([a for a, _ in maps]), np.array([b for _, b in maps])


@dataclass
class _Feed:
    """How one observer is fed: its spec, the estimator, its stride in rows and unit maps."""
    spec: ObserverSpec
    obs: object
    stride: int
    z_map: tuple | None = None
    u_map: tuple | None = None
    truth_map: dict[str, tuple[float, float]] = field(default_factory=dict)
    event: bool = False
    period: float = 0.0
    set_map: list[tuple[float, float]] = field(default_factory=list)  # signal-bound settings
    bound: dict[str, float] = field(default_factory=dict)  # their values at the first sample
    # set by open(): column indices into the recorded rows
    iz: list[int] = field(default_factory=list)
    iu: list[int] = field(default_factory=list)
    iset: list[int] = field(default_factory=list)
    flagged: list[int] = field(default_factory=list)  # measurement positions with a valid flag
    iflag: list[int] = field(default_factory=list)
    last_z: np.ndarray | None = None
    estimate: np.ndarray | None = None
    seconds: float = 0.0
    failed: str | None = None  # why the estimator stopped (its estimates are NaN from then on)

    def sample(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """``(Z, U, mask)`` of recorded rows (2-D) in the observer's units; mask None: as finite."""
        Z = rows[:, self.iz]
        if self.z_map is not None:
            Z = self.z_map[0] * Z + self.z_map[1]
        U = rows[:, self.iu] if self.iu else None
        if U is not None and self.u_map is not None:
            U = self.u_map[0] * U + self.u_map[1]
        mask = None
        if self.flagged or self.event:
            mask = np.ones(Z.shape, dtype=bool)
            if self.event:  # a channel without a flag is there when its value has changed
                prev = np.vstack([self.last_z if self.last_z is not None else np.full(Z.shape[1], np.nan), Z[:-1]])
                mask = ~(Z == prev)
                self.last_z = Z[-1].copy()
            mask[:, self.flagged] = rows[:, self.iflag] != 0.0
        return Z, U, mask


class ObserverBank:
    """A :class:`railfmu.fmus.cosim.system.Sink` running every observer of a system: the online ones
    as the rows arrive (``estimates.csv``), the offline ones after a complete run
    (``estimates_<name>.csv`` beside it)."""

    def __init__(self, system: System, out_csv: Path | None, record_format: str = "csv"):
        where = str(system.source or system.name)
        self.where = where
        self.step_size = system.step_size
        self.online: list[_Feed] = []
        self.offline: list[_Feed] = []
        for spec in system.observers:
            if not spec.enabled:  # switched off by a variant or --set: not built, not fed
                continue
            obs, stride = make_observer(spec, system.step_size, where, system)
            feed = _Feed(spec, obs, stride, event=spec.event if spec.event is not None else obs.event_driven,
                         period=_period(spec, system.step_size))
            feed.set_map = [unit_map(spec, obs, "setting", k, sig, where) for k, sig in spec.setting_signals.items()]
            feed.z_map = _affine([unit_map(spec, obs, "measurement", k, spec.measurements[k], where)
                                  for k in obs.measurements])
            feed.u_map = _affine([unit_map(spec, obs, "input", k, spec.inputs[k], where) for k in obs.inputs])
            feed.truth_map = {k: unit_map(spec, obs, "truth", k, s, where) for k, s in spec.truth.items()}
            if not spec.offline and callable(getattr(obs, "prepare", None)):  # a compiled kernel: loaded
                obs.prepare()                                                    # in the set-up, not at the first sample
            (self.offline if spec.offline else self.online).append(feed)
        self.out_csv = out_csv
        self.record_format = record_format  # csv, parquet or mat (railfmu.experiments.engine.records)
        self.recorder = records.recorder(out_csv, record_format) if out_csv is not None else None
        self.times: list[float] = []
        self.estimates: list[np.ndarray] = []  # blocks (rows, n_outputs_total), one row per recorded row
        self.results: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # offline: name -> (t, X)
        self._arrays: tuple[np.ndarray, np.ndarray] | None = None

    # the online observers, for plots and tables
    @property
    def specs(self) -> list[ObserverSpec]:
        return [f.spec for f in self.online]

    @property
    def observers(self) -> list:
        return [f.obs for f in self.online]

    def estimators(self) -> dict[str, object]:
        """Every built estimator by observer name, online and offline (after the run: the
        finished objects, e.g. for a smoother's ``error_samples``)."""
        return {f.spec.name: f.obs for f in (*self.online, *self.offline)}

    @property
    def columns(self) -> list[str]:
        return [f"{f.spec.name}.{o}" for f in self.online for o in f.obs.outputs]

    def open(self, columns: list[str]) -> None:
        def index(feed: _Feed, signal: str) -> int:
            try:
                return columns.index(signal)
            except ValueError:
                raise UserError(f"Observer {feed.spec.name!r}: signal {signal} is not recorded") from None

        for f in (*self.online, *self.offline):
            s = f.spec
            f.iz = [index(f, s.measurements[k]) for k in f.obs.measurements]
            f.iu = [index(f, s.inputs[k]) for k in f.obs.inputs]
            f.iset = [index(f, sig) for sig in s.setting_signals.values()]
            f.flagged = [j for j, k in enumerate(f.obs.measurements) if k in s.valid]
            f.iflag = [index(f, s.valid[f.obs.measurements[j]]) for j in f.flagged]
            f.last_z, f.estimate = None, None
        for f in self.online:
            f.obs.reset(0.0)
            f.seconds = 0.0
        # the offline observers' columns, kept for after the run
        self._kept = sorted({0, *(i for f in self.offline for i in (*f.iz, *f.iu, *f.iflag, *f.iset))})
        self._record: list[np.ndarray] = []
        self._row = 0
        self.times, self.estimates, self.results = [], [], {}
        self._arrays = None
        if self.recorder is not None:  # the same writer as signals.csv: complete rows, as it goes
            self.recorder.open(["time", *self.columns])

    def write(self, row: np.ndarray) -> None:
        self.write_block(row[None, :])

    def write_block(self, rows: np.ndarray) -> None:
        """A block of recorded rows: each online observer gets its sample rows of the block in
        one :meth:`Observer.step_block` call (units, masks and valid flags per block), and the
        estimates of every row (each held between its observer's samples) go out as one block."""
        m, k0 = rows.shape[0], self._row
        if m == 0:
            return
        self._row += m
        t = rows[:, 0]
        self.times.extend(t.tolist())
        if self.offline:
            self._record.append(rows[:, self._kept])
        if not self.online:  # offline observers only (a Monte Carlo of a smoother): nothing per row
            if self.recorder is not None:
                self.recorder.write_block(rows[:, :1])
            return
        parts = [self._feed_block(f, rows, k0) for f in self.online]
        est = np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]
        self.estimates.append(est)
        if self.recorder is not None:
            self.recorder.write_block(np.column_stack([t, est]))

    def _feed_block(self, f: _Feed, rows: np.ndarray, k0: int) -> np.ndarray:
        """``f``'s estimates on every row of ``rows`` (global row ``k0`` first)."""
        m = rows.shape[0]
        first = (-k0) % f.stride  # the block's first sample row of this observer
        if k0 == 0 and f.iset:
            bind_settings(f, rows[0], f.iset, self.where)
            f.obs.reset(0.0)
        held = np.empty((m, len(f.obs.outputs)))
        if first >= m:
            held[:] = f.estimate
            return held
        if first:
            held[:first] = f.estimate
        at = slice(first, None, f.stride)
        sampled = rows[at]
        n = sampled.shape[0]
        X = held[first:] if f.stride == 1 else np.empty((n, len(f.obs.outputs)))
        if f.failed is None:
            Z, U, mask = f.sample(sampled)
            t0 = time.perf_counter()
            try:
                step_block = getattr(f.obs, "step_block", None)
                if step_block is None:  # a plug-in's estimator with step only: row by row
                    Observer.step_block(f.obs, sampled[:, 0], Z, U, mask, out=X)
                else:
                    step_block(sampled[:, 0], Z, U, mask, out=X)
            except (ArithmeticError, ValueError) as exc:  # numerical failure (LinAlgError is a ValueError)
                i = getattr(exc, "rows_done", 0)
                self._fail(f, float(sampled[i, 0]), exc)
                X[i:] = np.nan
            f.seconds += time.perf_counter() - t0
        else:
            X[:] = np.nan
        f.estimate = X[-1].copy()
        if f.stride > 1:  # held between samples
            held[first:] = np.repeat(X, f.stride, axis=0)[:m - first]
        return held

    def _fail(self, f: _Feed, t: float, exc: Exception) -> None:
        """One estimator that fails numerically does not end the run nor lose the others'
        results: its estimates are NaN from ``t`` on, and the CLI and metrics.json say why."""
        f.failed = f"{type(exc).__name__} at t = {t:g} s: {exc}".splitlines()[0]
        f.estimate = np.full(len(f.obs.outputs), np.nan)
        print(f"railfmu: warning: {self.where}: Observer {f.spec.name!r} failed ({f.failed}); its estimates "
              "are NaN from there on", file=sys.stderr)

    def close(self, complete: bool) -> None:
        if self.recorder is not None:
            self.recorder.close(complete)
        if complete and self.offline and self._record:
            self._run_offline()
        for f in (*self.online, *self.offline):  # an FMU process model frees its instance
            close = getattr(f.obs, "close", None)
            if callable(close):
                close()

    def _run_offline(self) -> None:
        """Each offline observer on the whole record (its own sample rows), to estimates_<name>.csv."""
        kept = np.vstack(self._record)
        at = {c: j for j, c in enumerate(self._kept)}
        for f in self.offline:
            rows = kept[::f.stride]
            if f.iset:
                bind_settings(f, kept[0], [at[i] for i in f.iset], self.where)
            local = _Feed(f.spec, f.obs, f.stride, f.z_map, f.u_map, event=f.event,
                          iz=[at[i] for i in f.iz], iu=[at[i] for i in f.iu], flagged=f.flagged,
                          iflag=[at[i] for i in f.iflag])
            Z, U, mask = local.sample(rows)
            t0 = time.perf_counter()
            X = f.obs.run(rows[:, 0], Z, U, mask)
            f.seconds = time.perf_counter() - t0
            self.results[f.spec.name] = (rows[:, 0], X)
            if self.out_csv is not None:
                records.write_table(records.record_path(self.out_csv.parent, f"estimates_{f.spec.name}",
                                                        self.record_format),
                                    ["time", *(f"{f.spec.name}.{o}" for o in f.obs.outputs)],
                                    np.column_stack([rows[:, 0], X]))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The online estimates: times and one row of every online observer's outputs (stacked
        once per number of rows: the runner and :meth:`metrics` both ask after a run)."""
        cached = self._arrays
        if cached is None or cached[0].shape[0] != len(self.times):
            t = np.asarray(self.times)
            if not self.online:  # no estimates: one empty row per time
                est = np.empty((t.size, 0))
            else:
                est = np.vstack(self.estimates) if self.estimates else np.empty((0, len(self.columns)))
            self._arrays = cached = (t, est)
        return cached

    def offline_estimates(self) -> dict[str, np.ndarray]:
        """The offline estimates by column ``name.output`` (on their observer's sample times)."""
        return {f"{name}.{o}": X[:, j] for name, (_, X) in self.results.items()
                for j, o in enumerate(next(f.obs for f in self.offline if f.spec.name == name).outputs)}

    def metrics(self, signals: dict[str, np.ndarray], settle_fraction: float = 0.1) -> dict:
        """Per observer (online and offline): its diagnostics and, for every estimate with a
        truth signal, the rms error against it at its own samples after the first
        ``settle_fraction`` of the run (the filter's transient)."""
        t, est = self.arrays()
        out: dict[str, dict] = {}
        n0 = math.ceil(settle_fraction * len(t))
        col = 0
        for f in self.online:  # wall_time_s: in the observer's step calls, summed over the run
            out[f.spec.name] = {"wall_time_s": f.seconds,
                                **self._scores(f, t, est[:, col:col + len(f.obs.outputs)], n0, signals)}
            col += len(f.obs.outputs)
        for f in self.offline:
            if f.spec.name in self.results:
                _, X = self.results[f.spec.name]
                full = np.full((len(t), X.shape[1]), np.nan)
                full[::f.stride] = X
                m = self._scores(f, t, full, n0, signals)
                out[f.spec.name] = {"offline": True, "wall_time_s": f.seconds, **m}
        return out

    @staticmethod
    def _scores(f: _Feed, t: np.ndarray, est: np.ndarray, n0: int, signals: dict) -> dict:
        m: dict = dict(f.obs.finish())
        if f.failed:
            m["failed"] = f.failed
        if f.bound:
            m["settings_from_signals"] = dict(f.bound)
        rows = np.arange(0, len(t), f.stride)
        rows = rows[rows >= n0]
        if len(t) <= n0:
            return m
        for j, name in enumerate(f.obs.outputs):
            if name in f.spec.truth:
                truth = np.asarray(signals[f.spec.truth[name]])[:len(t)]
                a, b = f.truth_map[name]
                if (a, b) != (1.0, 0.0):
                    truth = a * truth + b
                truth = truth[rows]
                err = est[rows, j] - truth
                rms_truth = rms(truth)
                rms_err = rms(err)
                m[name] = {"rms_error": rms_err, "rms_truth": rms_truth,
                           "rel_error": rms_err / rms_truth if rms_truth > 0 else None,
                           "from_time_s": float(t[n0])}
        return m
