"""The interface every estimator block implements: the same object runs online and offline.

Online, a co-simulation master calls :meth:`Observer.step` once per communication step with
the current row of the signals the observer is bound to. Offline, :meth:`Observer.run` feeds
recorded arrays and :meth:`Observer.run_csv` a recorded ``signals.csv``; both reset first and
then call :meth:`Observer.step` row by row, so online and offline estimates are bit-identical.

Sampling: an observer is designed for a fixed sample time ``dt``. Between two calls of
``step`` it predicts ``round((t - t_prev) / dt)`` steps, so a dropped row costs accuracy, not
correctness; a time that is not a whole number of steps later is an error. A measurement row
with any non-finite value (NaN, inf) is never used: the observer predicts only, and counts the
row in :attr:`Observer.skipped`.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

#: relative tolerance on t - t_prev being a whole number of sample times
_TIME_RTOL = 1e-6


class Observer:
    """Base of every estimator block.

    Class attributes (set by each subclass):

    * ``inputs``: names of the measurements it reads, in order (units in ``units``);
    * ``outputs``: names of its estimates, in order;
    * ``units``: unit of each input and output (FMI unit names, '' = dimensionless).

    Subclasses implement :meth:`_reset` (the initial estimate), :meth:`_predict` (one sample
    time ahead), :meth:`_update` (with one finite measurement row) and :meth:`_estimate`
    (the output vector); the bookkeeping of time and skipped rows lives here.
    """

    inputs: ClassVar[tuple[str, ...]] = ()
    outputs: ClassVar[tuple[str, ...]] = ()
    units: ClassVar[dict[str, str]] = {}

    def __init__(self, dt: float, **settings: Any) -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"{type(self).__name__}: dt must be a positive number of seconds, not {dt!r}")
        self.dt = float(dt)
        self.settings = settings
        self.skipped = 0
        self.steps = 0
        self._t: float | None = None
        self._t0 = 0.0
        self._n_in = len(self.inputs)

    # -- hooks for subclasses --------------------------------------------------------------
    def _reset(self) -> None:
        raise NotImplementedError

    def _predict(self) -> None:
        raise NotImplementedError

    def _update(self, z: np.ndarray) -> None:
        raise NotImplementedError

    def _estimate(self) -> np.ndarray:
        raise NotImplementedError

    # -- the interface -----------------------------------------------------------------------
    def reset(self, t0: float = 0.0) -> None:
        """Back to the initial estimate; the first :meth:`step` is expected at ``t0`` (it
        updates the initial estimate without predicting)."""
        self._t0 = float(t0)
        self._t = None
        self.skipped = 0
        self.steps = 0
        self._reset()

    def step(self, t: float, z: np.ndarray) -> np.ndarray:
        """One sample: predict to ``t``, update with ``z`` (shape ``(len(inputs),)``, in the
        units of ``units``) unless it has a non-finite value; returns the estimate at ``t``
        (a new array, shape ``(len(outputs),)``)."""
        if self._t is None:
            n = self._n_steps(self._t0, t) if t != self._t0 else 0
        else:
            n = self._n_steps(self._t, t)
        for _ in range(n):
            self._predict()
        self._t = t
        z = np.asarray(z, dtype=float)
        if z.shape != (self._n_in,):
            raise ValueError(f"{type(self).__name__}.step: measurement of shape {z.shape}, "
                             f"expected ({self._n_in},) for inputs {self.inputs}")
        if np.isfinite(z).all():
            self._update(z)
        else:
            self.skipped += 1
        self.steps += 1
        return self._estimate()

    def _n_steps(self, t_prev: float, t: float) -> int:
        n = round((t - t_prev) / self.dt)
        if n < 1 or abs((t - t_prev) - n * self.dt) > _TIME_RTOL * self.dt:
            raise ValueError(f"{type(self).__name__}.step: t = {t!r} s is not a whole number (>= 1) of "
                             f"sample times dt = {self.dt!r} s after t = {t_prev!r} s")
        return n

    def run(self, t: np.ndarray, Z: np.ndarray) -> np.ndarray:
        """Offline: times ``(n,)`` and measurements ``(n, len(inputs))`` -> estimates
        ``(n, len(outputs))``. Resets to ``t[0]`` first; row by row through :meth:`step`."""
        t = np.asarray(t, dtype=float)
        Z = np.asarray(Z, dtype=float)
        if t.ndim != 1 or Z.shape != (t.shape[0], self._n_in):
            raise ValueError(f"{type(self).__name__}.run: t {t.shape} and Z {Z.shape} do not match "
                             f"(expected (n,) and (n, {self._n_in}))")
        out = np.empty((t.shape[0], len(self.outputs)))
        if t.shape[0] == 0:
            return out
        self.reset(float(t[0]))
        for k in range(t.shape[0]):
            out[k] = self.step(float(t[k]), Z[k])
        return out

    def run_csv(self, path: str | Path, columns: dict[str, str] | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Offline on a recorded ``signals.csv`` (header line, time column ``time``).
        ``columns`` maps an input name to its CSV column (default: the same name).
        Returns ``(t, estimates)``."""
        path = Path(path)
        columns = {**{name: name for name in self.inputs}, **(columns or {})}
        with open(path, newline="") as f:
            reader = csv.reader(f)
            try:
                header = next(reader)
            except StopIteration:
                raise ValueError(f"{path}: empty file") from None
            rows = [r for r in reader if r]
        index = {name.strip(): i for i, name in enumerate(header)}
        missing = [c for c in ["time", *(columns[n] for n in self.inputs)] if c not in index]
        if missing:
            raise ValueError(f"{path}: no column(s) {missing} (has {list(index)})")
        cols = [index["time"], *(index[columns[n]] for n in self.inputs)]
        try:
            data = np.array([[float(r[i]) for i in cols] for r in rows], dtype=float).reshape(-1, len(cols))
        except (ValueError, IndexError) as e:
            raise ValueError(f"{path}: unreadable row ({e})") from None
        return data[:, 0], self.run(data[:, 0], data[:, 1:])

    def finish(self) -> dict:
        """Diagnostics of the last run, for metrics.json."""
        return {"steps": self.steps, "skipped": self.skipped}
