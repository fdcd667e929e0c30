r"""Identification of the simplified model (SM) against the complete model (CM), and the
Kalman filter's noise covariances from CM runs: Muñoz et al., §3.4 (eqs. 7-8) and §4.2 (eqs. 28-31).

Design model
------------
:data:`railfmu.models.vehicle.wheelset.WHEELSET` (the paper's §3.3), linear, state ``x = [y, psi, y_f, dy, dpsi, dy_f]``
(m, rad, m, m/s, rad/s, m/s), input the alignment ``xi`` (m) under the wheelset and its rate
``xi_rate`` (m/s): ``dx/dt = A(p) x + B(p) [xi, xi_rate]``. ``A`` and ``B`` are the model's own
Jacobians, lambdified once in the parameters (the model is linear, so they do not depend on the
operating point).

SM response (:func:`sm_response`)
---------------------------------
The FMU holds its input over a communication step ``h`` to first order,
``xi(t_k + tau) = xi_k + xi_rate_k tau`` (``railfmu.models.base.Model._substitute_held_inputs``), and
integrates with RK4 at 1e-4 s. The exact solution of that is the matrix exponential of the
augmented system ``[x, xi, r]`` with ``d xi/dt = r``, ``dr/dt = 0``
(:func:`railfmu.estimators.core.discretize.foh`)::

    expm([[A, B_xi, B_rate], [0, 0, 1], [0, 0, 0]] h) = [[Phi, G0, G1], ...]
    x_{k+1} = Phi x_k + G0 xi_k + G1 xi_rate_k

(``B_rate`` is 0 for this SM; kept for generality). The recursion runs in modal coordinates
(``Phi = W diag(lambda) W^-1``): each mode is a first-order complex IIR filter
(``scipy.signal.lfilter``), so a 20000-step response costs about a millisecond. ``x_0 = 0``
(the CM also starts at rest on the centred track).

Identification (:func:`identify_primary`, the paper's eq. 8)
------------------------------------------------------------
The paper minimises ``J_ls(p_opt) = 1/N sum_k |x_real(k) - x_mod(k, p_opt)|^2`` with
``x = [y, psi]`` and ``p_opt = [kx, cx, ky, cy]`` (eq. 7; all other SM parameters fixed, taken
from the real vehicle). **Deviation**: that sum adds metres and radians; ``psi`` (~1e-4 rad) is
then almost weightless against ``y`` (~1e-3 m), and ``kx``/``cx`` (the yaw suspension) would be
fitted by ``y`` alone. Each channel is therefore normalised by its CM rms::

    r = [ (y_sm - y_cm) / rms(y_cm),  (psi_sm - psi_cm) / rms(psi_cm) ] / sqrt(N)
    cost = sum r^2 = NRMSE_y^2 + NRMSE_psi^2           (NRMSE = rms(error) / rms(CM))

minimised by ``scipy.optimize.least_squares`` (trust region reflective) over ``log p_opt``
(the parameters stay positive and are scaled alike), bounded to a factor 1000 around the
initial values. The paper's unnormalised ``J_ls`` is reported too.

Noise covariances (:func:`estimate_noise`, the paper's eqs. 28-31)
------------------------------------------------------------------
With ``x^CM_k`` the CM's state mapped onto the filter's augmented state
``[y, psi, y_f, dy, dpsi, dy_f, xi]`` and ``z^CM_k`` the CM's (noisy) sensor readings
``[ddy, dpsi, ddy_f]`` plus the virtual ``xi = 0`` reading::

    e^x_k = x^CM_k - F x^CM_{k-1},      Q = 1/N sum e^x e^xT         (eqs. 28-29)
    e^z_k = z^CM_k - H x^CM_k,          R = 1/N sum e^z e^zT         (eqs. 30-31)

``F = expm(F_c dt)`` and ``H`` are exactly the ones :class:`railfmu.estimators.track.alignment.AlignmentKalmanFilter`
builds (``xi`` a random walk, ``H`` from the SM's accelerations; rebuilt here from the model so
this module needs only ``models``, numpy and scipy).

Mapping onto the filter's settings: the filter takes a *continuous* diagonal
``Q_c = diag(0, 0, 0, q_acc, q_yaw, q_acc, q_xi)`` and discretises it by Van Loan, which for the
small ``dt`` of the data is ``Q_d ~= Q_c dt`` on those diagonal entries; its ``R`` is
``diag(sigma_acc^2, sigma_gyro^2, sigma_acc^2, sigma_virtual^2)``. So::

    q_acc      = (Q[dy, dy] + Q[dy_f, dy_f]) / (2 dt)   one intensity for both accelerations in
                                                        the filter: the mean of the two (the best
                                                        single value in least squares); both
                                                        are returned (q_acc_wheelset, q_acc_frame)
    q_yaw      = Q[dpsi, dpsi] / dt
    q_xi       = Q[xi, xi] / dt
    sigma_acc  = sqrt((R[ddy, ddy] + R[ddy_f, ddy_f]) / 2)   likewise, both returned
    sigma_gyro = sqrt(R[dpsi, dpsi])

The position rows of ``Q`` (``~ dt^2`` smaller) and the off-diagonal terms have no place in the
filter's ``Q_c`` and are dropped (returned in ``Q``). Because the CM's model error and the
alignment are not white noise, ``Q[.,.] / dt`` depends on ``dt``: the settings hold for the
filter run at the ``dt`` of the data. The virtual row of eq. 31 gives ``rms(xi)``
(``sigma_virtual_eq31``); the paper itself does not use it (it fixes 5 mm), and neither do the
settings: the filter derives ``sigma_virtual`` from ``q_xi`` so that the alignment's forgetting
corner stays at the ERRI B176 corner ``Omega_r`` (see :mod:`railfmu.estimators.track.alignment`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import sympy as sp
from scipy.optimize import least_squares
from scipy.signal import lfilter

from railfmu.models.vehicle.wheelset import WHEELSET

from railfmu.estimators.core.discretize import foh, zoh
from railfmu.estimators.track.metrics import rms

P_OPT = ("kx", "cx", "ky", "cy")
AUGMENTED_STATES = ("y", "psi", "y_f", "dy", "dpsi", "dy_f", "xi")
MEASUREMENTS = ("ddy", "dpsi", "ddy_f", "xi_virtual")
_STATE_NAMES = tuple(s.name for s in WHEELSET.states)
_INPUT_NAMES = tuple(u.name for u in WHEELSET.inputs)

_AB_FN = None


def _ab_function():
    """(A, B) of the SM as a numeric function of the parameter values (in WHEELSET order)."""
    global _AB_FN
    if _AB_FN is None:
        x = [s.symbol for s in WHEELSET.states]
        u = [v.symbol for v in WHEELSET.inputs]
        f = sp.Matrix(WHEELSET.derivative_exprs())
        zero = {s: 0 for s in x + u}
        J = f.jacobian(x).subs(zero), f.jacobian(u).subs(zero)
        _AB_FN = sp.lambdify([p.symbol for p in WHEELSET.parameters], list(J), modules="numpy")
    return _AB_FN


def sm_parameters(params: Mapping[str, float] | None = None) -> dict[str, float]:
    """All SM parameters: the defaults of :data:`railfmu.models.vehicle.wheelset.WHEELSET` updated by ``params``."""
    p = WHEELSET.default_parameters()
    unknown = sorted(set(params or {}) - set(p))
    if unknown:
        raise ValueError(f"unknown WheelsetLateral parameter(s) {unknown}")
    p.update({k: float(v) for k, v in (params or {}).items()})
    return p


def sm_matrices(params: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A (6x6), B (6x2)) of ``dx/dt = A x + B [xi, xi_rate]`` for the given parameters."""
    p = sm_parameters(params)
    A, B = _ab_function()(*[p[q.name] for q in WHEELSET.parameters])
    return np.asarray(A, dtype=float), np.asarray(B, dtype=float)


def _uniform_step(t: np.ndarray) -> float:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError("t must be a 1-D time grid with at least two samples")
    d = np.diff(t)
    h = float(np.mean(d))
    if not (h > 0 and np.allclose(d, h, rtol=1e-6, atol=1e-12)):
        raise ValueError("t must be uniformly spaced and increasing")
    return h


def sm_states(params: Mapping[str, float] | None, t: np.ndarray, xi: np.ndarray, xi_rate: np.ndarray
              ) -> np.ndarray:
    """SM states (N x 6: y, psi, y_f, dy, dpsi, dy_f) from rest, driven by ``xi`` (m) and
    ``xi_rate`` (m/s) sampled at ``t`` (s, uniform) and held to first order over each step."""
    h = _uniform_step(t)
    xi = np.asarray(xi, dtype=float)
    xi_rate = np.asarray(xi_rate, dtype=float)
    if xi.shape != np.shape(t) or xi_rate.shape != np.shape(t):
        raise ValueError("xi and xi_rate must have the shape of t")
    A, B = sm_matrices(params)
    # B's columns are xi and xi_rate: xi extrapolated with its rate (the FMU's hold)
    Phi, G0, G1, _ = foh(A, B[:, 0], h, B_rate=B[:, 1])
    G0, G1 = G0[:, 0], G1[:, 0]
    lam, W = np.linalg.eig(Phi)
    Winv = np.linalg.inv(W)
    # modal inputs u_k = W^-1 (G0 xi_k + G1 r_k); z_{k+1} = lam z_k + u_k, z_0 = 0
    u = np.outer(Winv @ G0, xi) + np.outer(Winv @ G1, xi_rate)  # (6, N)
    z = np.empty_like(u)
    for i in range(lam.size):
        z[i] = lfilter([0.0, 1.0], [1.0, -lam[i]], u[i])
    return np.real(W @ z).T


def sm_response(params: Mapping[str, float] | None, t: np.ndarray, xi: np.ndarray, xi_rate: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(y (m), psi (rad)) of the SM's wheelset from rest: see :func:`sm_states`. ``params``
    updates the WHEELSET defaults (any parameter, e.g. kx, cx, ky, cy, V)."""
    x = sm_states(params, t, xi, xi_rate)
    return x[:, _STATE_NAMES.index("y")], x[:, _STATE_NAMES.index("psi")]


@dataclass
class IdentificationResult:
    """Outcome of :func:`identify_primary`. ``values``/``initial``: kx (N/m), cx (N.s/m),
    ky (N/m), cy (N.s/m), per side; ``cost_*``: the normalised cost (NRMSE_y^2 + NRMSE_psi^2);
    ``J_ls_*``: eq. 8 of Muñoz et al. (m^2 + rad^2); ``nrmse_*``: rms(SM - CM) / rms(CM) of y and psi."""
    values: dict[str, float]
    initial: dict[str, float]
    cost_before: float
    cost_after: float
    J_ls_before: float
    J_ls_after: float
    nrmse_before: dict[str, float]
    nrmse_after: dict[str, float]
    n_evaluations: int
    success: bool
    message: str
    fixed: dict[str, float] = field(default_factory=dict)
    free: tuple[str, ...] = P_OPT
    #: singular values of the residual's Jacobian in log-parameters at the solution: a small
    #: one means a combination of the free parameters the responses cannot determine
    singular_values: list[float] = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"values": dict(self.values), "initial": dict(self.initial),
                "cost_before": self.cost_before, "cost_after": self.cost_after,
                "J_ls_before": self.J_ls_before, "J_ls_after": self.J_ls_after,
                "nrmse_before": dict(self.nrmse_before), "nrmse_after": dict(self.nrmse_after),
                "n_evaluations": self.n_evaluations, "success": self.success, "message": self.message,
                "free": list(self.free), "singular_values": list(self.singular_values)}


def identify_primary(t: np.ndarray, xi: np.ndarray, xi_rate: np.ndarray, y_cm: np.ndarray, psi_cm: np.ndarray,
                     initial: Mapping[str, float] | None = None, V: float = 20.0,
                     fixed: Mapping[str, float] | None = None, free: tuple[str, ...] = P_OPT,
                     bounds_factor: float = 1e3) -> IdentificationResult:
    """Identify the SM's primary suspension ``kx, cx, ky, cy`` (per side) from a CM run with
    lateral alignment only (Muñoz et al., §3.4): least squares between the CM's (``y_cm`` m, ``psi_cm``
    rad) and the SM's wheelset response to the same ``xi`` (m), ``xi_rate`` (m/s) at ``t`` (s).

    ``initial``: starting values (default: the WHEELSET defaults, Muñoz et al., Table 1); ``V``: speed
    (m/s); ``fixed``: other SM parameters (p_fix of eq. 7) if not the defaults; ``free``: the
    subset of kx, cx, ky, cy to fit (the others stay at ``initial``; e.g. for a profile of the
    cost); ``bounds_factor``: each fitted value stays within this factor of its initial value."""
    y_cm = np.asarray(y_cm, dtype=float)
    psi_cm = np.asarray(psi_cm, dtype=float)
    for name, a in (("xi", xi), ("xi_rate", xi_rate), ("y_cm", y_cm), ("psi_cm", psi_cm)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"identify_primary: {name} has non-finite values")
    base = sm_parameters({**(fixed or {}), "V": V})
    p0 = {k: float(base[k]) for k in P_OPT}
    p0.update({k: float(v) for k, v in (initial or {}).items() if k in P_OPT})
    if any(not (v > 0) for v in p0.values()):
        raise ValueError(f"identify_primary: initial values must be positive, not {p0}")
    sy, spsi = rms(y_cm), rms(psi_cm)
    if not (sy > 0 and spsi > 0):
        raise ValueError("identify_primary: the CM response is zero (no excitation?)")
    free = tuple(free)
    if not free or any(k not in P_OPT for k in free):
        raise ValueError(f"identify_primary: free must be a non-empty subset of {P_OPT}, not {free}")
    if not bounds_factor > 1:
        raise ValueError(f"identify_primary: bounds_factor must be > 1, not {bounds_factor}")
    n = y_cm.size
    count = [0]

    def simulate(theta):
        count[0] += 1
        return sm_response({**base, **p0, **dict(zip(free, np.exp(theta), strict=True))}, t, xi, xi_rate)

    def residual(theta):
        y, psi = simulate(theta)
        return np.concatenate([(y - y_cm) / sy, (psi - psi_cm) / spsi]) / math.sqrt(n)

    def scores(theta):
        y, psi = simulate(theta)
        ey, epsi = y - y_cm, psi - psi_cm
        nrmse = {"y": rms(ey) / sy, "psi": rms(epsi) / spsi}
        return nrmse["y"] ** 2 + nrmse["psi"] ** 2, float(np.mean(ey**2 + epsi**2)), nrmse

    theta0 = np.log([p0[k] for k in free])
    cost0, J0, nrmse0 = scores(theta0)
    span = math.log(bounds_factor)
    sol = least_squares(residual, theta0, bounds=(theta0 - span, theta0 + span),
                        method="trf", x_scale=1.0, xtol=1e-10, ftol=1e-12, gtol=1e-10, max_nfev=400)
    n_eval = count[0]
    cost1, J1, nrmse1 = scores(sol.x)
    return IdentificationResult(
        values={**p0, **dict(zip(free, (float(v) for v in np.exp(sol.x)), strict=True))}, initial=p0,
        cost_before=cost0, cost_after=cost1, J_ls_before=J0, J_ls_after=J1,
        nrmse_before=nrmse0, nrmse_after=nrmse1, n_evaluations=n_eval, success=bool(sol.success),
        message=str(sol.message), fixed={k: v for k, v in base.items() if k not in P_OPT}, free=free,
        singular_values=[float(v) for v in np.linalg.svd(np.atleast_2d(sol.jac), compute_uv=False)])


def filter_matrices(params: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(F_c (7x7), H (4x7)) of the alignment filter's augmented model (Muñoz et al., eqs. 15, 17), as
    :class:`railfmu.estimators.track.alignment.AlignmentKalmanFilter` builds them."""
    A, B = sm_matrices(params)
    F_c = np.zeros((7, 7))
    F_c[:6, :6] = A
    F_c[:6, 6] = B[:, _INPUT_NAMES.index("xi")]
    i_dy, i_dyf = _STATE_NAMES.index("dy"), _STATE_NAMES.index("dy_f")
    H = np.zeros((4, 7))
    H[0] = F_c[i_dy]  # ddy = d(dy)/dt
    H[1, _STATE_NAMES.index("dpsi")] = 1.0
    H[2] = F_c[i_dyf]
    H[3, 6] = 1.0
    return F_c, H


@dataclass
class NoiseEstimate:
    """Outcome of :func:`estimate_noise`: the discrete ``Q`` of Muñoz et al. (7x7, over
    :data:`AUGMENTED_STATES`) and ``R`` (4x4, over :data:`MEASUREMENTS`) at ``dt``, and
    ``settings`` for :class:`railfmu.estimators.track.alignment.AlignmentKalmanFilter` (see the module
    docstring for the mapping); ``details`` has the per-channel values."""
    Q: np.ndarray
    R: np.ndarray
    dt: float
    settings: dict[str, float]
    details: dict[str, float]

    def as_dict(self) -> dict:
        return {"settings": dict(self.settings), "details": dict(self.details), "dt": self.dt,
                "Q_diag": dict(zip(AUGMENTED_STATES, map(float, np.diag(self.Q)), strict=True)),
                "R_diag": dict(zip(MEASUREMENTS, map(float, np.diag(self.R)), strict=True))}


def estimate_noise(t: np.ndarray, states: np.ndarray, sensors: np.ndarray,
                   params: Mapping[str, float] | None = None, V: float = 20.0) -> NoiseEstimate:
    """``Q`` and ``R`` of the alignment filter from a CM run (Muñoz et al., eqs. 28-31).

    ``t`` (s, uniform); ``states`` (N x 7): the CM's state mapped onto
    ``[y, psi, y_f, dy, dpsi, dy_f, xi]`` (m, rad, m, m/s, rad/s, m/s, m): the leading wheelset,
    the bogie frame above it (the point of the frame accelerometer) and the alignment under the
    wheelset; ``sensors`` (N x 3): the CM's noisy readings ``[ddy, dpsi, ddy_f]`` (m/s2, rad/s,
    m/s2). ``params``: the SM's parameters (e.g. the identified kx, cx, ky, cy); ``V`` (m/s)."""
    dt = _uniform_step(t)
    X = np.asarray(states, dtype=float)
    Z = np.asarray(sensors, dtype=float)
    if X.shape != (np.size(t), 7) or Z.shape != (np.size(t), 3):
        raise ValueError(f"estimate_noise: states must be N x 7 and sensors N x 3 (N = {np.size(t)}), "
                         f"not {X.shape} and {Z.shape}")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Z))):
        raise ValueError("estimate_noise: non-finite states or sensors")
    F_c, H = filter_matrices({**(params or {}), "V": V})
    F = zoh(F_c, None, dt)[0]
    ex = X[1:] - X[:-1] @ F.T  # eq. 28
    Q = ex.T @ ex / ex.shape[0]  # eq. 29
    Zfull = np.column_stack([Z, np.zeros(Z.shape[0])])  # the virtual reading xi = 0
    ez = Zfull - X @ H.T  # eq. 30
    R = ez.T @ ez / ez.shape[0]  # eq. 31
    Q, R = 0.5 * (Q + Q.T), 0.5 * (R + R.T)
    i = {n: k for k, n in enumerate(AUGMENTED_STATES)}
    details = {
        "q_acc_wheelset": Q[i["dy"], i["dy"]] / dt,
        "q_acc_frame": Q[i["dy_f"], i["dy_f"]] / dt,
        "sigma_acc_wheelset": math.sqrt(R[0, 0]),
        "sigma_acc_frame": math.sqrt(R[2, 2]),
        "sigma_virtual_eq31": math.sqrt(R[3, 3]),
    }
    settings = {
        "q_acc": 0.5 * (details["q_acc_wheelset"] + details["q_acc_frame"]),
        "q_yaw": Q[i["dpsi"], i["dpsi"]] / dt,
        "q_xi": Q[i["xi"], i["xi"]] / dt,
        "sigma_acc": math.sqrt(0.5 * (R[0, 0] + R[2, 2])),
        "sigma_gyro": math.sqrt(R[1, 1]),
    }
    return NoiseEstimate(Q=Q, R=R, dt=dt, settings={k: float(v) for k, v in settings.items()},
                         details={k: float(v) for k, v in details.items()})
