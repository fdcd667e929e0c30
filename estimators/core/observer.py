"""The interface every estimator block implements: online observers and offline estimators.

An estimator declares

* ``inputs``: the *known inputs* ``u`` it predicts with (a tractive effort, the rail heights
  under a bogie), sampled at its own sample times and held between them;
* ``measurements``: the channels ``z`` it updates with (accelerometers, a GNSS fix);
* ``outputs``: its estimates;
* ``units``: the unit of each of them (FMI unit names, '' = dimensionless), which the
  observer bank checks against the connectors it is bound to;
* its sample period ``dt`` (s, a constructor argument): the grid it predicts on.

Each measurement channel may be missing at a sample: NaN/inf, or masked out by the caller
(``mask``, e.g. from a GNSS valid flag). Only the missing channels are skipped: the update
uses the rows present, and a sample with none present is a prediction only.

:class:`Observer` is the online kind. A co-simulation (``railfmu.experiments.engine.observer_bank``) calls
:meth:`Observer.step` at its sample times; between two calls it predicts
``round((t - t_prev) / dt)`` steps, so a dropped sample costs accuracy, not correctness, and a
time that is not a whole number of steps later is an error. :meth:`Estimator.run` feeds
recorded arrays and :meth:`Estimator.run_csv` a recorded ``signals.csv``; online and offline
estimates are bit-identical. :meth:`Observer.step_block` takes many samples at once (the observer
bank hands blocks of rows), with the same results as :meth:`Observer.step` row by row; an
estimator with a compiled recursion overrides it.

:class:`OfflineObserver` is the offline kind (smoothers, batch identification): it gets the
whole record — times, ``U``, ``Z`` and the mask — once, after the run.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, ClassVar, Mapping

import numpy as np

#: relative tolerance on t - t_prev being a whole number of sample times
_TIME_RTOL = 1e-6


class Estimator:
    """What online and offline estimators share: the declarations, the record's checks, CSV.

    Class attributes (set by each subclass): ``inputs`` (known inputs ``u``),
    ``measurements`` (``z``), ``outputs``, ``units`` (for each of them), ``event_driven``
    (True: the measurements arrive as events, a valid flag or a changed value, and the bank
    masks the others out at every sample; False: sampled every ``dt``).
    """

    inputs: ClassVar[tuple[str, ...]] = ()
    measurements: ClassVar[tuple[str, ...]] = ()
    outputs: ClassVar[tuple[str, ...]] = ()
    units: ClassVar[dict[str, str]] = {}
    offline: ClassVar[bool] = False
    event_driven: ClassVar[bool] = False

    def __init__(self, dt: float, **settings: Any) -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"{type(self).__name__}: dt must be a positive number of seconds, not {dt!r}")
        self.dt = float(dt)
        self.settings = settings
        self._n_in = len(self.measurements)
        self._n_u = len(self.inputs)

    def _n_steps(self, t_prev: float, t: float) -> int:
        n = round((t - t_prev) / self.dt)
        if n < 1 or abs((t - t_prev) - n * self.dt) > _TIME_RTOL * self.dt:
            raise ValueError(f"{type(self).__name__}.step: t = {t!r} s is not a whole number (>= 1) of "
                             f"sample times dt = {self.dt!r} s after t = {t_prev!r} s")
        return n

    def _record(self, t, Z, U, mask, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The record as float arrays, shapes checked; the mask is the caller's AND finite."""
        t = np.asarray(t, dtype=float)
        Z = np.asarray(Z, dtype=float)
        n = t.shape[0] if t.ndim == 1 else -1
        U = np.empty((max(n, 0), 0)) if U is None and self._n_u == 0 else np.asarray(U, dtype=float)
        if t.ndim != 1 or Z.shape != (n, self._n_in) or U.shape != (n, self._n_u):
            raise ValueError(f"{type(self).__name__}.{what}: t {t.shape}, Z {Z.shape} and U {U.shape} do not "
                             f"match (expected (n,), (n, {self._n_in}) measurements {self.measurements} and "
                             f"(n, {self._n_u}) inputs {self.inputs})")
        present = np.isfinite(Z)
        if mask is not None:
            mask = np.asarray(mask, dtype=bool)
            if mask.shape != Z.shape:
                raise ValueError(f"{type(self).__name__}.{what}: mask {mask.shape} does not match Z {Z.shape}")
            present &= mask
        return t, Z, U, present

    def run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray | None = None,
            mask: np.ndarray | None = None) -> np.ndarray:
        """Offline: times ``(n,)``, measurements ``Z (n, len(measurements))``, known inputs
        ``U (n, len(inputs))`` (None if it has none) and the channels present ``mask`` (bool,
        like ``Z``; default: the finite values) -> estimates ``(n, len(outputs))``."""
        raise NotImplementedError

    def run_named(self, t: np.ndarray, channels: Mapping[str, np.ndarray],
                  masks: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Offline on plain arrays named as the estimator names its channels: ``channels``
        maps every name of ``measurements`` and ``inputs`` to an array ``(n,)`` (in ``units``;
        NaN: missing), ``masks`` optionally a measurement name to its bool array (False:
        missing). Returns ``{"time": t, output: (n,) ...}``. A ValueError names a missing or
        unknown channel."""
        names = (*self.measurements, *self.inputs)
        missing = [n for n in names if n not in channels]
        unknown = sorted(set(channels) - set(names)) + sorted(set(masks or {}) - set(self.measurements))
        if missing or unknown:
            raise ValueError(f"{type(self).__name__}.run_named: "
                             + "; ".join(filter(None, [missing and f"missing channel(s) {missing}",
                                                       unknown and f"unknown channel(s) {unknown}"]))
                             + f" (measurements {self.measurements}, inputs {self.inputs})")
        t = np.asarray(t, dtype=float)
        column = lambda n: np.asarray(channels[n], dtype=float).reshape(-1)  # noqa: E731
        Z = np.column_stack([column(n) for n in self.measurements]) if self._n_in else np.empty((t.size, 0))
        U = np.column_stack([column(n) for n in self.inputs]) if self._n_u else None
        mask = None
        if masks:
            mask = np.ones(Z.shape, dtype=bool)
            for j, n in enumerate(self.measurements):
                if n in masks:
                    mask[:, j] = np.asarray(masks[n], dtype=bool).reshape(-1)
        est = np.asarray(self.run(t, Z, U, mask))
        return {"time": t, **{name: est[:, j] for j, name in enumerate(self.outputs)}}

    def run_csv(self, path: str | Path, columns: dict[str, str] | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Offline on a recorded ``signals.csv`` (header line, time column ``time``; an empty
        or NaN cell is a missing value). ``columns`` maps an input or measurement name to its
        CSV column (default: the same name). Returns ``(t, estimates)``."""
        path = Path(path)
        names = (*self.measurements, *self.inputs)
        columns = {**{name: name for name in names}, **(columns or {})}
        with open(path, newline="") as f:
            reader = csv.reader(f)
            try:
                header = next(reader)
            except StopIteration:
                raise ValueError(f"{path}: empty file") from None
            rows = [r for r in reader if r]
        index = {name.strip(): i for i, name in enumerate(header)}
        missing = [c for c in ["time", *(columns[n] for n in names)] if c not in index]
        if missing:
            raise ValueError(f"{path}: no column(s) {missing} (has {list(index)})")
        cols = [index["time"], *(index[columns[n]] for n in names)]
        try:
            data = np.array([[float(r[i]) if r[i].strip() else math.nan for i in cols] for r in rows],
                            dtype=float).reshape(-1, len(cols))
        except (ValueError, IndexError) as e:
            raise ValueError(f"{path}: unreadable row ({e})") from None
        t, Z, U = data[:, 0], data[:, 1:1 + self._n_in], data[:, 1 + self._n_in:]
        return t, self.run(t, Z, U if self._n_u else None)

    def finish(self) -> dict:
        """Diagnostics of the last run, for metrics.json."""
        return {}


class Observer(Estimator):
    """An online estimator: one :meth:`step` per sample time.

    Subclasses implement :meth:`_reset` (the initial estimate), :meth:`_input` (a new known
    input; the default keeps it in ``self._u``), :meth:`_predict` (one sample time ahead with
    the held input), :meth:`_update` (with the measurement channels present, ``mask``) and
    :meth:`_estimate` (the output vector); the bookkeeping of time, inputs and missing
    channels lives here. Diagnostics: :attr:`steps` samples, :attr:`skipped` of them with no
    measurement at all (prediction only), :attr:`partial` updated with some channels missing.
    """

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.skipped = 0
        self.partial = 0
        self.steps = 0
        self._t: float | None = None
        self._t0 = 0.0

    # -- hooks for subclasses --------------------------------------------------------------
    def _reset(self) -> None:
        raise NotImplementedError

    def _input(self, u: np.ndarray) -> None:
        self._u = u.copy()

    def _predict(self) -> None:
        raise NotImplementedError

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        raise NotImplementedError

    def _estimate(self) -> np.ndarray:
        raise NotImplementedError

    # -- the interface -----------------------------------------------------------------------
    def prepare(self) -> None:
        """Load what the first sample would otherwise load (a compiled kernel), so a run's
        set-up pays for it, not its first sample. Optional; the default does nothing."""

    def reset(self, t0: float = 0.0) -> None:
        """Back to the initial estimate; the first :meth:`step` is expected at ``t0`` (it
        updates the initial estimate without predicting)."""
        self._t0 = float(t0)
        self._t = None
        self.skipped = self.partial = self.steps = 0
        self._reset()

    def step(self, t: float, z: np.ndarray, u: np.ndarray | None = None,
             mask: np.ndarray | None = None) -> np.ndarray:
        """One sample: predict to ``t`` with the held input, take the known input ``u`` (shape
        ``(len(inputs),)``; a non-finite one keeps the held input), update with the channels
        of ``z`` (shape ``(len(measurements),)``) that are finite and in ``mask``; returns the
        estimate at ``t`` (a new array, shape ``(len(outputs),)``). Values in ``units``."""
        if self._t is None:
            n = self._n_steps(self._t0, t) if t != self._t0 else 0
        else:
            n = self._n_steps(self._t, t)
        z = np.asarray(z, dtype=float)
        if z.shape != (self._n_in,):
            raise ValueError(f"{type(self).__name__}.step: measurement of shape {z.shape}, "
                             f"expected ({self._n_in},) for measurements {self.measurements}")
        if self._n_u:
            u = np.asarray(u, dtype=float) if u is not None else None
            if u is None or u.shape != (self._n_u,):
                raise ValueError(f"{type(self).__name__}.step: known input of shape "
                                 f"{None if u is None else u.shape}, expected ({self._n_u},) for inputs {self.inputs}")
        present = np.isfinite(z)
        if mask is not None:
            present &= np.asarray(mask, dtype=bool)
        for _ in range(n):
            self._predict()
        self._t = t
        if self._n_u and np.isfinite(u).all():
            self._input(u)
        if present.all():
            self._update(z, present)
        elif present.any():
            self.partial += 1
            self._update(z, present)
        else:
            self.skipped += 1
        self.steps += 1
        return self._estimate()

    def step_block(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray | None = None,
                   mask: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """Many samples at once: row ``i`` of the result (``out`` if given, shape ``(n,
        len(outputs))``) is what ``step(t[i], Z[i], U[i], mask[i])`` returns, bit for bit
        (a subclass with a compiled block path keeps that). A failure at row ``i``
        (ArithmeticError, ValueError) propagates with ``exc.rows_done = i``: rows before it
        are in ``out``, the observer stands where ``step`` left it."""
        n = len(t)
        if out is None:
            out = np.empty((n, len(self.outputs)))
        i = 0
        try:
            for i in range(n):
                out[i] = self.step(float(t[i]), Z[i], None if U is None else U[i], None if mask is None else mask[i])
        except (ArithmeticError, ValueError) as exc:
            exc.rows_done = i
            raise
        return out

    def run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray | None = None,
            mask: np.ndarray | None = None) -> np.ndarray:
        """Offline, through :meth:`step` row by row after a reset to ``t[0]`` (so equal to
        the online estimates); arguments as :meth:`Estimator.run`."""
        t, Z, U, present = self._record(t, Z, U, mask, "run")
        out = np.empty((t.shape[0], len(self.outputs)))
        if t.shape[0] == 0:
            return out
        self.reset(float(t[0]))
        for k in range(t.shape[0]):
            out[k] = self.step(float(t[k]), Z[k], U[k] if self._n_u else None, present[k])
        return out

    def finish(self) -> dict:
        return {"steps": self.steps, "skipped": self.skipped, "partial": self.partial}


class OfflineObserver(Estimator):
    """An offline estimator (a smoother, a batch identification): run once on the whole
    record after the run. Subclasses implement :meth:`_run` on the checked record; the
    estimates are on the record's times. In an SSD it is an observer with
    ``offline="true"``: the bank runs it on the recorded signals when the run has ended."""

    offline: ClassVar[bool] = True

    def _run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray, mask: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray | None = None,
            mask: np.ndarray | None = None) -> np.ndarray:
        t, Z, U, present = self._record(t, Z, U, mask, "run")
        if t.shape[0] == 0:
            return np.empty((0, len(self.outputs)))
        return self._run(t, Z, U, present)
