"""ImuErrors FMU (models/inertial/imu_errors.py, fmus/native/models/ImuErrors.c): the C equals its Python
twin bit for bit, the ideal IMU passes its input through bit for bit, the Gauss-Markov
discretisation equals Van Loan's at 50 digits for any step, the Allan deviation of each grade
at rest reads back its datasheet numbers, the deterministic errors follow their closed forms,
the noise does not depend on how the master computes its time, and a bad grade is one line.

Measured when written (FMU, seed 1, axes x / y / z; the random walk N from the IEEE 952 fit at
tau = 1 s, the bias instability B = floor / 0.664 at tau_p = 1.89 Tc, in datasheet units;
over seeds 1-8 every axis of every grade stayed within 5 % of its parameter, so the +-10 %
bounds are not a lucky seed):

================  ========================  ========================  =======================  ======================
grade             gyro N (°/√h)             gyro B (°/h)              accel N (µg/√Hz)         accel B (µg)
================  ========================  ========================  =======================  ======================
navigation_grade  0.00493 0.00506 0.00505   0.01003 0.01024 0.00978   9.88 9.96 10.07          49.8 51.5 49.1
tactical_grade    0.1234 0.1266 0.1262      0.999 1.015 0.980         33.20 33.63 33.79        996 1030 983
mems_grade        0.2961 0.3038 0.3028      5.99 6.08 5.88            83.97 84.69 85.55        19.9 20.5 19.7
================  ========================  ========================  =======================  ======================

The tactical accelerometer's raw Allan deviation at 1 s is 36.1 / 37.1 / 37.2 µg (+9 %): its
1 mg bias instability already adds a rate-random-walk part there, which the fit separates.
The C equals the twin with tolerance 0 (glibc's log, cos, expm1, sqrt in both).
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from pathlib import Path

import allantools
import mpmath as mp
import numpy as np
import pytest
from lxml import etree

from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.fmus.ssp.params import read_parameter_set
from railfmu.fmus.ssp.units import Units
from railfmu.models.inertial.imu_errors import (
    ACCEL_SI,
    FLICKER_FLOOR,
    GM_ALLAN_PEAK,
    GM_ALLAN_PEAK_X,
    GM_SIGMA_PER_B,
    GRADES,
    GYRO_BIAS_SI,
    GYRO_NOISE_SI,
    IMU_ERRORS,
    STREAM_CONST,
    ImuErrorsTwin,
    allan_variance_gm,
    gauss,
    gm_f,
    gm_step,
    sample_index,
)
from railfmu.models.sources.sensors import noise

ROOT = Path(__file__).resolve().parents[1]
PARAMETERS = ROOT / "experiments" / "trolley_survey" / "parameters"
INPUTS = [f"dtheta_in_{a}" for a in "xyz"] + [f"dv_in_{a}" for a in "xyz"]
MEASURED = [f"dtheta_{a}" for a in "xyz"] + [f"dv_{a}" for a in "xyz"]
OUTPUTS = [v.name for v in IMU_ERRORS.outputs]
#: every error source on, drawn and fixed: turn-on biases, scale factors, misalignments
ALL_ERRORS = {**GRADES["mems_grade"], "seed": 11, "gyro_turn_on_bias_sigma_deg_h": 20.0,
              "gyro_turn_on_bias_y_deg_h": -3.0, "gyro_misalignment_sigma_urad": 500.0,
              "gyro_misalignment_zx_urad": 120.0, "accel_turn_on_bias_sigma_ug": 800.0,
              "accel_scale_factor_z_ppm": 250.0, "accel_misalignment_sigma_urad": 300.0,
              "accel_misalignment_xy_urad": -70.0, "gyro_bias_correlation_time": 40.0}


def _fmu_run(fmu: Path, params: dict, t, h, u, outputs=OUTPUTS, state_at: int | None = None):
    """Outputs (n, len(outputs)) of the FMU at the points ``t`` (t[0] the start) reached by
    steps ``h`` for the inputs ``u`` (n, 6) set at each point before it is read. ``state_at``:
    the FMU state saved at that point is restored after the run, and the rest run again must
    give the same outputs (asserted here)."""
    with Slave(fmu, "imu") as s:
        s.initialize(float(t[0]), None, params)
        vi = [s.vars[v].valueReference for v in INPUTS]
        real = [v for v in outputs if s.vars[v].type == "Real"]
        ints = [v for v in outputs if s.vars[v].type == "Integer"]
        vr = [s.vars[v].valueReference for v in real]
        vint = [s.vars[v].valueReference for v in ints]
        order = [(real + ints).index(v) for v in outputs]

        def run(m0: int) -> np.ndarray:
            y = np.empty((len(t) - m0, len(outputs)))
            for m in range(m0, len(t)):
                s.fmu.setReal(vi, list(u[m]))
                row = list(s.fmu.getReal(vr)) + (list(s.fmu.getInteger(vint)) if vint else [])
                y[m - m0] = [row[k] for k in order]
                if m == state_at and saved == []:
                    saved.append(s.fmu.getFMUstate())
                if m + 1 < len(t):
                    s.do_step(float(t[m]), h)
            return y

        saved: list = []
        y = run(0)
        if state_at is not None:
            s.fmu.setFMUstate(saved[0])
            s.fmu.freeFMUstate(saved[0])
            assert np.array_equal(run(state_at), y[state_at:])
        return y


def _twin_matrix(out: dict, outputs=OUTPUTS) -> np.ndarray:
    return np.column_stack([np.asarray(out[o], dtype=float) for o in outputs])


# ---- the twin: C equals Python ------------------------------------------------------------------

@pytest.mark.parametrize("h", [5e-3, 0.25])
def test_c_equals_the_twin_bit_for_bit_and_a_restored_state_replays(fmu_dir, h):
    """Every output, every point, all error sources on: the same doubles (log, cos, expm1 and
    sqrt are glibc's in both). Half-way the FMU state is saved, the run continued, the state
    restored and the second half run again: the memory (Gauss-Markov states, sample) replays."""
    n = 1500
    rng = np.random.default_rng(4)
    u = np.hstack([rng.normal(0, 1e-3, (n + 1, 3)), rng.normal(0, 5e-2, (n + 1, 3))])
    t = np.arange(n + 1) * h
    y = _fmu_run(fmu_dir / "ImuErrors.fmu", ALL_ERRORS, t, h, u, state_at=n // 2)
    twin = _twin_matrix(ImuErrorsTwin(ALL_ERRORS).run(t, h, u[:, :3], u[:, 3:]))
    assert np.array_equal(y, twin)
    assert np.all(y[:, :6] != u)  # every error source shows


def test_ideal_imu_passes_the_input_through_bit_for_bit(fmu_dir):
    """The ideal grade (and the FMU's defaults): y is u, bit for bit, signed zeros and
    subnormals included; the biases are 0."""
    ideal = {k: v for k, v in _read_ssv(PARAMETERS / "imu_ideal.ssv").items()}
    n = 400
    rng = np.random.default_rng(2)
    u = rng.normal(0, 1e-2, (n + 1, 6)) * 10.0 ** rng.integers(-300, 3, (n + 1, 6))
    u[::7, 1] = -0.0
    u[3::11, 4] = 5e-324
    t = np.arange(n + 1) * 5e-3
    for params in (ideal, {}):
        y = _fmu_run(fmu_dir / "ImuErrors.fmu", params, t, 5e-3, u, MEASURED + ["gyro_bias_x", "accel_bias_z"])
        assert np.array_equal(y[:, :6].view(np.int64), u.view(np.int64))
        assert not np.any(y[:, 6:])
    out = ImuErrorsTwin(ideal).run(t, 5e-3, u[:, :3], u[:, 3:])
    assert np.array_equal(_twin_matrix(out, MEASURED).view(np.int64), u.view(np.int64))


def test_counter_based_noise_is_the_sensor_noise_of_models_sensors():
    """gauss() is railfmu.models.sources.sensors.noise for any stream number (the same SplitMix64 streams)."""
    k = np.arange(0, 5000, 7)
    for ch in (1, 5, 8):
        assert np.array_equal(gauss(13, ch, k), noise(13, ch, k))


# ---- the grades ------------------------------------------------------------------------------

def _read_ssv(path: Path) -> dict:
    root = etree.parse(str(path)).getroot()
    return {v.name: v.value for v in read_parameter_set(root, path.name, Units())}


@pytest.mark.parametrize("name", list(GRADES))
def test_grade_ssv_equals_the_grade_table(name):
    """Each .ssv sets every Real parameter of the model (a grade swaps the whole IMU), with the
    values of GRADES; no seed (the run's)."""
    ssv = _read_ssv(PARAMETERS / f"imu_{name}.ssv")
    real = {p.name for p in IMU_ERRORS.parameters if p.type == "Real"}
    assert set(ssv) == real and ssv == GRADES[name]
    IMU_ERRORS.check_parameters(ssv)


def test_grades_are_the_cited_datasheet_numbers():
    nav, tac, mems = GRADES["navigation_grade"], GRADES["tactical_grade"], GRADES["mems_grade"]
    # Jiang et al. (2017), §3
    assert (nav["gyro_bias_instability_deg_h"], nav["gyro_arw_deg_sqrt_h"]) == (0.01, 0.005)
    assert (nav["accel_bias_instability_ug"], nav["accel_noise_ug_sqrt_hz"]) == (50.0, 10.0)
    # HG1700: 0.065 ft/s/√h; OpenIMU300ZA: 0.05 m/s/√h, as µg/√Hz (N in µg·√s)
    assert tac["accel_noise_ug_sqrt_hz"] == pytest.approx(0.065 * 0.3048 / 60 / 9.80665e-6, abs=0.005)
    assert mems["accel_noise_ug_sqrt_hz"] == pytest.approx(0.05 / 60 / 9.80665e-6, abs=0.005)
    assert (tac["gyro_bias_instability_deg_h"], tac["gyro_arw_deg_sqrt_h"]) == (1.0, 0.125)
    assert (mems["gyro_bias_instability_deg_h"], mems["gyro_arw_deg_sqrt_h"]) == (6.0, 0.3)


# ---- the Gauss-Markov discretisation ---------------------------------------------------------

def _van_loan(x: float):
    """(Phi, Qd) of the augmented system [b, int b] over h = x with sigma = Tc = 1 (so q^2 = 2),
    by Van Loan's matrix exponential in 50-digit arithmetic."""
    mp.mp.dps = 50
    F = mp.matrix([[-1, 0], [1, 0]])
    GQG = mp.matrix([[2, 0], [0, 0]])
    M = mp.zeros(4, 4)
    for i in range(2):
        for j in range(2):
            M[i, j] = -F[i, j] * x
            M[i, j + 2] = GQG[i, j] * x
            M[i + 2, j + 2] = F[j, i] * x
    E = mp.expm(M)
    Phi = E[2:4, 2:4].T
    Qd = Phi * E[0:2, 2:4]
    return Phi, Qd


@pytest.mark.parametrize("x", [1e-7, 1.4e-6, 1e-4, 0.01, 0.3, 0.4999999, 0.5, 0.7, 2.0, 20.0])
def test_gauss_markov_step_equals_van_loan(x):
    """The exact discretisation for any h / Tc: means (beta, Tc (1 - beta)) and the joint
    covariance of the state innovation and the integral, against Van Loan's method; the
    series and closed branches of f(x) agree at the switch."""
    Phi, Qd = _van_loan(x)
    beta, a, s_eta, gain, s_zeta = gm_step(x, 1.0, 1.0)
    assert beta == pytest.approx(float(Phi[0, 0]), rel=1e-15) and a == pytest.approx(float(Phi[1, 0]), rel=1e-15)
    assert s_eta**2 == pytest.approx(float(Qd[0, 0]), rel=1e-14)
    assert gain * s_eta**2 == pytest.approx(float(Qd[0, 1]), rel=1e-14)
    assert gain**2 * s_eta**2 + s_zeta**2 == pytest.approx(float(Qd[1, 1]), rel=1e-13)
    # units: sigma_b scales the covariances, Tc the time
    b2 = gm_step(x * 30.0, 30.0, 2.5)
    assert b2[2] == pytest.approx(2.5 * s_eta, rel=1e-14) and b2[4] == pytest.approx(2.5 * 30.0 * s_zeta, rel=1e-13)
    mp.mp.dps = 50
    exact = x - 2 * (1 - mp.e ** (-mp.mpf(x))) + (1 - mp.e ** (-2 * mp.mpf(x))) / 2
    assert gm_f(x) == pytest.approx(float(exact), rel=2e-15)


def test_allan_constants():
    """sqrt(2 ln 2 / pi) (IEEE 952 flicker floor) and the peak of the GM Allan deviation."""
    from scipy.optimize import minimize_scalar

    assert FLICKER_FLOOR == pytest.approx(math.sqrt(2 * math.log(2) / math.pi), rel=1e-13)
    res = minimize_scalar(lambda x: -allan_variance_gm(x, 1.0, 1.0), bounds=(0.5, 5), method="bounded",
                          options={"xatol": 1e-10})
    assert res.x == pytest.approx(GM_ALLAN_PEAK_X, rel=1e-6)
    assert math.sqrt(-res.fun) == pytest.approx(GM_ALLAN_PEAK, rel=1e-12)
    assert GM_SIGMA_PER_B == pytest.approx(FLICKER_FLOOR / GM_ALLAN_PEAK, rel=1e-15)


# ---- Allan deviation of each grade at rest ------------------------------------------------------

def _rates_at_rest(fmu_dir, params, h, n) -> np.ndarray:
    """(n, 6) measured rates (increment / h) of n steps of h at rest (ideal input zero)."""
    t = np.arange(n + 1) * h
    y = _fmu_run(fmu_dir / "ImuErrors.fmu", params, t, h, np.zeros((n + 1, 6)), MEASURED)
    return y[1:] / h


@pytest.mark.parametrize("grade", ["navigation_grade", "tactical_grade", "mems_grade"])
def test_allan_deviation_reads_back_the_grade(fmu_dir, grade):
    """At rest, per axis: the random walk N from the IEEE 952 least-squares fit
    sigma^2(tau) = N^2 / tau + K^2 tau / 3 over tau = 0.1..10 s (K: the GM's rate-random-walk
    slope below Tc), read at tau = 1 s; and the bias instability B = floor / 0.664 with the floor
    the Allan deviation at the GM's peak tau_p = 1.89 Tc less the white part N^2 / tau_p. Both
    within 10 % of the parameters. 2000 s at 20 Hz for N; 1000 tau_p in steps of tau_p / 8 for
    the floor (the discretisation is exact for any step, so a long step changes nothing but the
    cost). The tactical grade's 1 mg bias instability puts 9 % of the raw Allan deviation at
    1 s into the GM part: the fit separates it."""
    g = {**GRADES[grade], "seed": 1}
    h1 = 0.05
    short = _rates_at_rest(fmu_dir, g, h1, 40000)
    tc = g["gyro_bias_correlation_time"]
    assert g["accel_bias_correlation_time"] == tc
    taup = GM_ALLAN_PEAK_X * tc
    long = _rates_at_rest(fmu_dir, g, taup / 8, 8000)
    taus = np.array([0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0])
    for col in range(6):
        sensor = "gyro" if col < 3 else "accel"
        n_par = g["gyro_arw_deg_sqrt_h"] * GYRO_NOISE_SI if sensor == "gyro" else g["accel_noise_ug_sqrt_hz"] * ACCEL_SI
        b_par = (g["gyro_bias_instability_deg_h"] * GYRO_BIAS_SI if sensor == "gyro"
                 else g["accel_bias_instability_ug"] * ACCEL_SI)
        tt, dev, _, _ = allantools.oadev(short[:, col], rate=1 / h1, data_type="freq", taus=taus)
        assert np.allclose(tt, taus)
        # relative least squares, linear in (N^2, K^2 / 3)
        A = np.column_stack([1 / tt, tt]) / dev[:, None] ** 2
        n2, _ = np.linalg.lstsq(A, np.ones(len(tt)), rcond=None)[0]
        n_fit = math.sqrt(n2)
        assert n_fit == pytest.approx(n_par, rel=0.10), (grade, col, n_fit / n_par)
        _, dp, _, _ = allantools.oadev(long[:, col], rate=8 / taup, data_type="freq", taus=[taup])
        b_meas = math.sqrt(dp[0] ** 2 - n_fit**2 / taup) / FLICKER_FLOOR
        assert b_meas == pytest.approx(b_par, rel=0.10), (grade, col, b_meas / b_par)


def test_increments_integrate_the_reported_bias_state(fmu_dir):
    """Bias instability alone, at rest: each increment is the integral of the GM bias whose
    values at both ends the FMU reports, so y - h (b_before + b) / 2 is the trapezoid's error,
    a Brownian-bridge term of standard deviation q h^1.5 / sqrt(12) (q^2 = 2 sigma_b^2 / Tc,
    h << Tc); its mean is 0."""
    p = {**GRADES["ideal"], "gyro_bias_instability_deg_h": 6.0, "gyro_bias_correlation_time": 40.0,
         "accel_bias_instability_ug": 50.0, "accel_bias_correlation_time": 10.0, "seed": 3}
    h, n = 0.1, 4000
    names = MEASURED + [f"{s}_in_run_bias{b}_{a}" for s in ("gyro", "accel") for b in ("_before", "")
                        for a in "xyz"]
    y = _fmu_run(fmu_dir / "ImuErrors.fmu", p, np.arange(n + 1) * h, h, np.zeros((n + 1, 6)), names)[1:]
    for s, (sensor, bi, tc) in enumerate((("gyro", 6.0 * GYRO_BIAS_SI, 40.0), ("accel", 50.0 * ACCEL_SI, 10.0))):
        q = GM_SIGMA_PER_B * bi * math.sqrt(2 / tc)
        before, after = y[:, 6 + 6 * s:9 + 6 * s], y[:, 9 + 6 * s:12 + 6 * s]
        assert np.array_equal(before[1:], after[:-1])  # the memory hands the state on
        r = y[:, 3 * s:3 * s + 3] - h * (before + after) / 2
        sd = q * h**1.5 / math.sqrt(12)
        assert np.all(np.abs(r.std(axis=0) / sd - 1) < 0.08), r.std(axis=0) / sd
        assert np.all(np.abs(r.mean(axis=0)) < 4 * sd / math.sqrt(n))
        assert np.all(np.abs(after).max(axis=0) > 2 * GM_SIGMA_PER_B * bi)  # the bias did wander


# ---- deterministic errors: closed forms ------------------------------------------------------

def test_turn_on_bias_scale_factor_misalignment_closed_form(fmu_dir):
    """On a constant input without noise: y = (I + S + M) u + b_on h with S, M and b_on from the
    datasheet units by hand; drawn values are fixed + sigma w(seed, 4144 + axis, k) with k = 1
    (bias), 2 (scale), 3..5 (misalignment towards x, y, z)."""
    p = {**GRADES["ideal"], "seed": 21,
         "gyro_turn_on_bias_x_deg_h": 10.0, "gyro_turn_on_bias_sigma_deg_h": 4.0,
         "gyro_scale_factor_y_ppm": 300.0, "gyro_scale_factor_sigma_ppm": 50.0,
         "gyro_misalignment_xz_urad": 200.0, "gyro_misalignment_yx_urad": -150.0,
         "gyro_misalignment_sigma_urad": 30.0,
         "accel_turn_on_bias_z_ug": -500.0, "accel_turn_on_bias_sigma_ug": 100.0,
         "accel_scale_factor_x_ppm": -1000.0, "accel_misalignment_zy_urad": 400.0,
         "accel_misalignment_sigma_urad": 10.0, "accel_scale_factor_sigma_ppm": 20.0}
    h, n = 0.01, 50
    u = np.array([0.01, -0.02, 0.03, 0.05, -0.098, 9.81 * h])
    y = _fmu_run(fmu_dir / "ImuErrors.fmu", p, np.arange(n + 1) * h, h, np.tile(u, (n + 1, 1)),
                 MEASURED + [f"gyro_bias_{a}" for a in "xyz"] + [f"accel_bias_{a}" for a in "xyz"])
    deg_h = math.pi / 180 / 3600
    ug = 9.80665e-6
    for s, (sensor, unit) in enumerate((("gyro", deg_h), ("accel", ug))):
        bu = "deg_h" if sensor == "gyro" else "ug"
        IM = np.eye(3)
        b_on = np.zeros(3)
        for i, ax in enumerate("xyz"):
            w = gauss(21, STREAM_CONST + 3 * s + i + 1, np.arange(6))
            b_on[i] = (p.get(f"{sensor}_turn_on_bias_{ax}_{bu}", 0.0) + p[f"{sensor}_turn_on_bias_sigma_{bu}"] * w[1]) * unit
            IM[i, i] += (p.get(f"{sensor}_scale_factor_{ax}_ppm", 0.0) + p[f"{sensor}_scale_factor_sigma_ppm"] * w[2]) * 1e-6
            for j, bx in enumerate("xyz"):
                if j != i:
                    IM[i, j] = (p.get(f"{sensor}_misalignment_{ax}{bx}_urad", 0.0) +
                                p[f"{sensor}_misalignment_sigma_urad"] * w[3 + j]) * 1e-6
        us = u[3 * s:3 * s + 3]
        expected = IM @ us + b_on * h
        assert np.allclose(y[1:, 3 * s:3 * s + 3], expected, rtol=1e-14, atol=1e-18)
        assert np.allclose(y[0, 3 * s:3 * s + 3], IM @ us, rtol=1e-14, atol=1e-18)  # t0: no step, no bias
        assert np.allclose(y[:, 6 + 3 * s:9 + 3 * s], b_on, rtol=1e-15, atol=0)
    # the drawn constants are N(fixed, sigma): over 1000 seeds (std within 8 %: 3.6 sigma)
    draws = np.array([ImuErrorsTwin({**p, "seed": k}).constants[1]["turn_on"] for k in range(1000)]) / deg_h
    assert draws.mean() == pytest.approx(10.0, abs=4 * 4.0 / math.sqrt(1000))
    assert draws.std() == pytest.approx(4.0, rel=0.08)


# ---- time robustness -------------------------------------------------------------------------

def test_same_noise_whether_the_master_computes_n_h_or_accumulates(fmu_dir):
    """t = n h and t += h (float accumulation, as OMSimulator and FMPy's container) give the same
    sample index k = n (checked to 2e6 steps of 5 ms and 1 ms, 2.8 h at 200 Hz), so the FMU's outputs at a given point
    are the same doubles."""
    for h in (5e-3, 1e-3):
        n = 2_000_000
        acc = np.cumsum(np.full(n, h))  # sequential sums: t += h
        assert np.array_equal(sample_index(acc, 0.0, h), np.arange(1, n + 1))
        assert np.array_equal(sample_index(np.arange(1, n + 1) * h, 0.0, h), np.arange(1, n + 1))
    h, n = 5e-3, 4000
    acc = np.concatenate([[0.0], np.cumsum(np.full(n, h))])
    grid = np.arange(n + 1) * h
    assert np.any(acc != grid)
    u = np.tile([1e-4, 0, 0, 0, 0, -9.8 * h], (n + 1, 1))
    a = _fmu_run(fmu_dir / "ImuErrors.fmu", ALL_ERRORS, acc, h, u)
    b = _fmu_run(fmu_dir / "ImuErrors.fmu", ALL_ERRORS, grid, h, u)
    assert np.array_equal(a[:, :-1], b[:, :-1])  # all but sample_time (the master's t)


def test_a_growing_step_is_refused(fmu_dir):
    with Slave(fmu_dir / "ImuErrors.fmu", "imu") as s:
        s.initialize(0.0, None, ALL_ERRORS)
        for m in range(10):
            s.do_step(m * 0.01, 0.01)
        with pytest.raises(FMUError, match="step grew to 0.1 s at t = 0.2.*would repeat"):
            s.do_step(0.1, 0.1)


# ---- bad input ---------------------------------------------------------------------------------

IMU_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    version="1.0" name="imu_only">
  <ssd:System name="imu_only">
    <ssd:Elements>
      <ssd:Component name="imu" source="ImuErrors.fmu"/>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.1"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("setting, message", [
    ("imu.gyro_arw_deg_sqrt_h=-0.005", "-0.005 is out of range for variable 'gyro_arw_deg_sqrt_h' (must be >= 0)"),
    ("imu.accel_noise_ug_sqrt_hz=-10", "-10.0 is out of range for variable 'accel_noise_ug_sqrt_hz' (must be >= 0)"),
    ("imu.accel_bias_correlation_time=0", "accel_bias_correlation_time = 0 must be > 0"),
])
def test_a_negative_noise_density_is_one_line_and_exit_2(fmu_dir, tmp_path, setting, message):
    exp = tmp_path / "imu_only"
    exp.mkdir()
    shutil.copy(fmu_dir / "ImuErrors.fmu", exp)
    (exp / "SystemStructure.ssd").write_text(IMU_SSD)
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", str(exp), "--set", setting,
                          "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert res.returncode == 2, res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("railfmu: error:")]
    assert len(errors) == 1 and message in errors[0] and "Traceback" not in res.stderr, res.stderr
    name, value = setting.removeprefix("imu.").split("=")
    with pytest.raises(ValueError, match=name):
        ImuErrorsTwin({name: float(value)})


# ---- an independent importer --------------------------------------------------------------------

def test_libcosim_gives_the_twins_numbers(fmu_dir):
    """libcosim (the OSP engine, through libcosimpy) steps the FMU at its integer-nanosecond
    times t_k = k h_ns / 1e9 with steps t_k+1 - t_k that differ from 1 ms by an ulp now and
    then; the twin fed the same times gives the same doubles: the exact discretisation uses
    the step actually taken and the sample index is the step number."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed")
    from test_libcosim import STEP_NS, LibcosimRun

    n = 1000
    params = {**ALL_ERRORS, "seed": 5}
    lib = LibcosimRun()
    lib.add("imu", fmu_dir / "ImuErrors.fmu", {k: v for k, v in params.items()})
    for v in MEASURED:
        lib.observe("imu", v)
    lib.run(n)
    t = np.array([(k * STEP_NS) / 1e9 for k in range(n + 1)])
    h = np.concatenate([[0.0], np.diff(t)])
    assert len(set(h[1:])) > 1  # the steps are not all the same double
    twin = ImuErrorsTwin(params).run(t, h, np.zeros((n + 1, 3)), np.zeros((n + 1, 3)))
    for v in MEASURED:
        assert np.array_equal(lib.samples("imu", v, n), twin[v]), v
