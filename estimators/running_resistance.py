r"""Running resistance of a train from GNSS position and speed: the Unscented Kalman filter of
Cunillera et al. (2022) §3.1 (``PaperUKF``), with its process model as a replaceable part.

Design model (mass-specific, SI; state ``x = (s, v, r0, r1, r2)``, the Davis coefficients
constant: ``Q = 0`` as the paper)::

    a(x, u, s)  = u - r0 - r1 v - r2 v^2 - g(s)                         (eq. 5)
    f(x, u)     = x + (dt v + dt^2 a / 2, dt a, 0, 0, 0)                (eq. 4, "discrete")
    z           = (s, v) + w,   R = diag(sigma_s^2, sigma_v^2)          (eq. 6)

``g(s) = g0 (i(s) / 1000 + w_c(s)) / gamma`` is the line term of the line profile
(``models/line_profile.py``; the paper takes the track description as exact). The effort
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

1. the centre-referenced unscented transform of :mod:`estimators.ukf` (the weights multiply
   deviations from the centre point, never the state itself; PSD by construction);
2. the filter runs in **scaled coordinates** ``x~ = D^-1 x``, ``D = diag(Table 1 sigmas)``, so
   that ``P~_0 = I``: the unscented transform is exact under a linear change of coordinates
   (the sigma points of ``D P D`` are ``D`` times those of ``P``), so the estimates are the
   textbook filter's, and round-off acts on variances of order 1 instead of on a matrix
   whose entries span 1e-18 to 16.
Measured on a 32 km run of the shipped line (``tests/test_running_resistance.py``): at α = 0.5,
where every form is well conditioned, this filter equals filterpy's
``UnscentedKalmanFilter`` to 1.4e-9 standard deviations; at the paper's settings filterpy's
textbook sums differ from it by up to 8e-4 σ, the centre-referenced form in SI coordinates by
8e-5 σ. The posterior covariance is symmetrised; if it still lost positive definiteness the
step would raise a ``FloatingPointError`` naming the time (never a silent wrong answer).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from models.line_profile import DEFAULT_LINE, G0, LineProfile
from models.train_longitudinal import GAMMA, R0, R1, R2

from . import ukf
from .observer import Observer

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

    def __call__(self, s: np.ndarray) -> np.ndarray:
        k = np.searchsorted(self.line.position, s, side="right") - 1
        return self.values[np.clip(k, 0, len(self.values) - 1)]


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
        a = np.where(moving, u - R[:, 0] - R[:, 1] * v - R[:, 2] * v * v - g,
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


def _setting(settings: dict, name: str, default: float) -> float:
    value = float(settings.get(name, default))
    if not np.isfinite(value):
        raise ValueError(f"setting {name} = {value!r} is not a finite number")
    return value


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
    ``integrator_step`` (s, for ``"ode"``).
    """

    measurements: ClassVar[tuple[str, ...]] = ("position", "speed")
    outputs: ClassVar[tuple[str, ...]] = ("s", "v", "r0", "r1", "r2", "acceleration", "effort")
    units: ClassVar[dict[str, str]] = {"position": "m", "speed": "m/s", "s": "m", "v": "m/s", "r0": "N/kg",
                                       "r1": "N.s/(m.kg)", "r2": "N.s2/(m2.kg)", "acceleration": "m/s2",
                                       "effort": "N/kg"}
    event_driven: ClassVar[bool] = True

    def __init__(self, dt: float, process: str | Process = "discrete", **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.line = LineTerm(settings.get("line_file") or None, _setting(settings, "rotating_mass_factor", GAMMA))
        if callable(process):
            self.process = process
        elif process == "discrete":
            self.process = discrete_process(self.line)
        elif process == "ode":
            self.process = ode_process(self.line, _setting(settings, "integrator_step", 0.05))
        else:
            raise ValueError(f"process must be 'discrete', 'ode' or a callable, not {process!r}")
        self.x_init = np.array([0.0, 0.0, _setting(settings, "r0_init", R0), _setting(settings, "r1_init", R1),
                                _setting(settings, "r2_init", R2)])
        names = ("sigma_s0", "sigma_v0", "sigma_r0_0", "sigma_r1_0", "sigma_r2_0")
        self.D = np.array([_setting(settings, k, d) for k, d in zip(names, PAPER_SIGMAS)])
        if not (self.D > 0).all():
            raise ValueError("the initial standard deviations must be > 0")
        sr = np.array([_setting(settings, "sigma_position", PAPER_SIGMA_S), _setting(settings, "sigma_speed", PAPER_SIGMA_V)])
        if not (sr > 0).all():
            raise ValueError("sigma_position and sigma_speed must be > 0")
        # R in scaled measurement units: z~ = z / D[:2]
        self.R = np.diag((sr / self.D[:2]) ** 2)
        self.points = ukf.MerweScaledSigmaPoints(5, alpha=_setting(settings, "alpha", PAPER_ALPHA),
                                                 beta=_setting(settings, "beta", PAPER_BETA),
                                                 kappa=_setting(settings, "kappa", PAPER_KAPPA))
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
        self._check(t)

    def _check(self, t: float) -> None:
        try:
            np.linalg.cholesky(self.P)
        except np.linalg.LinAlgError:
            raise FloatingPointError(f"{type(self).__name__}: the covariance lost positive definiteness at "
                                     f"t = {t:g} s") from None

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
                "centre_weight": float(self.points.Wc[0])}
