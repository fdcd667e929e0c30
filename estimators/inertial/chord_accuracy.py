r"""Accuracy of the 30 m chord irregularities of a trolley survey (Jiang et al. (2017), § 5):
the chord errors that position errors cause, their prediction from the smoother's joint
Gaussian, the closed forms of eqs. 29-31 and the sensitivity curves of Figs. 8-11.

Chords and grid
---------------
The survey's chords are those of :func:`railfmu.models.track.geometry.chord_irregularity_along`:
consecutive chords ``[c, c + l]``, ``c = 0, l, 2 l, ...`` (``l`` = 30 m), points
``s = c, c + ds, ..., c + l - o`` (``ds`` = 0.5 m, offset ``o`` = 5 m) and the irregularity
of eq. 1, ``(d_s - d_{s+o}) - (dbar_s - dbar_{s+o})``, ``d`` the vector distance (eqs. 13-15,
:func:`railfmu.models.track.geometry.vector_distance`) of a surveyed point from its chord. The
design terms ``dbar`` are the same for the estimate and the truth, so the **chord error**
of a point is ::

    Delta_s = [d_s - d_{s+o}](r + e) - [d_s - d_{s+o}](r)          (alignment, level; m)

with ``r`` the true positions (n0 NED) of the four points it needs (``s``, ``s + o`` and
the chord's ends) and ``e`` their position errors. :func:`chord_grid` picks, from the true
along-track distance of a record, the record sample nearest to each grid distance
(multiples of ``ds``); :func:`chord_errors` evaluates ``Delta`` exactly (not linearised),
vectorised over any leading axes of ``e`` (one run, or ``S`` sampled error trajectories).
The errors are local NED, the positions n0: the two frames turn apart by the arc over the
Earth's radius, 1e-4 rad after 600 m, which changes a chord error by 1e-4 of itself (0.1 um
per mm): neglected.

Linearisation (the covariance map)
----------------------------------
To first order ``Delta_s = J_s [e_s, e_{s+o}, e_a, e_b]``; for a straight chord due north
this is eqs. 21-22, ``Delta_y = e_E(s) - e_E(s + o) + (o / l) (e_E(b) - e_E(a))``.
:func:`chord_error_jacobian` gives ``J`` (central differences of the exact map; the map is
smooth, so they are exact to ~1e-9 relative), the map a covariance goes through. It leaves
out terms of second order in the errors (the chord turns by ``~|e_b - e_a| / l`` while
points move along it by their along-track errors): for smooth errors whose chord errors
are ~1 mm it is off by ~1e-4 of them (0.1 um), growing in proportion to the errors (both
asserted in ``tests/test_chord_accuracy.py``). A constant error and a turn of the
whole survey about the vertical give no chord error, exactly.

Prediction of the RMS of the max
--------------------------------
The survey's figure of merit (from the paper's "We take the maximum value of track
irregularity error", § 6.1) is, per run, the maximum ``|Delta|`` over all surveyed chord
points, and over runs its RMS; the paper's Fig. 12 values themselves equal the largest
pointwise sigma (below, Sensitivity). From ``S`` samples of the smoother's joint Gaussian of
the position errors at the grid samples (``AidedInsSmoother.error_samples``, or
``covariance_analysis(...).error_samples``) :func:`predict_chord_sigma` returns
``sqrt(mean_S max_s Delta^2)`` (max over all surveyed points) for alignment and level, the
pointwise RMS of ``Delta`` along
the track (for the plots), and the relative standard error of the prediction (delta method:
``se(RMS) / RMS = std(M^2) / (2 sqrt(S) mean(M^2))``, ``M`` the per-sample maximum).
``std(M^2) / mean(M^2)`` is below 1 on the paper's nominal run with its sensor noise
(:func:`nominal_chord_accuracy`; ``tests/test_chord_accuracy.py``) and larger in the
noise-free simplified case of eqs. 29-31 (there the level error is one Gaussian times a
shape, ``M^2 ~ chi^2_1``: ``sqrt 2``), so the error falls as ``1 / sqrt(S)``, and at
``S = 500`` (:data:`DEFAULT_SAMPLES`) it is about that of a 500-run Monte Carlo's own RMS.
The sampling and the chord errors cost about linearly in ``S``.
:func:`chord_sigma_from_covariance` gives the pointwise sigma exactly from a joint
covariance instead (``SmootherRecord.joint_covariance`` at the grid epochs).

Sensitivity (Figs. 8-11)
------------------------
:func:`sensitivity_curves` runs ``railfmu.estimators.inertial.aided_ins.covariance_analysis`` on
:func:`nominal_run` (the paper's § 6.1 survey: straight, level, N45E, 30 m at 1 m/s, velocity
updates at both ends, navigation grade, 0.006 / 0.06 deg) varying one setting at a time.
At the nominal point the largest pointwise sigma on the chord is the paper's 0.99 mm
(alignment) and 0.70 mm (level) (its Fig. 12 Monte Carlo, which it calls consistent with this
covariance analysis: the Monte Carlo's peak RMS over runs,
``railfmu.experiments.trolley_survey.survey_accuracy``; within the tolerance asserted in
``tests/test_chord_accuracy.py``), and the predicted RMS over runs of the max is clearly
larger; the accelerometer noise (10 ug/sqrt(Hz)) makes most of both. As the paper remarks,
the level does not depend on the attitude errors, the gyro noise or the gyro biases, the
alignment not on the accelerometer bias, position updates at the ends change neither
noticeably, and both grow with the velocity update's sigma (the paper's Fig. 8: 1 mm of
alignment at 0.15 mm/s); these remarks are asserted in ``tests/test_chord_accuracy.py``.

Closed forms (eqs. 29-31)
-------------------------
The paper's simplified case: the error model of eq. 20 (eq. 7 without Earth rate and
Coriolis: ``phi_N' = -eps_N``, ``phi_D' = -eps_D``, ``dv_N' = g phi_E``, ``dv_E' = -g phi_N``,
``dv_D' = nabla_D``, ``dr' = dv``), no system noise, a straight track due north run in time
``T`` at constant speed, the initial covariance of eq. 25 with ``p_dv = sigma_v^2`` and
``p_dr = sigma_r^2``, one velocity + position update at ``T`` (sigmas ``sigma_v``,
``sigma_r``), RTS smoothing. Without system noise the smoothed error is the posterior error
of the initial state propagated, ``dr_E(t) = dr_0 + dv_0 t - g phi_N t^2 / 2 + g eps_N t^3 / 6``,
``dr_D(t) = dr_0 + dv_0 t + nabla_D t^2 / 2``, and eqs. 21-22 cancel every term linear in
``t``. With ``t_s`` the time of ``s``, ``t_s + k T`` that of ``s + o`` (``k = o / l``)::

    Q2 = k T ((1 - k) T - 2 t_s) / 2
    Q3 = k T ((1 - k^2) T^2 - 3 k T t_s - 3 t_s^2) / 6
    Var Delta_y = g^2 (Q2^2 P_phiphi - 2 Q2 Q3 P_phieps + Q3^2 P_epseps)          (eq. 29)
    Var Delta_z = Q2^2 P_nabla = Q2^2 2 p_nabla sigma_v^2 / (p_nabla T^2 + 2 sigma_v^2)   (eq. 30)

with the posterior of ``(phi_N, eps_N)`` after the update (``w = 1 / sigma_r^2``)::

    D        = 576 sv2 + 288 T^2 g^2 pphi + 72 T^4 g^2 peps
               + w (144 T^2 sv2^2 + 72 T^4 g^2 pphi sv2 + 20 T^6 g^2 peps sv2 + T^8 g^4 pphi peps)
    P_phiphi = 4 pphi (144 sv2 + 18 T^4 g^2 peps + w (36 T^2 sv2^2 + 5 T^6 g^2 peps sv2)) / D
    P_phieps = 36 T^3 g^2 pphi peps (4 + w T^2 sv2) / D
    P_epseps = 72 peps (4 + w T^2 sv2) (T^2 g^2 pphi + 2 sv2) / D

``w = 0`` (no position update) is eq. 31. Derived with sympy and checked against the
12-state system (``expm``, a Kalman update, the RTS smoother's covariances and
cross-covariances between ``0, t_s, t_s + k T, T``) in the tests. **Errata / reading
notes**: the paper writes these for its chord only, ``k = 1/6``, having put ``T = 6 k T``
(its ``5 k T`` stands for ``(1 - k) T``, its ``35 k^2 T^2`` for ``(1 - k^2) T^2``, and so on):
they are wrong for any other ``k``. Here ``k`` is free; at ``k = 1/6`` the values equal the
printed eqs. 29 and 31 to 1e-12 (no typo found in them). Eq. 30's denominator is
``4 (sigma_v^2 + 18 k^2 p_nabla T^2)``: the extracted text reads like
``4 sigma_v^2 + 18 k^2 p_nabla T^2``, which is wrong by up to a factor 4.

Use in a study
--------------
:func:`survey_chords` does it for one run: from the record's true ``distance``, ``north,
east, down``, the smoothed position errors (local NED, m; e.g.
``railfmu.estimators.inertial.ins_error_model.ned_difference`` of the smoothed and the true latitude,
longitude, height), the record times and the smoother, it returns the chord errors along
the track, the prediction and the study's metrics ``chord_{alignment,level}_{max,rms}_error_mm``
and ``predicted_sigma_{alignment,level}_mm``. The smoother's samples are at its KF epoch
nearest to each grid sample (within 0.025 s, 2.5 cm at 1 m/s; the errors are smooth over
metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from railfmu.estimators.inertial.ins_error_model import DR
from railfmu.models import earth
from railfmu.models.track.geometry import vector_distance

#: samples of the joint Gaussian per prediction: the precision of a 500-run Monte Carlo (module doc)
DEFAULT_SAMPLES = 500
MM = 1e3


# ---- the grid -------------------------------------------------------------------------------

@dataclass
class ChordGrid:
    """Grid samples of a run and the chord points on them.

    ``distance`` (m, n_grid): the grid distances reached, ``sample`` (n_grid): the record
    sample nearest to each; ``chord_start`` (m, n_chords): the surveyed chords (both ends
    reached); ``s`` (m, n_points): each chord point's distance, chord by chord;
    ``index`` (4, n_points): grid indices of ``s``, ``s + offset``, the chord's start, end;
    ``chord_index`` (n_chords, l / ds + 1): grid indices of each chord's grid points."""

    distance: np.ndarray
    sample: np.ndarray
    chord_start: np.ndarray
    s: np.ndarray
    index: np.ndarray
    chord_index: np.ndarray
    ds: float
    chord_length: float
    offset: float

    @property
    def n_points(self) -> int:
        return self.s.size


def chord_grid(distance, ds: float = 0.5, chord_length: float = 30.0, offset: float = 5.0) -> ChordGrid:
    """The survey's chord grid on a record whose samples have the true along-track
    ``distance`` (m, non-decreasing; the trolley's ``distance``).

    Grid distances are the multiples of ``ds`` in ``[distance[0], distance[-1]]`` (a grid
    point the run does not reach is left out); each takes the nearest record sample, the
    first of a stop (so a stop does not duplicate points). A chord ``[j l, (j + 1) l]`` is
    surveyed when both its ends are on the grid (a run shorter than a chord has none: its
    statistics are NaN)."""
    dist = np.asarray(distance, dtype=float)
    if dist.ndim != 1 or dist.size < 2 or not np.all(np.isfinite(dist)):
        raise ValueError("distance must be a finite 1-D array of at least two samples")
    if np.any(np.diff(dist) < 0.0):
        raise ValueError("distance must not decrease (the chord grid assumes a forward run)")
    n_chord, n_off = chord_length / ds, offset / ds
    if abs(n_chord - round(n_chord)) > 1e-9 or abs(n_off - round(n_off)) > 1e-9 or offset >= chord_length:
        raise ValueError("chord_length and offset must be multiples of ds, offset < chord_length")
    n_chord, n_off = int(round(n_chord)), int(round(n_off))
    tol = 1e-9 * max(1.0, abs(dist[-1]))
    j0 = int(math.ceil((dist[0] - tol) / ds))
    j1 = int(math.floor((dist[-1] + tol) / ds))
    if j1 < j0:
        raise ValueError("the run covers no grid point")
    jj = np.arange(j0, j1 + 1)
    grid = jj * ds
    right = np.clip(np.searchsorted(dist, grid, side="left"), 0, dist.size - 1)
    left = np.clip(right - 1, 0, dist.size - 1)
    left = np.searchsorted(dist, dist[left], side="left")  # the first sample of a stop
    sample = np.where(np.abs(dist[left] - grid) < np.abs(dist[right] - grid), left, right)
    # chords: ends on the grid; grid index of multiple j is j - j0
    first = -(-j0 // n_chord)
    starts = np.arange(first, (j1 - n_chord) // n_chord + 1) * n_chord
    pts = np.arange(n_chord - n_off + 1)
    js = (starts[:, None] + pts[None, :]).ravel()
    ja = np.repeat(starts, pts.size)
    index = np.stack([js, js + n_off, ja, ja + n_chord]) - j0
    chord_index = starts[:, None] - j0 + np.arange(n_chord + 1)[None, :]
    return ChordGrid(grid, sample, starts * ds, js * ds, index, chord_index, ds, chord_length, offset)


# ---- exact chord errors ---------------------------------------------------------------------

def _irregularity(ps, po, a, b):
    """``d_s - d_{s+o}`` (alignment, level) of points ``ps``, ``po`` (..., n, 3) against the
    chords ``a -> b`` (..., n, 3), one chord per point: one call of eq. 14 for all."""
    y, z = vector_distance(np.stack([ps, po], axis=-2), a, b)
    return y[..., 0] - y[..., 1], z[..., 0] - z[..., 1]


def _slots(grid: ChordGrid, q):
    return tuple(q[..., i, :] for i in grid.index)


def chord_errors(grid: ChordGrid, true_positions, position_errors) -> tuple[np.ndarray, np.ndarray]:
    """Exact chord errors (alignment, level; m) of every chord point, shape (..., n_points).

    ``true_positions`` (n_grid, 3): n0 NED (m) at the grid samples (the trolley's
    ``north, east, down`` at ``grid.sample``); ``position_errors`` (..., n_grid, 3): estimate
    minus truth (local NED, m), any leading axes (one run ``(n_grid, 3)``, samples
    ``(S, n_grid, 3)``)."""
    r = np.asarray(true_positions, dtype=float)
    e = np.asarray(position_errors, dtype=float)
    if r.shape != (grid.distance.size, 3) or e.shape[-2:] != r.shape:
        raise ValueError(f"true positions {r.shape} and errors {e.shape} must be (..., {grid.distance.size}, 3)")
    ya, za = _along_chords(grid, r + e)
    yt, zt = _along_chords(grid, r)
    return ya - yt, za - zt


def _along_chords(grid: ChordGrid, q):
    """``d_s - d_{s+o}`` of every chord point: eq. 14 once per chord for its ``l / ds + 1``
    grid points (the points ``s`` and ``s + o`` of a chord are those), then differences."""
    ci = grid.chord_index
    pts = q[..., ci, :]  # (..., n_chords, l/ds + 1, 3)
    y, z = vector_distance(pts, pts[..., 0, :], pts[..., -1, :])
    n_off = int(round(grid.offset / grid.ds))
    n = ci.shape[1] - n_off
    shape = y.shape[:-2] + (-1,)
    return ((y[..., :n] - y[..., n_off:]).reshape(shape), (z[..., :n] - z[..., n_off:]).reshape(shape))


def chord_offsets(grid: ChordGrid, positions) -> tuple[np.ndarray, np.ndarray]:
    """The chord measurement itself (alignment, level; m) of every chord point of a surveyed
    trajectory: ``d_s - d_{s+o}`` against each chord (eq. 14), ``positions`` (..., n_grid, 3)
    NED (m) at the grid samples. On a measured record it is the track's irregularity plus its
    design's own chord offsets (a curve's versine); :func:`chord_errors` is its difference
    between an estimate and a reference."""
    q = np.asarray(positions, dtype=float)
    if q.shape[-2:] != (grid.distance.size, 3):
        raise ValueError(f"positions {q.shape} must be (..., {grid.distance.size}, 3)")
    return _along_chords(grid, q)


def chord_error_jacobian(grid: ChordGrid, true_positions, step: float = 1e-4) -> np.ndarray:
    """The linearised map (the covariance map): ``J`` (2, n_points, 4, 3) with
    ``Delta[c, n] ~= sum_{u, i} J[c, n, u, i] e[grid.index[u, n], i]`` (c: alignment, level;
    u: the point ``s``, ``s + offset``, the chord's start, end; i: N, E, D). Central
    differences of the exact map with ``step`` (m): its third derivative is ~1/l^2, so the
    truncation is ~step^2 / l^2 = 1e-11 relative."""
    r = np.asarray(true_positions, dtype=float)
    base = _slots(grid, r)
    J = np.empty((2, grid.n_points, 4, 3))
    for u in range(4):
        for i in range(3):
            h = np.zeros(3)
            h[i] = step
            plus = [q + h if v == u else q for v, q in enumerate(base)]
            minus = [q - h if v == u else q for v, q in enumerate(base)]
            yp, zp = _irregularity(*plus)
            ym, zm = _irregularity(*minus)
            J[0, :, u, i] = (yp - ym) / (2.0 * step)
            J[1, :, u, i] = (zp - zm) / (2.0 * step)
    return J


def linear_chord_errors(grid: ChordGrid, jacobian, position_errors) -> tuple[np.ndarray, np.ndarray]:
    """The first-order chord errors ``J e`` (alignment, level; m), shape (..., n_points)."""
    e = np.asarray(position_errors, dtype=float)
    E = np.stack(_slots(grid, e), axis=-2)  # (..., n, 4, 3)
    out = np.einsum("cnui,...nui->c...n", np.asarray(jacobian), E)
    return out[0], out[1]


def chord_error_statistics(alignment, level) -> dict:
    """The paper's per-run statistic and the rms (mm): max |error| over all surveyed chord
    points and the rms over them, under the study's metric names. Leading axes (runs or
    samples) are kept: the values are then arrays. A run that surveys no whole chord gets NaN."""
    a, v = np.abs(np.asarray(alignment)), np.abs(np.asarray(level))
    if a.shape[-1] == 0:
        a = v = np.full(a.shape[:-1] + (1,), np.nan)
    out = {"chord_alignment_max_error_mm": MM * a.max(axis=-1),
           "chord_level_max_error_mm": MM * v.max(axis=-1),
           "chord_alignment_rms_error_mm": MM * np.sqrt(np.mean(a * a, axis=-1)),
           "chord_level_rms_error_mm": MM * np.sqrt(np.mean(v * v, axis=-1))}
    return {k: (float(x) if np.ndim(x) == 0 else x) for k, x in out.items()}


# ---- prediction from samples of the smoother's joint Gaussian ---------------------------------

@dataclass
class ChordPrediction:
    """Predicted accuracy of a survey's chords from ``n_samples`` error trajectories.

    ``sigma_alignment_mm``, ``sigma_level_mm``: the predicted RMS over runs of the per-run
    max |chord error| (the survey's statistic); ``relative_se_alignment``,
    ``relative_se_level``: their relative standard errors (sampling); ``pointwise_alignment_mm``,
    ``pointwise_level_mm`` (n_points): the RMS of the chord error at each point (its sigma;
    the mean is 0), at distances ``s`` (m)."""

    sigma_alignment_mm: float
    sigma_level_mm: float
    relative_se_alignment: float
    relative_se_level: float
    pointwise_alignment_mm: np.ndarray
    pointwise_level_mm: np.ndarray
    s: np.ndarray
    n_samples: int

    def metrics(self) -> dict:
        """The study's metric names; ``predicted_peak_sigma_*_mm`` is the largest pointwise
        sigma along the chords (the sigma of the covariance analysis' figures, Jiang et al.
        (2017), Figs. 8-11, whose values the paper's Fig. 12 figures equal)."""
        peak = {k: float(np.max(x)) if np.size(x) else math.nan
                for k, x in (("alignment", self.pointwise_alignment_mm), ("level", self.pointwise_level_mm))}
        return {"predicted_sigma_alignment_mm": self.sigma_alignment_mm,
                "predicted_sigma_level_mm": self.sigma_level_mm,
                "predicted_peak_sigma_alignment_mm": peak["alignment"],
                "predicted_peak_sigma_level_mm": peak["level"]}


def _rms_and_se(m: np.ndarray) -> tuple[float, float]:
    if m.size == 0:
        return math.nan, math.nan
    m2 = m * m
    mean = float(m2.mean())
    se = float(m2.std(ddof=1)) / (2.0 * math.sqrt(m2.size) * mean) if m2.size > 1 and mean > 0 else math.inf
    return math.sqrt(mean), se


def predict_chord_sigma(grid: ChordGrid, true_positions, error_samples) -> ChordPrediction:
    """Prediction from ``error_samples`` (S, n_grid, 3): samples of the smoothed position
    error (local NED, m) at the grid samples, drawn from the smoother's joint Gaussian
    (e.g. ``obs.error_samples(times[grid.sample], S, seed)``). See the module doc for the
    precision against ``S``."""
    e = np.asarray(error_samples, dtype=float)
    if e.ndim != 3:
        raise ValueError(f"error samples must be (S, n_grid, 3), got {e.shape}")
    a, v = chord_errors(grid, true_positions, e)
    none = np.zeros(0)  # no whole chord surveyed: nothing to predict (NaN)
    sa, ra = _rms_and_se(np.abs(a).max(axis=-1) if grid.n_points else none)
    sv, rv = _rms_and_se(np.abs(v).max(axis=-1) if grid.n_points else none)
    return ChordPrediction(MM * sa, MM * sv, ra, rv, MM * np.sqrt(np.mean(a * a, axis=0)),
                           MM * np.sqrt(np.mean(v * v, axis=0)), grid.s.copy(), e.shape[0])


@dataclass
class ChordSurvey:
    """One run's chords: the ``grid``, the chord errors ``alignment``, ``level`` (m, at
    ``grid.s``), the ``prediction`` (None without a smoother) and ``metrics`` (mm, the
    study's names)."""

    grid: ChordGrid
    alignment: np.ndarray
    level: np.ndarray
    prediction: ChordPrediction | None
    metrics: dict


def survey_chords(distance, true_positions, position_errors, times=None, smoother=None,
                  n_samples: int = DEFAULT_SAMPLES, seed: int | None = None) -> ChordSurvey:
    """The chord metrics of one run from its whole record (all arrays per record sample):
    true ``distance`` (m), ``true_positions`` (n0 NED, m; the trolley's ``north, east,
    down``), ``position_errors`` (smoothed minus true, local NED, m), and, for the
    prediction, the record ``times`` (s) and the ``smoother`` (anything with
    ``error_samples(times, n, seed)``: ``AidedInsSmoother`` after its run, or a
    ``covariance_analysis`` result). Only the grid samples are used."""
    grid = chord_grid(distance)
    r = np.asarray(true_positions, dtype=float)[grid.sample]
    a, v = chord_errors(grid, r, np.asarray(position_errors, dtype=float)[grid.sample])
    metrics = chord_error_statistics(a, v)
    pred = None
    if smoother is not None:
        t = np.asarray(times, dtype=float)[grid.sample]
        pred = predict_chord_sigma(grid, r, smoother.error_samples(t, n_samples, seed))
        metrics.update(pred.metrics())
    return ChordSurvey(grid, a, v, pred, metrics)


# ---- closed forms of the simplified case (eqs. 29-31) ------------------------------------------

def _q2_q3(t_s, k, T):
    t_s = np.asarray(t_s, dtype=float)
    q2 = k * T * ((1.0 - k) * T - 2.0 * t_s) / 2.0
    q3 = k * T * ((1.0 - k * k) * T * T - 3.0 * k * T * t_s - 3.0 * t_s * t_s) / 6.0
    return q2, q3


def alignment_variance(t_s, k: float, T: float, g: float, p_phi: float, p_eps: float, sigma_v: float,
                       sigma_r: float = math.inf):
    """Eq. 29 (eq. 31 for ``sigma_r = inf``, no position update): the variance (m^2) of the
    alignment chord error at the point passed at ``t_s`` (s, array allowed; ``0 <= t_s <=
    (1 - k) T``) of a chord run in ``T`` (s), ``k = offset / chord_length``; ``g`` (m/s^2),
    ``p_phi`` the initial tilt variance (rad^2), ``p_eps`` the gyro bias variance
    ((rad/s)^2), ``sigma_v`` (m/s), ``sigma_r`` (m) the update sigmas (also the initial
    velocity and position sigmas). Module doc: the formula, its derivation and the errata."""
    sv2, w = sigma_v * sigma_v, 0.0 if math.isinf(sigma_r) else 1.0 / (sigma_r * sigma_r)
    g2, T2 = g * g, T * T
    D = (576 * sv2 + 288 * T2 * g2 * p_phi + 72 * T2 ** 2 * g2 * p_eps
         + w * (144 * T2 * sv2 ** 2 + 72 * T2 ** 2 * g2 * p_phi * sv2 + 20 * T2 ** 3 * g2 * p_eps * sv2
                + T2 ** 4 * g2 * g2 * p_phi * p_eps))
    P_ff = 4 * p_phi * (144 * sv2 + 18 * T2 ** 2 * g2 * p_eps
                        + w * (36 * T2 * sv2 ** 2 + 5 * T2 ** 3 * g2 * p_eps * sv2)) / D
    P_fe = 36 * T2 * T * g2 * p_phi * p_eps * (4 + w * T2 * sv2) / D
    P_ee = 72 * p_eps * (4 + w * T2 * sv2) * (T2 * g2 * p_phi + 2 * sv2) / D
    q2, q3 = _q2_q3(t_s, k, T)
    return g2 * (q2 * q2 * P_ff - 2.0 * q2 * q3 * P_fe + q3 * q3 * P_ee)


def level_variance(t_s, k: float, T: float, p_nabla_D: float, sigma_v: float):
    """Eq. 30: the variance (m^2) of the level chord error at ``t_s`` (as
    :func:`alignment_variance`); ``p_nabla_D`` the vertical accelerometer bias variance
    ((m/s^2)^2). The position update does not enter."""
    q2, _ = _q2_q3(t_s, k, T)
    sv2 = sigma_v * sigma_v
    return q2 * q2 * 2.0 * p_nabla_D * sv2 / (p_nabla_D * T * T + 2.0 * sv2)


def closed_form_sigma(t_s, k: float, T: float, g: float, p_phi: float, p_eps: float, p_nabla_D: float,
                      sigma_v: float, sigma_r: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. 29-31 as sigmas (m): (alignment, level) at ``t_s``."""
    return (np.sqrt(alignment_variance(t_s, k, T, g, p_phi, p_eps, sigma_v, sigma_r)),
            np.sqrt(level_variance(t_s, k, T, p_nabla_D, sigma_v)))


# ---- exact pointwise sigma from a joint covariance ----------------------------------------------

def chord_sigma_from_covariance(grid: ChordGrid, true_positions, position_covariance) -> tuple[np.ndarray, np.ndarray]:
    """Pointwise sigma (m) of the chord errors (alignment, level), shape (n_points,), from the
    joint covariance of the position errors at the grid samples, ``(3 n_grid, 3 n_grid)``
    (sample-major: N, E, D of sample 0, then of sample 1, ...), through the linear map of
    :func:`chord_error_jacobian` (exact to ~1e-4 for millimetre errors, module doc)."""
    J = chord_error_jacobian(grid, true_positions)  # (2, n, 4, 3)
    C = np.asarray(position_covariance, dtype=float)
    m = grid.distance.size
    if C.shape != (3 * m, 3 * m):
        raise ValueError(f"position covariance must be ({3 * m}, {3 * m}), got {C.shape}")
    C4 = C.reshape(m, 3, m, 3)
    idx = grid.index  # (4, n)
    # blocks Cov(e_u, e_v) of each point's four samples: (n, 4, 3, 4, 3)
    B = C4[idx.T[:, :, None, None, None], np.arange(3)[None, None, :, None, None],
           idx.T[:, None, None, :, None], np.arange(3)[None, None, None, None, :]]
    var = np.einsum("cnui,nuivj,cnvj->cn", J, B, J)
    return np.sqrt(np.clip(var[0], 0.0, None)), np.sqrt(np.clip(var[1], 0.0, None))


# ---- sensitivity curves (Figs. 8-11) on the paper's nominal run ---------------------------------

DEG = math.pi / 180.0
#: the paper's nominal (§ 5 and § 6.1): the settings of ``covariance_analysis`` that the curves vary
NOMINAL = {"zupt_sigma": 1e-4, "velocity_sigma": 1e-4, "position_sigma": 0.1, "landmark_sigma": 0.1,
           "tilt_sigma": 0.006 * DEG, "heading_sigma": 0.06 * DEG,
           "gyro_arw_deg_sqrt_h": 0.005, "accel_noise_ug_sqrt_hz": 10.0,
           # the paper's "piecewise constant" biases (its § 2): random constants, no in-run drift
           "gyro_bias_instability_deg_h": 0.0, "gyro_turn_on_bias_sigma_deg_h": 0.01,
           "accel_bias_instability_ug": 0.0, "accel_turn_on_bias_sigma_ug": 50.0}
#: x axes of the curves: (setting, values in the unit shown, unit, factor to the setting's unit)
SENSITIVITY_AXES = {
    "zupt_sigma": (np.geomspace(0.01, 1.0, 9), "mm/s", 1e-3),  # Fig. 8 (with and without positions)
    "gyro_arw_deg_sqrt_h": (np.geomspace(0.001, 0.02, 7), "deg/sqrt(h)", 1.0),  # Fig. 9
    "accel_noise_ug_sqrt_hz": (np.geomspace(1.0, 50.0, 7), "ug/sqrt(Hz)", 1.0),  # Fig. 9
    "tilt_sigma": (np.geomspace(0.001, 0.03, 7), "deg", DEG),  # Fig. 10
    "heading_sigma": (np.geomspace(0.01, 0.3, 7), "deg", DEG),  # Fig. 10
    "gyro_turn_on_bias_sigma_deg_h": (np.geomspace(0.001, 0.1, 7), "deg/h", 1.0),  # Fig. 11
    "accel_turn_on_bias_sigma_ug": (np.geomspace(5.0, 500.0, 7), "ug", 1.0),  # Fig. 11
}


@dataclass
class NominalRun:
    """A straight level run at constant speed (the paper's § 5 idealisation: the stops at the
    ends are velocity updates, the accelerations are left out): KF epochs ``times`` (s), their
    ``f_n``, ``C_bn``, ``velocity``, the update flags, and the chord ``grid`` with the true
    positions at its samples (n0 NED, m) and their epochs ``grid_epochs``."""

    times: np.ndarray
    f_n: np.ndarray
    C_bn: np.ndarray
    velocity: np.ndarray
    latitude: float
    zupt: np.ndarray
    position: np.ndarray
    grid: ChordGrid
    true_positions: np.ndarray
    grid_epochs: np.ndarray


def nominal_run(length: float = 30.0, speed: float = 1.0, azimuth: float = 45.0 * DEG,
                latitude: float = 30.5 * DEG, filter_period: float = 0.05,
                position_updates: bool = False) -> NominalRun:
    """The paper's simulated survey (§ 6.1): straight, level, N45E, 30 m at 1 m/s, velocity
    (ZUPT) updates at the first and last epochs, landmark position updates there too when
    ``position_updates``."""
    n = int(round(length / speed / filter_period))
    times = np.arange(n + 1) * filter_period
    dist = speed * times
    u = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    ca, sa = math.cos(azimuth), math.sin(azimuth)
    C = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])  # body x along the track
    f_n = np.tile([0.0, 0.0, -earth.gravity(latitude, 0.0)], (n + 1, 1))
    ends = np.zeros(n + 1, dtype=bool)
    ends[[0, -1]] = True
    grid = chord_grid(dist)
    return NominalRun(times, f_n, np.broadcast_to(C, (n + 1, 3, 3)), np.tile(speed * u, (n + 1, 1)), latitude,
                      ends, ends.copy() if position_updates else np.zeros(n + 1, dtype=bool), grid,
                      np.outer(grid.distance, u), grid.sample)


def nominal_chord_accuracy(run: NominalRun, n_samples: int = 0, seed: int = 1, **settings) -> dict:
    """``covariance_analysis`` of ``run`` with ``settings`` (those of ``AidedInsSmoother``):
    the chord accuracy in mm: ``alignment_mm``, ``level_mm`` the largest pointwise sigma over
    the surveyed points (exact, from the smoother's joint covariance), ``pointwise_*_mm``, and
    with ``n_samples`` > 0 the predicted RMS over runs of the max ``|error|``
    (``max_rms_alignment_mm``, ``max_rms_level_mm``; :func:`predict_chord_sigma`)."""
    from railfmu.estimators.inertial.aided_ins import covariance_analysis  # the INS and its filter: only here

    ca = covariance_analysis(run.times, run.f_n, run.C_bn, run.latitude, run.velocity, run.zupt,
                             position=run.position, **settings)
    n, m = len(ca.state_names), run.grid_epochs.size
    cov = ca.joint_covariance(run.grid_epochs).reshape(m, n, m, n)[:, DR, :, DR].reshape(3 * m, 3 * m)
    sy, sz = chord_sigma_from_covariance(run.grid, run.true_positions, cov)
    out = {"alignment_mm": MM * float(sy.max()), "level_mm": MM * float(sz.max()),
           "pointwise_alignment_mm": MM * sy, "pointwise_level_mm": MM * sz}
    if n_samples:
        p = predict_chord_sigma(run.grid, run.true_positions,
                                ca.error_samples(run.times[run.grid_epochs], n_samples, seed))
        out.update(max_rms_alignment_mm=p.sigma_alignment_mm, max_rms_level_mm=p.sigma_level_mm)
    return out


def sensitivity_curves(axes=None, n_samples: int = 0, seed: int = 1, **nominal) -> dict:
    """Predicted chord accuracy against one setting at a time, the others at the paper's
    nominal (:data:`NOMINAL`, overridden by ``nominal``), on :func:`nominal_run`, like
    Jiang et al. (2017) Figs. 8-11. ``axes``: names from :data:`SENSITIVITY_AXES` (default
    all) or a dict ``{setting: (values, unit, factor)}``.

    Returns ``{setting: {"x": values (in ``unit``), "unit": str, "alignment_mm": array,
    "level_mm": array, ...}}`` with the largest pointwise sigma of the 30 m chord's errors
    (and ``max_rms_*_mm``, the predicted RMS of the max, when ``n_samples`` > 0: sampled, so
    with its ~``1 / sqrt(n_samples)`` scatter from point to point); ``zupt_sigma`` also has
    ``alignment_mm_position``, ``level_mm_position`` with landmark position updates at both
    ends (``landmark_sigma``), and there the initial velocity sigma follows the update's
    (the paper's ``p_dv = sigma_v^2``). ``"nominal"``: the values at the nominal point."""
    if axes is None:
        axes = SENSITIVITY_AXES
    elif not isinstance(axes, dict):
        axes = {a: SENSITIVITY_AXES[a] for a in axes}
    base = {**NOMINAL, **nominal}
    runs = {False: nominal_run(), True: nominal_run(position_updates=True)}
    keys = ("alignment_mm", "level_mm") + (("max_rms_alignment_mm", "max_rms_level_mm") if n_samples else ())
    out = {"nominal": nominal_chord_accuracy(runs[False], n_samples, seed, **base)}
    for name, (values, unit, factor) in axes.items():
        curve = {"x": np.asarray(values, dtype=float), "unit": unit}
        for pos in (False, True) if name == "zupt_sigma" else (False,):
            res = []
            for x in curve["x"]:
                s = {**base, name: x * factor}
                if name == "zupt_sigma":
                    s["velocity_sigma"] = x * factor
                res.append(nominal_chord_accuracy(runs[pos], n_samples, seed, **s))
            for k in keys:
                curve[k + ("_position" if pos else "")] = np.array([r[k] for r in res])
        out[name] = curve
    return out
