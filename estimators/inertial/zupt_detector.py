r"""Zero-velocity detection on IMU increments: the SHOE / GLRT stance detector.

Skog, Händel, Nilsson, Rantakokko, "Zero-velocity detection - an algorithm evaluation", IEEE
Trans. Biomed. Eng. 57 (2010) 2657: over a window of ``W`` samples the generalised likelihood
ratio test of "the IMU is at rest" (specific force of magnitude ``g`` along an unknown fixed
direction, white noise) is the statistic::

    T_k = 1/W sum_{j in window(k)} ( |f_j - g u_f|^2 / sigma_a^2 + |w_j - Omega u_w|^2 / sigma_g^2 )
    f_j = dv_j / dt (m/s2),  w_j = dtheta_j / dt (rad/s),  u_x = mean(x) / |mean(x)|

and the sample is stationary when ``T_k < gamma``. Skog et al. test the angular rate against
zero (``Omega = 0``, :func:`shoe_statistic`'s ``earth_rate=0``); here it is tested, like the
specific force, against a known magnitude along an unknown direction: a body at rest senses
the Earth rate ``Omega`` whatever its attitude, and for the navigation-grade gyro at 200 Hz
that is 3.5 sigma_g per sample (``(Omega / sigma_g)^2 = 12.5`` added to ``T`` at rest), and a
moving body whose rotation partly cancels it has a lower ``|w|`` than one at rest. The window
is centred on ``k`` (samples ``k - W/2 .. k + W/2 - 1``; the first and last take the nearest
whole window). With the window mean ``m``::

    sum |x_j - c u_x|^2 = sum |x_j - m|^2 + W (|m| - c)^2

(the cross term vanishes), from cumulative sums (no per-sample loop).

Noise and threshold: ``sigma_a``, ``sigma_g`` are the standard deviations of one sample's
specific force and angular rate: the white-noise densities over ``sqrt(dt)``
(:func:`noise_sigmas` of an ``ImuErrors`` grade). At rest ``W T`` is then chi-square: ``3 (W -
1)`` degrees of freedom from each triad's scatter about its mean, one from each magnitude test
(three from the gyros' when ``Omega`` is below their window-mean noise, as for a MEMS gyro), so
``6 W - 4`` to ``6 W - 2``; the default threshold is the ``1 - 1e-4`` quantile of the latter
(:func:`rest_threshold`: 7.95 for ``W = 50``). Biases along the magnitude tests raise ``T`` at
rest: the tactical-grade accelerometer's 1 mg is 2 sigma_a per sample, a ``g`` of 9.8 against
Wuhan's 9.7936 m/s2 is 4.6 sigma_a for the navigation grade. So ``gravity`` defaults to what
the record's accelerometers read for it, the median over the windows of ``|mean f|`` (a
trolley is level to a percent and its accelerations are milli-g: the median is gravity plus
the bias and scale factor along it).

Defaults, chosen on the trolley survey (``railfmu run trolley_survey``, 700 s, 11 stops of
5 s): ``W = 50`` (0.25 s) and ``min_samples = 100`` (runs of detection shorter than 0.5 s are
dropped). What the GLRT alone confuses: a trolley cruising at 1 m/s on straight, level track
feels no acceleration and no rotation, exactly as at rest, and a horizontal acceleration changes
``|f|`` by only ``a^2 / 2g``. Alone (``speed_change=None, trim=False``, the grade's sigmas,
the global median gravity) it gave, samples of 12,010 at rest and 127,990 moving, and runs:
navigation grade 0 misses / 87 false alarms / 0 false stops, tactical 2351 / 9747 / 47, MEMS
0 / 54,878 / 109; on the straight, smooth ``trolley_straight_30m.csv`` (``paper_montecarlo``)
it took 5,873 of 6,079 moving samples for rest and the smoother's chords were off by
decimetres. Five additions, each on by default, make it work on both shipped tracks:

* runs of detection less than ``W`` apart are one (a chance exceedance splits a stop);
* the noise floor (:func:`noise_floor`): each sigma is at least the record's own (a low
  quantile of the window scatter), so the threshold sits relative to the data's noise;
* the running gravity (:func:`_local_gravity`): a 60 s running median of ``|mean f|``, not
  the record's (a tactical-grade 1 mg Gauss-Markov bias drifts ~0.5 mg over the survey);
* the speed-change rule (:func:`speed_changes`, ``speed_change = 0.3`` m/s over
  ``ramp_span = 6`` s): a run is rest only after a deceleration and before an acceleration
  (or at the record's ends), which steady cruising is not (the IMU's x forward);
* the trim (:func:`trim_to_rest`): each run ends where the specific force's direction leaves
  the run's own, which shows a speed ramp long before the GLRT's magnitude test; then a
  ``margin`` of ``W`` samples off each end (not at the record's ends).

Measured with the defaults and each grade's sigmas (``trolley_survey --seed 1``, the stopped
flag as truth, samples of 12,011 at rest and 127,990 moving; ``tests/test_zupt_detector.py``
repeats the straight-track case per grade on a synthetic stop-and-go record):

    track / grade                    misses  false alarms  missed stops  false stops
    trolley_track, navigation           918             0             0            0
    trolley_track, tactical             435             0             0            0
    trolley_track, MEMS                 441             0             0            0
    trolley_straight_30m, navigation     96             0             1            0

The misses are the margins and the trim (before them the stops grew up to 11 samples into the
ramps at the navigation grade, 49 at the tactical and MEMS grades: speeds to 4 mm/s, which a
ZUPT of 0.1 mm/s takes as 40 sigma). The straight track's missed stop is its 0.1 s initial
rest, shorter than ``min_samples`` (of 222 samples at rest, 31.5 s).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from railfmu.models import earth
from railfmu.models.inertial.imu_errors import ACCEL_SI, GRADES, GYRO_NOISE_SI

#: probability that a window at rest exceeds the default threshold (one false "moving" in 1e4)
P_FALSE_MOVING = 1e-4


def noise_sigmas(grade: Mapping[str, float], dt: float) -> tuple[float, float]:
    """Per-sample standard deviations ``(sigma_a, sigma_g)`` (m/s2, rad/s) of the white noise of
    an ``ImuErrors`` grade (``railfmu.models.inertial.imu_errors.GRADES``; parameter names and datasheet units
    ``accel_noise_ug_sqrt_hz``, ``gyro_arw_deg_sqrt_h``) sampled every ``dt`` (s): density over
    ``sqrt(dt)``."""
    root = math.sqrt(dt)
    return (grade["accel_noise_ug_sqrt_hz"] * ACCEL_SI / root, grade["gyro_arw_deg_sqrt_h"] * GYRO_NOISE_SI / root)


#: (sigma_a m/s2, sigma_g rad/s) of the navigation grade (10 ug/sqrt(Hz), 0.005 deg/sqrt(h); Jiang et
#: al. (2017)) at 200 Hz
NAVIGATION_GRADE = noise_sigmas(GRADES["navigation_grade"], 0.005)


def _window_sums(x: np.ndarray, window: int, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per window ``[lo, lo + W)``: ``sum |x_j - m|^2`` (the scatter about the window mean ``m``)
    and ``m``, from cumulative sums of ``x - c`` (``c`` the median row: the differences of the
    sums stay at the noise's scale, not gravity's)."""
    c = np.median(x, axis=0)
    x = x - c
    s1 = np.concatenate([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    s2 = np.concatenate([[0.0], np.cumsum(np.einsum("ij,ij->i", x, x))])
    hi = lo + window
    total = s1[hi] - s1[lo]
    scatter = (s2[hi] - s2[lo]) - np.einsum("ij,ij->i", total, total) / window
    return np.maximum(scatter, 0.0), total / window + c


#: span (s) of the running median that gives the gravity the accelerometers read
GRAVITY_SPAN = 60.0


def _local_gravity(norm_f: np.ndarray, dt: float, window: int) -> np.ndarray | float:
    """What the accelerometers read for gravity about each sample: the running median over
    :data:`GRAVITY_SPAN` of the window-mean ``|f|`` (every ``W/2``-th window; a record shorter
    than the span: its median). Running, not global: a tactical-grade accelerometer's 1 mg
    Gauss-Markov bias moves ``|f|`` by ~0.5 mg over a 700 s survey, 1.1 on ``T`` at the ends."""
    n = norm_f.size
    step = max(1, window // 2)
    span = int(round(GRAVITY_SPAN / dt / step))
    coarse = norm_f[::step]
    if coarse.size <= span:
        return float(np.median(norm_f))
    from scipy.ndimage import median_filter
    med = median_filter(coarse, size=span | 1, mode="nearest")
    return np.interp(np.arange(n), np.arange(coarse.size) * step, med)


def shoe_statistic(increments: np.ndarray, dt: float, window: int, sigma_a: float, sigma_g: float,
                   gravity: float | None = None, earth_rate: float = earth.RATE) -> np.ndarray:
    """``T_k`` of the module docstring for each row of ``increments`` ``(n, 6)`` (``dtheta_x..z``
    rad, ``dv_x..z`` m/s over ``dt`` s), window centred on ``k``; ``(n,)``. ``gravity`` None:
    the running median over the windows of ``|mean f|`` (:func:`_local_gravity`)."""
    inc = np.asarray(increments, dtype=float)
    n = inc.shape[0]
    lo = np.clip(np.arange(n) - window // 2, 0, n - window)   # first sample of k's window
    scatter_f, mean_f = _window_sums(inc[:, 3:] / dt, window, lo)
    scatter_w, mean_w = _window_sums(inc[:, :3] / dt, window, lo)
    norm_f = np.linalg.norm(mean_f, axis=1)
    g = _local_gravity(norm_f, dt, window) if gravity is None else float(gravity)
    accel = scatter_f + window * (norm_f - g) ** 2
    gyro = scatter_w + window * (np.linalg.norm(mean_w, axis=1) - earth_rate) ** 2
    return (accel / sigma_a ** 2 + gyro / sigma_g ** 2) / window


def rest_threshold(window: int, p_false: float = P_FALSE_MOVING) -> float:
    """The ``1 - p_false`` quantile of ``T`` at rest: ``W T`` chi-square with ``6 W - 2``
    degrees of freedom (module docstring)."""
    from scipy.stats import chi2
    return float(chi2.isf(p_false, 6 * window - 2)) / window


def noise_floor(increments: np.ndarray, dt: float, window: int = 50, quantile: float = 0.01) -> tuple[float, float]:
    """The record's own per-sample noise ``(sigma_a, sigma_g)`` (m/s2, rad/s): per window of
    ``window`` samples the scatter of each triad about its mean over its ``3 (W - 1)`` degrees
    of freedom, the ``quantile`` over the windows, divided by that quantile of the chi-square's
    mean (unbiased when at least ``quantile`` of the windows are at rest or in quiet, steady
    motion). 0 for exact (simulated ideal) data."""
    from scipy.stats import chi2

    inc = np.asarray(increments, dtype=float)
    n = inc.shape[0]
    lo = np.arange(0, n - window + 1, max(1, window // 2))
    dof = 3 * (window - 1)
    bias = float(chi2.ppf(quantile, dof)) / dof
    out = []
    for cols in (slice(3, 6), slice(0, 3)):
        scatter, _ = _window_sums(inc[:, cols] / dt, window, lo)
        out.append(math.sqrt(float(np.quantile(scatter / dof, quantile)) / bias))
    return out[0], out[1]


def speed_changes(increments: np.ndarray, dt: float, runs: np.ndarray, span: float) -> np.ndarray:
    """Per candidate run ``[a, b)`` of detected rest the change of the body-forward speed
    (m/s) over the ``span`` s before it and after it, ``(k, 2)``: the forward specific force
    minus its mean over the run (the run's gravity along body x: at rest and at steady speed
    alike the mean specific force is gravity's reaction), integrated over that span. A trolley comes to rest after a deceleration (< 0) and
    leaves it with an acceleration (> 0); cruising at a steady speed looks like rest to the
    GLRT but follows an acceleration or a curve, not a deceleration."""
    fx = np.asarray(increments, dtype=float)[:, 3] / dt
    n, m = fx.size, int(round(span / dt))
    out = np.zeros((len(runs), 2))
    for i, (a, b) in enumerate(runs):
        ref = fx[a:b].mean()
        lo, hi = max(0, a - m), min(n, b + m)  # quiet cruising inside adds ~0: no need to skip it
        out[i] = (float((fx[lo:a] - ref).sum() * dt), float((fx[b:hi] - ref).sum() * dt))
    return out


def trim_to_rest(increments: np.ndarray, dt: float, a: int, b: int, window: int, sigma_a: float,
                 p_false: float = 1e-6) -> tuple[int, int]:
    """Shrink a run of rest ``[a, b)`` to where the specific force stays at the run's own
    (gravity's): from the run's middle outwards, up to the first centred window of ``window``
    samples whose mean specific force departs from the mean of the run's middle half by more
    than chance (``W |d|^2 / sigma_a^2`` over the chi-square's ``1 - p_false`` quantile, 3
    degrees of freedom). The GLRT tests the magnitude of the specific force, to which a
    horizontal acceleration adds only ``a^2 / 2g``: a noisy IMU's GLRT takes the first half
    second of a smooth speed ramp for rest (the MEMS grade: 100 samples, up to 1.2 cm/s at
    0.5 m/s2); its direction shows the ramp within a fifth of a second."""
    from scipy.stats import chi2

    f = np.asarray(increments[a:b, 3:], dtype=float) / dt
    n = b - a
    if n < 2 * window:
        return a, b
    ref = f[n // 4: n - n // 4].mean(axis=0)
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(f - ref, axis=0)])
    d = (c[window:] - c[:-window]) / window            # window starting at j, centre j + W/2
    stat = window * np.einsum("ij,ij->i", d, d) / sigma_a ** 2
    out = np.flatnonzero(stat > chi2.isf(p_false, 3)) + window // 2   # centres
    mid = n // 2
    above, below = out[out > mid], out[out < mid]
    return a + (int(below[-1]) + 1 if below.size else 0), a + (int(above[0]) if above.size else n)


def detect_stationary(increments: np.ndarray, dt: float, window: int = 50, threshold: float | None = None,
                      sigma_a: float = NAVIGATION_GRADE[0], sigma_g: float = NAVIGATION_GRADE[1],
                      gravity: float | None = None, min_samples: int = 100,
                      earth_rate: float = earth.RATE, noise_from_data: bool = True,
                      speed_change: float | None = 0.3, ramp_span: float = 6.0,
                      trim: bool = True, margin: int | None = None) -> np.ndarray:
    """Stationary samples of an IMU record (module docstring): ``increments`` ``(n, 6)``
    (``dtheta_x..z`` rad, ``dv_x..z`` m/s, each over the ``dt`` s before its sample), ``window``
    ``W`` samples, ``threshold`` ``gamma`` (default :func:`rest_threshold`), ``sigma_a`` (m/s2),
    ``sigma_g`` (rad/s) per sample (:func:`noise_sigmas`; default the navigation grade at
    200 Hz), ``gravity`` (m/s2; default the record's median window-mean specific force),
    ``min_samples``: runs of detection shorter than this are dropped, ``earth_rate`` (rad/s; 0
    gives Skog et al.'s statistic). ``noise_from_data``: each sigma is at least the record's
    own noise floor (:func:`noise_floor`), so the threshold sits relative to the data's noise
    whatever the datasheet says. ``speed_change`` (m/s; None: off): a run of detection is
    rest only if the body-forward speed changed by less than ``-speed_change`` over the
    ``ramp_span`` s before it (or it starts within ``2 W`` samples of the record's start) and by
    more than ``+speed_change`` after it (or it ends within ``2 W`` of the record's end) (:func:`speed_changes`; the IMU's x axis forward in
    the direction of travel): steady cruising on straight, smooth track is otherwise
    indistinguishable from rest. ``trim``: each run of rest is then shrunk by
    :func:`trim_to_rest`, and by ``margin`` samples at each end (default ``W``: 0.25 s of a
    5 s stop; a ZUPT in the first samples of a ramp is a lie of many sigma, one lost at rest
    costs nothing). Returns a bool array ``(n,)``."""
    inc = np.asarray(increments, dtype=float)
    if inc.ndim != 2 or inc.shape[1] != 6:
        raise ValueError(f"detect_stationary: increments of shape {inc.shape}, expected (n, 6)")
    if not (dt > 0 and sigma_a > 0 and sigma_g > 0 and (gravity is None or gravity > 0)):
        raise ValueError("detect_stationary: dt, sigma_a, sigma_g and gravity must be positive")
    if not 1 <= window <= inc.shape[0]:
        raise ValueError(f"detect_stationary: window {window} outside 1..{inc.shape[0]} samples")
    if noise_from_data and window >= 2:
        fa, fg = noise_floor(inc, dt, window)
        sigma_a, sigma_g = max(sigma_a, fa), max(sigma_g, fg)
    gamma = rest_threshold(window) if threshold is None else float(threshold)
    still = shoe_statistic(inc, dt, window, sigma_a, sigma_g, gravity, earth_rate) < gamma
    runs = _runs(still)
    for (_, b), (a, _) in zip(runs[:-1], runs[1:]):
        if a - b < window:  # a chance exceedance inside a rest (1e-4 per window): not motion
            still[b:a] = True
    if min_samples > 1:
        for a, b in _runs(still):
            if b - a < min_samples:
                still[a:b] = False
    if speed_change is not None:
        runs = _runs(still)
        dv = speed_changes(inc, dt, runs, ramp_span)
        n = inc.shape[0]
        span = round(ramp_span / dt)
        for (a, b), (before, after) in zip(runs, dv):
            # within two windows of the record's ends: the record starts or ends at rest (a
            # first row of zero increments, the initial time's, delays the first run by W);
            # a span cut short by an end: the threshold in proportion (a record ending 1 s
            # into the start ramp has seen 0.09 of its 1 m/s)
            need_b = speed_change * min(1.0, a / span)
            need_a = speed_change * min(1.0, (n - b) / span)
            if not ((a < 2 * window or before < -need_b) and (b > n - 2 * window or after > need_a)):
                still[a:b] = False
    if trim:
        for a, b in _runs(still):
            lo, hi = trim_to_rest(inc, dt, a, b, window, sigma_a)
            still[a:lo] = False
            still[hi:b] = False
    m = window if margin is None else int(margin)
    if m > 0:
        n = inc.shape[0]
        for a, b in _runs(still):
            lo, hi = (a if a < 2 * window else a + m), (b if b > n - 2 * window else b - m)
            still[a:b] = False
            still[lo:max(lo, hi)] = True
    return still


def _runs(mask: np.ndarray) -> np.ndarray:
    """(start, stop) index pairs of the runs of True in ``mask``; stop exclusive."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.column_stack([np.flatnonzero(d == 1), np.flatnonzero(d == -1)])


def detector_scores(detected: np.ndarray, stopped: np.ndarray) -> dict:
    """The detector against the truth's ``stopped`` flag, both bool ``(n,)``:

    ``misses``: samples at rest not detected (``miss_fraction`` of the samples at rest);
    ``false_alarms``: samples in motion detected as stationary (``false_alarm_fraction`` of the
    samples in motion); ``stops``: runs of rest; ``missed_stops``: runs of rest with no sample
    detected (a ZUPT lost); ``false_stops``: runs of detection with no sample at rest (a ZUPT
    applied to a moving trolley); ``early_samples`` / ``late_samples``: the largest number of
    samples by which a detected run starts before / ends after the stop it overlaps (the
    detector's stops grow into the starts and ends of motion).
    """
    det = np.asarray(detected, dtype=bool)
    rest = np.asarray(stopped, dtype=bool)
    if det.shape != rest.shape or det.ndim != 1:
        raise ValueError(f"detector_scores: detected {det.shape} and stopped {rest.shape} must be the same (n,)")
    n_rest, n_moving = int(rest.sum()), int((~rest).sum())
    misses = int((rest & ~det).sum())
    false_alarms = int((det & ~rest).sum())
    stops, found = _runs(rest), _runs(det)
    hit = np.concatenate([[0], np.cumsum(det)])
    at_rest = np.concatenate([[0], np.cumsum(rest)])
    missed_stops = int(sum(hit[b] == hit[a] for a, b in stops))
    false_stops = int(sum(at_rest[b] == at_rest[a] for a, b in found))
    early = late = 0
    for a, b in found:
        if at_rest[b] > at_rest[a]:   # overlaps a stop: how far it reaches past it
            inside = np.flatnonzero(rest[a:b])
            early = max(early, int(inside[0]))
            late = max(late, int(b - a - 1 - inside[-1]))
    return {"samples": int(det.size), "samples_at_rest": n_rest, "samples_moving": n_moving,
            "misses": misses, "miss_fraction": misses / n_rest if n_rest else 0.0,
            "false_alarms": false_alarms, "false_alarm_fraction": false_alarms / n_moving if n_moving else 0.0,
            "stops": int(len(stops)), "missed_stops": missed_stops, "detected_runs": int(len(found)),
            "false_stops": false_stops, "early_samples": early, "late_samples": late}
