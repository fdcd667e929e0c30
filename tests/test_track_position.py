"""TrackIrregularity driven by position: the travelled distance (m) and speed (m/s) as inputs
(``distance_input = true``), for stop-and-go and accelerating runs.

The FMU is driven through FMPy as a master would: at every communication point the inputs
are set, then the outputs read (the outputs of the inputs set there)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railfmu.fmus.cosim.slave import Slave
from railfmu.models.track.irregularity import TRACK, TrackIrregularity, tabulation_error_bound

OUT = [o.name for o in TRACK.outputs]
# every component, and a step on the 5 ms grid at 20 m/s (s_1 = 100 m at t = 5.5 s)
PARAMS = {"seed": 7, "psd_level": 2, "harmonic_lateral_amplitude": 1e-3, "harmonic_vertical_amplitude": 5e-4,
          "harmonic_wavelength": 15.66, "step_lateral": 2e-3, "step_vertical": -1e-3, "step_position": 100.0,
          "s_start": -10.0}


@pytest.fixture(scope="module")
def track_fmu(fmu_dir):
    return fmu_dir / "TrackIrregularity.fmu"


def drive(fmu, params, h, n, motion=None):
    """Outputs (n + 1, len(OUT)) at t = k h, k = 0..n, and the FMU's times; ``motion(t)``
    gives (distance, speed) to set at the FMU's time t (position mode)."""
    out, times = np.empty((n + 1, len(OUT))), np.empty(n + 1)
    with Slave(fmu, "track") as s:
        s.initialize(0.0, None, params)
        vr_out = [s.vars[o].valueReference for o in OUT]
        vr_in = [s.vars["distance"].valueReference, s.vars["speed"].valueReference]
        for k in range(n + 1):
            if k:
                s.do_step((k - 1) * h, h)
            t = s.fmu.getReal([0])[0]
            if motion is not None:
                s.fmu.setReal(vr_in, list(motion(t)))
            times[k] = t
            out[k] = s.fmu.getReal(vr_out)
    return out, times


def test_position_fed_with_constant_speed_equals_constant_speed(track_fmu):
    """distance = V t, speed = V: bit-identical to the constant-speed mode over 200 m, the step
    (on the grid) included."""
    V, h, n = 20.0, 5e-3, 2000
    const, t = drive(track_fmu, PARAMS, h, n)
    pos, _ = drive(track_fmu, {**PARAMS, "distance_input": True}, h, n, lambda t: (V * t, V))
    assert np.array_equal(const, pos)
    step_row = round(5.5 / h)  # s_1 = -10 + 20 t = 100 m
    j = OUT.index("alignment_1")
    jump = const[step_row, j] - const[step_row - 1, j]
    assert 1.5e-3 < jump < 2.5e-3  # 2 mm step plus ~0.1 m of random track


def test_standstill_holds_the_outputs_and_zeroes_the_rates(track_fmu):
    """Accelerate for 4 s, stop at 8 m for 2 s, move on: while v = 0 every value holds and every
    rate is exactly 0."""
    a, h = 1.0, 5e-3

    def motion(t):
        if t < 4.0:
            return 0.5 * a * t * t, a * t
        if t < 6.0:
            return 8.0, 0.0
        return 8.0 + 0.5 * a * (t - 6.0) ** 2, a * (t - 6.0)

    out, t = drive(track_fmu, {**PARAMS, "distance_input": True}, h, round(8.0 / h), motion)
    still = (t >= 4.0) & (t < 6.0)
    assert still.sum() == 400
    for j, name in enumerate(OUT):
        if "rate" in name:
            assert np.all(out[still, j] == 0.0), name
            assert np.abs(out[t > 6.5, j]).max() > 0, name
        else:
            assert np.all(out[still, j] == out[still, j][0]), name
    assert out[still, OUT.index("position")][0] == -10.0 + 8.0


def test_accelerating_run_equals_the_twin(track_fmu):
    """s(t) = s_start + a t^2 / 2, v = a t over 20 s (200 m): the FMU equals the twin's
    tabulated evaluation at the same s(t) to round-off, and the exact cosine sum within the
    tabulation bound (rates: times v <= 20 m/s)."""
    a, h = 1.0, 5e-3
    params = {**PARAMS, "distance_input": True}
    out, t = drive(track_fmu, params, h, round(20.0 / h), lambda t: (0.5 * a * t * t, a * t))
    tr = TrackIrregularity(params)
    d, v = 0.5 * a * t * t, a * t
    steps = np.r_[0.0, np.full(t.size - 1, h)]
    tab = tr.outputs(t, "tabulated", h=steps, distance=d, speed=v)
    sub = slice(None, None, 7)  # the cosine sum is slow: every 7th point
    exact = tr.outputs(t[sub], "exact", h=steps[sub], distance=d[sub], speed=v[sub])
    bound_m, bound_slope = tabulation_error_bound(tr.params)
    for j, name in enumerate(OUT):
        rate = "rate" in name
        assert np.abs(out[:, j] - tab[name]).max() <= (1e-12 * 20 if rate else 1e-13), name
        assert np.abs(out[sub, j] - exact[name]).max() <= (bound_slope * 20 if rate else bound_m) + 1e-12, name


def test_rates_are_the_time_derivatives():
    """d(irregularity)/dt = v d/ds, checked against a central difference in time of the twin's
    exact values along the accelerating run (an independent chain rule)."""
    a, dt = 1.0, 1e-5
    tr = TrackIrregularity({**PARAMS, "step_lateral": 0.0, "step_vertical": 0.0, "distance_input": True})
    t = np.linspace(1.0, 19.0, 37)

    def at(tt):
        return tr.outputs(tt, distance=0.5 * a * tt * tt, speed=a * tt)

    mid, up, down = at(t), at(t + dt), at(t - dt)
    for base, i in (("alignment", 1), ("vertical_left", 2), ("vertical_right", 4)):
        fd = (up[f"{base}_{i}"] - down[f"{base}_{i}"]) / (2 * dt)
        np.testing.assert_allclose(mid[f"{base}_rate_{i}"], fd, rtol=1e-5, atol=1e-9)


def test_distance_is_extrapolated_with_the_speed_until_new_inputs(track_fmu):
    """Read after a step before new inputs are set, s_1 = s_start + distance + speed h
    (first-order hold); once set, the new distance."""
    with Slave(track_fmu, "track") as s:
        s.initialize(0.0, None, {**PARAMS, "distance_input": True})
        s.set("distance", 3.0)
        s.set("speed", 12.0)
        assert s.get("position") == -10.0 + 3.0
        s.do_step(0.0, 0.25)
        assert s.get("position") == -10.0 + (3.0 + 12.0 * 0.25)
        s.set("distance", 2.0)
        assert s.get("position") == -10.0 + 2.0


def test_constant_speed_ignores_the_inputs(track_fmu):
    with Slave(track_fmu, "track") as s:
        s.initialize(0.0, None, {"V": 20.0})
        s.set("distance", 1e3)
        s.set("speed", -5.0)
        s.do_step(0.0, 0.5)
        assert s.get("position") == 10.0
        slope = TrackIrregularity().rails(np.array([10.0]), "tabulated")["alignment_ds"][0]
        assert math.isclose(s.get("alignment_rate_1"), 20.0 * slope, rel_tol=1e-12)


def test_twin_needs_the_inputs_in_position_mode():
    with pytest.raises(ValueError, match="distance_input is true"):
        TrackIrregularity({"distance_input": True}).outputs(np.array([0.0]))
