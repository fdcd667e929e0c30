r"""Exact sampling of linear continuous-time models: zero-order hold, the first-order hold our
FMUs use, and the process noise by Van Loan's method. All by one matrix exponential
(``scipy.linalg.expm``), exact for the linear model at any step ``dt`` (s).

Zero-order hold (input constant over the step)::

    dx/dt = A x + B u,   u(t_k + tau) = u_k
    expm([[A, B], [0, 0]] dt) = [[Phi, Gamma], [0, I]]
    x_{k+1} = Phi x_k + Gamma u_k,     Phi = e^{A dt},  Gamma = int_0^dt e^{A s} ds B

First-order hold, extrapolating (the FMUs' rate input: ``README``, "How a model becomes an
FMU"): the input goes on with its known rate ``r_k`` over the step, which may also act on the
state directly (``B_rate``)::

    dx/dt = A x + B u + B_rate r,   u(t_k + tau) = u_k + r_k tau,   r(t_k + tau) = r_k
    expm([[A, B_zoh, B, B_rate], [0, 0, 0, 0], [0, 0, 0, I], [0, 0, 0, 0]] dt)
        = [[Phi, Gamma_zoh, Gamma, Gamma_rate], ...]
    x_{k+1} = Phi x_k + Gamma_zoh v_k + Gamma u_k + Gamma_rate r_k

``B_zoh`` carries further inputs ``v`` held constant (a sensitivity column, for example).
This is not the triangle hold of ``control.sample_system(..., 'foh')``, which interpolates
to ``u_{k+1}`` (not causal); it is what a co-simulation slave does with an input and its
derivative, so the discretisation reproduces the FMU to its integrator's accuracy.

Process noise (Van Loan, IEEE TAC 23 (1978) 395) of ``dx = A x dt + dw``,
``E[dw dw^T] = Q_c dt``::

    expm([[-A, Q_c], [0, A^T]] dt) = [[., Phi^-1 Q_d], [0, Phi^T]],   Q_d = Phi (Phi^-1 Q_d)
    Q_d = int_0^dt e^{A s} Q_c e^{A^T s} ds

Why not ``control.sample_system``: importing python-control costs seconds per process, its
``foh`` is the triangle hold (above), and it has no noise discretisation.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla


def _columns(M: np.ndarray | None, n: int, name: str) -> np.ndarray:
    if M is None:
        return np.zeros((n, 0))
    M = np.asarray(M, dtype=float)
    M = M[:, None] if M.ndim == 1 else M
    if M.ndim != 2 or M.shape[0] != n:
        raise ValueError(f"{name} must have {n} rows, not shape {M.shape}")
    return M


def zoh(A: np.ndarray, B: np.ndarray | None, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Gamma)`` of ``dx/dt = A x + B u`` with ``u`` held constant over ``dt`` (s):
    ``x_{k+1} = Phi x_k + Gamma u_k`` (module docstring). ``B`` None: ``Gamma`` is ``(n, 0)``."""
    Phi, _, _, Gamma = foh(A, None, dt, B_zoh=B)
    return Phi, Gamma


def foh(A: np.ndarray, B: np.ndarray | None, dt: float, B_rate: np.ndarray | None = None,
        B_zoh: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(Phi, Gamma, Gamma_rate, Gamma_zoh)`` of ``dx/dt = A x + B u + B_rate r + B_zoh v``
    with ``u`` extrapolated over the step by its rate ``r`` (one rate per column of ``B``;
    ``B_rate`` defaults to no direct effect) and ``v`` held:
    ``x_{k+1} = Phi x_k + Gamma u_k + Gamma_rate r_k + Gamma_zoh v_k`` (module docstring).
    1-D ``B``/``B_rate``/``B_zoh`` are single columns; a missing one gives an ``(n, 0)``
    ``Gamma``."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    B = _columns(B, n, "B")
    m = B.shape[1]
    B_rate = np.zeros((n, m)) if B_rate is None else _columns(B_rate, n, "B_rate")
    if B_rate.shape[1] != m:
        raise ValueError(f"B_rate needs one column per input of B ({m}), not {B_rate.shape[1]}")
    B_zoh = _columns(B_zoh, n, "B_zoh")
    e = B_zoh.shape[1]
    # block order [x, v, u, r]: the matrix the estimators built by hand, so their results stay bit for bit
    N = n + e + 2 * m
    M = np.zeros((N, N))
    M[:n, :n] = A
    M[:n, n:n + e] = B_zoh
    M[:n, n + e:n + e + m] = B
    M[:n, n + e + m:] = B_rate
    M[n + e:n + e + m, n + e + m:] = np.eye(m)  # du/dt = r
    E = sla.expm(M * dt)
    return E[:n, :n], E[:n, n + e:n + e + m], E[:n, n + e + m:], E[:n, n:n + e]


def van_loan(A: np.ndarray, Q_c: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Q_d)`` of ``dx = A x dt + dw``, ``E[dw dw^T] = Q_c dt``, sampled at ``dt``
    (Van Loan's method, module docstring); ``Q_d`` symmetrised."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = Q_c
    M[n:, n:] = A.T
    E = sla.expm(M * dt)
    Phi = E[n:, n:].T
    Q_d = Phi @ E[:n, n:]
    return Phi, 0.5 * (Q_d + Q_d.T)
