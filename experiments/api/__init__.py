"""railfmu: model-based monitoring of railway vehicles and track.

FMI Co-Simulation FMUs of vehicles, tracks and sensors, SSP experiments, and estimators
(Kalman filters, UKF, aided INS with RTS smoother, suspension identification) that observe a
running co-simulation or replay measured data.

Sub-packages, in dependency order (each imports only those below it):

* :mod:`railfmu.experiments` — the run engine (runner, observer bank, study, CLI) and one
  folder per study;
* :mod:`railfmu.estimators` — the estimation core and the domains (inertial navigation, track
  geometry, train dynamics, vehicle suspension);
* :mod:`railfmu.fmus` — everything FMI/SSP: C runtime, code generation and build, masters,
  SSP read/write;
* :mod:`railfmu.models` — the physics: one definition per model.

This file is the package ``railfmu`` itself; in the repository it lives in ``experiments/api/``
because the top-level folders are fixed (``pyproject.toml`` maps it).
"""

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("railfmu")
except PackageNotFoundError:  # imported from a checkout that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
