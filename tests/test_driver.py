"""Driver FMU in the system TrainLongitudinal + Driver + GnssReceiver through our Jacobi master:
the 32 km run of the shipped line completes, stops at the station, keeps the limits, shows
the regimes in the order of Cunillera et al. (2022) §4 and equals the Python twins."""

from __future__ import annotations

import time

import numpy as np
import pytest

from railfmu.fmus.cosim.masters import run
from railfmu.fmus.cosim.slave import Slave
from railfmu.fmus.cosim.system import Component, Connection, System
from railfmu.models.train.driver import COAST, DriverTwin, uniform
from railfmu.models.track.line_profile import DEFAULT_LINE, LineProfile
from railfmu.models.train.longitudinal import Train

# measured over seeds 1-30 (1 s steps, Jacobi: the driver acts on the train's position of the
# previous step): stops 0.12 m short to 3.1 m past the stopping point; at most 0.81 km/h over
# a limit (a gentle start into the 40 km/h of the departure)
STOP_TOLERANCE_M = 5.0
OVERSPEED_KMH = 1.5
RECORD = ["train.s", "train.v", "train.speed_limit", "driver.command", "driver.regime", "driver.mode",
          "driver.stop_time", "driver.coasting_point", "driver.cycles", "gnss.valid", "gnss.position", "gnss.speed_kmh"]


def train_system(fmu_dir, seed: int) -> System:
    return System(
        "train_run",
        [Component("train", fmu_dir / "TrainLongitudinal.fmu", {}),
         Component("driver", fmu_dir / "Driver.fmu", {"seed": seed}),
         Component("gnss", fmu_dir / "GnssReceiver.fmu", {"seed": seed})],
        [Connection("driver", "command", "train", "command"),
         Connection("train", "s", "driver", "s"), Connection("train", "v", "driver", "v"),
         Connection("train", "speed_limit", "driver", "speed_limit"),
         Connection("train", "s", "gnss", "s_true"), Connection("train", "v", "gnss", "v_true")],
        stop_time=3000.0, step_size=1.0, record=RECORD)


def twin_run(seed: int):
    """The twins coupled as the Jacobi master couples the FMUs: every FMU steps from t_k with
    the outputs of t_k, so the driver decides at t_k on the train's outputs of t_(k-1)."""
    ln = LineProfile.read(DEFAULT_LINE)
    train, driver = Train(line=ln), DriverTwin({"seed": seed}, line=ln)
    t, prev, rows = 0.0, train.outputs(), []
    while t < 3000:
        out = train.outputs()
        d = driver.outputs(t, prev["s"], prev["v"], prev["speed_limit"])
        rows.append((t, out["s"], out["v"], d["mode"]))
        if driver.terminated:
            break
        train.u["command"] = d["command"]
        train.step(1.0)
        prev, t = out, t + 1.0
    return np.array(rows)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_run_completes_and_equals_the_twins(fmu_dir, seed):
    t0 = time.perf_counter()
    res = run(train_system(fmu_dir, seed), "jacobi", progress=False)
    wall = time.perf_counter() - t0
    col = {c: res.data[:, j] for j, c in enumerate(res.columns)}
    t, s, v = col["time"], col["train.s"], col["train.v"]
    L = LineProfile.read(DEFAULT_LINE).length
    assert wall < 5.0  # measured 0.08 s
    assert 1000 < t[-1] < 2000 and v[-1] == 0.0  # the driver ended the run at the station
    assert abs(s[-1] - L) < STOP_TOLERANCE_M
    assert np.max((v - col["train.speed_limit"]) * 3.6) < OVERSPEED_KMH

    # the paper's order: traction (and cruising) before the coasting point, then coast, brake, stop
    regime = col["driver.regime"].astype(int)
    before = s < col["driver.coasting_point"][0]
    assert regime[0] == 1 and set(regime[before]) <= {1, 2, 3}
    tail = regime[~before]
    standing = len(tail) - len(np.trim_zeros(tail, "b"))
    assert set(tail[:-standing]) <= {3, 4} and standing >= 30  # then 30 s (dwell_time) at the platform
    # the FMU ends the run (fmi2Discard + terminated) on the step that reaches stop + dwell: the
    # last complete row is the point before it
    assert col["time"][-1] - col["driver.stop_time"][-1] == 29.0
    seq = [r for k, r in enumerate(regime) if k == 0 or r != regime[k - 1]]
    assert seq[-3:] == [3, 4, 0]
    assert (2 in seq) != bool(col["driver.cycles"][0])  # holding gives cruising, cycles don't

    # GNSS: a fix every 10 s
    fixes = t[col["gnss.valid"] > 0]
    assert np.array_equal(fixes, np.arange(0, t[-1] + 1, 10.0))

    # the twins, bit for bit on the train's states, so on every command applied (the
    # recorder reads the driver after the master set its inputs of t_k: a get after a set
    # decides on those, one step ahead of the command the train got, so modes are not compared)
    tw = twin_run(seed)
    n = len(t) - 1
    # the twin decides on the previous step's outputs: it stops one step later and ends the run
    # on its own stop + dwell, where the FMU's run ended on the step reaching it (one row less)
    assert len(tw) == len(t) + 2
    assert np.array_equal(tw[:n, 1], s[:n]) and np.array_equal(tw[:n, 2], v[:n])


def test_style_is_drawn_from_the_seed(fmu_dir):
    fmu = Slave(fmu_dir / "Driver.fmu")
    fmu.initialize(0.0, parameters={"seed": 11})
    twin = DriverTwin({"seed": 11})
    for name, value in twin.style.items():
        assert fmu.get(name) == value, name
    assert fmu.get("cruise_target") == (120 + 20 * uniform(11, 0)) / 3.6
    assert fmu.get("stop_position") == 32103.0
    # a get after a set at the same point decides again from the previous point's mode
    fmu.set("v", 10.0), fmu.set("s", 500.0)
    first = (fmu.get("mode"), fmu.get("command"))
    fmu.set("v", 10.0)
    assert (fmu.get("mode"), fmu.get("command"), fmu.get("mode_before")) == (*first, 0)
    fmu.close()


def test_the_final_coast_starts_at_the_coasting_point(fmu_dir):
    res = run(train_system(fmu_dir, 2), "jacobi", progress=False)
    col = {c: res.data[:, j] for j, c in enumerate(res.columns)}
    k = int(np.argmax(col["driver.mode"] == COAST))
    # decided on the train's position one step earlier (Jacobi): within one step's travel
    assert col["train.s"][k - 1] < col["driver.coasting_point"][0] <= col["train.s"][k] + col["train.v"][k]


def test_thirty_drivers_stop_at_the_station_and_keep_the_limits(fmu_dir):
    """Seeds 1-30: every run ends at standstill within STOP_TOLERANCE_M of the stopping point,
    never more than OVERSPEED_KMH over the limit; both cruise styles occur; run times of
    19.5-27.3 min (measured)."""
    L = LineProfile.read(DEFAULT_LINE).length
    styles, times = set(), []
    for seed in range(1, 31):
        res = run(train_system(fmu_dir, seed), "jacobi", progress=False)
        col = {c: res.data[:, j] for j, c in enumerate(res.columns)}
        assert col["train.v"][-1] == 0.0 and abs(col["train.s"][-1] - L) < STOP_TOLERANCE_M, seed
        assert np.max((col["train.v"] - col["train.speed_limit"]) * 3.6) < OVERSPEED_KMH, seed
        styles.add(bool(col["driver.cycles"][0]))
        times.append(col["time"][-1])
    assert styles == {True, False} and 1100 < min(times) and max(times) < 1700
