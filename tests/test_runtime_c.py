"""Tests of the shared FMI 2.0 Co-Simulation runtime (fmus/native/runtime/fmi2_runtime.c).

The runtime is compiled with a small hand-written model (tests/data/oscillator/: a damped
oscillator dx/dt = v, dv/dt = -k x - c v + u with a first-order-hold input u, rate du) under
the same flags as every FMU, and driven through fmpy's FMU2Slave.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
from ctypes import CFUNCTYPE, byref, c_char_p, c_int, c_void_p, cast
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2CoSimulation,
    fmi2DoStepStatus,
    fmi2LastSuccessfulTime,
    fmi2ModelExchange,
    fmi2PendingStatus,
    fmi2Terminated,
)

ROOT = Path(__file__).resolve().parents[1]
RUNTIME = ROOT / "fmus" / "native" / "runtime"
DATA = ROOT / "tests" / "data" / "oscillator"
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
CFLAGS = ["-std=c99", "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror"]
# e.g. RAILFMU_EXTRA_CFLAGS="-fsanitize=address,undefined -fno-sanitize-recover=all" with
# LD_PRELOAD=$(gcc -print-file-name=libasan.so) ASAN_OPTIONS=detect_leaks=0
EXTRA_CFLAGS = os.environ.get("RAILFMU_EXTRA_CFLAGS", "").split()

GUID = "{5b2f6a0e-railfmu-test-oscillator-0001}"
ID = "oscillator"
# value references (tests/data/oscillator/model_config.h)
TIME, K, C, U, DU, X, V, A, H_INT, NAN_TIME = range(10)
NAN_MODE = 0  # Integer
DAMPING_ON = 0  # Boolean
DATA_FILE, DATA_PATH = 0, 1  # String

FMI2_STATUS_DISCARD, FMI2_STATUS_ERROR = 2, 3

pytestmark = pytest.mark.skipif(
    shutil.which("gcc") is None or fmpy.platform != "linux64", reason="needs gcc on linux64"
)


# ---- building and driving the FMU ------------------------------------------------------

@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory) -> Path:
    """An unzipped FMU; the space in its path makes the resource URI percent-encoded."""
    d = tmp_path_factory.mktemp("runtime") / "osc fmu"
    (d / "binaries" / "linux64").mkdir(parents=True)
    (d / "resources").mkdir()
    shutil.copy(DATA / "modelDescription.xml", d)
    cmd = [
        "gcc", *CFLAGS, *EXTRA_CFLAGS, f"-I{FMI_HEADERS}", f"-I{DATA}", f"-I{RUNTIME}",
        str(RUNTIME / "fmi2_runtime.c"), str(DATA / "oscillator.c"),
        "-o", str(d / "binaries" / "linux64" / f"{ID}.so"),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, f"compilation failed (warnings are errors):\n{res.stderr}"
    return d


# The FMI logger is variadic: logger(env, instance, status, category, message, ...). The
# runtime passes the finished text as the message, '%' doubled and no arguments, so a plain
# ctypes logger reads it without fmpy's addLoggerProxy (which keeps one global Python target
# per process and would mix up the instances of these tests).
LoggerType = CFUNCTYPE(None, c_void_p, c_char_p, c_int, c_char_p, c_char_p)


class Log(list):
    """(instance, status, category, message) tuples received by the logger."""

    def text(self) -> str:
        return "\n".join(m for _, _, _, m in self)

    def errors(self) -> list[str]:
        return [m for _, s, c, m in self if s == FMI2_STATUS_ERROR and c == "logStatusError"]


def make_callbacks(log: Log, allocators: bool = False) -> fmi2CallbackFunctions:
    def logger(env, instance, status, category, message):
        log.append((instance.decode(), status, category.decode(), message.decode().replace("%%", "%")))

    cb = fmi2CallbackFunctions()
    cb._py_logger = LoggerType(logger)  # keep the thunk alive
    cb.logger = cast(cb._py_logger, fmi2CallbackLoggerTYPE)
    if allocators:  # the runtime never uses them; NULL must be fine (see test below)
        from fmpy.fmi2 import defaultCallbacks

        cb.allocateMemory = defaultCallbacks.allocateMemory
        cb.freeMemory = defaultCallbacks.freeMemory
    return cb


@pytest.fixture
def new_slave(fmu_dir):
    """Factory: an instantiated FMU2Slave with .log; freed at teardown."""
    slaves = []

    def make(name="osc", logging_on=False, allocators=True, instantiate=True):
        s = FMU2Slave(guid=GUID, unzipDirectory=str(fmu_dir), modelIdentifier=ID,
                      instanceName=name)
        s.log = Log()
        s.cb = make_callbacks(s.log, allocators)
        s.component = None
        if instantiate:
            s.instantiate(callbacks=s.cb, loggingOn=logging_on)
        slaves.append(s)
        return s

    yield make
    for s in slaves:
        if s.component:
            s.freeInstance()


def get_str(s, vr: int) -> str:
    return s.getString([vr])[0].decode()


def start(s, start_time=0.0, stop_time=None, reals=None, integers=None):
    """SetupExperiment, set parameters/initial states, initialise."""
    s.setupExperiment(startTime=start_time, stopTime=stop_time)
    s.enterInitializationMode()
    if reals:
        s.setReal(list(reals), list(reals.values()))
    if integers:
        s.setInteger(list(integers), list(integers.values()))
    s.exitInitializationMode()


def analytic(t, k, c, x0, v0, u0, du):
    """x'' + c x' + k x = u0 + du t (underdamped), x(0) = x0, x'(0) = v0."""
    beta = du / k
    alpha = (u0 - c * beta) / k
    y0, yd0 = x0 - alpha, v0 - beta
    s = c / 2
    wd = math.sqrt(k - s * s)
    A, B = y0, (yd0 + s * y0) / wd
    e, co, si = np.exp(-s * t), np.cos(wd * t), np.sin(wd * t)
    x = alpha + beta * t + e * (A * co + B * si)
    v = beta + e * ((-s * A + wd * B) * co + (-s * B - wd * A) * si)
    return x, v


def rk4_reference(x, v, t0, h, hmax, k, c, u, du):
    """The runtime's integration written out in Python with the same operations in the same
    order (C99 mode: no FMA contraction), so the results must be bit-identical."""
    q = h / hmax - 1e-9
    n = max(int(q) + (1 if int(q) < q else 0), 1)
    dt = h / n

    def f(t, x_, v_):
        uu = u + du * (t - t0)
        return v_, -k * x_ - c * v_ + uu

    for step in range(n):
        t = t0 + step * dt
        k1 = f(t, x, v)
        k2 = f(t + 0.5 * dt, x + 0.5 * dt * k1[0], v + 0.5 * dt * k1[1])
        k3 = f(t + 0.5 * dt, x + 0.5 * dt * k2[0], v + 0.5 * dt * k2[1])
        k4 = f(t + dt, x + dt * k3[0], v + dt * k3[1])
        x = x + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        v = v + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
    return x, v, n


def run(s, t0, h, n_steps, u0=0.0, du=0.0):
    """n_steps communication steps; u follows the ramp u0 + du t. Returns rows t, x, v, a."""
    rows, t = [], t0
    for _ in range(n_steps):
        s.setReal([U, DU], [u0 + du * t, du])
        s.doStep(t, h)
        t = t + h
        rows.append([t, *s.getReal([X, V, A])])
    return np.array(rows), t


# ---- the binary ------------------------------------------------------------------------

CS_FUNCTIONS = """GetTypesPlatform GetVersion SetDebugLogging Instantiate FreeInstance
SetupExperiment EnterInitializationMode ExitInitializationMode Terminate Reset GetReal
GetInteger GetBoolean GetString SetReal SetInteger SetBoolean SetString GetFMUstate
SetFMUstate FreeFMUstate SerializedFMUstateSize SerializeFMUstate DeSerializeFMUstate
GetDirectionalDerivative SetRealInputDerivatives GetRealOutputDerivatives DoStep CancelStep
GetStatus GetRealStatus GetIntegerStatus GetBooleanStatus GetStringStatus""".split()


def test_exports_all_cs_functions_and_no_me_ones(fmu_dir):
    def nm(*flags):
        lib = fmu_dir / "binaries" / "linux64" / f"{ID}.so"
        res = subprocess.run(["nm", "-D", *flags, str(lib)], capture_output=True, text=True,
                             check=True)
        return {line.split()[-1] for line in res.stdout.splitlines()}

    exported = nm("--defined-only")
    assert {f"fmi2{f}" for f in CS_FUNCTIONS} <= exported
    assert "fmi2GetDerivatives" not in exported and "fmi2SetTime" not in exported
    # no dependency on libm, which not every importer loads (isfinite is a macro, the
    # sub-step count is rounded up by hand)
    assert not {"ceil", "fabs"} & {name.split("@")[0] for name in nm("--undefined-only")}


def test_fmpy_validates_and_simulates(fmu_dir):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(fmu_dir)) == []
    res = fmpy.simulate_fmu(str(fmu_dir), stop_time=2.0, output_interval=0.1, output=["x", "v"])
    x, v = analytic(res["time"], 4.0, 0.4, 1.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(res["x"], x, atol=1e-10)
    np.testing.assert_allclose(res["v"], v, atol=1e-10)


# ---- integration -----------------------------------------------------------------------

def test_rk4_matches_analytic_solution_with_first_order_hold_input(new_slave):
    s = new_slave()
    k, c, x0, v0, u0, du = 4.0, 0.4, 0.7, -0.3, 0.3, 0.05
    start(s, reals={K: k, C: c, X: x0, V: v0})
    assert s.getReal([A]) == [pytest.approx(-k * x0 - c * v0)]  # outputs at the start
    rows, t = run(s, 0.0, 0.01, 1000, u0=u0, du=du)
    x, v = analytic(rows[:, 0], k, c, x0, v0, u0, du)
    # RK4 with 1 ms steps: global error ~1e-12. Holding u over a step instead of following
    # du (or evaluating stages at the wrong time) would show errors ~1e-6.
    np.testing.assert_allclose(rows[:, 1], x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(rows[:, 2], v, rtol=0, atol=1e-10)
    # a = dv/dt at the communication point: after a step the FMU extrapolates the input it
    # was given over the step (first-order hold), so u(t) = u0 + du t exactly here
    np.testing.assert_allclose(rows[:-1, 3], -k * rows[:-1, 1] - c * rows[:-1, 2]
                               + (u0 + du * rows[:-1, 0]), atol=1e-12)
    assert s.getReal([TIME]) == [t]


def test_step_that_is_not_a_multiple_of_the_internal_step_lands_exactly(new_slave):
    s = new_slave()
    start(s, reals={H_INT: 1e-3})
    t, x, v = 0.0, 1.0, 0.0
    for h in [0.0123456, 0.0025, 1e-4, 0.003, 0.0030000000001, 0.1 / 3]:
        s.setReal([U, DU], [0.2, 0.1])
        s.doStep(t, h)
        x, v, _ = rk4_reference(x, v, t, h, 1e-3, 4.0, 0.4, 0.2, 0.1)
        t = t + h
        got_t, got_x, got_v = s.getReal([TIME, X, V])
        assert got_t == t  # exactly t + h, whatever h is
        assert (got_x, got_v) == (x, v)  # bit-identical: same sub-steps, same stage times
        assert s.getRealStatus(fmi2LastSuccessfulTime) == t
    # the sub-step counts the reference used: ceil(h / 1e-3) with a 1e-9 slack
    assert [rk4_reference(0, 0, 0, h, 1e-3, 1, 0, 0, 0)[2]
            for h in [0.0123456, 0.0025, 1e-4, 0.003, 0.1 / 3]] == [13, 3, 1, 3, 34]


# ---- state machine and setting rules ---------------------------------------------------

def test_illegal_call_sequences_are_errors_and_logged(new_slave):
    s = new_slave(logging_on=False)  # errors are logged even with debug logging off
    with pytest.raises(FMICallException):
        s.doStep(0.0, 0.1)
    assert "fmi2DoStep" in s.log.errors()[-1] and "Instantiated" in s.log.errors()[-1]
    with pytest.raises(FMICallException):
        s.getReal([X])  # nothing computed before initialisation
    with pytest.raises(FMICallException):
        s.exitInitializationMode()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    with pytest.raises(FMICallException):
        s.enterInitializationMode()
    assert "fmi2EnterInitializationMode" in s.log.errors()[-1]
    assert "InitializationMode" in s.log.errors()[-1]
    with pytest.raises(FMICallException):
        s.terminate()
    with pytest.raises(FMICallException):
        s.doStep(0.0, 0.1)
    s.exitInitializationMode()
    with pytest.raises(FMICallException):
        s.setupExperiment(startTime=1.0)
    assert "fmi2SetupExperiment" in s.log.errors()[-1] and "StepComplete" in s.log.errors()[-1]
    # the refused calls changed nothing: the instance still works
    s.doStep(0.0, 0.1)
    s.terminate()
    with pytest.raises(FMICallException):
        s.doStep(0.1, 0.1)
    assert "Terminated" in s.log.errors()[-1]
    assert s.getReal([TIME]) == [0.1]  # still readable after terminate
    assert all(inst == "osc" for inst, *_ in s.log)


def test_set_rules_by_causality_variability_and_state(new_slave):
    s = new_slave()

    def refused(fn, vrs, values, *words):
        with pytest.raises(FMICallException) as e:
            fn(vrs, values)
        assert e.value.status == FMI2_STATUS_ERROR
        for w in words:
            assert w in s.log.errors()[-1], s.log.errors()[-1]

    refused(s.setReal, [TIME], [1.0], "time", "independent")
    refused(s.setReal, [A], [1.0], "variable a", "output")
    refused(s.setString, [DATA_PATH], ["x"], "data_path", "calculatedParameter")
    refused(s.setReal, [99], [1.0], "value reference 99", "out of range")
    refused(s.setInteger, [5], [1], "value reference 5", "out of range")
    refused(s.setReal, [K], [float("nan")], "k", "not finite")
    # before/in initialisation: parameters, inputs, states
    s.setReal([K, C, U, X, V, H_INT], [5.0, 0.1, 0.5, 0.2, 0.3, 2e-3])
    s.setInteger([NAN_MODE], [0])
    s.setBoolean([DAMPING_ON], [True])
    s.setString([DATA_FILE], ["other.csv"])
    start(s)
    assert s.getReal([K, C, U, X, V, H_INT]) == [5.0, 0.1, 0.5, 0.2, 0.3, 2e-3]
    with pytest.raises(FMICallException):
        s.getReal([10])
    assert "out of range" in s.log.errors()[-1]
    # after initialisation: inputs and tunable parameters only
    refused(s.setReal, [X], [0.0], "variable x", "only inputs and tunable parameters")
    refused(s.setReal, [K], [1.0], "variable k")
    refused(s.setInteger, [NAN_MODE], [1], "nan_mode")
    refused(s.setString, [DATA_FILE], ["y"], "data_file")
    # a refused batch changes nothing, even its valid entries
    refused(s.setReal, [U, A], [9.0, 9.0], "variable a")
    assert s.getReal([U]) == [0.5]
    s.setReal([U, DU, C], [1.0, 0.5, 0.2])
    # a tunable parameter is checked again when it changes during the run
    refused(s.setReal, [C, U], [-0.1, 2.0], "parameter c = -0.1 is below its minimum 0")
    assert s.getReal([C, U]) == [0.2, 1.0]  # the refused call changed nothing
    s.setBoolean([DAMPING_ON], [False])
    assert s.getBoolean([DAMPING_ON]) == [False]
    s.doStep(0.0, 0.1)


def test_negative_parameter_fails_at_exit_initialization_mode(new_slave):
    s = new_slave()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal([K], [-1.0])
    with pytest.raises(FMICallException) as e:
        s.exitInitializationMode()
    assert e.value.status == FMI2_STATUS_ERROR
    # the model's message is the last one: importers such as libcosim show only that
    assert "parameter k = -1 is below its minimum 0" in s.log.errors()[-1]
    # still in initialisation mode: the importer can correct the value
    s.setReal([K], [1.0])
    s.exitInitializationMode()
    s.doStep(0.0, 0.1)


def test_integrator_step_must_be_positive(new_slave):
    s = new_slave()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal([H_INT], [0.0])
    with pytest.raises(FMICallException):
        s.exitInitializationMode()
    assert "integrator_step" in s.log.errors()[-1]


def test_do_step_argument_errors_leave_the_instance_usable(new_slave):
    s = new_slave()
    start(s, start_time=1.0, stop_time=1.25)
    assert s.getReal([TIME]) == [1.0]
    with pytest.raises(FMICallException):
        s.doStep(1.5, 0.1)  # not the FMU's time
    assert "currentCommunicationPoint" in s.log.errors()[-1]
    with pytest.raises(FMICallException):
        s.doStep(1.0, 0.0)
    assert "communicationStepSize" in s.log.errors()[-1]
    with pytest.raises(FMICallException):
        s.doStep(1.0, -0.1)
    with pytest.raises(FMICallException):
        s.doStep(1.0, 0.5)  # past stopTime
    assert "stopTime" in s.log.errors()[-1]
    s.doStep(1.0 + 1e-12, 0.125)  # round-off in the importer's time is tolerated
    s.doStep(1.125, 0.125)  # lands on stopTime
    assert s.getReal([TIME]) == [1.25]


def test_nan_state_is_an_error_naming_the_state_and_time(new_slave):
    s = new_slave()
    start(s, reals={NAN_TIME: 0.25}, integers={NAN_MODE: 1})
    s.doStep(0.0, 0.2)
    saved = s.getFMUstate()
    with pytest.raises(FMICallException):
        s.doStep(0.2, 0.2)
    msg = s.log.errors()[-1]
    # dv/dt is NaN from t = 0.25 on: the last RK4 stage of the internal step [0.249, 0.25]
    # makes v NaN (x only gets it one internal step later)
    assert "state v became nan" in msg and "t = 0.249" in msg, msg
    # state Error: values readable for debugging, no more steps, reset allowed
    assert math.isnan(s.getReal([V])[0])
    with pytest.raises(FMICallException):
        s.doStep(0.2, 0.2)
    assert "state Error" in s.log.errors()[-1]
    # a state saved before the failure brings the instance back (FMI 2.0.4, 2.1.8)
    s.setFMUstate(saved)
    s.freeFMUstate(saved)
    s.doStep(0.2, 0.04)
    assert s.getReal([TIME]) == [0.2 + 0.04]
    s.reset()
    start(s)
    assert s.getReal([X, V, TIME]) == [1.0, 0.0, 0.0]


def test_nan_output_is_an_error_naming_the_output(new_slave):
    s = new_slave()
    start(s, reals={NAN_TIME: 0.3}, integers={NAN_MODE: 2})
    s.doStep(0.0, 0.2)
    with pytest.raises(FMICallException):
        s.doStep(0.2, 0.2)
    assert "output a" in s.log.errors()[-1] and "t = 0.4" in s.log.errors()[-1]


def test_reset_returns_to_start_values(new_slave):
    s = new_slave()
    start(s, reals={K: 9.0, X: 0.5})
    run(s, 0.0, 0.1, 3, u0=1.0)
    s.reset()
    with pytest.raises(FMICallException):
        s.doStep(0.3, 0.1)  # Instantiated again
    start(s)
    assert s.getReal([TIME, K, X, V, U]) == [0.0, 4.0, 1.0, 0.0, 0.0]


# ---- FMU state -------------------------------------------------------------------------

def test_get_set_fmu_state_reproduces_the_continuation_bit_exactly(new_slave):
    s = new_slave()
    start(s)
    _, t = run(s, 0.0, 0.05, 20, u0=0.1, du=0.2)
    state = s.getFMUstate()
    first, t_end = run(s, t, 0.05, 30, u0=0.1, du=0.2)
    s.setReal([U], [7.0])  # the state also restores inputs
    s.setFMUstate(state)
    assert s.getReal([TIME]) == [t] and s.getReal([U]) == [pytest.approx(0.1 + 0.2 * (t - 0.05))]
    assert s.getRealStatus(fmi2LastSuccessfulTime) == t
    again, _ = run(s, t, 0.05, 30, u0=0.1, du=0.2)
    assert np.array_equal(first, again)  # bit-identical
    # *FMUstate != NULL on entry: that state object is overwritten and returned again
    pointer = state.value
    s.fmi2GetFMUstate(s.component, byref(state))
    assert state.value == pointer
    run(s, t_end, 0.05, 2)
    s.setFMUstate(state)
    assert s.getReal([TIME]) == [t_end]
    s.freeFMUstate(state)
    assert state.value is None


def test_serialize_deserialize_round_trip_into_another_instance(new_slave):
    s = new_slave("a")
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setString([DATA_FILE], ["sub dir/100%.csv"])  # a '%' and a space survive everything
    s.setReal([K, C], [2.5, 0.3])
    s.exitInitializationMode()
    _, t = run(s, 0.0, 0.1, 5, u0=0.4)
    state = s.getFMUstate()
    blob = s.serializeFMUstate(state)
    assert blob[:4] == b"RFMU" and GUID.encode() in blob
    expected, _ = run(s, t, 0.1, 10, u0=0.4)
    path_a = get_str(s, DATA_PATH)
    assert path_a.endswith("/resources/sub dir/100%.csv")
    s.freeFMUstate(state)

    b = new_slave("b")
    start(b)  # different parameters; the state brings its own
    restored = b.deSerializeFMUstate(blob)
    b.setFMUstate(restored)
    assert get_str(b, DATA_FILE) == "sub dir/100%.csv"
    assert get_str(b, DATA_PATH) == path_a
    assert b.getReal([K, C, TIME]) == [2.5, 0.3, t]
    got, _ = run(b, t, 0.1, 10, u0=0.4)
    assert np.array_equal(expected, got)
    assert b.serializeFMUstate(restored) == blob
    b.freeFMUstate(restored)


@pytest.mark.parametrize("damage", ["magic", "guid", "truncated", "trailing", "counts"])
def test_deserialize_rejects_foreign_or_damaged_data(new_slave, damage):
    s = new_slave()
    start(s)
    state = s.getFMUstate()
    blob = bytearray(s.serializeFMUstate(state))
    s.freeFMUstate(state)
    i = blob.find(GUID.encode())
    if damage == "magic":
        blob[0:4] = b"XFMU"
    elif damage == "guid":
        blob[i + 3] ^= 1
    elif damage == "truncated":
        blob = blob[:-3]
    elif damage == "trailing":
        blob += b"\0"
    elif damage == "counts":
        blob[8] += 1  # N_REAL
    with pytest.raises(FMICallException):
        s.deSerializeFMUstate(bytes(blob))
    assert "fmi2DeSerializeFMUstate" in s.log.errors()[-1]


def test_fmu_state_restores_the_state_machine(new_slave):
    s = new_slave()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    early = s.getFMUstate()  # in InitializationMode
    s.exitInitializationMode()
    s.doStep(0.0, 0.1)
    s.setFMUstate(early)
    with pytest.raises(FMICallException):
        s.doStep(0.0, 0.1)  # back in InitializationMode
    s.exitInitializationMode()
    s.doStep(0.0, 0.1)
    s.freeFMUstate(early)


# ---- several instances, logging, status, unsupported functions -------------------------

def test_two_instances_are_independent(new_slave):
    a, b = new_slave("a"), new_slave("b")
    start(a, reals={K: 4.0, X: 1.0})
    start(b, reals={K: 9.0, X: -1.0, C: 0.0})
    ta = tb = 0.0
    ra, rb = [], []
    for _ in range(50):  # interleaved
        a.setReal([U, DU], [0.0, 0.0])
        a.doStep(ta, 0.02)
        ta += 0.02
        ra.append(a.getReal([X, V]))
        b.doStep(tb, 0.03)
        tb += 0.03
        rb.append(b.getReal([X, V]))
    xa, va = analytic(np.arange(1, 51) * 0.02, 4.0, 0.4, 1.0, 0.0, 0.0, 0.0)
    xb, vb = analytic(np.arange(1, 51) * 0.03, 9.0, 0.0, -1.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(np.array(ra), np.c_[xa, va], atol=1e-10)
    np.testing.assert_allclose(np.array(rb), np.c_[xb, vb], atol=1e-10)
    with pytest.raises(FMICallException):
        a.setReal([K], [1.0])
    assert a.log.errors() and not b.log.errors()
    assert {inst for inst, *_ in a.log} == {"a"}


def test_status_queries_and_unsupported_functions(new_slave):
    s = new_slave(logging_on=True)
    start(s, start_time=0.5)
    s.doStep(0.5, 0.25)
    assert s.getRealStatus(fmi2LastSuccessfulTime) == 0.75
    assert s.getBooleanStatus(fmi2Terminated) is False
    for call in (lambda: s.getStatus(fmi2DoStepStatus),
                 lambda: s.getStringStatus(fmi2PendingStatus),
                 lambda: s.getIntegerStatus(fmi2LastSuccessfulTime),
                 lambda: s.getRealStatus(fmi2Terminated)):
        with pytest.raises(FMICallException) as e:
            call()
        assert e.value.status == FMI2_STATUS_DISCARD
    assert any(c == "logStatusWarning" for _, _, c, _ in s.log)
    for call, words in [
        (lambda: s.getDirectionalDerivative([X], [U], [1.0]), "not provided"),
        (lambda: s.cancelStep(), "asynchronous"),
        (lambda: s.setRealInputDerivatives([U], [1], [0.1]), "canInterpolateInputs"),
        (lambda: s.getRealOutputDerivatives([X], [1]), "MaxOutputDerivativeOrder"),
    ]:
        with pytest.raises(FMICallException) as e:
            call()
        assert e.value.status == FMI2_STATUS_ERROR
        assert words in s.log.errors()[-1]
    assert s.getTypesPlatform() == "default" and s.getVersion() == "2.0"


def test_debug_logging_categories(new_slave):
    s = new_slave(logging_on=False)
    start(s)
    with pytest.raises(FMICallException):
        s.getStatus(fmi2DoStepStatus)
    assert not s.log  # a Discard notice is not an error: silent without debug logging
    s.setDebugLogging(True, ["logStatusWarning"])
    with pytest.raises(FMICallException):
        s.getStatus(fmi2DoStepStatus)
    assert [c for _, _, c, _ in s.log] == ["logStatusWarning"]
    s.setDebugLogging(False, ["logStatusWarning"])
    with pytest.raises(FMICallException):
        s.getStatus(fmi2DoStepStatus)
    assert len(s.log) == 1
    with pytest.raises(FMICallException):
        s.setDebugLogging(True, ["noSuchCategory%s%n"])
    assert 'unknown log category "noSuchCategory%s%n"' in s.log.errors()[-1]


def test_no_memory_callbacks_and_no_logger(new_slave):
    s = new_slave(allocators=False)
    start(s)
    run(s, 0.0, 0.1, 3)
    q = new_slave(instantiate=False)
    q.cb.logger = type(q.cb.logger)()  # NULL logger: errors are silent, not a crash
    q.instantiate(callbacks=q.cb)
    with pytest.raises(FMICallException):
        q.doStep(0.0, 1.0)


# ---- instantiation and resources -------------------------------------------------------

def raw_instantiate(s, guid=GUID, kind=fmi2CoSimulation, resources=None, name=b"raw"):
    comp = s.fmi2Instantiate(name, kind, guid.encode(),
                             None if resources is None else resources.encode(),
                             byref(s.cb), 0, 0)
    s.component = comp
    return comp


def test_instantiate_checks_guid_type_and_name(new_slave):
    s = new_slave(instantiate=False)
    assert raw_instantiate(s, guid="{wrong}") is None
    assert "{wrong}" in s.log.errors()[-1] and GUID in s.log.errors()[-1]
    assert raw_instantiate(s, kind=fmi2ModelExchange) is None
    assert "Co-Simulation only" in s.log.errors()[-1]
    assert raw_instantiate(s, name=b"") is None
    assert "instanceName" in s.log.errors()[-1]


def test_resource_paths(new_slave, fmu_dir, tmp_path):
    # fmpy passes file:///.../osc%20fmu/resources
    s = new_slave()
    start(s)
    assert get_str(s, DATA_PATH) == str(fmu_dir / "resources" / "table.csv")
    # an absolute path is kept as it is
    s2 = new_slave("abs")
    s2.setString([DATA_FILE], [str(tmp_path / "x.csv")])
    start(s2)
    assert get_str(s2, DATA_PATH) == str(tmp_path / "x.csv")

    res = "/tmp/some where/resources"
    for location, expected in [
        ("file:///tmp/some%20where/resources", res + "/table.csv"),
        ("file:///tmp/some%20where/resources/", res + "/table.csv"),
        ("file:/tmp/some%20where/resources", res + "/table.csv"),
        ("file://localhost/tmp/some%20where/resources", res + "/table.csv"),
        ("/tmp/plain/resources", "/tmp/plain/resources/table.csv"),
        (None, ""),  # no resource location: nothing to resolve against
    ]:
        r = new_slave(instantiate=False)
        assert raw_instantiate(r, resources=location)
        start(r)
        assert get_str(r, DATA_PATH) == expected, location


# ---- the model ends the simulation (model_terminate) ----------------------------------

def test_model_ends_the_simulation_with_discard_and_terminated(new_slave):
    """FMI 2.0.4, 4.2.3: fmi2DoStep returns fmi2Discard, fmi2Terminated is true, the last
    successful time is where the model stopped, outputs stay readable, no further step."""
    s = new_slave(logging_on=True)
    start(s, reals={NAN_TIME: 0.25}, integers={NAN_MODE: 3})
    s.doStep(0.0, 0.2)
    assert s.getBooleanStatus(fmi2Terminated) is False
    expected = s.getFMUstate()
    with pytest.raises(FMICallException) as e:
        s.doStep(0.2, 0.2)  # reaches t = 0.4 >= 0.25: the model stops there
    assert e.value.status == FMI2_STATUS_DISCARD
    assert s.getBooleanStatus(fmi2Terminated) is True
    assert s.getRealStatus(fmi2LastSuccessfulTime) == 0.4
    t, x, v, a = s.getReal([TIME, X, V, A])
    assert t == 0.4
    s.setFMUstate(expected)  # the same step without the request computes the same values
    x_ok, v_ok = s.getReal([X, V])
    xr, vr, _ = rk4_reference(x_ok, v_ok, 0.2, 0.2, 1e-3, 4.0, 0.4, 0.0, 0.0)
    assert (x, v) == (xr, vr) and a == -4.0 * x - 0.4 * v
    with pytest.raises(FMICallException):
        s.doStep(0.2, 0.2)
    s.terminate()  # StepFailed -> Terminated is legal
    assert s.getReal([TIME]) == [0.4]
    assert any("ended the simulation at t = 0.4" in msg for *_, msg in s.log)
    assert any("reached nan_time" in msg for _, _, c, msg in s.log if c == "logEvents")
    assert not s.log.errors()


def test_model_ends_inside_the_step_at_its_own_time(new_slave):
    s = new_slave()
    start(s, reals={NAN_TIME: 0.3}, integers={NAN_MODE: 4})
    s.doStep(0.0, 0.2)
    with pytest.raises(FMICallException) as e:
        s.doStep(0.2, 0.2)
    assert e.value.status == FMI2_STATUS_DISCARD
    assert s.getRealStatus(fmi2LastSuccessfulTime) == 0.3 and s.getReal([TIME]) == [0.3]
    assert s.getBooleanStatus(fmi2Terminated) is True
    # further steps are illegal calls (state StepFailed), outputs still readable
    with pytest.raises(FMICallException) as e:
        s.doStep(0.3, 0.1)
    assert e.value.status == FMI2_STATUS_ERROR and "StepFailed" in s.log.errors()[-1]


def test_end_requested_at_initialisation_stops_at_the_start(new_slave):
    s = new_slave()
    start(s, start_time=1.0, reals={NAN_TIME: 0.5}, integers={NAN_MODE: 3})
    assert s.getBooleanStatus(fmi2Terminated) is True  # known before the first step
    x0 = s.getReal([X])
    with pytest.raises(FMICallException) as e:
        s.doStep(1.0, 0.1)
    assert e.value.status == FMI2_STATUS_DISCARD
    assert s.getRealStatus(fmi2LastSuccessfulTime) == 1.0
    assert s.getReal([TIME]) == [1.0] and s.getReal([X]) == x0  # nothing computed
    s.reset()  # a reset forgets the request
    start(s)
    assert s.getBooleanStatus(fmi2Terminated) is False
    s.doStep(0.0, 0.1)


def test_the_end_request_is_part_of_the_fmu_state(new_slave):
    s = new_slave("a")
    start(s, reals={NAN_TIME: 0.15}, integers={NAN_MODE: 3})
    s.doStep(0.0, 0.1)
    before = s.getFMUstate()
    with pytest.raises(FMICallException):
        s.doStep(0.1, 0.1)
    after = s.getFMUstate()
    blob = s.serializeFMUstate(after)
    s.setFMUstate(before)  # back to StepComplete, no request
    assert s.getBooleanStatus(fmi2Terminated) is False
    s.setFMUstate(after)
    assert s.getBooleanStatus(fmi2Terminated) is True
    b = new_slave("b")
    start(b)
    restored = b.deSerializeFMUstate(blob)
    b.setFMUstate(restored)
    assert b.getBooleanStatus(fmi2Terminated) is True
    assert b.getRealStatus(fmi2LastSuccessfulTime) == 0.2
    with pytest.raises(FMICallException):
        b.doStep(0.2, 0.1)  # StepFailed
    for st in (before, after):
        s.freeFMUstate(st)
    b.freeFMUstate(restored)


def test_fmpy_simulate_ends_where_the_model_ends(fmu_dir):
    res = fmpy.simulate_fmu(str(fmu_dir), stop_time=2.0, output_interval=0.1,
                            start_values={"nan_mode": 3, "nan_time": 0.95}, output=["x"])
    assert res["time"][-1] == pytest.approx(1.0) and len(res) == 11

