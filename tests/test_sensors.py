"""Sensor noise (models/sources/sensors.py, fmus/native/models/SensorNoise.c): the measurement equation, the
statistics of the counter-based noise, its independence from how an importer steps, and the
FMU's hand-written C equal to the Python twin bit for bit.

Measured when written: the FMU equals :func:`railfmu.models.sources.sensors.noise` exactly (tolerance 0) on
10000 samples of all eight channels; numpy's own log differs from libm's in the last bit for
~0.4 % of arguments, which is why the twin calls ``math.log``/``math.cos``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import simulate_fmu
from scipy import stats

from railfmu.fmus.cosim.masters import run
from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.fmus.ssp import read_system
from railfmu.fmus.cosim.system import Component, Connection, System
from railfmu.models.sources.sensors import (
    GAMMA,
    N_CHANNELS,
    MUNOZ_SENSORS,
    ONAT2016_SENSORS,
    SENSORS,
    SensorNoise,
    channel_state,
    noise,
    sample_index,
    uniforms,
)
from railfmu.models.track.irregularity import SplitMix64

CH = range(1, N_CHANNELS + 1)
U = [f"u_{i}" for i in CH]
Y = [f"y_{i}" for i in CH]
SIGMAS = {f"sigma_{i}": 0.5 * i for i in CH}


@pytest.fixture(scope="module")
def sensors_fmu(fmu_dir):
    return fmu_dir / "SensorNoise.fmu"


def _vrs(s: Slave, names):
    return [s.vars[n].valueReference for n in names]


def _drive(s: Slave, t, u=None):
    """Outputs at every time in ``t`` (steps t[n] -> t[n+1]); ``u`` (len(t), 8) is set at
    t[n] before the outputs there are read."""
    yv, uv = _vrs(s, Y), _vrs(s, U)
    out = np.empty((len(t), N_CHANNELS))
    for n, tn in enumerate(t):
        if u is not None:
            s.fmu.setReal(uv, list(u[n]))
        out[n] = s.fmu.getReal(yv)
        if n + 1 < len(t):
            s.do_step(tn, t[n + 1] - tn)
    return out


def _noise_run(fmu, params, stop=20.0, step=1e-3):
    res = simulate_fmu(str(fmu), start_values=params, stop_time=stop, output_interval=step, step_size=step,
                       output=Y)
    return res["time"], np.array([res[y] for y in Y])


# ---- the Python twin: an independent transcription of the algorithm --------------------------

def test_noise_is_splitmix64_streams_and_box_muller():
    """c_i is output i of SplitMix64(seed); sample k reads outputs 2k+1, 2k+2 of SplitMix64(c_i)
    (railfmu.models.track.irregularity.SplitMix64, itself tested against Vigna's reference), then Box-Muller."""
    for seed in (0, 1, 12345, -5):
        r = SplitMix64(seed)
        for i in CH:
            assert channel_state(seed, i) == r.next()
        stream = SplitMix64(channel_state(seed, 3))
        z = [stream.next() for _ in range(2 * 50)]
        ref = [math.sqrt(-2.0 * math.log(((z[2 * k] >> 11) + 1) * 2.0**-53))
               * math.cos(2.0 * math.pi * ((z[2 * k + 1] >> 11) * 2.0**-53)) for k in range(50)]
        assert noise(seed, 3, np.arange(50)).tolist() == ref
    # position k is reached directly (counter-based), also far out
    k = 10**12
    c = channel_state(7, 2)
    z1 = SplitMix64((c + 2 * k * GAMMA) & (2**64 - 1)).next()
    assert uniforms(7, 2, [k])[0][0] == ((z1 >> 11) + 1) * 2.0**-53
    # numpy's SIMD log/cos: the same to the last bit or two
    k = np.arange(10000)
    np.testing.assert_allclose(noise(4, 1, k, exact=False), noise(4, 1, k), rtol=1e-15, atol=1e-15)


def test_uniforms_range_and_bad_arguments():
    u1, u2 = uniforms(3, 8, np.arange(100000))
    assert u1.min() > 0 and u1.max() <= 1 and u2.min() >= 0 and u2.max() < 1
    with pytest.raises(ValueError, match="channel"):
        noise(1, 9, [0])
    with pytest.raises(ValueError, match="non-negative"):
        noise(1, 1, [-1])
    with pytest.raises(ValueError, match="sigma_2"):
        SensorNoise({"sigma_2": -1.0})
    with pytest.raises(ValueError, match="sample_period"):
        SensorNoise({"sample_period": 0.0})


def test_sample_index_on_a_floating_point_grid():
    t = np.arange(20001) * 1e-3  # 173 of these fall just below their sample: 2001 * 1e-3 / 1e-3 < 2001
    assert np.count_nonzero(np.floor(t / 1e-3) != np.arange(20001)) == 173
    np.testing.assert_array_equal(sample_index(t, 0.0, 1e-3, 1e-3), np.arange(20001))
    np.testing.assert_array_equal(sample_index(np.cumsum(np.full(1000, 1e-3)), 0.0, 1e-3, 1e-3), np.arange(1, 1001))
    np.testing.assert_array_equal(sample_index(5.0 + np.arange(8) * 0.25e-3, 5.0, 1e-3, 0.25e-3),
                                  [0, 0, 0, 0, 1, 1, 1, 1])
    # the band: a sample instant less than 1 % of min(h, T) ahead is reached
    T = 1e-3
    assert sample_index(T - 0.009 * T, 0.0, T, T) == 1 and sample_index(T - 0.011 * T, 0.0, T, T) == 0
    assert sample_index(T - 0.0009 * T, 0.0, T, 0.1 * T) == 1  # h < T: 1 % of h
    assert sample_index(T - 0.0011 * T, 0.0, T, 0.1 * T) == 0
    assert sample_index(10 * T - 0.011 * T, 0.0, T, 10 * T) == 9  # h > T: 1 % of T, not of h
    assert sample_index(0.0, 0.0, T, 0.0) == 0  # initialisation mode


# ---- the FMU ---------------------------------------------------------------------------------

def test_fmu_equals_python_bit_for_bit(sensors_fmu):
    """10000 samples of all channels with gains, biases, a negative seed and inputs that change
    every step: exact equality of doubles."""
    params = {**SIGMAS, **{f"gain_{i}": 1 + 0.01 * i for i in CH}, **{f"bias_{i}": -0.1 * i for i in CH},
              "seed": -12345, "sample_period": 1e-3}
    t = np.arange(10000) * 1e-3
    u = np.array([np.sin(2 * np.pi * (i + 1) * t) for i in range(N_CHANNELS)]).T
    with Slave(sensors_fmu, "s") as s:
        s.initialize(0.0, None, params)
        fmu = _drive(s, t, u)
    twin = SensorNoise(params).outputs(t, 1e-3, {f"u_{i}": u[:, i - 1] for i in CH})
    for i in CH:
        assert np.array_equal(fmu[:, i - 1], twin[f"y_{i}"]), i
    # and through FMPy's simulate_fmu (another driver, constant inputs at their start 0)
    tt, y = _noise_run(sensors_fmu, {**SIGMAS, "seed": 99}, stop=2.0)
    twin = SensorNoise({**SIGMAS, "seed": 99}).outputs(tt, 1e-3)
    for i in CH:
        assert np.array_equal(y[i - 1], twin[f"y_{i}"]), i


def test_log_uniform_distribution_fmu_equals_python(sensors_fmu):
    """distribution_i = 1: y_i = gain_i u_i + bias_i exp(sigma_i (2 u2 - 1)), the C equal to the
    twin bit for bit, every draw within [bias e^-sigma, bias e^sigma], log-uniform (mean of
    ln y/bias near 0, std near sigma / sqrt(3)); the other channels stay Gaussian."""
    params = {**SIGMAS, **{f"bias_{i}": 0.1 * i for i in CH}, "sigma_4": math.log(2.0), "sigma_5": 0.3,
              "distribution_4": 1, "distribution_5": 1, "seed": 7, "sample_period": 1e-3}
    t = np.arange(5000) * 1e-3
    u = np.array([np.cos(2 * np.pi * (i + 1) * t) for i in range(N_CHANNELS)]).T
    with Slave(sensors_fmu, "s") as s:
        s.initialize(0.0, None, params)
        fmu = _drive(s, t, u)
    twin = SensorNoise(params).outputs(t, 1e-3, {f"u_{i}": u[:, i - 1] for i in CH})
    for i in CH:
        assert np.array_equal(fmu[:, i - 1], twin[f"y_{i}"]), i
    x = np.log((fmu[:, 3] - u[:, 3]) / 0.4)
    assert x.min() >= -math.log(2.0) and x.max() < math.log(2.0)
    assert abs(x.mean()) < 0.03 and abs(x.std() - math.log(2.0) / math.sqrt(3.0)) < 0.02


def test_uniform_distribution_fmu_equals_python(sensors_fmu):
    """distribution_i = 2: y_i = gain_i u_i + bias_i + sigma_i (2 u2 - 1), the C equal to the
    twin bit for bit, every draw within [bias - sigma, bias + sigma), uniform (5000 draws: mean
    within 4 standard errors sigma / sqrt(3 n) of bias, Kolmogorov-Smirnov p > 0.001)."""
    params = {**SIGMAS, **{f"bias_{i}": 0.1 * i for i in CH}, "sigma_7": 0.5, "bias_7": 0.5,
              "distribution_7": 2, "seed": 11, "sample_period": 1e-3}
    t = np.arange(5000) * 1e-3
    u = np.array([np.cos(2 * np.pi * (i + 1) * t) for i in range(N_CHANNELS)]).T
    u[:, 6] = 0.0  # channel 7 a drawn parameter: no input
    with Slave(sensors_fmu, "s") as s:
        s.initialize(0.0, None, params)
        fmu = _drive(s, t, u)
    twin = SensorNoise(params).outputs(t, 1e-3, {f"u_{i}": u[:, i - 1] for i in CH})
    for i in CH:
        assert np.array_equal(fmu[:, i - 1], twin[f"y_{i}"]), i
    x = fmu[:, 6]
    assert x.min() >= 0.0 and x.max() < 1.0
    assert abs(x.mean() - 0.5) < 4 * 0.5 / math.sqrt(3 * len(x))
    assert stats.kstest(x, "uniform").pvalue > 1e-3


def test_noise_statistics(sensors_fmu):
    """20000 samples per channel (20 s at 1 kHz): zero mean and std sigma within 3 standard
    errors, lag-1 autocorrelation |r| < 0.03 (its standard error is 0.007), channels
    uncorrelated, and Gaussian (Kolmogorov-Smirnov p > 0.001)."""
    _, y = _noise_run(sensors_fmu, {**SIGMAS, "seed": 2024})
    y = y[:, :20000]
    n = y.shape[1]
    for i in CH:
        sigma = SIGMAS[f"sigma_{i}"]
        w = y[i - 1]
        assert abs(w.mean()) < 3 * sigma / math.sqrt(n), i
        assert abs(w.std(ddof=1) - sigma) < 3 * sigma / math.sqrt(2 * (n - 1)), i
        d = w - w.mean()
        r1 = np.dot(d[:-1], d[1:]) / np.dot(d, d)
        assert abs(r1) < 0.03, (i, r1)
        assert stats.kstest(w / sigma, "norm").pvalue > 1e-3, i
    corr = np.corrcoef(y)
    assert np.abs(corr[~np.eye(N_CHANNELS, dtype=bool)]).max() < 0.03


def test_disabled_gives_the_input_exactly(sensors_fmu):
    params = {**SIGMAS, **{f"gain_{i}": 2.0 for i in CH}, **{f"bias_{i}": 1.0 for i in CH}, "enabled": False}
    t = np.arange(200) * 1e-3
    u = np.random.default_rng(1).normal(size=(200, N_CHANNELS)) * 10.0 ** np.arange(-4, 4)
    with Slave(sensors_fmu, "s") as s:
        s.initialize(0.0, None, params)
        y = _drive(s, t, u)
    assert np.array_equal(y, u)


def test_gain_and_bias(sensors_fmu):
    params = {"gain_1": 1.02, "bias_1": 0.05, "gain_2": -1.0}
    t = np.arange(10) * 1e-3
    u = np.tile(np.linspace(-1, 1, N_CHANNELS), (10, 1))
    with Slave(sensors_fmu, "s") as s:
        s.initialize(0.0, None, params)
        y = _drive(s, t, u)
    np.testing.assert_array_equal(y[:, 0], 1.02 * -1.0 + 0.05)
    np.testing.assert_array_equal(y[:, 1], -u[:, 1])
    np.testing.assert_array_equal(y[:, 2:], u[:, 2:])


@pytest.mark.parametrize("step", [0.25e-3, 0.4e-3, 1e-3, 3e-3])
def test_noise_is_held_over_a_sample_and_independent_of_the_step(sensors_fmu, step):
    """Communication steps shorter than the sample period see the same noise until the next
    sample; longer ones skip samples. At every communication point the noise is w(k(t)),
    whatever the steps before: the same as a run at the sample period. Start time 5 s."""
    t0, T = 5.0, 1e-3
    params = {**SIGMAS, "sample_period": T, "seed": 8}
    n = round(0.06 / step)
    t = t0 + np.arange(n + 1) * step
    with Slave(sensors_fmu, "s") as s:
        s.initialize(t0, None, params)
        y = _drive(s, t)
    k = sample_index(t, t0, T, step)
    for i in CH:
        expected = SIGMAS[f"sigma_{i}"] * noise(8, i, k)
        assert np.array_equal(y[:, i - 1], expected), i
    if step < T:
        changes = np.flatnonzero(np.diff(y[:, 0]) != 0) + 1
        np.testing.assert_array_equal(changes, np.flatnonzero(np.diff(k) != 0) + 1)
        assert len(np.unique(y[:, 0])) == k[-1] + 1  # one value per sample
    # the reference run at the sample period gives the same values where the grids meet
    with Slave(sensors_fmu, "r") as s:
        s.initialize(t0, None, params)
        ref = _drive(s, t0 + np.arange(61) * T)
    on_grid = np.isclose((t - t0) / T, np.rint((t - t0) / T), atol=1e-6)
    np.testing.assert_array_equal(y[on_grid], ref[np.rint((t[on_grid] - t0) / T).astype(int)])


def test_seed(sensors_fmu):
    _, a = _noise_run(sensors_fmu, {**SIGMAS, "seed": 5}, stop=5.0)
    _, b = _noise_run(sensors_fmu, {**SIGMAS, "seed": 5}, stop=5.0)
    _, c = _noise_run(sensors_fmu, {**SIGMAS, "seed": 6}, stop=5.0)
    assert np.array_equal(a, b)
    assert not np.any(a == c)
    assert abs(np.corrcoef(a[0], c[0])[0, 1]) < 0.05


def test_saved_state_reproduces_the_noise(sensors_fmu):
    """get/set and serialise/deserialise the FMU state mid-run (between samples: step 0.4 ms,
    period 1 ms): the continuation repeats exactly, in the same and in another instance."""
    params = {**SIGMAS, "seed": 31}
    h = 0.4e-3
    t = np.arange(401) * h
    u = np.random.default_rng(2).normal(size=(401, N_CHANNELS))
    with Slave(sensors_fmu, "a") as s, Slave(sensors_fmu, "b") as other:
        s.initialize(0.0, None, params)
        _drive(s, t[:101], u[:101])
        state = s.fmu.getFMUstate()
        first = _drive(s, t[100:], u[100:])
        s.fmu.setFMUstate(state)
        assert np.array_equal(_drive(s, t[100:], u[100:]), first)
        blob = s.fmu.serializeFMUstate(state)
        s.fmu.freeFMUstate(state)
        other.initialize(0.0, None, {"seed": 1})  # other parameters: the state carries them
        restored = other.fmu.deSerializeFMUstate(blob)
        other.fmu.setFMUstate(restored)
        other.fmu.freeFMUstate(restored)
        assert np.array_equal(_drive(other, t[100:], u[100:]), first)
    twin = SensorNoise(params).outputs(t[100:], h, {f"u_{i}": u[100:, i - 1] for i in CH})
    assert np.array_equal(first, np.array([twin[y] for y in Y]).T)


def test_outputs_in_initialization_mode(sensors_fmu):
    with Slave(sensors_fmu, "s") as s:
        s.enter_initialization(2.0, 3.0)
        s.set("sigma_4", 0.1)
        s.set("u_4", 3.0)
        assert s.get("y_4") == 3.0 + 0.1 * noise(1, 4, [0])[0]
        assert s.get("y_1") == 0.0


@pytest.mark.parametrize("params, msg", [
    ({"sigma_3": -0.1}, "parameter sigma_3 = -0.1 must be >= 0"),
    ({"bias_8": math.inf}, "value inf for bias_8 is not finite"),  # the runtime refuses it
    ({"sample_period": 0.0}, "parameter sample_period = 0 must be > 0"),
])
def test_bad_parameters_are_clear_errors(sensors_fmu, params, msg):
    with Slave(sensors_fmu, "s") as s, pytest.raises(FMUError, match=msg):
        s.initialize(0.0, 1.0, params)


def test_model_structure_declares_direct_feedthrough(sensors_fmu):
    """y_i depends on u_i only (so masters see no loop through the other channels)."""
    from fmpy import read_model_description

    md = read_model_description(str(sensors_fmu))
    deps = {o.variable.name: [d.name for d in o.dependencies] for o in md.outputs}
    assert deps == {f"y_{i}": [f"u_{i}"] for i in CH}
    units = {v.name: v.unit for v in md.modelVariables}
    assert all(units[n] is None for n in U + Y) and units["sample_period"] == "s"


# ---- presets and co-simulation ---------------------------------------------------------------

@pytest.mark.parametrize("preset, channels, period", [
    (MUNOZ_SENSORS, {1: 0.01, 2: 0.0005, 3: 0.01}, 1e-3),
    (ONAT2016_SENSORS, {1: 0.01, 2: 5e-4, 3: 5e-4, 4: 0.01, 5: 5e-4, 6: 0.01, 7: 5e-4}, 0.01),
])
def test_presets(sensors_fmu, preset, channels, period):
    names = {p.name for p in SENSORS.parameters}
    assert set(preset) <= names
    SENSORS.check_parameters(preset)
    assert preset["sample_period"] == period
    _, y = _noise_run(sensors_fmu, preset, stop=2000 * period, step=period)
    for i in CH:
        sigma = channels.get(i, 0.0)
        assert abs(y[i - 1].std() - sigma) <= 4 * sigma / math.sqrt(2 * y.shape[1]), i


def _system(fmu_dir, record):
    return System(
        name="track_wheelset_sensors",
        components=[Component("track", fmu_dir / "TrackIrregularity.fmu", {"psd_level": 1, "seed": 3}),
                    Component("wheelset", fmu_dir / "WheelsetLateral.fmu", {}),
                    Component("sensors", fmu_dir / "SensorNoise.fmu", dict(MUNOZ_SENSORS))],
        connections=[Connection("track", "alignment_1", "wheelset", "xi"),
                     Connection("track", "alignment_rate_1", "wheelset", "xi_rate"),
                     Connection("wheelset", "ddy", "sensors", "u_1"),
                     Connection("wheelset", "dpsi", "sensors", "u_2"),
                     Connection("wheelset", "ddy_f", "sensors", "u_3")],
        stop_time=1.0, step_size=1e-3, record=record)


def test_in_a_cosimulation(fmu_dir):
    """The sensors of Muñoz et al. on track -> wheelset: every master gives the same measurements
    (counter-based noise), and y - sigma w is exactly the true signal recorded at the same
    communication point (the recorder samples after the inputs are handed over)."""
    rec = ["wheelset.ddy", "wheelset.dpsi", "wheelset.ddy_f", "sensors.y_1", "sensors.y_2", "sensors.y_3"]
    res = {m: run(_system(fmu_dir, rec), m, progress=False).data for m in ("jacobi", "gauss-seidel", "container")}
    assert np.array_equal(res["container"], res["jacobi"])
    for data in res.values():
        k = sample_index(data[:, 0], 0.0, 1e-3, 1e-3)
        for j, i in enumerate((1, 2, 3)):
            sigma = MUNOZ_SENSORS[f"sigma_{i}"]
            truth, y = data[:, 1 + j], data[:, 4 + j]
            assert np.array_equal(y, truth + sigma * noise(1, i, k)), i  # default seed 1
    ddy = res["jacobi"][:, 1]
    assert np.ptp(ddy) > 10 * MUNOZ_SENSORS["sigma_1"]  # a signal well above the noise


def test_unitless_inputs_accept_any_connection_in_an_ssd(fmu_dir, tmp_path):
    """An SSD connecting m/s2 and rad/s outputs to the unit-less inputs reads without a unit
    error and without conversion (identity maps)."""
    comps = "".join(f'<ssd:Component name="{n}" source="resources/{f}.fmu"/>'
                    for n, f in [("track", "TrackIrregularity"), ("wheelset", "WheelsetLateral"),
                                 ("sensors", "SensorNoise")])
    conns = "".join(f'<ssd:Connection startElement="{a}" startConnector="{b}" endElement="{c}" endConnector="{d}"/>'
                    for a, b, c, d in [("track", "alignment_1", "wheelset", "xi"),
                                       ("track", "alignment_rate_1", "wheelset", "xi_rate"),
                                       ("wheelset", "ddy", "sensors", "u_1"),
                                       ("wheelset", "dpsi", "sensors", "u_2")])
    ssd = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="s"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">
  <ssd:System name="s"><ssd:Elements>{comps}</ssd:Elements><ssd:Connections>{conns}</ssd:Connections></ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1"/>
</ssd:SystemStructureDescription>
"""
    (tmp_path / "SystemStructure.ssd").write_text(ssd)
    system = read_system(tmp_path, fmu_dirs=[fmu_dir], step_size=1e-3)
    to_sensors = [c for c in system.connections if c.dst == "sensors"]
    assert len(to_sensors) == 2 and all(c.identity for c in to_sensors)
