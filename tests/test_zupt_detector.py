"""The zero-velocity detector (estimators/inertial/zupt_detector.py): its statistic against a direct
per-window sum, its rest distribution, a synthetic rest / motion record with a known answer,
the scores on hand-made masks, and the detector on a short navigation-grade survey run."""

from __future__ import annotations

import io
import math
import shutil

import fmpy
import numpy as np
import pandas as pd
import pytest

from railfmu.estimators.inertial.zupt_detector import (
    NAVIGATION_GRADE,
    detect_stationary,
    detector_scores,
    noise_floor,
    noise_sigmas,
    rest_threshold,
    shoe_statistic,
)
from railfmu.models import earth
from railfmu.models.inertial.imu_errors import GRADES

DT = 0.005
SA, SG = NAVIGATION_GRADE
G = float(earth.gravity(math.radians(30.5), 25.0))


def rest_increments(n: int, rng, sigma_a=SA, sigma_g=SG) -> np.ndarray:
    """IMU increments at rest, tilted and turned (C_b^n from roll 0.1, pitch -0.2, heading 1),
    at 30.5 deg N: gravity and the Earth rate in the body plus white noise of sigma_a, sigma_g
    per sample."""
    from railfmu.estimators.inertial.attitude import dcm_from_rph
    C = dcm_from_rph(0.1, -0.2, 1.0)
    f = C.T @ np.array([0.0, 0.0, -G])
    w = C.T @ earth.earth_rate_n(math.radians(30.5))
    return np.column_stack([(w + rng.normal(0, sigma_g, (n, 3))) * DT, (f + rng.normal(0, sigma_a, (n, 3))) * DT])


def test_statistic_equals_the_direct_window_sum():
    """T_k from cumulative sums equals (1/W) sum (|f_j - g u_f|^2 / sigma_a^2 + |w_j - Omega
    u_w|^2 / sigma_g^2) summed directly, u the window-mean directions; centred windows, the
    ends take the nearest whole window."""
    rng = np.random.default_rng(5)
    inc = rest_increments(300, rng)
    inc[150:] += rng.normal(0, 3e-3, (150, 6)) * DT   # some motion
    W = 20
    T = shoe_statistic(inc, DT, W, SA, SG, G)
    for k in (0, 5, 10, 11, 149, 150, 160, 289, 290, 299):
        a = min(max(k - W // 2, 0), 300 - W)
        f, w = inc[a:a + W, 3:] / DT, inc[a:a + W, :3] / DT
        uf = f.mean(0) / np.linalg.norm(f.mean(0))
        uw = w.mean(0) / np.linalg.norm(w.mean(0))
        direct = (((f - G * uf) ** 2).sum() / SA ** 2 + ((w - earth.RATE * uw) ** 2).sum() / SG ** 2) / W
        assert T[k] == pytest.approx(direct, rel=1e-9), k


def test_rest_statistic_is_the_chi_square_of_the_noise():
    """At rest with the grade's noise, W T is chi-square with 6 W - 4 (navigation grade: the
    Earth rate stands out of the window-mean noise) to 6 W - 2 degrees of freedom: its mean
    per sample is between the two, and no window of 2e5 exceeds the default threshold's
    1 - 1e-4 quantile by more than chance (measured: mean 5.80 for W = 50)."""
    rng = np.random.default_rng(7)
    inc = rest_increments(200_000, rng)
    W = 50
    T = shoe_statistic(inc, DT, W, SA, SG, G)
    assert (6 * W - 4) / W * 0.99 < T.mean() < (6 * W - 2) / W * 1.01, T.mean()
    gamma = rest_threshold(W)
    assert gamma == pytest.approx(7.949, abs=1e-3)
    assert (T > gamma).mean() < 1e-3
    # the plain statistic of Skog et al. (earth_rate 0) carries the Earth rate as 12.5 per sample
    T0 = shoe_statistic(inc, DT, W, SA, SG, G, earth_rate=0.0)
    assert T0.mean() - T.mean() == pytest.approx((earth.RATE / SG) ** 2, rel=0.02)


def test_synthetic_rest_motion_rest_known_answer():
    """5 s at rest, 10 s of motion (angular rate 2e-3 rad/s and specific force 0.05 m/s2
    oscillating at 1 Hz, at full amplitude from its first sample: a trolley on an irregular
    track), 5 s at rest; navigation-grade noise. The motion is far above the noise, so a sample
    is detected exactly when its whole window (W = 50, samples k - 25 to k + 24) lies at rest:
    misses are the 24 samples before the motion and the 25 after it, and nothing else (with the
    default threshold and gravity; the GLRT alone, without the speed-change rule, the trim and
    the margin)."""
    rng = np.random.default_rng(11)
    n = 4000
    inc = rest_increments(n, rng)
    moving = np.zeros(n, bool)
    moving[1000:3000] = True
    t = np.arange(n) * DT
    wave = np.cos(2 * np.pi * t[moving])[:, None] * DT
    inc[moving, :3] += 2e-3 * wave * np.array([0.0, 0.6, 0.8])
    inc[moving, 3:] += 0.05 * wave * np.array([1.0, 0.0, 0.0])
    det = detect_stationary(inc, DT, speed_change=None, trim=False, margin=0)  # the GLRT alone
    # the default wants a deceleration into a rest and an acceleration out of it: this motion
    # has no net speed change, so neither rest is one
    assert not detect_stationary(inc, DT).any()
    expected = np.zeros(n, bool)
    expected[:1000 - 24] = True
    expected[3000 + 25:] = True
    np.testing.assert_array_equal(det, expected)
    s = detector_scores(det, ~moving)
    assert (s["misses"], s["false_alarms"], s["missed_stops"], s["false_stops"]) == (49, 0, 0, 0)


def test_scores_of_hand_made_masks():
    stopped = np.array([1, 1, 1, 0, 0, 0, 0, 1, 1, 0, 0, 0, 1, 1, 0], bool)
    detected = np.array([1, 1, 0, 1, 0, 1, 0, 0, 0, 0, 0, 1, 1, 1, 1], bool)
    s = detector_scores(detected, stopped)
    assert s["samples_at_rest"] == 7 and s["samples_moving"] == 8
    assert s["misses"] == 3 and s["miss_fraction"] == 3 / 7          # samples 2, 7, 8
    assert s["false_alarms"] == 4 and s["false_alarm_fraction"] == 4 / 8  # samples 3, 5, 11, 14
    assert s["stops"] == 3 and s["missed_stops"] == 1                 # the stop at 7-8
    assert s["detected_runs"] == 4 and s["false_stops"] == 2          # the runs at 3 and at 5
    assert s["early_samples"] == 1 and s["late_samples"] == 1         # run 11-14 around the stop 12-13
    with pytest.raises(ValueError, match="same"):
        detector_scores(detected[:-1], stopped)


def test_noise_sigmas_of_the_grades():
    assert noise_sigmas(GRADES["navigation_grade"], DT) == pytest.approx(NAVIGATION_GRADE, rel=1e-15)
    sa, sg = noise_sigmas(GRADES["mems_grade"], DT)
    assert sa == pytest.approx(84.98e-6 * 9.80665 / math.sqrt(DT)) and sg == pytest.approx(
        0.3 * math.pi / 180 / 60 / math.sqrt(DT))
    with pytest.raises(ValueError, match="window"):
        detect_stationary(np.zeros((10, 6)), DT, window=20)


@pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64", reason="needs gcc on linux64")
def test_detector_on_a_short_navigation_grade_survey(tmp_path, fmu_dir):
    """90 s of ``trolley_survey --variant navigation_grade`` (10 s rest, the 60 m run on straight
    track, the stop at 60 m, the next start), defaults (W = 50, min_samples = 100, margin W)
    with the grade's noise: both stops found, no false stop, no sample in motion taken for rest;
    the misses are the margins (W samples off each end of a rest that is not the record's start
    or end, plus the trim; measured 139). On the whole 700 s run: 918 misses, 0 false alarms,
    no false stop (the GLRT alone: 0 misses, 87 false alarms within 9 samples of the stops)."""
    from railfmu.experiments.engine.runner import run_experiment
    out = tmp_path / "run"
    run_experiment("trolley_survey", "navigation_grade", out=out, stop_time=90.0, step_size=DT, master="container",
                   progress=False, log=io.StringIO())
    imu = pd.read_csv(out / "imu.csv").to_numpy()[1:, 1:]   # row 0: the initialisation point
    truth = pd.read_csv(out / "truth.csv")[1:]
    stopped = truth.stopped.to_numpy().astype(bool)
    det = detect_stationary(imu, DT, sigma_a=SA, sigma_g=SG)
    s = detector_scores(det, stopped)
    assert s["stops"] == 2 and s["missed_stops"] == 0 and s["false_stops"] == 0, s
    assert s["misses"] <= 200 and s["false_alarms"] == 0, s
    speed = np.hypot(truth.vn, truth.ve).to_numpy()
    assert speed[det & ~stopped].max(initial=0.0) < 1e-5


def stop_go_increments(rng, sigma_a, sigma_g, rest=10.0, ramp=4.0, cruise=40.0, speed=1.0):
    """A trolley on straight, level, smooth track: rest, a sin^2 speed ramp to ``speed``,
    steady cruising (no acceleration, no rotation: to an IMU the same as rest), a ramp down,
    rest; body level, heading 0, 30.5 deg N, white noise of sigma_a, sigma_g per sample.
    Returns (increments (n, 6), stopped (n,))."""
    t_ramp = np.arange(0.0, ramp, DT)
    a = speed * 2.0 / ramp * np.sin(np.pi * t_ramp / ramp) ** 2
    fx = np.concatenate([np.zeros(int(rest / DT)), a, np.zeros(int(cruise / DT)), -a, np.zeros(int(rest / DT))])
    n = fx.size
    stopped = np.zeros(n, bool)
    stopped[:int(rest / DT)] = True
    stopped[n - int(rest / DT):] = True
    w = earth.earth_rate_n(math.radians(30.5))
    f = np.column_stack([fx, np.zeros(n), np.full(n, -G)])
    inc = np.column_stack([(w + rng.normal(0, sigma_g, (n, 3))) * DT, (f + rng.normal(0, sigma_a, (n, 3))) * DT])
    return inc, stopped


@pytest.mark.parametrize("grade", ["navigation_grade", "tactical_grade", "mems_grade"])
def test_steady_cruise_on_straight_smooth_track_is_not_rest(grade):
    """Cruising at 1 m/s on straight, smooth track is rest to the GLRT (the 40 s of cruise go
    for rest: false stops); the default's speed-change rule rejects it and keeps both rests
    (the stop after a deceleration, the start before an acceleration), and the trim keeps the
    stops' growth into the ramps within 0.4 s (80 samples, the MEMS grade: measured 42 and 59;
    the ramp's speed after 0.4 s is 6 mm/s; without the trim about 100)."""
    sa, sg = noise_sigmas(GRADES[grade], DT)
    inc, stopped = stop_go_increments(np.random.default_rng(3), sa, sg)
    glrt = detector_scores(detect_stationary(inc, DT, sigma_a=sa, sigma_g=sg, speed_change=None, trim=False), stopped)
    assert glrt["false_stops"] >= 1 and glrt["false_alarms"] > 7000, glrt
    s = detector_scores(detect_stationary(inc, DT, sigma_a=sa, sigma_g=sg), stopped)
    assert s["missed_stops"] == 0 and s["false_stops"] == 0, s
    assert s["early_samples"] <= 80 and s["late_samples"] <= 80, s
    assert s["misses"] <= 100, s


def test_noise_floor_is_the_records_own_noise():
    """The record's noise floor (a low quantile of the window scatter, de-biased) is its
    white noise to 5 % on a record that is half motion, and the detector's sigmas follow it
    when the given ones are lower: a record 3 times noisier than the navigation grade still
    has both rests found (with the grade's sigmas alone every window would be motion)."""
    sa, sg = noise_sigmas(GRADES["navigation_grade"], DT)
    inc, stopped = stop_go_increments(np.random.default_rng(4), 3 * sa, 3 * sg)
    fa, fg = noise_floor(inc, DT)
    assert fa == pytest.approx(3 * sa, rel=0.05) and fg == pytest.approx(3 * sg, rel=0.05)
    s = detector_scores(detect_stationary(inc, DT, sigma_a=sa, sigma_g=sg), stopped)
    assert s["missed_stops"] == 0 and s["false_stops"] == 0 and s["misses"] <= 100, s
    off = detector_scores(detect_stationary(inc, DT, sigma_a=sa, sigma_g=sg, noise_from_data=False), stopped)
    assert off["missed_stops"] == 2, off
