"""An FMU as the process model of a sigma-point filter (``fmus/cosim/process_model.py``):
TrainLongitudinal's process-model inputs (``set_state``, ``use_effort_set``) leave every
output bit for bit as before when false, equal the Python twin when true and give the closed
forms of a constant-effort step."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest

from fmus.cosim.masters import run
from fmus.cosim.slave import FMUError, Slave
from fmus.cosim.system import Component, Connection, System
from models.train_longitudinal import GAMMA, LOAD_MASS, R0, R1, R2, TARE_MASS, Train

DATA = Path(__file__).parent / "data"
M_EFF = GAMMA * (TARE_MASS + LOAD_MASS)
TRAIN_OUTPUTS = ("s", "v", "acceleration", "effort", "effort_specific", "power", "resistance_specific",
                 "gradient", "gradient_specific", "speed_limit")


def driven_run(fmu_dir: Path, seed: int = 1):
    """Driver + TrainLongitudinal + GnssReceiver, 1 s steps, Jacobi: the driven 32 km run."""
    system = System(
        "train_run",
        [Component("train", fmu_dir / "TrainLongitudinal.fmu", {}),
         Component("driver", fmu_dir / "Driver.fmu", {"seed": seed}),
         Component("gnss", fmu_dir / "GnssReceiver.fmu", {"seed": seed})],
        [Connection("driver", "command", "train", "command"),
         Connection("train", "s", "driver", "s"), Connection("train", "v", "driver", "v"),
         Connection("train", "speed_limit", "driver", "speed_limit"),
         Connection("train", "s", "gnss", "s_true"), Connection("train", "v", "gnss", "v_true")],
        stop_time=3000.0, step_size=1.0,
        record=["driver.command", *(f"train.{o}" for o in TRAIN_OUTPUTS)])
    return run(system, "jacobi", progress=False)


def test_with_the_new_inputs_false_every_output_is_bit_identical_to_before(fmu_dir):
    """tests/data/train_run_seed1.csv was recorded with the TrainLongitudinal FMU before these
    inputs existed: every 20th row as text (repr: exact), all 1308 rows as a SHA-256."""
    res = driven_run(fmu_dir)
    with open(DATA / "train_run_seed1.csv") as f:
        digest = f.readline().split()[-1]
        header = f.readline().strip().split(",")
        ref = np.array([[float(x) for x in line.split(",")] for line in f])
    assert res.columns == header
    data = np.ascontiguousarray(res.data, dtype="<f8")
    assert data.shape == (1308, len(header))
    assert np.array_equal(data[::20], ref)
    assert hashlib.sha256(data.tobytes()).hexdigest() == digest


def start(fmu_dir, **inputs) -> Slave:
    fmu = Slave(fmu_dir / "TrainLongitudinal.fmu")
    fmu.enter_initialization(0.0)
    for k, v in inputs.items():
        fmu.set(k, v)
    fmu.exit_initialization()
    return fmu


def test_set_state_and_effort_set_equal_the_twin_bit_for_bit(fmu_dir):
    """Traction on the shipped line, then steps that jump the state and impose the effort
    (also braking through v = 0 and at rest), then back to the command: FMU and twin agree in
    every output at every communication point."""
    fmu, twin = start(fmu_dir, command=1.0), Train()
    twin.u["command"] = 1.0
    plan = ([{}] * 30
            + [{"set_state": True, "s_set": 12000.0 + 7 * k, "v_set": 30.0 - k,
                "use_effort_set": k % 2 == 1, "effort_set": 0.05 * k - 0.3} for k in range(8)]
            + [{"set_state": False, "use_effort_set": True, "effort_set": -0.8}] * 40  # to a standstill
            + [{"use_effort_set": True, "effort_set": 0.01}] * 5   # at rest, less than r0: held
            + [{"use_effort_set": False, "command": 0.5}] * 20)
    t = 0.0
    for inputs in plan:
        for k, v in inputs.items():
            fmu.set(k, v)
            twin.u[k] = v
        fmu.do_step(t, 3.0)
        twin.step(3.0)
        t += 3.0
        out = twin.outputs()
        for name in TRAIN_OUTPUTS:
            assert fmu.get(name) == out[name], (t, name, inputs)
    assert twin.v > 0 and 60 * 3.0 < t
    fmu.close()


def test_a_step_from_a_set_state_with_a_set_effort_is_the_closed_form(fmu_dir, tmp_path):
    """Flat line, r = 0, f_t - f_b = a: v = v_set + a h, s = s_set + v_set h + a h^2 / 2 (RK4 is
    exact on polynomials of degree 2), whatever state and command the FMU had."""
    line = tmp_path / "flat.csv"
    line.write_text("position_m,gradient_permille,speed_limit_kmh\n0,0,200\n100000,0,200\n")
    fmu = start(fmu_dir, line_file=str(line), command=1.0, v=20.0, r0=0.0, r1=0.0, r2=0.0)
    fmu.do_step(0.0, 5.0)
    a, s0, v0, h = 0.37, 2500.0, 25.0, 10.0
    for k, v in {"set_state": True, "s_set": s0, "v_set": v0, "use_effort_set": True, "effort_set": a}.items():
        fmu.set(k, v)
    fmu.do_step(5.0, h)
    assert fmu.get("v") == pytest.approx(v0 + a * h, rel=1e-15)
    assert fmu.get("s") == pytest.approx(s0 + v0 * h + a * h * h / 2, rel=1e-15)
    assert fmu.get("acceleration") == a and fmu.get("effort_specific") == a
    assert fmu.get("effort") == a * M_EFF and fmu.get("power") == a * M_EFF * fmu.get("v")
    fmu.close()


def test_a_non_finite_state_input_is_refused_when_set(fmu_dir):
    """The runtime refuses it at fmi2SetReal; the run goes on as if it had not been sent."""
    fmu = start(fmu_dir, command=1.0)
    fmu.do_step(0.0, 10.0)
    with pytest.raises(FMUError, match="value inf for s_set is not finite"):
        fmu.set("s_set", math.inf)
    fmu.do_step(10.0, 10.0)
    twin = Train()
    twin.u["command"] = 1.0
    twin.step(10.0), twin.step(10.0)
    assert (fmu.get("s"), fmu.get("v")) == (twin.s, twin.v)
    fmu.close()
