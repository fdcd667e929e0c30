r"""Lateral track alignment from axle-box gyro + accelerometers: the linear Kalman filter of
Muñoz et al., §4 (eqs. 9-27), on the wheelset + suspended-frame design model (SM) of §3.3.

Design model
------------
:data:`railfmu.models.vehicle.wheelset.WHEELSET` linearised about the centred wheelset
(:meth:`railfmu.models.base.Model.linearize`; a run reads the numbers from the cache,
:class:`railfmu.models.design.DesignModel`), ``dx = A x + B [xi, xi_rate]``,
``[ddy, ddpsi, ddy_f] = C x + D [xi, xi_rate]``, with ``x = [y, psi, y_f, dy, dpsi, dy_f]``.
The alignment ``xi`` is appended to the state (the paper's eq. 9) as a random walk (eq. 12
``dxi/dt = 0`` plus process noise)::

    x_a = [y, psi, y_f, dy, dpsi, dy_f, xi]                      (m, rad, m, m/s, rad/s, m/s, m)

    dx_a/dt = F_c x_a + w,      F_c = [[A, B[:, xi]],            (eq. 15; B[:, xi] is
                                       [0,     0   ]]             M^-1 K_d of eq. 16)
    z       = H x_a + v,        H   = [[C[ddy],   D[ddy,   xi]],  wheelset lateral acc.  m/s2
                                       [e_dpsi,   0          ],  axle-box gyro          rad/s
                                       [C[ddy_f], D[ddy_f, xi]],  frame lateral acc.    m/s2
                                       [0,        1          ]]  virtual xi = 0         m
                                                                  (eq. 17)

The ``xi`` column of ``H`` is ``D``: the gravitational stiffness puts ``xi`` directly into the
wheelset's acceleration (``D[ddy_f, xi]`` is 0 for this model; it is kept for generality).
The input ``xi_rate`` has no column: the SM's forces do not depend on it (it only feeds the
FMU's first-order hold), and ``B[:, xi_rate]`` is zero.

The last row is the paper's *virtual* measurement: a zero reading of ``xi`` with standard
deviation ``sigma_virtual`` at every sample. It is needed, not only convenient: a rigid lateral
shift of wheelset, frame and track together (``y``, ``y_f``, ``xi`` + c) changes no creepage,
no suspension force and no gravitational force, so without it the three sensors cannot tell
where the track is (the rank of the observability matrix would be 6). The zero reading pins
that common mode and makes the estimate of ``xi`` a high-pass.

Discretisation
--------------
Zero-order hold of the autonomous augmented system, ``F = expm(F_c dt)``, which is exact for
the linear model at every dt, and the process noise by Van Loan's method
(:func:`railfmu.estimators.core.discretize.van_loan`)::

    expm([[-F_c, Q_c], [0, F_c^T]] dt) = [[., Phi^-1 Q_d], [0, Phi^T]],   Q_d = Phi (Phi^-1 Q_d)

``H`` needs no discretisation: ``z_k = H x_a(t_k)``. The paper discretises with an Euler step
whose position rows use a second-order Taylor expansion (eqs. 18-19); ``expm`` is the exact
version of that, costs nothing at run time (computed once), and is stable at any ``dt``.

Noise
-----
* Measurement noise ``R = diag(sigma_acc^2, sigma_gyro^2, sigma_acc^2, sigma_virtual^2)``:
  the paper's §5 sensor values, 0.01 m/s2 for the accelerometers and 5e-4 rad/s for the gyro.
* Process noise ``Q_c = diag(0, 0, 0, q_acc, q_yaw, q_acc, q_xi)`` (continuous white-noise
  intensities: m^2/s^3, rad^2/s^3, m^2/s). The paper estimates ``Q`` and ``R`` from the complete
  model's residuals (eqs. 28-31); the filter has no complete model, so:

  - ``q_xi``: between the ERRI B176 corner wavelengths (``2 pi / Omega_c`` = 7.6 m and
    ``2 pi / Omega_r`` = 305 m) the alignment *is* a random walk in space: the one-sided
    ``S_a(Omega) ~= A_a / Omega^2`` (m^2/(rad/m)). In time at speed ``V`` that is
    ``A_a V / omega^2`` (one-sided, rad/s); a random walk of intensity ``q`` has the one-sided
    PSD ``q / (pi omega^2)``, so ``q_xi = pi A_a V`` (1.33e-5 m^2/s for the low level,
    ``psd_level`` 1, at 20 m/s).
  - ``sigma_virtual``: on its own, a zero reading of a random walk at every sample tracks it
    with the bandwidth ``omega_c = sqrt(q_xi / (sigma_virtual^2 dt))``: what is slower is
    pulled to zero, as if the alignment were a first-order Markov process with that corner.
    Below ``Omega_r`` the ERRI spectrum is flat, i.e. exactly such a process, so
    ``omega_c = V Omega_r``: ``sigma_virtual = sqrt(q_xi / dt) / (V Omega_r)`` (0.28 m at
    20 m/s and 1 kHz). It scales with ``1 / sqrt(dt)``, so the filter hardly changes with the
    sample rate. **Deviation**: the paper uses 5 mm (its sample time is not stated). On our FMU
    data at 1 kHz, 5 mm pins the common mode so hard that the long wavelengths are lost
    (J_rel 0.92 in 3-200 m: D2 0.59, D3 0.99; 0.23 on a 1 mm / 20 m harmonic); the
    spectrum-based value gives 0.17 and 0.11 (``tests/test_alignment.py``).
  - **Tuning the pair** (measured): the stationary filter's transfer function from the true
    alignment to its estimate, on its own design model, is flat at 0.934 from 0.1 to 5 Hz
    at the spectrum-based pair (at 20 m/s, 1 kHz, the paper's sensor noise): every
    wavelength is shrunk by 7 %, and the pinning adds a phase lead of 14 deg at 200 m. A
    larger ``q_xi`` with a weaker pinning (a larger ``sigma_virtual``) lifts the gain towards
    1 (0.995 at 1e-2 m^2/s with the same corner) and moves the lead below the D3 band; the
    lateral_alignment experiment tunes the pair on a training track
    (``experiments/lateral_alignment/tune.py``: 8e-4 m^2/s, 8 m).
  - ``q_acc``, ``q_yaw``: model error of the SM's accelerations. Default 0 (the design model
    equals the simulated one); raise them when the data come from another model (a mismatch
    in conicity, creep coefficients, or a full vehicle).

Filter
------
Eqs. 20-26 of the paper: ``x^- = F x^+``, ``P^- = F P^+ F^T + Q_d``, ``K = P^- H^T (H P^- H^T + R)^-1``,
``x^+ = x^- + K (z - H x^-)``, ``P^+ = (I - K H) P^- (I - K H)^T + K R K^T`` (Joseph form).

* ``steady_state=True`` (default): the fixed gain of the stationary filter, from the discrete
  algebraic Riccati equation in scaled states (:func:`railfmu.estimators.core.kalman.steady_state`: scipy's
  QZ solver, the doubling algorithm where the common mode's pole is too close to 1). A step
  is a few small matrix-vector products.
* ``steady_state=False``: ``filterpy.kalman.KalmanFilter`` (its ``update`` is the Joseph form)
  from the initial a-priori covariance ``P0``, by default the stationary one (so both
  versions give the same estimates); a cold start (a larger ``P0``) converges slowly, with
  the slowest closed-loop pole (about 0.1 1/s at the defaults): the common mode is pinned
  only by the virtual reading.

The first sample is an update of the initial estimate ``x_a = 0`` (no prediction). A missing
sensor (NaN, or masked out by the observer bank) is left out: the update uses the sensors
present and the virtual reading (the fixed-gain filter with the gain of those rows at the
stationary ``P^-``); a sample with no sensor is a prediction only.

Smoother (offline, beyond the paper)
------------------------------------
:meth:`AlignmentKalmanFilter.smooth` adds the Rauch-Tung-Striebel backward pass to the same
forward filter: ``x^s_k = x^+_k + C_k (x^s_{k+1} - F x^+_k)``, ``C_k = P^+_k F^T (P^-_{k+1})^-1``;
for the fixed gain the stationary smoother, computed in the modified Bryson-Frazier form
(:func:`railfmu.estimators.core.smoothers.mbf_stationary`: no inverse of ``P^-``, stable whenever the
filter is); :func:`railfmu.estimators.core.smoothers.rts` for the time-varying filter. The filter's
estimate of ``xi`` lags (it is causal and its bandwidth is set by the slow common-mode
pinning); the smoother removes the lag. It leans on
the design model across time, so it needs a model that is right over the whole band: on the
complete vehicle model it runs on its own equivalent SM (experiments/lateral_alignment/tune.py).

Observability (the paper's eq. 27): :meth:`AlignmentKalmanFilter.observability_rank` is the rank of
``control.obsv(F, H)``; 7 for the paper's parameters.

Deviations from the paper: ``expm``/Van Loan instead of the modified Euler step; ``Q`` and
``sigma_virtual`` from the track spectrum instead of eqs. 28-31 and 5 mm; the paper's eq. 16
gravitational term is replaced by the design model's derivation (see
:mod:`railfmu.models.vehicle.wheelset`); the paper's eq. 17 prints the gyro and virtual rows with 6 entries,
read here as selecting ``dpsi`` and ``xi``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from railfmu.models.design import DesignModel
from railfmu.models.track import erri_b176 as track

from railfmu.estimators.core import fixed_gain, kalman, smoothers
from railfmu.estimators.core.discretize import van_loan
from railfmu.estimators.core.observer import _TIME_RTOL, Observer, OfflineObserver
from railfmu.estimators.core.settings import Settings, setting

#: the design model's numbers (parameters, linearisation) from the cache: building
#: :data:`railfmu.models.vehicle.wheelset.WHEELSET` (sympy) only when they are not there
WHEELSET = DesignModel("railfmu.models.vehicle.wheelset", "WHEELSET")

STATES = ("y", "psi", "y_f", "dy", "dpsi", "dy_f", "xi")
_STATE_UNITS = ("m", "rad", "m", "m/s", "rad/s", "m/s", "m")


def q_xi_from_spectrum(V: float, level: int = 1) -> float:
    """Random-walk intensity (m^2/s) of the alignment at speed ``V`` (m/s) that matches the
    ERRI B176 alignment spectrum between its corner wavelengths: ``pi A_a V``."""
    if int(level) not in track.ERRI_B176_LEVELS:
        raise ValueError(f"psd_level must be 1 (low) or 2 (high) to derive q_xi, not {level!r}")
    return math.pi * track.ERRI_B176_LEVELS[int(level)][0] * V


def sigma_virtual_from_spectrum(q_xi: float, V: float, dt: float) -> float:
    """Standard deviation (m) of the virtual zero reading of ``xi`` at every sample ``dt`` (s)
    that puts the forgetting of the random walk ``q_xi`` (m^2/s) at the ERRI B176 corner
    ``Omega_r`` at speed ``V`` (m/s): ``sqrt(q_xi / dt) / (V Omega_r)``."""
    return math.sqrt(q_xi / dt) / (V * track.OMEGA_R)


@dataclass(frozen=True)
class AlignmentSettings(Settings):
    """The filter's own settings (the design model's, ``V`` and any WHEELSET parameter, beside
    them are checked by the model); None: derived (module docstring)."""

    sigma_acc: float = setting(0.01, "m/s2", "accelerometer noise std (ddy, ddy_f); squares into R", gt=0)
    sigma_gyro: float = setting(5e-4, "rad/s", "yaw-rate gyro noise std (dpsi)", gt=0)
    sigma_virtual: float | None = setting(None, "m", "std of the virtual reading xi = 0; default "
                                          "sigma_virtual_from_spectrum", gt=0)
    q_xi: float | None = setting(None, "m^2/s", "random-walk intensity of xi; default q_xi_from_spectrum(V, "
                                 "psd_level)", gt=0)
    psd_level: int = setting(1, "", "ERRI B176 level (1 low, 2 high) of the default q_xi")
    q_acc: float = setting(0.0, "m^2/s^3", "white-noise intensity on the lateral velocities", ge=0)
    q_yaw: float = setting(0.0, "rad^2/s^3", "white-noise intensity on the yaw rate", ge=0)
    steady_state: bool = setting(True, "", "stationary gain from the DARE (else the time-varying filter)")
    P0: tuple[float, ...] | None = setting(None, "state units", "7 standard deviations of the initial estimate "
                                           "(time-varying filter; default the stationary a-priori covariance)",
                                           gt=0, length=7)


#: typical magnitudes of the states (m, rad, m, m/s, rad/s, m/s, m) to balance the DARE
_STATE_SCALE = np.array([1e-2, 1e-4, 1e-2, 1e-3, 1e-3, 1e-3, 1e-2])


class AlignmentKalmanFilter(Observer):
    """The Kalman filter of Muñoz et al. for the lateral track alignment under one wheelset.

    Inputs: ``ddy`` wheelset lateral acceleration (m/s2), ``dpsi`` wheelset yaw rate (rad/s),
    ``ddy_f`` suspended-frame lateral acceleration (m/s2); the virtual ``xi = 0`` is internal.
    Outputs: the state ``y`` (m), ``psi`` (rad), ``y_f`` (m), ``dy`` (m/s), ``dpsi`` (rad/s),
    ``dy_f`` (m/s), and the alignment ``xi`` (m).

    Settings: ``V`` (m/s, 20), any :data:`railfmu.models.vehicle.wheelset.WHEELSET` parameter (``alpha``,
    ``f11``, ...) and :class:`AlignmentSettings` (units, defaults, checks), as ``self.config``.
    The equations are in the module docstring.
    """

    measurements: ClassVar[tuple[str, ...]] = ("ddy", "dpsi", "ddy_f")
    outputs: ClassVar[tuple[str, ...]] = STATES
    units: ClassVar[dict[str, str]] = {"ddy": "m/s2", "dpsi": "rad/s", "ddy_f": "m/s2",
                                       **dict(zip(STATES, _STATE_UNITS, strict=True))}

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        model = WHEELSET.default_parameters()
        self.config = c = AlignmentSettings.from_mapping(settings, "AlignmentKalmanFilter", extra=model)
        self.params = {**model, **{k: float(v) for k, v in settings.items() if k in model}}
        WHEELSET.check_parameters(self.params)
        V = self.params["V"]
        self.q_xi = c.q_xi if c.q_xi is not None else q_xi_from_spectrum(V, c.psd_level)
        self.sigma_virtual = (c.sigma_virtual if c.sigma_virtual is not None
                              else sigma_virtual_from_spectrum(self.q_xi, V, self.dt))
        self.steady_state = c.steady_state

        A, B, C, D = WHEELSET.linearize(self.params)
        i_xi = WHEELSET.inputs.index("xi")
        rows = WHEELSET.outputs
        F_c = np.zeros((7, 7))
        F_c[:6, :6] = A
        F_c[:6, 6] = B[:, i_xi]
        H = np.zeros((4, 7))
        H[0, :6], H[0, 6] = C[rows.index("ddy")], D[rows.index("ddy"), i_xi]
        H[1, STATES.index("dpsi")] = 1.0
        H[2, :6], H[2, 6] = C[rows.index("ddy_f")], D[rows.index("ddy_f"), i_xi]
        H[3, 6] = 1.0
        Q_c = np.diag([0.0, 0.0, 0.0, c.q_acc, c.q_yaw, c.q_acc, self.q_xi])
        self.F_c, self.H, self.Q_c = F_c, H, Q_c
        self.F, self.Q = van_loan(F_c, Q_c, self.dt)
        self.R = np.diag(np.square([c.sigma_acc, c.sigma_gyro, c.sigma_acc, self.sigma_virtual]))

        # stationary filter: P^- from the DARE in scaled states (the covariances span ten decades)
        try:
            self.P_prior, self.P_post, self.K, self._S = kalman.steady_state(
                self.F, self.H, self.Q, self.R, scale=_STATE_SCALE)
        except ValueError as e:
            raise ValueError(f"AlignmentKalmanFilter: {e}") from None
        self.P0 = self.P_prior.copy() if c.P0 is None else np.diag(np.square(c.P0))
        self._zbuf = np.zeros(4)  # [ddy, dpsi, ddy_f, 0]: the virtual reading stays 0
        self._row_gains: dict[tuple[int, ...], np.ndarray] = {}
        self._block: fixed_gain.BlockFilter | None | bool = False  # False: not built yet
        self.reset()

    # -- Observer hooks ------------------------------------------------------------------------
    def _reset(self) -> None:
        self._x = np.zeros(7)
        if not self.steady_state:
            from filterpy.kalman import KalmanFilter  # only here: importing filterpy pulls in scipy.stats

            kf = KalmanFilter(dim_x=7, dim_z=4)
            kf.F, kf.H, kf.Q, kf.R = self.F, self.H, self.Q, self.R
            kf.P = self.P0.copy()
            self._kf = kf

    def _predict(self) -> None:
        if self.steady_state:
            self._x = self.F @ self._x
        else:
            self._kf.predict()

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        zb = self._zbuf
        zb[:3] = z
        if not mask.all():  # a sensor missing: the rows present and the virtual reading
            self._update_rows(tuple(np.flatnonzero(mask)) + (3,))
        elif self.steady_state:
            x = self._x
            self._x = x + self.K @ (zb - self.H @ x)
        else:
            self._kf.update(zb)

    def step_block(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray | None = None,
                   mask: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`Observer.step_block`: the fixed-gain filter runs each stretch of samples one
        ``dt`` apart with every sensor present as one compiled call
        (:mod:`railfmu.estimators.core.fixed_gain`, equal bit for bit to :meth:`step`); any other
        sample (the first, a gap, a missing sensor) goes through :meth:`step`."""
        t = np.asarray(t, dtype=float)
        n = t.shape[0]
        if out is None:
            out = np.empty((n, len(self.outputs)))
        self.prepare()
        Z = np.asarray(Z, dtype=float)
        if self._block is None or n == 0 or Z.shape != (n, 3):
            return super().step_block(t, Z, U, mask, out)
        ok = np.isfinite(Z).all(axis=1)
        if mask is not None:
            ok &= np.asarray(mask, dtype=bool).all(axis=1)
        prev = np.empty(n)
        prev[0] = np.nan if self._t is None else self._t
        prev[1:] = t[:-1]
        d = t - prev
        steps = np.round(d / self.dt)  # Observer._n_steps: one dt later, within its tolerance
        ok &= (steps == 1) & (np.abs(d - steps * self.dt) <= _TIME_RTOL * self.dt)
        i = 0
        while i < n:
            if not ok[i]:
                try:
                    super().step_block(t[i:i + 1], Z[i:i + 1], None, None if mask is None else mask[i:i + 1],
                                       out[i:i + 1])
                except (ArithmeticError, ValueError) as exc:
                    exc.rows_done = i
                    raise
                i += 1
                continue
            j = i + int(np.argmin(ok[i:])) if not ok[i:].all() else n
            self._block.run(self._x, Z[i:j], out[i:j])
            self._t = float(t[j - 1])
            self.steps += j - i
            i = j
        return out

    def prepare(self) -> None:
        """Build (load) the compiled fixed-gain recursion of :meth:`step_block`."""
        if self._block is False:
            self._block = fixed_gain.block_filter(self.F, self.H, self.K, 3) if self.steady_state else None

    def _update_rows(self, rows: tuple[int, ...]) -> None:
        """Update with the rows ``rows`` of ``H`` only (some sensors missing). The fixed-gain
        filter uses the gain of those rows at the stationary ``P^-`` (cached per set of rows);
        the time-varying one its own covariance."""
        r = list(rows)
        H, R, z = self.H[r], self.R[np.ix_(r, r)], self._zbuf[r]
        if self.steady_state:
            K = self._row_gains.get(rows)
            if K is None:
                PHt = self.P_prior @ H.T
                K = self._row_gains[rows] = np.linalg.solve(H @ PHt + R, PHt.T).T
            self._x = self._x + K @ (z - H @ self._x)
        else:
            self._kf.update(z[:, None], R=R, H=H)  # filterpy: z as a column when H is passed

    def _estimate(self) -> np.ndarray:
        if self.steady_state:
            return self._x.copy()
        return self._kf.x[:, 0].copy()

    # -- offline smoothing --------------------------------------------------------------------
    def smooth(self, t: np.ndarray, Z: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        r"""Offline Rauch-Tung-Striebel smoother: times ``(n,)`` and measurements
        ``(n, len(inputs))`` as for :meth:`run` -> smoothed estimates ``(n, len(outputs))`` of
        the same outputs, each conditioned on the whole record (past *and* future). Beyond
        Muñoz et al., who filter only.

        Forward pass: exactly :meth:`run` (the same hook calls in the same order, so the
        filtered estimates are bit-identical; a dropped row is predicted over, a row with
        missing sensors (non-finite or out of ``mask``) updates with the sensors present), on the grid of every sample time ``dt`` from ``t[0]``, so a
        gap of ``m`` steps contributes ``m - 1`` prediction-only grid points. Backward pass
        (Rauch, Tung & Striebel, AIAA J. 3 (1965) 1445), from ``x^s_N = x^+_N``::

            x^-_{k+1} = F x^+_k
            x^s_k     = x^+_k + C_k (x^s_{k+1} - x^-_{k+1})
            C_k       = P^+_k F^T (P^-_{k+1})^{-1},   P^-_{k+1} = F P^+_k F^T + Q_d

        On a prediction-only grid point ``x^+_k = x^-_k``: the smoother passes through it.

        * ``steady_state=True``: the stationary smoother of the fixed-gain filter (constant
          ``C`` from the DARE's :attr:`P_prior` and :attr:`P_post`), computed in the modified
          Bryson-Frazier form (:func:`railfmu.estimators.core.smoothers.mbf_stationary`): the same
          estimate without inverting ``P^-``, and a backward recursion that is stable
          whenever the filter is. Like the
          fixed gain it would ignore the larger covariance after a gap, records with gaps or
          missing sensors are smoothed by the time-varying filter's smoother from the same
          stationary start (the forward estimates stay the fixed gain's). One 7x7 product
          per step.
        * ``steady_state=False``: :func:`railfmu.estimators.core.smoothers.rts` on the filtered means and
          covariances of every grid point (the time-varying ``C_k``).

        For the time-varying filter ``(P^-)^{-1}`` is applied through the Cholesky factor of
        the correlation matrix ``D^{-1} P^- D^{-1}`` (``D = sqrt(diag P^-)``): ``P^-`` spans
        ten decades (1e-15 to 1e-5, condition ~1e10), the correlation matrix far fewer.

        Afterwards the filter stands where :meth:`run` would leave it (end of the record,
        :attr:`steps` and :attr:`skipped` counted), and :attr:`last_filtered` holds the
        forward estimates at the sample times (equal to what :meth:`run` returns)."""
        t, Z, _, present = self._record(t, Z, None, mask, "smooth")
        n = t.shape[0]
        if n == 0:
            return np.empty((0, len(self.outputs)))
        gaps = [0] + [self._n_steps(float(t[k - 1]), float(t[k])) for k in range(1, n)]
        ok = present.all(axis=1)
        some = present.any(axis=1)
        self.reset(float(t[0]))
        n_grid = 1 + sum(gaps)
        rows = np.cumsum(gaps)  # grid index of each sample
        X = np.empty((n_grid, 7))
        P = None if self.steady_state else np.empty((n_grid, 7, 7))
        g = 0
        if self.steady_state:
            # _predict and _update inlined, operation for operation (the same products in the
            # same order, so bit-identical to run; the hook calls cost half the time); the
            # innovations are kept for the backward pass
            F, K, H, zb, x = self.F, self.K, self.H, self._zbuf, self._x
            NU = np.zeros((n_grid, 4))
            for k in range(n):
                for i in range(gaps[k]):
                    x = F @ x
                    if i < gaps[k] - 1:  # a prediction-only grid point inside a gap
                        X[g] = x
                        g += 1
                if ok[k]:
                    zb[:3] = Z[k]
                    nu = zb - H @ x
                    x = x + K @ nu
                    NU[g] = nu
                elif some[k]:  # some sensors missing: smoothed below by the time-varying twin
                    self._x = x
                    self._update(Z[k], present[k])
                    x = self._x
                X[g] = x
                g += 1
            self._x = x
        else:
            kf = self._kf
            for k in range(n):
                for i in range(gaps[k]):
                    self._predict()
                    if i < gaps[k] - 1:
                        X[g], P[g] = kf.x[:, 0], kf.P
                        g += 1
                if some[k]:
                    self._update(Z[k], present[k])
                X[g], P[g] = kf.x[:, 0], kf.P
                g += 1
        self.steps, self.skipped, self._t = n, int(n - some.sum()), float(t[-1])
        self.partial = int(some.sum() - ok.sum())
        #: the forward (filtered) estimates of the last smooth(), at the sample times
        self.last_filtered = X[rows]

        if self.steady_state and n_grid == n and ok.all():
            Xs = smoothers.mbf_stationary(X, NU, self.F, self.H, self.K, self._S, self.P_post)
        elif self.steady_state:
            # a gap or a NaN row: the covariance is no longer the stationary one, and the
            # stationary smoother would turn the large innovation after the gap into a large
            # backward correction (measured: rms 7 x rms(xi) for a 50 ms gap). The smoother of
            # the time-varying filter from the same stationary start instead (rms 0.4 %).
            twin = type(self)(self.dt, **{**self.settings, "steady_state": False})
            return twin.smooth(t, Z, present)
        else:
            Xs = smoothers.rts(X, P, self.F, self.Q)[0]
        return Xs[rows]

    # -- diagnostics -------------------------------------------------------------------------
    @property
    def covariance(self) -> np.ndarray:
        """Posterior covariance of the current estimate (the stationary one for the fixed gain)."""
        return self.P_post.copy() if self.steady_state else self._kf.P.copy()

    def observability_rank(self) -> int:
        """Rank of the observability matrix of (F, H) (Muñoz et al., eq. 27); 7 = observable."""
        return int(np.linalg.matrix_rank(kalman.observability_matrix(self.F, self.H)))

    def finish(self) -> dict:
        P = self.covariance
        return {**super().finish(), "steady_state": self.steady_state, "q_xi": self.q_xi,
                "sigma_virtual": self.sigma_virtual, "sigma_xi": float(math.sqrt(P[6, 6])),
                "observability_rank": self.observability_rank()}


class AlignmentRTSSmoother(OfflineObserver):
    """The offline RTS smoother of :class:`AlignmentKalmanFilter` as an observer of the run:
    given the whole record, the estimates conditioned on past and future
    (:meth:`AlignmentKalmanFilter.smooth`). Measurements, outputs, units and settings are the
    filter's (a smoother on its own design model takes that model's settings)."""

    measurements: ClassVar[tuple[str, ...]] = AlignmentKalmanFilter.measurements
    outputs: ClassVar[tuple[str, ...]] = AlignmentKalmanFilter.outputs
    units: ClassVar[dict[str, str]] = AlignmentKalmanFilter.units

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.filter = AlignmentKalmanFilter(dt, **settings)

    def _run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray, mask: np.ndarray) -> np.ndarray:
        return self.filter.smooth(t, Z, mask)

    def observability_rank(self) -> int:
        return self.filter.observability_rank()

    def finish(self) -> dict:
        return self.filter.finish()
