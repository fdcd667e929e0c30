"""The wheelset + suspended-frame FMU against its own Python definition (Muñoz et al., §3.3)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from railfmu.fmus.cosim.slave import Slave
from railfmu.models.vehicle.wheelset import WHEELSET

STATES = [s.name for s in WHEELSET.states]


def run_fmu(fmu_dir, xi, xi_rate, stop, h, params=None):
    """Drive the FMU with xi(t), xi_rate(t) set at every communication point."""
    rows = []
    with Slave(fmu_dir / "WheelsetLateral.fmu", "ws") as s:
        s.initialize(0.0, stop, params)
        n = round(stop / h)
        for k in range(n + 1):
            t = k * h
            s.set("xi", xi(t))
            s.set("xi_rate", xi_rate(t))
            rows.append([s.get(name) for name in [*STATES, "ddy", "ddy_f"]])
            if k < n:
                s.do_step(t, h)
    return np.array(rows)


def run_scipy(xi, xi_rate, stop, h, params=None):
    """solve_ivp of the Python definition with the same first-order-held input, one
    communication interval at a time (the input's slope changes at every point)."""
    x = np.zeros(len(STATES))
    out = []
    n = round(stop / h)
    for k in range(n + 1):
        t = k * h
        u = {"xi": xi(t), "xi_rate": xi_rate(t)}
        o = WHEELSET.outputs_at(t, x, u, params)
        out.append([*x, o["ddy"], o["ddy_f"]])
        if k == n:
            break
        f = WHEELSET.rhs(params, lambda tt, t=t, u=u: {"xi": u["xi"] + u["xi_rate"] * (tt - t),
                                                       "xi_rate": u["xi_rate"]})
        sol = solve_ivp(f, (t, t + h), x, method="DOP853", rtol=1e-12, atol=1e-15)
        x = sol.y[:, -1]
    return np.array(out)


def test_fmu_equals_python_definition(fmu_dir):
    """Harmonic alignment (1 mm, 20 m wavelength at 20 m/s = 1 Hz) plus a faster 5 m wave:
    every state and both accelerations agree with scipy to 1e-6 of their range."""
    w1, w2 = 2 * math.pi * 1.0, 2 * math.pi * 4.0
    xi = lambda t: 1e-3 * math.sin(w1 * t) + 2e-4 * math.sin(w2 * t)
    xi_rate = lambda t: 1e-3 * w1 * math.cos(w1 * t) + 2e-4 * w2 * math.cos(w2 * t)
    fmu = run_fmu(fmu_dir, xi, xi_rate, 2.0, 2e-3)
    ref = run_scipy(xi, xi_rate, 2.0, 2e-3)
    scale = np.abs(ref).max(axis=0)
    err = np.abs(fmu - ref).max(axis=0) / scale
    assert err.max() < 1e-6, dict(zip([*STATES, "ddy", "ddy_f"], err))


def test_step_not_multiple_of_integrator_step(fmu_dir):
    """A 0.7 ms communication step with a 0.3 ms internal step lands on the same
    trajectory as scipy (the runtime splits each step into equal sub-steps)."""
    xi = lambda t: 1e-3 * math.sin(2 * math.pi * t)
    xi_rate = lambda t: 1e-3 * 2 * math.pi * math.cos(2 * math.pi * t)
    p = {"integrator_step": 3e-4}
    fmu = run_fmu(fmu_dir, xi, xi_rate, 0.7, 7e-4, p)
    ref = run_scipy(xi, xi_rate, 0.7, 7e-4)
    err = np.abs(fmu - ref).max(axis=0) / np.abs(ref).max(axis=0)
    assert err.max() < 1e-6


def test_steady_state_follows_constant_alignment(fmu_dir):
    """A constant 2 mm alignment: wheelset and frame settle on it, yaw returns to zero."""
    out = run_fmu(fmu_dir, lambda t: 2e-3, lambda t: 0.0, 20.0, 1e-2)
    y, psi, yf = out[-1, 0], out[-1, 1], out[-1, 2]
    assert y == pytest.approx(2e-3, rel=1e-3)
    assert yf == pytest.approx(2e-3, rel=1e-3)
    assert abs(psi) < 1e-8


def test_linearisation_and_modes():
    """A = d(rhs)/dx matches the hand-written entries of eq. 11 and K_d of eq. 16, and the SM
    is stable at 20 m/s with its kinematic mode where Klingel's formula puts it."""
    A, B, C, D = WHEELSET.linearize()
    p = WHEELSET.default_parameters()
    m, mf, g, a, l = p["m"], p["m_f"], p["g"], p["alpha"], p["l"]
    k_grav = (m + mf) * g * a / l
    assert A[3, 0] == pytest.approx(-(k_grav + 2 * p["ky"]) / m)
    assert B[3, 0] == pytest.approx(k_grav / m)  # K_d(1) / m
    assert B[4, 0] == pytest.approx(2 * a * p["f11"] * l / p["r0"] / p["I"])  # K_d(2) / I, eq. 16
    eig = np.linalg.eigvals(A)
    assert eig.real.max() < 0
    # the lightly damped mode is the wheelset's kinematic oscillation: Klingel's frequency
    # V/(2 pi) sqrt(alpha / (r0 l)) = 1.78 Hz, lowered a little by the suspension (1.71 Hz)
    f_klingel = p["V"] / (2 * math.pi) * math.sqrt(a / (p["r0"] * l))
    least_damped = eig[np.argmin(-eig.real / np.abs(eig))]
    assert abs(least_damped.imag) / (2 * math.pi) == pytest.approx(f_klingel, rel=0.06)


def test_a_linearisation_read_back_from_the_cache_is_the_derived_one(tmp_path, monkeypatch):
    """A new process reads (A, B, C, D) from the per-user cache: bit for bit what sympy's
    substitution gives; another parameter value is another entry, with its own matrices."""
    monkeypatch.setenv("RAILFMU_CACHE", str(tmp_path))
    memo = WHEELSET.__dict__.setdefault("_compiled", {}).setdefault("linearized", {})
    saved = dict(memo)
    memo.clear()  # as in a new process
    try:
        first = WHEELSET.linearize({"V": 31.0})
        assert len(list((tmp_path / "linearized").glob("*.npz"))) == 1
        memo.clear()
        again = WHEELSET.linearize({"V": 31.0})  # from the file
        derived = WHEELSET._substituted(WHEELSET._jacobians(), {**WHEELSET.default_parameters(), "V": 31.0},
                                        {v.name: v.start for v in WHEELSET.inputs})
        for a, b, c in zip(first, again, derived):
            assert a.dtype == b.dtype == np.float64 and np.array_equal(a, c) and np.array_equal(b, c)
        other = WHEELSET.linearize({"V": 15.0})
        assert len(list((tmp_path / "linearized").glob("*.npz"))) == 2
        assert not np.array_equal(other[0], first[0])  # the speed is in A (creep forces over V)
    finally:
        memo.clear()
        memo.update(saved)
