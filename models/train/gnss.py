r"""GNSS receiver: position and speed fixes every ``sample_period``, as the on-board GPS of
Cunillera et al. (2022) §4.1 (both sampled every 10 s; speed in km/h with an accuracy of 1 km/h;
the UKF's position noise 4 m, §4.2).

Measurement equation, with ``t0`` the start time, ``T = sample_period``, ``h`` the
communication step that ended at ``t`` (0 in initialisation mode) and ``eps`` =
``STEP_TOLERANCE`` = 0.01 (the sample index of ``models/sources/sensors.py``)::

    k(t)      = max(floor((t - t0) / T + eps min(h / T, 1)), 0)
    valid     = h = 0  or  k(t) > k(t - h)       a new sample instant reached at this point
    position  = s_true + position_sigma w(seed, 1, k)          (m)
    speed_kmh = q floor(3.6 v_true / q + 1/2)                  q = speed_resolution_kmh (> 0)
    speed     = speed_kmh / 3.6                                (m/s)

``w`` is the counter-based Gaussian of ``railfmu.models.sources.sensors.noise`` (SplitMix64 + Box-Muller):
a pure function of (seed, k), so any importer, step size or restored FMU state gives the
same fixes. The FMU has no memory: between fixes the outputs follow the true inputs with the
last sample's noise; an observer reads them where ``valid`` is true. With a communication
step that divides ``T`` the fixes are at exactly ``t0 + k T``, whether the master computes
its time as ``n h`` or accumulates ``t += h`` (within 1 % of ``h``). A step longer than ``T``
gives one fix per step. The C is hand-written (``fmus/native/models/GnssReceiver.c``, for
the noise's 64-bit arithmetic); :class:`Gnss` is its Python twin.
"""

from __future__ import annotations

import math
from typing import Mapping

from railfmu.models.base import STEP_TOLERANCE, Input, Model, Output, Parameter
from railfmu.models.sources.sensors import noise

PAPER = "Cunillera et al. (2022)"


def build() -> Model:
    parameters = [
        Parameter("sample_period", "Time between fixes T", "s", 10.0, source=f"{PAPER} §4.1", positive=True),
        Parameter("position_sigma", "Standard deviation of the position noise", "m", 4.0,
                  source=f"{PAPER} §4.2", min=0.0),
        Parameter("speed_resolution_kmh", "Speed reading resolution in km/h (0: no rounding)", "", 1.0,
                  source=f"{PAPER} §4.1", min=0.0),
        Parameter("seed", "Seed of the position noise", start=1, type="Integer", source="experiment (.ssv)"),
    ]
    inputs = [Input("s_true", "True position along the line", "m", 0.0),
              Input("v_true", "True speed", "m/s", 0.0)]
    outputs = [
        Output("position", "Measured position (valid where valid is true)", "m", depends_on=("s_true",)),
        Output("speed", "Measured speed: speed_kmh / 3.6", "m/s", depends_on=("v_true",)),
        Output("speed_kmh", "Measured speed as the receiver reports it, in km/h, rounded", "", depends_on=("v_true",)),
        Output("valid", "True at the communication point that reaches a new fix", type="Boolean", depends_on=()),
        Output("sample", "Index k of the current fix", type="Integer", depends_on=()),
    ]
    return Model(
        identifier="GnssReceiver",
        description="GNSS position and speed fixes every sample_period: position noise, speed "
                    "rounded to a resolution, a Boolean valid flag at the fixes",
        parameters=parameters, inputs=inputs, outputs=outputs,
        default_experiment=(0.0, 1500.0, 1.0),
        c_sources=["GnssReceiver.c"],
        documentation=__doc__,
    )


GNSS_RECEIVER = build()


def sample_index(t: float, h: float, t0: float, T: float) -> int:
    return max(math.floor((t - t0) / T + STEP_TOLERANCE * min(h / T, 1.0)), 0)


class Gnss:
    """Python twin of the GnssReceiver FMU."""

    def __init__(self, params: Mapping[str, float] | None = None):
        self.p = {**GNSS_RECEIVER.default_parameters(), **(params or {})}
        GNSS_RECEIVER.check_parameters(self.p)

    def outputs(self, t: float, h: float, s_true: float, v_true: float, t0: float = 0.0) -> dict:
        p = self.p
        T = p["sample_period"]
        k = sample_index(t, h, t0, T)
        valid = h == 0 or k > sample_index(t - h, h, t0, T)
        sigma = p["position_sigma"]
        w = float(noise(p["seed"], 1, [k])[0]) if sigma != 0 else 0.0
        q = p["speed_resolution_kmh"]
        kmh = v_true * 3.6
        if q > 0:
            kmh = q * math.floor(kmh / q + 0.5)
        return {"position": s_true + sigma * w, "speed": kmh / 3.6, "speed_kmh": kmh,
                "valid": bool(valid), "sample": k}
