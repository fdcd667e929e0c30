"""Driving-regime recognition and feature extraction (Cunillera et al. (2022) §3.2-3.3):
the rules on hand-made cases, the interval alignment on a hand-made driver grid, the
features on closed-form profiles, and both on Driver + Train + Gnss twin runs
(``tests/train_runs.py``) with exact and with GNSS signals."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from scipy.stats import theilslopes

from railfmu.estimators.train.driving_regimes import (
    BRAKING,
    COASTING,
    CRUISING,
    KMH,
    STANDSTILL,
    TRACTION,
    feature_errors,
    feature_truth,
    features,
    final_durations,
    interval_regimes,
    recognise,
    regime_accuracy,
    reference_features,
    theil_sen_at,
    true_regimes,
)
from railfmu.estimators.train.recognisers import score
from railfmu.fmus.cosim import masters
from railfmu.fmus.cosim.system import Component, Connection, System
from railfmu.models.train.longitudinal import (
    GAMMA,
    LOAD_MASS,
    MAX_POWER,
    MAX_TRACTION_FORCE,
    TARE_MASS,
)
from train_runs import sample, simulate

TRAIN = {"max_power": MAX_POWER, "max_traction_force": MAX_TRACTION_FORCE, "tare_mass": TARE_MASS,
         "load_mass": LOAD_MASS, "rotating_mass_factor": GAMMA}
HOLDING, CYCLES, SLOW_CYCLES = 2, 3, 6  # seeds: cruise by holding; cycles; cycles at f = 0.71


@lru_cache(maxsize=None)
def twin(seed):
    run = simulate(seed)
    return run, true_regimes(run.time, run.v, run.effort)


def recognised(run, period, gnss=None):
    d = sample(run, period, gnss)
    return d, recognise(d["speed"], d["acceleration"], d["effort"])


# ---- recognition rules ----------------------------------------------------------------------
def test_the_rules_and_their_band_edges():
    # (v_prev, v, a, f) -> regime; bands 0.025 N/kg and 0.06 m/s2, both edges inclusive
    cases = [
        ((0.0, 0.0, 0.0, 0.3), STANDSTILL),  # at rest, whatever the effort
        ((0.0, 0.09, 0.009, 0.3), STANDSTILL),  # under 0.1 m/s at both ends
        ((0.0, 1.2, 0.12, 0.3), TRACTION),  # departed within the interval
        ((1.2, 0.0, -0.12, -0.3), BRAKING),  # stopped within the interval
        ((20, 20, -0.02, 0.025), COASTING),  # |f| on the band edge: coasting
        ((20, 20, -0.02, -0.025), COASTING),
        ((20, 20, -0.02, 0.0251), CRUISING),
        ((20, 20, 0.06, 0.2), CRUISING),  # |a| on the band edge: cruising
        ((20, 20, -0.06, -0.2), CRUISING),  # braking that holds the speed (downhill)
        ((20, 20, 0.0601, 0.2), TRACTION),
        ((20, 20, -0.0601, 0.2), TRACTION),  # pulling uphill and still slowing: by the effort
        ((20, 20, -0.0601, -0.2), BRAKING),
        ((20, 20, 0.5, -0.03), BRAKING),  # braking downhill and still gaining speed
    ]
    for (vp, v, a, f), expected in cases:
        got = recognise([vp, v], [0.0, a], [0.0, f])
        assert got[1] == expected, ((vp, v, a, f), got)
    # the bands are parameters
    assert recognise([20, 20], [0, 0.1], [0, 0.04], band_effort=0.05)[1] == COASTING
    assert recognise([20, 20], [0, 0.1], [0, 0.04], band_acceleration=0.2)[1] == CRUISING
    assert recognise([0.3, 0.3], [0, 0], [0, 0.3], standstill_speed=0.5)[1] == STANDSTILL


def test_true_regimes_by_the_sign_of_the_effort_and_the_steps_acceleration():
    t = np.arange(7.0)
    v = np.array([0.0, 0.5, 1.0, 1.03, 1.03, 0.5, 0.0])
    f = np.array([0.6, 0.6, 0.1, 1e-9, -0.01, -0.6, -0.5])
    # step k is [t_k, t_k+1]: accelerating 0.5, 0.5; 0.03 (within the band); 0 with a tiny pull;
    # a brake of 0.01 N/kg (inside the recogniser's effort band: the truth has none); braking;
    # the last point at rest
    assert list(true_regimes(t, v, f)) == [TRACTION, TRACTION, CRUISING, CRUISING, BRAKING, BRAKING,
                                           STANDSTILL]
    assert true_regimes([0, 1, 2], [5, 5, 5], [0.0, 0.0, 0.0]).tolist() == [COASTING] * 3


def test_a_fix_is_compared_with_the_regime_covering_most_of_its_interval():
    time = np.arange(30.0)  # the driver's steps [k, k + 1]
    regime = np.array([1] * 7 + [2] * 3 + [2] * 5 + [3] * 5 + [3] * 4 + [4] * 6)
    fixes = np.array([0.0, 10, 20, 30])
    # (0, 10]: 7 traction, 3 cruising; (10, 20]: 5 cruising, 5 coasting, a tie: the later;
    # (20, 30]: 4 coasting, 6 braking; fix 0: standstill (the run starts at rest)
    assert interval_regimes(fixes, time, regime).tolist() == [STANDSTILL, TRACTION, COASTING, BRAKING]
    # fixes that do not fall on the driver's grid: overlaps are weighed in time
    assert interval_regimes([0.0, 6.5, 13.5], time, regime).tolist() == [STANDSTILL, TRACTION, CRUISING]
    assert np.array_equal(interval_regimes(fixes, time, regime, share=True)[1], [1.0, 0.7, 0.5, 0.6])
    rec = [STANDSTILL, TRACTION, CRUISING, BRAKING]
    assert regime_accuracy(rec, regime, fixes, time) == 0.75
    assert regime_accuracy(rec, [0, 1, 3, 4]) == 0.75
    with pytest.raises(ValueError, match="recognised has 4 samples, true_regime 3"):
        regime_accuracy(rec, [0, 1, 3])
    with pytest.raises(ValueError, match="both sample_time and time"):
        regime_accuracy(rec, regime, fixes)


# ---- features on closed-form profiles -------------------------------------------------------
def test_brake_rates_per_atb_eg_step_on_a_stepped_braking():
    """Braking from 150 km/h at a known rate in each ATB-EG step, the steps' edges at whole
    seconds: fixes every second give each rate exactly; the fix that ends at rest is left out."""
    edges = np.array([150.0, 130, 80, 60, 40, 0]) * KMH
    durations = np.array([40, 90, 30, 25, 30])  # s
    rates = (edges[:-1] - edges[1:]) / durations  # 0.139, 0.154, 0.185, 0.222, 0.370 m/s2
    v = np.concatenate([[edges[0]]] + [edges[k] - rates[k] * np.arange(1, d + 1)
                                       for k, d in enumerate(durations)])
    v = np.r_[v, 0.0, 0.0]  # at rest for two fixes
    t = np.arange(v.size, dtype=float)
    a = np.r_[0.0, np.diff(v)]
    f = a.copy()  # no resistance: the effort is the acceleration
    r = recognise(v, a, f)
    assert (r[1:durations.sum() + 1] == BRAKING).all() and (r[-2:] == STANDSTILL).all()
    feats = features(t, v, a, f, r)
    assert np.allclose(feats["brake_rates"], rates, rtol=1e-12, atol=0)
    # fix 0 (no interval, zero effort) reads as coasting, for no time
    assert feats["final_brake_duration"] == durations.sum() and feats["final_coast_duration"] == 0.0
    steps = sum(([k + 1] * d for k, d in enumerate(durations)), [])
    assert feats["brake_samples"]["step"].tolist() == steps[:-1]  # the last ends at rest
    # no fix in a step: NaN there, None in the errors
    cut = t <= 40 + 90  # only down to 80 km/h
    feats = features(t[cut], v[cut], a[cut], f[cut], r[cut])
    assert np.allclose(feats["brake_rates"][:2], rates[:2])
    assert all(map(math.isnan, feats["brake_rates"][2:]))
    err = feature_errors({**feats, "max_power_specific": 1.0, "max_effort_specific": 1.0, "cruise_speed": 30.0},
                         {"max_power_specific": 1.0, "max_effort_specific": 1.0, "cruise_speed": 30.0,
                          "brake_rates": list(rates)})
    assert err["brake_rate_error"][2:] == [None] * 3 and max(map(abs, err["brake_rate_error"][:2])) < 1e-12


def test_maximum_effort_and_power_on_a_traction_envelope():
    """f = min(F, P / v) / (gamma m) with a gentle start below 12 km/h; fixes every second with
    the exact interval efforts: the effort at 10 km/h is F's, the power P's, and a Theil-Sen
    line ignores the ramp a least-squares line tilts by."""
    m, F, P = GAMMA * (TARE_MASS + LOAD_MASS), MAX_TRACTION_FORCE, MAX_POWER
    dt = 1e-3
    t = np.arange(0, 160 + dt / 2, dt)
    v = np.empty_like(t)
    f = np.empty_like(t)
    v[0] = 0.0
    for k in range(t.size):
        ramp = min(0.3 + 0.7 * v[k] / (12 * KMH), 1.0)
        f[k] = ramp * min(F, P / max(v[k], 1e-9)) / m
        if k + 1 < t.size:
            v[k + 1] = v[k] + f[k] * dt  # no resistance: the train accelerates by f
    fix = np.arange(0, t.size, 1000)
    fv = np.r_[0.0, [f[i - 1000:i].mean() for i in fix[1:]]]
    vv = v[fix]
    a = np.r_[0.0, np.diff(vv)]
    r = recognise(vv, a, fv)
    assert (r[1:] == TRACTION).all()
    feats = features(t[fix], vv, a, fv, r, mass_effective=m)
    assert feats["max_effort"] == pytest.approx(F, rel=1e-12)
    assert feats["max_power"] == pytest.approx(P, rel=2e-4)  # mean of P/v over a second, times v_mid
    used = feats["effort_samples"]
    assert used["speed"].min() >= 10 * KMH and used["speed"].max() <= 30 * KMH
    slope, c0 = np.polyfit(used["speed"], used["effort"], 1)
    assert (c0 + slope * 10 * KMH) * m < 0.995 * F  # least squares: tilted by the ramp (-0.6 %)
    assert feats["power_samples"]["initial"].all()


def test_theil_sen_is_scipys_joint_estimator():
    rng = np.random.default_rng(5)
    x = rng.uniform(3, 8, 17)
    y = 0.6 - 0.01 * x + rng.normal(0, 0.01, 17)
    y[:3] -= 0.2  # outliers
    res = theilslopes(y, x, method="joint")
    assert theil_sen_at(x, y, 2.5) == pytest.approx(res.intercept + res.slope * 2.5, rel=1e-14)
    assert theil_sen_at([4.0], [0.3], 1.0) == 0.3 and math.isnan(theil_sen_at([], [], 1.0))


def test_truth_and_errors_of_the_features():
    style = {"cruise_target": 130 * KMH, "traction_fraction": 0.8,
             **{f"brake_rate_{k}": 0.3 + 0.05 * k for k in range(1, 6)}}
    truth = feature_truth(style, TRAIN)
    m = GAMMA * (TARE_MASS + LOAD_MASS)
    assert truth["max_power_specific"] == pytest.approx(0.8 * MAX_POWER / m, rel=1e-15)
    assert truth["max_effort_specific"] == pytest.approx(0.8 * MAX_TRACTION_FORCE / m, rel=1e-15)
    feats = {"max_power_specific": 1.03 * truth["max_power_specific"],
             "max_effort_specific": 0.9 * truth["max_effort_specific"], "cruise_speed": 128.5 * KMH,
             "brake_rates": [math.nan, 0.42, 0.44, 0.5, 0.55]}
    err = feature_errors(feats, truth)
    assert err["max_power_rel_error"] == pytest.approx(0.03, rel=1e-12)
    assert err["max_effort_rel_error"] == pytest.approx(0.1, rel=1e-12)
    assert err["cruise_speed_error_kmh"] == pytest.approx(1.5, rel=1e-12)
    assert err["brake_rate_error"][0] is None
    assert np.allclose(err["brake_rate_error"][1:], [0.02, -0.01, 0.0, 0.0], atol=1e-15)


def test_final_durations_skip_a_limit_brake_and_its_edges():
    # pull, cruise, coast 5 fixes, a brake for a limit with a "cruising" edge fix, coast 3,
    # the final brake 2, at rest
    r = [1, 1, 2, 2, 3, 3, 3, 3, 3, 4, 2, 3, 3, 3, 4, 4, 0]
    t = 10.0 * np.arange(len(r))
    assert final_durations(t, r) == (80.0, 20.0)
    coast, brake = final_durations(t[:4], [1, 3, 3, 0])
    assert math.isnan(coast) and math.isnan(brake)  # no brake: no final phase
    v = np.full(len(r), 20.0)
    assert final_durations(t, r, np.r_[v[:-1], 0.0]) == (80.0, 20.0)
    coast, brake = final_durations(t[:-1], r[:-1], v[:-1])  # the fixes end before the stop
    assert math.isnan(coast) and math.isnan(brake)


def test_too_short_a_run_and_mismatched_arrays_are_errors():
    with pytest.raises(ValueError, match="at least two fixes, got 1"):
        features([0.0], [0.0], [0.0], [0.0], [0])
    with pytest.raises(ValueError, match="effort has 2 samples, expected 3"):
        recognise([0, 1, 2], [0, 1, 1], [0, 1])
    with pytest.raises(ValueError, match=r"acceleration\[1\] is nan, not a finite number"):
        recognise([0, 1, 2], [0, np.nan, 1], [0, 1, 1])


# ---- twin runs ----------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [HOLDING, CYCLES, SLOW_CYCLES])
def test_regime_accuracy_with_exact_signals(seed):
    """Exact interval signals every second agree with the truth at >= 0.995 (measured
    0.997, 0.999, 0.995: the misses are seconds split between two regimes). Every 10 s
    every fix whose interval holds one regime is right; the intervals that mix traction and
    coasting of cruise cycles (12-40 s each) read as cruising: 0.98 holding, 0.87 and 0.93
    with cycles (measured 0.978, 0.868, 0.929). The Driver's own labels (by mode) agree at
    only 0.65-0.93 even at 1 s."""
    run, truth = twin(seed)
    d, rec = recognised(run, 1.0)
    assert regime_accuracy(rec, truth, d["time"], run.time) >= 0.995
    assert regime_accuracy(rec, run.regime, d["time"], run.time) < 0.94
    d, rec = recognised(run, 10.0)
    floor = {HOLDING: 0.975, CYCLES: 0.86, SLOW_CYCLES: 0.92}[seed]
    assert regime_accuracy(rec, truth, d["time"], run.time) >= floor
    # every miss is an interval that mixes regimes: one regime in the interval, no miss
    per_fix, share = interval_regimes(d["time"], run.time, truth, share=True)
    single = share == 1.0
    assert single.mean() > 0.75 and np.array_equal(rec[single], per_fix[single])  # 79-92 % single


@pytest.mark.parametrize("seed", [HOLDING, CYCLES, SLOW_CYCLES])
def test_features_with_exact_signals(seed):
    run, truth = twin(seed)
    ref = feature_truth(run.style, TRAIN)
    coast, brake = final_durations(run.time + run.h, truth)
    # every second: the applied maxima exactly (measured < 1e-6), cruise within 1 km/h
    d, rec = recognised(run, 1.0)
    feats = features(d["time"], d["speed"], d["acceleration"], d["effort"], rec)
    err = feature_errors(feats, ref)
    assert err["max_power_rel_error"] < 1e-4 and err["max_effort_rel_error"] < 1e-4
    assert feats["final_coast_duration"] == coast and feats["final_brake_duration"] == brake
    if not run.style["cycles"]:
        assert err["cruise_speed_error_kmh"] < 1.0  # holds 0.46 km/h under the target
    # the run's own grid gives the same: the reference for the durations and applied brake rates
    ref_feats = reference_features(run.time, run.v, run.effort)
    assert ref_feats["final_coast_duration"] == coast and ref_feats["final_brake_duration"] == brake
    assert feature_errors(ref_feats, ref)["max_power_rel_error"] < 1e-4
    assert np.allclose(ref_feats["brake_rates"], feats["brake_rates"], rtol=0.02, equal_nan=True)
    # every 10 s: the power within 1 % (measured 0.02-0.03 %), the effort from one or two fixes
    # within 7 % (measured 1.4, 1.3, 6.2 %), cruise within 1 km/h, the durations within 35 s
    d, rec = recognised(run, 10.0)
    feats = features(d["time"], d["speed"], d["acceleration"], d["effort"], rec)
    err = feature_errors(feats, ref)
    assert err["max_power_rel_error"] < 0.01 and err["max_effort_rel_error"] < 0.07
    assert err["cruise_speed_error_kmh"] < 1.0
    assert abs(feats["final_coast_duration"] - coast) <= 35
    assert abs(feats["final_brake_duration"] - brake) <= 20  # its start and its end each within one 10 s fix interval


@pytest.mark.parametrize("seed", [HOLDING, CYCLES, SLOW_CYCLES])
def test_features_from_gnss_fixes(seed):
    """GNSS every 10 s (4 m, 1 km/h) with a finite-difference effort and the true Davis
    coefficients (the UKF's filtered values do better): regimes 0.84-0.99, power within 1 %
    (measured 0.59, 0.30, 0.59 %)."""
    run, truth = twin(seed)
    d, rec = recognised(run, 10.0, {"seed": seed})
    acc = regime_accuracy(rec, truth, d["time"], run.time)
    assert acc >= {HOLDING: 0.98, CYCLES: 0.83, SLOW_CYCLES: 0.90}[seed]
    err = feature_errors(features(d["time"], d["speed"], d["acceleration"], d["effort"], rec),
                         feature_truth(run.style, TRAIN))
    assert err["max_power_rel_error"] < 0.015 and err["cruise_speed_error_kmh"] < 1.0


def test_the_truth_from_the_fmus_recorded_signals(fmu_dir):
    """What the experiment passes for the truth: the Jacobi run of the FMUs records, at t_k,
    the train's ``effort_specific`` with the command it holds over [t_k, t_k+1] (the driver's
    output read before its inputs were updated), so ``true_regimes(time, train.v,
    train.effort_specific)`` is the twins' truth. The recorded ``driver.regime`` is one step
    ahead: the recorder reads the driver after the master set its inputs of t_k, so it has
    already decided the command of the next step."""
    seed = CYCLES
    system = System(
        "train_run",
        [Component("train", fmu_dir / "TrainLongitudinal.fmu", {}),
         Component("driver", fmu_dir / "Driver.fmu", {"seed": seed})],
        [Connection("driver", "command", "train", "command"),
         Connection("train", "s", "driver", "s"), Connection("train", "v", "driver", "v"),
         Connection("train", "speed_limit", "driver", "speed_limit")],
        stop_time=3000.0, step_size=1.0, record=["train.v", "train.effort_specific", "driver.regime"])
    res = masters.run(system, "jacobi", progress=False)
    col = {c: res.data[:, j] for j, c in enumerate(res.columns)}
    t, v = col["time"], col["train.v"]
    truth = true_regimes(t, v, col["train.effort_specific"])
    run, twin_truth = twin(seed)
    n = t.size - 1  # the FMU run ends at the stop; the twin dwells there
    assert np.array_equal(v[:n], run.v[:n])
    assert np.array_equal(truth[:n - 1], twin_truth[:n - 1])
    assert np.array_equal(col["driver.regime"][:n - 1], run.regime[1:n])


def test_score_is_the_pieces_together():
    run, truth = twin(HOLDING)
    d, rec = recognised(run, 10.0, {"seed": HOLDING})
    metrics, feats = score(d["time"], d["speed"], d["acceleration"], d["effort"], run.time, run.v,
                           run.effort, run.style, TRAIN)
    assert metrics["regime_accuracy"] == regime_accuracy(rec, truth, d["time"], run.time)
    ref = feature_errors(features(d["time"], d["speed"], d["acceleration"], d["effort"], rec),
                         feature_truth(run.style, TRAIN))
    assert metrics == {"regime_accuracy": metrics["regime_accuracy"], **ref}
    assert feats["max_power"] == pytest.approx(feats["max_power_specific"] * GAMMA * (TARE_MASS + LOAD_MASS))


def test_power_from_pulls_that_go_on_and_cruise_speed_of_cycles():
    """The power's fixes are traction before and after (a pull's last fix may end in a coast:
    half its effort here); a cruise span that is at most a tenth cruising is traction/coast
    cycles, whose cruise speed is the span's median speed."""
    kmh = np.array([0, 20, 60, 80, 100, 120, 125, 122, 119, 123, 126, 121, 117, 118, 90, 40, 0])
    v = kmh * KMH
    r = np.array([STANDSTILL] + [TRACTION] * 5 + [TRACTION, COASTING, COASTING, TRACTION, TRACTION, COASTING,
                                                   COASTING, COASTING, BRAKING, BRAKING, BRAKING])
    t = 10.0 * np.arange(v.size)
    a = np.r_[0.0, np.diff(v) / 10.0]
    f = np.where(r == TRACTION, 0.3, np.where(r == BRAKING, -0.5, 0.0))
    f[6] = 0.15  # the pull's last fix before the first coast
    feats = features(t, v, a, f, r)
    vm = 0.5 * (v[1:] + v[:-1])
    # fixes 3-5 (mid 70, 90, 110 km/h): traction before and after; not fix 2 (mid 40 km/h), fix 6 (a
    # coast follows), fix 9 (a coast before) or fix 10 (a coast after)
    assert feats["max_power_specific"] == pytest.approx(np.mean([0.3 * vm[k - 1] for k in (3, 4, 5)]), rel=1e-14)
    assert feats["max_power_specific"] == pytest.approx(0.3 * 90 * KMH, rel=1e-14)
    # no cruising fix: the span from the first let-up at speed (fix 7) to the last pull (fix 10)
    assert feats["cruise_speed"] == pytest.approx(np.median(v[7:11]), rel=1e-14)
    r2 = r.copy()
    r2[8] = CRUISING  # one of four: more than a tenth, the cruising fixes decide
    assert features(t, v, a, f, r2)["cruise_speed"] == pytest.approx(v[8], rel=1e-14)
