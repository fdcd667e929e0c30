"""railfmu physics: one definition per model (parameters with units and sources, equations).

Imports numpy/scipy/sympy only. Each model is the single source for its FMU (fmus/) and for
any estimator's design model (estimators/).
"""

from __future__ import annotations

_BASE = ("Input", "Model", "Output", "Parameter", "State", "Variable")


def __getattr__(name: str):
    # lazily: ``railfmu.models.errors`` or ``earth`` must not pull in sympy through ``base``
    if name in _BASE:
        from railfmu.models import base

        return getattr(base, name)
    raise AttributeError(f"module 'railfmu.models' has no attribute {name!r}")


def all_models() -> list:
    """Every model that is built into an FMU, in build order."""
    from railfmu.models.vehicle.coach_vertical import COACH_VERTICAL
    from railfmu.models.train.driver import DRIVER
    from railfmu.models.train.gnss import GNSS_RECEIVER
    from railfmu.models.inertial.imu_errors import IMU_ERRORS
    from railfmu.models.sources.sensors import SENSORS
    from railfmu.models.sources.signal_table import SIGNAL_TABLE
    from railfmu.models.sources.step_source import STEP_SOURCE
    from railfmu.models.track.irregularity import TRACK
    from railfmu.models.track.recording import TRACK_RECORDING
    from railfmu.models.vehicle.vehicle_lateral import VEHICLE_LATERAL
    from railfmu.models.train.longitudinal import TRAIN_LONGITUDINAL
    from railfmu.models.inertial.trolley import TROLLEY
    from railfmu.models.vehicle.wheelset import WHEELSET

    return [TRACK, WHEELSET, COACH_VERTICAL, STEP_SOURCE, SENSORS, VEHICLE_LATERAL, SIGNAL_TABLE,
            TRAIN_LONGITUDINAL, GNSS_RECEIVER, DRIVER, IMU_ERRORS, TROLLEY, TRACK_RECORDING]


__all__ = ["Input", "Model", "Output", "Parameter", "State", "Variable", "all_models"]
