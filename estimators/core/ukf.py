r"""Unscented Kalman filter steps with a covariance that stays sound under scaled sigma points
with a tiny spread (Van der Merwe's ``alpha`` = 1e-3, ``kappa`` = -2: the running-resistance
UKF of Cunillera et al. 2022).

Sigma points and weights: filterpy's ``MerweScaledSigmaPoints`` (any point set whose
covariance and mean weights agree off the centre, ``Wc_i = Wm_i = W_i`` for ``i >= 1``)::

    X_0 = m,   X_{i}, X_{n+i} = m +- [sqrt((n + lambda) P)]_i,   lambda = alpha^2 (n + kappa) - n
    W_i = 1 / (2 (n + lambda)),   Wm_0 = lambda / (n + lambda),   Wc_0 = Wm_0 + 1 - alpha^2 + beta

At ``n`` = 5, ``alpha`` = 1e-3, ``kappa`` = -2: ``n + lambda`` = 3e-6, ``W_i`` = 1.7e5 and
``Wm_0`` = -1.7e6 (``Wc_0`` likewise). The textbook transform ``y = sum Wm_i Y_i`` adds terms
of 1e6 times ``|Y|`` with both signs, so the mean carries ~1e6 ulp of ``|Y|``: at a position
of 50 km with a 1 cm standard deviation it is 1e-5 m off (1e-3 sigma), and that error,
times the nonlinearity, reaches the cross-covariances of ``P = sum Wc_i (Y_i - y)(Y_i - y)^T``
(far off: ``tests/test_estimation_core.py``).

Centre-referenced form (used here): with the deviations from the centre point
``D_i = Y_i - Y_0`` and ``delta = sum_{i>=1} W_i D_i``, exactly (``sum Wm = 1``)::

    y   = Y_0 + delta
    P   = sum_{i>=1} W_i D_i D_i^T + c_0 delta delta^T (+ noise),   c_0 = Wc_0 - Wm_0 - 1
    P_xy = sum_{i>=1} W_i DX_i DY_i^T + c_0 delta_x delta_y^T

(expand ``sum Wc_i (D_i - delta)(D_i - delta)^T`` with ``sum Wc_i D_i = delta``,
``sum Wc_i = 2 + c_0``). The large weights now multiply only the deviations, of the size of
the spread, never ``|Y|``: the result does not depend on where the state lies (the same to
round-off at 50 km as at 0). For Merwe's points ``c_0 = beta - alpha^2`` (1.999999): ``P`` is a
sum of positive semi-definite terms with positive weights, PSD by construction (the
textbook sum is PSD only through the cancellation of its -1.7e6 term), and then
symmetrised. For a linear map ``delta`` = 0 and ``P = F P F^T`` to round-off, whatever
``alpha`` and ``kappa``. What no form can remove is the rounding of the sigma points
themselves (``m +- 1.7e-3 sigma``): the mean keeps ~``eps |x| / (alpha^2 (n + kappa))``,
1e-7 m at 1.5 km.

Filter steps (additive noise)::

    predict:  Y_i = f(X_i(x, P)),  x^- = y,  P^- = P_yy + Q
    update:   Z_i = h(X_i(x^-, P^-)),  z^ , S = P_zz + R,  P_xz,  K = P_xz S^-1
              x^+ = x^- + K (z - z^),  P^+ = P^- - K S K^T (symmetrised)

The update draws its sigma points afresh from ``(x^-, P^-)`` so that they carry ``Q`` (filterpy
reuses the propagated points, which do not); for a linear ``f`` and ``h`` both steps equal the
Kalman filter's. Missing channels (``mask``) drop their rows of ``Z``, ``z`` and ``R``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints

from railfmu.estimators.core.kalman import Update, symmetric

__all__ = ["MerweScaledSigmaPoints", "cross_covariance", "predict", "unscented_transform", "update"]


def _weights(points: Any) -> tuple[np.ndarray, float]:
    """``(W_i for i >= 1, c_0)`` of a sigma-point set (module docstring)."""
    Wm, Wc = np.asarray(points.Wm, dtype=float), np.asarray(points.Wc, dtype=float)
    if not np.array_equal(Wm[1:], Wc[1:]):
        raise ValueError("the centre-referenced unscented transform needs Wc_i = Wm_i off the centre")
    if hasattr(points, "alpha") and hasattr(points, "beta"):
        return Wm[1:], float(points.beta - points.alpha ** 2)  # exact for Merwe's points
    return Wm[1:], float(Wc[0] - Wm[0] - 1.0)


def unscented_transform(Y: np.ndarray, points: Any, noise_cov: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the transformed sigma points ``Y`` ``(2n + 1, m)`` (``Y[0]``
    from the centre point), centre-referenced (module docstring), plus ``noise_cov``."""
    W, c0 = _weights(points)
    D = Y[1:] - Y[0]
    delta = W @ D
    P = (D.T * W) @ D + c0 * np.outer(delta, delta)
    if noise_cov is not None:
        P = P + noise_cov
    return Y[0] + delta, symmetric(P)


def cross_covariance(X: np.ndarray, Y: np.ndarray, points: Any) -> np.ndarray:
    """``P_xy`` of two sets of sigma points of the same draw, centre-referenced."""
    W, c0 = _weights(points)
    DX, DY = X[1:] - X[0], Y[1:] - Y[0]
    return (DX.T * W) @ DY + c0 * np.outer(W @ DX, W @ DY)


def predict(x: np.ndarray, P: np.ndarray, fx: Callable[[np.ndarray], np.ndarray], Q: np.ndarray,
            points: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(x^-, P^-)`` through the process model ``fx`` (one sigma point -> its successor)."""
    X = points.sigma_points(x, P)
    Y = np.array([fx(s) for s in X])
    return unscented_transform(Y, points, Q)


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, hx: Callable[[np.ndarray], np.ndarray],
           R: np.ndarray, points: Any, mask: np.ndarray | None = None) -> Update:
    """Update of ``(x^-, P^-)`` with ``z`` through the measurement model ``hx``; ``mask``:
    True where a channel is present (module docstring). Returns :class:`railfmu.estimators.core.kalman.Update`."""
    X = points.sigma_points(x, P)
    Z = np.array([np.atleast_1d(hx(s)) for s in X])
    z = np.atleast_1d(np.asarray(z, dtype=float))
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        Z, z, R = Z[:, mask], z[mask], R[np.ix_(mask, mask)]
    if z.size == 0:
        return Update(x, P, np.zeros((x.size, 0)), z, np.zeros((0, 0)))
    z_hat, S = unscented_transform(Z, points, R)
    K = np.linalg.solve(S, cross_covariance(X, Z, points).T).T
    nu = z - z_hat
    return Update(x + K @ nu, symmetric(P - K @ S @ K.T), K, nu, S)
