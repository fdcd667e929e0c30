"""The estimation core (estimators/core/discretize.py, kalman.py, smoothers.py, ukf.py) alone,
against closed forms, textbook cases and independent implementations."""

import math

import numpy as np
import pytest
import scipy.linalg as sla
from filterpy.kalman import KalmanFilter, unscented_transform as filterpy_ut

from railfmu.estimators.core import kalman, smoothers, ukf
from railfmu.estimators.core.discretize import foh, van_loan, zoh
from railfmu.estimators.track.metrics import rms

RNG = np.random.default_rng(20260530)


def spd(n, scale=1.0):
    A = RNG.standard_normal((n, n))
    return scale * (A @ A.T + n * np.eye(n))


# -- discretisation --------------------------------------------------------------------------------

@pytest.mark.parametrize("T", [1e-3, 0.1, 2.5])
def test_zoh_double_integrator(T):
    Phi, Gamma = zoh([[0.0, 1.0], [0.0, 0.0]], [0.0, 1.0], T)
    assert np.allclose(Phi, [[1.0, T], [0.0, 1.0]], rtol=1e-14, atol=0)
    assert np.allclose(Gamma, [[T * T / 2], [T]], rtol=1e-14, atol=0)


@pytest.mark.parametrize("T", [1e-3, 0.1, 2.5])
def test_zoh_first_order_lag(T):
    """dx/dt = (k u - x) / tau: Phi = e^{-T/tau}, Gamma = k (1 - e^{-T/tau})."""
    tau, k = 0.7, 3.0
    Phi, Gamma = zoh([[-1 / tau]], [[k / tau]], T)
    assert Phi[0, 0] == pytest.approx(math.exp(-T / tau), rel=1e-14)
    assert Gamma[0, 0] == pytest.approx(k * -math.expm1(-T / tau), rel=1e-13)


@pytest.mark.parametrize("T", [1e-3, 0.1, 2.5])
def test_foh_first_order_lag_with_ramp(T):
    """dx/dt = -a x + b u + c r, u = u_k + r t over the step:
    Gamma = b (1 - e^{-aT}) / a, Gamma_rate = b (T/a - (1 - e^{-aT}) / a^2) + c (1 - e^{-aT}) / a."""
    a, b, c = 1.3, 0.4, -2.0
    Phi, G, Gr, Gz = foh([[-a]], [b], T, B_rate=[c], B_zoh=[[1.0], [2.0]][0])
    one = -math.expm1(-a * T)
    assert Phi[0, 0] == pytest.approx(math.exp(-a * T), rel=1e-14)
    assert G[0, 0] == pytest.approx(b * one / a, rel=1e-12)
    assert Gr[0, 0] == pytest.approx(b * (T / a - one / a**2) + c * one / a, rel=1e-9)
    assert Gz[0, 0] == pytest.approx(one / a, rel=1e-12)  # a held input: the ZOH column
    # without a rate the extrapolating hold is the zero-order hold
    Phi0, G0 = zoh([[-a]], [[b]], T)
    assert np.allclose(foh([[-a]], [b], T)[1], G0, rtol=1e-13) and foh([[-a]], [b], T)[3].shape == (1, 0)


def test_foh_double_integrator_is_the_exact_ramp():
    """A ramp u = u0 + r t into a double integrator: x(T) = x0 + v0 T + u0 T^2/2 + r T^3/6."""
    T = 0.3
    Phi, G, Gr, _ = foh([[0, 1], [0, 0]], [0, 1], T)
    assert np.allclose(G[:, 0], [T**2 / 2, T], rtol=1e-14)
    assert np.allclose(Gr[:, 0], [T**3 / 6, T**2 / 2], rtol=1e-14)


@pytest.mark.parametrize("T", [1e-3, 0.1, 2.5])
def test_van_loan_integrated_white_noise(T):
    """White acceleration of intensity q into (position, velocity): Q_d = q [[T^3/3, T^2/2], [T^2/2, T]]."""
    q = 0.37
    Phi, Q = van_loan(np.array([[0.0, 1.0], [0.0, 0.0]]), np.diag([0.0, q]), T)
    assert np.allclose(Phi, [[1, T], [0, 1]], rtol=1e-14, atol=0)
    assert np.allclose(Q, q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]]), rtol=1e-12, atol=0)
    assert np.array_equal(Q, Q.T)


# -- Kalman steps ------------------------------------------------------------------------------------

def test_joseph_update_equals_the_standard_form_and_stays_psd():
    n, m = 5, 3
    P, R = spd(n), spd(m, 0.1)
    H, x, z = RNG.standard_normal((m, n)), RNG.standard_normal(n), RNG.standard_normal(m)
    up = kalman.update(x, P, z, H, R)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    assert np.allclose(up.K, K, rtol=1e-12)
    assert np.allclose(up.x, x + K @ (z - H @ x), rtol=1e-12)
    assert np.allclose(up.P, (np.eye(n) - K @ H) @ P, rtol=1e-11, atol=1e-13)
    assert np.array_equal(up.P, up.P.T) and np.linalg.eigvalsh(up.P).min() > 0
    # a nearly exact measurement: the short form loses symmetry and definiteness, Joseph does not
    Rt = 1e-14 * np.eye(m)
    up = kalman.update(x, P, z, H, Rt)
    short = (np.eye(n) - up.K @ H) @ P
    assert np.array_equal(up.P, up.P.T)
    assert np.linalg.eigvalsh(up.P).min() > -1e-14 * np.abs(P).max()
    assert np.abs(short - short.T).max() > 0


def test_masked_update_equals_the_update_with_the_present_rows():
    n, m = 4, 3
    P, R = spd(n), spd(m, 0.2)
    H, x, z = RNG.standard_normal((m, n)), RNG.standard_normal(n), RNG.standard_normal(m)
    mask = np.array([True, False, True])
    a = kalman.update(x, P, z, H, R, mask=mask)
    b = kalman.update(x, P, z[mask], H[mask], R[np.ix_(mask, mask)])
    assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
    none = kalman.update(x, P, z, H, R, mask=np.zeros(m, bool))
    assert none.x is x and none.P is P and none.K.shape == (n, 0)
    # z_pred replaces H x (an extended filter's h(x)); mask applies to it too
    zp = RNG.standard_normal(m)
    c = kalman.update(x, P, z, H, R, z_pred=zp, mask=mask)
    assert np.allclose(c.x, x + b.K @ (z - zp)[mask], rtol=1e-14)


def test_predict():
    n = 3
    F, Q, P, G = RNG.standard_normal((n, n)), spd(n), spd(n), RNG.standard_normal((n, 2))
    x, u = RNG.standard_normal(n), RNG.standard_normal(2)
    xp, Pp = kalman.predict(x, P, F, Q, G, u)
    assert np.allclose(xp, F @ x + G @ u, rtol=1e-14) and np.allclose(Pp, F @ P @ F.T + Q, rtol=1e-14)
    assert np.array_equal(Pp, Pp.T)


def test_dare_scalar_closed_form():
    """x+ = a x + w, z = x + v: P^2 + (r (1 - a^2) - q) P - q r = 0."""
    a, q, r = 0.95, 0.3, 2.0
    b = r * (1 - a * a) - q
    P = (-b + math.sqrt(b * b + 4 * q * r)) / 2
    ss = kalman.steady_state(np.array([[a]]), np.array([[1.0]]), np.array([[q]]), np.array([[r]]))
    assert ss.P_prior[0, 0] == pytest.approx(P, rel=1e-13)
    assert ss.K[0, 0] == pytest.approx(P / (P + r), rel=1e-13)
    assert ss.P_post[0, 0] == pytest.approx(P * r / (P + r), rel=1e-13)


def test_dare_gain_is_the_limit_of_the_riccati_recursion():
    n, m = 4, 2
    F = sla.expm(0.1 * np.array([[0, 1, 0, 0], [-4, -0.2, 1, 0], [0, 0, 0, 1], [1, 0, -9, -0.3]]))
    H = RNG.standard_normal((m, n))
    Q, R = spd(n, 1e-3), spd(m, 1e-2)
    scale = np.array([1.0, 10.0, 0.1, 1.0])
    ss = kalman.steady_state(F, H, Q, R, scale=scale)
    P = np.eye(n)
    for _ in range(3000):
        up = kalman.update(np.zeros(n), P, np.zeros(m), H, R)
        P = kalman.predict_covariance(up.P, F, Q)
    assert np.allclose(P, ss.P_prior, rtol=1e-10, atol=1e-14)
    assert np.allclose(up.K, ss.K, rtol=1e-9, atol=1e-14)
    # the doubling algorithm (the fallback) solves the same equation
    assert np.allclose(kalman.dare_doubling(F, H, Q, R), ss.P_prior, rtol=1e-10, atol=1e-14)


def test_solve_dare_falls_back_to_doubling(monkeypatch):
    """Where scipy's QZ solver gives up (a pole too close to the unit circle), the doubling
    algorithm answers, in the same scaled states."""
    F = np.array([[1.0, 1e-3], [0.0, 1.0]])
    H, Q, R = np.array([[1.0, 0.0]]), np.diag([1e-12, 1e-8]), np.array([[1e-2]])
    scale = np.array([1e-2, 1e-1])
    expected = kalman.solve_dare(F, H, Q, R, scale)

    def gives_up(*args, **kwargs):
        raise np.linalg.LinAlgError("symplectic pencil has eigenvalues too close to the unit circle")

    monkeypatch.setattr(kalman.sla, "solve_discrete_are", gives_up)
    assert np.allclose(kalman.solve_dare(F, H, Q, R, scale), expected, rtol=1e-9, atol=0)


def test_dare_doubling_refuses_an_undetectable_model():
    F = np.diag([1.5, 0.5])
    H = np.array([[0.0, 1.0]])  # the unstable mode is not seen
    with pytest.raises(ValueError, match="did not converge"):
        kalman.dare_doubling(F, H, np.eye(2), np.eye(1), max_iter=30)


# -- smoothers ------------------------------------------------------------------------------------------

def _time_varying_problem(N=40, n=3, m=2):
    """A time-varying system (F_k, Q_k, H_k differ per step), measurements with missing channels,
    and the Kalman filter's record (kalman.predict/update)."""
    F = [sla.expm(0.2 * np.array([[0, 1 + 0.3 * math.sin(k), 0], [-1, -0.1, 0.2 * k / N], [0.1, 0, -0.05]]))
         for k in range(N - 1)]
    Q = [spd(n, 1e-3 * (1 + k % 3)) for k in range(N - 1)]
    H = [np.array([[1.0, 0.0, 0.5 * math.cos(k)], [0.0, 1.0, 1.0]]) for k in range(N)]
    R = np.diag([0.05, 0.02])
    m0, P0 = np.zeros(n), np.eye(n)
    x, X = RNG.multivariate_normal(m0, P0), []
    Z = np.empty((N, m))
    for k in range(N):
        X.append(x)
        Z[k] = H[k] @ x + RNG.multivariate_normal(np.zeros(m), R)
        if k < N - 1:
            x = F[k] @ x + RNG.multivariate_normal(np.zeros(n), Q[k])
    Z[5, 0] = Z[17, :] = Z[30, 1] = np.nan  # missing channels, one row without any
    xp, Pp, xf, Pf = (np.empty((N, n)), np.empty((N, n, n)), np.empty((N, n)), np.empty((N, n, n)))
    x, P = m0, P0
    for k in range(N):
        if k:
            x, P = kalman.predict(x, P, F[k - 1], Q[k - 1])
        xp[k], Pp[k] = x, P
        up = kalman.update(x, P, np.nan_to_num(Z[k]), H[k], R, mask=np.isfinite(Z[k]))
        x, P = up.x, up.P
        xf[k], Pf[k] = x, P
    return dict(F=F, Q=Q, H=H, R=R, m0=m0, P0=P0, Z=Z, xp=xp, Pp=Pp, xf=xf, Pf=Pf)


def _batch_smoother(p):
    """Independent: the smoothed trajectory as the weighted least-squares solution over all states
    (information form), its covariance the inverse of the information matrix."""
    F, Q, H, R, Z = p["F"], p["Q"], p["H"], p["R"], p["Z"]
    N, n = len(H), p["m0"].size
    Lam = np.zeros((N * n, N * n))
    eta = np.zeros(N * n)
    blk = lambda k: slice(k * n, (k + 1) * n)  # noqa: E731
    Lam[blk(0), blk(0)] += np.linalg.inv(p["P0"])
    eta[blk(0)] += np.linalg.solve(p["P0"], p["m0"])
    for k in range(N - 1):  # x_{k+1} - F_k x_k ~ N(0, Q_k)
        A = np.zeros((n, N * n))
        A[:, blk(k)], A[:, blk(k + 1)] = -F[k], np.eye(n)
        Lam += A.T @ np.linalg.solve(Q[k], A)
    for k in range(N):
        ok = np.isfinite(Z[k])
        Hk, Rk = H[k][ok], R[np.ix_(ok, ok)]
        Lam[blk(k), blk(k)] += Hk.T @ np.linalg.solve(Rk, Hk)
        eta[blk(k)] += Hk.T @ np.linalg.solve(Rk, Z[k][ok])
    cov = np.linalg.inv(Lam)
    return np.linalg.solve(Lam, eta).reshape(N, n), np.array([cov[blk(k), blk(k)] for k in range(N)])


def test_rts_and_mbf_equal_the_batch_smoother_on_a_time_varying_system():
    p = _time_varying_problem()
    x_b, P_b = _batch_smoother(p)
    x_r, P_r = smoothers.rts(p["xf"], p["Pf"], p["F"], p["Q"])
    x_r2, P_r2 = smoothers.rts(p["xf"], p["Pf"], p["F"], x_prior=p["xp"], P_prior=p["Pp"])
    x_m, P_m = smoothers.mbf(p["xp"], p["Pp"], p["Z"], p["H"], p["R"], p["F"])
    for x, P in ((x_r, P_r), (x_r2, P_r2), (x_m, P_m)):
        assert np.abs(x - x_b).max() < 1e-10 * np.abs(x_b).max()
        assert np.abs(P - P_b).max() < 1e-10 * np.abs(P_b).max()
    assert np.abs(x_r - x_m).max() < 1e-12 * np.abs(x_b).max()
    assert np.array_equal(x_r[-1], p["xf"][-1])  # nothing after the last sample
    # filterpy's rts_smoother pairs P^+_k with F_{k+1}: off on this system
    kf = KalmanFilter(dim_x=3, dim_z=2)
    x_f = kf.rts_smoother(p["xf"], p["Pf"], Fs=[*p["F"], p["F"][-1]], Qs=[*p["Q"], p["Q"][-1]])[0]
    assert np.abs(x_f - x_b).max() > 1e-3 * np.abs(x_b).max()


def test_mbf_stationary_equals_rts_of_the_fixed_gain_filter():
    n, m, N = 3, 2, 60
    F = sla.expm(0.1 * np.array([[0, 1, 0], [-2, -0.3, 0.5], [0, 0, -0.1]]))
    H, Q, R = RNG.standard_normal((m, n)), spd(n, 1e-3), spd(m, 1e-2)
    ss = kalman.steady_state(F, H, Q, R)
    Z = RNG.standard_normal((N, m))
    x, xf, nu = np.zeros(n), np.empty((N, n)), np.empty((N, m))
    for k in range(N):
        if k:
            x = F @ x
        nu[k] = Z[k] - H @ x
        x = x + ss.K @ nu[k]
        xf[k] = x
    xs = smoothers.mbf_stationary(xf, nu, F, H, ss.K, ss.S, ss.P_post)
    x_r, _ = smoothers.rts(xf, np.repeat(ss.P_post[None], N, 0), F, Q)
    assert np.abs(xs - x_r).max() < 1e-10 * np.abs(x_r).max()


def test_spd_inverse_of_a_badly_scaled_covariance():
    d = np.diag([1e-8, 1.0, 1e3])
    P = d @ spd(3) @ d
    Pi = smoothers.spd_inverse(P)  # inverse of the scaled matrix, checked in scaled form
    assert np.abs(d @ Pi @ d @ np.linalg.solve(d, P) @ np.linalg.inv(d) - np.eye(3)).max() < 1e-12


# -- unscented transform and UKF ------------------------------------------------------------------------

def _running_resistance_moments():
    """State (s, v, r0, r1, r2) at magnitudes like Cunillera et al. (2022): km, m/s, N/kg ..."""
    m = np.array([1234.5, 22.0, 1.2e-2, 3.1e-4, 2.2e-5])
    sd = np.array([3.0, 0.2, 1e-3, 3e-5, 2e-6])
    C = np.array([[1, 0.3, 0, 0, 0], [0.3, 1, 0.2, 0, 0], [0, 0.2, 1, -0.4, 0.1], [0, 0, -0.4, 1, -0.5],
                  [0, 0, 0.1, -0.5, 1]])
    return m, sd[:, None] * C * sd[None, :]


def test_sigma_points_of_a_linear_map_are_exact_at_tiny_alpha():
    """alpha = 1e-3, beta = 2, kappa = -2 (Wc_0 = -1.7e6): the mean and covariance of A x + b are
    A m + b and A P A^T, to round-off; the textbook sum with the huge centre weight is not."""
    n = 5
    pts = ukf.MerweScaledSigmaPoints(n, alpha=1e-3, beta=2.0, kappa=-2.0)
    assert pts.Wc[0] == pytest.approx(-1.67e6, rel=1e-2)
    m, P = _running_resistance_moments()
    dt = 1.0
    A = np.eye(n)
    A[0, 1], A[1, 2], A[1, 3], A[1, 4] = dt, -dt, -dt * 22.0, -dt * 22.0**2
    b = np.array([0.5, 0.1, 0, 0, 0])
    Y = pts.sigma_points(m, P) @ A.T + b
    y, Py = ukf.unscented_transform(Y, pts)
    exact = A @ P @ A.T
    sd = np.sqrt(np.diag(exact))
    assert np.abs(y - (A @ m + b)).max() < 1e-12 * np.abs(A @ m + b).max()
    assert np.abs((Py - exact) / np.outer(sd, sd)).max() < 1e-9
    assert np.array_equal(Py, Py.T) and np.linalg.eigvalsh(Py).min() > 0


def test_unscented_transform_does_not_depend_on_where_the_state_lies():
    """A nonlinear map at a position of 50 km (sd 1 cm) and at 0: the centre-referenced transform
    gives the same moments (measured 2e-8); the textbook sum (filterpy's unscented_transform),
    whose mean adds +-1.7e6 x 5e4, is 1e-3 sd off in the mean and 33 % in the cross-covariance."""
    n = 5
    pts = ukf.MerweScaledSigmaPoints(n, alpha=1e-3, beta=2.0, kappa=-2.0)
    sd = np.array([1e-2, 0.2, 1e-3, 3e-5, 2e-6])
    P = sd[:, None] * (np.eye(n) + 0.3 * (np.eye(n, k=1) + np.eye(n, k=-1))) * sd[None, :]

    def moments(s0, transform):
        m = np.array([s0, 22.0, 1.2e-2, 3.1e-4, 2.2e-5])
        Y = np.array([[x[0], 1e-3 * math.sin(250 * x[1])] for x in pts.sigma_points(m, P)])
        y, Py = transform(Y)
        return y - [s0, 0.0], Py

    ours = lambda Y: ukf.unscented_transform(Y, pts)  # noqa: E731
    text = lambda Y: filterpy_ut(Y, pts.Wm, pts.Wc)  # noqa: E731
    y_ref, P_ref = moments(0.0, ours)
    assert np.allclose(moments(0.0, text)[1], P_ref, rtol=1e-9)  # the two agree at the origin
    s = np.sqrt(np.diag(P_ref))
    y, Py = moments(5e4, ours)
    assert np.abs((y - y_ref) / s).max() < 1e-9 and np.abs((Py - P_ref) / np.outer(s, s)).max() < 1e-6
    y, Pt = moments(5e4, text)
    assert np.abs((y - y_ref) / s).max() > 1e-4 and abs(Pt[0, 1] / P_ref[0, 1] - 1) > 0.1


def test_ukf_of_a_linear_system_equals_the_kalman_filter():
    n = 5
    pts = ukf.MerweScaledSigmaPoints(n, alpha=1e-3, beta=2.0, kappa=-2.0)
    x, P = _running_resistance_moments()
    F = np.eye(n)
    F[0, 1], F[1, 2], F[1, 3], F[1, 4] = 1.0, -1.0, -22.0, -22.0**2
    H = np.array([[1.0, 0, 0, 0, 0], [0, 1.0, 0, 0, 0]])
    Q, R = np.diag([1e-2, 1e-3, 1e-10, 1e-14, 1e-16]), np.diag([4.0, 0.01])
    xk, Pk, xu, Pu = x, P, x, P
    for k in range(20):
        xk, Pk = kalman.predict(xk, Pk, F, Q)
        xu, Pu = ukf.predict(xu, Pu, lambda s: F @ s, Q, pts)
        z = H @ xk + np.array([1.0, -0.05]) * math.sin(k)
        mask = np.array([True, k % 4 != 3])  # the speed channel missing now and then
        a = kalman.update(xk, Pk, z, H, R, mask=mask)
        b = ukf.update(xu, Pu, z, lambda s: H @ s, R, pts, mask=mask)
        xk, Pk, xu, Pu = a.x, a.P, b.x, b.P
        sd = np.sqrt(np.diag(Pk))
        # the sigma points' own rounding (1.5 km +- 1.7e-3 sd) sets the floor: measured 1e-7
        assert np.abs((xu - xk) / sd).max() < 1e-6, k
        assert np.abs((Pu - Pk) / np.outer(sd, sd)).max() < 1e-6, k
    assert np.array_equal(Pu, Pu.T)


def test_rms():
    assert rms([3.0, -4.0]) == math.sqrt(12.5)
    assert math.isnan(rms([]))


def test_observability_matrix_equals_python_control_and_finds_an_unobservable_mode():
    import control

    rng = np.random.default_rng(4)
    F, H = rng.normal(size=(5, 5)), rng.normal(size=(2, 5))
    assert np.allclose(kalman.observability_matrix(F, H), control.obsv(F, H), rtol=1e-13, atol=0)
    # a double integrator seen through its velocity only: position is unobservable (rank 1 of 2)
    F2 = np.array([[1.0, 0.1], [0.0, 1.0]])
    assert np.linalg.matrix_rank(kalman.observability_matrix(F2, np.array([[0.0, 1.0]]))) == 1
    assert np.linalg.matrix_rank(kalman.observability_matrix(F2, np.array([[1.0, 0.0]]))) == 2
