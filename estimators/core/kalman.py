r"""The linear(ised) Kalman filter's steps and its stationary gain.

Prediction (``F`` the transition over one step, ``Q`` the discrete process noise)::

    x^- = F x^+ (+ G u),      P^- = F P^+ F^T + Q

Update in Joseph form (Bucy & Joseph 1968), with ``z_pred = H x^-`` for a linear model or
``h(x^-)`` for an extended filter (then ``H`` is the Jacobian of ``h``)::

    nu  = z - z_pred,   S = H P^- H^T + R,   K = P^- H^T S^-1
    x^+ = x^- + K nu,   P^+ = (I - K H) P^- (I - K H)^T + K R K^T

The Joseph form is a sum of two symmetric PSD terms for any ``K``, so ``P^+`` stays PSD under
round-off where ``(I - K H) P^-`` does not; it equals that short form for the optimal ``K``.
Both covariances are symmetrised after each step. A channel may be missing (per-channel
``mask``): the update uses only the rows of ``z``, ``H`` and ``R`` that are present, which is
the exact update with the smaller measurement.

Stationary filter (a time-invariant ``F, H, Q, R``): ``P^-`` solves the discrete algebraic
Riccati equation (DARE) of the estimation problem::

    P = F (P - P H^T (H P H^T + R)^-1 H P) F^T + Q

solved in scaled states ``x = T x'`` (``T = diag(scale)``, the states' typical magnitudes), by
scipy's QZ solver first and, where scipy finds the pencil too ill-conditioned (a closed-loop
pole within ~1e-4 of the unit circle), by the structure-preserving doubling algorithm.
Why ours: filterpy has no DARE, and scipy's refuses a pencil with a pole that close to the circle.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg as sla


class Update(NamedTuple):
    """Result of :func:`update`: the a-posteriori ``x`` and ``P``, the gain ``K``, the
    innovation ``nu`` and its covariance ``S`` (over the channels used)."""
    x: np.ndarray
    P: np.ndarray
    K: np.ndarray
    nu: np.ndarray
    S: np.ndarray


def symmetric(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2``: what round-off took from a covariance's symmetry."""
    return 0.5 * (P + P.T)


def predict_covariance(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """``F P F^T + Q``, symmetrised (an extended filter with its own mean prediction uses
    this with the Jacobian ``F``)."""
    return symmetric(F @ P @ F.T + Q)


def predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray,
            G: np.ndarray | None = None, u: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(F x + G u, F P F^T + Q)`` (module docstring); ``G u`` only when both are given."""
    x = F @ x if G is None or u is None else F @ x + G @ u
    return x, predict_covariance(P, F, Q)


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray,
           z_pred: np.ndarray | None = None, mask: np.ndarray | None = None) -> Update:
    """Joseph-form update of ``(x, P)`` with the measurement ``z`` (module docstring).

    ``z_pred``: the predicted measurement (default ``H x``; an extended filter passes
    ``h(x)``). ``mask``: per channel, True where ``z`` is present; the update then uses only
    those rows (none present: ``x``, ``P`` unchanged, empty ``K``, ``nu``, ``S``)."""
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if not mask.all():
            z, H, R = z[mask], H[mask], R[np.ix_(mask, mask)]
            z_pred = None if z_pred is None else z_pred[mask]
    nu = z - (H @ x if z_pred is None else z_pred)
    if nu.size == 0:
        return Update(x, P, np.zeros((x.size, 0)), nu, np.zeros((0, 0)))
    PHt = P @ H.T
    S = H @ PHt + R
    K = np.linalg.solve(S, PHt.T).T
    I_KH = np.eye(x.size) - K @ H
    P = I_KH @ P @ I_KH.T + K @ R @ K.T
    return Update(x + K @ nu, symmetric(P), K, nu, S)


def observability_matrix(F: np.ndarray, H: np.ndarray) -> np.ndarray:
    """``[H; H F; H F^2; ...; H F^(n-1)]`` of a discrete pair (F, H); (F, H) is observable when
    its rank is n. python-control's ``obsv`` computes the same, but importing it costs seconds
    per process, which a Monte Carlo member should not pay for a 7x7 product."""
    n = F.shape[0]
    blocks = [np.asarray(H, dtype=float)]
    for _ in range(n - 1):
        blocks.append(blocks[-1] @ F)
    return np.vstack(blocks)


# -- stationary filter ---------------------------------------------------------------------------

def dare_doubling(F: np.ndarray, H: np.ndarray, Q: np.ndarray, R: np.ndarray, tol: float = 1e-13,
                  max_iter: int = 100) -> np.ndarray:
    """``P^-`` of the stationary filter by the structure-preserving doubling algorithm (Chu,
    Fan, Lin & Wang, Linear Algebra Appl. 396 (2005) 55): with ``A = F^T``,
    ``G = H^T R^-1 H``, ``X_0 = Q``::

        W = I + G_k X_k,  A+ = A W^-1 A,  G+ = G + A W^-1 G A^T,  X+ = X + A^T X W^-1 A

    ``X_k`` covers ``2^k`` Riccati steps, so a closed-loop pole at 1 - 5e-5 needs ~20
    iterations. Raises ValueError if it does not converge or overflows (an undetectable
    model)."""
    n = F.shape[0]
    A, G, X = F.T.copy(), H.T @ np.linalg.solve(R, H), Q.copy()
    with np.errstate(over="ignore", invalid="ignore"):  # an undetectable mode overflows: raised below
        for _ in range(max_iter):
            W = np.eye(n) + G @ X
            WA, WG = np.linalg.solve(W, A), np.linalg.solve(W, G)
            X_new = symmetric(X + A.T @ X @ WA)
            A, G = A @ WA, G + A @ WG @ A.T
            if not np.isfinite(X_new).all():
                break
            done = np.abs(X_new - X).max() <= tol * np.abs(X_new).max()
            X = X_new
            if done:
                return X
    raise ValueError("the Riccati equation did not converge (is the model detectable?)")


def solve_dare(F: np.ndarray, H: np.ndarray, Q: np.ndarray, R: np.ndarray,
               scale: np.ndarray | None = None) -> np.ndarray:
    """A-priori covariance ``P^-`` of the stationary filter (module docstring), solved in the
    states scaled by ``scale`` (typical magnitudes, default 1): scipy's
    ``solve_discrete_are`` and, where it fails, :func:`dare_doubling`."""
    T = np.diag(np.ones(F.shape[0]) if scale is None else np.asarray(scale, dtype=float))
    Ti = np.linalg.inv(T)
    Fs, Hs, Qs = Ti @ F @ T, H @ T, Ti @ Q @ Ti.T
    try:
        Ps = sla.solve_discrete_are(Fs.T, Hs.T, Qs, R)
    except (ValueError, np.linalg.LinAlgError):
        Ps = dare_doubling(Fs, Hs, Qs, R)
    return T @ symmetric(Ps) @ T


class SteadyState(NamedTuple):
    """The stationary filter: a-priori and a-posteriori covariances, gain ``K``, innovation
    covariance ``S``."""
    P_prior: np.ndarray
    P_post: np.ndarray
    K: np.ndarray
    S: np.ndarray


def steady_state(F: np.ndarray, H: np.ndarray, Q: np.ndarray, R: np.ndarray,
                 scale: np.ndarray | None = None) -> SteadyState:
    """The stationary filter of ``(F, H, Q, R)``: ``P^-`` from :func:`solve_dare`, then
    ``S = H P^- H^T + R``, ``K = P^- H^T S^-1`` and the Joseph-form ``P^+``; the fixed gain
    ``K`` is the limit of the Riccati recursion's gain."""
    P_prior = solve_dare(F, H, Q, R, scale)
    S = H @ P_prior @ H.T + R
    K = np.linalg.solve(S, H @ P_prior).T
    I_KH = np.eye(F.shape[0]) - K @ H
    P_post = I_KH @ P_prior @ I_KH.T + K @ R @ K.T
    return SteadyState(P_prior, P_post, K, S)
