"""An FMU as the process model of a sigma-point filter (``fmus/cosim/process_model.py``) and
``ukf_fmu`` (``experiments/engine/fmu_process.py``): TrainLongitudinal's process-model inputs
(``set_state``, ``use_effort_set``) leave every output bit for bit as before when false,
equal the Python twin when true and give the closed forms of a constant-effort step; each
sigma point is one FMU step, bit for bit the twin's; ukf_fmu equals PaperUKF on the twin bit
for bit and on its Python ODE to round-off, on GNSS fixes of a driven run of the FMUs."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest

from railfmu.fmus.cosim.masters import run
from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.fmus.cosim.system import Component
from railfmu.models.train.longitudinal import GAMMA, LOAD_MASS, R0, R1, R2, TARE_MASS, Train

DATA = Path(__file__).parent / "data"
M_EFF = GAMMA * (TARE_MASS + LOAD_MASS)
TRAIN_OUTPUTS = ("s", "v", "acceleration", "effort", "effort_specific", "power", "resistance_specific",
                 "gradient", "gradient_specific", "speed_limit")


def start(fmu_dir, **inputs) -> Slave:
    """The TrainLongitudinal FMU initialised at t = 0 with ``inputs`` (and parameters) set."""
    fmu = Slave(fmu_dir / "TrainLongitudinal.fmu")
    fmu.enter_initialization(0.0)
    for k, v in inputs.items():
        fmu.set(k, v)
    fmu.exit_initialization()
    return fmu


# (command, seconds held in 1 s steps): traction, part traction, coast, brake to a standstill,
# stand, restart, part brake; r2 x 1.5 from 400 s
COMMAND_PLAN = [(1.0, 300), (0.4, 200), (0.0, 300), (-0.5, 200), (0.0, 20), (0.8, 120), (-0.3, 60)]


def test_with_the_new_inputs_false_every_output_is_bit_identical_to_before(fmu_dir):
    """tests/data/train_command_plan.csv was recorded with the TrainLongitudinal FMU before
    these inputs existed (the shipped line, COMMAND_PLAN): every 20th row as text (repr:
    exact), all 1201 rows as a SHA-256. The FMU now gives the same bits, and so does its twin."""
    fmu, twin = start(fmu_dir), Train()
    rows, t = [[0.0, 0.0, *(fmu.get(o) for o in TRAIN_OUTPUTS)]], 0.0
    for u, n in COMMAND_PLAN:
        for _ in range(n):
            r2 = R2 * (1.5 if t >= 400 else 1.0)
            fmu.set("command", u), fmu.set("r2", r2)
            twin.u.update(command=u, r2=r2)
            fmu.do_step(t, 1.0)
            twin.step(1.0)
            t += 1.0
            rows.append([t, u, *(fmu.get(o) for o in TRAIN_OUTPUTS)])
            out = twin.outputs()
            assert rows[-1][2:] == [out[o] for o in TRAIN_OUTPUTS], t
    fmu.close()
    with open(DATA / "train_command_plan.csv") as f:
        digest = f.readline().split()[-1]
        header = f.readline().strip().split(",")
        ref = np.array([[float(x) for x in line.split(",")] for line in f])
    assert header == ["time", "command", *TRAIN_OUTPUTS]
    data = np.ascontiguousarray(rows, dtype="<f8")
    assert data.shape == (1201, len(header)) and 0.0 in data[:, 3]  # it stood still once
    assert np.array_equal(data[::20], ref)
    assert hashlib.sha256(data.tobytes()).hexdigest() == digest


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


# ---- the process model -----------------------------------------------------------------------
TRAIN_COLUMNS = (("s_set", "s"), ("v_set", "v"), ("r0", None), ("r1", None), ("r2", None))
PROCESS = dict(known=("effort_set",), fixed={"set_state": True, "use_effort_set": True})


def twin_process(line=None):
    """The process model with the FMU's Python twin, one ``Train`` per sigma point: the FMU's
    arithmetic, operation for operation (independent of railfmu.estimators.train.running_resistance)."""
    from railfmu.models.track.line_profile import DEFAULT_LINE, LineProfile

    ln = line if isinstance(line, LineProfile) else LineProfile.read(line or DEFAULT_LINE)

    def f(X, u, t, dt):
        Y = X.copy()
        for i, (s, v, r0, r1, r2) in enumerate(X.tolist()):
            tr = Train(line=ln)
            tr.u.update(r0=r0, r1=r1, r2=r2, set_state=True, s_set=s, v_set=v, use_effort_set=True,
                        effort_set=float(u))
            tr.step(dt)
            Y[i, :2] = tr.s, tr.v
        return Y
    return f


def sigma_like_points(s=12000.0, v=25.0):
    """Eleven points around (s, v, R0, R1, R2), some at and below v = 0 (the at-rest rule)."""
    X = np.tile([s, v, R0, R1, R2], (11, 1))
    X[1:6] += np.diag([3.0, 0.5, 2e-3, 1e-4, 1e-5])
    X[6:11] -= np.diag([3.0, 0.5, 2e-3, 1e-4, 1e-5])
    return np.vstack([X, [[100.0, 0.0, R0, R1, R2], [100.0, -1e-3, R0, R1, R2]]])


def test_each_sigma_point_is_one_fmu_step_bit_for_bit(fmu_dir):
    """Consecutive filter steps (the instance follows the filter's clock), a second call at
    the same time (from the snapshot), a restarted filter (back to t = 0: the instance is
    reset), efforts of both signs: every row equals the twin started from it."""
    from railfmu.fmus.cosim.process_model import FmuProcessModel

    pm = FmuProcessModel(fmu_dir / "TrainLongitudinal.fmu", TRAIN_COLUMNS, **PROCESS)
    twin = twin_process()
    X = sigma_like_points()
    for t, u in [(0.0, 0.3), (10.0, -0.4), (10.0, 0.2), (20.0, 0.0), (0.0, 0.1), (10.0, 0.25)]:
        Y = pm(X, u, t, 10.0)
        np.testing.assert_array_equal(Y, twin(X, u, t, 10.0))
        np.testing.assert_array_equal(Y[:, 2:], X[:, 2:])
        if u < 0:  # at rest under a brake: held, no roll-back (v = -1 mm/s ends at 0)
            np.testing.assert_array_equal(Y[-2:, :2], [[100.0, 0.0], [100.0, 0.0]])
    assert (Y[-2:, 1] > 0).all() and (Y[-2:, 0] > 100.0).all()  # traction > r0: they start
    assert (pm.steps, pm.points) == (6, 6 * len(X))
    pm.close()
    Y2 = pm(X, 0.25, 0.0, 10.0)  # a closed process model opens a new instance
    np.testing.assert_array_equal(Y2, Y)
    pm.close()


def test_the_component_parameters_are_the_instances(fmu_dir, tmp_path):
    """A 10 per mille uphill line and a heavier train given as parameters: the FMU process
    model uses them (the twin with the same line and mass agrees; the default line does not)."""
    from railfmu.fmus.cosim.process_model import FmuProcessModel

    line = tmp_path / "uphill.csv"
    line.write_text("position_m,gradient_permille,speed_limit_kmh\n0,10,200\n100000,10,200\n")
    pm = FmuProcessModel(fmu_dir / "TrainLongitudinal.fmu", TRAIN_COLUMNS, **PROCESS,
                         parameters={"line_file": str(line), "tare_mass": 400e3})
    X = sigma_like_points()[:11]
    Y = pm(X, 0.2, 0.0, 10.0)
    np.testing.assert_array_equal(Y, twin_process(line)(X, 0.2, 0.0, 10.0))
    assert not np.array_equal(Y, twin_process()(X, 0.2, 0.0, 10.0))
    assert pm.value("tare_mass") == 400e3 and pm.resource(pm.value("line_file")) == line
    assert pm.resource("line.csv").read_text() == Path(DATA.parent.parent / "models" / "data" /
                                                        "eindhoven_hertogenbosch_like_line.csv").read_text()
    pm.close()


def test_an_fmu_that_cannot_save_its_state_is_refused_in_one_line(fmu_dir, tmp_path):
    import zipfile

    from railfmu.fmus.cosim.process_model import FmuProcessModel, ProcessModelError

    src, dst = fmu_dir / "TrainLongitudinal.fmu", tmp_path / "TrainLongitudinal.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'canGetAndSetFMUstate="true"', b'canGetAndSetFMUstate="false"')
            zout.writestr(item, data)
    with pytest.raises(ProcessModelError, match=r"TrainLongitudinal.fmu \(process_model\) as a process model: "
                                                r"it cannot save and restore its state"):
        FmuProcessModel(dst, TRAIN_COLUMNS, **PROCESS)
    with pytest.raises(ProcessModelError, match="no variable 's_set'"):
        FmuProcessModel(fmu_dir / "GnssReceiver.fmu", TRAIN_COLUMNS, **PROCESS)
    with pytest.raises(ProcessModelError, match="effort is a\\(n\\) output, expected an input"):
        FmuProcessModel(fmu_dir / "TrainLongitudinal.fmu", TRAIN_COLUMNS, known=("effort",))


# ---- ukf_fmu -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def gnss_fixes(fmu_dir):
    """The GNSS fixes (t, z = (position, speed)) of the driven run of seed 1 and the truth there."""
    from test_driver import train_system

    res = run(train_system(fmu_dir, 1), progress=False)
    c = {n: res.data[:, i] for i, n in enumerate(res.columns)}
    fix = c["gnss.valid"] > 0.5
    return c["time"][fix], np.c_[c["gnss.position"][fix], c["gnss.speed_kmh"][fix] / 3.6], c["train.s"][fix], c["train.v"][fix]


def ukf_fmu(fmu_dir, parameters=None):
    from railfmu.experiments.engine.fmu_process import FmuPaperUKF, process_model

    train = Component("train", fmu_dir / "TrainLongitudinal.fmu", dict(parameters or {}))
    return FmuPaperUKF(10.0, process=process_model(FmuPaperUKF, train, "Observer 'ukf_fmu'", "ukf_fmu"))


def test_ukf_fmu_equals_the_ukf_on_the_fmus_twin_bit_for_bit(fmu_dir, gnss_fixes):
    """PaperUKF with the twin as its process (the FMU's arithmetic in Python) gives the same
    estimates and covariance as with the FMU, bit for bit: the FMU process model adds nothing
    (first 12 fixes: the start from rest and the traction phase)."""
    from railfmu.estimators.train.running_resistance import PaperUKF

    t, z, _, _ = gnss_fixes
    f, ref = ukf_fmu(fmu_dir), PaperUKF(10.0, process=twin_process())
    np.testing.assert_array_equal(f.run(t[:12], z[:12]), ref.run(t[:12], z[:12]))
    np.testing.assert_array_equal(f.P, ref.P)
    d = f.finish()
    assert d["process_steps"] == 11 and d["process_sigma_points"] == 11 * 11
    f.close()


def test_ukf_fmu_equals_the_python_ode_process_bit_for_bit(fmu_dir, gnss_fixes):
    """PaperUKF's ``"ode"`` process is the FMU's RK4 with r(v) summed in the FMU's order: the
    FMU-process UKF equals it bit for bit, estimates and covariance (before the sums were
    ordered alike the sigma-point weights, 1.7e5, amplified the ulp differences to 1.4e-3
    sigma over the run)."""
    from railfmu.estimators.train.running_resistance import PaperUKF

    t, z, _, _ = gnss_fixes
    f, ode = ukf_fmu(fmu_dir), PaperUKF(10.0, process="ode")
    E, O = f.run(t[:50], z[:50]), ode.run(t[:50], z[:50])
    np.testing.assert_array_equal(E, O)
    np.testing.assert_array_equal(f.covariance, ode.covariance)
    f.close()


def test_ukf_fmu_against_the_papers_discrete_process(fmu_dir, gnss_fixes):
    """The whole run against PaperUKF with eq. 4, both with the paper's effort (eq. 1
    inverted with eq. 4's constant acceleration over the 10 s) and Q = 0. Measured on seed 1:
    speed rms 0.8-1.0 km/h against 0.28-0.29, position rms 80-110 m against 4-5 m, final
    r0-r2 within 0.6 % of each other (the ranges: the Driver with and without its 30 s
    dwell at the platform). Under eq. 1 the held effort does not reproduce the measured speed
    change (r(v) grows as the train accelerates), and the filter, sure of its state (Q = 0),
    does not correct it."""
    from railfmu.estimators.train.running_resistance import PaperUKF

    t, z, s_true, v_true = gnss_fixes
    f, disc = ukf_fmu(fmu_dir), PaperUKF(10.0)
    E, D = f.run(t, z), disc.run(t, z)

    def rms(x):
        return float(np.sqrt(np.mean(x * x)))

    assert 3.6 * rms(D[:, 1] - v_true) < 0.35 and rms(D[:, 0] - s_true) < 6.0
    assert 0.6 < 3.6 * rms(E[:, 1] - v_true) < 1.3 and 50 < rms(E[:, 0] - s_true) < 160
    np.testing.assert_allclose(E[-1, 2:5], D[-1, 2:5], rtol=1e-2)
    f.close()


def test_ukf_fmu_with_the_effort_its_process_needs_tracks_as_eq_4(fmu_dir, gnss_fixes):
    """effort="process": the effort whose FMU prediction of the centre point reproduces the
    measured speed change. Measured on seed 1: speed rms 0.28-0.29 km/h, position rms 3.8-4.9
    m, as eq. 4, final r0-r2 within 2e-6 of eq. 4's; three FMU process calls per fix."""
    from railfmu.estimators.train.running_resistance import PaperUKF
    from railfmu.experiments.engine.fmu_process import FmuPaperUKF, process_model

    t, z, s_true, v_true = gnss_fixes
    train = Component("train", fmu_dir / "TrainLongitudinal.fmu", {})
    f = FmuPaperUKF(10.0, process=process_model(FmuPaperUKF, train, "x", "ukf_fmu"), effort="process")
    E, D = f.run(t, z), PaperUKF(10.0).run(t, z)
    assert 3.6 * np.sqrt(np.mean((E[:, 1] - v_true) ** 2)) < 0.35
    assert np.sqrt(np.mean((E[:, 0] - s_true) ** 2)) < 6.0
    np.testing.assert_allclose(E[-1, 2:5], D[-1, 2:5], rtol=1e-4)
    assert f.finish()["process_steps"] == 3 * (len(t) - 1)
    with pytest.raises(ValueError, match="effort must be 'paper' or 'process'"):
        FmuPaperUKF(10.0, process=f.process, effort="measured")
    f.close()


def ssd(observers: str, line: Path, stop: float = 200.0) -> str:
    """TrainLongitudinal + Driver + GnssReceiver on ``line`` (both read it), 1 s steps."""
    from railfmu.fmus.ssp.xmltools import RF_NS

    def line_binding(name):
        return (f'<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet '
                f'version="1.0" name="{name}"><ssv:Parameters><ssv:Parameter name="line_file"><ssv:String '
                f'value="{line}"/></ssv:Parameter></ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues>'
                f'</ssd:ParameterBinding></ssd:ParameterBindings>')

    return f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="train" xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:rf="{RF_NS}">
  <ssd:System name="train">
    <ssd:Elements>
      <ssd:Component name="train" source="TrainLongitudinal.fmu">{line_binding("train")}</ssd:Component>
      <ssd:Component name="driver" source="Driver.fmu">{line_binding("driver")}</ssd:Component>
      <ssd:Component name="gnss" source="GnssReceiver.fmu"/>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="driver" startConnector="command" endElement="train" endConnector="command"/>
      <ssd:Connection startElement="train" startConnector="s" endElement="driver" endConnector="s"/>
      <ssd:Connection startElement="train" startConnector="v" endElement="driver" endConnector="v"/>
      <ssd:Connection startElement="train" startConnector="speed_limit" endElement="driver" endConnector="speed_limit"/>
      <ssd:Connection startElement="train" startConnector="s" endElement="gnss" endConnector="s_true"/>
      <ssd:Connection startElement="train" startConnector="v" endElement="gnss" endConnector="v_true"/>
    </ssd:Connections>
    <ssd:Annotations>
      <ssc:Annotation type="org.railfmu.observers"><rf:Observers>{observers}</rf:Observers></ssc:Annotation>
      <ssc:Annotation type="org.railfmu.recorder"><rf:Recorder>
        <rf:Record connector="gnss.position"/><rf:Record connector="gnss.speed"/><rf:Record connector="gnss.valid"/>
      </rf:Recorder></ssc:Annotation>
    </ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop}">
    <ssd:Annotations><ssc:Annotation type="org.railfmu.experiment"><rf:FixedStep stepSize="1"/></ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def ukf_observer(name="ukf_fmu", cls="resistance_ukf_fmu", component="train") -> str:
    setting = f'<rf:Setting name="process_component" value="{component}"/>' if component else ""
    return (f'<rf:Observer name="{name}" class="{cls}" sampling="event" samplePeriod="10">'
            '<rf:Measurement name="position" connector="gnss.position" valid="gnss.valid"/>'
            f'<rf:Measurement name="speed" connector="gnss.speed" valid="gnss.valid"/>{setting}</rf:Observer>')


@pytest.fixture
def hilly_line(tmp_path):
    """The shipped line's speed limits with gradients of +-4 per mille every 500 m."""
    p = tmp_path / "hilly.csv"
    rows = ["position_m,gradient_permille,speed_limit_kmh"]
    rows += [f"{k * 500},{4.0 if k % 2 else -4.0},{40 if k < 3 else 140}" for k in range(40)]
    p.write_text("\n".join(rows) + "\n")
    return p


def test_ukf_fmu_in_an_ssd_takes_the_components_fmu_and_parameters(fmu_dir, tmp_path, hilly_line):
    """Declared in the SSD with process_component="train": the bank builds the process model
    from the train component (its hilly line file), and the estimates equal PaperUKF on the
    twin with that line, bit for bit; the instance is freed when the run closes."""
    from railfmu.estimators.train.running_resistance import PaperUKF
    from railfmu.experiments.engine.observer_bank import ObserverBank
    from railfmu.experiments.engine.recorder import ArrayRecorder
    from railfmu.fmus.ssp import read_system

    (tmp_path / "exp").mkdir()
    (tmp_path / "exp" / "SystemStructure.ssd").write_text(ssd(ukf_observer(), hilly_line))
    system = read_system(tmp_path / "exp", fmu_dirs=[fmu_dir])
    bank, rec = ObserverBank(system, None), ArrayRecorder()
    res = run(system, "jacobi", sinks=[rec, bank], progress=False)
    c = {n: res.data[:, i] for i, n in enumerate(res.columns)}
    obs = bank.observers[0]
    assert obs.process.slave is None  # closed with the run
    assert len(obs.line.line.position) == 40 and obs.line.line.gradient[1] == 4.0  # the component's line
    t, est = bank.arrays()
    fix = c["gnss.valid"] > 0.5
    ref = PaperUKF(10.0, process=twin_process(hilly_line), line_file=str(hilly_line))
    expect = ref.run(c["time"][fix], np.c_[c["gnss.position"][fix], c["gnss.speed"][fix]])
    np.testing.assert_array_equal(est[fix], expect)
    assert bank.metrics(c)["ukf_fmu"]["process_steps"] == fix.sum() - 1


@pytest.mark.parametrize("observer, message", [
    (ukf_observer(component="track"), "Observer 'ukf_fmu': process_component 'track' is not a component"),
    (ukf_observer(component="gnss"), "Observer 'ukf_fmu': process_component 'gnss': GnssReceiver.fmu (ukf_fmu process model) as a "
                                      "process model: no variable 's_set'"),
    (ukf_observer(cls="resistance_ukf_paper"), "PaperUKF takes no FMU process model"),
    (ukf_observer(component=""), "ukf_fmu': bad settings: needs the setting process_component"),
])
def test_a_bad_process_component_is_one_line(fmu_dir, tmp_path, hilly_line, observer, message):
    from railfmu.experiments.engine.observer_bank import ObserverBank
    from railfmu.models.errors import UserError
    from railfmu.fmus.ssp import read_system

    (tmp_path / "exp").mkdir()
    (tmp_path / "exp" / "SystemStructure.ssd").write_text(ssd(observer, hilly_line))
    system = read_system(tmp_path / "exp", fmu_dirs=[fmu_dir])
    with pytest.raises(UserError) as err:
        ObserverBank(system, None)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_failing_sigma_point_names_itself_and_the_next_call_recovers(fmu_dir):
    """v = 1e200 m/s overflows r2 v^2: the FMU's own message, the sigma point and the step are
    in one line; the next call at the same time restores the snapshot and is exact again."""
    from railfmu.fmus.cosim.process_model import FmuProcessModel

    pm = FmuProcessModel(fmu_dir / "TrainLongitudinal.fmu", TRAIN_COLUMNS, **PROCESS)
    X = sigma_like_points()[:3]
    pm(X, 0.1, 0.0, 10.0)
    bad = X.copy()
    bad[1, 1] = 1e200
    with pytest.raises(FMUError) as err:
        pm(bad, 0.1, 10.0, 10.0)
    msg = str(err.value)
    assert "TrainLongitudinal.fmu (process_model): sigma point 1 [" in msg and "fmi2DoStep (step from t = 10 s, dt = 10 s)" in msg
    assert "state v became" in msg and "\n" not in msg
    np.testing.assert_array_equal(pm(X, 0.1, 10.0, 10.0), twin_process()(X, 0.1, 10.0, 10.0))
    pm.close()
