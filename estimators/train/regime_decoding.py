r"""Driving regimes decoded over the whole run: a hidden Markov model over the GNSS fixes,
decoded by Viterbi, then the intervals that mix two regimes given to the one that fills most
of them. The ``improved`` estimator's recogniser; the paper's rules (Cunillera et al. (2022)
§3.2, :func:`railfmu.estimators.train.driving_regimes.recognise`) decide each fix alone.

Why. Every 10 s the rules see the interval's mean acceleration ``a`` and effort ``f`` with
the error of two speed readings rounded to 1 km/h (0.028 m/s2 steps): a pull near 130 km/h
that accelerates at 0.07 m/s2 reads 0.055 (cruising) one fix and 0.083 (traction) the next,
a coast at 130 km/h reads an effort of -0.03 N/kg (braking). Regimes last several fixes
(the Driver's cycles tens of seconds, holds and coasts minutes), so the run as a whole tells what
one fix cannot. And a fix whose interval mixes two regimes (a cycle's pull and coast, the
start of a brake, the stop) has a mean that lies between the two; the truth gives it the
regime that fills most of the interval, which the neighbouring fixes' levels tell.

Inputs are the samples of :mod:`railfmu.estimators.train.driving_regimes` (``acceleration[j]`` and
``effort[j]`` of the interval ``(t_(j-1), t_j]``, ``speed[j]`` at ``t_j``); no truth.

1. Emission scores: soft §3.2 rules. With ``sigma_j = acceleration_noise / sqrt(dt_j)``
   the error of the interval's mean acceleration (and of its effort, ``f = a + r(v) + g``),
   ``beta`` the 0.06 m/s2 band and ``Phi`` the normal distribution function::

       traction    Phi((a - beta) / sigma) Phi(f / sigma)
       cruising    [Phi((beta - a) / sigma) - Phi((-beta - a) / sigma)] (1 - exp(-f^2 / 2 sigma^2))
       coasting    exp(-f^2 / 2 sigma^2)                       (the effort is zero)
       braking     Phi((-beta - a) / sigma) Phi((-f - f_b) / sigma)
       standstill  1 where max(v_(j-1), v_j) <= v_stop, and then the only regime

   each in [0, 1], 1 deep inside its region. An interval that ends at rest (``v_j <= v_stop
   < v_(j-1)``) is a brake (step 4 gives it to standstill where the train stood most of
   it). ``f_b`` (``brake_effort``, 0.06 N/kg): a brake is applied, not grazed (the
   Driver's brakes decelerate 0.3-0.7 m/s2), so a coast read at -0.03 N/kg stays a coast.
2. Transitions: a regime of mean duration ``tau`` (``regime_duration``) is left within
   ``dt`` with odds ``dt / tau`` against staying: switching costs ``log(tau / dt_j)``
   (>= 0) in the log score, staying nothing. Every switch is allowed (cruise cycles go
   traction -> coasting -> traction; a brake for a limit returns to coasting or cruising).
3. Viterbi (:func:`viterbi`): the sequence of regimes that maximises the sum of the log
   emission scores and transition log scores.
4. Mixed intervals (:func:`mixed_intervals`). Where the decoded regime changes across a
   fix ``j`` (``A`` at ``j-1``, ``B`` at ``j+1``, ``A != B``, ``j`` either's first or last
   fix or a third regime between them), its interval is taken as ``A`` for a share ``p``,
   then ``B``: its mean acceleration ``a_j = p a_(j-1) + (1 - p) a_(j+1)`` with the
   neighbours as the two regimes' levels (0 for a stop: ``B`` standstill where the
   interval ends at rest), so ``p = (a_j - a_(j+1)) / (a_(j-1) - a_(j+1))`` clipped to
   [0, 1]; the fix is ``A`` where ``p > 1/2``, else ``B`` (a tie to the later regime, as
   the truth). Only where the levels differ by ``2 sigma_j`` (else ``p`` is noise); not
   out of standstill (the Driver departs at once: a departure interval is traction); into
   standstill only after a braking fix (a final brake shorter than one interval keeps its
   one braking fix: the features' final brake); and a third regime other than cruising
   (what the rules read a mix as) only where ``a_j`` lies between the levels (a brake
   between a coast and the stop is a regime of its own).

Tuning (``ImprovedEstimator``'s outputs on the ``standard`` variant, seeds 100-199, not the
study's 1-67; the per-run accuracy's median and lower tail): the decoder beats the rules,
most on cruise cycles, at ``acceleration_noise`` 0.047 m/s^1.5 (0.015 m/s2 every 10 s; a
somewhat smaller value scores slightly lower, a larger one as well at 10 s, but at 1 s fixes
it reads the holds as cycles), ``regime_duration`` 27 s (20 or 40 s score the same),
``brake_effort`` 0.06 N/kg (0.04 scores the same); on ``gnss_1hz`` too it beats the rules.
The accuracy on the study, this decoder beside the rules, is ``regime_accuracy`` of
``railfmu study train_resistance`` (docs/studies/train_resistance.md); on FMU runs it is
asserted in ``tests/test_regime_decoding.py``.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from railfmu.estimators.train.driving_regimes import (
    BAND_ACCELERATION,
    BRAKING,
    COASTING,
    CRUISING,
    STANDSTILL,
    STANDSTILL_SPEED,
    TRACTION,
    finite_arrays,
    previous_fix,
)

#: m/s^1.5: the error of an interval's mean acceleration is this / sqrt(interval), 0.015 m/s2 at 10 s
ACCELERATION_NOISE = 0.047
#: s: a regime's mean duration, the odds of switching within an interval of dt: dt / tau
REGIME_DURATION = 27.0
#: N/kg: the least effort of a brake
BRAKE_EFFORT = 0.06
#: the floor of an emission score (log 1e-12: a regime the rules exclude, not -inf)
_FLOOR = 1e-12


def emission_scores(speed, acceleration, effort, sigma, band_acceleration: float = BAND_ACCELERATION,
                    brake_effort: float = BRAKE_EFFORT, standstill_speed: float = STANDSTILL_SPEED) -> np.ndarray:
    """Per fix and regime code (n x 5) the soft §3.2 score of step 1 of the module docstring;
    ``sigma`` (m/s2) per fix or one for all."""
    v, a, f = (np.asarray(x, dtype=float) for x in (speed, acceleration, effort))
    s = np.broadcast_to(np.asarray(sigma, dtype=float), v.shape)
    e = np.zeros((v.size, 5))
    zero = np.exp(-0.5 * (f / s) ** 2)
    e[:, TRACTION] = ndtr((a - band_acceleration) / s) * ndtr(f / s)
    e[:, CRUISING] = (ndtr((band_acceleration - a) / s) - ndtr((-band_acceleration - a) / s)) * (1.0 - zero)
    e[:, COASTING] = zero
    e[:, BRAKING] = ndtr((-band_acceleration - a) / s) * ndtr((-f - brake_effort) / s)
    still = np.maximum(v, previous_fix(v)) <= standstill_speed
    e[still] = 0.0
    e[still, STANDSTILL] = 1.0
    stops = (v <= standstill_speed) & ~still  # the interval ends at rest: a brake, then at rest
    e[stops] = 0.0
    e[stops, BRAKING] = 1.0  # step 4 gives it to standstill if the train stood most of it
    return e


def viterbi(log_emission: np.ndarray, log_transition: np.ndarray) -> np.ndarray:
    """The state sequence maximising ``sum_j log_emission[j, x_j] + sum_(j>=1)
    log_transition[j, x_(j-1), x_j]`` (``log_transition`` n x k x k, or k x k for every
    step; row 0 unused). Ties go to the lowest state."""
    E = np.asarray(log_emission, dtype=float)
    n, k = E.shape
    T = np.asarray(log_transition, dtype=float)
    if T.ndim == 2:
        T = np.broadcast_to(T, (n, k, k))
    back = np.zeros((n, k), dtype=int)
    score = E[0].copy()
    for j in range(1, n):
        cand = score[:, None] + T[j]  # from row to column
        back[j] = cand.argmax(axis=0)
        score = cand[back[j], np.arange(k)] + E[j]
    path = np.empty(n, dtype=int)
    path[-1] = int(score.argmax())
    for j in range(n - 1, 0, -1):
        path[j - 1] = back[j, path[j]]
    return path


def switch_log_odds(dt, regime_duration: float = REGIME_DURATION) -> np.ndarray:
    """Per interval the log score of a switch against staying: ``-max(log(tau / dt), 0)``."""
    return -np.maximum(np.log(regime_duration / np.maximum(np.asarray(dt, dtype=float), 1e-12)), 0.0)


def mixed_intervals(regimes, speed, acceleration, sigma, standstill_speed: float = STANDSTILL_SPEED) -> np.ndarray:
    """Step 4 of the module docstring: the fixes around each change of regime given to the
    regime that fills most of their interval."""
    r = np.asarray(regimes).astype(int)
    v, a = np.asarray(speed, dtype=float), np.asarray(acceleration, dtype=float)
    s = np.broadcast_to(np.asarray(sigma, dtype=float), v.shape)
    out = r.copy()
    for j in range(1, r.size - 1):
        A, B = r[j - 1], r[j + 1]
        if A == B or A == STANDSTILL or (B == STANDSTILL and (v[j] > standstill_speed or A != BRAKING)):
            continue
        a_A, a_B = a[j - 1], (0.0 if B == STANDSTILL else a[j + 1])
        if abs(a_A - a_B) < 2.0 * s[j]:
            continue
        if r[j] not in (A, B, CRUISING) and not min(a_A, a_B) - s[j] <= a[j] <= max(a_A, a_B) + s[j]:
            continue  # a third regime of its own (a brake between a coast and the stop), not a mix
        p = min(max((a[j] - a_B) / (a_A - a_B), 0.0), 1.0)
        out[j] = A if p > 0.5 else B
    return out


def recognise_hmm(time, speed, acceleration, effort, acceleration_noise: float = ACCELERATION_NOISE,
                  regime_duration: float = REGIME_DURATION, brake_effort: float = BRAKE_EFFORT,
                  band_acceleration: float = BAND_ACCELERATION, standstill_speed: float = STANDSTILL_SPEED
                  ) -> np.ndarray:
    """Regime code per fix (module docstring): ``time`` (s) of the fixes, ``speed`` (m/s) at
    them, ``acceleration`` (m/s2) and ``effort`` (N/kg) of the interval ending at each."""
    t, v, a, f = finite_arrays(time=time, speed=speed, acceleration=acceleration, effort=effort)
    if t.size == 0:
        return np.zeros(0, dtype=int)
    if t.size > 1 and not (np.diff(t) > 0).all():
        raise ValueError("time must increase from fix to fix")
    if not (acceleration_noise > 0 and regime_duration > 0 and brake_effort >= 0):
        raise ValueError("acceleration_noise and regime_duration must be > 0, brake_effort >= 0")
    dt = np.r_[np.diff(t[:2]) if t.size > 1 else 1.0, np.diff(t)]  # fix 0: its neighbour's
    sigma = acceleration_noise / np.sqrt(dt)
    E = np.log(np.maximum(emission_scores(v, a, f, sigma, band_acceleration, brake_effort, standstill_speed),
                          _FLOOR))
    T = switch_log_odds(dt, regime_duration)[:, None, None] * (1.0 - np.eye(5))
    return mixed_intervals(viterbi(E, T), v, a, sigma, standstill_speed)

