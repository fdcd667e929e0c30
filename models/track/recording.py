r"""Track recording: the rail heights under a vehicle's bogies as a track recording car's file gives them.

An estimator that takes the track as a known input (Onat et al. (2016), eq. 5) gets it in
service from a track recording car, not from the truth. The ``TrackRecording`` FMU gives the
rail heights of the ERRI B176 random track of :mod:`railfmu.models.track.irregularity` (the
same parameters and ``seed`` give the same track, to its tabulation error of ~1e-9 m) as a
recording of it: sampled every ``sample_spacing`` along the track, each sample with the
recording car's measurement error, the file's positions off by a position offset, and read
back by position with Catmull-Rom cubic Hermite interpolation (as ``suspension_replay`` reads a
recording car's geometry file, ``ProfileTable``). Its C code is hand written
(``fmus/native/models/TrackRecording.c``); ``tests/test_track_recording.py`` proves it equals
this module.

Recording
---------
With ``Delta`` = ``sample_spacing``, the file holds samples at its positions ``x_j = j Delta``
(``j`` any integer) of the true rails at ``x_j + delta``::

    y_j^left  = z_left(x_j + delta)  + sigma w_L(j)
    y_j^right = z_right(x_j + delta) + sigma w_R(j)
    delta     = offset_max (2 u - 1)                       one draw per run (per seed)

``z_left = xi_vp + b theta``, ``z_right = xi_vp - b theta``: the random vertical profile and
cross-level of the TrackIrregularity FMU with the same parameters (its cosine sum, evaluated
exactly: :meth:`railfmu.models.track.irregularity.TrackIrregularity.random_exact`).
``sigma`` = ``noise_sigma``: the recording car's error per sample and rail, white (independent
samples and rails). ``w_L(j) = N(seed, 1001, j)``, ``w_R(j) = N(seed, 1002, j)`` and
``u = U2(seed, 1003, 0)`` are the counter-based normals and uniforms of the SensorNoise FMU
(:mod:`railfmu.models.sources.sensors`, streams 1001-1003 so they share nothing with a
SensorNoise of the same seed; ``j`` as a 64-bit two's complement): the error is a function of
the position, so both bogies meet the same recorded error at the same place, and any importer
and step size give the same recording.

Read back at the wheelset positions ``s_i = s_start + V t - axle_position_i`` (the vehicle's
own positions, which it takes as the file's)::

    u = s_i / Delta,  j = floor(u),  tau = u - j
    m_j = (y_{j+1} - y_{j-1}) / (2 Delta)                  Catmull-Rom slopes
    vertical_*_i      = Hermite(tau; y_j, m_j, y_{j+1}, m_{j+1})
    vertical_*_rate_i = V d/ds Hermite(...)

so the estimator meets the recording's noise on the heights and, through the slope of the
interpolant, on the rates, and the track shifted by ``delta``.

Figures (the defaults)
----------------------
* ``sample_spacing`` 0.25 m: the sampling interval of track recording vehicles (EN 13848-2
  asks for at most 0.5 m; 0.25 m is the common choice).
* ``noise_sigma`` 0.5 mm: EN 13848-2 states the accuracy of a recording vehicle's vertical
  longitudinal level as +-1 mm; taken here as a 2-sigma bound on each sample.
* ``offset_max`` 3 m: the recording's positions against the vehicle's, from odometry and
  location references ("a few metres"); uniform in +-3 m.

``enabled`` = false passes the inputs ``exact_*_i`` (the true rails under the bogies, e.g. the
TrackIrregularity FMU's outputs) through unchanged, as SensorNoise's ``enabled``: the same
system then gives its estimators the exact track (Onat et al. (2016)'s known input) or its
recording by one parameter. Enabled, the inputs are not read.

Outputs: ``position`` (s_1, m), ``vertical_left_i``, ``vertical_right_i`` (m) and their rates
(m/s) for the two bogies i = 1, 2, and ``offset`` (``delta``, m: the truth of the draw, for
scoring; an estimator is not given it).

Python API: :data:`TRACK_RECORDING`, :class:`TrackRecording`.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from railfmu.models.base import Input, Model, Output, Parameter
from railfmu.models.sources.sensors import GAMMA, _libm, _mix64
from railfmu.models.track.irregularity import TRACK, TrackIrregularity, _hermite

#: counter-based streams (SensorNoise's generator): left rail, right rail, the offset's draw
STREAM_LEFT, STREAM_RIGHT, STREAM_OFFSET = 1001, 1002, 1003
N_BOGIES = 2
_MASK64 = (1 << 64) - 1

#: the TrackIrregularity parameters that make its random vertical track (same meaning, same defaults)
_TRACK_PARAMETERS = ("V", "s_start", "psd_level", "psd_scale", "psd_vertical_scale", "lambda_min",
                     "lambda_max", "period_length", "seed", "half_contact_width")


def _uniforms(seed: int, stream: int, k) -> tuple[np.ndarray, np.ndarray]:
    """(u1 in (0, 1], u2 in [0, 1)) of samples ``k`` (integers, any sign: two's complement) of
    ``stream``: rng.h's rng_normal / rng_uniform2."""
    k = np.asarray(k, dtype=np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        c = _mix64(np.array([(int(seed) + stream * GAMMA) & _MASK64], dtype=np.uint64))[0]
        n = np.uint64(2) * k + np.uint64(1)
        z1 = _mix64(c + n * np.uint64(GAMMA))
        z2 = _mix64(c + (n + np.uint64(1)) * np.uint64(GAMMA))
    u1 = ((z1 >> np.uint64(11)) + np.uint64(1)).astype(np.float64) * 2.0**-53
    u2 = (z2 >> np.uint64(11)).astype(np.float64) * 2.0**-53
    return u1, u2


def normals(seed: int, stream: int, k) -> np.ndarray:
    """Standard normals of ``stream`` at samples ``k``, bit-identical to the FMU (libm)."""
    u1, u2 = _uniforms(seed, stream, k)
    return np.sqrt(-2.0 * _libm(math.log, u1)) * _libm(math.cos, 2.0 * math.pi * u2)


def offset_draw(seed: int, offset_max: float) -> float:
    """delta = offset_max (2 u - 1), m: the run's position offset."""
    u2 = _uniforms(seed, STREAM_OFFSET, [0])[1][0]
    return float(offset_max * (2.0 * u2 - 1.0))


class TrackRecording:
    """Python twin of the ``TrackRecording`` FMU (``params`` override the defaults)."""

    def __init__(self, params: Mapping[str, float] | None = None):
        self.params = {**TRACK_RECORDING.default_parameters(), **(params or {})}
        unknown = set(self.params) - {p.name for p in TRACK_RECORDING.parameters}
        if unknown:
            raise KeyError(f"unknown TrackRecording parameters {sorted(unknown)}")
        p = self.params
        for name in ("sample_spacing",):
            if not p[name] > 0:
                raise ValueError(f"parameter {name} = {p[name]:g} must be > 0")
        for name in ("noise_sigma", "offset_max"):
            if not p[name] >= 0:
                raise ValueError(f"parameter {name} = {p[name]:g} must be >= 0")
        self.track = TrackIrregularity({k: p[k] for k in _TRACK_PARAMETERS})
        self.offset = offset_draw(int(p["seed"]), p["offset_max"])

    def samples(self, j) -> tuple[np.ndarray, np.ndarray]:
        """The file's samples y_j (left, right rail; m) at integer indices ``j``."""
        p = self.params
        j = np.asarray(j, dtype=np.int64)
        x = j * p["sample_spacing"] + self.offset
        v = self.track.random_exact(x)[0]
        b = p["half_contact_width"]
        left, right = v[1] + b * v[2], v[1] - b * v[2]
        if p["noise_sigma"] > 0:
            left = left + p["noise_sigma"] * normals(int(p["seed"]), STREAM_LEFT, j)
            right = right + p["noise_sigma"] * normals(int(p["seed"]), STREAM_RIGHT, j)
        return left, right

    def read(self, s) -> dict[str, np.ndarray]:
        """The recording read back at file positions ``s`` (m): ``vertical_left``,
        ``vertical_right`` (m) and their slopes ``*_ds`` (m/m)."""
        d = self.params["sample_spacing"]
        s = np.asarray(s, dtype=float)
        u = s / d
        j = np.floor(u)
        tau = u - j
        j = j.astype(np.int64)
        out = {}
        y = [self.samples(j + k) for k in (-1, 0, 1, 2)]
        for c, name in enumerate(("vertical_left", "vertical_right")):
            ym, y0, y1, y2 = (yy[c] for yy in y)
            m0 = (y1 - ym) / (2.0 * d)
            m1 = (y2 - y0) / (2.0 * d)
            out[name], out[name + "_ds"] = _hermite(tau, d, y0, m0, y1, m1)
        return out

    def outputs(self, t, exact: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """The FMU's outputs (by name) at communication points ``t`` (s); ``exact``: the
        ``exact_*`` inputs at ``t`` (passed through when ``enabled`` is false)."""
        p = self.params
        t = np.asarray(t, dtype=float)
        front = p["s_start"] + p["V"] * t
        out = {"position": front - p["axle_position_1"], "offset": np.full(t.shape, self.offset)}
        if not p["enabled"]:
            for i in range(1, N_BOGIES + 1):
                for side in ("left", "right"):
                    out[f"vertical_{side}_{i}"] = np.asarray((exact or {}).get(f"exact_{side}_{i}", 0.0) + 0 * t)
                    out[f"vertical_{side}_rate_{i}"] = np.asarray((exact or {}).get(f"exact_{side}_rate_{i}", 0.0) + 0 * t)
            return out
        for i in range(1, N_BOGIES + 1):
            r = self.read(front - p[f"axle_position_{i}"])
            for name in ("vertical_left", "vertical_right"):
                out[f"{name}_{i}"] = r[name]
                out[f"{name}_rate_{i}"] = p["V"] * r[name + "_ds"]
        return out


def _parameters() -> list[Parameter]:
    track = {p.name: p for p in TRACK.parameters}
    out = [track[n] for n in _TRACK_PARAMETERS]
    out.insert(2, Parameter("axle_position_1", "distance of bogie 1 behind the position s_1 along the track",
                            unit="m", start=0.0, source="choice: bogie 1 leads"))
    out.insert(3, Parameter("axle_position_2", "distance of bogie 2 behind the position s_1 along the track",
                            unit="m", start=19.0,
                            source="ERRI B176 coach: bogie pivot spacing 2 a1 = 19 m (Onat et al. (2016), Table 1)"))
    out += [
        Parameter("sample_spacing", "distance between the recording's samples (> 0)", unit="m", start=0.25,
                  positive=True, source="EN 13848-2: sampling interval of a track recording vehicle at most "
                  "0.5 m; 0.25 m the common choice"),
        Parameter("noise_sigma", "standard deviation of the recording's error per sample and rail", unit="m",
                  start=5e-4, min=0.0, source="EN 13848-2: vertical longitudinal level accurate to +-1 mm, "
                  "taken as 2 sigma"),
        Parameter("offset_max", "the recording's position offset delta is uniform in +-offset_max, one "
                  "draw per seed", unit="m", start=3.0, min=0.0,
                  source="choice: the recording's positions against the vehicle's, 'a few metres'"),
        Parameter("enabled", "true: the recording; false: the exact_* inputs passed through", unit="",
                  start=True, type="Boolean", source="choice (as SensorNoise's enabled)"),
    ]
    return out


def _inputs() -> list[Input]:
    out = []
    for i in range(1, N_BOGIES + 1):
        for side in ("left", "right"):
            out += [Input(f"exact_{side}_{i}", f"true height of the {side} rail under bogie {i} (read when "
                          "enabled is false)", unit="m", start=0.0),
                    Input(f"exact_{side}_rate_{i}", f"time derivative of exact_{side}_{i} (read when enabled "
                          "is false)", unit="m/s", start=0.0)]
    return out


def _outputs() -> list[Output]:
    out = [Output("position", "track position s_1 = s_start + V t", unit="m", depends_on=()),
           Output("offset", "the recording's position offset delta: the file at x holds the rails at "
                  "x + delta (the draw's truth, for scoring)", unit="m", depends_on=())]
    for i in range(1, N_BOGIES + 1):
        out += [
            Output(f"vertical_left_{i}", f"recorded height of the left rail under bogie {i}", unit="m",
                   depends_on=(f"exact_left_{i}",)),
            Output(f"vertical_right_{i}", f"recorded height of the right rail under bogie {i}", unit="m",
                   depends_on=(f"exact_right_{i}",)),
            Output(f"vertical_left_rate_{i}", f"time derivative of vertical_left_{i} (V d/ds)", unit="m/s",
                   depends_on=(f"exact_left_rate_{i}",)),
            Output(f"vertical_right_rate_{i}", f"time derivative of vertical_right_{i} (V d/ds)", unit="m/s",
                   depends_on=(f"exact_right_rate_{i}",)),
        ]
    return out


TRACK_RECORDING = Model(
    identifier="TrackRecording",
    description="Rail heights under two bogies as a track recording car's file gives them: the ERRI B176 "
                "random track sampled every 0.25 m with a measurement error, a position offset, read back "
                "by Catmull-Rom interpolation",
    parameters=_parameters(),
    inputs=_inputs(),
    outputs=_outputs(),
    c_sources=["TrackRecording.c"],
    default_experiment=(0.0, 150.0, 0.01),
    documentation=__doc__,
)
