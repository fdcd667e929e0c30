r"""Track irregularity source: ERRI B176 random track + harmonic + step + measured profile.

The ``TrackIrregularity`` FMU feeds the vehicle models with the rail deviations under each
of the four wheelsets of a coach on straight track, running at a constant speed ``V`` or, for
stop-and-go and accelerating runs, at the travelled distance and speed given as inputs (see
Position and speed). It has no states; its C code is hand written
(``fmus/native/models/TrackIrregularity.c``) and ``tests/test_track.py`` and
``tests/test_track_position.py`` prove it equals this module.

Irregularity variables
----------------------
As in Muñoz et al. (eq. 1), with ``u_y``/``u_z`` the lateral/vertical deviation of the left
(``lr``) and right (``rr``) rail from its ideal position::

    alignment   xi_a  = (u_y^lr + u_y^rr) / 2        gauge  xi_g  = u_y^lr - u_y^rr = 0
    profile     xi_vp = (u_z^lr + u_z^rr) / 2        cross-level  xi_cl = u_z^lr - u_z^rr

Gauge variation is zero (Muñoz et al., §5.1: "gauge is assumed to be constant"), so the
alignment is the lateral deviation of both rails. The cross-level channel is generated as
an angle ``theta`` (rad), and the rails are ::

    z_left  = xi_vp + b theta        z_right = xi_vp - b theta      (xi_cl = 2 b theta)

with ``b`` = ``half_contact_width``, half the distance between the contact points.

ERRI B176 spectra
-----------------
ERRI B176 ("German" high-speed track spectra; ORE B176 RP1, as quoted by Claus & Schiehlen,
VSD 29 suppl. (1998) 538-552, which is ref. [18] of Muñoz et al., the method that paper uses
to generate its irregularities) give one-sided PSDs in the spatial angular frequency
``Omega`` (rad/m)::

    S_a(Omega) = A_a Oc^2 / ((Omega^2 + Or^2)(Omega^2 + Oc^2))                 m^2/(rad/m)
    S_v(Omega) = A_v Oc^2 / ((Omega^2 + Or^2)(Omega^2 + Oc^2))                 m^2/(rad/m)
    S_c(Omega) = (A_v / b^2) Oc^2 Omega^2
                 / ((Omega^2 + Or^2)(Omega^2 + Oc^2)(Omega^2 + Os^2))         rad^2/(rad/m)

    Oc = 0.8246 rad/m, Or = 0.0206 rad/m, Os = 0.438 rad/m
    low level  (psd_level 1): A_a = 2.119e-7 m rad, A_v = 4.032e-7 m rad
    high level (psd_level 2): A_a = 6.125e-7 m rad, A_v = 1.080e-6 m rad

**One-sided convention**: the variance is the integral over positive frequencies only,
``var(xi) = int_0^inf S(Omega) dOmega``. The ``b`` in ``S_c`` is the same parameter
``half_contact_width`` as in the rail heights, so the spectrum of ``xi_cl = 2 b theta`` does
not depend on it.

Random-phase superposition on an FFT grid
-----------------------------------------
With ``L`` = ``period_length`` and ``dOmega = 2 pi / L``, the spectral lines are
``Omega_k = k dOmega`` for ``k = ceil(L/lambda_max) .. floor(L/lambda_min)``; each channel is ::

    xi(s) = sum_k a_k cos(Omega_k s + phi_k),   a_k = psd_scale sqrt(2 S(Omega_k) dOmega)

so the profile is periodic with period ``L`` and its mean square over one period is exactly
``sum_k a_k^2 / 2 = psd_scale^2 sum_k S(Omega_k) dOmega`` (the Riemann sum of the one-sided
integral over ``lambda_min .. lambda_max``). ``psd_scale`` multiplies the amplitudes (the
PSD scales with its square); ``psd_level = 0`` switches the random part off.

The phases ``phi = 2 pi u`` come from one SplitMix64 stream (Steele, Lea & Flood, OOPSLA
2014; the same integer arithmetic in Python and C, so both give bit-identical phases)
seeded with ``seed`` taken as an unsigned 64-bit integer (two's complement for negative
seeds)::

    state += 0x9E3779B97F4A7C15;  z = state;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9;  z = (z ^ (z >> 27)) * 0x94D049BB133111EB;
    z ^= z >> 31;  u = (z >> 11) * 2^-53

first all alignment phases (k ascending), then all vertical-profile phases, then all
cross-level phases.

Because every line lies on the FFT grid, an inverse real FFT of size ``M`` gives the
profile and its slope exactly at ``s_n = n L / M`` (for ``M > 2 k_max``). The FMU
tabulates values and slopes this way at ``model_initialize`` (``M`` = the smallest power
of two with ``L/M <= grid_step`` and ``M > 2 floor(L/lambda_min)``, at most 2^22) and
evaluates a periodic cubic Hermite interpolant; with the defaults ``h = L/M = 0.038 m``
and the interpolation error is below ``h^4/384 sum_k a_k Omega_k^4`` (1.9e-8 m at the low
level, 3e-8 m at the high level; about 1e-9 m measured,
see :func:`tabulation_error_bound`). :meth:`TrackIrregularity.random_exact` evaluates the
cosine sum itself; :meth:`TrackIrregularity.random_tabulated` mirrors the FMU.

Deterministic components (all components add up)
------------------------------------------------
* harmonic: ``A sin(2 pi s / lambda_h + phase)`` with ``A`` = ``harmonic_lateral_amplitude``
  on the alignment and ``harmonic_vertical_amplitude`` on both rails (Muñoz et al.,
  §5.5 case 2: 1 mm lateral at 15.66 m);
* step: ``step_lateral`` on the alignment and ``step_vertical`` on both rails for
  ``s >= step_position``; its derivative is taken as 0 everywhere (the Dirac impulse at the
  step is ignored);
* measured profile: a CSV file ``profile_file`` with the header line
  ``s,alignment,vertical_left,vertical_right`` (metres, ``s`` strictly increasing, at least
  two rows), or a recording car's rail heights ``position_m,vertical_left_m,vertical_right_m``
  (the alignment 0) times ``profile_scale``, interpolated by cubic Hermite splines with Catmull-Rom
  slopes (central differences ``(y[i+1] - y[i-1]) / (s[i+1] - s[i-1])``, one-sided at both
  ends); outside ``[s[0], s[-1]]`` it contributes 0. In the FMU a relative path is resolved
  against the FMU's ``resources/`` folder.

Position and speed
------------------
``distance_input`` selects where the leading wheelset is and how fast it goes::

    distance_input = false (default):   s_1(t) = s_start + V t              v = V
    distance_input = true:              s_1(t) = s_start + distance(t)      v = speed(t)

with the inputs ``distance`` (m, travelled by the vehicle since the start; it may stop and
go, or run backwards) and ``speed`` (m/s, d distance/dt), e.g. from a longitudinal train or
trolley model. At constant speed the inputs are not read, and the outputs are bit-identical
to what they were before the inputs existed; fed with ``distance = V t`` and ``speed = V``
the position mode gives the same numbers. Why a parameter and not inputs that default to
``s = V t``: an FMI input starts at a constant, which cannot be ``V t``; the parameter makes
the mode explicit in the experiment's ``.ssv``. The outputs at a communication point are
those of the inputs set there; read after a step before new inputs are set, the distance is
extrapolated with the speed, ``distance + speed (t - t_set)`` (first-order hold, as the
wheelset's ``xi`` with ``xi_rate``).

Wheelsets and outputs
---------------------
Wheelset ``i`` is at ``s_i = s_1 - axle_position_i``; the outputs are the values at ``s_i``
and the rates ``d/dt = v d/ds`` (chain rule)::

    position            = s_1                                      m
    alignment_i         = xi_a(s_i)                                m
    vertical_left_i     = xi_vp(s_i) + b theta(s_i)                m
    vertical_right_i    = xi_vp(s_i) - b theta(s_i)                m
    *_rate_i            = v d/ds (...)(s_i)                        m/s

With ``v = 0`` the outputs hold and the rates are zero. The step counts as reached at a
communication point when ``s_i >= step_position - eps |v| h``, with ``h`` the communication
step that ended there (0 in initialisation mode) and ``eps = railfmu.models.base.STEP_TOLERANCE``
= 0.01: a step on the master's grid (``step_position = s_start + V n h``) then switches at
that grid point however the master computes its time (``n h``, or ``t += h``, which drifts
by up to 1.8e-3 h after 1e7 steps), and one between grid points keeps its place.

Run-in
------
With ``L_r`` = ``run_in_length`` > 0, the total deviation of every channel (the sum of the
random, harmonic, step and measured-profile parts; alignment and both rails, at every
wheelset) is multiplied by the raised-cosine weight of that wheelset's position ``s`` ::

    w(s) = 0                             s <= 0
           (1 - cos(pi s / L_r)) / 2     0 < s < L_r
           1                             s >= L_r

and the rates follow the product rule, ``d(w x)/ds = w dx/ds + x dw/ds`` with
``dw/ds = pi / (2 L_r) sin(pi s / L_r)`` on ``0 < s < L_r`` and 0 elsewhere (times ``v`` for
the time rates). Why: a vehicle model and an estimator that both start from rest on ideal
track are in equilibrium at t = 0; the run-in takes them onto the irregular track smoothly,
as multibody track simulations do, instead of starting the vehicle centred while the rails
are already millimetres off. ``run_in_length = 0`` (the default) switches it off: the weight
is not evaluated and the outputs are unchanged, also at ``s < 0``. See :func:`run_in_weight`.

Parameters
----------
=========================== ======== ========= ==========================================
name                        unit     default   source
=========================== ======== ========= ==========================================
V                           m/s      20        Muñoz et al., §5 (V = 20 m/s)
s_start                     m        0         track position of the leading wheelset, t=0
axle_position_1..4          m        0, 2.5,   ERRI B176 coach: bogie pivots 2 a1 = 19 m
                                     19, 21.5  (Onat et al. (2016), Table 1), bogie wheelbase 2.5 m
psd_level                   (int)    1         0 none, 1 ERRI B176 low, 2 high
psd_scale                   ""       1         amplitude factor
psd_lateral_scale           ""       1         extra factor on the random alignment
psd_vertical_scale          ""       1         extra factor on the random vertical/cross-level
lambda_min, lambda_max      m        1, 300    wavelength band of the random lines
period_length               m        5000      L: the random profile repeats after it
grid_step                   m        0.05      upper bound of the FMU's tabulation step
seed                        (int)    1         SplitMix64 seed
half_contact_width          m        0.75      b, Muñoz et al., Table 1 (l, wheelset half width)
harmonic_lateral_amplitude  m        0         Muñoz et al., §5.5 uses 1e-3
harmonic_vertical_amplitude m        0
harmonic_wavelength         m        20        Muñoz et al., §5.5 uses 15.66
harmonic_phase              rad      0
step_lateral, step_vertical m        0
step_position               m        100
profile_file                (string) ""        CSV table, none when empty
profile_scale               ""       1         factor on the table
run_in_length               m        0         raised-cosine ramp from s = 0 (see Run-in);
                                               0: none
distance_input              (bool)   false     true: position and speed from the inputs
=========================== ======== ========= ==========================================

Inputs (read only when ``distance_input`` is true)
--------------------------------------------------
=========================== ======== ========= ==========================================
name                        unit     start     meaning
=========================== ======== ========= ==========================================
distance                    m        0         distance travelled since the start
speed                       m/s      0         speed along the track, d distance / dt
=========================== ======== ========= ==========================================

Python API: :data:`TRACK` (the model definition), :func:`psd_alignment`,
:func:`psd_vertical`, :func:`psd_crosslevel`, :class:`SplitMix64`, :func:`spectral_lines`,
:func:`grid_size`, :class:`ProfileTable`, :class:`TrackIrregularity`,
:func:`check_track_parameters`, :func:`tabulation_error_bound`, :func:`run_in_weight`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from railfmu.models.base import STEP_TOLERANCE, Input, Model, Output, Parameter
from railfmu.models.track.erri_b176 import ERRI_B176_LEVELS, OMEGA_C, OMEGA_R, OMEGA_S

# ---- ERRI B176 spectra ---------------------------------------------------------------------

CHANNELS = ("alignment", "vertical_profile", "crosslevel")  # crosslevel: the angle theta
MAX_GRID_POINTS = 1 << 22  # the FMU's tabulation limit (memory: 48 bytes per point)


def _levels(level: int) -> tuple[float, float]:
    if level == 0:
        return 0.0, 0.0
    try:
        return ERRI_B176_LEVELS[int(level)]
    except KeyError:
        raise ValueError(f"psd_level must be 0, 1 or 2, not {level!r}") from None


def psd_alignment(omega, level: int = 1):
    """One-sided PSD of the lateral alignment, m^2/(rad/m), at ``omega`` (rad/m)."""
    o2 = np.square(np.asarray(omega, dtype=float))
    A_a = _levels(level)[0]
    return A_a * OMEGA_C**2 / ((o2 + OMEGA_R**2) * (o2 + OMEGA_C**2))


def psd_vertical(omega, level: int = 1):
    """One-sided PSD of the vertical profile, m^2/(rad/m), at ``omega`` (rad/m)."""
    o2 = np.square(np.asarray(omega, dtype=float))
    A_v = _levels(level)[1]
    return A_v * OMEGA_C**2 / ((o2 + OMEGA_R**2) * (o2 + OMEGA_C**2))


def psd_crosslevel(omega, level: int = 1, b: float = 0.75):
    """One-sided PSD of the cross-level angle, rad^2/(rad/m); ``b`` = half contact distance (m)."""
    o2 = np.square(np.asarray(omega, dtype=float))
    A_v = _levels(level)[1]
    return (A_v / b**2) * OMEGA_C**2 * o2 / ((o2 + OMEGA_R**2) * (o2 + OMEGA_C**2) * (o2 + OMEGA_S**2))


# ---- portable random numbers ---------------------------------------------------------------

_MASK64 = (1 << 64) - 1


class SplitMix64:
    """SplitMix64 (Steele, Lea & Flood 2014); the FMU's C implementation is identical."""

    def __init__(self, seed: int):
        self.state = int(seed) & _MASK64

    def next(self) -> int:
        """The next 64-bit output as a Python int."""
        self.state = (self.state + 0x9E3779B97F4A7C15) & _MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
        return z ^ (z >> 31)

    def uniform(self) -> float:
        """Uniform in [0, 1) with 53 random bits."""
        return (self.next() >> 11) * 2.0**-53

    def uniforms(self, n: int) -> np.ndarray:
        """``n`` uniforms; vectorised with numpy's wrapping uint64 arithmetic."""
        if n <= 0:
            return np.zeros(0)
        with np.errstate(over="ignore"):
            steps = np.arange(1, n + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
            z = np.uint64(self.state) + steps
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            z ^= z >> np.uint64(31)
        self.state = (self.state + n * 0x9E3779B97F4A7C15) & _MASK64
        return (z >> np.uint64(11)).astype(np.float64) * 2.0**-53


# ---- parameters ----------------------------------------------------------------------------

def check_track_parameters(p: Mapping[str, float]) -> None:
    """The FMU's ``model_check_parameters``: raises ValueError naming the parameter."""
    def need(ok: bool, name: str, rule: str) -> None:
        if not ok:
            raise ValueError(f"parameter {name} = {float(p[name]):g} must be {rule}")

    for name, value in p.items():
        if isinstance(value, float) and not math.isfinite(value):
            need(False, name, "finite")
    need(p["V"] >= 0, "V", ">= 0")
    need(p["psd_level"] in (0, 1, 2), "psd_level", "0, 1 or 2")
    need(p["psd_scale"] >= 0, "psd_scale", ">= 0")
    need(p["psd_lateral_scale"] >= 0, "psd_lateral_scale", ">= 0")
    need(p["psd_vertical_scale"] >= 0, "psd_vertical_scale", ">= 0")
    need(p["lambda_min"] > 0, "lambda_min", "> 0")
    need(p["lambda_max"] > p["lambda_min"], "lambda_max", f"> lambda_min = {float(p['lambda_min']):g}")
    need(p["period_length"] > 0, "period_length", "> 0")
    need(p["grid_step"] > 0, "grid_step", "> 0")
    need(p["half_contact_width"] > 0, "half_contact_width", "> 0")
    need(p["harmonic_wavelength"] > 0, "harmonic_wavelength", "> 0")
    need(p["run_in_length"] >= 0, "run_in_length", ">= 0")
    if p["psd_level"] != 0 and grid_size(p) > MAX_GRID_POINTS:
        raise ValueError(f"parameter grid_step = {float(p['grid_step']):g} with period_length = "
                         f"{float(p['period_length']):g} and lambda_min = {float(p['lambda_min']):g} "
                         f"needs more than {MAX_GRID_POINTS} grid points")


def _line_range(p: Mapping[str, float]) -> tuple[int, int]:
    L = float(p["period_length"])
    return max(math.ceil(L / p["lambda_max"]), 1), math.floor(L / p["lambda_min"])  # no k = 0


def grid_size(p: Mapping[str, float]) -> int:
    """The FMU's tabulation size M: the smallest power of two with ``L/M <= grid_step`` and
    ``M > 2 k_max`` (every line below the grid's Nyquist frequency)."""
    L = float(p["period_length"])
    k_max = _line_range(p)[1]
    M = 1
    while L / M > p["grid_step"] or M <= 2 * k_max:
        M *= 2
    return M


@dataclass
class SpectralLines:
    """The random part: ``xi_c(s) = sum_k amplitude[c, k] cos(omega[k] s + phase[c, k])`` for
    the channels c = alignment (m), vertical profile (m), cross-level angle (rad)."""

    k: np.ndarray  # line numbers, Omega_k = k 2 pi / L
    omega: np.ndarray  # rad/m
    amplitude: np.ndarray  # (3, n)
    phase: np.ndarray  # (3, n), rad


def spectral_lines(p: Mapping[str, float]) -> SpectralLines:
    """Lines, amplitudes and SplitMix64 phases of the random part for parameters ``p``."""
    L = float(p["period_length"])
    k_lo, k_hi = _line_range(p)
    k = np.arange(k_lo, k_hi + 1) if (p["psd_level"] != 0 and k_hi >= k_lo) else np.zeros(0, int)
    d_omega = 2.0 * math.pi / L
    omega = k * d_omega
    level = int(p["psd_level"])
    if level == 0:
        S = np.zeros((3, k.size))
    else:
        S = np.array([psd_alignment(omega, level), psd_vertical(omega, level),
                      psd_crosslevel(omega, level, p["half_contact_width"])])
    channel = np.array([p["psd_lateral_scale"], p["psd_vertical_scale"], p["psd_vertical_scale"]])
    amplitude = p["psd_scale"] * channel[:, None] * np.sqrt(2.0 * S * d_omega)
    phase = 2.0 * math.pi * SplitMix64(p["seed"]).uniforms(3 * k.size).reshape(3, k.size)
    return SpectralLines(k=k, omega=omega, amplitude=amplitude, phase=phase)


def tabulation_error_bound(p: Mapping[str, float]) -> tuple[float, float]:
    """Bounds on the FMU's cubic Hermite tabulation error of the random part:
    (value error in m, slope error in m/m), from ``|f - p| <= h^4/384 max|f''''|`` and
    ``|f' - p'| <= sqrt(3)/216 h^3 max|f''''|`` (Birkhoff & Priver 1967) with
    ``max|f''''| <= sum_k a_k Omega_k^4`` for the alignment and for each rail
    (``|a_vp| + b |a_theta|``)."""
    lines = spectral_lines(p)
    h = float(p["period_length"]) / grid_size(p)
    o4 = lines.omega**4
    b = p["half_contact_width"]
    d4 = max(np.sum(lines.amplitude[0] * o4),
             np.sum((lines.amplitude[1] + b * lines.amplitude[2]) * o4), 0.0)
    return h**4 / 384.0 * d4, math.sqrt(3.0) / 216.0 * h**3 * d4


# ---- cubic Hermite (the same arithmetic as the C) ------------------------------------------

def _hermite(t, h, y0, m0, y1, m1):
    """Cubic Hermite on an interval of length h at t in [0, 1]: value and d/ds."""
    t2 = t * t
    t3 = t2 * t
    h00 = 2.0 * t3 - 3.0 * t2 + 1.0
    h10 = t3 - 2.0 * t2 + t
    h01 = -2.0 * t3 + 3.0 * t2
    h11 = t3 - t2
    d00 = 6.0 * t2 - 6.0 * t
    d10 = 3.0 * t2 - 4.0 * t + 1.0
    d01 = -6.0 * t2 + 6.0 * t
    d11 = 3.0 * t2 - 2.0 * t
    value = h00 * y0 + h10 * h * m0 + h01 * y1 + h11 * h * m1
    slope = (d00 * y0 + d01 * y1) / h + d10 * m0 + d11 * m1
    return value, slope


# ---- run-in ------------------------------------------------------------------------------

def run_in_weight(s, length: float) -> tuple[np.ndarray, np.ndarray]:
    """The run-in weight and its slope at track positions ``s`` (m) for ``length`` > 0 (m):
    ``w = 0`` at ``s <= 0``, ``(1 - cos(pi s / length)) / 2`` on ``0 < s < length``, 1 beyond;
    ``dw/ds = pi / (2 length) sin(pi s / length)`` inside, 0 elsewhere. The same arithmetic
    as the C's ``run_in_weight``."""
    s = np.asarray(s, dtype=float)
    length = float(length)
    arg = math.pi * np.clip(s, 0.0, length) / length  # clipped: no overflow outside
    inside = (s > 0.0) & (s < length)
    w = np.where(inside, 0.5 * (1.0 - np.cos(arg)), np.where(s >= length, 1.0, 0.0))
    w_d = np.where(inside, (math.pi / (2.0 * length)) * np.sin(arg), 0.0)
    return w, w_d


# ---- measured profile table ----------------------------------------------------------------

PROFILE_HEADER = ("s", "alignment", "vertical_left", "vertical_right")
#: a recording car's rail heights by position (m): the same table with alignment 0
CAR_HEADER = ("position_m", "vertical_left_m", "vertical_right_m")
_NUMBER_CHARS = re.compile(r"^[0-9eE.+-]+$")


def _is_float(f: str) -> bool:
    try:
        float(f)
        return True
    except ValueError:
        return False


class ProfileTable:
    """A measured profile ``s,alignment,vertical_left,vertical_right`` (m), interpolated by
    cubic Hermite splines with Catmull-Rom slopes; 0 outside the table's range."""

    def __init__(self, s, values):
        self.s = np.asarray(s, dtype=float)
        self.values = np.atleast_2d(np.asarray(values, dtype=float))  # (3, n)
        if self.s.ndim != 1 or self.s.size < 2 or self.values.shape != (3, self.s.size):
            raise ValueError("a profile table needs at least two rows of 4 columns")
        if not np.all(np.diff(self.s) > 0):
            raise ValueError("profile table: s must be strictly increasing")
        s, y = self.s, self.values
        m = np.empty_like(y)
        m[:, 1:-1] = (y[:, 2:] - y[:, :-2]) / (s[2:] - s[:-2])
        m[:, 0] = (y[:, 1] - y[:, 0]) / (s[1] - s[0])
        m[:, -1] = (y[:, -1] - y[:, -2]) / (s[-1] - s[-2])
        self.slopes = m

    @classmethod
    def from_csv(cls, path: str | Path) -> "ProfileTable":
        """Read a CSV table; errors (as the FMU's) name the file and line."""
        path = Path(path)
        try:
            data = path.read_bytes()
        except OSError as e:
            raise ValueError(f"profile_file {path}: cannot open ({e.strerror})") from None
        nul = data.find(b"\0")
        if nul >= 0:  # as the C reader: never a table cut short at the NUL
            line, start = data.count(b"\n", 0, nul) + 1, data.rfind(b"\n", 0, nul) + 1
            raise ValueError(f"profile_file {path}:{line}: NUL byte at character {nul - start + 1} "
                             "(a binary or UTF-16 file?)")
        # a BOM (spreadsheet exports) as every table reader; bytes that are not UTF-8 stay in
        # their cells (as U+FFFD), which are then not numbers; lines end at "\n" only, CR trimmed:
        # the C reader's lines
        text = data.decode("utf-8-sig", errors="replace")
        rows = []
        lines = text.split("\n")
        header = tuple(f.strip() for f in lines[0].split(",")) if lines else ()
        if header not in (PROFILE_HEADER, CAR_HEADER):
            raise ValueError(f"profile_file {path}:1: header must be {','.join(PROFILE_HEADER)} or "
                             f"{','.join(CAR_HEADER)}")
        ncol = len(header)
        for no, line in enumerate(lines[1:], start=2):
            if not line.strip():
                continue
            fields = [f.strip() for f in line.split(",")]
            if len(fields) != ncol:
                raise ValueError(f"profile_file {path}:{no}: expected {ncol} comma-separated numbers")
            row = []
            for f in fields:  # the C accepts what strtod reads fully, from these characters
                x = float(f) if _NUMBER_CHARS.match(f) and _is_float(f) else math.nan
                if not math.isfinite(x):
                    raise ValueError(f"profile_file {path}:{no}: not a number: '{f}'")
                row.append(x)
            if rows and not row[0] > rows[-1][0]:
                raise ValueError(f"profile_file {path}:{no}: s = {row[0]:g} is not greater "
                                 f"than the previous s = {rows[-1][0]:g}")
            rows.append(row)
        if len(rows) < 2:
            raise ValueError(f"profile_file {path}: needs at least two data rows")
        a = np.array(rows)
        if ncol == 3:  # no alignment column: 0
            a = np.column_stack([a[:, 0], np.zeros(len(a)), a[:, 1:]])
        return cls(a[:, 0], a[:, 1:].T)

    def __call__(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Values and d/ds, shape (3, *s.shape): alignment, vertical_left, vertical_right."""
        s = np.asarray(s, dtype=float)
        n = self.s.size
        i = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, n - 2)
        inside = (s >= self.s[0]) & (s <= self.s[-1])
        h = self.s[i + 1] - self.s[i]
        t = (s - self.s[i]) / h
        y, m = self.values, self.slopes
        value, slope = _hermite(t, h, y[:, i], m[:, i], y[:, i + 1], m[:, i + 1])
        return np.where(inside, value, 0.0), np.where(inside, slope, 0.0)


# ---- the generator -------------------------------------------------------------------------

class TrackIrregularity:
    """Python twin of the ``TrackIrregularity`` FMU.

    ``params`` override :data:`TRACK`'s defaults; a non-empty ``profile_file`` is read
    relative to ``base_dir`` (the FMU resolves relative paths against its resources/).
    Rail-level quantities come as dicts with keys ``alignment``, ``vertical_left``,
    ``vertical_right`` and their derivatives ``*_ds`` (per metre of track).
    """

    def __init__(self, params: Mapping[str, float] | None = None, base_dir: str | Path | None = None):
        self.params = {**TRACK.default_parameters(), **(params or {})}
        unknown = set(self.params) - {p.name for p in TRACK.parameters}
        if unknown:
            raise KeyError(f"unknown track parameters {sorted(unknown)}")
        check_track_parameters(self.params)
        self.lines = spectral_lines(self.params)
        f = self.params["profile_file"]
        self.profile = None
        if f:
            path = Path(f) if Path(f).is_absolute() else Path(base_dir or ".") / f
            self.profile = ProfileTable.from_csv(path)
        self._grid = None

    @property
    def period_length(self) -> float:
        return float(self.params["period_length"])

    # -- random part --
    def random_exact(self, s, chunk: int = 1 << 21) -> tuple[np.ndarray, np.ndarray]:
        """Cosine sum at arbitrary ``s`` (m): (values, d/ds), each of shape (3, *s.shape) for
        alignment (m), vertical profile (m), cross-level angle (rad). ``chunk`` bounds the
        size of the temporary (points x lines) arrays."""
        s = np.asarray(s, dtype=float)
        flat = np.mod(s.ravel(), self.period_length)  # Omega_k L = 2 pi k: keeps arguments small
        values = np.zeros((3, flat.size))
        slopes = np.zeros((3, flat.size))
        ln = self.lines
        if ln.k.size:
            # cos(w s + phi) = cos(w s) cos(phi) - sin(w s) sin(phi): two transcendental calls
            # per (point, line) for all channels, the rest is matrix products
            a, om = ln.amplitude, ln.omega
            ac, as_ = a * np.cos(ln.phase), a * np.sin(ln.phase)
            coef_c = np.concatenate([ac, -om * as_]).T  # (K, 6): values then slopes
            coef_s = np.concatenate([-as_, -om * ac]).T
            step = max(1, chunk // ln.k.size)
            for j in range(0, flat.size, step):
                arg = np.multiply.outer(flat[j:j + step], om)  # (n, K)
                r = np.cos(arg) @ coef_c + np.sin(arg) @ coef_s  # (n, 6)
                values[:, j:j + step] = r[:, :3].T
                slopes[:, j:j + step] = r[:, 3:].T
        return values.reshape((3, *s.shape)), slopes.reshape((3, *s.shape))

    def random_grid(self, M: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact values and slopes on ``s_n = n L / M``, n = 0..M-1, by inverse real FFT:
        (s, values (3, M), slopes (3, M)). ``M`` defaults to the FMU's :func:`grid_size` and
        must exceed twice the highest line number."""
        M = grid_size(self.params) if M is None else int(M)
        ln = self.lines
        if ln.k.size and M <= 2 * ln.k[-1]:
            raise ValueError(f"M = {M} must exceed 2 k_max = {2 * ln.k[-1]}")
        X = np.zeros((3, M // 2 + 1), dtype=complex)
        X[:, ln.k] = 0.5 * M * ln.amplitude * np.exp(1j * ln.phase)
        values = np.fft.irfft(X, n=M, axis=1)
        d_omega = 2.0 * math.pi / self.period_length
        slopes = np.fft.irfft(X * (1j * d_omega * np.arange(M // 2 + 1)), n=M, axis=1)
        return np.arange(M) * (self.period_length / M), values, slopes

    def sample(self, ds: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The random part at ``s = 0, ds, .., (n-1) ds`` by FFT; ``L / ds`` must be an integer
        (the profile is periodic, longer records repeat it): (s, values, slopes)."""
        M = self.period_length / ds
        if abs(M - round(M)) > 1e-9 * M:
            raise ValueError(f"period_length / ds = {M} is not an integer")
        s_grid, v, d = self.random_grid(int(round(M)))
        idx = np.arange(n) % v.shape[1]
        return np.arange(n) * ds, v[:, idx], d[:, idx]

    def random_tabulated(self, s) -> tuple[np.ndarray, np.ndarray]:
        """The FMU's evaluation of the random part: periodic cubic Hermite interpolation of the
        FFT-tabulated values and slopes (grid :func:`grid_size`), same arithmetic as the C."""
        s = np.asarray(s, dtype=float)
        if not self.lines.k.size:
            return np.zeros((3, *s.shape)), np.zeros((3, *s.shape))
        if self._grid is None:
            self._grid = self.random_grid()
        _, gv, gd = self._grid
        M = gv.shape[1]
        L = self.period_length
        h = L / M
        u = np.fmod(s, L)
        u = np.where(u < 0, u + L, u)
        x = u / h
        n = np.floor(x)
        t = x - n
        n = n.astype(np.int64)
        n = np.where(n >= M, n - M, n)
        n1 = np.where(n + 1 == M, 0, n + 1)
        return _hermite(t, h, gv[:, n], gd[:, n], gv[:, n1], gd[:, n1])

    # -- rails --
    def rails(self, s, method: str = "exact", reach=0.0) -> dict[str, np.ndarray]:
        """All components summed at track positions ``s`` (m); ``method`` 'exact' (cosine sum)
        or 'tabulated' (the FMU's interpolation) for the random part; a step less than
        ``reach`` (m) ahead of ``s`` counts as reached (the FMU's eps |v| h)."""
        p = self.params
        s = np.asarray(s, dtype=float)
        if method == "exact":
            rv, rd = self.random_exact(s)
        elif method == "tabulated":
            rv, rd = self.random_tabulated(s)
        else:
            raise ValueError(f"method must be 'exact' or 'tabulated', not {method!r}")
        b = p["half_contact_width"]
        ali, ali_d = rv[0], rd[0]
        zl, zl_d = rv[1] + b * rv[2], rd[1] + b * rd[2]
        zr, zr_d = rv[1] - b * rv[2], rd[1] - b * rd[2]
        # harmonic
        k = 2.0 * math.pi / p["harmonic_wavelength"]
        arg = k * s + p["harmonic_phase"]
        sn, cs = np.sin(arg), np.cos(arg)
        Ay, Az = p["harmonic_lateral_amplitude"], p["harmonic_vertical_amplitude"]
        ali, ali_d = ali + Ay * sn, ali_d + Ay * k * cs
        zl, zl_d = zl + Az * sn, zl_d + Az * k * cs
        zr, zr_d = zr + Az * sn, zr_d + Az * k * cs
        # step (its Dirac derivative is ignored)
        on = s >= p["step_position"] - reach
        ali = ali + np.where(on, p["step_lateral"], 0.0)
        zl = zl + np.where(on, p["step_vertical"], 0.0)
        zr = zr + np.where(on, p["step_vertical"], 0.0)
        # measured profile
        if self.profile is not None:
            tv, td = self.profile(s)
            g = p["profile_scale"]
            ali, zl, zr = ali + g * tv[0], zl + g * tv[1], zr + g * tv[2]
            ali_d, zl_d, zr_d = ali_d + g * td[0], zl_d + g * td[1], zr_d + g * td[2]
        # run-in: the total deviation times w(s), the slopes by the product rule
        if p["run_in_length"] > 0:
            w, w_d = run_in_weight(s, p["run_in_length"])
            ali_d, zl_d, zr_d = w * ali_d + ali * w_d, w * zl_d + zl * w_d, w * zr_d + zr * w_d
            ali, zl, zr = w * ali, w * zl, w * zr
        return {"alignment": ali, "vertical_left": zl, "vertical_right": zr,
                "alignment_ds": ali_d, "vertical_left_ds": zl_d, "vertical_right_ds": zr_d}

    def _motion(self, t, distance, speed) -> tuple[np.ndarray, np.ndarray]:
        """(s_1, v): s_start + V t and V, or s_start + distance and speed (distance_input)."""
        p = self.params
        t = np.asarray(t, dtype=float)
        if not p["distance_input"]:
            return p["s_start"] + p["V"] * t, np.full(t.shape, float(p["V"]))
        if distance is None or speed is None:
            raise ValueError("distance_input is true: give the distance (m) and speed (m/s) at t")
        d = np.broadcast_to(np.asarray(distance, dtype=float), t.shape)
        v = np.broadcast_to(np.asarray(speed, dtype=float), t.shape)
        return p["s_start"] + d, v

    def wheelset_positions(self, t, distance=None) -> np.ndarray:
        """s_i = s_1 - axle_position_i, shape (4, *t.shape), with s_1 = s_start + V t, or
        s_start + ``distance`` (m, at t) when distance_input is true."""
        front, _ = self._motion(t, distance, 0.0)
        return np.array([front - self.params[f"axle_position_{i}"] for i in range(1, 5)])

    def outputs(self, t, method: str = "exact", h=0.0, distance=None, speed=None) -> dict[str, np.ndarray]:
        """The FMU's outputs (by name) at communication points ``t`` (s) reached by steps ``h``
        (s, scalar or per point; 0: initialisation mode; it only places a step on the grid).
        With distance_input, ``distance`` (m) and ``speed`` (m/s) are the inputs at ``t``
        (set there: no extrapolation)."""
        p = self.params
        front, v = self._motion(t, distance, speed)
        reach = STEP_TOLERANCE * np.abs(v) * np.asarray(h, dtype=float)
        out = {"position": front - p["axle_position_1"]}
        for i in range(4):
            r = self.rails(front - p[f"axle_position_{i + 1}"], method, reach)
            for name in ("alignment", "vertical_left", "vertical_right"):
                out[f"{name}_{i + 1}"] = r[name]
                out[f"{name}_rate_{i + 1}"] = v * r[name + "_ds"]
        return out


# ---- the model definition ------------------------------------------------------------------

def _axle_positions() -> list[Parameter]:
    src = ("ERRI B176 coach: bogie pivot spacing 2 a1 = 19 m (Onat et al. (2016), Table 1, a1 = 9.5 m), "
           "bogie wheelbase 2.5 m")
    return [Parameter(f"axle_position_{i}", f"distance of wheelset {i} behind wheelset 1 along the track",
                      unit="m", start=x, source=src)
            for i, x in zip(range(1, 5), (0.0, 2.5, 19.0, 21.5))]


def _outputs() -> list[Output]:
    # feedthrough (distance_input true): every output reads distance; the rates are
    # speed d/ds, and speed also moves the step's reach tolerance (STEP_TOLERANCE |v| h)
    both = ("distance", "speed")
    out = [Output("position", "track position s_1 of the leading wheelset (s_start + V t, or "
                  "s_start + distance)", unit="m", depends_on=("distance",))]
    for i in range(1, 5):
        out += [
            Output(f"alignment_{i}", f"lateral alignment of both rails at wheelset {i}", unit="m", depends_on=both),
            Output(f"alignment_rate_{i}", f"time derivative of alignment_{i} (v d/ds)", unit="m/s", depends_on=both),
            Output(f"vertical_left_{i}", f"vertical deviation of the left rail at wheelset {i}", unit="m", depends_on=both),
            Output(f"vertical_right_{i}", f"vertical deviation of the right rail at wheelset {i}", unit="m", depends_on=both),
            Output(f"vertical_left_rate_{i}", f"time derivative of vertical_left_{i} (v d/ds)", unit="m/s", depends_on=both),
            Output(f"vertical_right_rate_{i}", f"time derivative of vertical_right_{i} (v d/ds)", unit="m/s", depends_on=both),
        ]
    return out


_B176 = "ERRI B176 / ORE B176 RP1 track spectra (Claus & Schiehlen 1998, ref. [18] of Muñoz et al.)"

TRACK = Model(
    identifier="TrackIrregularity",
    description="Track irregularities under four wheelsets: ERRI B176 random track (SplitMix64 "
                "phases), harmonic, step and measured profile",
    parameters=[
        Parameter("V", "vehicle speed along the track", unit="m/s", start=20.0, min=0.0,
                  source="Muñoz et al., §5 (V = 20 m/s)"),
        Parameter("s_start", "track position of wheelset 1 at time 0", unit="m", start=0.0,
                  source="choice"),
        *_axle_positions(),
        Parameter("psd_level", "ERRI B176 spectrum level: 0 none, 1 low, 2 high", unit="", start=1,
                  type="Integer", min=0, max=2, source=_B176),
        Parameter("psd_scale", "factor on the random amplitudes (PSD times its square)", unit="",
                  start=1.0, min=0.0, source="choice"),
        Parameter("psd_lateral_scale", "extra factor on the random alignment only (0: no random "
                  "alignment, e.g. a harmonic-only lateral case)", unit="", start=1.0, min=0.0,
                  source="choice (Muñoz et al., §5.4-5.5 cases)"),
        Parameter("psd_vertical_scale", "extra factor on the random vertical profile and cross-level "
                  "(0: no vertical irregularity; the alignment keeps its phases)", unit="", start=1.0,
                  min=0.0, source="choice (Muñoz et al., §5.4, 'no vertical irregularities')"),
        Parameter("lambda_min", "shortest wavelength of the random lines (> 0)", unit="m", start=1.0,
                  positive=True,
                  source="choice: covers EN 13848 band D1 (3-25 m) and vehicle response"),
        Parameter("lambda_max", "longest wavelength of the random lines (> lambda_min)", unit="m",
                  start=300.0, source="choice: covers EN 13848 bands D1-D3 (3-200 m)"),
        Parameter("period_length", "L: the random profile repeats after it; line spacing 2 pi / L",
                  unit="m", start=5000.0, positive=True,
                  source="choice"),
        Parameter("grid_step", "upper bound of the FMU's tabulation step of the random profile",
                  unit="m", start=0.05, positive=True,
                  source="choice: Hermite error < 1e-9 m (tabulation_error_bound)"),
        Parameter("seed", "seed of the SplitMix64 phase stream", unit="", start=1, type="Integer",
                  source="choice"),
        Parameter("half_contact_width", "b: half the distance between the wheel-rail contact points",
                  unit="m", start=0.75, positive=True,
                  source="Muñoz et al., Table 1 (l = 0.75 m); ERRI B176 b"),
        Parameter("harmonic_lateral_amplitude", "amplitude of the harmonic alignment", unit="m",
                  start=0.0, source="Muñoz et al., §5.5 case 2 uses 1e-3 m"),
        Parameter("harmonic_vertical_amplitude", "amplitude of the harmonic on both rails' heights",
                  unit="m", start=0.0, source="choice"),
        Parameter("harmonic_wavelength", "wavelength of the harmonic (> 0)", unit="m", start=20.0,
                  positive=True,
                  source="choice; Muñoz et al., §5.5 uses 15.66 m"),
        Parameter("harmonic_phase", "phase of the harmonic at s = 0", unit="rad", start=0.0,
                  source="choice"),
        Parameter("step_lateral", "lateral step of the alignment at step_position", unit="m",
                  start=0.0, source="choice"),
        Parameter("step_vertical", "vertical step of both rails at step_position", unit="m",
                  start=0.0, source="choice"),
        Parameter("step_position", "track position of the step", unit="m", start=100.0,
                  source="choice"),
        Parameter("profile_file", "CSV s,alignment,vertical_left,vertical_right (m); relative to "
                  "resources/; none when empty", unit="", start="", type="String", source="choice"),
        Parameter("profile_scale", "factor on the measured profile", unit="", start=1.0,
                  source="choice"),
        # appended last: the other parameters keep their value references
        Parameter("run_in_length", "length over which all irregularities ramp in from zero at "
                  "s = 0 (raised cosine); 0: no run-in", unit="m", start=0.0, min=0.0,
                  source="choice: vehicle and estimator start in equilibrium on ideal track and "
                  "run onto the irregular track smoothly, as multibody track simulations do"),
        Parameter("distance_input", "take the position and speed from the inputs distance and speed "
                  "(stop-and-go, accelerating runs); false: constant speed V", unit="", start=False,
                  type="Boolean", source="choice: constant V is the case of Muñoz et al. and Onat et al. (2016)"),
    ],
    inputs=[
        Input("distance", "distance travelled by the vehicle since the start, s_1 = s_start + "
              "distance (read when distance_input is true)", unit="m", start=0.0, rate="speed"),
        Input("speed", "speed along the track, d distance/dt; the rates are speed d/ds (read when "
              "distance_input is true)", unit="m/s", start=0.0),
    ],
    outputs=_outputs(),
    c_sources=["TrackIrregularity.c"],
    # an example profile shipped in resources/: set profile_file = "isolated_alignment_defect.csv"
    # (a synthetic 4 mm, 10 m raised-cosine alignment cusp at s = 50..60 m)
    resources={"isolated_alignment_defect.csv": Path(__file__).resolve().parents[1] / "data" / "isolated_alignment_defect.csv"},
    documentation=__doc__,
)
