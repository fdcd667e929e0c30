"""Integer, Boolean and String variables and terminate_when in generated FMUs, end to end:
models/base.py -> fmus/generate/codegen.py -> compiled FMU -> FMPy, compared with the same
definition evaluated in Python (Model.outputs_at, Model.terminates)."""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
import zipfile

import fmpy
import pytest
import sympy as sp
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2LastSuccessfulTime, fmi2Terminated

from railfmu.fmus.generate.build import build_fmu, validate
from railfmu.models.base import Input, Model, Output, Parameter, State

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64",
                                reason="needs gcc on linux64")

k, levels, enabled, label = (sp.Symbol(n, real=True) for n in ("k", "levels", "enabled", "label"))
u, gear, valid, x = (sp.Symbol(n, real=True) for n in ("u", "gear", "valid", "x"))

DEMO = Model(
    "DiscreteDemo", "Test model: every FMI 2.0 type as parameter, input and output",
    parameters=[
        Parameter("k", "gain on the speed", "", 2.0, min=0.0),
        Parameter("levels", "number of regimes", start=3, type="Integer", min=1, max=10),
        Parameter("enabled", "integrate only when true", start=True, type="Boolean", tunable=True),
        Parameter("label", "a name, used by no expression", start='a "quoted" <name>', type="String"),
    ],
    inputs=[
        Input("u", "speed", "m/s"),
        Input("gear", "driving regime (integer)", start=1, type="Integer"),
        Input("valid", "the speed is valid", start=False, type="Boolean"),
    ],
    states=[State("x", "distance travelled while valid and enabled", "m", 0.0,
                  der=k * u * valid * enabled)],
    outputs=[
        Output("regime", "gear times levels, plus 1 above 0.5 m/s", type="Integer",
               expr=gear * levels + sp.Piecewise((1, u > 0.5), (0, True))),
        Output("half", "x / 2 rounded (halves away from zero)", type="Integer", expr=x / 2 - 0.25),
        Output("stopped", "|u| < 0.01 m/s", type="Boolean", expr=sp.Abs(u) < 0.01),
        Output("y", "x times levels", "m", expr=x * levels),
    ],
    terminate_when=x > 1.0,
    integrator_step=0.01,
    default_experiment=(0.0, 10.0, 0.1),
)


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    return build_fmu(DEMO, tmp_path_factory.mktemp("discrete"), force=True)


@pytest.fixture
def slave(fmu):
    md = read_model_description(str(fmu))
    d = extract(str(fmu))
    s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="DiscreteDemo", instanceName="demo")
    s.instantiate()
    s.vr = {v.name: v.valueReference for v in md.modelVariables}
    yield s
    s.freeInstance()
    shutil.rmtree(d, ignore_errors=True)


def test_model_description_types_variability_and_validation(fmu):
    assert validate(fmu) == []
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    got = {v.get("name"): (v.get("causality"), v.get("variability"), v[0].tag, v[0].get("start"))
           for v in root.iter("ScalarVariable")}
    assert got["levels"] == ("parameter", "fixed", "Integer", "3")
    assert got["enabled"] == ("parameter", "tunable", "Boolean", "true")
    assert got["label"] == ("parameter", "fixed", "String", 'a "quoted" <name>')
    assert got["gear"] == ("input", "discrete", "Integer", "1")
    assert got["valid"] == ("input", "discrete", "Boolean", "false")
    assert got["regime"] == ("output", "discrete", "Integer", None)
    assert got["stopped"] == ("output", "discrete", "Boolean", None)
    assert got["y"][:3] == ("output", "continuous", "Real")
    md = read_model_description(str(fmu))
    vars_ = {v.name: v for v in md.modelVariables}
    deps = {vars_[o.variable.name].name: sorted(d.name for d in o.dependencies) for o in md.outputs}
    assert deps["regime"] == ["gear", "u"] and deps["stopped"] == ["u"] and deps["y"] == []


def python_outputs(xv, inputs, params=None):
    return DEMO.outputs_at(0.0, [xv], inputs, params)


def test_get_and_set_of_every_type_in_every_state_equals_the_python_definition(slave):
    s, vr = slave, slave.vr
    s.setupExperiment(startTime=0.0)
    s.setInteger([vr["levels"]], [4])
    s.setString([vr["label"]], ["run 7"])
    s.enterInitializationMode()
    s.setInteger([vr["gear"]], [2])
    s.setBoolean([vr["valid"]], [True])
    s.setReal([vr["u"]], [0.75])
    # initialisation mode: outputs from the values set so far
    assert s.getInteger([vr["regime"], vr["half"]]) == [2 * 4 + 1, 0]
    assert s.getBoolean([vr["stopped"], vr["enabled"]]) == [False, True]
    assert s.getString([vr["label"]]) == [b"run 7"]
    s.exitInitializationMode()
    p = {"levels": 4}
    xv, ti = 0.0, 0.0
    for step, (uu, g, ok) in enumerate([(0.75, 2, True), (0.005, 3, True), (0.3, 0, False),
                                        (-0.6, 1, True), (0.0, 5, True)]):
        s.setReal([vr["u"]], [uu])
        s.setInteger([vr["gear"]], [g])
        s.setBoolean([vr["valid"]], [ok])
        inputs = {"u": uu, "gear": g, "valid": ok}
        want = python_outputs(xv, inputs, p)  # direct feedthrough, before the step
        assert s.getInteger([vr["regime"], vr["half"]]) == [want["regime"], want["half"]]
        assert s.getBoolean([vr["stopped"]]) == [want["stopped"]]
        s.doStep(ti, 0.5)
        ti += 0.5
        xv += 2.0 * uu * ok * 0.5  # dx/dt is constant over the step: RK4 is exact
        got = s.getReal([vr["x"], vr["y"]])
        assert got[0] == pytest.approx(xv, abs=1e-15)
        want = python_outputs(got[0], inputs, p)
        assert got[1] == want["y"]
        assert s.getInteger([vr["regime"], vr["half"]]) == [want["regime"], want["half"]]
        assert s.getBoolean([vr["stopped"]]) == [want["stopped"]]
    # x = 0.75 - 0.6 = 0.15 -> half = round(0.075 - 0.25) = 0; Integer rounding checked at 2.5
    assert DEMO.outputs_at(0, [5.5], {"u": 0}, p)["half"] == 3  # 2.5 -> 3, as C lround
    assert DEMO.outputs_at(0, [-4.5], {"u": 0}, p)["half"] == -3  # -2.5 -> -3
    # a tunable Boolean during the run; a fixed Integer and a String are refused
    s.setBoolean([vr["enabled"]], [False])
    with pytest.raises(FMICallException):
        s.setInteger([vr["levels"]], [2])
    with pytest.raises(FMICallException):
        s.setString([vr["label"]], ["x"])
    s.setReal([vr["u"]], [1.0])
    s.setBoolean([vr["valid"]], [True])
    before = s.getReal([vr["x"]])
    s.doStep(ti, 0.5)
    assert s.getReal([vr["x"]]) == before  # disabled: no motion


def test_integer_parameter_range_is_checked(slave):
    s, vr = slave, slave.vr
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setInteger([vr["levels"]], [11])
    with pytest.raises(FMICallException):
        s.exitInitializationMode()
    s.setInteger([vr["levels"]], [10])
    s.exitInitializationMode()


def test_terminate_when_ends_the_simulation_at_the_first_communication_point(slave):
    s, vr = slave, slave.vr
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.setReal([vr["u"]], [0.8])
    s.setBoolean([vr["valid"]], [True])
    ti, h = 0.0, 0.1
    while True:  # x = 1.6 t: x > 1 first at t = 0.7
        try:
            s.doStep(ti, h)
        except FMICallException as e:
            assert e.status == 2  # fmi2Discard
            break
        ti += h
        assert not DEMO.terminates(ti, s.getReal([vr["x"]]), {"u": 0.8, "valid": True})
    assert s.getBooleanStatus(fmi2Terminated)
    t_end = s.getRealStatus(fmi2LastSuccessfulTime)
    assert t_end == ti + h and t_end == pytest.approx(0.7)
    x_end = s.getReal([vr["x"]])[0]
    assert x_end == pytest.approx(1.12) and DEMO.terminates(t_end, [x_end], {"u": 0.8, "valid": True})
    with pytest.raises(FMICallException):
        s.doStep(t_end, h)  # StepFailed: the master stops here
    # every type stays readable in StepFailed and after fmi2Terminate
    want = DEMO.outputs_at(t_end, [x_end], {"u": 0.8, "gear": 1, "valid": True})
    for state in ("StepFailed", "Terminated"):
        if state == "Terminated":
            s.terminate()
        assert s.getInteger([vr["regime"], vr["levels"]]) == [want["regime"], 3], state
        assert s.getBoolean([vr["stopped"], vr["valid"]]) == [False, True], state
        assert s.getString([vr["label"]]) == [b'a "quoted" <name>'], state


def test_model_refuses_what_fmi_does_not_allow():
    with pytest.raises(ValueError, match="String parameter label used in an expression"):
        Model("Bad", "", parameters=[Parameter("label", "", start="", type="String")],
              outputs=[Output("y", "", expr=label + 1)])
    with pytest.raises(ValueError, match="type String is not allowed"):
        Model("Bad", "", inputs=[Input("name", "", start="", type="String")])
    with pytest.raises(ValueError, match="has no unit"):
        Model("Bad", "", outputs=[Output("n", "", "m", type="Integer", expr=sp.Integer(1))])
    with pytest.raises(ValueError, match="type Integer is not allowed"):
        Model("Bad", "", states=[State("n", "", type="Integer", der=sp.Integer(0))])
