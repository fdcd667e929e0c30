r"""Running resistance of a unit whose resistance is not known: coasting found from the
kinematics, then recognition and estimation iterated (``CoastingEM``, registered
``resistance_coasting_em``; an offline estimator over the whole run, as the paper's
processing of Cunillera et al. (2022) is, and its §5 purpose: calibrate a unit).

Why. :class:`~railfmu.estimators.train.running_resistance.ImprovedEstimator` recognises
coasting with the published coefficients ``theta0`` as truth: a window is coasting if the
effort eq. 1 needs with ``theta0`` is within ``effort_band``, and a segment only if its mean
effort fits ``theta0``'s predictive distribution. A unit at 1.4 theta0 coasts with an
apparent effort of -(0.4 r0(v)), beyond both tests: no segment, the estimate stays on the
prior. Zero effort is not observable; the GNSS speed and position are.

Method (SI, mass-specific; fixes ``t_k, s_k, v_k``; interval quantities as
``ImprovedEstimator``: ``phi_i = (1, vb_i, vb_i^2)``, ``g_i`` the mean line term)::

    u_w(theta) = (v_b - v_a) / T_w + sum_i (dt_i / T_w) (phi_i^T theta + g_i)          (C0)

1. Hypotheses: ``theta_h = theta0 * (c0, c1, c2)``, each factor on a log grid of
   ``grid_points`` values over [``ratio_low``, ``ratio_high``] (a plausible range for any
   rolling stock, 1/4 to 4: wider than any unit is from its published values).
2. Consensus: for each hypothesis the coasting segments ``ImprovedEstimator`` would accept
   with ``theta_h`` as its prior centre (window band, trimming, ``min_coast``, the predictive
   test with ``test_rel_sigma``); its score is the accepted coasting time. A speed hold
   fits no hypothesis (its speed does not fall as a positive resistance makes it), braking
   and traction none either (their apparent resistance is far outside the box); true coasting
   fits the hypotheses near the truth. The best-scoring hypothesis seeds step 3.
3. Iteration (an EM of the regimes and the coefficients): recognise with the current
   ``theta^`` as the centre (same tests), fit (C3) to the accepted segments with the wide
   prior ``N(theta0, diag(prior_rel_sigma theta0)^2)``::

       theta^ = (Lambda0 + sum A_seg)^-1 (Lambda0 theta0 + sum b_seg)                  (C3)

   (``A_seg, b_seg``: :func:`~railfmu.estimators.train.running_resistance.coasting_information`),
   until the segment set repeats (at most ``iterations``).
4. Outputs at every sample: ``s, v`` from the kinematic Kalman filter of
   ``ImprovedEstimator`` (white jerk; no resistance), in an accepted segment ``v`` from the
   segment's fit (C2) with ``theta^``; ``r0..r2 = theta^`` (constant: the run's
   calibration); ``acceleration`` the interval's ``(v^_k - v^_(k-1)) / dt`` (in coasting
   ``-(r^(v^) + g)``), ``effort = acceleration + r^(v^) + g(s^)`` (eq. 1): the regimes and
   features read the run with the calibrated resistance.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from railfmu.estimators.core.observer import OfflineObserver
from railfmu.estimators.core.settings import setting
from railfmu.estimators.train.running_resistance import (ImprovedEstimator, ImprovedSettings, LineTerm,
                                                         PaperUKF, coasting_information)


@dataclass(frozen=True)
class CoastingEMSettings(ImprovedSettings):
    """:class:`CoastingEM` (module docstring): ``ImprovedEstimator``'s tests and filter, the
    hypothesis grid, the wide prior of the fit."""

    prior_rel_sigma: float = setting(1.0, "", "std of the fit's prior on theta, a fraction of theta0 (wide)", gt=0)
    test_rel_sigma: float = setting(0.1, "", "relative std about a hypothesis in the segment test", gt=0)
    ratio_low: float = setting(0.25, "", "smallest factor on theta0 a hypothesis takes", gt=0)
    ratio_high: float = setting(4.0, "", "largest factor on theta0 a hypothesis takes", gt=0)
    grid_points: int = setting(13, "", "hypotheses per coefficient (log grid)", ge=1)
    iterations: int = setting(10, "", "most recognition-estimation rounds", ge=1)


class _Kinematic(ImprovedEstimator):
    """ImprovedEstimator's kinematic filter alone (no segments: outputs s, v^, a_interval)."""

    def _add_fix(self, t: float, s: float, v: float) -> None:
        pass


class CoastingEM(OfflineObserver):
    """Davis coefficients of an unknown unit from one run's GNSS fixes (module docstring).
    Measurements ``position``, ``speed`` (a fix where both are present); outputs as
    :class:`PaperUKF`. ``finish()`` adds the segments, the iterations and the posterior sigmas."""

    measurements: ClassVar[tuple[str, ...]] = PaperUKF.measurements
    outputs: ClassVar[tuple[str, ...]] = PaperUKF.outputs
    units: ClassVar[dict[str, str]] = PaperUKF.units
    event_driven: ClassVar[bool] = True
    regime_recogniser: ClassVar[str] = "hmm"

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.config = p = CoastingEMSettings.from_mapping(settings, type(self).__name__)
        self.settings_in = dict(settings)
        self.line = LineTerm(p.line_file, p.rotating_mass_factor)
        self.theta0 = np.array([p.r0_init, p.r1_init, p.r2_init])
        self._W = p.recognition_window * (1.0 - 1e-9)
        self.prior_cov = np.diag((p.prior_rel_sigma * self.theta0) ** 2)  # the fit's prior (C3)
        self.diag: dict = {}

    # -- the record's fixes and sums ----------------------------------------------------------
    def _prepare(self, t: np.ndarray, s: np.ndarray, v: np.ndarray) -> None:
        """Cumulative sums over the fixes: Phi_j = sum dt (1, vb, vb^2), G_j = sum dt g."""
        self.t, self.s, self.v = t, s, v
        dt = np.diff(t)
        vb = 0.5 * (v[1:] + v[:-1])
        g = np.array([self._g_mean(a, b) for a, b in zip(s[:-1], s[1:])])
        self.vb, self.g = vb, g
        self.Phi = np.vstack([np.zeros(3), np.cumsum(dt[:, None] * np.c_[np.ones_like(vb), vb, vb * vb], axis=0)])
        self.G = np.r_[0.0, np.cumsum(dt * g)]
        # windows: for each last fix b, the last fix a at least a window before it
        a = np.searchsorted(t, t - self._W, side="right") - 1
        ok = a >= 0
        self.wb, self.wa = np.flatnonzero(ok), a[ok]
        self.wb, self.wa = self.wb[self.wb > self.wa], self.wa[self.wb > self.wa]

    def _g_mean(self, s0: float, s1: float) -> float:
        if abs(s1 - s0) < 1.0:
            return self.line.at(0.5 * (s0 + s1))
        return (self.line.integral(s1) - self.line.integral(s0)) / (s1 - s0)

    def _efforts(self, a: np.ndarray, b: np.ndarray, Theta: np.ndarray) -> np.ndarray:
        """(C0) over fixes a..b (arrays) for each row of Theta (H, 3): (H, len(a))."""
        T = self.t[b] - self.t[a]
        return ((self.v[b] - self.v[a] + self.G[b] - self.G[a])[None, :]
                + Theta @ (self.Phi[b] - self.Phi[a]).T) / T[None, :]

    # -- recognition --------------------------------------------------------------------------
    def _segments(self, Theta: np.ndarray) -> list[list[tuple[int, int]]]:
        """Per hypothesis (row of Theta) the accepted coasting segments (first, last fix)."""
        p = self.config
        n = len(self.t) - 1  # intervals
        passed = np.abs(self._efforts(self.wa, self.wb, Theta)) <= p.effort_band
        fast = self.vb > p.min_speed
        out = []
        for h in range(Theta.shape[0]):
            cand = np.zeros(n, bool)
            for a, b in zip(self.wa[passed[h]], self.wb[passed[h]]):
                cand[a:b] = True
            cand &= fast
            out.append(self._accepted(cand, Theta[h]))
        return out

    def _accepted(self, cand: np.ndarray, theta: np.ndarray) -> list[tuple[int, int]]:
        """Maximal runs of candidate intervals, trimmed by a window at each end, of min_coast,
        whose mean effort passes the predictive test about ``theta``."""
        p = self.config
        t = self.t
        segs = []
        edges = np.flatnonzero(np.diff(np.r_[0, cand.astype(int), 0]))
        for first, end in zip(edges[::2], edges[1::2]):  # intervals [first, end): fixes first..end
            f0 = bisect.bisect_left(t, t[first] + self._W)
            f1 = bisect.bisect_right(t, t[end] - self._W) - 1
            if f1 <= f0 or t[f1] - t[f0] < p.min_coast:
                continue
            T = t[f1] - t[f0]
            phibar = (self.Phi[f1] - self.Phi[f0]) / T
            var = 2.0 * p.sigma_speed ** 2 / T ** 2 + np.sum((p.test_rel_sigma * theta * phibar) ** 2)
            u = self._efforts(np.array([f0]), np.array([f1]), theta[None, :])[0, 0]
            if abs(u) <= p.test_sigmas * np.sqrt(var):
                segs.append((int(f0), int(f1)))
        return segs

    # -- estimation ---------------------------------------------------------------------------
    def _fit(self, segs: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
        """(C3) with the wide prior: (theta^, its covariance)."""
        p = self.config
        L0 = np.linalg.inv(self.prior_cov)
        A, b = L0.copy(), L0 @ self.theta0
        for f0, f1 in segs:
            Ai, bi = coasting_information(self.t[f0:f1 + 1], self.v[f0:f1 + 1], self.g[f0:f1], p.sigma_speed)
            A, b = A + Ai, b + bi
        P = np.linalg.inv(A)
        return P @ b, 0.5 * (P + P.T)

    def calibrate(self, t: np.ndarray, s: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
        """Steps 1-3 on fixes ``t, s, v`` (s, m, m/s): (theta^, covariance, segments)."""
        p = self.config
        self._prepare(np.asarray(t, float), np.asarray(s, float), np.asarray(v, float))
        if len(self.t) < 3:
            P = np.diag((p.prior_rel_sigma * self.theta0) ** 2)
            return self.theta0.copy(), P, []
        c = np.geomspace(p.ratio_low, p.ratio_high, p.grid_points)
        C = np.stack(np.meshgrid(c, c, c, indexing="ij"), -1).reshape(-1, 3)
        per = self._segments(self.theta0 * C)
        score = np.array([sum(self.t[b] - self.t[a] for a, b in sg) for sg in per])
        # best time; among ties the hypothesis closest to theta0 (least log distance)
        best = np.lexsort((np.sum(np.log(C) ** 2, axis=1), -score))[0]
        segs = per[best]
        theta, P = self._fit(segs)
        rounds = 0
        for rounds in range(1, p.iterations + 1):
            new = self._segments(np.maximum(theta, 1e-12)[None, :])[0]
            if new == segs:
                break
            segs = new
            theta, P = self._fit(segs)
        self.diag = {"hypothesis_ratio": [float(x) for x in C[best]], "hypothesis_coast_s": float(score[best]),
                     "iterations": rounds}
        return theta, P, segs

    # -- the record ---------------------------------------------------------------------------
    def _run(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray, mask: np.ndarray) -> np.ndarray:
        kin = _Kinematic(self.dt, **{k: v for k, v in self.settings_in.items()
                                     if k in ImprovedSettings.__dataclass_fields__})
        X = kin.run(t, Z, None, mask)  # s, v^, (theta0), a, effort
        both = mask.all(axis=1)
        rows = np.flatnonzero(both)
        theta, P, segs = self.calibrate(t[rows], Z[rows, 0], Z[rows, 1])
        self.theta, self.theta_cov, self.segments = theta, P, segs
        s_hat, v_hat = X[:, 0].copy(), X[:, 1].copy()
        coast = np.zeros(len(t), bool)
        for f0, f1 in segs:  # (C2): the segment's fit with theta^ at its fixes
            tt, vv = self.t[f0:f1 + 1], self.v[f0:f1 + 1]
            Xr = -(self.Phi[f0:f1 + 1] - self.Phi[f0])
            y = vv + self.G[f0:f1 + 1] - self.G[f0]
            c = np.mean(y - Xr @ theta)
            v_hat[rows[f0:f1 + 1]] = c + Xr @ theta - (self.G[f0:f1 + 1] - self.G[f0])
            coast[rows[f0 + 1:f1 + 1]] = True
        a = X[:, 5].copy()
        for j in range(1, len(rows)):  # the interval ending at each fix, held to the next
            k0, k1 = rows[j - 1], rows[j]
            a[k1] = (v_hat[k1] - v_hat[k0]) / (t[k1] - t[k0])
        r = theta[0] + theta[1] * v_hat + theta[2] * v_hat * v_hat
        g = self.line(s_hat)
        a = np.where(coast, -(r + g), a)
        effort = a + r + g
        return np.column_stack([s_hat, v_hat, np.broadcast_to(theta, (len(t), 3)), a, effort])

    def finish(self) -> dict:
        out = {**super().finish(), **self.diag}
        segs = getattr(self, "segments", [])
        out["coasting_segments"] = len(segs)
        out["coasting_s"] = float(sum(self.t[b] - self.t[a] for a, b in segs)) if segs else 0.0
        if hasattr(self, "theta_cov"):
            for name, sd in zip(("r0_sigma", "r1_sigma", "r2_sigma"), np.sqrt(np.diag(self.theta_cov))):
                out[name] = float(sd)
        return out
