"""Chord irregularity errors, their prediction and the closed forms (Jiang et al. (2017), § 5):
against exact geometry (a circular arc's bow, a sinusoidal error), invariances, the 12-state
simplified system integrated numerically, and the exact Gaussian max statistic."""

import math

import numpy as np
import pytest
import scipy.linalg as sla
from mpmath import mp

from railfmu.estimators.inertial.chord_accuracy import (
    DEFAULT_SAMPLES,
    NOMINAL,
    alignment_variance,
    chord_error_jacobian,
    chord_error_statistics,
    chord_errors,
    chord_grid,
    chord_sigma_from_covariance,
    closed_form_sigma,
    nominal_chord_accuracy,
    nominal_run,
    sensitivity_curves,
    level_variance,
    linear_chord_errors,
    predict_chord_sigma,
    survey_chords,
)

D2R = math.pi / 180.0
G = 9.8
#: the paper's nominal (§ 5): 0.006 deg tilt, 0.01 deg/h gyro bias, 50 ug accelerometer bias
P_PHI, P_EPS, P_NABLA = (0.006 * D2R) ** 2, (0.01 * D2R / 3600.0) ** 2, (50e-6 * G) ** 2
SIGMA_V, SIGMA_R = 1e-4, 0.1


def straight(s, azimuth=0.0):
    """Points of a straight level track at distances s (n0 NED, m)."""
    s = np.asarray(s, dtype=float)
    return np.stack([s * math.cos(azimuth), s * math.sin(azimuth), 0.0 * s], axis=-1)


# ---- grid ----

def test_grid_takes_the_nearest_sample_once_per_stop_and_leaves_out_what_is_not_reached():
    rng = np.random.default_rng(3)
    moving = np.sort(rng.uniform(0.0, 45.2, 3000))
    dist = np.concatenate([np.zeros(40), moving[moving < 30.0], np.full(40, 30.0), moving[moving > 30.0]])
    g = chord_grid(dist)
    assert g.distance[0] == 0.0 and g.distance[-1] == 45.0 and g.distance.size == 91
    assert np.unique(g.sample).size == g.distance.size  # no point twice
    for x, i in zip(g.distance, g.sample):
        assert abs(dist[i] - x) == np.abs(dist - x).min()
    assert g.sample[0] == 0 and g.sample[60] == 40 + np.sum(moving < 30.0)  # the first of each stop
    # only [0, 30] is surveyed: 51 points, each needs s, s + 5 and the ends 0, 30
    assert g.chord_start.tolist() == [0.0] and g.n_points == 51
    assert np.allclose(g.distance[g.index[0]], g.s) and np.allclose(g.distance[g.index[1]], g.s + 5.0)
    assert set(g.distance[g.index[2]]) == {0.0} and set(g.distance[g.index[3]]) == {30.0}
    # a run that starts at 3.2 m and ends at 61 m surveys [30, 60] only
    g2 = chord_grid(np.linspace(3.2, 61.0, 2000))
    assert g2.distance[0] == 3.5 and g2.chord_start.tolist() == [30.0] and g2.s[0] == 30.0 and g2.s[-1] == 55.0
    # shorter than a chord: no chord point, NaN statistics
    g3 = chord_grid(np.linspace(0.0, 29.0, 300))
    r3 = straight(g3.distance)
    assert g3.n_points == 0
    st = chord_error_statistics(*chord_errors(g3, r3, np.zeros_like(r3)))
    assert all(math.isnan(x) for x in st.values())
    assert math.isnan(predict_chord_sigma(g3, r3, np.zeros((5,) + r3.shape)).sigma_level_mm)
    with pytest.raises(ValueError):
        chord_grid(np.array([0.0, 2.0, 1.0]))


# ---- exact chord errors ----

def test_bow_of_a_circular_arc():
    """Estimated points on a circular arc of radius R (bending left of north), truth on the
    straight line: the midpoint's vector distance is the sagitta R (1 - cos(l / 2R)) = l^2 / (8 R)
    + O(l^4 / R^3), and every chord error is R (cos(u_s / R) - cos(u_{s+5} / R)), u the arc
    length from the chord's middle, on every chord (the arc turns, the geometry does not)."""
    R, L = 400.0, 90.0
    g = chord_grid(np.linspace(0.0, L, 901))
    s = g.distance
    th = s / R
    arc = np.stack([R * np.sin(th), -R * (1.0 - np.cos(th)), np.zeros_like(s)], axis=-1)
    r = straight(s)
    a, v = chord_errors(g, r, arc - r)
    u = (g.s - g.chord_start.repeat(51)) - 15.0
    expected = R * (np.cos(u / R) - np.cos((u + 5.0) / R))
    assert np.abs(a - expected).max() < 1e-12 and np.abs(v).max() < 1e-12
    # the bow itself: the errors at 15, 20, 25 m telescope to d_15 - d_30 = d_15, the sagitta
    # (to the right: the arc bulges away from its centre, which is left)
    bow = sum(a[np.flatnonzero(g.s == x)[0]] for x in (15.0, 20.0, 25.0))
    assert bow == pytest.approx(R * (1.0 - math.cos(15.0 / R)), rel=1e-12)
    assert bow == pytest.approx(30.0 ** 2 / (8.0 * R), abs=30.0 ** 4 / (384.0 * R ** 3) * 1.01)
    assert abs(bow - 30.0 ** 2 / (8.0 * R)) > 30.0 ** 4 / (384.0 * R ** 3) * 0.99
    # and a vertical arc (sagging down) is a level error of the same size, no alignment error
    sag_v = np.stack([R * np.sin(th), np.zeros_like(s), R * (1.0 - np.cos(th))], axis=-1)
    a, v = chord_errors(g, r, sag_v - r)
    assert np.abs(v + expected).max() < 1e-12 and np.abs(a).max() < 1e-12


def test_a_lateral_and_vertical_sinusoidal_error_gives_the_known_chord_error():
    """Straight level track at N45E; errors y = A sin(2 pi s / lam) to the right and
    z = B sin(...) down. Exact vector distances against the erroneous chord (as
    test_track_geometry's closed form): dy = y(c + 30) - y(c), hor = |(30, dy)|,
    d_y(x) = ((y(x) - y(c)) 30 - (x - c) dy) / hor, d_z = ((z(x) - z(c)) hor - a_h dz) / l."""
    A, B, lam, az = 2e-3, 1.5e-3, 13.0, math.radians(45.0)
    dist = np.linspace(0.0, 60.0, 1201)
    g = chord_grid(dist)
    s = g.distance
    right = np.array([-math.sin(az), math.cos(az), 0.0])
    y = lambda x: A * np.sin(2 * np.pi * x / lam)  # noqa: E731
    z = lambda x: B * np.sin(2 * np.pi * x / lam)  # noqa: E731
    e = y(s)[:, None] * right + z(s)[:, None] * np.array([0.0, 0.0, 1.0])
    a, v = chord_errors(g, straight(s, az), e)

    def closed(x, c):
        dy, dz = y(c + 30) - y(c), z(c + 30) - z(c)
        hor = math.hypot(30.0, dy)
        lc = math.hypot(hor, dz)

        def d(p):
            ah = ((p - c) * 30.0 + (y(p) - y(c)) * dy) / hor
            return ((y(p) - y(c)) * 30.0 - (p - c) * dy) / hor, ((z(p) - z(c)) * hor - ah * dz) / lc
        (a0, v0), (a5, v5) = d(x), d(x + 5.0)
        return a0 - a5, v0 - v5

    for j, c in enumerate(g.chord_start):
        sel = slice(51 * j, 51 * (j + 1))
        ac, vc = closed(g.s[sel], c)
        assert np.abs(a[sel] - ac).max() < 1e-13 and np.abs(v[sel] - vc).max() < 1e-13
    assert np.abs(a).max() > 1e-3 and np.abs(v).max() > 1e-3
    st = chord_error_statistics(a, v)
    assert st["chord_alignment_max_error_mm"] == pytest.approx(1e3 * np.abs(a).max(), rel=1e-15)
    assert st["chord_level_rms_error_mm"] == pytest.approx(1e3 * math.sqrt(np.mean(v * v)), rel=1e-14)
    # samples: leading axes carry through
    two = chord_errors(g, straight(s, az), np.stack([e, 2 * e]))
    assert two[0].shape == (2, g.n_points) and np.allclose(two[0][0], a, atol=1e-18)
    assert chord_error_statistics(*two)["chord_alignment_max_error_mm"].shape == (2,)


def test_translation_and_heading_rotation_give_no_chord_error():
    rng = np.random.default_rng(7)
    g = chord_grid(np.linspace(0.0, 90.0, 1801))
    s = g.distance
    r = straight(s, 0.7) + np.stack([0 * s, 0.3 * np.sin(s / 40.0), 0.02 * np.cos(s / 17.0)], axis=-1)
    a, v = chord_errors(g, r, np.broadcast_to(rng.normal(0.0, 0.1, 3), r.shape))
    assert np.abs(a).max() < 1e-13 and np.abs(v).max() < 1e-13
    # the whole survey turned about the vertical through any point: the same chords
    c, sn = math.cos(0.01), math.sin(0.01)
    Rz = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    turned = (r - r[17]) @ Rz.T + r[17]
    a, v = chord_errors(g, r, turned - r)
    assert np.abs(a).max() < 1e-13 and np.abs(v).max() < 1e-13


def test_the_linear_map_is_eqs_21_22_and_the_linearisation_error_is_second_order():
    g = chord_grid(np.linspace(0.0, 60.0, 601))
    r = straight(g.distance)  # due north, level: eqs. 21-22 hold exactly to first order
    J = chord_error_jacobian(g, r)
    k = 5.0 / 30.0
    eq21 = np.zeros((4, 3))
    eq21[:, 1] = [1.0, -1.0, -k, k]  # e_E(s) - e_E(s + 5) + k (e_E(30) - e_E(0))
    eq22 = np.zeros((4, 3))
    eq22[:, 2] = [1.0, -1.0, -k, k]
    assert np.abs(J[0] - eq21).max() < 1e-9 and np.abs(J[1] - eq22).max() < 1e-9
    # smooth errors like a smoother's: drifts of the given size, random per sample set
    rng = np.random.default_rng(11)
    s = g.distance
    basis = np.stack([np.ones_like(s), s / 30, (s / 30) ** 2, (s / 30) ** 3, np.sin(s / 7.0)], axis=-1)
    offs = []
    for size in (1e-3, 0.1):
        e = size * np.einsum("nb,kbi->kni", basis, rng.normal(size=(200, 5, 3))) / 3.0
        a, v = chord_errors(g, r, e)
        la, lv = linear_chord_errors(g, J, e)
        offs.append(max(np.abs(a - la).max(), np.abs(v - lv).max()) / np.abs(a).max())
        print(f"errors of {size} m: chord errors up to {np.abs(a).max():.3g} m, linearisation off by "
              f"{offs[-1]:.3g} of it")
    assert 1e-5 < offs[0] < 3e-4  # millimetre chord errors: the covariance map is exact to 1e-4
    assert 0.5e2 < offs[1] / offs[0] < 2e2  # second order: the relative error grows with the error


# ---- closed forms (eqs. 29-31) against the 12-state simplified system ----

def simplified_system(g=G):
    """Eq. 20: eq. 7 without Earth rate and Coriolis; f^n = (0, 0, -g)."""
    A = np.zeros((12, 12))
    A[0, 9] = A[2, 10] = -1.0  # phi' = -eps
    A[3, 1], A[4, 0] = g, -g  # dv_N' = -f_D phi_E, dv_E' = f_D phi_N
    A[5, 11] = 1.0  # dv_D' = nabla_D
    A[6, 3] = A[7, 4] = A[8, 5] = 1.0
    return A


def smoothed_joint_covariance(times, T, p_phi, p_eps, p_nabla, sigma_v, sigma_r, g=G, digits=30):
    """The RTS smoother on eq. 20, eq. 25's P0 (p_dv = sigma_v^2, p_dr = sigma_r^2, or
    0.01 m^2 without position updates), one velocity (+ position) update at ``T``: the joint
    covariance of the smoothing errors at ``times`` (sorted, the last = T), (n 12, n 12).
    In ``digits``-digit arithmetic (mpmath): a chord error is a 1e-3 difference of position
    errors and the tilt makes P^- nearly singular, so doubles would leave ~1e-4 of it."""
    with mp.workdps(digits):
        A = mp.matrix(simplified_system(g).tolist())
        p_dr = sigma_r ** 2 if math.isfinite(sigma_r) else 0.01
        P0 = mp.diag([p_phi] * 3 + [sigma_v ** 2] * 3 + [p_dr] * 3 + [p_eps] * 2 + [p_nabla])
        n = len(times)
        Phi = [mp.expm(A * (mp.mpf(times[i + 1]) - mp.mpf(times[i]))) for i in range(n - 1)]
        Pm, Pp = [P0], []
        for i in range(n):
            P = Pm[i]
            if times[i] == T:
                rows = [3, 4, 5] + ([6, 7, 8] if math.isfinite(sigma_r) else [])
                H = mp.matrix(np.eye(12)[rows].tolist())
                R = mp.diag([sigma_v ** 2] * 3 + ([sigma_r ** 2] * 3 if math.isfinite(sigma_r) else []))
                K = P * H.T * (H * P * H.T + R) ** -1
                IKH = mp.eye(12) - K * H
                P = IKH * P * IKH.T + K * R * K.T
            Pp.append(P)
            if i < n - 1:
                Pm.append(Phi[i] * P * Phi[i].T)
        Ps, C = [None] * n, [None] * n
        Ps[-1] = Pp[-1]
        for i in range(n - 2, -1, -1):
            C[i] = Pp[i] * Phi[i].T * Pm[i + 1] ** -1
            Ps[i] = Pp[i] + C[i] * (Ps[i + 1] - Pm[i + 1]) * C[i].T
        J = mp.zeros(12 * n, 12 * n)
        for j in range(n):
            M = Ps[j]
            for i in range(j, -1, -1):  # Cov(e_i, e_j) = C_i ... C_{j-1} P_j
                if i < j:
                    M = C[i] * M
                for a in range(12):
                    for b in range(12):
                        J[12 * i + a, 12 * j + b] = J[12 * j + b, 12 * i + a] = M[a, b]
        return J


def chord_variance_numerically(t_s, k, T, sigma_r, p_phi=P_PHI, p_eps=P_EPS, p_nabla=P_NABLA, sigma_v=SIGMA_V):
    times = [0.0, t_s, t_s + k * T, T]
    Jc = smoothed_joint_covariance(times, T, p_phi, p_eps, p_nabla, sigma_v, sigma_r)
    out = []
    for comp in (7, 8):  # dr_E (eq. 21), dr_D (eq. 22)
        c = np.zeros(48)
        c[[comp, 12 + comp, 24 + comp, 36 + comp]] = [-k, 1.0, -1.0, k]
        cm = mp.matrix(c.tolist())
        out.append(float((cm.T * Jc * cm)[0]))
    return out


@pytest.mark.parametrize("k, sigma_r", [(1.0 / 6.0, 0.1), (1.0 / 6.0, math.inf), (0.25, 1e-3), (0.25, math.inf)])
def test_closed_forms_equal_the_smoothed_12_state_system(k, sigma_r):
    T = 30.0
    for t_s in (0.4, 7.3, 0.5 * (1 - k) * T + 1.1, (1 - k) * T - 0.2):
        vy, vz = chord_variance_numerically(t_s, k, T, sigma_r)
        cy = alignment_variance(t_s, k, T, G, P_PHI, P_EPS, SIGMA_V, sigma_r)
        cz = level_variance(t_s, k, T, P_NABLA, SIGMA_V)
        assert cy == pytest.approx(vy, rel=1e-12) and cz == pytest.approx(vz, rel=1e-12)
    # a case where every term matters (velocity update poor, large biases)
    vy, vz = chord_variance_numerically(5.0, k, T, sigma_r, p_eps=(1.0 * D2R / 3600) ** 2,
                                        p_nabla=(500e-6 * G) ** 2, sigma_v=3e-3)
    cy = alignment_variance(5.0, k, T, G, P_PHI, (1.0 * D2R / 3600) ** 2, 3e-3, sigma_r)
    assert cy == pytest.approx(vy, rel=1e-12)
    assert level_variance(5.0, k, T, (500e-6 * G) ** 2, 3e-3) == pytest.approx(vz, rel=1e-12)


def paper_eq29(t, k, T, g, pf, pe, sv, sr):
    """Eq. 29 as printed (the paper's chord, k = 1/6)."""
    sv2, sr2 = sv * sv, sr * sr
    D = (sv2 * sr2 + 9 * k ** 2 * (sv2 ** 2 + 2 * g ** 2 * pf * sr2) * T ** 2
         + 162 * k ** 4 * g ** 2 * (pf * sv2 + pe * sr2) * T ** 4 + 1620 * k ** 6 * g ** 2 * pe * sv2 * T ** 6
         + 2916 * k ** 8 * g ** 4 * pf * pe * T ** 8)
    return (k ** 2 * g ** 2 * T ** 2 * pf * sv2 * (sr2 + 9 * k ** 2 * sv2 * T ** 2) * (2 * t - 5 * k * T) ** 2 / (4 * D)
            + k ** 2 * g ** 2 * T ** 2 * pe * sv2 * (sr2 + 9 * k ** 2 * sv2 * T ** 2)
            * (3 * t ** 2 + 3 * k * T * t - 35 * k ** 2 * T ** 2) ** 2 / (36 * D)
            + k ** 4 * g ** 4 * T ** 4 * pf * pe * sr2
            * (3 * t ** 2 - 15 * k * T * t + 10 * k ** 2 * T ** 2) ** 2 / (2 * D)
            + 9 * k ** 6 * g ** 4 * T ** 6 * pf * pe * sv2
            * (9 * t ** 4 - 90 * k * T * t ** 3 + 321 * k ** 2 * T ** 2 * t ** 2 - 480 * k ** 3 * T ** 3 * t
               + 325 * k ** 4 * T ** 4) / (2 * D))


def paper_eq31(t, k, T, g, pf, pe, sv):
    sv2 = sv * sv
    D = sv2 + 18 * k ** 2 * g ** 2 * pf * T ** 2 + 162 * k ** 4 * g ** 2 * pe * T ** 4
    return (k ** 2 * g ** 2 * T ** 2 * pf * sv2 * (2 * t - 5 * k * T) ** 2 / (4 * D)
            + k ** 2 * g ** 2 * T ** 2 * pe * sv2 * (3 * t ** 2 + 3 * k * T * t - 35 * k ** 2 * T ** 2) ** 2 / (36 * D)
            + k ** 4 * g ** 4 * T ** 4 * pf * pe * (3 * t ** 2 - 15 * k * T * t + 10 * k ** 2 * T ** 2) ** 2 / (2 * D))


def test_at_the_papers_chord_the_closed_forms_are_the_printed_eqs_29_to_31():
    k, T = 1.0 / 6.0, 30.0
    t = np.linspace(0.0, 25.0, 51)
    for pe, sv, sr in ((P_EPS, SIGMA_V, SIGMA_R), (100 * P_EPS, 1e-3, 0.01), (P_EPS, 3e-5, 1.0)):
        assert np.allclose(alignment_variance(t, k, T, G, P_PHI, pe, sv, sr), paper_eq29(t, k, T, G, P_PHI, pe, sv, sr),
                           rtol=1e-12, atol=0)
        assert np.allclose(alignment_variance(t, k, T, G, P_PHI, pe, sv), paper_eq31(t, k, T, G, P_PHI, pe, sv),
                           rtol=1e-12, atol=0)
        eq30 = (k ** 2 * P_NABLA * sv ** 2 * T ** 2 * (5 * k * T - 2 * t) ** 2
                / (4 * (sv ** 2 + 18 * k ** 2 * P_NABLA * T ** 2)))
        assert np.allclose(level_variance(t, k, T, P_NABLA, sv), eq30, rtol=1e-12, atol=1e-30)
    # the paper's remarks: monotone in sigma_v and sigma_r; sigma_r barely matters
    sy = [closed_form_sigma(t, k, T, G, P_PHI, P_EPS, P_NABLA, sv, SIGMA_R)[0].max() for sv in (1e-5, 1e-4, 1e-3)]
    assert sy[0] < sy[1] < sy[2]
    without = closed_form_sigma(t, k, T, G, P_PHI, P_EPS, P_NABLA, SIGMA_V)[0].max()
    with_r = closed_form_sigma(t, k, T, G, P_PHI, P_EPS, P_NABLA, SIGMA_V, SIGMA_R)[0].max()
    assert with_r < without < with_r * (1 + 1e-5)  # 10 cm landmarks: 3e-6 of it
    with_mm = closed_form_sigma(t, k, T, G, P_PHI, P_EPS, P_NABLA, SIGMA_V, 1e-3)[0].max()
    assert 0.99 * without < with_mm < 0.995 * without  # 1 mm landmarks: 0.8 % less


# ---- the sampled prediction against the exact Gaussian max statistic ----

def simplified_run(T=30.0, v=1.0, sigma_r=SIGMA_R):
    """The simplified case on a straight track due north at speed v: the grid, the true
    positions, the smoothed covariance at 0 and the map x0 -> position errors at the grid."""
    g = chord_grid(np.linspace(0.0, v * T, 3001))
    t = g.distance / v
    A = simplified_system()
    P0s = np.array(smoothed_joint_covariance([0.0, T], T, P_PHI, P_EPS, P_NABLA, SIGMA_V, sigma_r).tolist(),
                   dtype=float)[:12, :12]
    Gmap = np.stack([sla.expm(A * x)[6:9] for x in t])  # (n_grid, 3, 12)
    return g, straight(g.distance), P0s, Gmap


def sqrtm_psd(P):
    w, V = np.linalg.eigh(0.5 * (P + P.T))
    return V * np.sqrt(np.clip(w, 0.0, None))


def exact_rms_of_max(W):
    """sqrt(E[max_n (W z)_n^2]) for z ~ N(0, I) when W (n, m) has rank <= 2: with the two
    singular directions, W z = M u r, u = (cos th, sin th), E r^2 = 2, th uniform."""
    U, sv, _ = np.linalg.svd(W, full_matrices=False)
    M = U[:, :2] * sv[:2]
    assert sv[2:].max(initial=0.0) < 1e-6 * sv[0]
    th = (np.arange(200000) + 0.5) * np.pi / 200000
    h2 = np.zeros_like(th)
    for row in M:  # max over points of (m . u)^2, point by point
        h2 = np.maximum(h2, (row[0] * np.cos(th) + row[1] * np.sin(th)) ** 2)
    return math.sqrt(2.0 * h2.mean())


def test_sampled_prediction_matches_the_exact_max_statistic_and_the_closed_forms():
    g, r, P0s, Gmap = simplified_run()
    L = sqrtm_psd(P0s)
    # exact: the chord errors are linear in x0 = L z; alignment of rank 2 (phi_N, eps_N), level rank 1
    J = chord_error_jacobian(g, r)
    Gs = np.stack([Gmap[i] for i in g.index], axis=1)  # (n, 4, 3, 12)
    Wy = np.einsum("nui,nuij->nj", J[0], Gs) @ L
    Wz = np.einsum("nui,nuij->nj", J[1], Gs) @ L
    exact_y, exact_z = exact_rms_of_max(Wy), exact_rms_of_max(Wz)
    # the covariance map gives the closed forms point by point
    t_s = g.s
    vy = alignment_variance(t_s, 1 / 6, 30.0, G, P_PHI, P_EPS, SIGMA_V, SIGMA_R)
    vz = level_variance(t_s, 1 / 6, 30.0, P_NABLA, SIGMA_V)
    assert np.allclose(np.sum(Wy ** 2, axis=1), vy, rtol=1e-6) and np.allclose(np.sum(Wz ** 2, axis=1), vz, rtol=1e-6)
    assert exact_z == pytest.approx(math.sqrt(vz.max()), rel=1e-6)  # rank 1: the max pointwise sigma
    # sampled: error trajectories from the smoothed Gaussian, through the exact chord map
    rng = np.random.default_rng(2024)
    S = 4000
    e = np.einsum("nij,sj->sni", Gmap, rng.standard_normal((S, 12)) @ L.T)
    p = predict_chord_sigma(g, r, e)
    assert p.n_samples == S
    assert abs(p.sigma_alignment_mm - 1e3 * exact_y) < 4 * p.relative_se_alignment * 1e3 * exact_y
    assert abs(p.sigma_level_mm - 1e3 * exact_z) < 4 * p.relative_se_level * 1e3 * exact_z
    # its stated precision: se / RMS = std(M^2) / (2 sqrt(S) mean(M^2)) and the level M^2 is chi^2_1
    assert p.relative_se_level * 2 * math.sqrt(S) == pytest.approx(math.sqrt(2.0), rel=0.1)
    assert 1.0 < p.relative_se_alignment * 2 * math.sqrt(S) < 1.45
    assert np.allclose(p.pointwise_alignment_mm, 1e3 * np.sqrt(vy), rtol=5 / math.sqrt(2 * S))
    assert np.allclose(p.pointwise_level_mm, 1e3 * np.sqrt(vz), rtol=5 / math.sqrt(2 * S))
    assert p.metrics() == {"predicted_sigma_alignment_mm": p.sigma_alignment_mm,
                           "predicted_sigma_level_mm": p.sigma_level_mm,
                           "predicted_peak_sigma_alignment_mm": p.pointwise_alignment_mm.max(),
                           "predicted_peak_sigma_level_mm": p.pointwise_level_mm.max()}
    # the max over the chord's points exceeds the largest pointwise sigma (the paper's statistic)
    assert p.sigma_alignment_mm > p.pointwise_alignment_mm.max()


def test_pointwise_sigma_from_a_joint_covariance_is_the_closed_form():
    g, r, P0s, Gmap = simplified_run(sigma_r=1e-3)
    cov = np.einsum("aij,jk,blk->aibl", Gmap, P0s, Gmap).reshape(3 * g.distance.size, 3 * g.distance.size)
    sy, sz = chord_sigma_from_covariance(g, r, cov)
    vy = alignment_variance(g.s, 1 / 6, 30.0, G, P_PHI, P_EPS, SIGMA_V, 1e-3)
    vz = level_variance(g.s, 1 / 6, 30.0, P_NABLA, SIGMA_V)
    assert np.allclose(sy, np.sqrt(vy), rtol=1e-6) and np.allclose(sz, np.sqrt(vz), rtol=1e-6)


# ---- the covariance analysis of the aided INS (railfmu.estimators.inertial.aided_ins) ----

@pytest.mark.parametrize("position", [False, True])
def test_covariance_analysis_of_the_simplified_case_gives_the_closed_forms(position):
    """The full error model reduces to eq. 20 at the equator on a straight track due north
    without sensor noise, with constant biases and ~no heading error (Earth rate and Coriolis
    then leave the alignment and level channels but for < 1e-3): one update at the end
    (velocity, and position when ``position``) gives eqs. 29-31 point by point."""
    from railfmu.models import earth
    run = nominal_run(azimuth=0.0, latitude=0.0, position_updates=position)
    run.zupt[0] = run.position[0] = False
    grade = {"gyro_arw_deg_sqrt_h": 0.0, "accel_noise_ug_sqrt_hz": 0.0, "gyro_bias_correlation_time": math.inf,
             "accel_bias_correlation_time": math.inf}
    res = nominal_chord_accuracy(run, **{**NOMINAL, **grade, "heading_sigma": 1e-6, "position_sigma": SIGMA_R,
                                         "landmark_sigma": SIGMA_R})
    p_eps = (0.01 * D2R / 3600.0) ** 2  # the nominal's constant (turn-on) biases
    p_nabla = (50e-6 * 9.80665) ** 2
    g0 = earth.gravity(0.0, 0.0)
    sy, sz = closed_form_sigma(run.grid.s, 1 / 6, 30.0, g0, P_PHI, p_eps, p_nabla, SIGMA_V,
                               SIGMA_R if position else math.inf)
    off_y = np.abs(res["pointwise_alignment_mm"] / (1e3 * sy) - 1).max()
    off_z = np.abs(res["pointwise_level_mm"] - 1e3 * sz).max() / (1e3 * sz.max())
    print(f"covariance analysis vs eqs. 29-31: alignment {off_y:.2g} relative, level {off_z:.2g} of its max")
    # level: absolute (its sigma is 0 at t_s = (1 - k) T / 2); the free-air term 2 g / a dr_D,
    # which eq. 20 leaves out, is 6e-4 of nabla_D for 0.1 m position errors
    assert off_y < 1e-5 and off_z < 1e-3
    assert res["alignment_mm"] == pytest.approx(1e3 * sy.max(), rel=1e-3)


def test_sensitivity_curves_follow_the_papers_remarks():
    axes = {"zupt_sigma": (np.array([0.03, 0.1, 0.3]), "mm/s", 1e-3),
            "tilt_sigma": (np.array([0.002, 0.02]), "deg", D2R),
            "heading_sigma": (np.array([0.02, 0.2]), "deg", D2R),
            "gyro_turn_on_bias_sigma_deg_h": (np.array([0.003, 0.03]), "deg/h", 1.0),
            "accel_turn_on_bias_sigma_ug": (np.array([10.0, 200.0]), "ug", 1.0)}
    c = sensitivity_curves(axes)
    nom = c["nominal"]
    # the paper's nominal (0.1 mm/s, 0.005 deg/sqrt(h), 10 ug/sqrt(Hz), constant biases of
    # 0.01 deg/h and 50 ug, 0.006 / 0.06 deg): the largest pointwise sigma on the 30 m chord is
    # the paper's Fig. 12 figure, 0.99 mm (alignment) and 0.70 mm (level), within 3 %
    print(f"nominal: largest pointwise sigma {nom['alignment_mm']:.4f} / {nom['level_mm']:.4f} mm")
    assert nom["alignment_mm"] == pytest.approx(0.99, rel=0.03)
    assert nom["level_mm"] == pytest.approx(0.70, rel=0.03)
    z = c["zupt_sigma"]
    assert np.all(np.diff(z["alignment_mm"]) > 0) and np.all(np.diff(z["level_mm"]) > 0)  # Fig. 8
    assert z["alignment_mm"][1] == pytest.approx(nom["alignment_mm"], rel=1e-9)
    # position updates at the ends change neither (Fig. 8; eq. 30; eq. 29 barely)
    assert np.allclose(z["alignment_mm_position"], z["alignment_mm"], rtol=3e-3)
    assert np.allclose(z["level_mm_position"], z["level_mm"], rtol=3e-3)
    # the level does not see the attitude errors nor the gyro biases (Figs. 10, 11) ...
    for name in ("tilt_sigma", "heading_sigma", "gyro_turn_on_bias_sigma_deg_h"):
        lv = c[name]["level_mm"]
        assert abs(lv[1] / lv[0] - 1) < 1e-3, name
    # ... while the alignment grows with the heading error and the gyro bias
    assert c["heading_sigma"]["alignment_mm"][1] > 1.05 * c["heading_sigma"]["alignment_mm"][0]
    gb = c["gyro_turn_on_bias_sigma_deg_h"]["alignment_mm"]
    assert gb[1] > 1.01 * gb[0]
    # the accelerometer bias does not act on the alignment (eq. 29 has no nabla) and on the level
    # only a little (Fig. 11: "small"; eq. 30 saturates: a constant bias is pinned by the two ZUPTs)
    ab = c["accel_turn_on_bias_sigma_ug"]
    assert abs(ab["alignment_mm"][1] / ab["alignment_mm"][0] - 1) < 1e-3
    assert ab["level_mm"][0] < ab["level_mm"][1] < 1.01 * ab["level_mm"][0]


def rms_of_max_of_independent_normals(n: int) -> float:
    """sqrt(E[max_i Z_i^2]) of n independent |N(0, 1)|: E[M^2] = int_0^inf 2x (1 - (2 Phi(x) - 1)^n) dx."""
    from scipy import integrate, special

    val, _ = integrate.quad(lambda x: 2 * x * (1 - special.erf(x / math.sqrt(2)) ** n), 0, 40)
    return math.sqrt(val)


def test_rms_of_max_of_independent_normals():
    assert rms_of_max_of_independent_normals(1) == pytest.approx(1.0, rel=1e-9)  # E[Z^2] = 1
    z = np.abs(np.random.default_rng(0).standard_normal((200_000, 51))).max(axis=1)
    assert rms_of_max_of_independent_normals(51) == pytest.approx(math.sqrt(np.mean(z**2)), rel=0.01)


def test_prediction_from_the_smoothers_samples_agrees_with_its_joint_covariance():
    """On the paper's nominal run: the pointwise sigma from ``error_samples`` through the exact
    chord map equals the one from ``joint_covariance`` through the linear map, and the
    predicted RMS of the max lies above the largest pointwise sigma (a max of 51 points)."""
    from railfmu.estimators.inertial.aided_ins import covariance_analysis
    run = nominal_run()
    ca = covariance_analysis(run.times, run.f_n, run.C_bn, run.latitude, run.velocity, run.zupt, **NOMINAL)
    m = run.grid_epochs.size
    cov = ca.joint_covariance(run.grid_epochs).reshape(m, 12, m, 12)[:, 6:9, :, 6:9].reshape(3 * m, 3 * m)
    sy, sz = chord_sigma_from_covariance(run.grid, run.true_positions, cov)
    S = 4000
    p = predict_chord_sigma(run.grid, run.true_positions, ca.error_samples(run.times[run.grid_epochs], S, 5))
    assert np.allclose(p.pointwise_alignment_mm, 1e3 * sy, rtol=5 / math.sqrt(2 * S))
    assert np.allclose(p.pointwise_level_mm, 1e3 * sz, rtol=5 / math.sqrt(2 * S))
    # the RMS of the max of n points lies between the largest pointwise sigma (fully correlated
    # points) and that sigma times the RMS of the max of n independent |N(0, 1)|
    upper = rms_of_max_of_independent_normals(sy.size)
    assert 1e3 * sy.max() < p.sigma_alignment_mm < upper * 1e3 * sy.max()
    assert 1e3 * sz.max() < p.sigma_level_mm < upper * 1e3 * sz.max()
    # the stated precision: std(M^2) / mean(M^2) ~ 0.78 here, so 0.39 / sqrt(S)
    assert 0.3 < p.relative_se_alignment * math.sqrt(S) < 0.5 and 0.3 < p.relative_se_level * math.sqrt(S) < 0.5
    print(f"nominal: max pointwise sigma {1e3 * sy.max():.3f} / {1e3 * sz.max():.3f} mm, predicted RMS of the "
          f"max {p.sigma_alignment_mm:.3f} / {p.sigma_level_mm:.3f} mm (alignment / level)")


def test_survey_chords_of_a_record_gives_the_study_metrics():
    """A 200 Hz record of the nominal run with a stop at each end, errors drawn from the
    covariance analysis: the metrics are those of the grid samples, the prediction attached."""
    from railfmu.estimators.inertial.aided_ins import covariance_analysis
    run = nominal_run()
    ca = covariance_analysis(run.times, run.f_n, run.C_bn, run.latitude, run.velocity, run.zupt, **NOMINAL)
    t = np.arange(0.0, 30.0 + 1e-9, 0.005)
    dist = np.clip(t - 1.0, 0.0, 28.0) * 30.0 / 28.0  # 1 s at rest, 28 s moving, 1 s at rest
    truth = straight(dist, math.radians(45.0))
    err = ca.error_samples(t, 1, seed=3)[0]
    sv = survey_chords(dist, truth, err, times=t, smoother=ca, n_samples=300, seed=4)
    assert sorted(sv.metrics) == sorted(["chord_alignment_max_error_mm", "chord_level_max_error_mm",
                                         "chord_alignment_rms_error_mm", "chord_level_rms_error_mm",
                                         "predicted_sigma_alignment_mm", "predicted_sigma_level_mm",
                                         "predicted_peak_sigma_alignment_mm", "predicted_peak_sigma_level_mm"])
    g = chord_grid(dist)
    a, v = chord_errors(g, truth[g.sample], err[g.sample])
    assert sv.metrics["chord_level_max_error_mm"] == 1e3 * np.abs(v).max()
    assert np.array_equal(sv.alignment, a) and sv.prediction.n_samples == 300
    assert g.sample[0] == 0 and dist[g.sample[-1]] == 30.0 and np.all(dist[g.sample[1:]] > 0)
    assert 0.5 < sv.metrics["predicted_sigma_alignment_mm"] < 3.0
    assert survey_chords(dist, truth, err).prediction is None
