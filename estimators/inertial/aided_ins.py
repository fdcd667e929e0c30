r"""The ZUPT-aided INS of the trolley survey (Jiang et al. (2017), §4): an error-state Kalman
filter on the strapdown INS with closed-loop feedback, the Rauch-Tung-Striebel smoother over
the run (eq. 12), sampling of the smoother's joint error distribution, and the same
recursions without data (the paper's covariance analysis, §5).

Forward pass. The :class:`~railfmu.estimators.inertial.strapdown.Strapdown` integrates the measured increments at
the IMU rate; the error covariance runs at the epochs ``t_k`` (``filter_period`` apart) with the
error model of :mod:`railfmu.estimators.inertial.ins_error_model` (``A`` held at the epoch's mean specific force
``f^n = (v_k - v_{k-1}) / T - g^n + (2 omega_ie + omega_en) x v``, exact for the mechanisation,
and its mid-epoch attitude, latitude, height and velocity)::

    b_k = Phi_{k-1} a_{k-1},     P-_k = Phi_{k-1} P+_{k-1} Phi_{k-1}^T + Q_{k-1}     (eq. 11)
    x+_k = b_k + K_k (z_k - H_k b_k),  P+_k Joseph form            (railfmu.estimators.core.kalman.update)
    c_k = (x+_k of phi, dv, dr; 0 for the biases) at a feedback epoch, else 0
    a_k = x+_k - c_k

The epochs go in blocks of :data:`BLOCK` (20: 1 s at the default epoch): the INS integrates a
block's increments in one ``Strapdown.integrate`` call, ``Phi`` and ``Q`` of its epochs are
formed stacked, then the covariance recursion and the updates loop over its epochs.

Reset convention: at the last epoch of each block the navigation part ``c_k`` of the estimate
is fed back into the INS (``Strapdown.set_state``: ``C <- exp([phi x]) C``, ``v <- v - dv``,
position moved by ``-dr``), after which the navigation error estimate is zero; the bias
estimates stay in the filter's state ``a_k`` (the INS integrates the raw increments) and act
through ``Phi`` on the predictions, which are fed back at the next block's end. Within a block
the filter runs open loop about the INS: over 1 s the nominal moves from the corrected one by
(error rate) x 1 s, and the linearisation error is the square of that, ~1e-9 of the error
itself. The covariance is unchanged by the reset (its Jacobian ``I - [phi/2 x]`` differs from
I by < 1e-4). Without feedback (``feedback=False``) ``c_k = 0`` everywhere and this is the
textbook open-loop filter around the free INS; the two agree to the linearisation error while
the free INS drifts away (the bound is asserted in ``tests/test_aided_ins.py``).

Backward pass (RTS, eq. 12) on the errors relative to the *fed-back* nominal ``n_k^+``: the
INS carries ``n_k^+`` to ``n_{k+1}^-``, so ``Phi_k`` maps errors of ``n_k^+`` to errors of
``n_{k+1}^-``, and an error relative to ``n_{k+1}^-`` is the one relative to ``n_{k+1}^+``
plus ``c_{k+1}``::

    C_k = P+_k Phi_k^T (P-_{k+1})^-1
    s_N = a_N,                     s_k = a_k + C_k (s_{k+1} + c_{k+1} - b_{k+1})
    P^s_N = P+_N,                  P^s_k = P+_k + C_k (P^s_{k+1} - P-_{k+1}) C_k^T

and the smoothed navigation at epoch ``k`` is ``n_k^+`` corrected by ``s_k``. With
``feedback=False`` (``c = 0``, ``a = x+``) this is :func:`railfmu.estimators.core.smoothers.rts` term for term
(``tests/test_aided_ins.py``). All ``C_k`` come from the forward record alone: they are solved
in blocks of epochs at once (batched, in the correlation-scaled form of
:func:`railfmu.estimators.core.smoothers.spd_inverse`), leaving two ``n x n`` products per epoch in the loop.

Between epochs the smoothed navigation at each IMU sample is the INS's sample corrected by the
correction interpolated linearly between ``s_{k-1}`` (at ``t_{k-1}``, relative to ``n_{k-1}^+``,
where the chunk starts) and ``s_k + c_k`` (at ``t_k``, relative to ``n_k^-``, where it ends).
The error this makes is the curvature of the smoothed error over one epoch, ``|e''| T^2 / 8``:
for the position ``(g |phi| + |nabla|) T^2 / 8`` ~ 1e-4 m/s2 x 3e-4 s2 = 3e-8 m. The
``sigma_*`` outputs interpolate the smoothed variances the same way.

Smoother's joint errors (:meth:`SmootherRecord.error_samples`). The RTS smoothing errors
``e_k = x_k - x^s_k`` form a backward Markov chain (Rauch, Tung & Striebel 1965)::

    e_N ~ N(0, P+_N),    e_k = C_k e_{k+1} + w_k,   w_k ~ N(0, P+_k - C_k P-_{k+1} C_k^T)

independent ``w_k``: sampling it backwards gives draws with the exact joint covariance
``Cov(e_k, e_j) = C_k ... C_{j-1} P^s_j`` (``k < j``). ``P+_k - C_k P-_{k+1} C_k^T`` is formed
as ``(I - C_k Phi_k) P+_k (I - C_k Phi_k)^T + C_k Q_k C_k^T`` (the same matrix, a sum of PSD
terms). Only the epochs asked for are drawn, the chain's steps between them composed (their
noise covariances summed through the ``C_k``), so the random numbers scale with the points
wanted, not the epochs.

Measurements (the observer's ``measurements``; NaN or masked: absent). Each aiding is a
measurement object of :mod:`railfmu.estimators.inertial.aiding` that gives its ``(z, H, R)``
at an epoch, or nothing; the forward loop (and :func:`covariance_analysis`, with ``H, R``
only) stacks what the active ones give, in the order below, into one Joseph update:

* ``stopped`` (0/1): zero-velocity update ``z = v~^n``, ``H = [0 I 0]``, ``R = zupt_sigma^2 I`` at
  the epochs whose sample is stopped: every such epoch (``zupt_interval = 0``), the first of a
  stop and then every ``zupt_interval`` s, or one per stop (``zupt_interval = inf``, the
  paper's): at the epoch the trolley has come to rest, and for a rest the record starts with,
  at its last epoch, when the motion starts (Jiang et al. (2017), §6: "updates at the beginning
  and the end of the trajectory"). ``zupt_source="detector"`` takes
  the stops from ``railfmu.estimators.inertial.zupt_detector.detect_stationary`` on the increments instead and
  reports its misses and false alarms against the flag.
* non-holonomic constraint (``nhc``): ``z = (v~^b_y, v~^b_z)``, the rows y, z of
  ``ErrorModel.body_velocity_rows``, ``R = nhc_sigma^2 I``, at the epochs without a ZUPT. On
  the ``Trolley`` FMU the body point rides the rail and x is the rail tangent, so the
  constraint is exact unless its ``wobble`` is set (the default ``nhc_sigma``, 1 mm/s, is for
  that case). A wobble of amplitude ``a`` and wavelength ``l`` at speed ``v`` (the wheel-rail
  play) moves the body sideways at up to ``2 pi a v / l``: with ``play_model="white"`` (the
  default) ``nhc_sigma`` should be its rms, ``sqrt(2) pi a v / l`` (2 mm at 0.5 m and 1 m/s:
  18 mm/s), or the constraint is overconfident. White noise lets the integral of the body's
  cross-track velocity -- its offset from the rail -- wander like a random walk, although the
  play bounds it. ``play_model="shaping"`` says so: four nuisance states appended after the
  error model's (:class:`FilterModel`), the body's lateral and vertical offset from the rail and
  their slopes in the distance, ``(y, y', z, z')``, each a stationary damped oscillator in the
  distance travelled (:mod:`railfmu.estimators.inertial.rail_play`: stationary sigmas ``play_sigma_lateral``,
  ``play_sigma_vertical``, natural wavenumber ``2 pi / play_wavelength``, ``play_damping``),
  sampled exactly over each epoch's along-track distance ``ds = |x_b^T v_m| T`` (the nominal's
  body-x speed at mid-epoch; 0 at rest: ``Phi = I``, ``Q = 0``), their prior the stationary
  covariance. The NHC rows then read ``z = v~^b_{y,z} = H_b dx + v_s (y', z')`` (``v_s`` the
  INS's body-x speed at the epoch: the true cross-track velocity is ``d(offset)/dt = v_s
  dy/ds``) and ``nhc_sigma`` is only what the play model leaves out (default 0.1 mm/s with
  ``shaping``; on the ``Trolley`` FMU the body's cross-track velocity is the wobble's slope
  times the speed exactly, the cant mixing some vertical play into body y, which the lateral
  state absorbs). The play states are not navigation: they stay in the
  filter's state (not fed back), like the biases; the smoother, ``error_samples``,
  ``joint_covariance`` and :func:`covariance_analysis` carry them as any other state.
  With the trolley wobbling 1 mm / 0.5 mm at 2 m (navigation grade, NHC + odometer) the
  shaping model's chord errors are well below the white NHC's, and smaller again at a low
  damping such as 0.1 (the wobble is one sinusoid: a narrowband model fits it); the smoother's
  prediction of the max chord error is conservative there: the model's play keeps changing its
  amplitude and phase, the wobble's does not. Measured by ``railfmu study trolley_survey
  --variant zupt_nhc_odometer`` (docs/studies/trolley_survey.md); that the shaping model beats
  the white NHC and its lateral play follows the wobble is asserted in
  ``tests/test_aided_ins.py``.
* odometer (``odometer``, m, cumulative): speed form. ``z = x_b^T (r_k - r_{k-1}) / T -
  (s_k - s_{k-1}) / T``, the INS's mean body-x speed over the epoch (its own position
  increment, ``x_b`` at mid-epoch) minus the odometer's, with the body-x row of
  ``body_velocity_rows`` at the epoch's end. Why speed, not distance: the distance travelled
  by the INS is the integral of a state (a delayed-state or an extra distance-offset state
  would be needed), while the mean speed over one epoch differs from the end velocity error
  by ``|dv'| T / 2`` < 3e-5 m/s, below ``odometer_sigma`` (default 1 mm/s); the odometer's
  scale-factor error is not a state (a 100 ppm scale factor is 1e-4 m/s at 1 m/s).
* landmarks (``landmark_latitude``, ``landmark_longitude`` (rad), ``landmark_height`` (m)):
  ``z = r~(t_j) - r_landmark`` (local NED), ``H = [0 0 I]``, ``R = landmark_sigma^2 I``, at the
  epoch that ends the chunk with the fix's sample ``t_j`` (the INS position at ``t_j`` itself;
  the error moves by ``dv (t_k - t_j)`` < 1e-5 m in between). A fix held over consecutive
  samples (the same three values) is one fix, used once.

Memory: per epoch the record holds ``Phi``, ``Q``, ``P-``, ``P+``, ``C``, ``P^s`` (``n^2``
floats each), five state vectors and the nominal (17 floats), and after the first
:meth:`~SmootherRecord.error_samples` the backward chain's noise covariances (``n^2``); per IMU sample the INS's
navigation (9 floats). Up to ``memory_budget_mb`` (default 320 MB; a 700 s run at 20 Hz epochs
takes 107 MB with 12 states, 160 MB with 15, 263 MB with 15 + 4 play states: the default
holds the 600 m survey of ``experiments/trolley_survey`` with the play model, whose spill
would write ~0.3 GB per run) they are numpy arrays in RAM; beyond it the
same arrays are ``np.memmap`` files in a temporary directory (removed with the observer), so a
long run's peak memory is the budget plus one block's temporaries (the smoother's gains and
the smoothed output are formed in blocks too), not the run; the results are bit for bit the
same (``tests/test_aided_ins.py`` runs with a 0.01 MB budget).

Consistency (asserted in ``tests/test_aided_ins.py``): over IMU seeds of the navigation grade
on the trolley's 150 s stop-and-go record, initial attitude errors drawn from P0, the smoothed
position errors normalised by the smoothed sigmas have mean squares near 1 per axis. With the
non-holonomic constraint and the odometer use ``full15``: they observe the tilts directly (the
body velocity through ``v x phi``), so the horizontal accelerometer biases can no longer hide in
the tilts, and paper12, which lacks them, becomes overconfident in height (its normalised mean
square grows over the run) while full15 stays consistent. With the ideal IMU the smoothed
position is at the truth to far below a millimetre.

Cost: the wall times of a run are ``filter_seconds``, ``smoother_seconds`` and
``strapdown_seconds`` (:meth:`~AidedInsSmoother.finish`; the study's ``filter_seconds``,
``smoother_seconds``, docs/studies/trolley_survey.md).

After :meth:`AidedInsSmoother.run`: ``epoch_times``, ``P_filter``, ``P_smoothed`` (``(N, n, n)``,
``state_names``), :meth:`~SmootherRecord.error_samples`, :meth:`~SmootherRecord.joint_covariance`,
:meth:`AidedInsSmoother.nominal` (the linearisation trajectory, for
:func:`covariance_analysis`), ``zupt_epochs``, ``filter_seconds``, ``smoother_seconds``,
``strapdown_seconds``; :meth:`~AidedInsSmoother.finish` gives the times and the update counts.

Settings (all optional; SSD ``rf:Setting`` or keyword arguments): :class:`AidedInsSettings`, as
``self.config``, composed of the blocks (each field with its unit, default, one-line doc and
checks; ``AidedInsSettings.describe()`` lists them):

* :class:`~railfmu.estimators.inertial.ins_observer.InitialState`: the true initial state and the
  INS's initial attitude error (rad, m, m/s; as ``StrapdownINS``), and
  :class:`SmootherCore`: the initial velocity error, the P0 sigmas, ``error_model``,
  ``filter_period``, ``feedback``, ``memory_budget_mb``;
* :class:`ImuGradeSettings`: the IMU grade in the ``ImuErrors`` names and datasheet units
  (deg/sqrt(h), deg/h, µg/sqrt(Hz), µg: :class:`ImuGrade` turns them into SI);
* one block per aiding of :data:`~railfmu.estimators.inertial.aiding.AIDINGS` (its
  ``settings``): ``zupt*``, ``nhc*`` with the ``play_*`` of the play model, ``odometer*``,
  ``landmark*``.

Angles are in rad: the SSDs bind the initial state to the trolley's signals (rad) and the
variants give the initial errors in rad; the paper's 0.006 deg / 0.06 deg are the P0 defaults.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from railfmu.estimators.core import kalman
from railfmu.estimators.core.settings import Settings, number_or_inf, setting
from railfmu.estimators.inertial.aiding import (
    AIDINGS,
    EpochBlock,
    Landmark,
    Measurement,
    Nhc,
    Odometer,
    Record,
    Zupt,
    aidings_from_record,
    stack,
    update_counts,
)
from railfmu.estimators.inertial.attitude import dcm_from_rph, perturb, rph_from_dcm
from railfmu.estimators.inertial.ins_error_model import (
    DR,
    DV,
    PHI,
    ErrorModel,
    ImuGrade,
    corrected_position,
    skews,
)
from railfmu.estimators.inertial.ins_observer import INCREMENTS, InitialState
from railfmu.estimators.core.observer import OfflineObserver
from railfmu.estimators.inertial.rail_play import RailPlay
from railfmu.estimators.inertial.strapdown import NAV, Strapdown
from railfmu.models import earth

DEG = math.pi / 180.0
#: the record's measurements: the aidings' columns ("stopped", "odometer", "landmark_*")
MEASUREMENTS = tuple(c for cls in AIDINGS for c in cls.columns)
SIGMAS = ("sigma_north", "sigma_east", "sigma_down")
_GRADE_NAMES = tuple(f.name for f in fields(ImuGrade))
#: KF epochs per block of the forward pass (feedback at the end of each)
BLOCK = 20

_GRADE = ImuGrade()


@dataclass(frozen=True)
class SmootherCore(InitialState):
    """The smoother's own settings beside the initial state: the initial velocity error, P0 and
    the filter's set-up."""

    velocity_error_north: float = setting(0.0, "m/s", "initial velocity error, north (added to vn)")
    velocity_error_east: float = setting(0.0, "m/s", "initial velocity error, east")
    velocity_error_down: float = setting(0.0, "m/s", "initial velocity error, down")
    tilt_sigma: float = setting(0.006 * DEG, "rad", "P0 std of phi_N, phi_E (paper: 0.006 deg)", ge=0)
    heading_sigma: float = setting(0.06 * DEG, "rad", "P0 std of phi_D (paper: 0.06 deg)", ge=0)
    velocity_sigma: float = setting(1e-4, "m/s", "P0 std of dv per axis", ge=0)
    position_sigma: float = setting(0.1, "m", "P0 std of dr per axis", ge=0)
    error_model: str = setting("paper12", "", "the INS error model: 'paper12' or 'full15' (ins_error_model)",
                               choices=("paper12", "full15"))
    filter_period: float = setting(0.05, "s", "Kalman filter epoch (a whole number of IMU steps)", gt=0)
    feedback: bool = setting(True, "", "closed-loop error feedback into the INS")
    memory_budget_mb: float = setting(320.0, "MB", "RAM for the record before it spills to disk", gt=0)


@dataclass(frozen=True)
class ImuGradeSettings(Settings):
    """The filter's IMU noise model in the ``ImuErrors`` parameter names and datasheet units
    (default: the navigation grade of Jiang et al. (2017), §3); :meth:`grade` gives the
    :class:`ImuGrade`, which turns them into SI."""

    gyro_arw_deg_sqrt_h: float = setting(_GRADE.gyro_arw_deg_sqrt_h, "deg/sqrt(h)", "gyro angle random walk",
                                         ge=0)
    gyro_bias_instability_deg_h: float = setting(_GRADE.gyro_bias_instability_deg_h, "deg/h",
                                                 "gyro bias instability (Gauss-Markov sigma 1.076 x this)", ge=0)
    gyro_bias_correlation_time: float = setting(_GRADE.gyro_bias_correlation_time, "s", "gyro bias correlation "
                                                "time (inf: a random constant)", gt=0, convert=number_or_inf)
    accel_noise_ug_sqrt_hz: float = setting(_GRADE.accel_noise_ug_sqrt_hz, "µg/sqrt(Hz)",
                                            "accelerometer noise density", ge=0)
    accel_bias_instability_ug: float = setting(_GRADE.accel_bias_instability_ug, "µg",
                                               "accelerometer bias instability", ge=0)
    accel_bias_correlation_time: float = setting(_GRADE.accel_bias_correlation_time, "s", "accelerometer bias "
                                                 "correlation time (inf: a random constant)", gt=0,
                                                 convert=number_or_inf)
    gyro_turn_on_bias_sigma_deg_h: float = setting(_GRADE.gyro_turn_on_bias_sigma_deg_h, "deg/h",
                                                   "sigma of the turn-on gyro bias (constant per run)", ge=0)
    accel_turn_on_bias_sigma_ug: float = setting(_GRADE.accel_turn_on_bias_sigma_ug, "µg",
                                                 "sigma of the turn-on accelerometer bias", ge=0)

    def grade(self) -> ImuGrade:
        return ImuGrade(**{k: getattr(self, k) for k in _GRADE_NAMES})


# the aidings' blocks after the smoother's own (fields go in reverse MRO order)
@dataclass(frozen=True)
class AidedInsSettings(*reversed([cls.settings for cls in AIDINGS]), ImuGradeSettings, SmootherCore):
    """:class:`AidedInsSmoother`'s (and :func:`covariance_analysis`'s) settings: the initial
    state, :class:`SmootherCore`, :class:`ImuGradeSettings` and the settings of every aiding in
    :data:`~railfmu.estimators.inertial.aiding.AIDINGS` (module docstring)."""


class FilterModel:
    """The filter's state: the INS error model's (:class:`~railfmu.estimators.inertial.ins_error_model.ErrorModel`,
    ``n_nav`` states, navigation first: ``PHI, DV, DR``), then with ``play_model="shaping"`` the
    wheel-rail play's (:class:`~railfmu.estimators.inertial.rail_play.RailPlay`, four nuisance states, not fed
    back). Its matrices are the two blocks side by side; the play enters only the NHC rows."""

    def __init__(self, s: AidedInsSettings) -> None:
        self.nav = ErrorModel(s.error_model, s.grade())
        self.play = RailPlay(s.play_sigma_lateral, s.play_sigma_vertical, s.play_wavelength,
                             s.play_damping) if s.play_model == "shaping" else None
        self.n_nav = self.nav.n
        self.names = self.nav.names + (self.play.names if self.play else ())
        self.n = len(self.names)

    def _pad(self, H: np.ndarray) -> np.ndarray:
        out = np.zeros(H.shape[:-1] + (self.n,))
        out[..., :self.n_nav] = H
        return out

    def initial_covariance(self, s: AidedInsSettings) -> np.ndarray:
        """P0: the error model's from the settings' sigmas, the play's stationary covariance."""
        m = self.n_nav
        P = np.zeros((self.n, self.n))
        P[:m, :m] = self.nav.initial_covariance(s.tilt_sigma, s.heading_sigma, s.velocity_sigma,
                                                s.position_sigma)
        if self.play:
            P[self.n_nav:, self.n_nav:] = self.play.stationary_covariance()
        return P

    def discretize(self, A: np.ndarray, T, C_bn: np.ndarray, v_n: np.ndarray):
        """``(Phi, Q_d)`` ``(M, n, n)`` of ``M`` epochs: the error model's over ``T`` (s) with
        ``A`` held; the play's over the nominal's along-track distance ``ds = |x_b . v^n| T``
        (``x_b`` the first column of ``C_bn``, ``v_n`` NED, m/s: the INS's body-x speed)."""
        Phi, Qd = self.nav.discretize(A, T)
        if not self.play:
            return Phi, Qd
        M, n, m = Phi.shape[0], self.n, self.n_nav
        ds = np.abs(np.einsum("ki,ki->k", np.asarray(C_bn)[:, :, 0], np.asarray(v_n))) * np.asarray(T, dtype=float)
        Pp, Qp = self.play.discretize(ds)
        Phi_a, Q_a = np.zeros((M, n, n)), np.zeros((M, n, n))
        Phi_a[:, :m, :m], Phi_a[:, m:, m:] = Phi, Pp
        Q_a[:, :m, :m], Q_a[:, m:, m:] = Qd, Qp
        return Phi_a, Q_a

    def velocity_rows(self) -> np.ndarray:
        return self._pad(self.nav.velocity_rows())

    def position_rows(self) -> np.ndarray:
        return self._pad(self.nav.position_rows())

    def body_velocity_rows(self, C_bn: np.ndarray, v_n: np.ndarray) -> np.ndarray:
        """``(M, 3, n)``: ``ErrorModel.body_velocity_rows`` of ``M`` epochs (``C_bn`` ``(M, 3,
        3)``, ``v_n`` ``(M, 3)``) and, in rows y, z, the play's ``v_s (y', z')`` with ``v_s``
        the nominal body-x speed (``RailPlay.velocity_rows``)."""
        C, v = np.asarray(C_bn, dtype=float), np.asarray(v_n, dtype=float)
        H = self._pad(self.nav.body_velocity_rows(C, v))
        if self.play:
            H[:, 1:, self.n_nav:] = self.play.velocity_rows(np.einsum("ki,ki->k", C[:, :, 0], v))
        return H


class _Store:
    """Named float64 arrays in RAM up to a byte budget, beyond it ``np.memmap`` files in a
    temporary directory that lives as long as this object."""

    def __init__(self, shapes: dict[str, tuple[int, ...]], budget_bytes: float) -> None:
        total = sum(8 * math.prod(s) for s in shapes.values())
        self.spilled = total > budget_bytes
        self._dir = tempfile.TemporaryDirectory(prefix="aided_ins_") if self.spilled else None
        self.arrays: dict[str, np.ndarray] = {}
        for name, shape in shapes.items():
            self.new(name, shape)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]

    def new(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """Another array, in RAM or on disk as the others."""
        if self.spilled and math.prod(shape) > 0:
            self.arrays[name] = np.lib.format.open_memmap(f"{self._dir.name}/{name}.npy", mode="w+",
                                                          dtype=np.float64, shape=shape)
        else:
            self.arrays[name] = np.zeros(shape)
        return self.arrays[name]


def _smoother_gains(Pp: np.ndarray, Pm_next: np.ndarray, Phi: np.ndarray) -> np.ndarray:
    """``C_k = P+_k Phi_k^T (P-_{k+1})^-1`` for a block of epochs at once: ``C^T`` solves
    ``P-_{k+1} C^T = Phi_k P+_k``, in the correlation scaling of ``P-`` (a state with zero
    variance gets a unit pivot: its column of ``C`` is zero, the pseudo-inverse's answer)."""
    d = np.sqrt(np.einsum("kii->ki", Pm_next))
    zero = d <= 0.0
    d = np.where(zero, 1.0, d)
    corr = Pm_next / (d[:, :, None] * d[:, None, :])
    corr = 0.5 * (corr + corr.transpose(0, 2, 1))
    idx = np.arange(corr.shape[1])
    corr[:, idx, idx] = np.where(zero, 1.0, corr[:, idx, idx])
    rhs = (Phi @ Pp) / d[:, :, None]
    CT = np.linalg.solve(corr, rhs) / d[:, :, None]
    return CT.transpose(0, 2, 1)


class SmootherRecord:
    """What the smoother leaves for the error analysis: epoch times, the filter's ``P-``,
    ``P+``, ``Phi``, ``Q`` and the RTS gains ``C``, the smoothed covariances ``P^s``. Shared by
    :class:`AidedInsSmoother` (after ``run``) and :func:`covariance_analysis`."""

    epoch_times: np.ndarray
    state_names: tuple[str, ...]

    def _init_record(self, store: _Store, names: tuple[str, ...]) -> None:
        self._store = store
        self.state_names = names
        self._noise_cov: np.ndarray | None = None

    @property
    def P_filter(self) -> np.ndarray:
        """Filtered covariances ``P+_k`` ``(N, n, n)``."""
        return self._store["Pp"]

    @property
    def P_predicted(self) -> np.ndarray:
        return self._store["Pm"]

    @property
    def P_smoothed(self) -> np.ndarray:
        """Smoothed covariances ``P^s_k`` ``(N, n, n)``."""
        return self._store["Ps"]

    def nearest_epochs(self, times) -> np.ndarray:
        t = np.atleast_1d(np.asarray(times, dtype=float))
        j = np.clip(np.searchsorted(self.epoch_times, t), 1, max(len(self.epoch_times) - 1, 1))
        left = self.epoch_times[j - 1]
        right = self.epoch_times[np.minimum(j, len(self.epoch_times) - 1)]
        return np.where(np.abs(t - left) <= np.abs(right - t), j - 1, j).clip(0, len(self.epoch_times) - 1)

    def _noise_covariances(self) -> np.ndarray:
        """Per epoch ``Sigma_k = P+_k - C_k P-_{k+1} C_k^T`` in its PSD form (module docstring);
        the last epoch: ``P+_N``. Formed once, in blocks."""
        if self._noise_cov is None:
            st = self._store
            N, n = st["Pp"].shape[:2]
            Sig = st.new("Sig", (N, n, n))
            eye = np.eye(n)
            for a in range(0, N - 1, 512):
                b = min(a + 512, N - 1)
                C, F, Q = (np.asarray(st[k][a:b]) for k in ("C", "Phi", "Q"))
                I_CF = eye - C @ F
                S = I_CF @ np.asarray(st["Pp"][a:b]) @ I_CF.transpose(0, 2, 1) + C @ Q @ C.transpose(0, 2, 1)
                Sig[a:b] = 0.5 * (S + S.transpose(0, 2, 1))
            Sig[N - 1] = st["Pp"][N - 1]
            self._noise_cov = Sig
        return self._noise_cov

    @staticmethod
    def _factor(S: np.ndarray) -> np.ndarray:
        """``F`` with ``F F^T = S`` for a PSD ``S`` (eigen-decomposition, negative rounding
        clipped)."""
        w, V = np.linalg.eigh(0.5 * (S + S.T))
        return V * np.sqrt(np.clip(w, 0.0, None))

    def error_samples(self, times, n_samples: int, seed: int | None = None, states=DR) -> np.ndarray:
        """``(n_samples, len(times), 3)``: draws of the smoothing error of the position (NED,
        m; ``states`` another slice of the error state) at the epochs nearest to ``times``,
        from the smoother's joint Gaussian (backward sampling, module docstring).

        Only the wanted epochs are drawn: from the latest one ``k_b`` (``e ~ N(0, P^s_{k_b})``)
        down, each next wanted ``k_a`` given the last is ``e_a = G e_b + w``, ``G = C_a ...
        C_{b-1}``, ``w ~ N(0, S_a)`` with ``S_k = C_k S_{k+1} C_k^T + Sigma_k``, ``S_b = 0``
        (the chain's steps composed: a sum of PSD terms, no difference of covariances)."""
        if isinstance(n_samples, bool) or not (isinstance(n_samples, (int, np.integer)) and n_samples >= 1):
            raise ValueError(f"error_samples: n_samples must be a positive integer, not {n_samples!r}")
        want = self.nearest_epochs(times)
        n = len(self.state_names)
        width = len(range(*states.indices(n)))
        out = np.empty((n_samples, want.size, width))
        if want.size == 0:
            return out
        st = self._store
        Sig = self._noise_covariances()
        rng = np.random.default_rng(seed)
        order = sorted(set(want.tolist()), reverse=True)
        top = order[0]
        e = rng.standard_normal((n_samples, n)) @ self._factor(np.asarray(st["Ps"][top])).T
        drawn = {top: e}
        eye = np.eye(n)
        prev = top
        for k_a in order[1:]:
            G, S = eye, np.zeros((n, n))
            for k in range(prev - 1, k_a - 1, -1):
                Ck = st["C"][k]
                S = Ck @ S @ Ck.T + Sig[k]
                G = Ck @ G
            e = e @ G.T + rng.standard_normal((n_samples, n)) @ self._factor(S).T
            drawn[k_a] = e
            prev = k_a
        for i, k in enumerate(want.tolist()):
            out[:, i] = drawn[k][:, states]
        return out

    def joint_covariance(self, epochs) -> np.ndarray:
        """Exact joint covariance of the smoothing errors (all states) at the given epoch
        indices (ascending): ``Cov(e_k, e_j) = C_k ... C_{j-1} P^s_j`` for ``k < j``.
        Shape ``(m n, m n)``; for tests and small analyses."""
        ks = [int(k) for k in epochs]
        if any(b <= a for a, b in zip(ks, ks[1:])) or (ks and not 0 <= ks[0] <= ks[-1] < len(self.epoch_times)):
            raise ValueError(f"joint_covariance: epochs must be increasing indices in 0..{len(self.epoch_times) - 1}")
        n = len(self.state_names)
        st = self._store
        M = np.zeros((len(ks) * n, len(ks) * n))
        for a, k in enumerate(ks):
            M[a * n:(a + 1) * n, a * n:(a + 1) * n] = st["Ps"][k]
            G = np.eye(n)
            j_prev = k
            for b in range(a + 1, len(ks)):
                j = ks[b]
                for m in range(j_prev, j):
                    G = G @ st["C"][m]
                j_prev = j
                block = G @ st["Ps"][j]
                M[a * n:(a + 1) * n, b * n:(b + 1) * n] = block
                M[b * n:(b + 1) * n, a * n:(a + 1) * n] = block.T
        return M


def _smooth(store: _Store, block: int = 256) -> None:
    """The backward pass (module docstring) over a store holding ``Pm, Pp, Phi, a, d``
    (``d_k = c_k - b_k``); fills ``C``, ``Ps`` and the smoothed corrections ``s``."""
    Pm, Pp, Phi, a, d = (store[k] for k in ("Pm", "Pp", "Phi", "a", "d"))
    C, Ps, s = store["C"], store["Ps"], store["s"]
    N = Pp.shape[0]
    s[N - 1] = a[N - 1]
    Ps[N - 1] = Pp[N - 1]
    end = N - 1  # gains for epochs [start, end)
    s_next, P_next = np.array(s[N - 1]), np.array(Ps[N - 1])
    while end > 0:
        start = max(0, end - block)
        Cb = _smoother_gains(np.asarray(Pp[start:end]), np.asarray(Pm[start + 1:end + 1]), np.asarray(Phi[start:end]))
        C[start:end] = Cb
        ab, db, Ppb, Pmb = np.asarray(a[start:end]), np.asarray(d[start + 1:end + 1]), \
            np.asarray(Pp[start:end]), np.asarray(Pm[start + 1:end + 1])
        sb = np.empty_like(ab)
        Psb = np.empty_like(Ppb)
        for i in range(end - start - 1, -1, -1):
            Ck = Cb[i]
            s_next = ab[i] + Ck @ (s_next + db[i])
            P_next = Ppb[i] + Ck @ (P_next - Pmb[i]) @ Ck.T
            P_next = 0.5 * (P_next + P_next.T)
            sb[i], Psb[i] = s_next, P_next
        s[start:end], Ps[start:end] = sb, Psb
        end = start


def _quat_mul(p, q):
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3, p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1, p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


def _quat_rotvec(x: float, y: float, z: float):
    a2 = x * x + y * y + z * z
    if a2 < 1e-8:
        c, k = 1.0 - a2 / 8.0, 0.5 - a2 / 48.0
    else:
        a = math.sqrt(a2)
        c, k = math.cos(0.5 * a), math.sin(0.5 * a) / a
    return c, k * x, k * y, k * z


def _dcm_rph(roll, pitch, heading) -> np.ndarray:
    """C_b^n = R_z(heading) R_y(pitch) R_x(roll) of arrays ``(M,)`` -> ``(M, 3, 3)`` (plain
    numpy: building scipy's Rotation costs more than a block of the filter)."""
    sr, cr, sp, cp, sh, ch = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch), np.sin(heading), np.cos(heading)
    C = np.empty((np.shape(roll)[0], 3, 3))
    C[:, 0, 0], C[:, 0, 1], C[:, 0, 2] = cp * ch, -cr * sh + sr * sp * ch, sr * sh + cr * sp * ch
    C[:, 1, 0], C[:, 1, 1], C[:, 1, 2] = cp * sh, cr * ch + sr * sp * sh, -sr * ch + cr * sp * sh
    C[:, 2, 0], C[:, 2, 1], C[:, 2, 2] = -sp, sr * cp, cr * cp
    return C


def _rph_dcm(C: np.ndarray) -> np.ndarray:
    """(roll, pitch, heading) of ``(M, 3, 3)`` DCMs, as ``Strapdown.rph`` -> ``(M, 3)``."""
    return np.column_stack((np.arctan2(C[:, 2, 1], C[:, 2, 2]),
                            np.arctan2(-C[:, 2, 0], np.hypot(C[:, 2, 1], C[:, 2, 2])),
                            np.arctan2(C[:, 1, 0], C[:, 0, 0])))


def _rotations(phi: np.ndarray) -> np.ndarray:
    """exp([phi x]) of rotation vectors ``(M, 3)`` (Rodrigues; series below 1e-4 rad)."""
    a2 = np.einsum("ki,ki->k", phi, phi)
    a = np.sqrt(a2)
    small = a < 1e-4
    safe = np.where(small, 1.0, a)
    s = np.where(small, 1.0 - a2 / 6.0, np.sin(safe) / safe)
    c = np.where(small, 0.5 - a2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    K = skews(phi)
    return np.eye(3) + s[:, None, None] * K + c[:, None, None] * (K @ K)


def _dcm(q) -> np.ndarray:
    q0, q1, q2, q3 = q
    return np.array([[q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
                     [2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)],
                     [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3]])


class AidedInsSmoother(OfflineObserver, SmootherRecord):
    """ZUPT-aided INS with closed-loop error feedback and RTS smoothing (module docstring):
    ``AidedInsSmoother(dt, **settings)``, ``dt`` the IMU step (s). After :meth:`run`:
    ``epoch_times``, :meth:`error_samples`, ``filter_seconds``, ``smoother_seconds``,
    ``strapdown_seconds``; :meth:`finish` gives them and the update counts."""

    inputs: ClassVar[tuple[str, ...]] = INCREMENTS
    measurements: ClassVar[tuple[str, ...]] = MEASUREMENTS
    outputs: ClassVar[tuple[str, ...]] = (*NAV, *SIGMAS)
    units: ClassVar[dict[str, str]] = {
        **{k: "rad" for k in INCREMENTS[:3]}, **{k: "m/s" for k in INCREMENTS[3:]},
        **{k: u for cls in AIDINGS for k, u in cls.units.items()},
        "latitude": "rad", "longitude": "rad", "height": "m", "vn": "m/s", "ve": "m/s", "vd": "m/s",
        "roll": "rad", "pitch": "rad", "heading": "rad", **{k: "m" for k in SIGMAS}}

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.config = s = AidedInsSettings.from_mapping(settings, "AidedInsSmoother")
        steps = s.filter_period / self.dt
        self.epoch_steps = max(1, round(steps))
        if abs(steps - self.epoch_steps) > 1e-6 * steps:
            raise ValueError(f"AidedInsSmoother: filter_period {s.filter_period!r} s is not a whole number of "
                             f"IMU steps ({self.dt!r} s)")
        self.states = FilterModel(s)
        self.model = self.states.nav
        self.epoch_times = np.empty(0)
        self.state_names = self.states.names
        self.filter_seconds = self.smoother_seconds = self.strapdown_seconds = 0.0
        self.counts: dict[str, int] = {}
        self.detector: dict[str, Any] = {}

    # -- the run -------------------------------------------------------------------------------
    def _zupt_epochs(self, stopped: np.ndarray, idx: np.ndarray, times: np.ndarray) -> np.ndarray:
        """Which epochs get a ZUPT (module docstring), from the stopped flag per sample."""
        at = stopped[idx]
        use = np.zeros(idx.size, dtype=bool)
        interval = self.config.zupt_interval
        if interval == 0:
            return at
        k = 0
        while k < idx.size:
            if not at[k]:
                k += 1
                continue
            end = k
            while end + 1 < idx.size and at[end + 1]:
                end += 1
            if math.isinf(interval):  # the epoch next to the motion (module docstring)
                before, after = k > 0, end < idx.size - 1
                use[k if before else end if after else (k + end) // 2] = True
            else:
                last = -math.inf
                for j in range(k, end + 1):
                    if times[j] - last >= interval - 1e-9:
                        use[j] = True
                        last = times[j]
            k = end + 1
        return use

    def _stopped(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray, mask: np.ndarray) -> np.ndarray:
        flag = mask[:, 0] & (np.nan_to_num(Z[:, 0]) >= 0.5)
        if self.config.zupt_source == "flag":
            return flag
        from railfmu.estimators.inertial.zupt_detector import (
            detect_stationary,
            detector_scores,
            noise_sigmas,
        )
        sigmas = noise_sigmas({k: getattr(self.config, k) for k in _GRADE_NAMES}, self.dt)
        detected = np.asarray(detect_stationary(U, self.dt, **({"sigma_a": sigmas[0], "sigma_g": sigmas[1]}
                                                              if min(sigmas) > 0 else {})), dtype=bool)
        self.detector = dict(detector_scores(detected, flag))
        return detected

    def _run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray, mask: np.ndarray) -> np.ndarray:
        s, model, dt = self.config, self.states, self.dt
        n_samples = t.shape[0]
        if n_samples > 1:
            steps = np.diff(t) / dt
            bad = np.flatnonzero(np.abs(steps - 1.0) > 1e-6)
            if bad.size:
                k = int(bad[0])
                raise ValueError(f"AidedInsSmoother.run: t[{k + 1}] = {float(t[k + 1])!r} s is not one IMU step "
                                 f"({dt!r} s) after t[{k}] = {float(t[k])!r} s (the record must be uniform)")
        if not np.isfinite(U).all():
            k = int(np.flatnonzero(~np.isfinite(U).all(axis=1))[0])
            raise ValueError(f"AidedInsSmoother.run: increments at t = {float(t[k])!r} s are not finite")
        m = self.epoch_steps
        idx = np.arange(0, n_samples, m)
        if idx[-1] != n_samples - 1:
            idx = np.append(idx, n_samples - 1)
        N, n = idx.size, model.n
        self.epoch_times = t[idx]
        stopped = self._stopped(t, Z, U, mask)
        zupt = self._zupt_epochs(stopped, idx, self.epoch_times) if s.zupt else np.zeros(N, dtype=bool)

        shapes = {"Pm": (N, n, n), "Pp": (N, n, n), "Phi": (max(N - 1, 0), n, n), "Q": (max(N - 1, 0), n, n),
                  "C": (max(N - 1, 0), n, n), "Ps": (N, n, n), "a": (N, n), "d": (N, n), "s": (N, n),
                  "c": (N, n), "nav": (n_samples, 9), "nominal": (N, 17)}
        store = _Store(shapes, s.memory_budget_mb * 1e6)
        self._init_record(store, model.names)
        self.spilled = store.spilled
        self.zupt_epochs = zupt
        t_start = time.perf_counter()
        strap = self._forward(t, Z, U, mask, idx, zupt, store)
        t_mid = time.perf_counter()
        _smooth(store)
        out = self._smoothed_navigation(idx, store)
        t_end = time.perf_counter()
        self.strapdown_seconds = strap
        self.filter_seconds = t_mid - t_start - strap
        self.smoother_seconds = t_end - t_mid
        return out

    def _initial_ins(self, u0: np.ndarray) -> Strapdown:
        s = self.config
        C = perturb(dcm_from_rph(s.roll, s.pitch, s.heading),
                    [s.tilt_error_north, s.tilt_error_east, s.heading_error])
        v = (s.vn + s.velocity_error_north, s.ve + s.velocity_error_east,
             s.vd + s.velocity_error_down)
        ins = Strapdown.from_rph(s.latitude, s.longitude, s.height, v, rph_from_dcm(C), self.dt)
        ins.prime(u0[:3], u0[3:])
        return ins

    def _forward(self, t, Z, U, mask, idx, zupt, store) -> float:
        """The forward filter with feedback (module docstring); returns the seconds spent in
        the strapdown. The epochs go in blocks of :data:`BLOCK`: the INS integrates a block in
        one call, ``Phi``, ``Q`` of its epochs are formed at once and the aidings prepare theirs
        (:class:`~railfmu.estimators.inertial.aiding.EpochBlock`), the covariance recursion and
        the updates of the aidings that measure loop over its epochs, and the navigation part of
        the estimate is fed back at the block's end (open loop within one block: 1 s at the
        default epoch, where the linearisation error is ~|dx|^2, < 1e-9 of the error)."""
        s, model, dt = self.config, self.states, self.dt
        n, N = model.n, idx.size
        Pm, Pp, Phi_s, Q_s, a_s, d_s, c_s, nav = (store[k] for k in ("Pm", "Pp", "Phi", "Q", "a", "d", "c", "nav"))
        ins = self._initial_ins(U[0])
        strap = 0.0
        aidings = aidings_from_record(Record(s, model, Z, mask, self.measurements, idx, zupt))
        counts = update_counts()
        nav[0] = ins.navigation()
        x = np.zeros(n)  # the filter's estimate relative to the fed-back INS
        P = model.initial_covariance(s)
        feedback = s.feedback
        zero = np.zeros(n)
        k0 = -1  # the last epoch done
        while k0 < N - 1:
            k1 = min(k0 + BLOCK, N - 1) if k0 >= 0 else 0
            lat0, lon0, h0, v0 = ins.lat, ins.lon, ins.h, (ins.vn, ins.ve, ins.vd)
            C0 = _dcm(tuple(ins.quaternion()))
            if k0 < 0:  # epoch 0: the initial state, no prediction
                rows = nav[:1].copy()
                store["nominal"][0] = np.r_[lat0, h0, v0, 0.0, 0.0, -earth.gravity(lat0, h0), C0.ravel()]
                block = EpochBlock(model, 0, C0[None], rows[:, 3:6], epoch_nav=rows, nav=nav)
                Phi = Qd = None
            else:
                i0, i1 = int(idx[k0]), int(idx[k1])
                ts = time.perf_counter()
                nav[i0 + 1:i1 + 1] = ins.integrate(U[i0 + 1:i1 + 1])
                strap += time.perf_counter() - ts
                rows = np.asarray(nav[idx[k0 + 1:k1 + 1]])
                C = _dcm_rph(rows[:, 6], rows[:, 7], rows[:, 8])
                C[-1] = _dcm(tuple(ins.quaternion()))
                lat = np.concatenate(([lat0], rows[:, 0]))
                hh = np.concatenate(([h0], rows[:, 2]))
                v = np.vstack((v0, rows[:, 3:6]))
                T = np.diff(idx[k0:k1 + 1]) * dt
                lat_m, h_m, v_m = 0.5 * (lat[1:] + lat[:-1]), 0.5 * (hh[1:] + hh[:-1]), 0.5 * (v[1:] + v[:-1])
                w2 = 2.0 * earth.earth_rate_n(lat_m) + earth.transport_rate_n(lat_m, h_m, v_m)
                f_n = np.diff(v, axis=0) / T[:, None] + np.cross(w2, v_m)
                f_n[:, 2] -= earth.gravity(lat_m, h_m)
                C_m = 0.5 * (C + np.concatenate((C0[None], C[:-1])))
                Phi, Qd = model.discretize(model.nav.system_matrices(lat_m, h_m, v_m, f_n, C_m), T, C_m, v_m)
                Phi_s[k0:k1], Q_s[k0:k1] = Phi, Qd
                store["nominal"][k0 + 1:k1 + 1] = np.column_stack((lat_m, h_m, v_m, f_n, C_m.reshape(-1, 9)))
                block = EpochBlock(model, k0 + 1, C, rows[:, 3:6], epoch_nav=rows, C_m=C_m, T=T, start=(lat0, lon0, h0),
                                   nav=nav)
            for aiding in aidings:
                aiding.prepare(block)
            for j, k in enumerate(range(block.first, k1 + 1)):
                if Phi is not None:
                    b = Phi[j] @ x
                    P = Phi[j] @ P @ Phi[j].T + Qd[j]
                    P = 0.5 * (P + P.T)
                else:
                    b = x
                Pm[k] = P
                got = []
                for aiding in aidings:
                    m = aiding.measure(j, k, block)
                    if m is not None:
                        got.append(m)
                        counts[f"{aiding.name}_updates"] += 1
                if got:
                    z, H, R = stack(got)
                    upd = kalman.update(b, P, z, H, R)
                    x, P = upd.x, upd.P
                else:
                    x = b
                Pp[k] = P
                if k == k1 and feedback and np.any(x[:9]):
                    c = np.zeros(n)
                    c[:9] = x[:9]
                    self._feed_back(ins, c)
                    a_s[k], d_s[k], c_s[k] = x - c, c - b, c
                    x = x - c
                else:
                    a_s[k], d_s[k], c_s[k] = x, -b, zero
            k0 = k1
        self.counts = counts
        return strap

    @staticmethod
    def _feed_back(ins: Strapdown, c: np.ndarray) -> None:
        """Correct the INS by the navigation error estimate ``c`` (phi, dv, dr)."""
        lat, lon, h = corrected_position(ins.lat, ins.lon, ins.h, c[DR])
        dq = _quat_rotvec(*c[PHI].tolist())
        q = _quat_mul(dq, tuple(ins.quaternion()))
        ins.set_state(lat=float(lat), lon=float(lon), height=float(h),
                      v_ned=(ins.vn - c[3], ins.ve - c[4], ins.vd - c[5]), q=q)

    def _smoothed_navigation(self, idx: np.ndarray, store: _Store) -> np.ndarray:
        """The INS's samples corrected by the smoothed error, interpolated between epochs
        (module docstring), and the smoothed position sigmas."""
        nav = store["nav"]
        n_samples = nav.shape[0]
        s_ep, c_ep, Ps = store["s"], store["c"], store["Ps"]
        out = np.empty((n_samples, len(self.outputs)))
        N = idx.size
        var = np.einsum("kii->ki", np.asarray(Ps[:, DR, DR]))
        for lo in range(0, n_samples, 1 << 16):  # bounded temporaries on long runs
            hi = min(n_samples, lo + (1 << 16))
            j = np.arange(lo, hi)
            k = np.clip(np.searchsorted(idx, j, side="left"), 1, max(N - 1, 1)) if N > 1 else np.zeros(hi - lo, int)
            if N > 1:
                i0, i1 = idx[k - 1], idx[k]
                w = ((j - i0) / (i1 - i0))[:, None]
                start = np.asarray(s_ep[k - 1])
                end = np.asarray(s_ep[k]) + np.asarray(c_ep[k])
                # sample 0 is the INS's initial state, before the feedback of epoch 0
                at0 = j == 0
                corr = (1.0 - w) * start + w * end
                corr[at0] = np.asarray(s_ep[0]) + np.asarray(c_ep[0])
                v = (1.0 - w) * var[k - 1] + w * var[k]
            else:
                corr = np.repeat((np.asarray(s_ep[0]) + np.asarray(c_ep[0]))[None], hi - lo, axis=0)
                v = np.repeat(var[:1], hi - lo, axis=0)
            block = np.asarray(nav[lo:hi])
            lat, lon, h = corrected_position(block[:, 0], block[:, 1], block[:, 2], corr[:, DR])
            out[lo:hi, 0], out[lo:hi, 1], out[lo:hi, 2] = lat, lon, h
            out[lo:hi, 3:6] = block[:, 3:6] - corr[:, DV]
            out[lo:hi, 6:9] = _rph_dcm(_rotations(corr[:, PHI]) @ _dcm_rph(block[:, 6], block[:, 7], block[:, 8]))
            out[lo:hi, 9:12] = np.sqrt(np.clip(v, 0.0, None))
        return out

    def nominal(self) -> dict[str, np.ndarray]:
        """The nominal trajectory the filter linearised about, per epoch ``k`` the values it
        held over the interval that ends at ``t_k`` (mid-interval latitude, height, velocity,
        attitude; mean specific force): the keyword arguments of :func:`covariance_analysis`
        (``times, f_n, C_bn, latitude, height, velocity``) that reproduce its covariances."""
        m = np.asarray(self._store["nominal"])
        return {"times": self.epoch_times.copy(), "f_n": m[:, 5:8].copy(), "C_bn": m[:, 8:17].reshape(-1, 3, 3).copy(),
                "latitude": m[:, 0].copy(), "height": m[:, 1].copy(), "velocity": m[:, 2:5].copy()}

    def finish(self) -> dict:
        out = {"filter_seconds": self.filter_seconds, "smoother_seconds": self.smoother_seconds,
               "strapdown_seconds": self.strapdown_seconds, "epochs": int(self.epoch_times.size), **self.counts}
        if self.detector:
            out.update({f"zupt_detector_{k}": v for k, v in self.detector.items()})
        return out


class CovarianceAnalysis(SmootherRecord):
    """Result of :func:`covariance_analysis`: ``epoch_times``, ``P_filter``, ``P_smoothed``,
    :meth:`error_samples`, :meth:`joint_covariance`."""

    def __init__(self, epoch_times: np.ndarray, store: _Store, names: tuple[str, ...]) -> None:
        self.epoch_times = epoch_times
        self._init_record(store, names)


def covariance_analysis(times, f_n, C_bn, latitude, velocity, zupt, position=None, height=0.0, nhc=None,
                        odometer=None, **settings: Any) -> CovarianceAnalysis:
    r"""The filter's and the smoother's covariance recursions on a given nominal trajectory,
    without data (Jiang et al. (2017), §5): the same error model, ``Phi``/``Q`` sampling,
    aidings (the objects of :mod:`railfmu.estimators.inertial.aiding` on the given epoch masks,
    their ``(H, R)`` only), Joseph updates and RTS covariance pass as :class:`AidedInsSmoother`.

    ``times`` ``(N,)`` (s): the epochs; per epoch ``k`` the nominal over the interval that ends
    at ``t_k`` (row 0 unused but for the shape): ``f_n`` ``(N, 3)`` specific force (NED, m/s2),
    ``C_bn`` ``(N, 3, 3)`` attitude, ``latitude`` (rad), ``velocity`` ``(N, 3)`` (NED, m/s),
    ``height`` (m) (each may be one value for all epochs); ``zupt`` ``(N,)`` bool: a
    zero-velocity update at the epoch; ``position``, ``nhc``, ``odometer`` ``(N,)`` bool or None:
    a landmark position update, the non-holonomic constraint, the odometer speed at the epoch
    (their rows from ``C_bn`` and ``velocity``, as the filter's at the end of the interval;
    the masks as given: unlike the filter's, an NHC or odometer epoch may also have a ZUPT).
    ``settings``: those of :class:`AidedInsSmoother` that concern the covariances (the grade,
    the P0 sigmas, ``error_model``, ``zupt_sigma``, ``landmark_sigma``, ``nhc_sigma``,
    ``odometer_sigma``, the ``play_*`` settings (the play's distance per epoch is
    ``|x_b . velocity| T``, as the filter's), ``memory_budget_mb``). ``AidedInsSmoother.nominal()`` and ``.zupt_epochs`` after a run
    reproduce its covariances to rounding. Returns a :class:`CovarianceAnalysis`
    (``epoch_times``, ``P_filter``, ``P_smoothed``, ``error_samples``, ``joint_covariance``).

    The paper's straight track (§5): ``f_n = (0, 0, -g)`` while cruising, ``C_bn`` the constant
    heading N45E, ``velocity`` 1 m/s along it, ZUPT (and optionally position) updates at both
    ends of the 30 m."""
    s = AidedInsSettings.from_mapping(settings, "covariance_analysis")
    times = np.asarray(times, dtype=float)
    N = times.shape[0]
    if times.ndim != 1 or N < 1 or np.any(np.diff(times) <= 0):
        raise ValueError("covariance_analysis: times must be a non-empty increasing 1-D array")
    f_n = np.broadcast_to(np.asarray(f_n, dtype=float), (N, 3))
    C_bn = np.broadcast_to(np.asarray(C_bn, dtype=float), (N, 3, 3))
    lat = np.broadcast_to(np.asarray(latitude, dtype=float), (N,))
    hgt = np.broadcast_to(np.asarray(height, dtype=float), (N,))
    vel = np.broadcast_to(np.asarray(velocity, dtype=float), (N, 3))
    zupt = np.broadcast_to(np.asarray(zupt, dtype=bool), (N,))
    pos, nhc, odo = (np.zeros(N, dtype=bool) if x is None else np.broadcast_to(np.asarray(x, dtype=bool), (N,))
                     for x in (position, nhc, odometer))
    model = FilterModel(s)
    n = model.n
    shapes = {"Pm": (N, n, n), "Pp": (N, n, n), "Phi": (max(N - 1, 0), n, n), "Q": (max(N - 1, 0), n, n),
              "C": (max(N - 1, 0), n, n), "Ps": (N, n, n), "a": (N, n), "d": (N, n), "s": (N, n)}
    store = _Store(shapes, s.memory_budget_mb * 1e6)
    P = model.initial_covariance(s)
    # the filter's aidings without data: only their (H, R) at the given epochs
    aidings = [Zupt(zupt, s.zupt_sigma, model), Nhc(nhc, s.nhc_sigma), Odometer(odo, s.odometer_sigma),
               Landmark(pos, s.landmark_sigma, model)]
    for a in range(1, N, 512):  # Phi, Q of the epochs in blocks (bounded temporaries)
        b = min(a + 512, N)
        A = model.nav.system_matrices(lat[a:b], hgt[a:b], vel[a:b], f_n[a:b], C_bn[a:b])
        store["Phi"][a - 1:b - 1], store["Q"][a - 1:b - 1] = model.discretize(A, np.diff(times[a - 1:b]), C_bn[a:b],
                                                                               vel[a:b])
    zero = np.zeros(n)
    for k in range(N):
        if k:
            Phi, Qd = store["Phi"][k - 1], store["Q"][k - 1]
            P = Phi @ P @ Phi.T + Qd
            P = 0.5 * (P + P.T)
        store["Pm"][k] = P
        block = EpochBlock(model, k, C_bn[k:k + 1], vel[k:k + 1])  # the body rows from the epoch's nominal
        got = [Measurement(np.zeros(r[0].shape[0]), *r) for r in (a.rows(0, k, block) for a in aidings)
               if r is not None]
        if got:
            z, H, R = stack(got)
            P = kalman.update(zero, P, z, H, R).P
        store["Pp"][k] = P
    _smooth(store)
    return CovarianceAnalysis(times, store, model.names)
