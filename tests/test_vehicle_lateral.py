"""The complete vehicle model (CM) FMU against its own Python definition, and its physics."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from railfmu.fmus.cosim.slave import Slave
from railfmu.models.track.irregularity import TrackIrregularity
from railfmu.models.vehicle.vehicle_lateral import (
    VEHICLE_LATERAL,
    first_lateral_mode,
    kinematic_mode,
    lateral_modes,
    state_matrix,
)

M = VEHICLE_LATERAL
STATES = [s.name for s in M.states]
OUTPUTS = [o.name for o in M.outputs]
INPUTS = [u.name for u in M.inputs]
P = M.default_parameters()
Q0 = (P["m_c"] + 2 * P["m_b"] + 4 * P["m_w"]) * P["g"] / 8
HELD = [u for u in M.inputs if u.rate]


def track_inputs(params=None):
    """Rail irregularities under the four wheelsets from the track model (exact cosine sum)."""
    track = TrackIrregularity({"psd_level": 1, "seed": 7, **(params or {})})

    def at(t):
        out = track.outputs(np.array([t]))
        return {n: float(out[n][0]) for n in INPUTS}

    return at


def constant(values):
    u = {n: 0.0 for n in INPUTS}
    u.update(values)
    return lambda t: u


def run_fmu(fmu_dir, inputs, stop, h, params=None, start=None):
    rows = []
    with Slave(fmu_dir / "VehicleLateral.fmu", "cm") as s:
        s.initialize(0.0, stop, {**(params or {}), **(start or {})})
        n = round(stop / h)
        for k in range(n + 1):
            t = k * h
            for name, v in inputs(t).items():
                s.set(name, v)
            rows.append([s.get(name) for name in [*STATES, *OUTPUTS]])
            if k < n:
                s.do_step(t, h)
    return np.array(rows)


def run_scipy(inputs, stop, h, params=None):
    """solve_ivp of the Python definition with the FMU's first-order hold of the rail inputs."""
    x = np.zeros(len(STATES))
    out = []
    n = round(stop / h)
    for k in range(n + 1):
        t = k * h
        u = inputs(t)
        o = M.outputs_at(t, x, u, params)
        out.append([*x, *[o[name] for name in OUTPUTS]])
        if k == n:
            break

        def held(tt, t=t, u=u):
            return {**u, **{v.name: u[v.name] + u[v.rate] * (tt - t) for v in HELD}}

        sol = solve_ivp(M.rhs(params, held), (t, t + h), x, method="DOP853", rtol=1e-11, atol=1e-14)
        x = sol.y[:, -1]
    return np.array(out)


def col(rows, name):
    return rows[:, [*STATES, *OUTPUTS].index(name)]


@pytest.fixture(scope="module")
def psd_runs(fmu_dir):
    """2 s on ERRI B176 low-level track (alignment and both rails under all four wheelsets):
    the FMU with flange contact off and on, and scipy."""
    u = track_inputs()
    off = run_fmu(fmu_dir, u, 2.0, 2e-3)
    on = run_fmu(fmu_dir, u, 2.0, 2e-3, {"flange_contact": 1})
    ref = run_scipy(u, 2.0, 2e-3)
    return off, on, ref


def test_fmu_equals_python_definition(psd_runs):
    """Every state and output agrees with scipy to 1e-6 of its range."""
    fmu, _, ref = psd_runs
    scale = np.abs(ref).max(axis=0)
    err = np.abs(fmu - ref).max(axis=0) / np.where(scale > 0, scale, 1.0)
    worst = {n: e for n, e in zip([*STATES, *OUTPUTS], err) if e > 1e-6}
    assert not worst, worst
    # the track moves every body: the run is not trivially zero
    assert np.abs(col(ref, "y_w1")).max() > 1e-4 and np.abs(col(ref, "Q_1L") - Q0).max() > 10.0


def test_flange_contact_off_equals_on_inside_the_clearance(psd_runs):
    off, on, _ = psd_runs
    for j in range(1, 5):
        assert np.abs(col(off, f"y_w{j}")).max() < P["delta_fl"]
    assert np.array_equal(off, on)


def test_flange_contact_bounds_the_wheelset_outside_the_clearance(fmu_dir):
    """A 25 mm lateral step of the track under a vehicle at rest on the centre line. Without
    flange contact creep and gravitational stiffness swing the wheelsets over and they
    overshoot far outside the clearance on the other side; with it the flanges push them
    back at once and the overshoot stops at the clearance. The FMU still equals the Python
    definition with the (non-smooth) flange force."""
    u = constant({f"alignment_{j}": 0.025 for j in range(1, 5)})
    off = run_fmu(fmu_dir, u, 0.5, 1e-3)
    on = run_fmu(fmu_dir, u, 0.5, 1e-3, {"flange_contact": 1})
    later = slice(150, None)  # after the first swing (t > 0.15 s)
    for j in range(1, 5):
        e_off = 0.025 - col(off, f"y_w{j}")
        e_on = 0.025 - col(on, f"y_w{j}")
        assert np.abs(e_off[later]).max() > 0.015
        assert np.abs(e_on[later]).max() < P["delta_fl"] + 1e-3
        assert np.abs(e_on).max() <= 0.025 + 1e-9
    assert np.all(np.isfinite(on))
    # flange force right at the start: k_fl (e - delta) towards the displaced track
    F0 = col(on, "F_y1")[0] - col(off, "F_y1")[0]
    assert F0 == pytest.approx(P["k_fl"] * (0.025 - P["delta_fl"]), rel=1e-9)
    ref = run_scipy(u, 0.1, 1e-3, {"flange_contact": 1})
    n = len(ref)
    # (vertical states stay at round-off level under a purely lateral input: floor 1e-9)
    err = np.abs(on[:n] - ref).max(axis=0) / np.maximum(np.abs(ref).max(axis=0), 1e-9)
    assert err.max() < 1e-5


def test_constant_alignment_is_followed_by_the_whole_vehicle(fmu_dir):
    """2 mm constant alignment under every wheelset: every body settles 2 mm to the side,
    without yaw or roll; the loads return to Q0."""
    out = run_fmu(fmu_dir, constant({f"alignment_{j}": 2e-3 for j in range(1, 5)}), 15.0, 1e-2)
    for name in ("y_c", "y_b1", "y_b2", "y_w1", "y_w2", "y_w3", "y_w4"):
        assert col(out, name)[-1] == pytest.approx(2e-3, rel=1e-3), name
    for name in STATES:
        if name.startswith(("psi", "phi", "dpsi", "dphi", "z_", "theta")):
            assert abs(col(out, name)[-1]) < 1e-6, name  # 2 mm / l = 2.7e-3 rad for scale
    assert col(out, "Q_1L")[-1] == pytest.approx(Q0, rel=1e-7)


def test_wheel_loads_at_rest_and_under_a_raised_left_rail(fmu_dir):
    """At rest the eight loads carry the vehicle's weight equally; a 1 mm rise of the left rail
    under wheelset 1 loads that wheel more and its diagonal partner (2R), unloads 1R and 2L,
    and the loads still sum to the weight."""
    rest = M.outputs_at(0.0, np.zeros(len(STATES)))
    weight = (P["m_c"] + 2 * P["m_b"] + 4 * P["m_w"]) * P["g"]
    loads = [rest[f"Q_{j}{s}"] for j in range(1, 5) for s in "LR"]
    assert loads == pytest.approx([weight / 8] * 8, rel=1e-12)
    out = run_fmu(fmu_dir, constant({"vertical_left_1": 1e-3}), 10.0, 1e-2)
    Q = {f"{j}{s}": col(out, f"Q_{j}{s}")[-1] for j in range(1, 5) for s in "LR"}
    assert sum(Q.values()) == pytest.approx(weight, rel=1e-7)
    assert Q["1L"] > Q0 + 50 and Q["2R"] > Q0
    assert Q["1R"] < Q0 and Q["2L"] < Q0
    # the first instant: the wheelset rolls about the right contact point, so the left axle box
    # (at l_s, outboard of the contact point at l) rises by 1 mm (1 + l_s/l)/2 = 1.067 mm
    assert col(out, "Q_1L")[0] == pytest.approx(Q0 + P["kz_p"] * 1e-3 * (1 + P["l_s"] / P["l"]) / 2, rel=1e-9)


def test_linear_stability_and_modes():
    """Stable at 20 m/s; the wheelsets' kinematic modes lie a little below Klingel's
    frequency V/(2 pi) sqrt(alpha / (r0 l)) of a free wheelset, because the primary yaw
    stiffness ties them to the bogie frame (a rigid bogie would lower it by
    sqrt(1 + (a_w/l)^2) = 1.94) and they couple with the car body's upper sway."""
    A = state_matrix()
    assert np.linalg.eigvals(A).real.max() < 0
    f_klingel = P["V"] / (2 * math.pi) * math.sqrt(P["alpha"] / (P["r0"] * P["l"]))
    f_k, zeta_k, desc = kinematic_mode()
    assert desc.startswith("wheelsets")
    assert 0.8 * f_klingel <= f_k < f_klingel  # 1.51 Hz vs 1.78 Hz with the defaults
    assert 0 < zeta_k < 0.5
    f1, zeta1, _ = first_lateral_mode()
    assert 0.5 < f1 < 2.0 and zeta1 < 0.25
    # the car body's vertical modes are those of a coach (benchmark frequencies are kept by scaling)
    modes = lateral_modes()
    bounce = [f for f, _, d in modes if d.startswith("car body z")]
    assert bounce and 0.8 < bounce[0] < 1.3


def test_state_matrix_equals_symbolic_jacobian_on_the_lateral_block():
    """The central-difference A matches the exact derivative of the linear terms: a wheelset's
    lateral creep damping and gravitational stiffness."""
    A = state_matrix()
    n = len(STATES) // 2
    i = STATES.index("y_w1")
    W = 8 * Q0 / 4  # axle load
    assert A[n + i, i] == pytest.approx(-(W * P["alpha"] / P["l"] + 2 * P["ky_p"]) / P["m_w"], rel=1e-7)
    assert A[n + i, n + i] == pytest.approx(-(2 * P["f22"] / P["V"] + 2 * P["cy_p"]) / P["m_w"], rel=1e-7)


@pytest.mark.slow
def test_symbolic_linearization_equals_state_matrix():
    """Model.linearize (symbolic, minutes) and the numerical state_matrix agree."""
    A = M.linearize()[0]
    assert np.abs(A - state_matrix()).max() < 1e-8 * np.abs(A).max()
