r"""IMU errors: the ``ImuErrors`` FMU turns the ideal increments of an IMU (from the ``Trolley``)
into measured ones, with the error model of a datasheet, so that IMU grades are swapped by an
``.ssv`` (``experiments/trolley_survey/parameters/imu_*.ssv``, :data:`GRADES`).

Inputs ``dtheta_in_{x,y,z}`` (rad) and ``dv_in_{x,y,z}`` (m/s) are the integrals of the true
angular rate omega_ib^b and specific force f^b over the communication step ``h`` that ends at
the sample time ``t`` (body frame forward-right-down); the outputs ``dtheta_{x,y,z}``,
``dv_{x,y,z}`` are the measured increments over the same interval. The C is hand written
(``fmus/native/models/ImuErrors.c``); :class:`ImuErrorsTwin` is its Python twin, bit for bit
(``tests/test_imu_errors.py``).

Error model
-----------
Per sensor triad (gyro: ``u`` = Δθ, rates in rad/s; accelerometer: ``u`` = Δv, specific force
in m/s2), axis ``i`` of x, y, z, with the increment ``u`` over ``[t - h, t]``::

    y_i = u_i + s_i u_i + sum_{j != i} m_ij u_j          scale factor, misalignment
              + b_on,i h                                  turn-on bias (constant over the run)
              + int_{t-h}^{t} b_i(t') dt'                 bias instability (Gauss-Markov)
              + N sqrt(h) w_i(k)                          angle / velocity random walk

``(I + S + M)`` with ``S = diag(s_i)`` and the off-diagonal ``m_ij`` is the small-angle
sensor-axes matrix of the IMU error model in Groves (2013), *Principles of GNSS, Inertial, and
Multisensor Integrated Navigation Systems*, 2nd ed., ch. 4: ``m_ij`` is the angle (rad) by which
sensitive axis ``i`` leans towards body axis ``j``; a triad rotated by the small angles phi
measures ``(I - [phi x]) u`` (``m = -[phi x]``), non-orthogonal axes need all six. With every
error zero ``y_i = u_i`` bit for bit (the sum is only added where it is non-zero).

Bias instability: a first-order Gauss-Markov (GM) process per axis,
``db/dt = -b / Tc + sqrt(2 sigma_b^2 / Tc) w(t)``, stationary from the start
(``b(t0) ~ N(0, sigma_b^2)``). Why GM and not a random walk: the datasheet "bias instability"
is the flat floor of the Allan deviation (flicker noise, IEEE Std 952-1997 Annex C /
IEEE Std 1293-1998), a bounded quantity; a random-walk bias grows without bound and is a
different datasheet figure (rate random walk, K, an Allan slope of +1/2 everywhere). A GM
process is bounded, has an Allan deviation that rises as sqrt(tau) below Tc, peaks and falls
as 1/sqrt(tau) above (the shape of a floor with its corners rounded), and has an exact
discrete form that an error-state Kalman filter models with the same equation. Its Allan
variance in closed form (x = tau / Tc)::

    sigma_A^2(tau) = sigma_b^2 (2 x - 3 + 4 e^-x - e^-2x) / x^2             (allan_variance_gm)

peaks at ``x_p = 1.8926`` with ``sigma_A = 0.61736 sigma_b`` (:data:`GM_ALLAN_PEAK`). A flicker
floor reads ``sigma_A = sqrt(2 ln 2 / pi) B = 0.66428 B`` for the datasheet bias instability
``B`` (IEEE 952, :data:`FLICKER_FLOOR`). We set ``sigma_b = (0.66428 / 0.61736) B = 1.0760 B``
(:data:`GM_SIGMA_PER_B`): the Allan deviation of the simulated bias peaks exactly at the
datasheet floor, so an analyst reading the floor of our data divides by 0.664 and gets ``B``
back. ``Tc`` is a parameter (datasheets do not give it): 1 h in the grades, about 50 times the
~70 s between the stops of Jiang et al. (2017), so the bias is nearly constant between two
zero-velocity updates as their filter assumes (§2, "piecewise constant") yet drifts over a
run. At ``tau_p = 1.8926 Tc`` the white noise adds ``N^2 / tau_p`` to the Allan variance: 30 %
of the GM's for the navigation-grade gyro at Tc = 1 h (0.005 °/√h against a 0.0066 °/h floor),
< 2 % in the other grades; below Tc the GM is a rate random walk, ``sigma_A^2 ~ (2 sigma_b^2 /
Tc) tau / 3``, which adds 19 % to the Allan variance at 1 s of the tactical-grade
accelerometer (its 1 mg bias instability against 34 µg/√Hz), < 1 % elsewhere.

Exact discretisation over the actual step ``h`` (any ``h``; no small-step approximation). With
``x = h / Tc``, ``e = expm1(-x)`` (so ``beta = e^-x = 1 + e`` and ``1 - beta = -e`` are exact to
the last bit also for ``h << Tc``) the end state and the integral over the step are jointly
Gaussian given the state ``b0`` at the step's start::

    b1 = beta b0 + eta                                      Var eta   = sigma_b^2 (1 - beta^2)
    I  = Tc (1 - beta) b0 + zeta                            Var zeta  = 2 sigma_b^2 Tc^2 f(x)
    f(x) = x - 2 (1 - e^-x) + (1 - e^-2x) / 2               Cov(eta, zeta) = sigma_b^2 Tc^2 (1 - beta)^2
    eta  = sigma_b sqrt((1 - beta)(1 + beta)) w1
    zeta = Tc (1 - beta) / (1 + beta) eta                   the part of zeta explained by eta
           + sigma_b Tc sqrt(2 f(x) - (1 - beta)^3 / (1 + beta)) w2

``f(x) = x^3/3 - x^4/4 + ...`` cancels catastrophically for small ``x`` (5e-3 s / 1 h = 1.4e-6):
below ``x = 0.5`` it is summed as its series ``sum_{n>=3} (-1)^(n+1) (2^(n-1) - 2) x^n / n!``
(30 terms, relative error ~1e-16), above as written. ``tests/test_imu_errors.py`` checks the
covariances against Van Loan's matrix exponential for x from 1e-7 to 20.

Random walks: a white rate noise of (two-sided) density ``N`` integrates over ``h`` to an
increment of standard deviation ``N sqrt(h)``; its Allan deviation is ``N / sqrt(tau)``, so ``N``
is read at tau = 1 s (IEEE 952). Datasheet units: gyro ARW in °/√h (``N = ARW pi/180 / 60``
rad/√s), accelerometer noise density in µg/√Hz taken as ``N`` in µg·√s (the datasheet
convention that 1 unit/√Hz of density is 1 unit·√s of random walk, e.g. 0.05 m/s/√h = 85 µg/√Hz);
``g = 9.80665 m/s2`` (standard gravity: the unit g of datasheets, not local gravity).

Counter-based noise, sample index
---------------------------------
All random numbers are the counter-based Gaussians of ``models/sources/sensors.py`` (SplitMix64 +
Box-Muller, libm ``log``/``cos``): a pure function of (seed, stream, k), so C, the twin and any
importer give the same numbers and a restored FMU state replays them. Streams (``a`` = 1..6
for gyro x, y, z, accelerometer x, y, z; above SensorNoise's and GnssReceiver's channels 1..8,
which take the same run seed)::

    4096 + a   w_a(k)  the random walk of step k
    4112 + a   w1      the GM state innovation eta of step k
    4128 + a   w2      the GM integral's own part of step k
    4144 + a   constants at k = 0 GM state at t0, 1 turn-on bias, 2 scale factor,
                                3, 4, 5 misalignment towards x, y, z

Turn-on bias, scale factor and misalignment are ``fixed + sigma w`` (datasheet units, then
converted), drawn once per seed. The sample index of the step that ended at ``t`` is
SensorNoise's with the period equal to the step: ``k = max(floor((t - t0) / h + 0.01), 0)``
(``STEP_TOLERANCE``), which is the step number ``n`` whether the master computes ``t = t0 + n h``
or accumulates ``t += h`` (they differ by < 2e-3 h up to 1e7 steps). The step must not grow
during a run (k would repeat a used sample: an error); railfmu's masters, FMPy and libcosim
step at a fixed ``h`` (libcosim's nanosecond clock makes it vary by an ulp: k still counts the
steps, and each step is discretised with the ``h`` it took).

Memory: the GM states at ``t`` (``*_in_run_bias_*``) and at the previous communication point
(``*_in_run_bias_before_*``), ``sample`` and ``sample_time`` are outputs, so fmi2GetFMUstate keeps
them; at a new communication point the state at ``t`` moves to "before" and is advanced from
there, so a get after a set at the same point computes the same step again, not a second one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import sympy as sp

from railfmu.models.base import STEP_TOLERANCE, Input, Model, Output, Parameter
from railfmu.models.sources.sensors import GAMMA, _libm, _mix64

AXES = ("x", "y", "z")
SENSORS = ("gyro", "accel")
#: value reference order of the misalignment parameters: (row i, column j), i != j
MISALIGNMENT = ("xy", "xz", "yx", "yz", "zx", "zy")
STREAM_WHITE, STREAM_ETA, STREAM_ZETA, STREAM_CONST = 4096, 4112, 4128, 4144
K_GM0, K_TURN_ON, K_SCALE, K_MISALIGNMENT = 0, 1, 2, 3  # k of the constants' stream

G0 = 9.80665  # m/s2: the unit g of datasheets (standard gravity)
DEG = math.pi / 180.0
#: datasheet unit -> SI, in the same arithmetic as the C
GYRO_NOISE_SI = DEG / 60.0  # °/√h -> rad/√s
GYRO_BIAS_SI = DEG / 3600.0  # °/h -> rad/s
ACCEL_SI = 1e-6 * G0  # µg -> m/s2 and µg/√Hz -> m/s/√s
PPM = 1e-6
URAD = 1e-6
#: IEEE 952 flicker floor: sigma_A = sqrt(2 ln 2 / pi) B
FLICKER_FLOOR = 0.66428247026796
#: maximum over tau of the Allan deviation of a unit-variance first-order GM process, and its tau / Tc
GM_ALLAN_PEAK = 0.6173642831444414
GM_ALLAN_PEAK_X = 1.8926178329250188
#: sigma_b / B: the GM's Allan peak equals the datasheet's flicker floor (FLICKER_FLOOR / GM_ALLAN_PEAK)
GM_SIGMA_PER_B = 1.0759975729152142
SERIES_BELOW = 0.5
SERIES_TERMS = 30
_MASK64 = (1 << 64) - 1


# ---- the Gauss-Markov bias over one step -------------------------------------------------------

def gm_f(x: float) -> float:
    """f(x) = x - 2 (1 - e^-x) + (1 - e^-2x) / 2 for x = h / Tc >= 0, without cancellation
    (the same arithmetic as ImuErrors.c)."""
    if x >= SERIES_BELOW:
        e = math.expm1(-x)
        return x + e - 0.5 * e * e
    term = x * x * x / 6.0  # x^n / n! at n = 3
    p = 4.0  # 2^(n-1)
    s = 0.0
    sign = 1.0
    for n in range(3, 3 + SERIES_TERMS):
        s += sign * (p - 2.0) * term
        term *= x / (n + 1)
        p *= 2.0
        sign = -sign
    return s


def gm_step(h: float, tc: float, sigma: float) -> tuple[float, float, float, float, float]:
    """Coefficients of the exact GM step (module docstring): ``(beta, a, s_eta, gain, s_zeta)``
    with ``b1 = beta b0 + s_eta w1`` and ``I = a b0 + gain s_eta w1 + s_zeta w2``."""
    x = h / tc
    e = math.expm1(-x)
    om = -e  # 1 - beta
    beta = 1.0 + e
    s_eta = sigma * math.sqrt(om * (2.0 - om))
    gain = tc * om / (2.0 - om)
    schur = 2.0 * gm_f(x) - om * om * om / (2.0 - om)
    s_zeta = sigma * tc * math.sqrt(schur if schur > 0.0 else 0.0)
    return beta, tc * om, s_eta, gain, s_zeta


def allan_variance_gm(tau, sigma: float, tc: float):
    """Allan variance of a first-order GM rate process (variance sigma^2, correlation time tc)
    averaged over tau: sigma^2 (2x - 3 + 4e^-x - e^-2x) / x^2, x = tau / tc."""
    x = np.asarray(tau, dtype=float) / tc
    return sigma**2 * (2 * x - 3 + 4 * np.exp(-x) - np.exp(-2 * x)) / x**2


# ---- the counter-based noise --------------------------------------------------------------------

def gauss(seed: int, stream: int, k, exact: bool = True) -> np.ndarray:
    """Standard Gaussians of ``stream`` at samples ``k`` (non-negative integers): the noise of
    ``railfmu.models.sources.sensors.noise`` (c = mix64(seed + stream G), outputs 2k+1, 2k+2 of SplitMix64(c),
    Box-Muller) for any stream number; ``exact=False`` uses numpy's log/cos (faster, may differ
    from the FMU in the last bit)."""
    k = np.asarray(k, dtype=np.int64).astype(np.uint64)
    one, two, g = np.uint64(1), np.uint64(2), np.uint64(GAMMA)
    with np.errstate(over="ignore"):
        c = _mix64(np.array([(int(seed) + stream * GAMMA) & _MASK64], dtype=np.uint64))[0]
        n = two * k + one
        z1 = _mix64(c + n * g)
        z2 = _mix64(c + (n + one) * g)
    u1 = ((z1 >> np.uint64(11)) + one).astype(np.float64) * 2.0**-53
    u2 = (z2 >> np.uint64(11)).astype(np.float64) * 2.0**-53
    if exact:
        lg, cs = _libm(math.log, u1), _libm(math.cos, 2.0 * math.pi * u2)
    else:
        lg, cs = np.log(u1), np.cos(2.0 * math.pi * u2)
    return np.sqrt(-2.0 * lg) * cs


def sample_index(t, t0: float, h) -> np.ndarray:
    """k = max(floor((t - t0) / h + STEP_TOLERANCE), 0) for points ``t`` reached by steps ``h``
    (> 0): SensorNoise's rule with the sample period equal to the step."""
    t = np.asarray(t, dtype=float)
    k = np.floor((t - t0) / np.asarray(h, dtype=float) + STEP_TOLERANCE)
    return np.maximum(k, 0.0).astype(np.int64)


# ---- the Python twin ---------------------------------------------------------------------------

def _si(sensor: str) -> tuple[float, float]:
    """(noise density, bias) datasheet unit -> SI factors of a sensor triad."""
    return (GYRO_NOISE_SI, GYRO_BIAS_SI) if sensor == "gyro" else (ACCEL_SI, ACCEL_SI)


class ImuErrorsTwin:
    """Python twin of the ``ImuErrors`` FMU. ``params`` override :data:`IMU_ERRORS`' defaults
    (datasheet units, as the FMU's parameters)."""

    def __init__(self, params: Mapping[str, float] | None = None):
        self.p = {**IMU_ERRORS.default_parameters(), **(params or {})}
        unknown = set(self.p) - {q.name for q in IMU_ERRORS.parameters}
        if unknown:
            raise KeyError(f"unknown ImuErrors parameters {sorted(unknown)}")
        IMU_ERRORS.check_parameters(self.p)
        self.constants = self._draw_constants()

    def _draw_constants(self) -> dict:
        """Per axis a = 1..6: turn-on bias (SI), scale factor, misalignment row {j: m_ij} and
        the GM state at t0, drawn once from the seed (module docstring)."""
        p, seed = self.p, int(self.p["seed"])
        out = {}
        for s, sensor in enumerate(SENSORS):
            _, bias_si = _si(sensor)
            sigma_b = GM_SIGMA_PER_B * (p[f"{sensor}_bias_instability_{_BI_UNIT[sensor]}"] * bias_si)
            for i, ax in enumerate(AXES):
                a = 3 * s + i + 1
                w = gauss(seed, STREAM_CONST + a, np.arange(6))
                on = p[f"{sensor}_turn_on_bias_{ax}_{_BI_UNIT[sensor]}"] + \
                    p[f"{sensor}_turn_on_bias_sigma_{_BI_UNIT[sensor]}"] * w[K_TURN_ON]
                sf = p[f"{sensor}_scale_factor_{ax}_ppm"] + p[f"{sensor}_scale_factor_sigma_ppm"] * w[K_SCALE]
                row = {}
                for j, bx in enumerate(AXES):
                    if j != i:
                        m = p[f"{sensor}_misalignment_{ax}{bx}_urad"] + \
                            p[f"{sensor}_misalignment_sigma_urad"] * w[K_MISALIGNMENT + j]
                        row[j] = float(m) * URAD
                out[a] = {"turn_on": float(on) * bias_si, "scale": float(sf) * PPM, "misalignment": row,
                          "gm0": sigma_b * float(w[K_GM0]), "sigma_b": sigma_b}
        return out

    def run(self, t, h, dtheta_in, dv_in, t0: float | None = None, exact: bool = True) -> dict[str, np.ndarray]:
        """Outputs at the communication points ``t`` (s, as the master computes them; ``t[0]``
        is the start, in initialisation mode) reached by steps ``h`` (s; scalar, or one per
        point with ``h[0]`` ignored; the step from ``t[m-1]`` ends at the FMU time
        ``t[m-1] + h[m]``), for the ideal increments ``dtheta_in``, ``dv_in`` (arrays (n, 3), the inputs
        at each point). Returns every output of the FMU by name, as arrays of length n."""
        p = self.p
        t = np.asarray(t, dtype=float)
        n = len(t)
        t0 = float(t[0]) if t0 is None else float(t0)
        hs = np.broadcast_to(np.asarray(h, dtype=float), (n,)).copy()
        hs[0] = 0.0
        # the FMU's own time after a step from t[m-1] is t[m-1] + h (the runtime's r[0])
        tf = t.copy()
        tf[1:] = t[:-1] + hs[1:]
        k = np.zeros(n, dtype=np.int64)
        if n > 1:
            k[1:] = sample_index(tf[1:], t0, hs[1:])
            if np.any(np.diff(k) <= 0):
                raise ValueError("the sample index would repeat: the step size grew during the run")
        u = {"gyro": np.asarray(dtheta_in, dtype=float).reshape(n, 3),
             "accel": np.asarray(dv_in, dtype=float).reshape(n, 3)}
        out: dict[str, np.ndarray] = {"sample": k, "sample_time": tf}
        seed = int(p["seed"])
        for s, sensor in enumerate(SENSORS):
            noise_si, _ = _si(sensor)
            n_si = p[f"{sensor}_{_NOISE_NAME[sensor]}"] * noise_si
            tc = p[f"{sensor}_bias_correlation_time"]
            us = u[sensor]
            for i, ax in enumerate(AXES):
                a = 3 * s + i + 1
                c = self.constants[a]
                sigma_b = c["sigma_b"]
                # the deterministic part: scale factor and misalignment (also at t0)
                err = c["scale"] * us[:, i]
                for j in (0, 1, 2):
                    if j != i:
                        err = err + c["misalignment"][j] * us[:, j]
                ws = gauss(seed, STREAM_WHITE + a, k[1:], exact) if n_si != 0 else np.zeros(n - 1)
                w1 = gauss(seed, STREAM_ETA + a, k[1:], exact) if sigma_b != 0 else np.zeros(n - 1)
                w2 = gauss(seed, STREAM_ZETA + a, k[1:], exact) if sigma_b != 0 else np.zeros(n - 1)
                gm = np.empty(n)
                before = np.empty(n)
                gm[0] = before[0] = c["gm0"]
                errl = err.tolist()
                coef: dict[float, tuple] = {}
                b = c["gm0"]
                on = c["turn_on"]
                for m in range(1, n):
                    hm = float(hs[m])
                    if hm not in coef:
                        coef[hm] = (*gm_step(hm, tc, sigma_b), n_si * math.sqrt(hm))
                    beta, aa, s_eta, gain, s_zeta, s_white = coef[hm]
                    eta = s_eta * float(w1[m - 1])
                    integral = aa * b + gain * eta + s_zeta * float(w2[m - 1])
                    errl[m] = errl[m] + on * hm + integral + s_white * float(ws[m - 1])
                    before[m] = b
                    b = beta * b + eta
                    gm[m] = b
                err = np.asarray(errl)
                y = np.where(err != 0.0, us[:, i] + err, us[:, i])
                out[f"{_OUT[sensor]}_{ax}"] = y
                out[f"{sensor}_in_run_bias_{ax}"] = gm
                out[f"{sensor}_in_run_bias_before_{ax}"] = before
                out[f"{sensor}_bias_{ax}"] = on + gm
        return out


# ---- the model definition ---------------------------------------------------------------------

_OUT = {"gyro": "dtheta", "accel": "dv"}
_BI_UNIT = {"gyro": "deg_h", "accel": "ug"}
_NOISE_NAME = {"gyro": "arw_deg_sqrt_h", "accel": "noise_ug_sqrt_hz"}
_SRC_GRADE = "grade .ssv (models/inertial/imu_errors.py GRADES); 0: the ideal IMU"


def _sensor_parameters(sensor: str) -> list[Parameter]:
    what = {"gyro": "gyro", "accel": "accelerometer"}[sensor]
    bu = {"gyro": "°/h", "accel": "µg"}[sensor]
    bn = _BI_UNIT[sensor]
    noise = (Parameter(f"gyro_{_NOISE_NAME['gyro']}", "angle random walk N of the gyros, in °/√h (>= 0)",
                       "", 0.0, min=0.0, source=_SRC_GRADE) if sensor == "gyro" else
             Parameter(f"accel_{_NOISE_NAME['accel']}", "white noise density of the accelerometers, in µg/√Hz "
                       "(velocity random walk N in µg·√s; >= 0)", "", 0.0, min=0.0, source=_SRC_GRADE))
    return [
        noise,
        Parameter(f"{sensor}_bias_instability_{bn}", f"bias instability B of the {what}s (Allan floor / 0.664), "
                  f"in {bu} (>= 0): Gauss-Markov sigma_b = 1.076 B", "", 0.0, min=0.0, source=_SRC_GRADE),
        Parameter(f"{sensor}_bias_correlation_time", f"correlation time Tc of the {what} bias instability (> 0)",
                  "s", 3600.0, positive=True,
                  source="choice: 1 h, ~50 stop-to-stop intervals of Jiang et al. (2017) (datasheets give none)"),
        Parameter(f"{sensor}_turn_on_bias_sigma_{bn}", f"standard deviation of the {what} turn-on bias drawn from "
                  f"the seed, in {bu} (>= 0)", "", 0.0, min=0.0, source=_SRC_GRADE),
        *[Parameter(f"{sensor}_turn_on_bias_{ax}_{bn}", f"fixed turn-on bias of the {ax} {what}, in {bu}", "", 0.0,
                    source="experiment (.ssv); 0: none") for ax in AXES],
        Parameter(f"{sensor}_scale_factor_sigma_ppm", f"standard deviation of the {what} scale-factor errors "
                  "drawn from the seed, in ppm (>= 0)", "", 0.0, min=0.0, source=_SRC_GRADE),
        *[Parameter(f"{sensor}_scale_factor_{ax}_ppm", f"fixed scale-factor error of the {ax} {what}, in ppm",
                    "", 0.0, source="experiment (.ssv); 0: none") for ax in AXES],
        Parameter(f"{sensor}_misalignment_sigma_urad", f"standard deviation of the {what} axis misalignments "
                  "drawn from the seed, in µrad (>= 0)", "", 0.0, min=0.0, source=_SRC_GRADE),
        *[Parameter(f"{sensor}_misalignment_{ij}_urad", f"fixed misalignment m_{ij} of the {what}s: angle of "
                    f"sensitive axis {ij[0]} towards body axis {ij[1]}, in µrad", "", 0.0,
                    source="experiment (.ssv); 0: none") for ij in MISALIGNMENT],
    ]


def _io() -> tuple[list[Input], list[Output]]:
    inputs, outputs = [], []
    for sensor, unit, rate in (("gyro", "rad", "rad/s"), ("accel", "m/s", "m/s2")):
        name = _OUT[sensor]
        what = {"gyro": "angle", "accel": "velocity"}[sensor]
        ins = [Input(f"{name}_in_{ax}", f"ideal {what} increment about/along body {ax} over the last "
                     "communication step", unit, 0.0) for ax in AXES]
        inputs += ins
        for i, ax in enumerate(AXES):
            # the expression declares the structure (output i depends on the three inputs of
            # its triad: misalignment); the values come from the hand-written C
            err = sp.Symbol(f"e_{name}_{ax}", real=True)
            outputs.append(Output(f"{name}_{ax}", f"measured {what} increment about/along body {ax} over the "
                                  "last communication step", unit,
                                  expr=sum((u.symbol for u in ins), sp.Integer(0)) + err))
    for sensor, rate in (("gyro", "rad/s"), ("accel", "m/s2")):
        for ax in AXES:
            outputs.append(Output(f"{sensor}_bias_{ax}", f"true {sensor} bias on {ax} at t: turn-on + in-run",
                                  rate, expr=sp.Symbol(f"b_{sensor}_{ax}", real=True)))
        for ax in AXES:
            outputs.append(Output(f"{sensor}_in_run_bias_{ax}", f"Gauss-Markov bias-instability state on {ax} at "
                                  "t (memory)", rate, expr=sp.Symbol(f"g_{sensor}_{ax}", real=True)))
        for ax in AXES:
            outputs.append(Output(f"{sensor}_in_run_bias_before_{ax}", f"the state {sensor}_in_run_bias_{ax} at the "
                                  "previous communication point (memory)", rate,
                                  expr=sp.Symbol(f"gb_{sensor}_{ax}", real=True)))
    outputs.append(Output("sample", "sample index k of the step that ended at t (memory)", type="Integer",
                          expr=sp.Symbol("k_sample", real=True)))
    outputs.append(Output("sample_time", "the communication point the memory belongs to (memory)", "s",
                          expr=sp.Symbol("t_sample", real=True)))
    return inputs, outputs


_INPUTS, _OUTPUTS = _io()

IMU_ERRORS = Model(
    identifier="ImuErrors",
    description="IMU error model on angle and velocity increments: scale factor, misalignment, turn-on bias, "
                "Gauss-Markov bias instability and random walks, discretised exactly over the step; "
                "counter-based noise (SplitMix64 + Box-Muller); parameters in datasheet units",
    parameters=[*_sensor_parameters("gyro"), *_sensor_parameters("accel"),
                Parameter("seed", "seed of the counter-based noise and of the drawn constants", "", 1,
                          type="Integer", source="experiment (.ssv) or the run's --seed")],
    inputs=_INPUTS,
    outputs=_OUTPUTS,
    default_experiment=(0.0, 700.0, 5e-3),
    c_sources=["ImuErrors.c"],
    documentation=__doc__,
)


# ---- grades ------------------------------------------------------------------------------------

def _grade(**values: float) -> dict[str, float]:
    """Every Real parameter of the model at 0 (correlation times 1 h), then ``values``: a grade
    sets all of them, so swapping the .ssv swaps the whole IMU."""
    g = {q.name: float(q.start) for q in IMU_ERRORS.parameters if q.type == "Real"}
    unknown = set(values) - set(g)
    if unknown:
        raise KeyError(f"unknown ImuErrors parameters {sorted(unknown)}")
    g.update({k: float(v) for k, v in values.items()})
    return g


#: IMU grades in datasheet units; each is written as experiments/trolley_survey/parameters/imu_<name>.ssv
#: (the seed is the run's). Sources:
#:
#: * ``ideal``: every error zero, the output equals the input bit for bit.
#: * ``navigation_grade``: Jiang et al. (2017), §3 (the trolley's IMU, also §5's Monte Carlo): ring
#:   laser gyros with bias instability 0.01 °/h and ARW 0.005 °/√h, quartz accelerometers with
#:   bias instability 50 µg and noise 10 µg/√Hz. The paper gives no turn-on bias, scale factor or
#:   misalignment: 0. (Its filter takes the biases as piecewise constant; a variant may add
#:   ``gyro_turn_on_bias_sigma_deg_h = 0.01`` and ``accel_turn_on_bias_sigma_ug = 50`` for that reading.)
#: * ``tactical_grade``: Honeywell HG1700 (the higher-end AG58-class versions), Honeywell brochure
#:   N61-1619-000-001 "HG1700 Inertial Measurement Unit", 1-sigma values as transcribed in is4s
#:   NavToolkit's ``hg1700_model``: gyro bias 1 °/h, ARW 0.125 °/√h; accelerometer bias 1 mg,
#:   VRW 0.065 ft/s/√h = 0.065 · 0.3048 / 60 m/s/√s = 33.67 µg/√Hz. The bias is taken as the bias
#:   instability of the GM model (as NavToolkit does, with an assumed correlation time); the
#:   brochure gives no scale factor or misalignment: 0.
#: * ``mems_grade``: Aceinna OpenIMU300ZA, user manual "IMU Sensors" specification table (Aceinna,
#:   2018; github.com/Aceinna/docs_openrtk, 300ZA/imu-sensors.rst): gyro bias instability < 6 °/h
#:   (Allan, constant temperature, 1 sigma), ARW < 0.3 °/√h, scale-factor accuracy < 0.1 %;
#:   accelerometer bias instability < 20 µg, VRW < 0.05 m/s/√h = 0.05 / 60 / 9.80665e-6 = 84.98
#:   µg/√Hz, scale-factor accuracy < 0.1 % (1000 ppm, drawn per run). Its bias stability over
#:   temperature (0.5 °/s, 5 mg rms) is a temperature effect, not modelled; no misalignment given: 0.
GRADES: dict[str, dict[str, float]] = {
    "ideal": _grade(),
    "navigation_grade": _grade(gyro_arw_deg_sqrt_h=0.005, gyro_bias_instability_deg_h=0.01,
                               accel_noise_ug_sqrt_hz=10.0, accel_bias_instability_ug=50.0),
    "tactical_grade": _grade(gyro_arw_deg_sqrt_h=0.125, gyro_bias_instability_deg_h=1.0,
                             accel_noise_ug_sqrt_hz=33.67, accel_bias_instability_ug=1000.0),
    "mems_grade": _grade(gyro_arw_deg_sqrt_h=0.3, gyro_bias_instability_deg_h=6.0, gyro_scale_factor_sigma_ppm=1000.0,
                         accel_noise_ug_sqrt_hz=84.98, accel_bias_instability_ug=20.0,
                         accel_scale_factor_sigma_ppm=1000.0),
}
