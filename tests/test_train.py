"""TrainLongitudinal FMU: equal to its Python twin (bit for bit) and to the closed forms of
eqs. 1-2 of Cunillera et al. (2022): terminal speed at the power limit, coasting deceleration
= resistance, braking distance, the traction envelope, the gradient term."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.models.track.line_profile import DEFAULT_LINE, G0, LineProfile
from railfmu.models.train.longitudinal import (
    GAMMA,
    LOAD_MASS,
    MAX_DECELERATION,
    MAX_POWER,
    MAX_TRACTION_FORCE,
    R0,
    R1,
    R2,
    TARE_MASS,
    Train,
)

M_EFF = GAMMA * (TARE_MASS + LOAD_MASS)


def line(tmp_path, gradient=0.0, name="flat.csv"):
    p = tmp_path / name
    p.write_text(f"position_m,gradient_permille,speed_limit_kmh\n0,{gradient},200\n100000,{gradient},200\n")
    return p


def start(fmu_dir, params=None, inputs=None):
    fmu = Slave(fmu_dir / "TrainLongitudinal.fmu")
    fmu.enter_initialization(0.0)
    for k, v in {**(params or {}), **(inputs or {})}.items():
        fmu.set(k, v)
    fmu.exit_initialization()
    return fmu


def test_vehicle_data_are_the_documented_values():
    assert TARE_MASS == 297e3 and LOAD_MASS == pytest.approx(0.35 * 570 * 80)
    assert MAX_POWER == 2388e3 and MAX_TRACTION_FORCE == 226e3  # 2388 kW / 38 km/h = 226.2 kN
    # KISS Davis 5.672 kN + 0.02545 kN/(km/h) v + 0.00121 kN/(km/h)^2 v^2 at 100 km/h, per gamma m
    v = 100 / 3.6
    assert R0 + R1 * v + R2 * v * v == pytest.approx((5.672 + 2.545 + 12.1) * 1e3 / M_EFF, rel=1e-12)
    ln = LineProfile.read(DEFAULT_LINE)
    assert ln.length == 32103 and ln.limit_at(0) * 3.6 == pytest.approx(40)
    assert ln.limit_at(16000) * 3.6 == pytest.approx(140) and ln.limit_at(32000) * 3.6 == pytest.approx(40)
    assert np.abs(ln.gradient).max() <= 1.2


def test_fmu_equals_its_python_twin(fmu_dir):
    """A run through traction, coast, brake to standstill on the shipped line, with r2 stepped:
    the FMU and the twin agree bit for bit at every communication point."""
    fmu, twin = start(fmu_dir), Train()
    plan = [(1.0, 300), (0.4, 200), (0.0, 300), (-0.5, 200)]
    t = 0.0
    for u, n in plan:
        for k in range(n):
            r2 = R2 * (1.5 if t >= 400 else 1.0)
            fmu.set("command", u), fmu.set("r2", r2)
            twin.u.update(command=u, r2=r2)
            fmu.do_step(t, 1.0)
            twin.step(1.0)
            t += 1.0
            out = twin.outputs()
            for name in ("s", "v", "acceleration", "effort", "power", "speed_limit", "gradient_specific"):
                assert fmu.get(name) == out[name], (t, name)
    assert twin.v == 0.0 and twin.s > 5000  # braked to standstill
    fmu.close()


def test_load_factor_input_sets_the_mass(fmu_dir, tmp_path):
    """The load_factor input (start 1: the load_mass parameter, so nothing changes unconnected):
    the twin equals the FMU bit for bit at a drawn load, the mass output is m_tare + l m_load,
    and from rest on a flat line at full traction the acceleration is F_max / (gamma m) - r0
    (eq. 1 below the transition speed), lower for the heavier train."""
    flat = line(tmp_path)
    fmu0 = start(fmu_dir, {"line_file": str(flat)})
    assert fmu0.get("load_factor") == 1.0 and fmu0.get("mass") == TARE_MASS + LOAD_MASS
    fmu0.close()
    acc = {}
    for lf in (0.0, 0.37, 1.0):
        fmu = start(fmu_dir, {"line_file": str(flat), "load_mass": 45600.0}, {"load_factor": lf, "command": 1.0})
        twin = Train({"load_mass": 45600.0}, line=flat)
        twin.u.update(load_factor=lf, command=1.0)
        m = TARE_MASS + lf * 45600.0
        assert fmu.get("mass") == m and twin.outputs()["mass"] == m
        # at rest r0 holds the train; the net traction starts it
        acc[lf] = fmu.get("acceleration")
        assert acc[lf] == pytest.approx(MAX_TRACTION_FORCE / (GAMMA * m) - R0, rel=1e-12)
        t = 0.0
        for u, n in [(1.0, 120), (0.0, 60), (-0.6, 40)]:
            for _ in range(n):
                fmu.set("command", u)
                twin.u["command"] = u
                fmu.do_step(t, 1.0)
                twin.step(1.0)
                t += 1.0
                out = twin.outputs()
                for name in ("s", "v", "acceleration", "effort", "effort_specific", "mass"):
                    assert fmu.get(name) == out[name], (lf, t, name)
        fmu.close()
    assert acc[0.0] > acc[0.37] > acc[1.0]
    fmu = start(fmu_dir, {"line_file": str(flat)})
    fmu.set("load_factor", -0.1)
    with pytest.raises(FMUError, match="load_factor"):
        fmu.do_step(0.0, 1.0)
    fmu.close()


def test_terminal_speed_where_power_limited_traction_equals_resistance(fmu_dir, tmp_path):
    """P/v = gamma m r(v) on the flat: the train started at that speed stays there."""
    f = lambda v: MAX_POWER / v / M_EFF - (R0 + R1 * v + R2 * v * v)  # noqa: E731
    lo, hi = 30.0, 80.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    v_t = 0.5 * (lo + hi)  # 54.64 m/s = 196.7 km/h
    fmu = start(fmu_dir, {"line_file": str(line(tmp_path))}, {"v": v_t, "command": 1.0})
    assert abs(fmu.get("acceleration")) < 1e-15
    assert fmu.get("power") == pytest.approx(MAX_POWER, rel=1e-15)
    for k in range(100):
        fmu.do_step(float(k), 1.0)
    assert fmu.get("v") == pytest.approx(v_t, abs=1e-12)
    assert fmu.get("s") == pytest.approx(100 * v_t, rel=1e-12)
    fmu.close()


def test_coasting_deceleration_is_the_resistance_and_the_gradient(fmu_dir, tmp_path):
    fmu = start(fmu_dir, {"line_file": str(line(tmp_path, gradient=2.5))}, {"v": 30.0})
    assert fmu.get("acceleration") == pytest.approx(-(R0 + 30 * R1 + 900 * R2) - G0 * 2.5e-3 / GAMMA, rel=1e-14)
    assert fmu.get("resistance_specific") == pytest.approx(R0 + 30 * R1 + 900 * R2, rel=1e-15)
    assert fmu.get("effort") == 0.0
    fmu.close()


def test_braking_distance_at_constant_deceleration(fmu_dir, tmp_path):
    """r = 0, flat, command -1: v0^2 / (2 b_max) = 450 m from 30 m/s, stopped after 30 s."""
    fmu = start(fmu_dir, {"line_file": str(line(tmp_path))},
                {"v": 30.0, "command": -1.0, "r0": 0.0, "r1": 0.0, "r2": 0.0})
    assert fmu.get("effort") == pytest.approx(-MAX_DECELERATION * M_EFF, rel=1e-15)
    for k in range(40):
        fmu.do_step(float(k), 1.0)
    assert fmu.get("v") == 0.0
    # the RK4 sub-step (dt = 0.05 s) that crosses v = 0 adds b dt^2 / 12 = 2.08e-4 m (measured)
    assert fmu.get("s") == pytest.approx(30.0**2 / (2 * MAX_DECELERATION) + 0.05**2 / 12, abs=1e-9)
    fmu.close()


@pytest.mark.parametrize("v, command", [(5.0, 1.0), (20.0, 1.0), (20.0, 0.5), (0.0, 0.3)])
def test_traction_envelope(fmu_dir, tmp_path, v, command):
    """F_t = u min(F_max, P_max / v): F_max up to 10.57 m/s (38 km/h), P_max / v above."""
    fmu = start(fmu_dir, {"line_file": str(line(tmp_path))}, {"v": v, "command": command})
    expected = command * min(MAX_TRACTION_FORCE, MAX_POWER / v if v > 0 else math.inf)
    assert fmu.get("effort") == pytest.approx(expected, rel=1e-15)
    assert fmu.get("power") == pytest.approx(expected * v, rel=1e-15)
    fmu.close()


def test_standstill_on_an_uphill_is_held(fmu_dir, tmp_path):
    """At rest, no command, 5 per mille uphill: the train does not roll back."""
    fmu = start(fmu_dir, {"line_file": str(line(tmp_path, gradient=5.0))})
    for k in range(10):
        fmu.do_step(float(k), 1.0)
    assert fmu.get("v") == 0.0 and fmu.get("s") == 0.0
    fmu.close()


@pytest.mark.parametrize("text, message", [
    ("position_m,gradient_permille,speed_limit_kmh\n0,0,140\n10,x,140\n", "line 3, column 2"),
    ("position_m,gradient_permille,speed_limit_kmh,curve_radius_m\n0,0,140,40\n", "beyond 55 m"),
    ("position_m,gradient_permille,speed_limit_kmh,curve_radius_m\n0,0,140\n", "3 fields, expected 4"),
    ("position_m,gradient_permille,speed_limit_kmh\n0,0,140\n0,0,140\n", "does not increase"),
    ("position_m,gradient\n0,0\n", "2 fields"),
    ("position_m,gradient_permille,speed_limit_kmh\n0,0,nan\n", "line 2, column 3"),
])
def test_a_bad_line_file_is_one_message(fmu_dir, tmp_path, text, message):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(FMUError) as err:
        start(fmu_dir, {"line_file": str(p)})
    assert message in str(err.value) and "bad.csv" in str(err.value)
    with pytest.raises(ValueError):
        LineProfile.read(p)


def test_fmu_state_restores_the_run(fmu_dir):
    """What a UKF with the FMU as process model does: save, step a sigma point, restore."""
    fmu = start(fmu_dir, inputs={"command": 1.0})
    for k in range(60):
        fmu.do_step(float(k), 1.0)
    state = fmu.fmu.getFMUstate()
    fmu.set("r2", 2 * R2)
    fmu.do_step(60.0, 10.0)
    perturbed = fmu.get("v")
    fmu.fmu.setFMUstate(state)
    fmu.set("r2", R2)
    fmu.do_step(60.0, 10.0)
    twin = Train()
    twin.u["command"] = 1.0
    for k in range(60):
        twin.step(1.0)
    twin.step(10.0)
    assert fmu.get("v") == twin.v and fmu.get("s") == twin.s and perturbed < twin.v
    fmu.fmu.freeFMUstate(state)
    fmu.close()


@pytest.mark.parametrize("radius, w_c", [(1055.0, 0.65 / 1000), (-230.0, 0.5 / 200), (0.0, 0.0)])
def test_curve_resistance_from_the_optional_fourth_column(fmu_dir, tmp_path, radius, w_c):
    """Röckl: 0.65 / (R - 55) from 300 m, 0.5 / (R - 30) below, either sign; coasting at
    20 m/s on a 1 per mille uphill curve decelerates by r(v) + g0 (i / 1000 + w_c) / gamma."""
    p = tmp_path / "curvy.csv"
    p.write_text("position_m,gradient_permille,speed_limit_kmh,curve_radius_m\n"
                 f"0,1.0,140,{radius}\n5000,0,140,0\n")
    fmu = start(fmu_dir, {"line_file": str(p)}, {"v": 20.0})
    expected = -(R0 + 20 * R1 + 400 * R2) - G0 * (1e-3 + w_c) / GAMMA
    assert fmu.get("acceleration") == pytest.approx(expected, rel=1e-14)
    assert LineProfile.read(p).curve_at(10.0) == pytest.approx(w_c, rel=1e-15)
    twin = Train(line=p)
    twin.v = 20.0
    assert twin.outputs()["acceleration"] == fmu.get("acceleration")
    fmu.close()
