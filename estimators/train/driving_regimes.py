r"""Driving-regime recognition and feature extraction: Cunillera et al. (2022) §3.2-3.3.

Regime codes (as the Driver FMU's ``regime`` output): 0 standstill, 1 traction, 2 cruising,
3 coasting, 4 braking. Units are SI; efforts are mass-specific, ``f = F / (gamma m)`` (N/kg,
the same number as m/s2).

What a sample describes
-----------------------
An estimator that predicts from fix ``j-1`` to fix ``j`` with an applied effort computed from
the speeds of both fixes (the paper's UKF: the effort "needed to match the observed
acceleration") outputs at fix ``j`` the effort and acceleration *of the interval*
``(t_(j-1), t_j]``. Every function here takes the samples in that sense: ``acceleration[j]``
and ``effort[j]`` describe ``(t_(j-1), t_j]``, ``speed[j]`` is the speed at ``t_j``; fix 0 has
no interval before it (its effort and acceleration are whatever the estimator holds there,
normally 0 at rest).

Recognition (§3.2), per fix::

    standstill   max(v_(j-1), v_j) <= v_stop                     (the train did not move)
    coasting     |f| <= 0.025 N/kg                               (the noise band of zero effort)
    cruising     |f| >  0.025 N/kg  and |a| <= 0.06 m/s2
    traction     f > 0.025 and a > 0.06;   braking  f < -0.025 and a < -0.06

(``|a| > 0.06`` with the acceleration against the effort, e.g. traction while decelerating
uphill, is traction or braking by the effort's sign.) 0.025 N/kg is ~5 % of the paper's
maximum tractive effort; 0.06 m/s2 lets 2 km/h pass between two fixes 10 s apart.

These rules decide each fix alone. :mod:`railfmu.estimators.train.regime_decoding` decodes the same
regions over the whole run (a hidden Markov model, Viterbi) and gives an interval that mixes
two regimes to the one that fills most of it. An estimator names the recogniser its outputs
are read with (:func:`recogniser`: ``"paper"`` these rules, ``"hmm"`` the decoder; its class
attribute or SSD setting ``regime_recogniser``, default the paper's).

The truth a recognised regime is compared with
----------------------------------------------
The Driver labels its *modes* (``models/train/driver.py``); the paper's regimes are what the train
does. They differ where the driver's traction does not accelerate the train: the departure's
"accelerate" mode holds just below the 40 km/h limit for over a minute with an effort just
above the coasting band, and the traction of traction/coast cycles near top speed accelerates
within the cruising band. Against the Driver's labels even exact signals every second agree
poorly (``tests/test_driving_regimes.py``). So the truth is the paper's definition applied to
the driver's exact signals on its own grid (:func:`true_regimes`): step ``k`` (the command
held over ``[t_k, t_(k+1)]``) is traction/braking/coasting by the *sign* of the applied
effort (no noise band: the command is known), cruising where the mean acceleration
``(v_(k+1) - v_k) / h`` is within the band, standstill where the train did not move. A fix
is compared with the regime that covers most of its interval (:func:`interval_regimes`; ties
to the later one, the regime the interval ends in); fix 0, which has no interval, with
standstill (a run starts at rest).

With the exact interval signals of twin runs (``tests/train_runs.py``) every 10 s, every
fix whose interval holds one regime is recognised right; the fixes whose interval mixes
regimes are the misses, so a run where the driver cruises by holding scores higher than one
with traction/coast cycles: the Driver's cycles (+2/-3 km/h around the target) alternate
tens of seconds of traction and coasting, and a 10 s interval that mixes them has a mean
effort above the band and a mean acceleration within it, so it reads "cruising" (the paper's
Fig. 6 shows the same). That is a limit of 10 s fixes, not of an estimator; every 1 s nearly
every fix is right. The accuracies per run and fix period are asserted in
``tests/test_driving_regimes.py``.

Features (§3.3), from the recognised regimes
---------------------------------------------
"Continuously accelerating" (§3.3): fix ``j`` and fix ``j-1`` both traction (the whole
interval, as far as the fixes tell; the first fix of a traction block is dropped, its
interval began in another regime) and ``a > 0`` (a traction fix that slows the train is an
interval that mixes a coast into the pull: the mean effort of 2 s of traction in 10 s
passes the band, and would pull the power down). Speed windows use the
interval's mid speed ``(v_(j-1) + v_j) / 2``: the effort of an interval belongs to the
speeds it spans.

* ``max_effort_specific`` (N/kg): the continuously accelerating fixes with mid speed in 10-30 km/h
  (below: the gentle start; 30-50 km/h: the transition to the power limit and the 40 km/h
  departure limit, §4.4), a line f = c0 + c1 v fitted by Theil-Sen (:func:`theil_sen_at`),
  its value at 10 km/h (the maximum tractive effort is constant or falls with speed, §3.3:
  the low end is the maximum). One fix: its effort; none: NaN. Times ``mass_effective`` in
  ``max_effort`` (N). Every 10 s the window holds one or two fixes (the paper: "not enough
  data"), so the effort is only roughly right; every 1 s it is exact (both asserted in
  ``tests/test_driving_regimes.py``).
* ``max_power_specific`` (W/kg): the mean of ``f v_mid`` over the continuously accelerating
  fixes with mid speed in 50-130 km/h whose next fix is traction too (mass-specific power
  f v: what the fixes give without a mass; the last fix of a pull may end in a coast: a
  recogniser that gives a mixed interval to its larger share labels it traction).
  ``max_power`` (W) = ``mass_effective`` times it. Scored against the *applied* maximum
  ``traction_fraction P_max / (gamma m)`` (:func:`feature_truth`); the bounds on twin runs,
  exact signals and GNSS with a finite-difference effort, are asserted in
  ``tests/test_driving_regimes.py``.
* ``brake_rates`` (m/s2, five, NaN where a step has none): the mean deceleration ``-a`` of the
  braking fixes by the ATB-EG step of their mid speed: > 130, 130-80, 80-60, 60-40, < 40 km/h
  (§3.3: the observed deceleration, resistance included); a fix that ends at standstill is
  left out (its interval's mean counts time at rest). Against the Driver's style rates
  ``brake_rate_k``: the Driver brakes later and harder than its style (it decides on the
  position of the step before and starts at rho >= 1: brake efforts at or above b_k), and
  the deceleration adds the resistance, so even exact signals every second read above them;
  every 10 s a brake of a few fixes' length gives one or two fixes that mix it with the coast
  before. The steps above 80 km/h see no braking where the final coast ends below 80 km/h
  (most runs of the shipped line; the step above 130 km/h rarely sees any).
* ``cruise_speed`` (m/s): the median speed of the cruising fixes at or above half the run's
  top speed (a hold below a low limit, the 40 km/h at departure, is not the cruise). Where
  at most a tenth of the cruise span (the fixes at that speed from the first non-traction
  fix to the last traction fix) is cruising, the driver cycles (traction/coast, the cruising
  fixes are a pull's weak end): the span's median speed (on the tuning runs of ``improved``
  with the HMM, seeds 100-199, it shortens the tail of the cruise-speed error). NaN where
  neither exists. A hold sits a little under the driver's target; the bound on twin runs
  every 10 s is asserted in ``tests/test_driving_regimes.py``, the study's error is
  ``cruise_speed_error_kmh`` (docs/studies/train_resistance.md).
* ``final_brake_duration`` (s): the last block of braking fixes; ``final_coast_duration`` (s):
  the coasting fixes after the last traction fix and before that brake (the final coast
  from the coasting point on: the driver does not pull again; a brake for a lower limit
  inside it, and the fixes at its edges that mix braking and coasting into "cruising", do
  not count). A block of fixes ``j0..j1`` lasts ``t_(j1) - t_(j0-1)``. Both NaN unless the
  fixes end at rest (a record that ends before the stop has not seen the final brake).
  Every 10 s both are within a few fixes of the truth (the same function on
  :func:`true_regimes`), every 1 s exact (asserted in ``tests/test_driving_regimes.py``).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

STANDSTILL, TRACTION, CRUISING, COASTING, BRAKING = range(5)
REGIME_NAMES = {0: "standstill", 1: "traction", 2: "cruising", 3: "coasting", 4: "braking"}
KMH = 1.0 / 3.6
BAND_EFFORT = 0.025  # N/kg, §3.2
BAND_ACCELERATION = 0.06  # m/s2, §3.2
#: below this speed (m/s) the train is at rest: under the GNSS's 1 km/h resolution (a reading
#: of 0) and above a filtered speed's residue at rest
STANDSTILL_SPEED = 0.1
#: ATB-EG speed steps (km/h, (low, high]): > 130, 130-80, 80-60, 60-40, < 40
ATB_EG_STEPS = ((130.0, math.inf), (80.0, 130.0), (60.0, 80.0), (40.0, 60.0), (0.0, 40.0))
EFFORT_WINDOW_KMH = (10.0, 30.0)
POWER_WINDOW_KMH = (50.0, 130.0)
#: a cruise span with at most this share of cruising fixes is traction/coast cycles (cruise speed)
CYCLE_CRUISING_SHARE = 0.1


def finite_arrays(n_expected: int | None = None, **named) -> list[np.ndarray]:
    """Each named signal as a flat float array; a ValueError names a non-finite sample or a
    wrong length."""
    out = []
    for name, x in named.items():
        a = np.asarray(x, dtype=float).ravel()
        if n_expected is not None and a.size != n_expected:
            raise ValueError(f"{name} has {a.size} samples, expected {n_expected}")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:  # NaN would fall through every band into "braking"
            raise ValueError(f"{name}[{bad[0]}] is {a[bad[0]]}, not a finite number")
        out.append(a)
        n_expected = a.size
    return out


def previous_fix(x: np.ndarray) -> np.ndarray:
    """x_(j-1) per fix (fix 0: itself)."""
    return np.r_[x[:1], x[:-1]]


def mid_speed(speed: Sequence[float]) -> np.ndarray:
    """(v_(j-1) + v_j) / 2 per fix (fix 0: v_0), m/s."""
    v = np.asarray(speed, dtype=float)
    return 0.5 * (v + previous_fix(v))


def recognise(speed, acceleration, effort, band_effort: float = BAND_EFFORT,
              band_acceleration: float = BAND_ACCELERATION,
              standstill_speed: float = STANDSTILL_SPEED) -> np.ndarray:
    """Regime code per fix by the §3.2 rules (module docstring): ``speed`` (m/s) at the fixes,
    ``acceleration`` (m/s2) and ``effort`` (N/kg) of the interval ending at each fix."""
    v, a, f = finite_arrays(speed=speed, acceleration=acceleration, effort=effort)
    regime = np.where(np.abs(f) <= band_effort, COASTING,
                      np.where(np.abs(a) <= band_acceleration, CRUISING,
                               np.where(f > 0, TRACTION, BRAKING)))
    return np.where(np.maximum(v, previous_fix(v)) <= standstill_speed, STANDSTILL, regime).astype(int)


def true_regimes(time, speed, effort, band_acceleration: float = BAND_ACCELERATION,
                 standstill_speed: float = STANDSTILL_SPEED) -> np.ndarray:
    """The regime of each step ``[t_k, t_(k+1)]`` of a simulated run by the §3.2 definitions on
    its exact signals: ``effort[k]`` the applied effort of that step (N/kg; its sign is the
    driver's command: the Train's ``effort_specific`` with the step's command set), ``speed``
    the train's speed at ``t_k`` (m/s). The effort needs no band (the command is known); the
    acceleration is the step's mean ``(v_(k+1) - v_k) / h``. The last point (no step after it)
    takes the regime of its effort at zero acceleration: standstill at rest."""
    t, v, f = finite_arrays(time=time, speed=speed, effort=effort)
    a = np.r_[np.diff(v) / np.diff(t), 0.0]
    regime = np.where(f == 0, COASTING, np.where(np.abs(a) <= band_acceleration, CRUISING,
                                                  np.where(f > 0, TRACTION, BRAKING)))
    moved = np.maximum(v, np.r_[v[1:], v[-1:]]) > standstill_speed
    return np.where(moved, regime, STANDSTILL).astype(int)


def interval_regimes(sample_time, time, regime, share: bool = False):
    """The truth per fix: the regime covering most of ``(t_(j-1), t_j]`` among the steps
    ``[t_k, t_(k+1)]`` of ``time``/``regime`` (the driver's grid; ``regime[k]`` the regime of
    that step), ties to the later regime. Fix 0 has no interval: standstill (a run starts at
    rest, the Driver in its wait mode), as :func:`recognise` gives at rest. With ``share``
    also the fraction of each interval that regime covers (1: a single-regime interval)."""
    ts = np.asarray(sample_time, dtype=float)
    t, r = np.asarray(time, dtype=float), np.asarray(regime).astype(int)
    if t.size != r.size:
        raise ValueError(f"regime has {r.size} samples, time {t.size}")
    h = np.diff(t, append=t[-1] + (t[-1] - t[-2] if t.size > 1 else 1.0))
    tol = 1e-9 * max(1.0, float(np.abs(t).max()))
    out = np.full(ts.size, STANDSTILL, dtype=int)
    frac = np.ones(ts.size)
    for j in range(1, ts.size):
        lo, hi = ts[j - 1], ts[j]
        # overlap of each step [t_k, t_k + h_k] with (lo, hi]
        w = np.clip(np.minimum(t + h, hi) - np.maximum(t, lo), 0.0, None)
        cover = np.bincount(r, weights=w, minlength=5)
        best = np.flatnonzero(cover >= cover.max() - tol)
        if best.size == 1 or cover.max() <= 0:
            out[j] = best[0]
        else:  # a tie: the regime that comes later in the interval
            k = np.flatnonzero((w > 0) & np.isin(r, best))
            out[j] = r[k[-1]]
        frac[j] = cover.max() / cover.sum() if cover.sum() > 0 else 1.0
    return (out, frac) if share else out


def regime_accuracy(recognised, true_regime, sample_time=None, time=None) -> float:
    """Fraction of fixes whose recognised regime equals the truth. ``true_regime`` per fix, or
    on the driver's grid ``time`` (then aligned by :func:`interval_regimes` to ``sample_time``,
    the fixes' times)."""
    rec = np.asarray(recognised).astype(int).ravel()
    truth = np.asarray(true_regime).astype(int).ravel()
    if sample_time is not None or time is not None:
        if sample_time is None or time is None:
            raise ValueError("regime_accuracy: give both sample_time and time, or neither")
        truth = interval_regimes(sample_time, time, truth)
    if rec.size != truth.size:
        raise ValueError(f"recognised has {rec.size} samples, true_regime {truth.size}")
    return float(np.mean(rec == truth)) if rec.size else float("nan")


def theil_sen_at(x, y, x0: float) -> float:
    """The Theil-Sen line through (x, y) at x0: slope the median of the pairwise slopes,
    intercept the median of ``y - slope x``. One point: its y; none: NaN. Robust where a least-
    squares line is not: at 1 s the first fixes above 10 km/h still carry the gentle start (the
    driver acts on the speed of the step before), and least squares tilts by them at 10 km/h
    on twin runs, where Theil-Sen is exact."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.size < 2:
        return float(y[0]) if x.size else math.nan
    i, j = np.triu_indices(x.size, 1)
    dx = x[j] - x[i]
    ok = dx != 0
    slope = float(np.median((y[j] - y[i])[ok] / dx[ok])) if ok.any() else 0.0
    return float(np.median(y - slope * x) + slope * x0)


def _blocks(regime: np.ndarray) -> list[tuple[int, int, int]]:
    """(code, first, last) of each run of equal codes."""
    edges = np.flatnonzero(np.diff(regime)) + 1
    starts, ends = np.r_[0, edges], np.r_[edges - 1, regime.size - 1]
    return [(int(regime[s]), int(s), int(e)) for s, e in zip(starts, ends)]


def _duration(t: np.ndarray, first: int, last: int) -> float:
    return float(t[last] - t[max(first - 1, 0)])


def final_durations(time, regimes, speed=None, standstill_speed: float = STANDSTILL_SPEED
                    ) -> tuple[float, float]:
    """(final coast, final brake) durations in s: the last block of braking fixes, and the
    coasting fixes after the last traction fix and before that brake (module docstring). NaN
    where the run has no such fixes, or (with ``speed``, m/s) does not end at rest: fixes
    that stop before the train does have not seen the final brake end. ``time``/``regimes``
    per fix, each fix describing the interval before it; the driver's grid (``regime[k]``
    the step after ``t_k``) takes ``time + h``."""
    t, r = np.asarray(time, dtype=float), np.asarray(regimes).astype(int)
    brakes = [b for b in _blocks(r) if b[0] == BRAKING]
    if not brakes or (speed is not None and np.asarray(speed, dtype=float)[-1] > standstill_speed):
        return math.nan, math.nan
    _, b0, b1 = brakes[-1]
    pulled = np.flatnonzero(r[:b0] == TRACTION)
    start = int(pulled[-1]) + 1 if pulled.size else 0
    coasts = [(s, e) for c, s, e in _blocks(r[:b0]) if c == COASTING and s >= start]
    coast = sum(_duration(t, s, e) for s, e in coasts) if coasts else math.nan
    return float(coast), _duration(t, b0, b1)


def features(time, speed, acceleration, effort, regimes, mass_effective: float | None = None,
             standstill_speed: float = STANDSTILL_SPEED) -> dict:
    """The §3.3 features of one run (module docstring for every definition). Returns

    ``max_effort_specific`` (N/kg), ``max_power_specific`` (W/kg), ``brake_rates`` (five,
    m/s2), ``cruise_speed`` (m/s), ``final_coast_duration``, ``final_brake_duration`` (s), and
    with ``mass_effective`` (gamma m, kg) ``max_effort`` (N) and ``max_power`` (W); for the
    figures: ``regimes`` (per fix, Fig. 6), ``effort_samples`` / ``power_samples`` (``time``,
    ``speed`` the mid speeds, ``effort`` or ``power`` of the fixes used; ``initial``: the fix
    is in the initial traction phase, up to the first non-traction fix at or above 50 km/h,
    Fig. 9), ``brake_samples`` (``time``, ``speed``, ``deceleration``, ``step`` 1-5 of every
    braking fix used, Fig. 8)."""
    t, v, a, f, r = finite_arrays(time=time, speed=speed, acceleration=acceleration, effort=effort,
                            regimes=regimes)
    if t.size < 2:
        raise ValueError(f"features: a run needs at least two fixes, got {t.size}")
    r = r.astype(int)
    vm = mid_speed(v)
    kmh = vm / KMH
    prev = previous_fix(r)
    prev[:1] = -1  # fix 0 has no interval
    continuous = (r == TRACTION) & (prev == TRACTION) & (a > 0)
    sel = continuous & (kmh >= EFFORT_WINDOW_KMH[0]) & (kmh <= EFFORT_WINDOW_KMH[1])
    max_effort = theil_sen_at(vm[sel], f[sel], EFFORT_WINDOW_KMH[0] * KMH)
    effort_samples = {"time": t[sel], "speed": vm[sel], "effort": f[sel]}

    # the power's fixes also pull after them: a block's last traction fix may end in a coast
    pulls_on = np.r_[r[1:], TRACTION] == TRACTION
    sel = continuous & pulls_on & (kmh >= POWER_WINDOW_KMH[0]) & (kmh <= POWER_WINDOW_KMH[1])
    power = f[sel] * vm[sel]
    max_power = float(power.mean()) if power.size else math.nan
    # the initial traction phase (Fig. 9): until the first non-traction fix at or above 50 km/h
    later = np.flatnonzero((kmh >= POWER_WINDOW_KMH[0]) & (r != TRACTION))
    end = int(later[0]) if later.size else r.size
    power_samples = {"time": t[sel], "speed": vm[sel], "power": power,
                     "initial": np.flatnonzero(sel) < end}

    braking = (r == BRAKING) & (v > standstill_speed)
    step = np.zeros(r.size, dtype=int)
    for k, (lo, hi) in enumerate(ATB_EG_STEPS, 1):
        step[braking & (kmh > lo) & (kmh <= hi)] = k
    rates = [float(-a[step == k].mean()) if (step == k).any() else math.nan for k in range(1, 6)]
    used = step > 0
    brake_samples = {"time": t[used], "speed": vm[used], "deceleration": -a[used], "step": step[used]}

    cruise = (r == CRUISING) & (v >= 0.5 * v.max())
    cruise_speed = float(np.median(v[cruise])) if cruise.any() else math.nan
    # the cruise span: from the first let-up at speed to the last pull; where at most a tenth of it
    # is cruising, the driver cycles (traction/coast), and the cruise speed is the span's median
    high = np.flatnonzero((v >= 0.5 * v.max()) & (r != TRACTION))
    pulls = np.flatnonzero(r == TRACTION)
    if high.size and pulls.size and pulls[-1] > high[0]:
        span = np.arange(high[0], pulls[-1] + 1)
        span = span[v[span] >= 0.5 * v.max()]
        if cruise[span].sum() <= CYCLE_CRUISING_SHARE * span.size:
            cruise_speed = float(np.median(v[span]))
    coast, brake = final_durations(t, r, v, standstill_speed)

    out = {"max_effort_specific": max_effort, "max_power_specific": max_power, "brake_rates": rates,
           "cruise_speed": cruise_speed, "final_coast_duration": coast, "final_brake_duration": brake,
           "regimes": r, "effort_samples": effort_samples, "power_samples": power_samples,
           "brake_samples": brake_samples}
    if mass_effective is not None:
        out["max_effort"] = max_effort * float(mass_effective)
        out["max_power"] = max_power * float(mass_effective)
    return out


def reference_features(time, speed, effort, mass_effective: float | None = None) -> dict:
    """:func:`features` of a simulated run on the driver's own grid with its exact signals:
    what the run reveals at full resolution, the reference for what the style outputs do not
    give (the final coast and brake durations) or give only as intent (the Driver's applied
    brake rates exceed its style's, module docstring). ``time``, ``speed``, ``effort`` as
    :func:`true_regimes` (the recorded ``train.v`` and ``train.effort_specific``); fix ``k``
    is the step ``[t_(k-1), t_k]``, its regime the step's :func:`true_regimes`. Score the
    power and effort against :func:`feature_truth` instead: the recorded effort is the one
    at ``t_k``, not the step's mean, which puts P/v off by ``dv / 2v`` (~0.5 %)."""
    t, v, f = finite_arrays(time=time, speed=speed, effort=effort)
    r = np.r_[STANDSTILL, true_regimes(t, v, f)[:-1]]
    a = np.r_[0.0, np.diff(v) / np.diff(t)]
    return features(t, v, a, np.r_[0.0, f[:-1]], r, mass_effective)


def feature_truth(style: Mapping, train: Mapping) -> dict:
    """The values the features are scored against, from the Driver's style outputs
    (``cruise_target``, ``traction_fraction``, ``brake_rate_1..5``) and the Train's parameters
    (``max_power``, ``max_traction_force``, ``tare_mass``, ``load_mass``,
    ``rotating_mass_factor``): the *applied* maxima. At 50-130 km/h the driver's traction is
    the command ``traction_fraction`` (the gentle start is over, no limit below the cruise
    target) on an envelope that is power-limited above 38 km/h, so the power it applies is
    ``traction_fraction P_max``; at 10-30 km/h it is ``traction_fraction F_max`` (the gentle
    start ends at 10 km/h, the approach to the 40 km/h limit begins at 35). A run reveals no
    more: scored against P_max the feature would measure the driver's 0.7-1.0, not the
    extraction."""
    m_eff = float(train["rotating_mass_factor"]) * (float(train["tare_mass"]) + float(train["load_mass"]))
    fr = float(style["traction_fraction"])
    return {"max_power_specific": fr * float(train["max_power"]) / m_eff,
            "max_effort_specific": fr * float(train["max_traction_force"]) / m_eff,
            "cruise_speed": float(style["cruise_target"]),
            "brake_rates": [float(style[f"brake_rate_{k}"]) for k in range(1, 6)],
            "mass_effective": m_eff}


def feature_errors(feats: Mapping, truth: Mapping) -> dict:
    """The study's metrics (``metrics.json`` names) of :func:`features` against
    :func:`feature_truth`: ``max_power_rel_error``, ``max_effort_rel_error`` (absolute
    relative errors), ``cruise_speed_error_kmh`` (absolute, km/h) and ``brake_rate_error``
    (five signed errors estimate - truth in m/s2, None where the run has no braking fix in
    the step). NaN (None in the list) where a feature is undefined."""
    def rel(name):
        return abs(feats[name] / truth[name] - 1.0)

    def none(x):
        return None if not math.isfinite(x) else float(x)

    return {"max_power_rel_error": rel("max_power_specific"),
            "max_effort_rel_error": rel("max_effort_specific"),
            "cruise_speed_error_kmh": abs(feats["cruise_speed"] - truth["cruise_speed"]) / KMH,
            "brake_rate_error": [none(e - b) for e, b in zip(feats["brake_rates"], truth["brake_rates"])]}
