"""A model's numbers for an estimator's design, without building the model.

An estimator designed on a model (the alignment filter on the wheelset) needs its parameters
(defaults and range checks), the names of its inputs and outputs, and its linearisation at the
run's parameter values. Building the model means importing sympy and deriving its expressions
(a few tenths of a second), which a run that has those numbers cached never needs.
:class:`DesignModel` reads them from the per-user cache (``<cache>/design/``) and builds the
model (``module:name``) only on a miss: the first run of a version of the sources, or a
linearisation at new parameter values, which the model then computes as
:meth:`railfmu.models.base.Model.linearize` always does; the arrays are stored as float64, so
the numbers are the model's bit for bit.

The key is a hash of the bytes of every file under ``models/`` (as the FMU build's key is) and
of the numpy and sympy versions: any change to a model definition is a new entry.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from railfmu.models.cache import cache_root, write_atomic

_MODELS = Path(__file__).resolve().parent


def check_parameters(identifier: str, parameters: Sequence[Any], params: Mapping[str, float]) -> None:
    """The range checks the FMU applies when initialisation ends, on ``params`` (missing ones
    at their ``start``) against ``parameters`` (each with name, start, type, min, max,
    positive); a ValueError naming the first violation."""
    for p in parameters:
        if p.type not in ("Real", "Integer"):
            continue
        v = params.get(p.name, p.start)
        if p.min is not None and not v >= p.min:
            raise ValueError(f"{identifier}: parameter {p.name} = {v} is below its minimum {p.min}")
        if p.positive and not v > 0:
            raise ValueError(f"{identifier}: parameter {p.name} = {v} must be > 0")
        if p.max is not None and not v <= p.max:
            raise ValueError(f"{identifier}: parameter {p.name} = {v} is above its maximum {p.max}")


@dataclass(frozen=True)
class ParameterSpec:
    """What a parameter check needs of a :class:`railfmu.models.base.Parameter`."""

    name: str
    start: Any
    type: str = "Real"
    min: float | None = None
    max: float | None = None
    positive: bool = False


def _sources_key(ref: str) -> str:
    h = hashlib.sha256(f"{ref} numpy {np.__version__}".encode())
    spec = importlib.util.find_spec("sympy")  # its version without importing it
    release = Path(spec.origin).parent / "release.py" if spec is not None and spec.origin else None
    h.update(release.read_bytes() if release is not None and release.is_file() else b"no sympy")
    for f in sorted(_MODELS.rglob("*")):
        if f.is_file() and "__pycache__" not in f.parts:
            h.update(f.relative_to(_MODELS).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:32]


class DesignModel:
    """The design numbers of the model ``name`` in module ``module``, e.g.
    ``DesignModel("railfmu.models.vehicle.wheelset", "WHEELSET")``: what
    :class:`railfmu.models.base.Model` gives for :meth:`default_parameters`,
    :meth:`check_parameters` and :meth:`linearize`, and the names of its ``inputs``,
    ``states`` and ``outputs``."""

    def __init__(self, module: str, name: str) -> None:
        self.module, self.name = module, name
        self._key: str | None = None
        self._spec: dict | None = None
        self._memo: dict[tuple, tuple] = {}

    def model(self):
        """The model itself (imports its module: sympy, the expressions)."""
        return getattr(importlib.import_module(self.module), self.name)

    @property
    def key(self) -> str:
        if self._key is None:
            self._key = _sources_key(f"{self.module}:{self.name}")
        return self._key

    def _path(self, suffix: str) -> Path:
        return cache_root() / "design" / f"{self.key}{suffix}"

    @property
    def spec(self) -> dict:
        """identifier, parameters, inputs (name, start), states, outputs: from the cache, else
        from the model (and stored)."""
        if self._spec is None:
            path = self._path(".json")
            try:
                self._spec = json.loads(path.read_text())
            except (OSError, ValueError):
                m = self.model()
                self._spec = {
                    "identifier": m.identifier,
                    "parameters": [[p.name, p.start, p.type, p.min, p.max, p.positive] for p in m.parameters],
                    "inputs": [[u.name, u.start] for u in m.inputs],
                    "states": [s.name for s in m.states],
                    "outputs": [o.name for o in m.outputs],
                }
                try:
                    text = json.dumps(self._spec)  # floats as repr: read back bit for bit
                except (TypeError, ValueError):  # a start value JSON cannot hold: built every time
                    text = None
                if text is not None:
                    write_atomic(path, lambda f: f.write(text.encode()))
        return self._spec

    @property
    def identifier(self) -> str:
        return self.spec["identifier"]

    @property
    def parameters(self) -> list[ParameterSpec]:
        return [ParameterSpec(*p) for p in self.spec["parameters"]]

    @property
    def inputs(self) -> list[str]:
        return [u[0] for u in self.spec["inputs"]]

    @property
    def states(self) -> list[str]:
        return list(self.spec["states"])

    @property
    def outputs(self) -> list[str]:
        return list(self.spec["outputs"])

    def default_parameters(self) -> dict[str, Any]:
        return {p[0]: p[1] for p in self.spec["parameters"]}

    def check_parameters(self, params: Mapping[str, float]) -> None:
        check_parameters(self.identifier, self.parameters, params)

    def linearize(self, p: Mapping[str, float] | None = None, u0: Mapping[str, float] | None = None):
        """:meth:`railfmu.models.base.Model.linearize` (same arguments, same arrays)."""
        pv = {**self.default_parameters(), **(p or {})}
        uv = {**{name: start for name, start in self.spec["inputs"]}, **(u0 or {})}
        key = (tuple(sorted(pv.items())), tuple(sorted(uv.items())))
        if key not in self._memo:
            path = self._path(f"-{hashlib.sha256(repr(key).encode()).hexdigest()[:32]}.npz")
            try:
                with np.load(path) as z:
                    mats = tuple(z[n] for n in "ABCD")
            except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):  # none yet, or a damaged file
                mats = self.model().linearize(pv, uv)
                write_atomic(path, lambda f: np.savez(f, **dict(zip("ABCD", mats))))
            self._memo[key] = mats
        return tuple(m.copy() for m in self._memo[key])
