r"""Sensor noise: the inertial sensors of a monitoring system as a component of the co-simulation.

The ``SensorNoise`` FMU turns up to eight true signals (accelerations, angular rates, ... from
the vehicle FMUs) into measurements, as the synthetic sensor data of Muñoz et al. (§4.2 and §5:
"contaminated with the Gaussian white noise of the sensors") and Onat et al. (2016) (§3, the
noise r ~ N(0, R) of its measurement equation). Its C code is hand written
(``fmus/native/models/SensorNoise.c``); ``tests/test_sensors.py`` proves it equals this module bit for bit.

Measurement equation
--------------------
For channel ``i = 1..8``, with ``t0`` the start time (fmi2SetupExperiment), ``T`` =
``sample_period`` and ``h`` the communication step that ended at ``t`` (s; 0 in
initialisation mode)::

    k     = floor((t - t0) / T + eps min(h / T, 1))         sample index (k >= 0)
    y_i   = gain_i u_i + bias_i + sigma_i w_i(k)            enabled = true, distribution_i = 0
    y_i   = gain_i u_i + bias_i exp(sigma_i (2 u2_i(k) - 1))  enabled = true, distribution_i = 1
    y_i   = gain_i u_i + bias_i + sigma_i (2 u2_i(k) - 1)     enabled = true, distribution_i = 2
    y_i   = u_i                                             enabled = false (exactly)
    eps   = STEP_TOLERANCE = 0.01

evaluated at every communication point (and in initialisation mode). The noise is held over a
sample period: a communication step shorter than ``T`` sees the same ``w_i(k)``; a longer one
skips samples. ``w_i = 0`` when ``sigma_i = 0``. ``y_i`` depends directly on ``u_i`` only
(declared in the ModelStructure).

``distribution_i = 1`` makes channel i a log-uniform scatter of its bias instead of additive
Gaussian noise: ``bias_i`` is the geometric centre and ``sigma_i`` the half-width of the
uniform interval of ``ln(y_i / bias_i)`` (at ``u_i = 0``), ``u2_i(k)`` the uniform of
channel i's stream at sample k below (the one Box-Muller's cosine reads): ``sigma_i = ln 2``
draws ``y_i`` between ``bias_i / 2`` and ``2 bias_i``, every ratio scale equally likely (an
unknown vehicle's Davis coefficient; held over a run by a long ``sample_period``).
``distribution_i = 2`` draws uniformly between ``bias_i - sigma_i`` and ``bias_i + sigma_i``
from the same ``u2_i(k)`` (a train's load between empty and full).

Sample instants and the master's clock: ``k`` counts the sample instants ``t0 + j T`` reached
at ``t``, and an instant that lies less than ``eps min(h, T)`` after ``t`` counts as reached.
FMI does not say how a master computes its communication points: ``t0 + n h`` in floating
point lands just below a sample instant (``2001 * 1e-3 / 1e-3 = 2000.9999999999998``), and a
master that accumulates ``t += h`` (OMSimulator, FMPy's container FMU) drifts from
``n h`` by a fraction of ``h`` that grows as ``n^2`` and stays below ``eps`` over runs of
millions of steps. Both give the same ``k`` as the exact grid. The tolerance is a fraction
of the step the FMU sees (``fmi2DoStep``'s ``communicationStepSize``), not of ``t``, so it
does not grow over a long run; ``min(h, T)`` keeps it a fraction of one sample when a step
spans several. A sample instant further than ``eps min(h, T)`` after ``t`` belongs to the
next communication point, so a period that is not a multiple of the step keeps its meaning.
At ``t0`` (``h = 0``) ``k`` is 0. The noise at a communication point is therefore the same
whatever the step sizes that led there, except for an instant within that band.

Inputs, outputs, sigma and bias carry no unit: the FMU is generic and connects to any Real
output (a unit-less connector is never converted by the SSP reader, ``fmus/ssp/units.py``);
``sigma_i`` and ``bias_i`` are in the unit of what channel ``i`` carries, say which in the
``.ssv`` that sets them.

Counter-based Gaussian white noise
----------------------------------
``w_i(k)`` is a pure function of ``(seed, i, k)``: no generator state advances with the steps,
so saving/restoring the FMU state, any importer (FMPy, libcosim, a container FMU) and any step
size give the same noise for the same seed. With ``mix64`` the SplitMix64 output function
(Steele, Lea & Flood, OOPSLA 2014; the same constants as ``railfmu.models.track.irregularity.SplitMix64``) and
``G = 0x9E3779B97F4A7C15`` (all arithmetic modulo 2^64)::

    mix64(z) = z ^= z >> 30; z *= 0xBF58476D1CE4E5B9; z ^= z >> 27; z *= 0x94D049BB133111EB;
               z ^ (z >> 31)

    s     = seed as unsigned 64-bit (two's complement for a negative seed)
    c_i   = mix64(s + i G)                      the i-th output of SplitMix64(seed)
    z1    = mix64(c_i + (2k + 1) G)             outputs 2k+1 and 2k+2 of SplitMix64(c_i):
    z2    = mix64(c_i + (2k + 2) G)             channel i's stream, read at position k
    u1    = ((z1 >> 11) + 1) 2^-53              in (0, 1]   (log(u1) finite)
    u2    = (z2 >> 11) 2^-53                    in [0, 1)
    w     = sqrt(-2 log(u1)) cos(2 pi u2)       Box-Muller, cosine branch; |w| <= 8.57

All integer-to-double conversions are exact (< 2^53). ``log`` and ``cos`` come from the C
library in both the FMU and :func:`noise` (Python's ``math`` calls libm): numpy's SIMD ``log``
differs from glibc's in the last bit for a small share of arguments, so the twin does not use it for
the bit-exact path.

Parameters
----------
============== ====== ======= =========================================================
name           unit   default source
============== ====== ======= =========================================================
sigma_1..8     (u_i)  0       standard deviation of the white noise; presets below
                              (distribution_i = 1: half-width of ln y_i / bias_i, 1)
distribution_1..8 --  0       0 Gaussian white noise, 1 log-uniform scatter of bias_i, 2 uniform (Integer)
gain_1..8      1      1       scale factor of the sensor (calibration error)
bias_1..8      (u_i)  0       offset of the sensor
seed           1      1       seed of the noise (Integer)
sample_period  s      1e-3    sensor sample period: 1 kHz (Muñoz et al. runs), 0.01 s (Onat et al. 2016)
enabled        --     true    false: y = u exactly (noise-free reference run)
============== ====== ======= =========================================================

Presets (:data:`MUNOZ_SENSORS`, :data:`ONAT2016_SENSORS`) assign the channels of the two
studies and give their sigmas.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import sympy as sp

from railfmu.models.base import STEP_TOLERANCE, Input, Model, Output, Parameter

N_CHANNELS = 8
GAMMA = 0x9E3779B97F4A7C15  # SplitMix64 increment (golden ratio), as railfmu.models.track.irregularity.SplitMix64
_MASK64 = (1 << 64) - 1


# ---- the noise -------------------------------------------------------------------------------

def _mix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64's output function on uint64 arrays (wrapping arithmetic)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def channel_state(seed: int, channel: int) -> int:
    """c_i = mix64(seed + i G): the ``channel``-th output of SplitMix64(seed), as a Python int."""
    if not 1 <= channel <= N_CHANNELS:
        raise ValueError(f"channel must be 1..{N_CHANNELS}, not {channel}")
    with np.errstate(over="ignore"):
        z = np.array([(int(seed) + channel * GAMMA) & _MASK64], dtype=np.uint64)
        return int(_mix64(z)[0])


def uniforms(seed: int, channel: int, k) -> tuple[np.ndarray, np.ndarray]:
    """(u1 in (0, 1], u2 in [0, 1)) of samples ``k`` (non-negative integers) of ``channel``."""
    k = np.asarray(k)
    if k.size and (k.min() < 0 or not np.issubdtype(k.dtype, np.integer)):
        raise ValueError("sample indices k must be non-negative integers")
    k = k.astype(np.uint64)
    c = np.uint64(channel_state(seed, channel))
    two, one, g = np.uint64(2), np.uint64(1), np.uint64(GAMMA)
    with np.errstate(over="ignore"):
        n = two * k + one
        z1 = _mix64(c + n * g)
        z2 = _mix64(c + (n + one) * g)
    u1 = ((z1 >> np.uint64(11)) + one).astype(np.float64) * 2.0**-53
    u2 = (z2 >> np.uint64(11)).astype(np.float64) * 2.0**-53
    return u1, u2


def _libm(fn, x: np.ndarray) -> np.ndarray:
    """``fn`` (a ``math`` function, i.e. the C library's) elementwise."""
    return np.fromiter((fn(v) for v in x.ravel().tolist()), dtype=np.float64, count=x.size).reshape(x.shape)


def noise(seed: int, channel: int, k, exact: bool = True) -> np.ndarray:
    """Standard Gaussian w_i(k) of ``channel`` (1..8) at samples ``k`` (array of non-negative
    integers), bit-identical to the FMU. ``exact=False`` uses numpy's log/cos (much
    faster; may differ from the FMU in the last bit)."""
    u1, u2 = uniforms(seed, channel, k)
    if exact:
        lg, cs = _libm(math.log, u1), _libm(math.cos, 2.0 * math.pi * u2)
    else:
        lg, cs = np.log(u1), np.cos(2.0 * math.pi * u2)
    return np.sqrt(-2.0 * lg) * cs


def log_uniform_factor(seed: int, channel: int, k, sigma: float) -> np.ndarray:
    """exp(sigma (2 u2 - 1)) of ``channel`` at samples ``k``: the factor on bias_i of
    ``distribution_i = 1``, bit-identical to the FMU (libm's exp)."""
    u2 = uniforms(seed, channel, k)[1]
    return _libm(math.exp, sigma * (2.0 * u2 - 1.0))


def sample_index(t, t0: float, sample_period: float, h) -> np.ndarray:
    """k = floor((t - t0) / T + eps min(h / T, 1)), clipped at 0: the FMU's sample at
    communication points ``t`` (s) reached by steps ``h`` (s; scalar or one per point, 0 in
    initialisation mode); the same arithmetic as the C."""
    t = np.asarray(t, dtype=float)
    T = float(sample_period)
    k = np.floor((t - t0) / T + STEP_TOLERANCE * np.minimum(np.asarray(h, dtype=float) / T, 1.0))
    return np.maximum(k, 0.0).astype(np.int64)


class SensorNoise:
    """Python twin of the ``SensorNoise`` FMU. ``params`` override :data:`SENSORS`' defaults."""

    def __init__(self, params: Mapping[str, float] | None = None):
        self.params = {**SENSORS.default_parameters(), **(params or {})}
        unknown = set(self.params) - {p.name for p in SENSORS.parameters}
        if unknown:
            raise KeyError(f"unknown SensorNoise parameters {sorted(unknown)}")
        SENSORS.check_parameters(self.params)

    def outputs(self, t, h, u: Mapping[str, np.ndarray] | None = None, t0: float = 0.0,
                exact: bool = True) -> dict[str, np.ndarray]:
        """y_1..y_8 at communication points ``t`` (s) reached by steps ``h`` (s, scalar or one
        per point, as :func:`sample_index`) for inputs ``u`` ({'u_i': values at t}, missing
        = 0), the run starting at ``t0``."""
        p = self.params
        t = np.asarray(t, dtype=float)
        u = u or {}
        k = sample_index(t, t0, p["sample_period"], h)
        out = {}
        for i in range(1, N_CHANNELS + 1):
            ui = np.broadcast_to(np.asarray(u.get(f"u_{i}", 0.0), dtype=float), t.shape)
            if not p["enabled"]:
                out[f"y_{i}"] = ui.copy()
                continue
            sigma = p[f"sigma_{i}"]
            if p[f"distribution_{i}"] == 1:
                f = log_uniform_factor(p["seed"], i, k, sigma) if sigma != 0 else np.ones(t.shape)
                out[f"y_{i}"] = p[f"gain_{i}"] * ui + p[f"bias_{i}"] * f
                continue
            if p[f"distribution_{i}"] == 2:
                d = sigma * (2.0 * uniforms(p["seed"], i, k)[1] - 1.0) if sigma != 0 else np.zeros(t.shape)
                out[f"y_{i}"] = p[f"gain_{i}"] * ui + p[f"bias_{i}"] + d
                continue
            w = noise(p["seed"], i, k, exact) if sigma != 0 else np.zeros(t.shape)
            out[f"y_{i}"] = p[f"gain_{i}"] * ui + p[f"bias_{i}"] + sigma * w
        return out


# ---- the model definition --------------------------------------------------------------------

_SIGMA_SRC = "experiment (.ssv); Muñoz et al., §5: 0.01 m/s2 accelerometers, 0.0005 rad/s gyro"


def _parameters() -> list[Parameter]:
    ch = range(1, N_CHANNELS + 1)
    return [
        *[Parameter(f"sigma_{i}", f"standard deviation of the white noise on channel {i}, in the "
                    f"unit of u_{i} (>= 0)", "", 0.0, min=0.0, source=_SIGMA_SRC)
          for i in ch],
        *[Parameter(f"gain_{i}", f"scale factor of channel {i} (1 = ideal sensor)", "", 1.0,
                    source="choice: ideal sensor") for i in ch],
        *[Parameter(f"bias_{i}", f"offset of channel {i}, in the unit of u_{i}", "", 0.0,
                    source="choice: ideal sensor") for i in ch],
        *[Parameter(f"distribution_{i}", f"channel {i}: 0 Gaussian white noise sigma_{i} w, 1 log-uniform "
                    f"scatter bias_{i} exp(sigma_{i} (2 u - 1)), 2 uniform bias_{i} + sigma_{i} (2 u - 1)",
                    "", 0, type="Integer", min=0, max=2,
                    source="choice: 0 a sensor; 1, 2 an unknown parameter drawn per run") for i in ch],
        Parameter("seed", "seed of the counter-based noise (same seed, same noise in any importer)",
                  "", 1, type="Integer", source="choice"),
        Parameter("sample_period", "sensor sample period: the noise is held for this long (> 0)", "s",
                  1e-3, positive=True,
                  source="1 kHz for Muñoz et al. runs (our 20 s experiment at 1e-3 s); Onat et al. (2016), "
                         "§3 uses 0.01 s"),
        Parameter("enabled", "add the sensor model; false: y_i = u_i exactly", "", True, type="Boolean",
                  source="choice; Muñoz et al., §5.4, Table 3: the 'without sensor noise' case"),
    ]


def _io() -> tuple[list[Input], list[Output]]:
    inputs, outputs = [], []
    for i in range(1, N_CHANNELS + 1):
        u = Input(f"u_{i}", f"true signal of channel {i} (any unit)", "", 0.0)
        g, b, s = (sp.Symbol(f"{n}_{i}", real=True) for n in ("gain", "bias", "sigma"))
        # the expression declares the structure (y_i depends on u_i only, codegen's
        # ModelStructure); the values come from the hand-written C, w_i is the noise
        w = sp.Symbol(f"w_{i}", real=True)
        inputs.append(u)
        outputs.append(Output(f"y_{i}", f"measured channel {i}: gain_{i} u_{i} + bias_{i} + "
                              f"sigma_{i} w_{i}(k) (u_{i} when enabled is false)", "",
                              expr=g * u.symbol + b + s * w))
    return inputs, outputs


_INPUTS, _OUTPUTS = _io()

SENSORS = Model(
    identifier="SensorNoise",
    description="Eight sensor channels: y = gain u + bias + sigma w with counter-based Gaussian "
                "white noise w (SplitMix64 + Box-Muller) held over a sample period",
    parameters=_parameters(),
    inputs=_INPUTS,
    outputs=_OUTPUTS,
    c_sources=["SensorNoise.c"],
    documentation=__doc__,
)


# ---- presets -----------------------------------------------------------------------------------

#: Muñoz et al. (lateral alignment, §5 "sensor noise"): an axle-box accelerometer and yaw-rate
#: gyro on the leading wheelset and an accelerometer on the bogie frame. The paper calls the
#: values "variance" but gives them in m/s2 and rad/s, i.e. as standard deviations ("10 % of
#: the maximum absolute value of the signals"). Channels 4..8 stay noise-free (sigma 0).
#: 1 kHz: our runs of this study sample at 1e-3 s (the paper does not state its rate).
MUNOZ_SENSORS: dict[str, float | int | bool] = {
    "sample_period": 1e-3,
    "sigma_1": 0.01,    # m/s2, u_1 <- WheelsetLateral.ddy   (axle-box lateral accelerometer)
    "sigma_2": 0.0005,  # rad/s, u_2 <- WheelsetLateral.dpsi (axle-box yaw-rate gyro)
    "sigma_3": 0.01,    # m/s2, u_3 <- WheelsetLateral.ddy_f (bogie-frame lateral accelerometer)
}

#: Onat et al. (2016) (secondary vertical spring, §3, eq. 6): seven inertial signals, in the
#: paper's order (CoachVertical outputs/states), sampled at the paper's 10 ms discretisation
#: step. The paper gives no sensor specification (only its filter's R = I, a tuning choice, not
#: a sensor); we take the sensor class of Muñoz et al.: 0.01 m/s2 for the accelerometers and
#: 0.0005 rad/s for the gyros. Channel 8 is unused.
ONAT2016_SENSORS: dict[str, float | int | bool] = {
    "sample_period": 0.01,
    "sigma_1": 0.01,    # m/s2, u_1 <- CoachVertical.ddz_c    (car-body vertical accelerometer)
    "sigma_2": 0.0005,  # rad/s, u_2 <- CoachVertical.dtheta_c (car-body pitch-rate gyro)
    "sigma_3": 0.0005,  # rad/s, u_3 <- CoachVertical.dphi_c   (car-body roll-rate gyro)
    "sigma_4": 0.01,    # m/s2, u_4 <- CoachVertical.ddz_b1   (bogie 1 vertical accelerometer)
    "sigma_5": 0.0005,  # rad/s, u_5 <- CoachVertical.dphi_b1  (bogie 1 roll-rate gyro)
    "sigma_6": 0.01,    # m/s2, u_6 <- CoachVertical.ddz_b2   (bogie 2 vertical accelerometer)
    "sigma_7": 0.0005,  # rad/s, u_7 <- CoachVertical.dphi_b2  (bogie 2 roll-rate gyro)
}
