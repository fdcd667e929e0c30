"""railfmu physics: one definition per model (parameters with units and sources, equations).

Imports numpy/scipy/sympy only. Each model is the single source for its FMU (fmus/) and for
any estimator's design model (estimators/).
"""

from .base import Input, Model, Output, Parameter, State, Variable


def all_models() -> list[Model]:
    """Every model that is built into an FMU, in build order."""
    from .coach_vertical import COACH_VERTICAL
    from .driver import DRIVER
    from .gnss import GNSS_RECEIVER
    from .imu_errors import IMU_ERRORS
    from .sensors import SENSORS
    from .signal_table import SIGNAL_TABLE
    from .step_source import STEP_SOURCE
    from .track import TRACK
    from .vehicle_lateral import VEHICLE_LATERAL
    from .train_longitudinal import TRAIN_LONGITUDINAL
    from .trolley import TROLLEY
    from .wheelset import WHEELSET

    return [TRACK, WHEELSET, COACH_VERTICAL, STEP_SOURCE, SENSORS, VEHICLE_LATERAL, SIGNAL_TABLE,
            TRAIN_LONGITUDINAL, GNSS_RECEIVER, DRIVER, IMU_ERRORS, TROLLEY]


__all__ = ["Input", "Model", "Output", "Parameter", "State", "Variable", "all_models"]
