r"""Running resistance of a train from GNSS position and speed: the Unscented Kalman filter of
Cunillera et al. (2022) §3.1 (``PaperUKF``), with its process model as a replaceable part,
and ``ImprovedEstimator``, which fits the Davis coefficients to the coasting segments of a run
(its own docstring).

Design model (mass-specific, SI; state ``x = (s, v, r0, r1, r2)``, the Davis coefficients
constant: ``Q = 0`` as the paper)::

    a(x, u, s)  = u - r0 - r1 v - r2 v^2 - g(s)                         (eq. 5)
    f(x, u)     = x + (dt v + dt^2 a / 2, dt a, 0, 0, 0)                (eq. 4, "discrete")
    z           = (s, v) + w,   R = diag(sigma_s^2, sigma_v^2)          (eq. 6)

``g(s) = g0 (i(s) / 1000 + w_c(s)) / gamma`` is the line term of the line profile
(``models/track/line_profile.py``; the paper takes the track description as exact). The effort
``u`` is not measured: as the paper, it is the effort "needed to match the observed
acceleration" by eq. 1 with the last estimates. Over the interval ``[t_{k-1}, t_k]`` that
ends at a fix::

    a_obs = (v_meas[k] - v_meas[k-1]) / (t_k - t_{k-1})
    u     = a_obs + r0^ + r1^ v^ + r2^ v^2 + g(s^)       (posterior at k-1)

so the prediction to ``t_k`` can only be made when the fix at ``t_k`` has arrived (as in the
paper's offline processing; online this is a delay of one GNSS period). Without a new speed
fix the last effort is held.

Process models (setting ``process``): ``"discrete"`` is eq. 4; ``"ode"`` integrates eq. 1
with the effort held over ``dt`` by classical RK4 in sub-steps of ``integrator_step`` (the
``TrainLongitudinal`` FMU's equations with its ``use_effort_set`` input: at ``v <= 0`` the
train does not roll back, ``dv/dt = max(u - r0 - g, 0)``). A callable
``process(X, u, t, dt) -> Y`` on the sigma points ``X`` (rows ``(s, v, r0, r1, r2)``) can
replace both: that is how an experiment makes a vehicle FMU the process model (``ukf_fmu``).

Numerics. The paper's settings (α = 1e-3, β = 2, κ = −2, Table 1's initial sigmas from 1 m to
1e-9 N/(kg (m/s)^2)) give a centre weight of −1.7e6 and a covariance whose diagonal spans 18
orders of magnitude. Two measures keep it sound:

1. the centre-referenced unscented transform of :mod:`railfmu.estimators.core.ukf` (the weights multiply
   deviations from the centre point, never the state itself; PSD by construction);
2. the filter runs in **scaled coordinates** ``x~ = D^-1 x``, ``D = diag(Table 1 sigmas)``, so
   that ``P~_0 = I``: the unscented transform is exact under a linear change of coordinates
   (the sigma points of ``D P D`` are ``D`` times those of ``P``), so the estimates are the
   textbook filter's, and round-off acts on variances of order 1 instead of on a matrix
   whose entries span 1e-18 to 16.
Checked on a 32 km run of the shipped line (``tests/test_running_resistance.py`` asserts the
bounds): at α = 0.5, where every form is well conditioned, this filter equals filterpy's
``UnscentedKalmanFilter`` to round-off; at the paper's settings filterpy's textbook sums drift
from it by a small fraction of a standard deviation, the centre-referenced form in SI
coordinates by less. The covariance is symmetrised; where a clamping process model makes it
singular (a stopped train) its eigenvalues are floored and the repair is counted
(``covariance_repairs``).
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from railfmu.models.track.line_profile import DEFAULT_LINE, G0, LineProfile
from railfmu.models.train.longitudinal import GAMMA, R0, R1, R2

from railfmu.estimators.core import kalman, ukf
from railfmu.estimators.core.observer import Observer
from railfmu.estimators.core.settings import Settings, setting

KMH = 1.0 / 3.6
#: Table 1 of Cunillera et al. (2022): initial standard deviations of (s, v, r0, r1, r2), SI
PAPER_SIGMAS = (1.0, 0.0018 * KMH, 1e-6, 1e-8, 1e-9)
#: Table 1: van der Merwe's scaled sigma points
PAPER_ALPHA, PAPER_BETA, PAPER_KAPPA = 1e-3, 2.0, -2.0
#: §4.2: measurement standard deviations, 4 m and 1 km/h
PAPER_SIGMA_S, PAPER_SIGMA_V = 4.0, 1.0 * KMH

Process = Callable[[np.ndarray, float, float, float], np.ndarray]


class LineTerm:
    """``g(s)`` (N/kg) of a line profile for arrays of positions: the FMU's look-up."""

    def __init__(self, line: LineProfile | str | Path | None = None, gamma: float = GAMMA):
        self.line = line if isinstance(line, LineProfile) else LineProfile.read(line or DEFAULT_LINE)
        self.values = G0 * (self.line.gradient / 1000.0 + self.line.curve) / gamma
        self._cumulative = np.r_[0.0, np.cumsum(self.values[:-1] * np.diff(self.line.position))]
        self._rows = (self.line.position.tolist(), self.values.tolist(), self._cumulative.tolist())

    def __call__(self, s: np.ndarray) -> np.ndarray:
        k = np.searchsorted(self.line.position, s, side="right") - 1
        return self.values[np.clip(k, 0, len(self.values) - 1)]

    def integral(self, s: float) -> float:
        """``G(s)``, the integral of ``g`` from the first row's position to ``s`` (N m/kg; the
        first and last rows' values hold beyond the ends): exact for the piecewise-constant
        profile, so ``(G(s1) - G(s0)) / (s1 - s0)`` is the mean line term over a distance."""
        position, values, cumulative = self._rows
        k = min(max(bisect.bisect_right(position, s) - 1, 0), len(values) - 1)
        return cumulative[k] + values[k] * (s - position[k])

    def at(self, s: float) -> float:
        """``g(s)`` at one position (a scalar: no array round trip)."""
        position, values, _ = self._rows
        return values[min(max(bisect.bisect_right(position, s) - 1, 0), len(values) - 1)]


def acceleration(X: np.ndarray, u: float, g: np.ndarray) -> np.ndarray:
    """Eq. 5 for the rows ``(s, v, r0, r1, r2)`` of ``X`` and the line term ``g`` at their s."""
    v = X[:, 1]
    return u - X[:, 2] - X[:, 3] * v - X[:, 4] * v * v - g


def discrete_process(line: LineTerm) -> Process:
    """Eq. 4 of Cunillera et al. (2022): constant acceleration over ``dt``."""
    def f(X: np.ndarray, u: float, t: float, dt: float) -> np.ndarray:
        a = acceleration(X, u, line(X[:, 0]))
        Y = X.copy()
        Y[:, 0] += dt * X[:, 1] + 0.5 * dt * dt * a
        Y[:, 1] += dt * a
        return Y
    return f


def ode_process(line: LineTerm, integrator_step: float = 0.05) -> Process:
    """Eq. 1 with the effort held over ``dt``, RK4 in ``ceil(dt / integrator_step)`` equal
    sub-steps, the speed set to 0 where a sub-step ends below it (the FMU's rule)."""
    def rates(s, v, R, u):
        g = line(s)
        moving = v > 0
        a = np.where(moving, u - (R[:, 0] + R[:, 1] * v + R[:, 2] * v * v) - g,
                     np.maximum(u - R[:, 0] - g, 0.0))
        return np.where(moving, v, 0.0), a

    def f(X: np.ndarray, u: float, t: float, dt: float) -> np.ndarray:
        q = dt / integrator_step - 1e-9
        n = max(int(np.ceil(q)) if q > 0 else 0, 1)
        h = dt / n
        s, v, R = X[:, 0].copy(), X[:, 1].copy(), X[:, 2:]
        for _ in range(n):
            k1 = rates(s, v, R, u)
            k2 = rates(s + 0.5 * h * k1[0], v + 0.5 * h * k1[1], R, u)
            k3 = rates(s + 0.5 * h * k2[0], v + 0.5 * h * k2[1], R, u)
            k4 = rates(s + h * k3[0], v + h * k3[1], R, u)
            s = s + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            v = v + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        Y = X.copy()
        Y[:, 0], Y[:, 1] = s, np.maximum(v, 0.0)
        return Y
    return f


def _line(raw: Any) -> Any:
    """``line_file``: a path or a LineProfile; '' (an SSD's empty value) is the shipped line."""
    return raw or None


@dataclass(frozen=True)
class ResistanceSettings(Settings):
    """What both estimators take: the starting Davis coefficients and the line term."""

    r0_init: float = setting(R0, "N/kg", "Davis r0 to start from (the published value)")
    r1_init: float = setting(R1, "N.s/(m.kg)", "Davis r1 to start from")
    r2_init: float = setting(R2, "N.s2/(m2.kg)", "Davis r2 to start from")
    line_file: Any = setting(None, "", "line profile CSV (gradient, curvature) or a LineProfile; None or '': "
                             "the shipped line", convert=_line)
    rotating_mass_factor: float = setting(GAMMA, "", "gamma, effective over static mass", gt=0)
    regime_recogniser: str | None = setting(None, "", "how a study reads its regimes ('paper', 'hmm'; the "
                                            "study checks it); default the class attribute")


@dataclass(frozen=True)
class PaperUKFSettings(ResistanceSettings):
    """:class:`PaperUKF`: Table 1 of Cunillera et al. (2022)."""

    sigma_s0: float = setting(PAPER_SIGMAS[0], "m", "initial std of s; also its scaling D", gt=0)
    sigma_v0: float = setting(PAPER_SIGMAS[1], "m/s", "initial std of v", gt=0)
    sigma_r0_0: float = setting(PAPER_SIGMAS[2], "N/kg", "initial std of r0", gt=0)
    sigma_r1_0: float = setting(PAPER_SIGMAS[3], "N.s/(m.kg)", "initial std of r1", gt=0)
    sigma_r2_0: float = setting(PAPER_SIGMAS[4], "N.s2/(m2.kg)", "initial std of r2", gt=0)
    sigma_position: float = setting(PAPER_SIGMA_S, "m", "GNSS position std", gt=0)
    sigma_speed: float = setting(PAPER_SIGMA_V, "m/s", "GNSS speed std (1 km/h)", gt=0)
    alpha: float = setting(PAPER_ALPHA, "", "Merwe sigma-point spread")
    beta: float = setting(PAPER_BETA, "", "Merwe prior-distribution weight (2: Gaussian)")
    kappa: float = setting(PAPER_KAPPA, "", "Merwe secondary scaling")
    integrator_step: float = setting(0.05, "s", "RK4 step of process='ode'", gt=0)


class PaperUKF(Observer):
    """The running-resistance UKF of Cunillera et al. (2022) §3.1 as written (module docstring).

    Measurements: ``position`` (m) and ``speed`` (m/s) of a GNSS fix (event-driven: a fix is
    there where its valid flag is set). No known inputs: the effort is computed from the
    measured acceleration. Outputs (SI): ``s``, ``v``, ``r0``, ``r1``, ``r2``, the
    ``acceleration`` of eq. 5 and the mass-specific ``effort`` ``u`` used over the last interval.

    Settings (defaults: the paper's): ``r0_init``, ``r1_init``, ``r2_init`` (the vehicle's
    published Davis coefficients, as the paper starts from the manufacturer's values),
    ``sigma_s0``..``sigma_r2_0`` (Table 1), ``sigma_position`` (4 m), ``sigma_speed``
    (1 km/h, in m/s), ``alpha``, ``beta``, ``kappa`` (Table 1), ``line_file`` (the line
    profile; default the shipped line), ``rotating_mass_factor`` (1.06), ``process``
    (``"discrete"``, eq. 4, or ``"ode"``; or a callable, see the module docstring),
    ``integrator_step`` (s, for ``"ode"``); units and checks in :class:`PaperUKFSettings`
    (``self.config``).
    """

    measurements: ClassVar[tuple[str, ...]] = ("position", "speed")
    outputs: ClassVar[tuple[str, ...]] = ("s", "v", "r0", "r1", "r2", "acceleration", "effort")
    units: ClassVar[dict[str, str]] = {"position": "m", "speed": "m/s", "s": "m", "v": "m/s", "r0": "N/kg",
                                       "r1": "N.s/(m.kg)", "r2": "N.s2/(m2.kg)", "acceleration": "m/s2",
                                       "effort": "N/kg"}
    event_driven: ClassVar[bool] = True

    def __init__(self, dt: float, process: str | Process = "discrete", **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.config = c = PaperUKFSettings.from_mapping(settings, type(self).__name__)
        self.line = LineTerm(c.line_file, c.rotating_mass_factor)
        if callable(process):
            self.process = process
        elif process == "discrete":
            self.process = discrete_process(self.line)
        elif process == "ode":
            self.process = ode_process(self.line, c.integrator_step)
        else:
            raise ValueError(f"process must be 'discrete', 'ode' or a callable, not {process!r}")
        self.x_init = np.array([0.0, 0.0, c.r0_init, c.r1_init, c.r2_init])
        self.D = np.array([c.sigma_s0, c.sigma_v0, c.sigma_r0_0, c.sigma_r1_0, c.sigma_r2_0])
        sr = np.array([c.sigma_position, c.sigma_speed])
        # R in scaled measurement units: z~ = z / D[:2]
        self.R = np.diag((sr / self.D[:2]) ** 2)
        self.points = ukf.MerweScaledSigmaPoints(5, alpha=c.alpha, beta=c.beta, kappa=c.kappa)
        self.Q = np.zeros((5, 5))

    # scaled process and measurement models
    def _f(self, X: np.ndarray) -> np.ndarray:
        return self.process(X * self.D, self.u, self._t_pred, self._dt_pred) / self.D

    @staticmethod
    def _h(x: np.ndarray) -> np.ndarray:
        return x[:2]

    def _reset(self) -> None:
        self.x = self.x_init / self.D  # s, v set from the first fix
        self.P = np.eye(5)
        self.u = 0.0
        self.a = 0.0
        self._pending = 0
        self._v_meas: float | None = None
        self._t_meas: float | None = None
        self._t_post = self._t0
        self._started = False
        self.repairs = 0
        self.first_repair: float | None = None

    def _predict(self) -> None:
        self._pending += 1  # made once the next fix gives the effort (module docstring)

    def _flush(self, u: float) -> None:
        """The pending predictions, over ``_pending`` periods with effort ``u``."""
        self.u = u
        for _ in range(self._pending):
            self._t_pred, self._dt_pred = self._t_post, self.dt
            X = self.points.sigma_points(self.x, self.P)
            self.x, self.P = ukf.unscented_transform(self._f(X), self.points, self.Q)
            self._t_post += self.dt
            self._ensure_positive_definite(self._t_post)
        self._pending = 0

    def _effort(self, v_meas: float, t: float) -> float:
        """The effort matching the measured acceleration since the last speed fix (eq. 1)."""
        if self._v_meas is None or t <= self._t_meas:
            return self.u
        a_obs = (v_meas - self._v_meas) / (t - self._t_meas)
        x = self.x * self.D
        s, v = x[0], x[1]
        return float(a_obs + x[2] + x[3] * v + x[4] * v * v + self.line(np.array([s]))[0])

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        t = self._t
        if not self._started:
            # the first fix is the initial state (Table 1's sigmas are about it), not an update
            self.x[:2] = np.where(mask, z / self.D[:2], self.x[:2])
            self._started = bool(mask.all())
            if mask[1]:
                self._v_meas, self._t_meas = float(z[1]), t
            return
        if mask[1]:
            self._flush(self._effort(float(z[1]), t))
        else:
            self._flush(self.u)
        if mask[1]:
            self._v_meas, self._t_meas = float(z[1]), t
        xs = self.x * self.D
        self.a = float(acceleration(xs[None, :], self.u, self.line(xs[:1]))[0])
        up = ukf.update(self.x, self.P, z / self.D[:2], self._h, self.R, self.points, mask)
        self.x, self.P = up.x, up.P
        self._ensure_positive_definite(t)

    def _ensure_positive_definite(self, t: float) -> None:
        """Sigma points need a Cholesky factor. A process model that clamps the speed at 0 (the
        FMU's and the ODE's: a braked train does not roll back) maps every sigma point of a
        stopped train to v = 0, and the predicted covariance is then singular. Its eigenvalues are
        floored at 1e-12 of the largest (in the scaled coordinates, where they start at 1): the
        speed of a stopped train is known to 1e-6 of its initial sigma. Counted in
        :meth:`finish` (``covariance_repairs``, ``first_repair_s``), never silent."""
        try:
            np.linalg.cholesky(self.P)
            return
        except np.linalg.LinAlgError:
            pass
        w, V = np.linalg.eigh(self.P)
        if not np.isfinite(w).all():
            raise FloatingPointError(f"{type(self).__name__}: the covariance is not finite at t = {t:g} s")
        w = np.maximum(w, 1e-12 * max(w.max(), 1e-300))
        self.P = (V * w) @ V.T
        self.P = 0.5 * (self.P + self.P.T)
        self.repairs += 1
        if self.first_repair is None:
            self.first_repair = t

    def _estimate(self) -> np.ndarray:
        if self._pending and self._started:
            self._flush(self.u)  # no fix at this sample: predict with the held effort
        x = self.x * self.D
        return np.array([*x, self.a, self.u])

    @property
    def covariance(self) -> np.ndarray:
        """The state covariance in SI units."""
        return self.P * np.outer(self.D, self.D)

    def finish(self) -> dict:
        return {**super().finish(), "alpha": self.points.alpha, "kappa": self.points.kappa,
                "centre_weight": float(self.points.Wc[0]), "covariance_repairs": self.repairs,
                "first_repair_s": self.first_repair}


# ---- the improved estimator: coasting segments, a prior, a kinematic filter ---------------------
#: the standard deviation of a speed reading rounded to 1 km/h (uniform error: q / sqrt(12)), m/s
ROUNDING_SIGMA_SPEED = KMH / np.sqrt(12.0)


@dataclass(frozen=True)
class ImprovedSettings(ResistanceSettings):
    """:class:`ImprovedEstimator` (its docstring says why each value)."""

    r0_init: float = setting(R0, "N/kg", "prior mean of r0 (the published value)", gt=0)
    r1_init: float = setting(R1, "N.s/(m.kg)", "prior mean of r1", gt=0)
    r2_init: float = setting(R2, "N.s2/(m2.kg)", "prior mean of r2", gt=0)
    prior_rel_sigma: float = setting(0.1, "", "prior std as a fraction of each prior mean", gt=0)
    sigma_speed: float = setting(float(ROUNDING_SIGMA_SPEED), "m/s", "speed std (1 km/h rounding / sqrt(12))",
                                 gt=0)
    sigma_position: float = setting(PAPER_SIGMA_S, "m", "position std", gt=0)
    jerk_noise: float = setting(1e-2, "m^2/s^5", "white-jerk intensity of the kinematic filter", gt=0)
    effort_band: float = setting(0.04, "N/kg", "|effort| below which a window counts as coasting", gt=0)
    recognition_window: float = setting(10.0, "s", "span of the fixes a coasting test looks back over", gt=0)
    min_coast: float = setting(30.0, "s", "shortest coasting segment fitted", ge=0)
    min_speed: float = setting(5.0 * KMH, "m/s", "slowest interval fitted", ge=0)
    test_sigmas: float = setting(4.0, "", "prior predictive test of a segment, in standard deviations", gt=0)
    r_random_walk: float = setting(0.0, "1/sqrt(s)", "relative random walk of the coefficients", ge=0)


def coasting_information(t: np.ndarray, v: np.ndarray, g_mean: np.ndarray, sigma_speed: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    r"""The information ``(A, b)`` on ``theta = (r0, r1, r2)`` of one coasting segment's speed
    record (:class:`ImprovedEstimator`, eqs. C1-C3): fixes ``t, v`` (n + 1 of them) and the
    mean line term ``g_mean`` over each of the n intervals. The segment's initial speed is
    eliminated (the regression is centred over the segment's fixes), so that
    ``theta = A^-1 b`` is its least-squares fit and ``A^-1`` its covariance."""
    dt = np.diff(t)
    vb = 0.5 * (v[1:] + v[:-1])
    X = np.zeros((v.size, 3))
    X[1:] = -np.cumsum(dt[:, None] * np.c_[np.ones_like(vb), vb, vb * vb], axis=0)
    y = v.copy()
    y[1:] += np.cumsum(dt * g_mean)
    X -= X.mean(axis=0)
    y -= y.mean()
    w = 1.0 / sigma_speed**2
    return w * X.T @ X, w * X.T @ y


class ImprovedEstimator(Observer):
    r"""Running resistance from the coasting segments of a run, with the published values as
    prior; position and speed by a kinematic Kalman filter (SSD name ``improved``).

    Why. The effort is not measured: in traction, cruising and braking any resistance fits
    the fixes with a matching effort, so those parts carry no information on ``r``
    (the paper's UKF computes the effort from the measured acceleration with its own
    estimates, which leaves ``r`` where it started). Where the effort is known, it does:
    coasting (effort 0). So the estimator (1) recognises coasting segments from the fixes,
    (2) fits the Davis coefficients to their speed records in closed form, weighed against
    the published values as a prior, and (3) tracks position and speed with a filter that
    needs no resistance at all.

    1. Recognition. With ``theta0`` the prior mean (the published coefficients), the
       effort of eq. 1 needed over a window of fixes ``a..b`` (``b`` each new fix, ``a`` the
       last fix at least ``recognition_window`` before it: one interval at 10 s fixes, ten
       at 1 s) is::

           u_w = (v_b - v_a) / T_w + sum_i (dt_i / T_w) (phi_i^T theta0 + g_i)      (C0)
           phi_i = (1, vb_i, vb_i^2),  vb_i = (v_(i-1) + v_i) / 2,  T_w = t_b - t_a

       with ``g_i`` the mean line term over the interval's distance (exact for the
       piecewise-constant profile). An interval is a coasting candidate if some window
       holding it has ``|u_w| <= effort_band`` and its speed is above ``min_speed``. A
       segment is a maximal run of candidates, trimmed by a recognition window at each end
       (a regime change may lie inside the window that let it in), kept if it lasts
       ``min_coast`` and passes a test against the prior predictive distribution of its mean
       effort (a speed hold at 40 km/h passes the band but not this: its speed does not fall
       as any plausible resistance would make it)::

           |u_seg| <= test_sigmas sqrt(2 sigma_v^2 / T^2 + sum_j (rho theta0_j phibar_j)^2)

       (``phibar`` the mean regressor over the segment, ``rho`` = ``prior_rel_sigma``).
       Recognition uses the prior only, never the estimate, so an error cannot reinforce
       itself.
    2. Regression. In a coasting segment, eq. 1 with zero effort over interval i
       (the trapezoid rule; the speed is nearly linear over 10 s)::

           v_i - v_(i-1) = -dt_i (phi_i^T theta + g_i)                              (C1)

       Summed from the segment's first fix, with each reading's own error ``e_j``
       (rounding: ``sigma_v = sigma_speed``, independent between fixes)::

           v_j + sum_(i<=j) dt_i g_i = c - Phi_j^T theta + e_j,                     (C2)
       Phi_j = sum_(i<=j) dt_i phi_i

       linear in the segment's initial speed ``c`` and ``theta``. Eliminating ``c``
       (centring over the segment: :func:`coasting_information` in batch; the estimator
       keeps the running sums of (C2)'s products from the segment's first fix, so a fix
       costs O(1)) gives its information ``A_seg = X~^T X~ / sigma_v^2``,
       ``b_seg = X~^T y~ / sigma_v^2``. The estimate is the
       posterior mean with the Gaussian prior ``N(theta0, diag(rho theta0)^2)``::

           theta^ = (Lambda0 + sum A_seg)^-1 (Lambda0 theta0 + sum b_seg),
           Lambda0 = diag(rho theta0)^-2                                             (C3)

       With ``r_random_walk = q > 0`` the coefficients may drift: before each segment the
       covariance grows by ``diag(q theta0)^2 (t - t_last)`` (a Kalman filter on theta with
       the segments as measurements). Online, a segment is closed a window or two after
       its end (when no later window can hold its intervals); until then it counts
       provisionally, so the estimate at the last fix is the batch estimate of the whole
       record. The fixes may be irregular (a missing fix lengthens an interval).
    3. Position and speed: a Kalman filter on ``(s, v, a)`` with white jerk of spectral
       density ``jerk_noise`` (``Q`` the integrated white-jerk model) and measurement noise
       ``sigma_position``, ``sigma_speed``; it needs no resistance and no effort. While the
       train coasts in an accepted (open) segment, the speed output at a fix is instead the
       segment's fit (C2) there, ``c^ - Phi_j^T theta^ - sum dt g`` with ``c^`` the least
       squares initial speed given ``theta^``: it averages every reading of the segment
       instead of following the 1 km/h rounding. The output ``acceleration`` is the mean
       acceleration of the interval that ends at the last fix, ``(v^_k - v^_{k-1}) /
       (t_k - t_{k-1})`` from the filter's speeds (what the regime recognition of §3.2 and
       the features read: the interval's regime; the state ``a^`` lags it and recognised the
       regimes clearly worse), in coasting ``-(r^(v^) + g)``; ``effort``
       = ``acceleration + r^(v^) + g(s^)`` (eq. 1 solved for the effort; 0 in coasting).

    Tuning (on simulated 32 km runs of the shipped line with 10 % per-run scatter of each
    Davis coefficient, seeds 1001-1040, not the study's): ``effort_band`` 0.04 N/kg (the
    paper's 0.025 cuts long coasts into pieces at 10 s rounding noise; slightly wider bands
    score the same), one window of trim, ``min_coast`` 30 s, ``test_sigmas`` 4 (its
    neighbours score the same), ``prior_rel_sigma`` 0.1 (insensitive within a factor of two),
    ``r_random_walk`` 0 (a random walk costs accuracy on constant resistance and did not
    help with a +30 % drift of r2: the coasting data come late in a run anyway),
    ``jerk_noise`` 1e-2 m^2/s^5 (a decade either side gives the same speed error; much
    smaller values lag the regime changes).

    Its accuracy beside the paper's UKF (``resistance_rel_error``, ``speed_rmse_kmh``) for
    10 s and 1 s fixes, 100 % load and r2 rising by 30 % over 1500 s, and its run time, are
    measured by ``railfmu study train_resistance`` (docs/studies/train_resistance.md). With
    a drifting r2 the estimate lags the truth at the end of the run: the coasting data lie
    minutes before the end.

    Settings (SI): ``r0_init``, ``r1_init``, ``r2_init`` (prior mean, N/kg, N/(kg m/s),
    N/(kg (m/s)^2); default the published values), ``prior_rel_sigma`` (-), ``sigma_speed``
    (m/s; default 1 km/h / sqrt(12), the rounding error of a 1 km/h reading),
    ``sigma_position`` (m, 4), ``jerk_noise`` (m^2/s^5), ``effort_band`` (N/kg),
    ``recognition_window`` (s), ``min_coast`` (s), ``min_speed`` (m/s), ``test_sigmas``
    (-), ``r_random_walk`` (1/sqrt(s)), ``line_file``, ``rotating_mass_factor``;
    ``regime_recogniser`` (how a study reads its regimes, ``"hmm"`` unless set: the class
    attribute of that name, :func:`railfmu.estimators.train.recognisers.recogniser`); units,
    defaults and checks in :class:`ImprovedSettings` (``self.config``).
    """

    measurements: ClassVar[tuple[str, ...]] = PaperUKF.measurements
    outputs: ClassVar[tuple[str, ...]] = PaperUKF.outputs
    units: ClassVar[dict[str, str]] = PaperUKF.units
    event_driven: ClassVar[bool] = True
    #: its outputs are read by the hidden Markov model over the run (estimators/train/regime_decoding.py)
    regime_recogniser: ClassVar[str] = "hmm"

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.config = self.p = p = ImprovedSettings.from_mapping(settings, type(self).__name__)
        self.line = LineTerm(p.line_file, p.rotating_mass_factor)
        self.theta0 = np.array([p.r0_init, p.r1_init, p.r2_init])
        self._W = p.recognition_window * (1.0 - 1e-9)  # fix times on a grid, up to round-off
        self.Lambda0 = np.diag((p.prior_rel_sigma * self.theta0) ** -2.0)
        self.R = np.diag([p.sigma_position ** 2, p.sigma_speed ** 2])
        self.H = np.eye(2, 3)
        h, q = self.dt, p.jerk_noise
        self.F = np.array([[1.0, h, 0.5 * h * h], [0.0, 1.0, h], [0.0, 0.0, 1.0]])
        self.Q = q * np.array([[h**5 / 20, h**4 / 8, h**3 / 6], [h**4 / 8, h**3 / 3, h**2 / 2],
                               [h**3 / 6, h**2 / 2, h]])

    # -- line term ---------------------------------------------------------------------------
    def _g_mean(self, s0: float, s1: float) -> float:
        """Mean of g over the distance [s0, s1] (the midpoint's value below 1 m)."""
        if abs(s1 - s0) < 1.0:
            return self.line.at(0.5 * (s0 + s1))
        return (self.line.integral(s1) - self.line.integral(s0)) / (s1 - s0)

    # -- Observer hooks ----------------------------------------------------------------------
    def _reset(self) -> None:
        self.x = np.zeros(3)
        self.P = np.diag([1e6, 1e4, 1.0])  # replaced by the first fix; a: 1 m/s2
        self._started = False
        self.a_interval: float | None = None
        self._fix_prev: tuple[float, float] | None = None
        self.fix_t: list[float] = []  # the fixes with both channels (the regression's data)
        self.fix_s: list[float] = []
        self.fix_v: list[float] = []
        self.vb: list[float] = []  # per interval i (fixes i, i + 1): mean speed
        self.cand: list[bool] = []  # per interval: coasting candidate
        self.Phi = [np.zeros(3)]  # per fix j: sum over the intervals before it of dt (1, vb, vb^2)
        self.Gc = [0.0]  # per fix j: sum over the intervals before it of dt g
        self._a = 0  # first fix of the recognition window that ends at the last fix
        self._done = 0  # intervals whose candidate flag is final
        self._open: int | None = None  # first interval of the open run of candidates
        self._origin: int | None = None  # its trimmed first fix, once it has arrived
        self._hist: list[np.ndarray] = []  # the open segment's sums, from its trimmed first fix
        self.closed: list[tuple[int, int]] = []  # accepted segments: first and last fix
        self._provisional: tuple[int, int] | None = None  # the open one, if it counts
        self.info_P = np.linalg.inv(self.Lambda0)  # covariance of theta after the closed segments
        self.info_theta = self.theta0.copy()
        self._t_info = self._t0
        self.theta = self.theta0.copy()
        self.theta_cov = self.info_P.copy()
        self.v_coast: float | None = None

    def _predict(self) -> None:
        self.x = self.F @ self.x
        self.P = kalman.predict_covariance(self.P, self.F, self.Q)

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        if not self._started:
            self.x[:2] = np.where(mask, z, self.x[:2])
            self.P[np.ix_(mask.nonzero()[0], mask.nonzero()[0])] = self.R[np.ix_(mask, mask)]
            self._started = bool(mask.all())
        elif mask.all():
            # kalman.update written out for H = [I 0]: the common case, cheaper than the masked form
            P = self.P
            S = P[:2, :2] + self.R
            K = P[:, :2] @ np.linalg.inv(S)
            self.x = self.x + K @ (z - self.x[:2])
            self.P = kalman.symmetric(P - K @ S @ K.T)
        else:
            up = kalman.update(self.x, self.P, z, self.H, self.R, mask=mask)
            self.x, self.P = up.x, up.P
        if mask.all():  # a fix with a channel missing only lengthens the regression's interval
            self._add_fix(self._t, float(z[0]), float(z[1]))
            if self._fix_prev is not None and self._t > self._fix_prev[0]:
                self.a_interval = (self.x[1] - self._fix_prev[1]) / (self._t - self._fix_prev[0])
            self._fix_prev = (self._t, float(self.x[1]))

    def _estimate(self) -> np.ndarray:
        s, v, a = self.x
        if self.a_interval is not None:
            a = self.a_interval
        th = self.theta
        if self.v_coast is not None and self._t == self.fix_t[-1]:
            v = self.v_coast
            a = -(th[0] + th[1] * v + th[2] * v * v + self.line.at(s))
        effort = a + th[0] + th[1] * v + th[2] * v * v + self.line.at(s)
        return np.array([s, v, *th, a, effort])

    # -- coasting segments -------------------------------------------------------------------
    def _add_fix(self, t: float, s: float, v: float) -> None:
        """A complete fix: its interval's sums (C0, C2), the recognition window that ends at
        it, and the candidate intervals that became final."""
        if self.fix_t:
            dt = t - self.fix_t[-1]
            vb = 0.5 * (v + self.fix_v[-1])
            self.vb.append(vb)
            self.cand.append(False)
            self.Phi.append(self.Phi[-1] + dt * np.array([1.0, vb, vb * vb]))
            self.Gc.append(self.Gc[-1] + dt * self._g_mean(self.fix_s[-1], s))
        self.fix_t.append(t)
        self.fix_s.append(s)
        self.fix_v.append(v)
        n = len(self.cand)  # intervals 0..n-1; interval i joins fixes i and i + 1
        if n == 0:
            return
        # the window ending at fix n starts at the last fix a recognition window before it
        while self._a + 1 < n and t - self.fix_t[self._a + 1] >= self._W:
            self._a += 1
        a = self._a
        if t - self.fix_t[a] >= self._W and abs(self._effort(a, n)) <= self.p.effort_band:
            for i in range(a, n):
                self.cand[i] = self.vb[i] > self.p.min_speed
        while self._done < a:  # no later window holds an interval before a: its flag is final
            i = self._done
            if self.cand[i] and self._open is None:
                self._open, self._origin, self._hist = i, None, []
            elif not self.cand[i] and self._open is not None:
                self._close(self._open, i)
                self._open = None
            self._done += 1
        if self._open is not None:
            self._accumulate(n)
        self._refresh()

    def _effort(self, a: int, b: int) -> float:
        """(C0) over the fixes a..b with the prior resistance: the mean effort eq. 1 needs."""
        T = self.fix_t[b] - self.fix_t[a]
        return ((self.fix_v[b] - self.fix_v[a]) + (self.Phi[b] - self.Phi[a]) @ self.theta0
                + self.Gc[b] - self.Gc[a]) / T

    def _trimmed(self, first: int, end: int) -> tuple[int, int]:
        """The fixes (f0, f1) of the run of intervals [first, end) trimmed by a recognition
        window at each end (a regime change may lie inside the windows that let it in)."""
        return (bisect.bisect_left(self.fix_t, self.fix_t[first] + self._W),
                bisect.bisect_right(self.fix_t, self.fix_t[end] - self._W) - 1)

    def _accumulate(self, n: int) -> None:
        """The open segment's sums up to fix n: M_j = sum_(k<=j) z_k z_k^T, z = (x_k, y_k, 1)
        of (C2) with the trimmed segment's first fix as origin (centring then costs O(1))."""
        if self._origin is None:
            f0 = self._trimmed(self._open, self._open)[0]
            if f0 > n:
                return
            self._origin = f0
        f0 = self._origin
        for j in range(f0 + len(self._hist), n + 1):
            z = np.empty(5)
            z[:3] = self.Phi[f0] - self.Phi[j]
            z[3] = self.fix_v[j] + self.Gc[j] - self.Gc[f0]
            z[4] = 1.0
            M = np.outer(z, z)
            self._hist.append(M if not self._hist else self._hist[-1] + M)

    def _segment(self, first: int, end: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The information (A, b) of the open run of candidate intervals [first, end),
        trimmed, if it lasts min_coast and passes the prior predictive test (docstring, 1.);
        else None."""
        f0, f1 = self._trimmed(first, end)
        if f1 <= f0 or self._origin != f0:
            return None
        T = self.fix_t[f1] - self.fix_t[f0]
        p = self.p
        if T < p.min_coast:
            return None
        phibar = (self.Phi[f1] - self.Phi[f0]) / T
        var = 2.0 * p.sigma_speed ** 2 / T**2 + np.sum((p.prior_rel_sigma * self.theta0 * phibar) ** 2)
        if abs(self._effort(f0, f1)) > p.test_sigmas * np.sqrt(var):
            return None
        M = self._hist[f1 - f0]
        C = M[:4, :4] - np.outer(M[:4, 4], M[:4, 4]) / M[4, 4]
        w = 1.0 / p.sigma_speed ** 2
        return w * C[:3, :3], w * C[:3, 3]

    def _posterior(self, P: np.ndarray, theta: np.ndarray, t_prev: float, t: float,
                   info: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(C3) in information form, after the random walk from t_prev to t: (P, theta)."""
        q = self.p.r_random_walk
        if q > 0:
            P = P + np.diag((q * self.theta0) ** 2) * max(t - t_prev, 0.0)
        Pinv = np.linalg.inv(P)
        A, b = info
        P_new = kalman.symmetric(np.linalg.inv(Pinv + A))
        return P_new, P_new @ (Pinv @ theta + b)

    def _close(self, first: int, end: int) -> None:
        info = self._segment(first, end)
        if info is not None:
            f0, f1 = self._trimmed(first, end)
            t_end = self.fix_t[f1]
            self.info_P, self.info_theta = self._posterior(self.info_P, self.info_theta, self._t_info, t_end, info)
            self._t_info = t_end
            self.closed.append((f0, f1))

    def _refresh(self) -> None:
        """theta^: the closed segments and, provisionally, the open run of candidates; while
        the train coasts in an accepted segment, its speed from the segment's fit (C2)."""
        self.theta, self.theta_cov = self.info_theta, self.info_P
        self.v_coast = None
        self._provisional = None
        if self._open is not None:
            n = end = len(self.cand)
            while end > self._open and not self.cand[end - 1]:
                end -= 1
            info = self._segment(self._open, end)
            if info is not None:
                f0, f1 = self._provisional = self._trimmed(self._open, end)
                self.theta_cov, self.theta = self._posterior(self.info_P, self.info_theta, self._t_info,
                                                             self.fix_t[f1], info)
                if end == n:  # still coasting: c of (C2) given theta^, then the fit at the last fix
                    M = self._hist[f1 - f0]
                    c = (M[3, 4] - M[:3, 4] @ self.theta) / M[4, 4]
                    self.v_coast = float(c + (self.Phi[f0] - self.Phi[n]) @ self.theta - (self.Gc[n] - self.Gc[f0]))

    @property
    def segments(self) -> list[tuple[int, int]]:
        """The coasting segments the last estimate used (first and last fix index): the
        closed ones and the open one if it counts."""
        return self.closed + ([self._provisional] if self._provisional else [])

    @property
    def covariance(self) -> np.ndarray:
        """The covariance of ``(s, v, r0, r1, r2)`` (SI) as the last estimate: the kinematic
        filter's for ``s, v`` and the posterior (C3)'s for the coefficients (independent)."""
        C = np.zeros((5, 5))
        C[:2, :2] = self.P[:2, :2]
        C[2:, 2:] = self.theta_cov
        return C

    def finish(self) -> dict:
        """Diagnostics: the coasting segments used (count, seconds, speed range in km/h) and
        the posterior standard deviations of r0, r1, r2 (SI)."""
        out = {**super().finish(), "coasting_segments": len(self.segments), "coasting_s": 0.0}
        if self.segments:
            t, v = np.array(self.fix_t), np.array(self.fix_v)
            out["coasting_s"] = float(sum(t[b] - t[a] for a, b in self.segments))
            fixes = np.concatenate([np.arange(a, b + 1) for a, b in self.segments])
            out["coasting_min_speed_kmh"] = float(3.6 * v[fixes].min())
            out["coasting_max_speed_kmh"] = float(3.6 * v[fixes].max())
        for name, sigma in zip(("r0_sigma", "r1_sigma", "r2_sigma"), np.sqrt(np.diag(self.theta_cov))):
            out[name] = float(sigma)
        return out
