r"""Fleet calibration: the per-run Davis estimates of one unit pooled into one, with its
uncertainty, and a change of the unit's resistance between runs flagged.

Each run k gives a posterior ``N(theta_k, P_k)`` on ``theta = (r0, r1, r2)`` (N/kg, N s/(m
kg), N s^2/(m^2 kg)) that holds the same prior ``N(theta0, Lambda0^-1)`` once
(:class:`~railfmu.estimators.train.coasting_em.CoastingEM`). The data's information of run
k is ``P_k^-1 - Lambda0``, so the pooled posterior, the prior counted once, is::

    Lambda = Lambda0 + sum_k (P_k^-1 - Lambda0)
    theta^ = Lambda^-1 (Lambda0 theta0 + sum_k (P_k^-1 theta_k - Lambda0 theta0))      (F1)

the batch least squares over all coasting segments of all runs (exact: each run's
information is a sum over its segments). Change test, in run order: run k against the
pooled estimate of the runs since the last change (``theta^_<k``, ``P^_<k``)::

    d_k = theta_k - theta^_<k,   chi2_k = d_k^T (P_k + P^_<k)^-1 d_k      (3 dof)     (F2)
    S_k = max(0, S_(k-1) + chi2_k - drift),  flag where S_k > threshold               (F3)

a CUSUM of the chi-square (``drift`` 3 x ``inflation``: its mean; the threshold one run's
chi-square at p = 1e-4 above it), with the per-run covariance scaled by ``inflation`` (the
run-to-run scatter of the estimates beyond their stated covariance: rounding errors that are
not independent, the driver). After a flag the pool restarts at the flagged run.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def pool(thetas: Sequence, covariances: Sequence, theta0=None, prior_cov=None) -> tuple[np.ndarray, np.ndarray]:
    """(F1): the pooled ``(theta^, covariance)`` of runs ``thetas`` (each 3) with
    ``covariances`` (each 3x3); ``theta0, prior_cov``: the prior every run holds once (None:
    no prior, inverse-covariance weighting)."""
    L0 = np.zeros((3, 3)) if prior_cov is None else np.linalg.inv(np.asarray(prior_cov, float))
    m0 = np.zeros(3) if theta0 is None else L0 @ np.asarray(theta0, float)
    A, b = L0.copy(), m0.copy()
    for th, P in zip(thetas, covariances):
        Li = np.linalg.inv(np.asarray(P, float))
        A += Li - L0
        b += Li @ np.asarray(th, float) - m0
    C = np.linalg.inv(A)
    return C @ b, 0.5 * (C + C.T)


def change_test(thetas: Sequence, covariances: Sequence, theta0=None, prior_cov=None, inflation: float = 4.0,
                threshold: float = 21.1) -> dict:
    """(F2, F3) over the runs in order: per run its ``chi2`` and CUSUM ``S``, the runs
    flagged (0-based), the first flag (or None), and the pooled ``theta``, ``cov`` of the runs
    since the last flag."""
    chi2, S, flags = [], [], []
    start, s = 0, 0.0
    drift = 3.0
    for k in range(len(thetas)):
        if k - start >= 1:
            th, C = pool(thetas[start:k], covariances[start:k], theta0, prior_cov)
            d = np.asarray(thetas[k], float) - th
            c2 = float(d @ np.linalg.solve(inflation * (np.asarray(covariances[k], float) + C), d))
        else:
            c2 = 0.0
        s = max(0.0, s + c2 - drift)
        chi2.append(c2)
        S.append(s)
        if s > threshold:
            flags.append(k)
            start, s = k, 0.0
    th, C = pool(thetas[start:], covariances[start:], theta0, prior_cov)
    return {"chi2": chi2, "cusum": S, "flagged_runs": flags, "first_flag": flags[0] if flags else None,
            "theta": th, "cov": C, "since_run": start}


def resistance_band(theta: np.ndarray, cov: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r(v) = theta^T (1, v, v^2) (N/kg) and its standard deviation at speeds ``v`` (m/s)."""
    X = np.c_[np.ones_like(v), v, v * v]
    return X @ theta, np.sqrt(np.einsum("ij,jk,ik->i", X, cov, X))
