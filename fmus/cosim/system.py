"""A co-simulation system ready to run: what the SSP reader produces and the masters consume.

Everything here is resolved: FMU files exist, parameter values are final (FMU defaults <
SSD bindings < variant .ssv < command line), each connection carries one affine map
``dst = factor * src + offset`` (the SSD's LinearTransformation composed with any unit
conversion), and the experiment's time grid is fixed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

Value = float | int | bool | str


@dataclass
class Component:
    name: str
    fmu: Path
    parameters: dict[str, Value] = field(default_factory=dict)  # FMU variable name -> value


@dataclass
class Connection:
    src: str  # component name
    src_var: str
    dst: str
    dst_var: str
    factor: float = 1.0  # dst = factor * src + offset
    offset: float = 0.0

    @property
    def identity(self) -> bool:
        return self.factor == 1.0 and self.offset == 0.0

    def __str__(self) -> str:
        return f"{self.src}.{self.src_var} -> {self.dst}.{self.dst_var}"


@dataclass
class ObserverSpec:
    """An estimator attached to the run (declared in the SSD's railfmu annotation).

    ``cls`` is a dotted path ``package.module.Class``; ``measurements`` and ``inputs`` (its
    known inputs) map the observer's names to recorded signals ``component.variable``;
    ``valid`` maps a measurement to a flag signal (nonzero: the measurement is there);
    ``truth`` maps estimate names to the recorded signals they are scored against (metrics
    only, never fed to the estimator); ``settings`` are keyword arguments of the class.
    ``period``: its sample period in s (None: the system's step); ``event``: its
    measurements arrive as events (None: as its class declares); ``offline``: run once on
    the whole record after the run. ``units``: the unit of each bound signal that has one
    (an ``fmus.ssp.units.Unit``), for the bank's unit checks.
    """
    name: str
    cls: str
    measurements: dict[str, str] = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)
    truth: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Value] = field(default_factory=dict)
    valid: dict[str, str] = field(default_factory=dict)
    period: float | None = None
    event: bool | None = None
    offline: bool = False
    units: dict[str, object] = field(default_factory=dict)

    @property
    def signals(self) -> list[str]:
        """Every recorded signal it reads (fed or scored)."""
        return [*self.measurements.values(), *self.inputs.values(), *self.valid.values(), *self.truth.values()]


@dataclass
class System:
    name: str
    components: list[Component]
    connections: list[Connection]
    start_time: float = 0.0
    stop_time: float = 1.0
    step_size: float = 1e-3
    record: list[str] = field(default_factory=list)  # "component.variable"; empty: every output
    observers: list[ObserverSpec] = field(default_factory=list)
    source: Path | None = None  # the SSD (or .ssp) it came from, for messages
    description: str = ""
    warnings: list[str] = field(default_factory=list)  # e.g. an unconnected input keeping its start

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def n_steps(self) -> int:
        return round((self.stop_time - self.start_time) / self.step_size)


def recorded_signals(system: System, variables: dict[str, dict]) -> list[str]:
    """``system.record``, or every Real output of every component in component order;
    ``variables`` maps component names to their FMU variables by name."""
    from ..errors import UserError

    if system.record:
        for signal in system.record:
            if "." not in signal:
                raise UserError(f"recorded signal {signal!r}: expected component.variable")
        return list(system.record)
    return [f"{c.name}.{v.name}" for c in system.components for v in variables[c.name].values()
            if v.causality == "output" and v.type == "Real"]


class Sink(Protocol):
    """Receives the recorded samples of a run: the CSV recorder, observers.

    ``columns`` are ``time`` followed by the recorded signals. Masters that step in Python
    call :meth:`write` once per communication point; the container path calls
    :meth:`write_block` with many rows at once. ``close(complete)`` says whether the run
    reached its stop time.
    """

    def open(self, columns: list[str]) -> None: ...

    def write(self, row: np.ndarray) -> None: ...

    def write_block(self, rows: np.ndarray) -> None: ...

    def close(self, complete: bool) -> None: ...
