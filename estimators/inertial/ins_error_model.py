r"""The INS error model of the trolley survey's aided filter (Jiang et al. (2017), §4, eqs. 2-10):
continuous error dynamics, their sampling over one Kalman-filter epoch, the initial covariance
and the measurement rows of the aiding (zero velocity, landmark position, non-holonomic
constraint, odometer).

Error state (NED, SI units), ``paper12`` (the paper's eq. 6)::

    x = (phi_N, phi_E, phi_D, dv_N, dv_E, dv_D, dr_N, dr_E, dr_D, eps_N, eps_D, nabla_D)

``full15``: ``phi, dv, dr`` and the body-frame gyro and accelerometer biases
``b_g = (b_gx, b_gy, b_gz)`` (rad/s), ``b_a = (b_ax, b_ay, b_az)`` (m/s2), the biases of the
``ImuErrors`` FMU (``models/inertial/imu_errors.py``). Conventions:

* ``phi`` (rad): the computed attitude is ``C_b^n(computed) = (I - [phi x]) C_b^n(true)`` (the
  psi-angle convention of the paper and of Savage). ``railfmu.estimators.inertial.attitude.perturb``'s rotation
  vector (``StrapdownINS``'s ``tilt_error_*``, ``heading_error``) is ``e = -phi``.
* ``dv = v_computed - v_true`` (m/s), ``dr = r_computed - r_true`` (m, local NED:
  ``dr_N = (R_N + h) dL``, ``dr_E = (R_E + h) cos L dlambda``, ``dr_D = -dh``).
* sensor errors: measured rate ``omega~ = omega + b_g + w_g``, specific force ``f~ = f + b_a + w_a``.

Dynamics (eq. 2 with the paper's eqs. 3-4; ``omega_in = omega_ie + omega_en``)::

    phi' = -omega_in^n x phi - eps^n - C_b^n w_g
    dv'  =  f^n x phi - (2 omega_ie^n + omega_en^n) x dv + (2 g / a) dr_D e_D + nabla^n + C_b^n w_a
    dr'  =  dv
    paper12:  eps^n = (eps_N, 0, eps_D),  nabla^n = (0, 0, nabla_D)  (n-frame, "equivalent" biases)
    full15:   eps^n = C_b^n b_g,          nabla^n = C_b^n b_a
    bias' = -bias / T_c + w_b,   E[w_b w_b^T] = 2 sigma_b^2 / T_c      (first-order Gauss-Markov)

This is eq. 7 (A) and eq. 8 (G) in their full form: the Earth-rate terms of ``phi`` (the
``-Omega sin L``, ``Omega cos L`` entries), the Coriolis terms of ``dv``, and the specific force
``f^n`` of the epoch (not the straight-track ``f = (0, 0, -g)`` of the paper's §5 simplification,
eq. 20). Added to eq. 7 because they cost nothing: the transport rate ``omega_en`` (1.6e-7
rad/s at 1 m/s, 0.2 % of the Earth rate) and the vertical gravity gradient ``2 g / a``
(3.1e-6 /s2, the mechanisation's free-air term).
Neglected, as in the paper: the rates' dependence on the position and velocity errors
(``delta omega_in``, ``(2 delta omega_ie + delta omega_en) x v``: coefficients ``v / R`` =
1.6e-7 /s and below) and the frame difference ``C_n0^n ~ I`` within a survey segment; over
a 60 s interval they change the error growth by < 1e-5 of its size. The paper's
straight-track simplifications (§5: ``f^n = (0, 0, -g)``, no Earth rate or Coriolis, eq. 20)
are used only by the closed forms of the chord error (eqs. 29-31), not here.

Noise (eq. 10 from the grade, :class:`ImuGrade`): gyro angle random walk ``N_g`` (rad/sqrt(s))
and accelerometer velocity random walk ``N_a`` (m/s/sqrt(s)) as white rate and specific-force
noises of PSD ``N_g^2``, ``N_a^2`` per axis. ``C_b^n diag(q) C_n^b = q I`` for equal axes, so
``G Q G^T`` does not depend on the attitude. The paper takes its biases as random constants
("piecewise constant"); here they are the ``ImuErrors`` FMU's Gauss-Markov processes
(``sigma_b = GM_SIGMA_PER_B B`` for the datasheet bias instability ``B``, correlation time
``T_c``), so the filter's model is the simulation's; ``T_c = inf`` gives the paper's constants.

Sampling over one epoch ``T`` (the filter period, 0.05 s): ``A`` is held at the epoch's mean
specific force and mid-epoch attitude. ``Phi = exp(A T)`` by its Taylor series to the fourth
power; ``Q_d = int_0^T exp(A s) Q_c exp(A^T s) ds`` by three-point Gauss-Legendre quadrature
with the same series at the nodes (exact for integrands of degree <= 5 in ``s``, which covers
the dominant terms: white specific force into position ``s^2``, white rate into position
``s^4``). Against Van Loan's matrix exponential (``railfmu.estimators.core.discretize.van_loan``) on a
moving trolley's ``A``: at ``T = 0.05 s`` ``Phi`` and ``Q_d`` (relative to each entry's scale
``sqrt(Q_ii Q_jj)``) agree to round-off, at 0.5 s to the truncated ``A^5`` term (the bounds
asserted in ``tests/test_ins_error_model.py``). Stacked over the epochs of a block, it costs a
fraction of one ``expm`` per epoch.

Observability (:func:`observability_gramian`, ``tests/test_ins_error_model.py``): a straight
level track heading N45E at 30.5 deg N, two 60 m runs at 1 m/s between stops with zero-velocity
updates (0.1 mm/s) at every stop epoch. A direction counts as observed when the run's
information on it exceeds the prior's (eigenvalue > 1 of the Gramian scaled by the P0 sigmas:
0.006 deg tilt, 0.06 deg heading, 0.1 mm/s, 0.1 m, the grade's bias sigmas):

* ``paper12``, ZUPT only: 8 of 12. Not observed: ``dr_N, dr_E, dr_D`` (nothing measures a
  position; ``dr_D`` reaches the velocity only through the gravity gradient ``2 g / a``: nil)
  and ``eps_D`` (the vertical gyro bias turns the heading, which reaches the velocity only
  through the Earth rate: 1e-4 of its prior over the run). The heading is observed weakly
  (gyrocompassing through ``phi_E' = Omega cos L phi_D``: 16 times its prior information).
  With landmark fixes at the stops (0.1 m): 11 of 12, ``eps_D`` remains.
* ``full15``, ZUPT only: 8 of 15. Not observed: the three positions, and four combinations of
  attitude and body biases: with the attitude constant the horizontal accelerometer biases
  cannot be told from the tilts (``dv_N' = g phi_E + nabla_N``, two directions), the east gyro
  bias not from the heading (``phi_E' = Omega cos L phi_D - eps_E``) and the vertical gyro
  bias barely at all -- the paper's reason to leave ``eps_E, nabla_N, nabla_E`` out of its 12
  states. With landmarks: 11 of 15. The tilt-equivalent biases are absorbed into ``phi`` by
  the 12-state filter: its attitude estimate carries ``nabla / g`` (~5e-5 rad for 50 ug) and
  its heading ``eps_E / (Omega cos L)`` (~8e-4 rad for 0.01 deg/h); a constant rotation of
  the surveyed line, which the chords do not see.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from railfmu.models import earth
from railfmu.models.inertial.imu_errors import ACCEL_SI, GM_SIGMA_PER_B, GYRO_BIAS_SI, GYRO_NOISE_SI

PAPER12 = ("phi_n", "phi_e", "phi_d", "dv_n", "dv_e", "dv_d", "dr_n", "dr_e", "dr_d", "eps_n", "eps_d", "nabla_d")
FULL15 = ("phi_n", "phi_e", "phi_d", "dv_n", "dv_e", "dv_d", "dr_n", "dr_e", "dr_d",
          "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z")
MODELS = {"paper12": PAPER12, "full15": FULL15}
PHI, DV, DR = slice(0, 3), slice(3, 6), slice(6, 9)

# three-point Gauss-Legendre nodes and weights on [0, 1]
_GL_X = 0.5 * (1.0 + np.array([-math.sqrt(0.6), 0.0, math.sqrt(0.6)]))
_GL_W = np.array([5.0, 8.0, 5.0]) / 18.0


def skews(v) -> np.ndarray:
    """``[v x]`` (the matrix with ``[v x] u = v x u``) of each row of ``v`` ``(M, 3)`` -> ``(M, 3, 3)``."""
    v = np.asarray(v, dtype=float)
    S = np.zeros((v.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


@dataclass(frozen=True)
class ImuGrade:
    """The IMU's error densities in the ``ImuErrors`` parameter names and datasheet units
    (defaults: the navigation grade of Jiang et al. (2017), §3): gyro ARW (deg/sqrt(h)), bias
    instability (deg/h), its Gauss-Markov correlation time (s, ``inf``: a random constant);
    accelerometer noise density (ug/sqrt(Hz)), bias instability (ug), correlation time (s); the
    turn-on biases' sigmas (deg/h, ug: a random constant per run, the paper's "piecewise
    constant" biases).

    A bias state is the sum of the turn-on bias and the Gauss-Markov in-run bias. With no turn-on
    bias it is the Gauss-Markov process exactly; with one, the sum of a constant and a GM process is
    not one GM process, so the state becomes a random walk of the GM's intensity ``2 sigma_b^2 /
    T_c`` from ``P0 = sigma_on^2 + sigma_b^2``: the GM's own short-time law, exact for the constant
    and for runs much shorter than ``T_c`` (1 h in the grades; a survey between two ZUPTs lasts
    seconds to minutes)."""

    gyro_arw_deg_sqrt_h: float = 0.005
    gyro_bias_instability_deg_h: float = 0.01
    gyro_bias_correlation_time: float = 3600.0
    accel_noise_ug_sqrt_hz: float = 10.0
    accel_bias_instability_ug: float = 50.0
    accel_bias_correlation_time: float = 3600.0
    gyro_turn_on_bias_sigma_deg_h: float = 0.0
    accel_turn_on_bias_sigma_ug: float = 0.0

    def __post_init__(self) -> None:
        for k, v in self.__dict__.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or v < 0:
                raise ValueError(f"ImuGrade: {k} must be a number >= 0, not {v!r}")
            if k.endswith("correlation_time") and not v > 0:
                raise ValueError(f"ImuGrade: {k} must be > 0 s (inf: a random constant), not {v!r}")
            if not k.endswith("correlation_time") and not math.isfinite(v):
                raise ValueError(f"ImuGrade: {k} must be finite, not {v!r}")

    @property
    def gyro_noise(self) -> float:
        """Angle random walk N_g (rad/sqrt(s))."""
        return self.gyro_arw_deg_sqrt_h * GYRO_NOISE_SI

    @property
    def accel_noise(self) -> float:
        """Velocity random walk N_a (m/s/sqrt(s))."""
        return self.accel_noise_ug_sqrt_hz * ACCEL_SI

    @property
    def gyro_bias_sigma(self) -> float:
        """Gauss-Markov sigma_b of the gyro bias (rad/s): 1.076 x bias instability."""
        return GM_SIGMA_PER_B * self.gyro_bias_instability_deg_h * GYRO_BIAS_SI

    @property
    def accel_bias_sigma(self) -> float:
        """Gauss-Markov sigma_b of the accelerometer bias (m/s2)."""
        return GM_SIGMA_PER_B * self.accel_bias_instability_ug * ACCEL_SI

    @property
    def gyro_turn_on_sigma(self) -> float:
        """Sigma of the constant gyro bias (rad/s)."""
        return self.gyro_turn_on_bias_sigma_deg_h * GYRO_BIAS_SI

    @property
    def accel_turn_on_sigma(self) -> float:
        """Sigma of the constant accelerometer bias (m/s2)."""
        return self.accel_turn_on_bias_sigma_ug * ACCEL_SI


class ErrorModel:
    """The error model of the module docstring for ``kind`` ``"paper12"`` or ``"full15"`` and
    an :class:`ImuGrade`. ``names``: the state names; ``n``: their number."""

    def __init__(self, kind: str = "paper12", grade: ImuGrade | None = None) -> None:
        if kind not in MODELS:
            raise ValueError(f"error_model must be one of {', '.join(MODELS)}, not {kind!r}")
        self.kind, self.grade = kind, grade or ImuGrade()
        self.names = MODELS[kind]
        self.n = n = len(self.names)
        g = self.grade
        # bias states: (index, sigma_b, T_c, sigma_on) (ImuGrade: turn-on + Gauss-Markov)
        gyro = (g.gyro_bias_sigma, g.gyro_bias_correlation_time, g.gyro_turn_on_sigma)
        accel = (g.accel_bias_sigma, g.accel_bias_correlation_time, g.accel_turn_on_sigma)
        if kind == "paper12":
            self.biases = [(9, *gyro), (10, *gyro), (11, *accel)]
        else:
            self.biases = [(9 + i, *gyro) for i in range(3)] + [(12 + i, *accel) for i in range(3)]
        Qc = np.zeros((n, n))
        Qc[PHI, PHI] = g.gyro_noise**2 * np.eye(3)  # C diag(q) C^T = q I
        Qc[DV, DV] = g.accel_noise**2 * np.eye(3)
        for i, s, tc, _ in self.biases:
            Qc[i, i] = 2.0 * s * s / tc if math.isfinite(tc) else 0.0
        self.Qc = Qc

    # -- dynamics ------------------------------------------------------------------------------
    def system_matrix(self, lat: float, h: float, v_n, f_n, C_bn) -> np.ndarray:
        """``A`` (module docstring) at latitude ``lat`` (rad), height ``h`` (m), velocity
        ``v_n`` (NED, m/s), specific force ``f_n`` (NED, m/s2) and attitude ``C_bn``."""
        return self.system_matrices(np.array([lat]), np.array([h]), np.asarray(v_n, dtype=float)[None],
                                    np.asarray(f_n, dtype=float)[None], np.asarray(C_bn, dtype=float)[None])[0]

    def system_matrices(self, lat, h, v_n, f_n, C_bn) -> np.ndarray:
        """:meth:`system_matrix` for ``M`` epochs at once: ``lat``, ``h`` ``(M,)``, ``v_n``,
        ``f_n`` ``(M, 3)``, ``C_bn`` ``(M, 3, 3)`` -> ``(M, n, n)``."""
        lat, h = np.asarray(lat, dtype=float), np.asarray(h, dtype=float)
        v_n, f_n = np.asarray(v_n, dtype=float), np.asarray(f_n, dtype=float)
        M, n = lat.shape[0], self.n
        A = np.zeros((M, n, n))
        w_ie = earth.earth_rate_n(lat)
        w_en = earth.transport_rate_n(lat, h, v_n)
        A[:, PHI, PHI] = -skews(w_ie + w_en)
        A[:, DV, PHI] = skews(f_n)
        A[:, DV, DV] = -skews(2.0 * w_ie + w_en)
        A[:, 5, 8] = 2.0 * earth.gravity(lat, 0.0) / earth.A  # the mechanisation's g (1 - 2 h / a)
        A[:, DR, DV] = np.eye(3)
        if self.kind == "paper12":
            A[:, 0, 9] = A[:, 2, 10] = -1.0
            A[:, 5, 11] = 1.0
        else:
            C = np.asarray(C_bn, dtype=float)
            A[:, PHI, 9:12] = -C
            A[:, DV, 12:15] = C
        for i, _, tc, on in self.biases:
            A[:, i, i] = -1.0 / tc if math.isfinite(tc) and on == 0.0 else 0.0  # ImuGrade: with a turn-on bias a random walk
        return A

    def discretize(self, A: np.ndarray, T) -> tuple[np.ndarray, np.ndarray]:
        """``(Phi, Q_d)`` over one epoch of ``T`` seconds with ``A`` held (module docstring:
        Taylor series to A^4, three-point Gauss-Legendre for ``Q_d``). ``A`` ``(n, n)`` or a
        stack ``(M, n, n)`` with ``T`` scalar or ``(M,)``."""
        A = np.asarray(A, dtype=float)
        one = A.ndim == 2
        A = A[None] if one else A
        A1 = A * np.asarray(T, dtype=float).reshape(-1, 1, 1)
        A2 = A1 @ A1
        A3 = A2 @ A1
        A4 = A3 @ A1
        eye = np.eye(self.n)
        Phi = eye + A1 + A2 / 2.0 + A3 / 6.0 + A4 / 24.0
        q = np.diag(self.Qc)
        Qd = np.zeros_like(A)
        for x, w in zip(_GL_X, _GL_W):
            F = eye + x * A1 + (x * x / 2.0) * A2 + (x**3 / 6.0) * A3 + (x**4 / 24.0) * A4
            Qd += w * ((F * q) @ F.transpose(0, 2, 1))  # Q_c is diagonal
        Qd *= np.asarray(T, dtype=float).reshape(-1, 1, 1)
        Qd = 0.5 * (Qd + Qd.transpose(0, 2, 1))
        return (Phi[0], Qd[0]) if one else (Phi, Qd)

    # -- initial covariance ---------------------------------------------------------------------
    def initial_covariance(self, tilt_sigma: float, heading_sigma: float, velocity_sigma: float,
                           position_sigma: float) -> np.ndarray:
        """``P0 = diag(tilt^2, tilt^2, heading^2, velocity^2 x 3, position^2 x 3, sigma_b^2 ...)``
        (rad, m/s, m; the biases at their turn-on plus stationary Gauss-Markov variance)."""
        d = np.zeros(self.n)
        d[0:2], d[2] = tilt_sigma**2, heading_sigma**2
        d[DV], d[DR] = velocity_sigma**2, position_sigma**2
        for i, s, _, on in self.biases:
            d[i] = s * s + on * on
        return np.diag(d)

    # -- measurement rows -----------------------------------------------------------------------
    def velocity_rows(self) -> np.ndarray:
        """``H`` of a NED velocity measurement (ZUPT: ``z = v_computed - 0``): ``[0 I 0 ...]``."""
        H = np.zeros((3, self.n))
        H[:, DV] = np.eye(3)
        return H

    def position_rows(self) -> np.ndarray:
        """``H`` of a NED position fix (landmark: ``z = r_computed - r_landmark``, local NED)."""
        H = np.zeros((3, self.n))
        H[:, DR] = np.eye(3)
        return H

    def body_velocity_rows(self, C_bn, v_n) -> np.ndarray:
        r"""``H`` (3 rows, body x y z) of the computed body velocity
        ``v~^b = C~_n^b v~^n = C_n^b (I + [phi x]) (v^n + dv)``, to first order::

            v~^b - v^b = -C_n^b [v^n x] phi + C_n^b dv

        The non-holonomic constraint uses rows y, z (``z = v~^b_{y,z} - 0``); the odometer
        row x (``z = v~^b_x - v_odometer``). One epoch (``C_bn`` (3, 3), ``v_n`` (3,)) gives
        (3, n); ``M`` epochs (``(M, 3, 3)``, ``(M, 3)``) give ``(M, 3, n)``."""
        C, v = np.asarray(C_bn, dtype=float), np.asarray(v_n, dtype=float)
        CT = C.reshape(-1, 3, 3).transpose(0, 2, 1)
        H = np.zeros((CT.shape[0], 3, self.n))
        H[:, :, PHI] = -CT @ skews(v.reshape(-1, 3))
        H[:, :, DV] = CT
        return H[0] if C.ndim == 2 else H


# -- closed-loop feedback: the navigation corrected by an error estimate ------------------------

def corrected_position(lat, lon, h, dr):
    """``(lat, lon, h)`` minus the NED position error ``dr`` (m) (arrays broadcast; ``dr``
    shape ``(..., 3)``)."""
    dr = np.asarray(dr, dtype=float)
    rn, re = earth.principal_radii(lat, h)
    return (lat - dr[..., 0] / rn, lon - dr[..., 1] / (re * np.cos(lat)), h + dr[..., 2])


def ned_difference(lat, lon, h, lat0, lon0, h0):
    """``r - r0`` in local NED (m) of two nearby points (the inverse of
    :func:`corrected_position` to first order), shape ``(..., 3)``."""
    rn, re = earth.principal_radii(lat0, h0)
    return np.stack(np.broadcast_arrays((np.asarray(lat) - lat0) * rn, (np.asarray(lon) - lon0) * re * np.cos(lat0),
                                        -(np.asarray(h) - h0)), axis=-1)


def attitude_error(C_computed, C_true) -> np.ndarray:
    """``phi`` (rad, NED) with ``C_computed = (I - [phi x]) C_true`` (to first order; the
    rotation vector of ``C_true C_computed^T``). Shapes ``(3, 3)`` or ``(n, 3, 3)``."""
    from scipy.spatial.transform import Rotation
    M = np.asarray(C_true) @ np.swapaxes(np.asarray(C_computed), -1, -2)
    return Rotation.from_matrix(M).as_rotvec()


# -- observability --------------------------------------------------------------------------------

def observability_gramian(Phis, Hs, Rs=None) -> np.ndarray:
    """``sum_k Phi(k, 0)^T H_k^T R_k^-1 H_k Phi(k, 0)`` over epochs ``k = 0 .. N``:
    ``Phis`` ``(N, n, n)`` (``Phi_k``: ``k -> k + 1``), ``Hs`` a list of ``N + 1`` arrays
    ``(m_k, n)`` (``m_k = 0``: no measurement), ``Rs`` their noise covariances (default I).
    Its null space is the unobservable subspace of the run."""
    Phis = np.asarray(Phis, dtype=float)
    n = Phis.shape[1]
    W = np.zeros((n, n))
    T = np.eye(n)
    for k, H in enumerate(Hs):
        if H.shape[0]:
            Ri = np.eye(H.shape[0]) if Rs is None else np.linalg.inv(Rs[k])
            HT = H @ T
            W += HT.T @ Ri @ HT
        if k < Phis.shape[0]:
            T = Phis[k] @ T
    return 0.5 * (W + W.T)
