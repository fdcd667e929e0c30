"""The same samples whatever the master's clock: t = k h or an accumulated t += h.

FMI does not say how a master computes its communication points. FMPy's ``simulate_fmu`` and
our masters use ``start + k h``; OMSimulator adds ``h`` to its time every step. Over 1e6 steps
the two differ by up to 2.2e-5 h (1e7 steps: 1.8e-3 h), which is why a sample or switching
instant counts as reached within ``STEP_TOLERANCE`` = 1 % of the step (railfmu.models.base, model.h).

Measured when written: with the former sample index ``floor(t / T + 1e-9)`` an accumulated
clock lands on the previous noise sample from step 11,621 on at 1 ms (750,713 of 1e6 steps)
and from step 61,530 on at 0.1 ms (27,662 of 1e6); with the step-relative tolerance none.
"""

from __future__ import annotations

import ctypes
import re

import numpy as np
import pytest

from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.models.base import STEP_TOLERANCE
from railfmu.models.sources.sensors import N_CHANNELS, SensorNoise, noise, sample_index
from railfmu.models.sources.step_source import STEP_SOURCE

N = 10**6


def clocks(h: float, n: int = N) -> tuple[np.ndarray, np.ndarray]:
    """The communication points 1..n as ``k h`` and as ``t += h`` (np.cumsum adds in order,
    exactly as the loop ``t = t + h``)."""
    return np.arange(1, n + 1) * h, np.cumsum(np.full(n, h))


def test_step_tolerance_is_one_value_in_c_and_python():
    from railfmu.fmus.generate.build import FMUS

    header = (FMUS / "native" / "runtime" / "model.h").read_text()
    (value,) = re.findall(r"^#define STEP_TOLERANCE (\S+)$", header, re.M)
    assert float(value) == STEP_TOLERANCE == 0.01


@pytest.mark.parametrize("h", [1e-3, 1e-4])
def test_accumulated_clock_drift_is_far_inside_the_tolerance(h):
    grid, acc = clocks(h)
    drift = np.abs(acc - grid).max() / h
    assert 1e-6 < drift < 3e-5  # measured 1.67e-5 (1 ms), 2.20e-5 (0.1 ms)
    assert drift < STEP_TOLERANCE / 100


@pytest.mark.parametrize("h", [1e-3, 1e-4])
def test_sensor_sample_index_is_the_same_for_both_clocks(h):
    """10^6 steps, sample period 1 ms: the Python twin's index (the C's arithmetic) agrees on
    every point, and is the exact k of the grid; the former 1e-9 index did not."""
    T = 1e-3
    grid, acc = clocks(h)
    k_grid, k_acc = sample_index(grid, 0.0, T, h), sample_index(acc, 0.0, T, h)
    assert np.array_equal(k_grid, k_acc)
    exact = np.arange(1, N + 1) // round(T / h)  # T / h = 1 or 10 steps per sample
    assert np.array_equal(k_grid, exact)
    old_mismatch = np.count_nonzero(np.floor(acc / T + 1e-9) != np.floor(grid / T + 1e-9))
    assert old_mismatch == {1e-3: 750713, 1e-4: 27662}[h]


@pytest.mark.parametrize("h", [1e-3, 1e-4])
def test_step_source_switches_at_the_same_point_for_both_clocks(h):
    """Every step time K h (K = 1..10^6, computed as K * h) switches at communication point K
    under both clocks: the first point with t >= step_time - 0.01 h, by binary search on
    the monotonic clocks; and the twin's expression agrees where it is evaluated."""
    grid, acc = clocks(h)
    K = np.arange(1, N + 1)
    edge = K * h - STEP_TOLERANCE * h
    assert np.array_equal(np.searchsorted(grid, edge, side="left") + 1, K)
    assert np.array_equal(np.searchsorted(acc, edge, side="left") + 1, K)
    p = {"initial_value": 0.0, "final_value": 1.0}
    for k in (1, 11621, 61530, 999_999):
        ts = k * h
        for clock in (grid, acc):
            before = STEP_SOURCE.outputs_at(clock[k - 2] if k > 1 else 0.0, [], None, {**p, "step_time": ts}, h=h)
            at = STEP_SOURCE.outputs_at(clock[k - 1], [], None, {**p, "step_time": ts}, h=h)
            assert (before["y"], at["y"]) == (0.0, 1.0), (k, clock is acc)


def _drive(slave: Slave, times: np.ndarray, h: float, names: list[str]) -> np.ndarray:
    """Step the FMU from each of ``times`` by ``h`` (times[0] is its current time; the master
    passes its own time and step, as OMSimulator does) with raw ctypes calls (FMPy's wrappers
    cost ~10 us a call) and return ``names`` after every step."""
    f, c = slave.fmu, slave.fmu.component
    vr = (ctypes.c_uint * len(names))(*[slave.vars[n].valueReference for n in names])
    val = (ctypes.c_double * len(names))()
    out = np.empty((len(times), len(names)))
    for j, t in enumerate(times.tolist()):
        if f.fmi2DoStep(c, t, h, 1) != 0:
            raise slave.failure(f"fmi2DoStep at t = {t}", "status != OK")
        f.fmi2GetReal(c, vr, len(names), val)
        out[j] = val[:]
    return out


@pytest.mark.parametrize("h, n", [(1e-3, 20_000), (1e-4, 70_000)])
def test_sensor_fmu_gives_the_same_noise_for_both_clocks(fmu_dir, h, n):
    """The real FMU over the stretch where the old index failed (from step 11,621 at 1 ms,
    61,530 at 0.1 ms): every sample equal under both clocks and to the twin at k h."""
    T = 1e-3
    sigmas = {f"sigma_{i}": 0.1 * i for i in range(1, N_CHANNELS + 1)}
    grid, acc = clocks(h, n)
    ys = {}
    for name, clock in (("grid", grid), ("acc", acc)):
        with Slave(fmu_dir / "SensorNoise.fmu", name) as s:
            s.initialize(0.0, None, {**sigmas, "sample_period": T, "seed": 7})
            ys[name] = _drive(s, np.r_[0.0, clock[:-1]], h, ["y_1", "y_8"])
    assert np.array_equal(ys["grid"], ys["acc"])
    k = np.arange(1, n + 1) // round(T / h)  # the exact sample index
    assert np.array_equal(ys["grid"][:, 0], 0.1 * noise(7, 1, k))
    twin = SensorNoise({**sigmas, "sample_period": T, "seed": 7}).outputs(acc, h)
    assert np.array_equal(ys["acc"][:, 1], twin["y_8"])
    # the stretch contains points the former index put on the previous sample
    assert np.count_nonzero(np.floor(acc / T + 1e-9) != k) > 100


def test_step_source_fmu_switches_on_the_grid_with_an_accumulated_clock(fmu_dir):
    """A step at 18.437 s (step 18,437 of 1 ms, where the accumulated clock is 2.9e-12 s below
    the grid point) appears at that point in both clocks."""
    h, n, K = 1e-3, 20_000, 18_437
    grid, acc = clocks(h, n)
    assert acc[K - 1] < K * h
    ys = {}
    for name, clock in (("grid", grid), ("acc", acc)):
        with Slave(fmu_dir / "StepSource.fmu", name) as s:
            s.initialize(0.0, None, {"initial_value": -1.0, "final_value": 2.0, "step_time": K * h})
            ys[name] = _drive(s, np.r_[0.0, clock[:-1]], h, ["y"])[:, 0]
    expected = np.where(np.arange(1, n + 1) >= K, 2.0, -1.0)
    assert np.array_equal(ys["grid"], expected) and np.array_equal(ys["acc"], expected)


def test_step_between_grid_points_keeps_its_place(fmu_dir):
    """h = 10 ms: a step time 2 % of h before grid point 50 appears there; 0.5 % after it is
    within the band, so it counts as reached at point 50; 2 % after it appears at 51."""
    h = 0.01
    for step_time, first in ((0.5 - 0.02 * h, 50), (0.5 + 0.005 * h, 50), (0.5 + 0.02 * h, 51)):
        with Slave(fmu_dir / "StepSource.fmu", "s") as s:
            s.initialize(0.0, None, {"initial_value": 0.0, "final_value": 1.0, "step_time": step_time})
            y = [s.get("y")]
            for k in range(60):
                s.do_step(k * h, h)
                y.append(s.get("y"))
        assert y.index(1.0) == first, step_time


# ---- the runtime's matching of currentCommunicationPoint --------------------------------------

def test_communication_point_matches_within_one_percent_of_the_step(fmu_dir):
    with Slave(fmu_dir / "StepSource.fmu", "s") as s:
        s.initialize(0.0, None)
        s.do_step(0.0, 1e-3)
        s.do_step(1e-3 + 0.009e-3, 1e-3)  # 0.9 % of h off: the same point
        with pytest.raises(FMUError, match="differs from the FMU time"):
            s.do_step(2e-3 + 0.02e-3, 1e-3)  # 2 %: another point
        s.do_step(2.009e-3, 1e-3)  # refused calls changed nothing


def test_communication_point_tolerance_does_not_grow_with_time(fmu_dir):
    """At t = 1e7 s a relative 1e-9 of t (the former rule) is 0.01 s, ten 1 ms steps: a master
    that skipped ten steps went unnoticed. Tied to h it is refused."""
    t0 = 1e7
    with Slave(fmu_dir / "StepSource.fmu", "s") as s:
        s.initialize(t0, None, {"step_time": 0.0})
        s.do_step(t0, 1e-3)
        with pytest.raises(FMUError, match="differs from the FMU time"):
            s.do_step(t0 + 11e-3, 1e-3)
        s.do_step(t0 + 1e-3, 1e-3)


def test_stop_time_allows_an_accumulated_last_step(fmu_dir):
    """The last step of an accumulated clock may end a hair past stopTime:
    accepted; a step that ends 2 % of h past it is refused."""
    h = 1e-4  # 10^6 steps of 0.1 ms to 100 s: the accumulated clock ends 2.2e-5 h late
    _, acc = clocks(h)
    stop, last = N * h, float(acc[-2])
    assert 2e-5 * h < last + h - stop < 3e-5 * h
    with Slave(fmu_dir / "StepSource.fmu", "s") as s:
        s.initialize(last, stop)
        with pytest.raises(FMUError, match="goes past stopTime"):
            s.do_step(last, 1.03 * h)
        s.do_step(last, h)


def test_step_size_is_part_of_the_saved_state(fmu_dir):
    """A state saved after a step of h carries h: restored into another instance, a sample
    instant 0.05 % of T ahead of t = 0.05 s still counts as reached (k = 5) when the outputs
    are recomputed (it would not with h = 0: k = 4)."""
    h, T = 1e-3, 0.05 / 4.9995
    params = {"sigma_1": 1.0, "sample_period": T, "seed": 3}
    assert sample_index(0.05, 0.0, T, h) == 5 and sample_index(0.05, 0.0, T, 0.0) == 4
    with Slave(fmu_dir / "SensorNoise.fmu", "a") as a, Slave(fmu_dir / "SensorNoise.fmu", "b") as b:
        a.initialize(0.0, None, params)
        for k in range(50):
            a.do_step(k * h, h)
        assert a.get("y_1") == noise(3, 1, [5])[0]
        state = a.fmu.getFMUstate()
        blob = a.fmu.serializeFMUstate(state)
        a.fmu.freeFMUstate(state)
        b.initialize(0.0, None, {"seed": 1})
        state = b.fmu.deSerializeFMUstate(blob)
        b.fmu.setFMUstate(state)
        b.fmu.freeFMUstate(state)
        b.set("u_1", 0.0)  # an input: the outputs are recomputed from the restored state
        assert b.get("y_1") == noise(3, 1, [5])[0]
