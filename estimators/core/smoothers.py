r"""Fixed-interval smoothers of a linear, possibly time-varying, state-space model, run
backwards over a Kalman filter's record: Rauch-Tung-Striebel (RTS) and the modified
Bryson-Frazier (MBF) form. Both give ``x_{k|N}``, ``P_{k|N}``, the estimate conditioned on
all ``N`` samples; they are the same smoother rearranged.

Model and indexing: grid points ``k = 0 .. N-1``; ``F_k`` carries the state from ``k`` to
``k+1`` and ``Q_k`` is the noise added on the way; the filter gives at each ``k`` the
predicted ``x^-_k, P^-_k`` (before the measurement at ``k``) and the filtered ``x^+_k, P^+_k``.

RTS (Rauch, Tung & Striebel, AIAA J. 3 (1965) 1445), from ``x_{N-1|N} = x^+_{N-1}``::

    C_k       = P^+_k F_k^T (P^-_{k+1})^-1
    x_{k|N}   = x^+_k + C_k (x_{k+1|N} - x^-_{k+1})
    P_{k|N}   = P^+_k + C_k (P_{k+1|N} - P^-_{k+1}) C_k^T

Ours because filterpy's ``rts_smoother`` pairs ``P^+_k`` with ``F_{k+1}`` instead of
``F_k`` (a known filterpy bug): right only for a constant ``F``. ``(P^-)^-1`` is applied through
the Cholesky factor of the correlation matrix (:func:`spd_inverse`): a covariance whose
diagonal spans ten decades has a far better conditioned correlation matrix.

MBF (Bierman, Factorization Methods for Discrete Sequential Estimation, 1977, ch. X), with
``S_k = H_k P^-_k H_k^T + R_k``, ``K_k = P^-_k H_k^T S_k^-1``, ``nu_k = z_k - H_k x^-_k``, from
``lam^_{N-1} = 0``, ``Lam^_{N-1} = 0``::

    lam~_k = -H_k^T S_k^-1 nu_k + (I - K_k H_k)^T lam^_k
    Lam~_k =  H_k^T S_k^-1 H_k  + (I - K_k H_k)^T Lam^_k (I - K_k H_k)
    x_{k|N} = x^-_k - P^-_k lam~_k,        P_{k|N} = P^-_k - P^-_k Lam~_k P^-_k
    lam^_{k-1} = F_{k-1}^T lam~_k,         Lam^_{k-1} = F_{k-1}^T Lam~_k F_{k-1}

No covariance is inverted (only ``S``), and the adjoint runs backwards on the transpose of
the filter's closed loop ``(I - K H) F``: stable whenever the filter is. Where no measurement
was used at ``k`` (missing channels are dropped row by row), ``lam~_k = lam^_k``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

Matrices = np.ndarray | Sequence[np.ndarray]


def spd_inverse(P: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix whose diagonal spans many decades:
    Cholesky of the correlation matrix ``D^-1 P D^-1`` (``D = sqrt(diag P)``), rescaled."""
    d = 1.0 / np.sqrt(np.diag(P))
    corr = P * np.outer(d, d)
    inv = sla.cho_solve(sla.cho_factor(0.5 * (corr + corr.T)), np.eye(P.shape[0]))
    return inv * np.outer(d, d)


def _at(M: Matrices, k: int) -> np.ndarray:
    """The ``k``-th of a sequence of matrices, or the one matrix of a time-invariant model."""
    return M if isinstance(M, np.ndarray) and M.ndim == 2 else M[k]


def rts(x_post: np.ndarray, P_post: np.ndarray, F: Matrices, Q: Matrices | None = None,
        x_prior: np.ndarray | None = None, P_prior: np.ndarray | None = None
        ) -> tuple[np.ndarray, np.ndarray]:
    """RTS smoother (module docstring): ``x_post`` ``(N, n)``, ``P_post`` ``(N, n, n)``;
    ``F`` (and ``Q``) one matrix or ``N - 1`` of them (``F[k]``: ``k -> k+1``).
    ``x_prior``, ``P_prior`` ``(N, ...)``: the filter's predictions (index 0 unused); by
    default ``F_k x^+_k`` and ``F_k P^+_k F_k^T + Q_k`` (then ``Q`` is needed). Returns the
    smoothed means ``(N, n)`` and covariances ``(N, n, n)``."""
    if P_prior is None and Q is None:
        raise ValueError("rts: give Q or the predicted covariances P_prior")
    xs, Ps = np.array(x_post, dtype=float), np.array(P_post, dtype=float)
    for k in range(xs.shape[0] - 2, -1, -1):
        Fk, Pk = _at(F, k), Ps[k].copy()
        Pp = Fk @ Pk @ Fk.T + _at(Q, k) if P_prior is None else P_prior[k + 1]
        xp = Fk @ xs[k] if x_prior is None else x_prior[k + 1]
        C = Pk @ Fk.T @ spd_inverse(Pp)
        xs[k] += C @ (xs[k + 1] - xp)
        Ps[k] += C @ (Ps[k + 1] - Pp) @ C.T
    return xs, Ps


def mbf(x_prior: np.ndarray, P_prior: np.ndarray, z: np.ndarray, H: Matrices, R: Matrices,
        F: Matrices) -> tuple[np.ndarray, np.ndarray]:
    """Modified Bryson-Frazier smoother (module docstring) from the filter's predictions
    ``x_prior`` ``(N, n)``, ``P_prior`` ``(N, n, n)``, the measurements ``z`` ``(N, m)`` (a
    non-finite entry is a missing channel), ``H``, ``R`` and ``F`` (one matrix or one per
    grid point; ``F[k]``: ``k -> k+1``). Returns the smoothed means and covariances."""
    x_prior, P_prior, z = (np.asarray(a, dtype=float) for a in (x_prior, P_prior, z))
    N, n = x_prior.shape
    xs, Ps = np.empty((N, n)), np.empty((N, n, n))
    lam, Lam = np.zeros(n), np.zeros((n, n))
    eye = np.eye(n)
    for k in range(N - 1, -1, -1):
        Pk, ok = P_prior[k], np.isfinite(z[k])
        if ok.any():
            Hk, Rk = _at(H, k)[ok], _at(R, k)[np.ix_(ok, ok)]
            S = Hk @ Pk @ Hk.T + Rk
            SiH = np.linalg.solve(S, Hk)  # S^-1 H
            A = eye - Pk @ Hk.T @ SiH  # I - K H
            lam = A.T @ lam - SiH.T @ (z[k, ok] - Hk @ x_prior[k])
            Lam = Hk.T @ SiH + A.T @ Lam @ A
        xs[k] = x_prior[k] - Pk @ lam
        Ps[k] = Pk - Pk @ Lam @ Pk
        if k:
            Fk = _at(F, k - 1)
            lam, Lam = Fk.T @ lam, Fk.T @ Lam @ Fk
    return xs, 0.5 * (Ps + Ps.transpose(0, 2, 1))


def mbf_stationary(x_post: np.ndarray, nu: np.ndarray, F: np.ndarray, H: np.ndarray, K: np.ndarray,
                   S: np.ndarray, P_post: np.ndarray) -> np.ndarray:
    """Smoothed means of the stationary (fixed-gain) filter, MBF form, for a record where
    every grid point was updated: filtered ``x_post`` ``(N, n)``, innovations ``nu``
    ``(N, m)``, and the stationary ``K``, ``S``, ``P^+``. With a constant gain the adjoint
    alone is needed::

        lam~_k = -H^T S^-1 nu_k + (I - K H)^T lam^_k,   lam^_{k-1} = F^T lam~_k,
        x_{k|N} = x^+_k - P^+ lam^_k

    One ``n x n`` product per step. (RTS's constant ``C = P^+ F^T (P^-)^-1`` has the slow
    common mode of a weakly pinned filter as an eigenvalue a hair from 1: its round-off
    accumulated, and for some settings its spectral radius came out above 1.)"""
    W = nu @ np.linalg.solve(S, H)  # (H^T S^-1 nu_k)^T per grid point
    A_upd = np.eye(F.shape[0]) - K @ H  # lam @ A_upd = (I - K H)^T lam
    xs = np.empty_like(x_post)
    lam = np.zeros(F.shape[0])
    for j in range(x_post.shape[0] - 1, -1, -1):
        xs[j] = x_post[j] - P_post @ lam
        lam = F.T @ (lam @ A_upd - W[j])
    return xs
