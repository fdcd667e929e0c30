"""Observers attached to a run: a recorder sink that feeds each estimator its bound signals.

The SSD declares each observer (``org.railfmu.observers`` annotation, read into
:class:`fmus.cosim.system.ObserverSpec`). :class:`ObserverBank` instantiates them and, as a sink
of the master, hands every recorded row to each observer's ``step`` — one communication
step at a time inside the Python masters, row by row from blocks on the container path
(observers are passive, so both see the same samples). ``estimates.csv`` is written as the
run goes, like ``signals.csv``.
"""

from __future__ import annotations

import importlib
import math
from pathlib import Path

import numpy as np

from fmus.errors import UserError
from fmus.cosim.recorder import CsvRecorder
from fmus.cosim.system import ObserverSpec, System


def make_observer(spec: ObserverSpec, dt: float, where: str):
    """Import ``spec.cls`` and instantiate it with the spec's settings (a UserError if not possible)."""
    module_name, _, class_name = spec.cls.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError, ValueError):
        raise UserError(f"{where}: Observer {spec.name!r}: cannot import class {spec.cls!r}") from None
    try:
        obs = cls(dt, **spec.settings)
    except (TypeError, ValueError) as exc:
        raise UserError(f"{where}: Observer {spec.name!r}: bad settings: {exc}") from None
    missing = [k for k in obs.inputs if k not in spec.inputs]
    unknown = [k for k in spec.inputs if k not in obs.inputs]
    if missing or unknown:
        raise UserError(f"{where}: Observer {spec.name!r}: inputs must be {', '.join(obs.inputs)}"
                        f" ({'missing ' + ', '.join(missing) if missing else 'unknown ' + ', '.join(unknown)})")
    bad_truth = [k for k in spec.truth if k not in obs.outputs]
    if bad_truth:
        raise UserError(f"{where}: Observer {spec.name!r}: Truth {bad_truth[0]!r} is not one of its "
                        f"outputs ({', '.join(obs.outputs)})")
    return obs


class ObserverBank:
    """A :class:`fmus.cosim.system.Sink` running every observer of a system and writing estimates.csv."""

    def __init__(self, system: System, out_csv: Path | None):
        where = str(system.source or system.name)
        self.specs = system.observers
        self.observers = [make_observer(s, system.step_size, where) for s in self.specs]
        self.recorder = CsvRecorder(out_csv) if out_csv is not None else None
        self.times: list[float] = []
        self.estimates: list[np.ndarray] = []  # one (n_outputs_total,) row per sample

    @property
    def columns(self) -> list[str]:
        return [f"{s.name}.{o}" for s, obs in zip(self.specs, self.observers) for o in obs.outputs]

    def open(self, columns: list[str]) -> None:
        self._index = []
        for spec, obs in zip(self.specs, self.observers):
            try:
                self._index.append([columns.index(spec.inputs[k]) for k in obs.inputs])
            except ValueError:
                raise UserError(f"Observer {spec.name!r}: an input signal is not recorded") from None
        for obs in self.observers:
            obs.reset(0.0)
        if self.recorder is not None:  # the same writer as signals.csv: complete rows, as it goes
            self.recorder.open(["time", *self.columns])

    def write(self, row: np.ndarray) -> None:
        t = float(row[0])
        est = np.concatenate([obs.step(t, row[idx]) for obs, idx in zip(self.observers, self._index)]) \
            if self.observers else np.empty(0)
        self.times.append(t)
        self.estimates.append(est)
        if self.recorder is not None:
            self.recorder.write(np.concatenate(([t], est)))

    def write_block(self, rows: np.ndarray) -> None:
        for row in rows:
            self.write(row)

    def close(self, complete: bool) -> None:
        if self.recorder is not None:
            self.recorder.close(complete)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(self.times)
        return t, (np.vstack(self.estimates) if self.estimates else np.empty((0, len(self.columns))))

    def metrics(self, signals: dict[str, np.ndarray], settle_fraction: float = 0.1) -> dict:
        """Per observer: its diagnostics and, for every estimate with a truth signal, the rms
        error against it after the first ``settle_fraction`` of the run (the filter's transient)."""
        t, est = self.arrays()
        out: dict[str, dict] = {}
        col = 0
        n0 = math.ceil(settle_fraction * len(t))
        for spec, obs in zip(self.specs, self.observers):
            m: dict = dict(obs.finish())
            for j, name in enumerate(obs.outputs):
                if name in spec.truth and len(t) > n0:
                    truth = np.asarray(signals[spec.truth[name]])[n0:len(t)]
                    err = est[n0:, col + j] - truth
                    rms_truth = float(np.sqrt(np.mean(truth ** 2)))
                    rms_err = float(np.sqrt(np.mean(err ** 2)))
                    m[name] = {"rms_error": rms_err, "rms_truth": rms_truth,
                               "rel_error": rms_err / rms_truth if rms_truth > 0 else None,
                               "from_time_s": float(t[n0])}
            out[spec.name] = m
            col += len(obs.outputs)
        return out
