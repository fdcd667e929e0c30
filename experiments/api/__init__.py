"""railfmu: model-based monitoring of railway vehicles and track.

FMI Co-Simulation FMUs of vehicles, tracks and sensors, SSP experiments, and estimators
(Kalman filters, UKF, aided INS with RTS smoother, suspension identification) that observe a
running co-simulation or replay measured data.

The public API (the command line ``railfmu`` is a thin layer over it)::

    import railfmu
    r = railfmu.run("track_wheelset", seed=1, stop_time=5.0)
    r.signals["wheelset.y"], r.estimates["alignment"]["xi"], r.metrics["rms"]
    r.save("out/tw")

* :func:`run` -> :class:`Run`; :func:`study` (variants x seeds on Dask); :func:`export` (a
  self-contained ``.ssp``); :func:`read_ssp` (the resolved system); :func:`parameters` (what
  ``parameters=`` / ``--set`` can change); :func:`list_experiments`; :func:`register_study`
  (the study an SSD's ``org.railfmu.study`` annotation names); :class:`UserError`.

Sub-packages, in dependency order (each imports only those below it):

* :mod:`railfmu.experiments` — the run engine (runner, observer bank, study, CLI, this API)
  and one folder per study;
* :mod:`railfmu.estimators` — the estimation core and the domains (inertial navigation, track
  geometry, train dynamics, vehicle suspension);
* :mod:`railfmu.fmus` — everything FMI/SSP: C runtime, code generation and build, masters,
  SSP read/write;
* :mod:`railfmu.models` — the physics: one definition per model.

This file is the package ``railfmu`` itself; in the repository it lives in ``experiments/api/``
because the top-level folders are fixed (``pyproject.toml`` maps it). ``import railfmu`` loads
nothing else: the API is imported on first use (module ``__getattr__``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

# public name -> the module defining it, imported on first access (numpy, FMPy: seconds)
_LAZY = {
    "run": "railfmu.experiments.engine.api",
    "study": "railfmu.experiments.engine.api",
    "export": "railfmu.experiments.engine.api",
    "read_ssp": "railfmu.experiments.engine.api",
    "parameters": "railfmu.experiments.engine.api",
    "list_experiments": "railfmu.experiments.engine.api",
    "read_signals": "railfmu.experiments.engine.api",
    "register_study": "railfmu.experiments.engine.studies",
    "Run": "railfmu.experiments.engine.result",
    "Parameter": "railfmu.experiments.engine.parameters",
    "Study": "railfmu.experiments.engine.study_protocol",
    "UserError": "railfmu.models.errors",
}

__all__ = ["__version__", *_LAZY]

if TYPE_CHECKING:  # what type checkers and IDEs see
    __version__: str
    from railfmu.experiments.engine.api import (export, list_experiments, parameters, read_signals, read_ssp,
                                                run, study)
    from railfmu.experiments.engine.parameters import Parameter
    from railfmu.experiments.engine.result import Run
    from railfmu.experiments.engine.studies import register_study
    from railfmu.experiments.engine.study_protocol import Study
    from railfmu.models.errors import UserError


def _package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version  # ~0.1 s of imports: on first use

    try:
        return version("railfmu")
    except PackageNotFoundError:  # imported from a checkout that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        globals()[name] = value = _package_version()
        return value
    if name not in _LAZY:
        raise AttributeError(f"module 'railfmu' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value  # once: later lookups do not come here
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
