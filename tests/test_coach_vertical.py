"""The vertical 7-DOF coach FMU (Onat et al. (2016), §2) against its own Python definition."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import logm

from railfmu.fmus.cosim.slave import Slave
from railfmu.models.vehicle.coach_vertical import (
    COACH_VERTICAL,
    K1_NOMINAL,
    MODES,
    SENSORS,
    natural_frequencies,
)

STATES = [s.name for s in COACH_VERTICAL.states]
ACCELERATIONS = [o.name for o in COACH_VERTICAL.outputs]
RAILS = ["z_l1", "z_r1", "z_l2", "z_r2"]
P = COACH_VERTICAL.default_parameters()


def run_fmu(fmu_dir, stop, h, inputs=None, start=None, params=None):
    """Drive the FMU with ``inputs(t)`` (name -> value) set at every communication point;
    rows of [t, states..., accelerations...]."""
    rows = []
    with Slave(fmu_dir / "CoachVertical.fmu", "coach") as s:
        s.initialize(0.0, stop, {**(params or {}), **(start or {})})
        n = round(stop / h)
        for k in range(n + 1):
            t = k * h
            for name, v in (inputs(t) if inputs else {}).items():
                s.set(name, v)
            rows.append([t, *[s.get(name) for name in [*STATES, *ACCELERATIONS]]])
            if k < n:
                s.do_step(t, h)
    return np.array(rows)


def column(rows, name):
    return rows[:, 1 + [*STATES, *ACCELERATIONS].index(name)]


def run_scipy(inputs, stop, h):
    """solve_ivp of the Python definition, one communication interval at a time with the same
    first-order hold of the rail heights (k1 held)."""
    x = np.zeros(len(STATES))
    out = []
    n = round(stop / h)
    for k in range(n + 1):
        t = k * h
        u = inputs(t)
        o = COACH_VERTICAL.outputs_at(t, x, u)
        out.append([t, *x, *[o[a] for a in ACCELERATIONS]])
        if k == n:
            break

        def held(tt, t=t, u=u):
            return {**u, **{r: u[r] + u["d" + r] * (tt - t) for r in RAILS}}

        sol = solve_ivp(COACH_VERTICAL.rhs(None, held), (t, t + h), x, method="DOP853", rtol=1e-12, atol=1e-15)
        x = sol.y[:, -1]
    return np.array(out)


def zero_crossing_frequency(t, x):
    """Frequency (Hz) from the mean spacing of the zero crossings (linear interpolation)."""
    i = np.flatnonzero(np.sign(x[:-1]) * np.sign(x[1:]) < 0)
    tc = t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])
    assert len(tc) >= 6, "too few zero crossings"
    return 1.0 / (2.0 * np.mean(np.diff(tc)))


def test_fmu_equals_python_definition(fmu_dir):
    """A different harmonic under every wheel contact (bounce, pitch and roll all excited) and
    k1 halved through its input at t = 1 s: every state and acceleration agrees with scipy to
    1e-6 of its range."""
    amp = {"z_l1": (1e-3, 1.0, 0.0), "z_r1": (0.6e-3, 1.3, 0.5), "z_l2": (0.8e-3, 0.8, 1.0),
           "z_r2": (1.2e-3, 6.0, 2.0)}  # m, Hz, rad

    def inputs(t):
        u = {"k1": K1_NOMINAL if t < 1.0 - 1e-9 else 0.5 * K1_NOMINAL}
        for r, (a, f, ph) in amp.items():
            w = 2 * math.pi * f
            u[r], u["d" + r] = a * math.sin(w * t + ph), a * w * math.cos(w * t + ph)
        return u

    fmu = run_fmu(fmu_dir, 2.0, 2e-3, inputs)
    ref = run_scipy(inputs, 2.0, 2e-3)
    scale = np.abs(ref).max(axis=0)[1:]
    err = np.abs(fmu - ref).max(axis=0)[1:] / scale
    assert err.max() < 1e-6, dict(zip([*STATES, *ACCELERATIONS], err))


@pytest.mark.parametrize("k1", [K1_NOMINAL, 0.5 * K1_NOMINAL])
def test_fmu_eigenfrequencies_equal_python_definition(fmu_dir, k1):
    """The FMU's one-step transition matrix Phi (column j: the states after 10 ms from the unit
    state j, no rail input) gives A_fmu = logm(Phi) / h; its damped frequencies equal those of
    natural_frequencies() (the model's A) to 1e-6."""
    h = 1e-2
    phi = np.zeros((len(STATES), len(STATES)))
    with Slave(fmu_dir / "CoachVertical.fmu", "coach") as s:
        for j, name in enumerate(STATES):
            s.fmu.reset()  # initial states can only be set before initialisation ends
            s.initialize(0.0, None, {name: 1e-3})
            s.set("k1", k1)
            s.do_step(0.0, h)
            phi[:, j] = [s.get(n) / 1e-3 for n in STATES]
    lam = np.linalg.eigvals(logm(phi) / h)
    f_fmu = np.sort(np.abs(lam.imag[lam.imag > 0])) / (2 * math.pi)
    f_py = np.sort(list(natural_frequencies({"k1": k1}).values()))
    assert f_fmu == pytest.approx(f_py, rel=1e-6)


@pytest.mark.parametrize("coordinate,mode", [("z_c", "coach_bounce"), ("phi_c", "coach_roll"),
                                              ("theta_c", "coach_pitch")])
def test_free_decay_frequency(fmu_dir, coordinate, mode):
    """Released from 1 mm bounce (1 mrad roll or pitch) on a perfect track, the car body rings
    at the damped frequency of its mode (zero crossings after the bogie modes have died out)."""
    rows = run_fmu(fmu_dir, 8.0, 1e-3, start={coordinate: 1e-3})
    t, x = rows[:, 0], column(rows, coordinate)
    late = t > 0.5  # bogie modes decay at ~10 1/s
    assert zero_crossing_frequency(t[late], x[late]) == pytest.approx(natural_frequencies()[mode], rel=0.01)


def test_k1_input_changes_coach_bounce_frequency(fmu_dir):
    """Halving k1 through its input lowers the coach bounce frequency as the square root of the
    bounce stiffness predicts: 4 k1 k2 / (k1 + k2), the secondary spring in series with the
    primary (so by 0.754, not by sqrt(1/2) = 0.707)."""
    f = {}
    for k1 in (K1_NOMINAL, 0.5 * K1_NOMINAL):
        rows = run_fmu(fmu_dir, 10.0, 1e-3, inputs=lambda t, k1=k1: {"k1": k1}, start={"z_c": 1e-3})
        late = rows[:, 0] > 0.5
        f[k1] = zero_crossing_frequency(rows[late, 0], column(rows, "z_c")[late])
        assert f[k1] == pytest.approx(natural_frequencies({"k1": k1})["coach_bounce"], rel=0.01)

    def stiffness(k1):
        return 4 * k1 * P["k2"] / (k1 + P["k2"])

    predicted = math.sqrt(stiffness(0.5 * K1_NOMINAL) / stiffness(K1_NOMINAL))
    assert f[0.5 * K1_NOMINAL] / f[K1_NOMINAL] == pytest.approx(predicted, rel=0.01)


def test_eigenfrequencies_against_uncoupled_hand_formulas():
    """Undamped frequencies of A against single-mode formulas: car-body modes on the secondary
    and primary springs in series (bogie mass neglected), bogie modes with the car body held
    still. The couplings the formulas neglect are below 1 %."""
    k1, k2, c1, c2, a1 = K1_NOMINAL, P["k2"], P["c1"], P["c2"], P["a1"]
    per_bogie = 2 * k1 * k2 / (k1 + k2)  # one bogie's two sides, secondary in series with primary
    hand = {
        "coach_bounce": math.sqrt(2 * per_bogie / P["m1"]),
        "coach_pitch": math.sqrt(2 * per_bogie * a1**2 / P["Jz1"]),
        "coach_roll": math.sqrt(2 * 2 * (k1 * c1**2) * (k2 * c2**2) / (k1 * c1**2 + k2 * c2**2) / P["Jx1"]),
        "bogie_bounce_in_phase": math.sqrt(2 * (k1 + k2) / P["m2"]),
        "bogie_bounce_anti_phase": math.sqrt(2 * (k1 + k2) / P["m2"]),
        "bogie_roll_in_phase": math.sqrt(2 * (k1 * c1**2 + k2 * c2**2) / P["Jx2"]),
        "bogie_roll_anti_phase": math.sqrt(2 * (k1 * c1**2 + k2 * c2**2) / P["Jx2"]),
    }
    f = natural_frequencies(damped=False)
    assert list(f) == list(MODES)
    for mode, w in hand.items():
        assert f[mode] == pytest.approx(w / (2 * math.pi), rel=0.01), mode
    assert 0.9 < f["coach_bounce"] < 1.1  # the ~1 Hz of a passenger coach
    eig = np.linalg.eigvals(COACH_VERTICAL.linearize()[0])
    assert eig.real.max() < 0


def test_linearisation_matches_the_equations():
    """A few entries of A and B by hand, and linearize() about a changed k1."""
    A, B, _, _ = COACH_VERTICAL.linearize()
    i = {n: k for k, n in enumerate(STATES)}
    j = {u.name: k for k, u in enumerate(COACH_VERTICAL.inputs)}
    assert A[i["dz_c"], i["z_c"]] == pytest.approx(-4 * K1_NOMINAL / P["m1"])
    assert A[i["dz_b1"], i["z_b1"]] == pytest.approx(-2 * (K1_NOMINAL + P["k2"]) / P["m2"])
    assert A[i["dphi_c"], i["dphi_c"]] == pytest.approx(-4 * P["b1"] * P["c1"] ** 2 / P["Jx1"])
    assert B[i["dz_b1"], j["z_l1"]] == pytest.approx(P["k2"] / P["m2"])
    assert B[i["dz_b1"], j["dz_l1"]] == pytest.approx(P["b2"] / P["m2"])
    assert B[i["dphi_b2"], j["z_r2"]] == pytest.approx(-P["k2"] * P["c2"] / P["Jx2"])
    assert not B[i["dz_b2"], j["z_l1"]]
    A_half = COACH_VERTICAL.linearize(u0={"k1": 0.5 * K1_NOMINAL})[0]
    assert A_half[i["dz_c"], i["z_c"]] == pytest.approx(-2 * K1_NOMINAL / P["m1"])
    # the sensor set: the paper's seven inertial signals are variables of the FMU
    names = {v.name for v in COACH_VERTICAL.variables}
    assert set(SENSORS) <= names


def test_step_under_every_wheel_is_static_equilibrium(fmu_dir):
    """1 mm under all four wheel contacts: car body and bogies settle 1 mm higher, no rotation."""
    rows = run_fmu(fmu_dir, 20.0, 1e-2, inputs=lambda t: dict.fromkeys(RAILS, 1e-3))
    last = rows[-1]
    for name in ("z_c", "z_b1", "z_b2"):
        assert abs(column(rows, name)[-1] - 1e-3) < 1e-6, name
    for name in ("theta_c", "phi_c", "phi_b1", "phi_b2"):
        assert np.abs(column(rows, name)).max() < 1e-12, name
    assert np.abs(last[1 + STATES.index("dz_c")]) < 1e-6
    assert abs(column(rows, "ddz_c")[-1]) < 1e-5


def test_onat2016_fig2_step_response(fmu_dir):
    """Onat et al. (2016), Fig. 2: a 1 mm step under both bogies at t = 1 s. The car body overshoots
    (lightly damped 1 Hz bounce: about 75 %), peaks about half a period after the step and
    converges to the step value; the stiffly suspended bogie follows within a few tenths of a
    second."""
    rows = run_fmu(fmu_dir, 12.0, 1e-3, inputs=lambda t: dict.fromkeys(RAILS, 1e-3 if t >= 1.0 - 1e-9 else 0.0))
    t, zc, zb2 = rows[:, 0], column(rows, "z_c"), column(rows, "z_b2")
    assert np.abs(zc[t < 1.0]).max() == 0.0
    peak = np.argmax(zc)
    assert 1.5e-3 < zc[peak] < 1.9e-3
    assert 0.3 < t[peak] - 1.0 < 0.7
    assert np.abs(zc[t > 8.0] - 1e-3).max() < 0.02e-3
    assert np.abs(zb2[t > 8.0] - 1e-3).max() < 0.01e-3
    assert zb2[np.searchsorted(t, 1.1)] > 0.5e-3  # the bogie is already halfway after 0.1 s
    assert abs(zc[-1] - 1e-3) < 2e-6
