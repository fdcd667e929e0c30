"""The step source FMU: the step happens at the first communication point t >= step_time."""

import numpy as np
import pytest
from fmpy import simulate_fmu

from railfmu.fmus.cosim.slave import Slave
from railfmu.models.sources.step_source import STEP_SOURCE


def run(fmu_dir, params, stop=1.0, h=1e-2, accumulate=False):
    """(t, y) at every communication point; ``accumulate``: the importer's time is t += h, with
    its rounding (0.1 + 0.2 ... drifts off the decimal grid)."""
    ts, ys = [], []
    with Slave(fmu_dir / "StepSource.fmu", "step") as s:
        s.initialize(0.0, stop, params)
        t = 0.0
        for k in range(round(stop / h) + 1):
            ts.append(t)
            ys.append(s.get("y"))
            if k < round(stop / h):
                s.do_step(t, h)
                t = t + h if accumulate else (k + 1) * h
    return np.array(ts), np.array(ys)


@pytest.mark.parametrize("accumulate", [False, True])
def test_before_at_and_after_the_step(fmu_dir, accumulate):
    t, y = run(fmu_dir, {"initial_value": 430e3, "final_value": 215e3, "step_time": 0.5},
               accumulate=accumulate)
    k = int(np.argmin(np.abs(t - 0.5)))
    assert t[k] == pytest.approx(0.5, abs=1e-12)
    assert np.all(y[:k] == 430e3)  # ... 0.48, 0.49
    assert np.all(y[k:] == 215e3)  # 0.50 (exactly at the step), 0.51, ...


def test_step_between_grid_points_appears_at_the_next_one(fmu_dir):
    t, y = run(fmu_dir, {"initial_value": -1.0, "final_value": 2.0, "step_time": 0.505})
    assert np.all(y[t < 0.505] == -1.0)
    assert np.all(y[t > 0.505] == 2.0)
    assert y[np.argmin(np.abs(t - 0.51))] == 2.0


def test_initial_output_and_step_at_start(fmu_dir):
    with Slave(fmu_dir / "StepSource.fmu", "step") as s:
        s.enter_initialization(0.0, 1.0)
        s.set("initial_value", 3.0)
        assert s.get("y") == 3.0  # read in initialisation mode, before the step
        s.set("step_time", 0.0)
        s.set("final_value", 4.0)
        assert s.get("y") == 4.0  # t = 0 >= step_time: already stepped
        s.exit_initialization()
        assert s.get("y") == 4.0


def test_equals_python_definition_and_runs_in_fmpy(fmu_dir):
    params = {"initial_value": 1.0, "final_value": 0.5, "step_time": 0.3}
    res = simulate_fmu(str(fmu_dir / "StepSource.fmu"), stop_time=1.0, step_size=1e-2, output_interval=1e-2,
                       start_values=params)
    expected = [STEP_SOURCE.outputs_at(t, [], None, params, h=1e-2 if t > 0 else 0.0)["y"] for t in res["time"]]
    assert np.array_equal(res["y"], expected)
    assert res["y"][np.argmin(np.abs(res["time"] - 0.29))] == 1.0
    assert res["y"][np.argmin(np.abs(res["time"] - 0.30))] == 0.5


def test_output_has_no_unit():
    """Generic: it connects to an input of any unit (the coach's k1 in N/m)."""
    assert STEP_SOURCE.variable("y").unit == ""
    assert STEP_SOURCE.variable("step_time").unit == "s"


@pytest.mark.parametrize("accumulate", [False, True])
def test_step_on_the_grid_switches_there_after_many_steps(fmu_dir, accumulate):
    """A step at communication point 7,212 of 10 ms (72.12 s) switches exactly there with the
    master's time as k h or as t += h (1.4e-14 s below 72.12 there)."""
    t, y = run(fmu_dir, {"initial_value": 0.0, "final_value": 1.0, "step_time": 72.12}, stop=80.0,
               accumulate=accumulate)
    assert not accumulate or t[7212] < 72.12
    assert np.all(y[:7212] == 0.0) and np.all(y[7212:] == 1.0)


def test_the_band_is_one_percent_of_the_step():
    """Python definition: reached at t when t >= step_time - 0.01 h; exact in
    initialisation mode (h = 0)."""
    y = lambda t, ts, h: STEP_SOURCE.outputs_at(t, [], None, {"step_time": ts}, h=h)["y"]  # noqa: E731
    assert y(1.0, 1.0 + 0.0099 * 0.1, 0.1) == 1.0
    assert y(1.0, 1.0 + 0.0101 * 0.1, 0.1) == 0.0
    assert y(0.0, 1e-12, 0.0) == 0.0 and y(0.0, 0.0, 0.0) == 1.0
