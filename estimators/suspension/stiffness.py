r"""Online estimation of the secondary vertical stiffness ``k1`` of the ERRI B176 coach
(Onat et al. (2016)) from inertial signals and the known track input, and its fault metrics.

Two observers share one design model:

* :class:`SuspensionWLS`: the paper's scheme (eqs. 7-11), a linear Kalman filter on the 7-DOF
  model at the current estimate ``theta`` plus a weighted-least-squares update of ``theta``
  from the filter's residuals;
* :class:`SuspensionJoint`: joint estimation, an extended Kalman filter on the state
  augmented with ``theta`` as a random walk (our choice; it does better, see below).

Design model (both)
-------------------
:data:`railfmu.models.vehicle.coach_vertical.COACH_VERTICAL` linearised about rest (it is linear in the
state; ``k1`` enters as a factor)::

    x = [z_c, theta_c, phi_c, z_b1, phi_b1, z_b2, phi_b2, dz_c, ..., dphi_b2]   (14, m / rad, m/s / rad/s)
    dx/dt = (A0 + k1 A1) x + Bz w + Bd dw          (eqs. 2-5: T_k u + T_b u')
    y     = (H0 + k1 H1) x + Du [w, dw]            (eq. 6: the 7 sensors of SENSORS)

``w = [z_l1, z_r1, z_l2, z_r2]`` are the rail heights under bogie 1 (leading) and bogie 2, ``dw``
their rates. ``A0``, ``A1`` (and ``H0``, ``H1``) are exact: the model is affine in ``k1``, so
two linearisations (``k1`` = 0 and 1) give them. The sensor rows of ``H`` are the model's
accelerations (``ddz_c``, ``ddz_b1``, ``ddz_b2``: they depend on ``k1`` and on the rails) and the
gyro states (``dtheta_c``, ``dphi_c``, ``dphi_b1``, ``dphi_b2``).

**Known track input**: the paper's filter propagates with ``G_b(theta) u' + G_k(theta) u``
(eqs. 7-8) and takes the irregularity from a measured 3 km track section (§3), so both
observers read the rail heights and rates as inputs, next to the seven sensors (in the
experiment: the track FMU's outputs, as a track recording would give them).

Discretisation (both): exact for the FMU's input hold. The coach FMU extrapolates every rail
height linearly with its rate over a communication step (first-order hold) and holds the
rate, so one matrix exponential of (:func:`railfmu.estimators.core.discretize.foh`) ::

    [[A(k1), Bz, Bd], [0, 0, I], [0, 0, 0]] dt

gives ``x_{k+1} = F x_k + G [w_k, dw_k]`` exactly (checked against the FMU to round-off in
``tests/test_suspension.py``).
The rails are known inputs ``u`` (taken at each sample, held by the FMU's hold in between);
a sample whose rails are missing is bridged by extrapolating the last rails with their rates.
A missing sensor (NaN, or masked out) is left out of the update: both observers update with
the rows present. The observers are designed for ``dt`` = the data's sample time (10 ms in the paper, §3).

Sensor noise levels
-------------------
Onat et al. (2016) give no sensor noise levels: its ``R = I`` (§4) is a filter tuning, and as a noise
level (1 m/s2, 1 rad/s) it would be orders of magnitude above the coach signals on ERRI
B176 low level at 20 m/s (accelerations of hundredths of m/s2, rates of milliradians per
second). We use the
"low cost inertial sensor" levels of Muñoz et al., §5.3 (this project's other inertial study):
:data:`SENSOR_NOISE_STD`, 0.01 m/s2 for every accelerometer and 5e-4 rad/s for every gyro
(white, per sample at 100 Hz).

Metrics: :func:`suspension_metrics`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from filterpy.kalman import KalmanFilter

from railfmu.models.vehicle.coach_vertical import COACH_VERTICAL, SENSORS

from railfmu.estimators.core import kalman
from railfmu.estimators.core.discretize import foh
from railfmu.estimators.core.observer import Observer
from railfmu.estimators.core.settings import Settings, setting

#: rail inputs of the observers (bogie 1 = leading), then their rates
RAILS = ("z_l1", "z_r1", "z_l2", "z_r2")
RAIL_RATES = tuple("d" + r for r in RAILS)
STATES = tuple(s.name for s in COACH_VERTICAL.states)
_STATE_UNITS = tuple(s.unit for s in COACH_VERTICAL.states)
_SENSOR_UNITS = {"ddz_c": "m/s2", "dtheta_c": "rad/s", "dphi_c": "rad/s", "ddz_b1": "m/s2",
                 "dphi_b1": "rad/s", "ddz_b2": "m/s2", "dphi_b2": "rad/s"}

#: sensor noise standard deviation per channel (Muñoz et al., §5.3 levels; see the module docstring)
SENSOR_NOISE_STD: dict[str, float] = {s: (0.01 if s.startswith("dd") else 5e-4) for s in SENSORS}

#: Onat et al. (2016), eq. 10: 70 % of the weight on ddz_c and dphi_c (35 % each), the rest equally
ONAT2016_WEIGHTS: dict[str, float] = {s: (0.35 if s in ("ddz_c", "dphi_c") else 0.06) for s in SENSORS}

K1_INITIAL = 330e3  # N/m, Onat et al. (2016), §4: initial guess of k1


# -- design model ------------------------------------------------------------------------------

@functools.lru_cache(maxsize=8)
def _matrices(params: tuple[tuple[str, float], ...]) -> tuple[np.ndarray, ...]:
    p = dict(params)
    A0, B, C0, D = COACH_VERTICAL.linearize(p, {"k1": 0.0})
    A1 = COACH_VERTICAL.linearize(p, {"k1": 1.0})[0] - A0
    C1 = COACH_VERTICAL.linearize(p, {"k1": 1.0})[2] - C0
    inputs = [u.name for u in COACH_VERTICAL.inputs]
    outputs = [o.name for o in COACH_VERTICAL.outputs]
    cols = [inputs.index(n) for n in (*RAILS, *RAIL_RATES)]
    H0 = np.zeros((7, 14))
    H1 = np.zeros((7, 14))
    Du = np.zeros((7, 8))
    for r, s in enumerate(SENSORS):
        if s in outputs:
            j = outputs.index(s)
            H0[r], H1[r], Du[r] = C0[j], C1[j], D[j, cols]
        else:
            H0[r, STATES.index(s)] = 1.0
    return A0, A1, B[:, cols], H0, H1, Du


class DesignModel:
    """The 7-DOF coach as ``(A0 + k1 A1, [Bz Bd], H0 + k1 H1, Du)`` (module docstring), with
    the exact first-order-hold discretisation. ``params``: any CoachVertical parameter."""

    def __init__(self, params: dict[str, float] | None = None) -> None:
        known = COACH_VERTICAL.default_parameters()
        unknown = sorted(set(params or {}) - set(known))
        if unknown:
            raise ValueError(f"unknown CoachVertical parameter(s) {unknown}")
        self.params = {**known, **{k: float(v) for k, v in (params or {}).items()}}
        COACH_VERTICAL.check_parameters(self.params)
        self.A0, self.A1, self.B, self.H0, self.H1, self.Du = _matrices(tuple(sorted(self.params.items())))

    def H(self, k1: float) -> np.ndarray:
        return self.H0 + k1 * self.H1

    def discretize(self, k1: float, dt: float, column: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(F, G, g)``: ``x_{k+1} = F x_k + G [w_k, dw_k]`` under the FMU's hold, and, if
        ``column`` (14,) is given, ``g = int_0^dt expm(A s) ds column`` (the response to
        ``column`` held over the step: a sensitivity, see the observers)."""
        # the rails ramp with their rates (B[:, :4] heights, B[:, 4:] rates); the column is held
        F, Gz, Gd, g = foh(self.A0 + k1 * self.A1, self.B[:, :4], dt, B_rate=self.B[:, 4:], B_zoh=column)
        return F, np.hstack([Gz, Gd]), (None if column is None else g[:, 0])


def _per_channel(raw: Any, default: dict[str, float], what: str) -> tuple[float, ...]:
    """7 values in the order of SENSORS from a number (every channel), a mapping channel ->
    value (the others: ``default``) or a sequence of 7."""
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        return (float(raw),) * 7
    if isinstance(raw, dict):
        unknown = sorted(set(raw) - set(SENSORS))
        if unknown:
            raise ValueError(f"has unknown channel(s) {unknown}")
        return tuple(float(raw.get(c, default[c])) for c in SENSORS)
    out = np.asarray(raw, dtype=float)
    if out.shape != (7,):
        raise ValueError(f"must be 7 {what} (order {SENSORS})")
    return tuple(out.tolist())


def _sigmas(raw: Any) -> tuple[float, ...]:
    """``sigma``: per-channel standard deviations (> 0; a number, mapping or 7 values)."""
    out = _per_channel(raw, SENSOR_NOISE_STD, "positive standard deviations")
    if not all(math.isfinite(v) and v > 0 for v in out):
        raise ValueError(f"must be 7 positive standard deviations (order {SENSORS})")
    return out


def _weights(raw: Any) -> tuple[float, ...]:
    """``weights``: per-channel weights gamma (>= 0, not all 0; normalised by the observer)."""
    out = _per_channel(raw, ONAT2016_WEIGHTS, "non-negative weights")
    if not (all(math.isfinite(v) and v >= 0 for v in out) and sum(out) > 0):
        raise ValueError("must be 7 non-negative numbers, not all 0")
    return out


@dataclass(frozen=True)
class CoachSettings(Settings):
    """What both observers take beside the CoachVertical parameters (their design model's)."""

    k1_initial: float = setting(K1_INITIAL, "N/m", "initial guess of k1 (Onat et al. (2016), §4)", gt=0)
    sigma: Any = setting(tuple(SENSOR_NOISE_STD[c] for c in SENSORS), "sensor units",
                         "noise std per channel: a number, a mapping channel -> std, or 7 values", convert=_sigmas)
    theta_min: float = setting(0.05, "", "lower bound of theta = k1 / k1_initial (the model stays stable)", gt=0)


@dataclass(frozen=True)
class WLSSettings(CoachSettings):
    """:class:`SuspensionWLS`: the paper's filter tuning and the WLS update's."""

    beta: float = setting(0.3, "", "relaxation of the Gauss-Newton step of theta", gt=0)
    window: int = setting(100, "samples", "samples per update of theta", ge=1)
    weights: Any = setting(tuple(ONAT2016_WEIGHTS[c] for c in SENSORS), "",
                           "gamma per channel (a mapping or 7 values; normalised to sum 1)", convert=_weights)
    p0: float = setting(0.01, "state units^2", "P0 = p0 I (the paper's)", gt=0)
    q: float = setting(0.001, "state units^2", "Q = q I (the paper's)", ge=0)
    r: float = setting(1.0, "sensor units^2", "R = r I (the paper's)", gt=0)
    residual: str = setting("gradient", "", "the WLS step: least-squares 'gradient' or the paper's 'literal' sum",
                            choices=("gradient", "literal"))


@dataclass(frozen=True)
class JointSettings(CoachSettings):
    """:class:`SuspensionJoint`: noise intensities and initial standard deviations."""

    q_theta: float = setting(1e-4, "1/s", "random-walk intensity of theta", ge=0)
    q_acc: float = setting(1e-8, "m^2/s^3, rad^2/s^3", "white-noise intensity on the velocities", ge=0)
    p0_theta: float = setting(0.3, "", "initial std of theta", gt=0)
    p0_pos: float = setting(1e-3, "m, rad", "initial std of the positions", gt=0)
    p0_vel: float = setting(1e-2, "m/s, rad/s", "initial std of the velocities", gt=0)
    rail_sigma: float = setting(0.0, "m", "std of the error of the rail heights taken as known (0: exact, the "
                                "paper's known track; a recording: its error)", ge=0)
    rail_rate_sigma: float = setting(0.0, "m/s", "std of the error of the rail rates taken as known", ge=0)
    lag_max: float = setting(0.0, "s", "largest time shift between the rails taken as known and the vehicle "
                             "(a recording's position offset / speed) searched for; 0: none", ge=0)
    lag_window: float = setting(10.0, "s", "span at the start over which the shift is estimated", gt=0)
    change_ratio: float = setting(0.0, "", "a change of k1 is declared when the mean normalised innovation "
                                  "over change_window exceeds this times its running level; 0: never", ge=0)
    change_window: float = setting(0.5, "s", "span of the innovation mean of the change test", gt=0)
    change_holdoff: float = setting(3.0, "s", "no new change declared within this after one", ge=0)
    change_theta_std: float = setting(0.3, "", "std of theta set when a change is declared", gt=0)


class _CoachObserver(Observer):
    """Bookkeeping shared by both: measurements (the 7 sensors), known inputs (rails + rates,
    held as ``self._u``)."""

    measurements: ClassVar[tuple[str, ...]] = SENSORS
    inputs: ClassVar[tuple[str, ...]] = (*RAILS, *RAIL_RATES)
    Config: ClassVar[type[CoachSettings]] = CoachSettings

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        model = COACH_VERTICAL.default_parameters()
        self.config = self.Config.from_mapping(settings, type(self).__name__, extra=model)
        self.model = DesignModel({k: v for k, v in settings.items() if k in model})
        self.k1_initial = self.config.k1_initial
        self.sigma = np.array(self.config.sigma)

    def _hold_rails(self) -> None:
        """After a prediction: extrapolate the rails with their rates (the FMU's hold) for
        the case that the next sample's rails are missing."""
        self._u[:4] += self._u[4:] * self.dt


# -- metrics ------------------------------------------------------------------------------------

def suspension_metrics(t, k1_est, k1_true, fault_time: float | None = None,
                       converge_tol: float = 0.02, detect_tol: float = 0.05) -> dict:
    """Scores of a k1 estimate against the truth (both N/m, sampled at ``t``, s).

    * ``k1_true_final``, ``k1_est_final`` (N/m), ``rel_error_final`` = |est - true| / true
      at the last sample;
    * ``convergence_time_s``: the first sample time after which the relative error stays
      within ``converge_tol`` (2 %) to the end; None if the last sample is outside;
    * with ``fault_time``: ``detection_delay_s``, the time from the fault until the estimate
      enters and stays within ``detect_tol`` (5 %) of the (new) true value; None if it never
      does. A non-finite estimate counts as outside.
    """
    t = np.asarray(t, dtype=float)
    est = np.asarray(k1_est, dtype=float)
    true = np.asarray(k1_true, dtype=float)
    if not (t.shape == est.shape == true.shape and t.ndim == 1 and t.size):
        raise ValueError("suspension_metrics: t, k1_est and k1_true need the same non-empty 1-D shape")
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.abs(est - true) / np.abs(true)
    ok = np.isfinite(rel)

    def settle(mask: np.ndarray, tol: float) -> float | None:
        inside = ok & (rel <= tol)
        bad = np.flatnonzero(mask & ~inside)
        if bad.size == 0:
            first = np.flatnonzero(mask)
            return float(t[first[0]]) if first.size else None
        return float(t[bad[-1] + 1]) if bad[-1] + 1 < t.size else None

    out = {"k1_true_final": float(true[-1]), "k1_est_final": float(est[-1]),
           "rel_error_final": float(rel[-1]) if ok[-1] else None,
           "convergence_time_s": settle(np.ones(t.size, bool), converge_tol)}
    if fault_time is not None:
        t_in = settle(t >= fault_time - 1e-9, detect_tol)
        out["detection_delay_s"] = None if t_in is None else max(0.0, t_in - float(fault_time))
    return out


# -- (a) the paper's scheme -----------------------------------------------------------------

class SuspensionWLS(_CoachObserver):
    r"""The scheme of Onat et al. (2016): a linear Kalman filter on the 7-DOF model at the current
    ``theta = k1`` (eqs. 7-9) and the weighted-least-squares update ``theta_k = theta_{k-1} +
    beta J(theta)`` from the filter's residuals (eqs. 10-11).

    Measurements: the 7 sensors of :data:`railfmu.models.vehicle.coach_vertical.SENSORS` (ddz_c m/s2,
    dtheta_c, dphi_c rad/s, ddz_b1 m/s2, dphi_b1 rad/s, ddz_b2 m/s2, dphi_b2 rad/s). Known
    inputs: the rail heights ``z_l1, z_r1, z_l2, z_r2`` (m) and their rates ``dz_*`` (m/s), the
    paper's known track input ``u``, ``u'``. Outputs: ``k1`` (N/m) and the 14 states (m, rad, m/s, rad/s).

    Kalman filter (eqs. 7-9), with ``F(theta), G(theta)`` the exact discretisation of the
    design model (module docstring) at the current estimate::

        x^-_k = F x^+_{k-1} + G u_{k-1},   P^-_k = F P^+ F^T + Q
        r_k   = y_k - (H(theta) x^-_k + Du u_k)                 (the residual y_meas - y_model)
        K     = P^- H^T (H P^- H^T + R)^-1,  x^+ = x^- + K r,  P^+ Joseph form (filterpy)

    The paper's tuning (§4), kept: ``P0 = 0.01 I``, ``Q = 0.001 I``, ``R = I`` (settings ``p0``,
    ``q``, ``r``; all in the state's / sensor's own units, as the paper gives them).

    Weighted least squares (eqs. 10-11), and how we read them. Taken literally, ``J`` is a
    weighted *sum of signed residuals*; but the residuals of a linear filter driven by a
    zero-mean track are zero-mean whatever the error in ``k1``, so that sum has no direction
    (``residual="literal"`` keeps this reading, ``theta += beta * mean(gamma . r / sigma)``:
    on noise-free data it stays near the initial guess; with the paper's ``beta`` = 1.5e6 on
    raw residuals it random-walks to a negative k1).
    A weighted least-squares estimate
    minimises ``sum_k sum_i gamma_i (r_ik / sigma_i)^2`` over ``theta``; linearised about the
    current ``theta`` the residual is ``r - s dtheta``, ``s = d y_model / d theta``, and the
    least-squares increment over a window is what we use (default ``residual="gradient"``)::

        J_m = sum_{k in window m} sum_i gamma_i (r_ik / sigma_i) (s_ik / sigma_i)
              / sum_{k in window m} sum_i gamma_i (s_ik / sigma_i)^2
        theta_m = theta_{m-1} + beta J_m           (theta = k1 / k1_initial, dimensionless)
        s_k = H(theta) w^-_k + k1_initial H1 x^-_k

    ``w = dx/dtheta`` follows the filter (a recursive prediction-error sensitivity, the gain
    held): ``w^-_{k+1} = F w^+_k + g_k`` with ``g_k`` the response to ``k1_initial A1 x^+_k``
    held over the step, and ``w^+ = w^- - K s``. Through ``w`` the roll-rate residual carries
    information about ``k1`` (it has no direct ``H1`` term), so the paper's weights act as it
    describes. ``beta`` relaxes the Gauss-Newton step (``beta = 1``: jump to the window's
    least-squares value).

    Tuning and why:

    * ``gamma`` (:data:`ONAT2016_WEIGHTS`): the paper's, 35 % each on ddz_c and dphi_c, 6 % on each
      of the other five. Residuals and sensitivities are divided by the sensor noise std
      ``sigma`` (:data:`SENSOR_NOISE_STD`): in raw units a weight on a roll rate (1e-3 rad/s)
      and one on an acceleration (0.1 m/s2) would not be comparable.
    * ``window`` n = 100 samples (1 s, about one period of the coach bounce and pitch modes,
      1.0 and 1.2 Hz): ``theta`` is updated once per window (``k`` of eq. 11 counts windows).
    * ``beta`` = 0.3: the paper's 1.5e6 belongs to its unstated residual scaling and cannot be
      transferred. On ERRI low-level track (the paper's tuning of the filter) it converges to
      430 kN/m and, after the fault, to 215 kN/m within seconds on noise-free data; with the
      sensor noise (:data:`SENSOR_NOISE_STD`) it settles somewhat low. 0.1 is slower and as
      biased; 0.5 is noisier. The convergence time, detection delay and final error are
      measured by ``railfmu study suspension_fault`` (docs/studies/suspension_fault.md).
    * The filter keeps the paper's tuning (faithful). It is what limits the scheme under noise:
      ``R = I`` is 1e4-1e6 times the sensor variance, so the residuals are barely filtered.
      With ``r = 1e-4, q = 1e-8`` (closer to the sensors) the same update ends much closer to
      the truth on noisy data, converging and detecting the fault as fast as the paper's
      tuning does on noise-free data.
    * ``theta`` is kept >= ``theta_min`` (0.05) so the model stays stable.

    Settings: :class:`WLSSettings` (``k1_initial`` N/m, ``beta``, ``window``, ``weights``,
    ``sigma``, ``p0``, ``q``, ``r``, ``residual``, ``theta_min``: units, defaults and checks
    there; as ``self.config``) and any CoachVertical parameter.
    """

    outputs: ClassVar[tuple[str, ...]] = ("k1", *STATES)
    units: ClassVar[dict[str, str]] = {**_SENSOR_UNITS, **{r: "m" for r in RAILS},
                                       **{r: "m/s" for r in RAIL_RATES}, "k1": "N/m",
                                       **dict(zip(STATES, _STATE_UNITS))}
    Config: ClassVar[type[CoachSettings]] = WLSSettings

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        c = self.config
        self.beta = c.beta
        self.window = c.window
        w = np.array(c.weights)
        self.gamma = w / w.sum()
        self.gradient = c.residual == "gradient"
        self.theta_min = c.theta_min
        self.P0 = np.eye(14) * c.p0
        self.Q = np.eye(14) * c.q
        self.R = np.eye(7) * c.r
        self.reset()

    def _reset(self) -> None:
        kf = KalmanFilter(dim_x=14, dim_z=7)
        kf.P = self.P0.copy()
        kf.Q = self.Q.copy()
        kf.R = self.R.copy()
        self._kf = kf
        self.theta = 1.0
        self._u = np.zeros(8)
        self._w = np.zeros(14)  # d x / d theta
        self._acc = 0.0
        self._info = 0.0
        self._n = 0
        self.updates = 0

    def _predict(self) -> None:
        kf, k1 = self._kf, self.theta * self.k1_initial
        x = kf.x[:, 0]
        col = self.k1_initial * (self.model.A1 @ x) if self.gradient else None
        F, G, g = self.model.discretize(k1, self.dt, col)
        kf.predict(u=self._u[:, None], B=G, F=F)
        if self.gradient:
            self._w = F @ self._w + g
        self._hold_rails()

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        kf, m = self._kf, self.model
        H = m.H(self.theta * self.k1_initial)
        x_prior = kf.x[:, 0].copy()
        rows = slice(None) if mask.all() else np.flatnonzero(mask)  # the sensors present
        # filterpy: Joseph form; z as a column (filterpy reshapes z only when H is not passed)
        if mask.all():
            kf.update((z - m.Du @ self._u)[:, None], H=H)
        else:
            kf.update((z[rows] - m.Du[rows] @ self._u)[:, None], R=self.R[np.ix_(rows, rows)], H=H[rows])
        r = kf.y[:, 0]
        sigma, gamma = self.sigma[rows], self.gamma[rows]
        rn = r / sigma
        if self.gradient:
            dHx = self.k1_initial * (m.H1 @ x_prior)
            sens = (H @ self._w + dHx)[rows]
            sn = sens / sigma
            self._acc += float(gamma @ (rn * sn))
            self._info += float(gamma @ (sn * sn))
            self._w = self._w - kf.K @ sens
        else:
            self._acc += float(gamma @ rn)
        self._n += 1
        if self._n == self.window:
            if self.gradient:  # Gauss-Newton: the window's weighted least-squares increment
                J = self._acc / self._info if self._info > 0 else 0.0
            else:  # literal eq. 10: the mean weighted residual
                J = self._acc / self._n
            self.theta = max(self.theta + self.beta * J, self.theta_min)
            self._acc, self._info, self._n = 0.0, 0.0, 0
            self.updates += 1

    def _estimate(self) -> np.ndarray:
        return np.concatenate(([self.theta * self.k1_initial], self._kf.x[:, 0]))

    def finish(self) -> dict:
        return {**super().finish(), "k1": self.theta * self.k1_initial, "wls_updates": self.updates,
                "beta": self.beta, "window": self.window,
                "residual": "gradient" if self.gradient else "literal"}


# -- (b) joint estimation ---------------------------------------------------------------------

class SuspensionJoint(_CoachObserver):
    r"""Joint state and stiffness estimation: an extended Kalman filter on the 7-DOF model
    augmented with ``theta = k1 / k1_initial`` as a random walk.

    Measurements and known inputs: as :class:`SuspensionWLS` (7 sensors; rails ``z_*`` m,
    rates ``dz_*`` m/s).
    Outputs: ``k1`` (N/m), ``k1_std`` (N/m, the filter's 1-sigma) and the 14 states.

    Augmented design model (``x_a = [x, theta]``, 15 states)::

        dx/dt     = (A0 + theta k1_initial A1) x + Bz w + Bd dw + v_x
        dtheta/dt = v_theta                          (random walk: a stiffness that may change)
        y         = (H0 + theta k1_initial H1) x + Du [w, dw] + e,   e ~ N(0, diag(sigma^2))

    Prediction: the exact discretisation at the current ``theta`` (module docstring), so the
    predicted state is exact for a constant ``k1``; its Jacobian is ``[[F, g], [0, 1]]`` with
    ``g`` the response to ``k1_initial A1 x`` held over the step (from the same matrix
    exponential). Update: ``H_a = [H(theta), k1_initial H1 x^-]``, Joseph form, symmetric P
    (:func:`railfmu.estimators.core.kalman.update` with ``h(x^-)`` as the predicted measurement).
    Not filterpy's ``ExtendedKalmanFilter``: its prediction is ``F x + B u`` and would have to
    be overridden anyway, and its update deep-copies each row.

    Why it does better than the paper's scheme: ``theta`` gets the Kalman gain from its
    covariance with the states instead of a hand-tuned fixed step, so it is fast while
    uncertain (the start and a fault) and averages as evidence accumulates; every channel
    enters with its own noise level.

    Tuning and why:

    * ``R = diag(sigma^2)``: the sensor noise (:data:`SENSOR_NOISE_STD`); it is also used on
      noise-free data (it only slows the filter slightly there).
    * ``q_theta`` = 1e-4 1/s: random-walk intensity of ``theta`` (1 % per sqrt(s)). It sets
      the trade-off between tracking a fault and the noise on the estimate: a 50 % drop is
      tracked within seconds and the static estimate stays close to the truth with the sensor
      noise of :data:`SENSOR_NOISE_STD` (``railfmu study suspension_fault``,
      docs/studies/suspension_fault.md); a smaller ``q_theta`` lowers the jitter but lengthens
      the delay.
    * ``q_acc`` = 1e-8 m2/s3 (and rad2/s3) on the velocities: the design model is the
      simulated one, so only a small floor for numerical mismatch.
    * ``P0``: ``theta`` 0.3 (30 % of the initial guess: the paper starts 23 % low), the
      positions 1e-3 (m, rad), the velocities 1e-2 (m/s, rad/s); the state starts at rest.
    * ``theta`` is kept >= ``theta_min`` (0.05) so the model stays stable.

    Rails from a track recording (all off by default: the rails are exact, as in the paper):

    * ``rail_sigma`` (m), ``rail_rate_sigma`` (m/s): the error of the given rails. It drives the
      design model like process noise, ``Q += G diag(rail_sigma^2 I4, rail_rate_sigma^2 I4) G^T``,
      and reaches the bogie accelerometers directly, ``R += Du (...) Du^T``.
    * ``lag_max`` (s): the recording's positions may be off (a position offset ``delta``; at
      speed ``V`` the rails arrive ``delta / V`` early or late). The filter then runs ``lag_max``
      (plus two samples) behind the data. Over the first ``lag_window`` s it buffers, simulates
      the design model at ``k1_initial`` from rest on the given rails and takes the shift that
      best aligns its bogie accelerations and roll rates with the measured ones (the
      cross-correlation's peak, refined by a parabola); from then on it feeds the filter the
      rails shifted back by it (heights by cubic Hermite with their rates, rates linearly).
      The shift is one number per run: a constant speed (a varying one would need the shift
      in position).
    * ``change_ratio`` > 0: a change test on the innovations (:meth:`_change_test`) sets theta's
      variance back up when they jump, so a fault is followed at start-up speed while a small
      ``q_theta`` keeps the estimate steady in between.

    Settings: :class:`JointSettings` (``k1_initial`` N/m, ``sigma``, ``q_theta`` 1/s, ``q_acc``,
    ``p0_theta``, ``p0_pos``, ``p0_vel``, ``theta_min``, ``rail_sigma`` m, ``rail_rate_sigma``
    m/s, ``lag_max`` s, ``lag_window`` s, ``change_ratio``, ``change_window`` s,
    ``change_holdoff`` s, ``change_theta_std``; as ``self.config``) and any CoachVertical
    parameter.
    """

    outputs: ClassVar[tuple[str, ...]] = ("k1", "k1_std", *STATES)
    units: ClassVar[dict[str, str]] = {**SuspensionWLS.units, "k1_std": "N/m"}
    Config: ClassVar[type[CoachSettings]] = JointSettings

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        c = self.config
        self.R = np.diag(self.sigma ** 2)
        self.Q = np.zeros((15, 15))
        # white noise on the velocities / theta, integrated over one step (first order)
        self.Q[7:14, 7:14] = np.eye(7) * c.q_acc * self.dt
        self.Q[14, 14] = c.q_theta * self.dt
        self.P0 = np.diag(np.square([c.p0_pos] * 7 + [c.p0_vel] * 7 + [c.p0_theta]))
        self.theta_min = c.theta_min
        self._I = np.eye(15)
        # an error in the rails taken as known enters like process and measurement noise
        self._Su = np.diag([c.rail_sigma ** 2] * 4 + [c.rail_rate_sigma ** 2] * 4)
        self._rails_uncertain = c.rail_sigma > 0 or c.rail_rate_sigma > 0
        if self._rails_uncertain:
            Du = self.model.Du
            self.R = self.R + Du @ self._Su @ Du.T
        self._lag_samples = int(math.ceil(c.lag_max / self.dt)) if c.lag_max > 0 else 0
        self._change_n = max(1, int(round(c.change_window / self.dt)))
        self.reset()

    def _reset(self) -> None:
        self._x = np.zeros(15)
        self._x[14] = 1.0
        self._P = self.P0.copy()
        self._u = np.zeros(8)
        self._buffer: list[tuple] = []  # (t, z, u, mask) while the shift is estimated and applied
        self._next = 0
        self.lag_s: float | None = None
        self._nis: list[float] = []  # normalised innovation squared per update (change test)
        self._nis_level: float | None = None
        self._since_change = 0
        self.changes = 0

    # -- a shift between the rails taken as known and the vehicle (lag_max > 0) --------------
    def step(self, t: float, z: np.ndarray, u: np.ndarray | None = None,
             mask: np.ndarray | None = None) -> np.ndarray:
        """As :meth:`Observer.step`; with ``lag_max`` > 0 the filter runs ``lag_max`` (plus two
        samples) behind the data: the rails at the vehicle at ``t`` are the given rails at
        ``t - lag`` (``lag``: estimated over the first ``lag_window``), which may lie ahead."""
        if not self._lag_samples:
            return super().step(t, z, u, mask)
        self._buffer.append((float(t), np.array(z, dtype=float), np.array(u, dtype=float),
                             None if mask is None else np.array(mask, dtype=bool)))
        if self.lag_s is None:
            if self._buffer[-1][0] - self._buffer[0][0] < self.config.lag_window:
                return self._estimate()  # the initial estimate until the shift is known
            self.lag_s = self._estimate_lag()
        out = None
        while self._next + self._lag_samples + 2 <= len(self._buffer):
            tk, zk, _, mk = self._buffer[self._next]
            out = super().step(tk, zk, self._shifted_input(self._next), mk)
            self._next += 1
        return self._estimate() if out is None else out

    def _estimate_lag(self) -> float:
        """The shift ``lag`` (s) that best aligns the bogie sensors with the design model's
        response (at ``k1_initial``, from rest) to the given rails: the peak of their
        cross-correlation over ``+-lag_max``, refined by a parabola through its neighbours.
        The bogie signals come mostly through the primary suspension, so ``k1`` barely moves
        the peak."""
        U = np.array([b[2] for b in self._buffer])
        Z = np.array([b[1] for b in self._buffer])
        m = self.model
        F, G, _ = m.discretize(self.k1_initial, self.dt)
        H = m.H(self.k1_initial)
        x = np.zeros(14)
        Yh = np.empty_like(Z)
        for k in range(U.shape[0]):
            uk = np.nan_to_num(U[k])
            Yh[k] = H @ x + m.Du @ uk
            x = F @ x + G @ uk
        rows = [SENSORS.index(c) for c in ("ddz_b1", "dphi_b1", "ddz_b2", "dphi_b2")]
        y = np.nan_to_num(Z[:, rows] / self.sigma[rows])
        yh = Yh[:, rows] / self.sigma[rows]
        L, n = self._lag_samples, y.shape[0]
        start = min(n - 1, L + int(round(1.0 / self.dt)))  # the model's start from rest: 1 s
        lags = np.arange(-L, L + 1)
        c = np.array([float(np.sum(y[start:n - L] * yh[start - j:n - L - j])) for j in lags])
        i = int(np.argmax(c))
        frac = 0.0
        if 0 < i < lags.size - 1:
            den = c[i - 1] - 2.0 * c[i] + c[i + 1]
            frac = 0.5 * (c[i - 1] - c[i + 1]) / den if den < 0 else 0.0
        return float((lags[i] + frac) * self.dt)

    def _shifted_input(self, k: int) -> np.ndarray:
        """The rails at sample ``k`` shifted by ``lag``: heights by cubic Hermite with their
        rates, rates linearly, between the two given samples around ``t_k - lag``."""
        p = k - self.lag_s / self.dt
        i0 = int(math.floor(p))
        a = p - i0
        last = len(self._buffer) - 1
        u0 = self._buffer[min(max(i0, 0), last)][2]
        u1 = self._buffer[min(max(i0 + 1, 0), last)][2]
        h = self.dt
        h00, h10 = 2 * a**3 - 3 * a**2 + 1, a**3 - 2 * a**2 + a
        h01, h11 = -2 * a**3 + 3 * a**2, a**3 - a**2
        out = np.empty(8)
        out[:4] = h00 * u0[:4] + h10 * h * u0[4:] + h01 * u1[:4] + h11 * h * u1[4:]
        out[4:] = (1 - a) * u0[4:] + a * u1[4:]
        return out

    def _predict(self) -> None:
        x, m = self._x, self.model
        ks = self.k1_initial
        F, G, g = m.discretize(x[14] * ks, self.dt, ks * (m.A1 @ x[:14]))
        Fa = self._I.copy()
        Fa[:14, :14] = F
        Fa[:14, 14] = g
        x[:14] = F @ x[:14] + G @ self._u
        Q = self.Q
        if self._rails_uncertain:
            Q = Q.copy()
            Q[:14, :14] += G @ self._Su @ G.T
        self._P = kalman.predict_covariance(self._P, Fa, Q)
        self._hold_rails()

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        x, m = self._x, self.model
        ks = self.k1_initial
        H = m.H(x[14] * ks)
        Ha = np.empty((7, 15))
        Ha[:, :14] = H
        Ha[:, 14] = ks * (m.H1 @ x[:14])
        up = kalman.update(x, self._P, z, Ha, self.R, z_pred=H @ x[:14] + m.Du @ self._u, mask=mask)
        self._x, self._P = up.x, up.P
        self._x[14] = max(self._x[14], self.theta_min)
        if self.config.change_ratio > 0 and up.nu.size:
            self._change_test(float(up.nu @ np.linalg.solve(up.S, up.nu)) / up.nu.size)

    def _change_test(self, nis: float) -> None:
        """A step in k1 makes the innovations grow: when their normalised mean over the last
        ``change_window`` exceeds ``change_ratio`` times their running level (an exponential
        mean over ~20 s), the covariance is set back to the start's ``P0`` with theta's std
        ``change_theta_std``, so the filter re-learns k1 at its start-up speed; ``q_theta`` can
        then stay small (less jitter)."""
        c = self.config
        self._nis.append(nis)
        self._since_change += 1
        n = self._change_n
        if len(self._nis) < 2 * n:
            return
        recent = float(np.mean(self._nis[-n:]))
        old = self._nis[-n - 1]
        a = self.dt / 20.0
        self._nis_level = old if self._nis_level is None else (1 - a) * self._nis_level + a * old
        if (recent > c.change_ratio * self._nis_level
                and self._since_change * self.dt > c.change_holdoff):
            # as at the start: the states' variances too, so the jump in the innovations is
            # shared between the states and theta (theta alone would overshoot)
            self._P = self.P0.copy()
            self._P[14, 14] = c.change_theta_std ** 2
            self._since_change = 0
            self.changes += 1

    def _estimate(self) -> np.ndarray:
        ks = self.k1_initial
        return np.concatenate(([self._x[14] * ks, math.sqrt(max(self._P[14, 14], 0.0)) * ks], self._x[:14]))

    def finish(self) -> dict:
        est = self._estimate()
        out = {**super().finish(), "k1": float(est[0]), "k1_std": float(est[1]),
               "q_theta": self.config.q_theta}
        if self._lag_samples:
            out["lag_s"] = self.lag_s
        if self.config.change_ratio > 0:
            out["changes"] = self.changes
        return out
