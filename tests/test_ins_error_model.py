"""The INS error model of the aided filter (estimators/inertial/ins_error_model.py): its sampling against
Van Loan's matrix exponential, its error growth against the nonlinear strapdown INS run twice
on the trolley's increments, the measurement rows against the nonlinear functions, and the
observability statement of its docstring."""

from __future__ import annotations

import io
import math
import shutil

import fmpy
import numpy as np
import pandas as pd
import pytest

from railfmu.estimators.inertial.attitude import dcm_from_rph, perturb
from railfmu.estimators.core.discretize import van_loan
from railfmu.estimators.inertial.ins_error_model import (
    DR,
    DV,
    PHI,
    ErrorModel,
    ImuGrade,
    attitude_error,
    corrected_position,
    ned_difference,
    observability_gramian,
)
from railfmu.estimators.inertial.strapdown import Strapdown
from railfmu.models import earth

DEG = math.pi / 180
LAT = 30.5 * DEG
INC = [f"trolley.{k}" for k in ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")]
CONSTANT = ImuGrade(gyro_bias_correlation_time=math.inf, accel_bias_correlation_time=math.inf)


def moving_A(model: ErrorModel) -> np.ndarray:
    """A trolley accelerating through a curve: f^n with a horizontal part, tilted body."""
    C = dcm_from_rph(0.02, -0.01, 0.8)
    return model.system_matrix(LAT, 25.0, np.array([0.7, 0.7, 0.01]), np.array([0.3, -0.2, -9.79]), C)


@pytest.mark.parametrize("kind", ["paper12", "full15"])
def test_sampling_against_van_loan(kind):
    """Phi (Taylor to A^4) and Q_d (3-point Gauss-Legendre) against expm (Van Loan). Measured at
    0.05 s: Phi to 2e-15 absolute, Q_d to 6e-16 of each entry's scale sqrt(Q_ii Q_jj); at 0.5 s
    2e-10 and 1.5e-13 (the A^5 term)."""
    model = ErrorModel(kind)
    A = moving_A(model)
    for T, tol_phi, tol_q in ((0.05, 1e-14, 1e-14), (0.5, 1e-9, 1e-12)):
        Phi_ref, Q_ref = van_loan(A, model.Qc, T)
        Phi, Q = model.discretize(A, T)
        assert np.abs(Phi - Phi_ref).max() < tol_phi
        scale = np.sqrt(np.outer(np.diag(Q_ref), np.diag(Q_ref)))
        assert (np.abs(Q - Q_ref) / scale).max() < tol_q
        # the stacked form gives the same
        Phis, Qs = model.discretize(np.stack([A, A]), np.array([T, T]))
        assert np.array_equal(Phis[1], Phi) and np.array_equal(Qs[0], Q)
    # the white noises reach the position: accel q T^3 / 3, the closed form
    _, Q = model.discretize(A, 0.05)
    q_a = model.grade.accel_noise ** 2
    assert Q[6, 6] == pytest.approx(q_a * 0.05 ** 3 / 3, rel=1e-3)


def test_a_is_equation_7():
    """paper12's A on a level straight track at rest (f = (0, 0, -g)) is eq. 7 of Jiang et al.
    (2017) entry by entry (with the gravity gradient added at (dv_D, dr_D))."""
    model = ErrorModel("paper12", CONSTANT)
    g = earth.gravity(LAT, 0.0)
    A = model.system_matrix(LAT, 0.0, np.zeros(3), np.array([0.0, 0.0, -g]), np.eye(3))
    W, s, c = earth.RATE, math.sin(LAT), math.cos(LAT)
    E = np.zeros((12, 12))
    E[0, 1], E[0, 9] = -W * s, -1
    E[1, 0], E[1, 2] = W * s, W * c
    E[2, 1], E[2, 10] = -W * c, -1
    fN, fE, fD = 0.0, 0.0, -g
    E[3, 1], E[3, 2], E[3, 4] = -fD, fE, -2 * W * s
    E[4, 0], E[4, 2], E[4, 3], E[4, 5] = fD, -fN, 2 * W * s, 2 * W * c
    E[5, 0], E[5, 1], E[5, 4], E[5, 11] = -fE, fN, -2 * W * c, 1
    E[6:9, 3:6] = np.eye(3)
    E[5, 8] = 2 * earth.gravity(LAT, 0.0) / earth.A
    assert np.abs(A - E).max() < 1e-18


@pytest.fixture(scope="module")
def trolley(tmp_path_factory, fmu_dir):
    """45 s of the survey (10 s rest, 35 s pushed along the straight) at 5 ms: signals."""
    if shutil.which("gcc") is None or fmpy.platform != "linux64":
        pytest.skip("needs gcc on linux64")
    from railfmu.experiments.engine.runner import run_experiment
    out = tmp_path_factory.mktemp("trolley45")
    run_experiment("trolley_survey", "ideal_imu", out=out, stop_time=45.0, step_size=0.005, master="container",
                   progress=False, log=io.StringIO())
    return pd.read_csv(out / "signals.csv")


def _ins(row, dr=(0.0, 0.0, 0.0), dv=(0.0, 0.0, 0.0), phi=(0.0, 0.0, 0.0)) -> Strapdown:
    lat, lon, h = corrected_position(row["trolley.latitude"], row["trolley.longitude"], row["trolley.height"],
                                     -np.asarray(dr))
    C = perturb(dcm_from_rph(row["trolley.roll"], row["trolley.pitch"], row["trolley.heading"]), -np.asarray(phi))
    v = np.array([row["trolley.vn"], row["trolley.ve"], row["trolley.vd"]]) + dv
    from railfmu.estimators.inertial.attitude import rph_from_dcm
    return Strapdown.from_rph(float(lat), float(lon), float(h), v, rph_from_dcm(C), 0.005)


def _epochs(ins: Strapdown, U: np.ndarray, m: int) -> list[tuple]:
    """The INS at every m-th sample: (lat, lon, h, v, C)."""
    from railfmu.estimators.inertial.aided_ins import _dcm
    out = [(ins.lat, ins.lon, ins.h, np.array([ins.vn, ins.ve, ins.vd]), _dcm(tuple(ins.quaternion())))]
    for i in range(1, U.shape[0], m):
        ins.integrate(U[i:i + m])
        out.append((ins.lat, ins.lon, ins.h, np.array([ins.vn, ins.ve, ins.vd]), _dcm(tuple(ins.quaternion()))))
    return out


@pytest.mark.parametrize("kind", ["paper12", "full15"])
def test_linear_error_growth_against_the_nonlinear_ins(trolley, kind):
    """The strapdown INS twice on the same ideal increments (10 s at rest, then 30 s pushed
    along the track), once from the true state and once from a perturbed one (tilt 1e-4 rad,
    heading 1e-3 rad, velocity 1 mm/s, position 5 cm, and gyro 0.01 deg/h / accelerometer
    50 ug biases added to its increments); their difference against ``prod Phi_k x_0`` with
    ``Phi_k`` from the unperturbed INS as the filter builds it. Measured at 40 s (position
    error ~0.2 m in N, E): the linear prediction is within 2e-4 of the error in position,
    velocity and attitude -- the second-order terms (1e-3 rad x the error) and the neglected
    delta-omega_in terms; a wrong sign or a missing Coriolis/Earth-rate term is 1e-2 and more."""
    U = trolley[INC].to_numpy()[: int(40 / 0.005) + 1]
    row = trolley.iloc[0]
    model = ErrorModel(kind, CONSTANT)
    phi0, dv0, dr0 = np.array([1e-4, -1e-4, 1e-3]), np.array([1e-3, -1e-3, 5e-4]), np.array([0.05, -0.05, 0.02])
    C0 = dcm_from_rph(row["trolley.roll"], row["trolley.pitch"], row["trolley.heading"])
    eps_n, nab_n = np.array([0.01, 0.0, 0.01]) * DEG / 3600, np.array([0.0, 0.0, 50e-6 * 9.80665])
    if kind == "paper12":  # n-frame biases, constant on the straight (C within 1e-3 of C0)
        bg, ba = C0.T @ eps_n, C0.T @ nab_n
        x0 = np.r_[phi0, dv0, dr0, eps_n[0], eps_n[2], nab_n[2]]
    else:
        bg, ba = np.array([3e-8, -4e-8, 5e-8]), np.array([4e-4, -5e-4, 3e-4])
        x0 = np.r_[phi0, dv0, dr0, bg, ba]
    Up = U.copy()
    Up[1:, :3] += bg * 0.005
    Up[1:, 3:] += ba * 0.005
    nominal = _ins(row)
    nominal.prime(U[0, :3], U[0, 3:])
    perturbed = _ins(row, dr0, dv0, phi0)
    perturbed.prime(Up[0, :3], Up[0, 3:])
    m = 10
    nom, per = _epochs(nominal, U, m), _epochs(perturbed, Up, m)
    x = x0.copy()
    worst = np.zeros(3)
    for k in range(1, len(nom)):
        (la0, _, h0, v0, Ca), (la1, _, h1, v1, Cb) = nom[k - 1], nom[k]
        T = m * 0.005
        lat_m, h_m, v_m = 0.5 * (la0 + la1), 0.5 * (h0 + h1), 0.5 * (v0 + v1)
        w2 = 2 * earth.earth_rate_n(lat_m) + earth.transport_rate_n(lat_m, h_m, v_m)
        f = (v1 - v0) / T + np.cross(w2, v_m) - np.array([0, 0, earth.gravity(lat_m, h_m)])
        Phi, _ = model.discretize(model.system_matrix(lat_m, h_m, v_m, f, 0.5 * (Ca + Cb)), T)
        x = Phi @ x
        lat, lon, h, v, C = per[k]
        la, lo, hh, vv, Ct = nom[k]
        true_err = np.r_[attitude_error(C, Ct), v - vv, ned_difference(lat, lon, h, la, lo, hh)]
        for i, sl in enumerate((PHI, DV, DR)):
            worst[i] = max(worst[i], np.abs(x[sl] - true_err[sl]).max() / np.abs(true_err[sl]).max())
    assert np.abs(true_err[DR]).max() > 0.1  # the error did grow
    assert np.all(worst < [5e-4, 2e-3, 1.5e-3]), worst


def test_measurement_rows_against_the_nonlinear_functions():
    """``body_velocity_rows`` is the Jacobian of ``v~^b = C~^T v~`` with ``C~ = (I - [phi x]) C``:
    finite differences agree to 1e-7 of the entries."""
    model = ErrorModel("full15")
    C = dcm_from_rph(0.03, -0.02, 0.9)
    v = np.array([0.8, 0.6, -0.02])
    H = model.body_velocity_rows(C, v)

    def body_velocity(x):
        phi = x[PHI]
        Cc = perturb(C, -phi)  # exp(-[phi x]) C = (I - [phi x]) C to first order
        return Cc.T @ (v + x[DV])

    J = np.zeros((3, model.n))
    for i in range(model.n):
        dx = np.zeros(model.n)
        dx[i] = 1e-6
        J[:, i] = (body_velocity(dx) - body_velocity(-dx)) / 2e-6
    assert np.abs(J - H).max() < 1e-7
    assert np.array_equal(model.velocity_rows()[:, DV], np.eye(3))
    assert np.array_equal(model.position_rows()[:, DR], np.eye(3))


def _stop_and_go(model: ErrorModel, landmarks: bool, T: float = 0.5):
    """Straight level track N45E: 10 s stop, 60 m at 1 m/s (2 s ramps), 5 s stop, again."""
    g = earth.gravity(LAT, 0.0)
    psi = 45 * DEG
    C, u = dcm_from_rph(0.0, 0.0, psi), np.array([math.cos(psi), math.sin(psi), 0.0])
    phases = [(10, 0.0, True), (2, 0.5, False), (56, 0.0, False), (2, -0.5, False), (5, 0.0, True),
              (2, 0.5, False), (56, 0.0, False), (2, -0.5, False), (5, 0.0, True)]
    Phis, Hs, Rs, v, first = [], [], [], 0.0, True
    for duration, a, stop in phases:
        for i in range(round(duration / T)):
            if not first:
                A = model.system_matrix(LAT, 0.0, (v + 0.5 * a * T) * u, a * u + np.array([0, 0, -g]), C)
                Phis.append(model.discretize(A, T)[0])
                v += a * T
            first = False
            H, R = [], []
            if stop:
                H, R = [model.velocity_rows()], [1e-8] * 3
                if landmarks and i == 0:
                    H, R = H + [model.position_rows()], R + [1e-2] * 3
            Hs.append(np.vstack(H) if H else np.zeros((0, model.n)))
            Rs.append(np.diag(R) if R else np.zeros((0, 0)))
    W = observability_gramian(np.array(Phis), Hs, Rs)
    S = np.sqrt(np.diag(model.initial_covariance(0.006 * DEG, 0.06 * DEG, 1e-4, 0.1)))
    return np.linalg.eigh(S[:, None] * W * S[None, :])


@pytest.mark.parametrize("kind, landmarks, unobserved", [("paper12", False, 4), ("paper12", True, 1),
                                                          ("full15", False, 7), ("full15", True, 4)])
def test_observability_of_a_stop_and_go_survey(kind, landmarks, unobserved):
    """The module docstring's statement: the directions whose information over the run is below
    the prior's (eigenvalues < 1 of the P0-scaled Gramian) -- positions without landmarks,
    eps_D always, and in full15 the tilt/bias and heading/bias combinations. The observed ones
    clear 1 by a factor of 15 at least (the heading by gyrocompassing), the unobserved stay
    below 0.25."""
    model = ErrorModel(kind)
    w, V = _stop_and_go(model, landmarks)
    assert (w < 1).sum() == unobserved, w
    assert w[unobserved - 1] < 0.25 and w[unobserved] > 2.9
    null = V[:, :unobserved]
    eps_d = np.zeros(model.n)
    eps_d[10 if kind == "paper12" else 11] = 1.0  # eps_D (paper12) / the body z gyro (level: down)
    assert np.linalg.norm(null.T @ eps_d) > 0.99  # eps_D lies in the unobserved subspace
    if not landmarks:
        for i in (6, 7, 8):
            assert np.linalg.norm(null.T @ np.eye(model.n)[i]) > 0.999  # no position is observed


def test_bad_grade_and_model_are_one_line():
    with pytest.raises(ValueError, match="error_model must be one of paper12, full15"):
        ErrorModel("paper15")
    with pytest.raises(ValueError, match="gyro_arw_deg_sqrt_h must be a number >= 0"):
        ImuGrade(gyro_arw_deg_sqrt_h=-1.0)
    with pytest.raises(ValueError, match="accel_bias_correlation_time must be > 0"):
        ImuGrade(accel_bias_correlation_time=0.0)


def test_turn_on_biases_are_random_constants_in_the_model():
    """The paper's "piecewise constant" biases: turn-on sigmas only -> P0 holds them, no process
    noise, no decay; both kinds -> P0 is the sum and the state a random walk of the GM intensity."""
    from railfmu.estimators.inertial.ins_error_model import ErrorModel, ImuGrade

    const = ImuGrade(gyro_bias_instability_deg_h=0.0, accel_bias_instability_ug=0.0,
                     gyro_turn_on_bias_sigma_deg_h=0.01, accel_turn_on_bias_sigma_ug=50.0)
    for kind, gyro, accel in (("paper12", (9, 10), (11,)), ("full15", (9, 10, 11), (12, 13, 14))):
        m = ErrorModel(kind, const)
        P0 = m.initial_covariance(1e-4, 1e-3, 1e-4, 0.1)
        A = m.system_matrix(0.5, 0.0, (1.0, 0.0, 0.0), (0.0, 0.0, -9.8), np.eye(3))
        for i in gyro:
            assert P0[i, i] == pytest.approx((0.01 * np.pi / 180 / 3600) ** 2, rel=1e-12)
        for i in accel:
            assert P0[i, i] == pytest.approx((50e-6 * 9.80665) ** 2, rel=1e-12)
        for i in (*gyro, *accel):
            assert A[i, i] == 0.0 and m.Qc[i, i] == 0.0
    both = ErrorModel("paper12", ImuGrade(accel_turn_on_bias_sigma_ug=30.0))
    s_b = both.grade.accel_bias_sigma
    assert both.initial_covariance(1e-4, 1e-3, 1e-4, 0.1)[11, 11] == pytest.approx(s_b**2 + (30e-6 * 9.80665) ** 2)
    A = both.system_matrix(0.5, 0.0, (1.0, 0.0, 0.0), (0.0, 0.0, -9.8), np.eye(3))
    assert A[11, 11] == 0.0 and both.Qc[11, 11] == pytest.approx(2 * s_b**2 / 3600.0)
    assert A[9, 9] == pytest.approx(-1 / 3600.0)  # the gyro has no turn-on bias: exact GM
