"""The wheel-rail play's shaping filter (estimators/inertial/rail_play.py) against independent
computations: its stationary covariance solves the Lyapunov equation, its closed-form
discretisation is Van Loan's matrix exponential of the continuous model, rest is the identity,
and bad values are one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm, solve_continuous_lyapunov

from railfmu.estimators.core.discretize import van_loan
from railfmu.estimators.inertial.rail_play import RailPlay

PLAYS = [  # sigma_lateral, sigma_vertical (m), wavelength (m), damping
    (7.07e-4, 3.54e-4, 2.0, 1 / math.sqrt(2)),
    (1e-3, 0.0, 0.7, 0.2),
    (3e-3, 1e-3, 5.0, 1.0),
    (2e-4, 5e-4, 1.3, 2.5),
]


@pytest.mark.parametrize("play", PLAYS, ids=["butterworth", "light", "critical", "overdamped"])
def test_stationary_covariance_solves_the_lyapunov_equation(play):
    """P_inf from the closed form equals scipy's solution of F P + P F^T + G q G^T = 0 to 1e-9
    of its scale, and its diagonal is (sigma^2, k^2 sigma^2) per axis: the settings' sigmas."""
    rp = RailPlay(*play)
    P = rp.stationary_covariance()
    L = solve_continuous_lyapunov(rp.system_matrix(), -rp.noise_density())
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P))) + 1e-30
    assert np.abs((P - L) / scale).max() < 1e-9
    assert np.sqrt(P[0, 0]) == pytest.approx(play[0], rel=1e-12)
    assert np.sqrt(P[2, 2]) == pytest.approx(play[1], rel=1e-12)
    assert np.sqrt(P[1, 1]) == pytest.approx(2 * math.pi / play[2] * play[0], rel=1e-12)


@pytest.mark.parametrize("play", PLAYS, ids=["butterworth", "light", "critical", "overdamped"])
def test_discretisation_is_van_loans(play):
    """Phi and Q_d over distances from creeping to ten wavelengths equal scipy's expm(F ds) and
    railfmu.estimators.core.discretize.van_loan of (F, G q G^T) to 1e-10 (Phi, absolute; Q_d, of the
    stationary covariance's scale). Van Loan's exponential grows as exp(2 zeta k ds) and loses
    the digits beyond a wavelength, so it is taken over ds / 2^m <= 0.05 m and doubled m times
    (Phi <- Phi Phi, Q <- Phi Q Phi^T + Q)."""
    rp = RailPlay(*play)
    F, Qc = rp.system_matrix(), rp.noise_density()
    ds = np.array([1e-6, 0.005, 0.05, 0.37, 1.0, 3.0, 10 * play[2]])
    Phi, Qd = rp.discretize(ds)
    P = rp.stationary_covariance()
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P))) + 1e-30
    for j, d in enumerate(ds):
        m = max(0, math.ceil(math.log2(d / 0.05)))
        Phi_ref, Q_ref = van_loan(F, Qc, d / 2**m)
        for _ in range(m):
            Q_ref = Phi_ref @ Q_ref @ Phi_ref.T + Q_ref
            Phi_ref = Phi_ref @ Phi_ref
        assert np.abs(Phi[j] - expm(F * d)).max() < 1e-10
        assert np.abs(Phi[j] - Phi_ref).max() < 1e-10
        assert np.abs((Qd[j] - Q_ref) / scale).max() < 1e-10
    # the sign of ds does not matter (Markov in the distance travelled)
    assert np.array_equal(rp.discretize(-ds)[0], Phi)


def test_rest_is_the_identity():
    """ds = 0: Phi = I and Q_d = 0 exactly (the play does not change while the vehicle stands);
    zero sigmas: Q_d = 0 at any distance."""
    Phi, Qd = RailPlay(7e-4, 3.5e-4, 2.0).discretize(np.zeros(3))
    assert np.array_equal(Phi, np.broadcast_to(np.eye(4), (3, 4, 4)))
    assert not Qd.any()
    assert not RailPlay(0.0, 0.0, 2.0).discretize(np.array([0.05, 5.0]))[1].any()


def test_velocity_rows():
    """v^b_{y,z} = v_s (y', z'): the rows put the speed on the slopes."""
    H = RailPlay.velocity_rows([0.0, 1.5])
    x = np.array([1e-3, 2e-3, -5e-4, -1e-3])
    assert np.array_equal(H @ x, [[0.0, 0.0], [3e-3, -1.5e-3]])


@pytest.mark.parametrize("args, message", [
    ((1e-3, 1e-3, 0.0), "wavelength must be a finite number > 0"),
    ((-1e-3, 1e-3, 2.0), "sigma_lateral must be a finite number >= 0"),
    ((1e-3, math.nan, 2.0), "sigma_vertical must be a finite number >= 0"),
    ((1e-3, 1e-3, 2.0, 0.0), "damping must be a finite number > 0"),
])
def test_bad_values_are_one_line(args, message):
    with pytest.raises(ValueError, match=message):
        RailPlay(*args)
