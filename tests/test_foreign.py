"""Other tools' example SSPs and FMUs (tests/data/foreign) in railfmu.

Every SSP of the corpus either runs, under each master, with the numbers the tool that wrote
it gives, or is refused in one line naming the construct; none takes the process down or
prints a traceback. The numbers: OMSimulator's LinearTransformation examples against the
results OMSimulator's own testsuite records for them (testsuite/tests/simulation/
LinearTransformation1.py and 3.py, "endResult"; OMSimulator 3.0 here aborts on these SSP 2.0
files); the other OpenModelica examples against what OMSimulator 3.0 computes for them here
(tests/interop/test_foreign_tools.py compares every row with OMSimulator and libcosim where
they are installed). ``railfmu run X.fmu`` on the Reference-FMUs equals ``fmpy.simulate_fmu``.
"""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from foreign_corpus import SSPS, reference_fmu
from railfmu.models.errors import UserError
from railfmu.fmus.cosim.masters import MASTERS, run
from railfmu.fmus.ssp import read_system

# case -> (signals to record, {signal: value at the last row}) for the SSPs that run; the
# OpenModelica models are algebraic: every row after the first carries these values
RUNS = {
    # Gain1.y = k u = 0 (u, k at their start values 0 and 1); Add1.u1 = 2 * 0 + 3 through the
    # connection's LinearTransformation (SSP 2.0); OMSimulator records Add1.u1 = 3
    "omsimulator/LinearTransformation": (["Add1.u1", "Add1.y", "Gain1.y"], {"Add1.u1": 3.0, "Gain1.y": 0.0}),
    # parameters through an .ssm mapping: Gain1.u = 2 * 2 + 10, Gain1.k = 4 * 2 + 5; OMSimulator
    # records k 13, u 14, y 182, Add1.u1 182
    "omsimulator/LinearTransformation3": (["Gain1.k", "Gain1.u", "Gain1.y", "Add1.u1"],
                                          {"Gain1.k": 13.0, "Gain1.u": 14.0, "Gain1.y": 182.0, "Add1.u1": 182.0}),
    # a nested system, system-level connectors: Input_cref (-20) feeds addP.u1, the parameter
    # connectors k_cref (30) and T_cref (20) set addP.k1 and addI.k2 over the .ssv's own
    # bindings of them (10 and 2); OMSimulator 3.0: addP.y = -600
    **{f"omsimulator/import_export_parameters{i}": (["addP.u1", "addP.k1", "addP.y", "addI.k2"],
                                                    {"addP.u1": -20.0, "addP.k1": 30.0, "addP.y": -600.0,
                                                     "addI.k2": 20.0})
       for i in (1, 2, 3)},
    # a top-level input connector bound to -20 and connected to nothing: addP keeps u1 = 0; the
    # system-level addP.k1 = -200 outranks the component's own binding (10)
    **{f"omsimulator/toplevelparameter{i}": (["addP.u1", "addP.k1", "addP.y"],
                                             {"addP.u1": 0.0, "addP.k1": -200.0, "addP.y": 0.0})
       for i in (1, 2)},
    # the crane demo (20-sim, OSP step annotation): runs; tests/interop compares it with libcosim
    "libcosim/demo": ([], {}),
    # FMI 1.0 (ViProMa's identity FMU): identity1.realIn bound by two .ssv files, the later
    # (4) over the earlier (2); identity2.realIn = 1.3 * 4 + 50 through the connection's
    # LinearTransformation. libcosim takes the first .ssv as its default set (2 -> 52.6) and
    # the second as the named set "initialValues2" (its own test reads 4 from that);
    # tests/interop compares every row with libcosim at realIn = 2
    "libcosim/linear_transformation": (["identity1.realOut", "identity2.realIn", "identity2.realOut"],
                                       {"identity1.realOut": 4.0, "identity2.realIn": 55.2,
                                        "identity2.realOut": 55.2}),
    # Vico's FMI 1.0 BouncingBall (the FMI SDK's), dropped from h = 2 (inline) and h = 5 (.ssv):
    # the first row; test_vico_bouncing_ball_equals_fmpy checks the whole run
    "vico/bouncingBall": (["bouncingBall.h"], {}),
    "vico/bouncingBall/external_ssv": (["bouncingBall.h"], {}),
    # 20-sim FMUs with Windows binaries and C sources (compiled); tests/interop has no Vico
    "vico/quarter-truck": ([], {}),
    # OSP's dynamic-positioning ship (FMI 1.0 and 2.0 FMUs, one whose modelDescription repeats
    # variable names: read with a warning); tests/interop compares it with libcosim
    "vico/dp-ship": ([], {}),
}
# case -> the words of the one-line refusal
REFUSED = {
    "libcosim/demo/proxy": "proxyfmu://",  # libcosim's remote FMU proxy
    "vico/bouncingBall/proxyfmu": "proxyfmu://",
    # starts at 5 s: the crane model's actuator limits are NaN at 5.001 s (in libcosim too)
    "libcosim/demo/no_algorithm_element": "non-finite value",
}
# the crane's controller and crane feed each other through direct feedthrough: an algebraic
# loop, which the Gauss-Seidel master refuses in one line (Jacobi and the container run it)
# (the quarter-truck's chassis and wheel, and the ship's observer loop, likewise)
LOOPS = {"libcosim/demo", "libcosim/demo/no_algorithm_element", "vico/quarter-truck", "vico/dp-ship"}
STOP = {"libcosim/demo": 0.1, "libcosim/demo/no_algorithm_element": 5.1,  # s: the SSDs give none
        "libcosim/linear_transformation": 0.1, "vico/quarter-truck": 1.0, "vico/dp-ship": 2.0}
STEP = {"libcosim/linear_transformation": 1e-3}  # s: no step anywhere; libcosim's own test's


def test_the_corpus_is_covered():
    assert sorted(SSPS) == sorted([*RUNS, *REFUSED])
    # 13 of the 16 run (FMI 1.0 included); the 3 refused: two remote proxies and a start
    # time at which the model's own values are NaN
    assert len(RUNS) >= 13


# compiling the quarter-truck's three 20-sim FMUs from their sources takes ~17 s (measured)
SLOW = {"vico/quarter-truck"}


@pytest.mark.parametrize("master", MASTERS)
@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW else c for c in sorted(SSPS)])
def test_corpus_ssp_runs_and_agrees_or_is_refused_in_one_line(case, master):
    record, expected = RUNS.get(case, ([], {}))
    try:
        system = read_system(SSPS[case], stop_time=STOP.get(case), step_size=STEP.get(case))
        system.record = list(record)
        res = run(system, master, progress=False)
    except UserError as exc:
        msg = str(exc)
        if master == "gauss-seidel" and case in LOOPS:
            assert msg.startswith("algebraic loop: ") and "\n" not in msg, msg
            return
        assert case in REFUSED and "\n" not in msg, msg
        assert REFUSED[case] in msg, msg
        return
    assert case in RUNS, f"{case} runs: move it to RUNS with its expected values"
    assert res.complete and res.end_time == pytest.approx(system.stop_time)
    assert np.isfinite(res.data).all()
    last = dict(zip(res.columns, res.data[-1]))
    for signal, value in expected.items():
        assert last[signal] == pytest.approx(value, rel=1e-12, abs=1e-12), signal


def test_a_top_level_input_is_a_parameter_of_the_run():
    system = read_system(SSPS["omsimulator/import_export_parameters1"],
                         overrides={"co_sim": {"Input_cref": "-5"}})
    assert system.component("addP").parameters["u1"] == -5.0
    assert system.step_size == 1e-3  # from oms:FixedStepMaster: the SSD has no step
    assert system.step_size_from.startswith("the org.openmodelica annotation")


def test_ssp_2_0_is_named_and_another_version_refused(tmp_path):
    ssd = (SSPS["omsimulator/LinearTransformation"] / "SystemStructure.ssd").read_text()
    (tmp_path / "SystemStructure.ssd").write_text(ssd.replace('version="2.0"', 'version="3.0"'))
    with pytest.raises(UserError, match=r"SSP version '3.0' is not supported \(SSP 1.0 and 2.0 are\)"):
        read_system(tmp_path)


@pytest.fixture(scope="module")
def reference_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("reference-fmus")


@pytest.mark.parametrize("model, fmi_version", [*[(m, 2) for m in ("BouncingBall", "Dahlquist", "VanDerPol")],
                                                *[(m, 3) for m in ("BouncingBall", "Dahlquist", "VanDerPol",
                                                                   "Feedthrough")]])
def test_single_reference_fmu_equals_fmpy_simulate(model, fmi_version, reference_dir):
    """``railfmu run X.fmu``'s system (the FMU's default experiment, FMPy's output interval)
    gives FMPy's samples exactly: one FMU, the same calls in the same order. FMI 3: the
    sources as the Reference-FMUs ship them (buildDescription.xml, prefixed function names)."""
    import fmpy

    from railfmu.fmus.cosim.system import read_model

    fmu = reference_fmu(model, reference_dir, fmi_version)
    system = read_system(fmu)
    res = run(system, "jacobi", progress=False)
    compiled, _ = read_model(fmu, "test")
    theirs = fmpy.simulate_fmu(str(compiled), fmi_type="CoSimulation")
    assert len(res.data) == len(theirs) > (100 if model != "Feedthrough" else 20)
    assert len(res.columns) >= 2
    for j, col in enumerate(res.columns):
        name = "time" if col == "time" else col.split(".", 1)[1]
        np.testing.assert_array_equal(res.data[:, j], theirs[name].astype(float), err_msg=col)
    if model == "Feedthrough":
        # FMI 3.0 carries an Enumeration as an Int64: set by item name, recorded, under both masters
        for master in ("jacobi", "gauss-seidel"):
            system = read_system(fmu, overrides={"Feedthrough": {"Enumeration_input": "Option 2",
                                                                 "Float64_continuous_input": "3"}})
            res = run(system, master, progress=False)
            last = dict(zip(res.columns, res.data[-1]))
            assert last["Feedthrough.Enumeration_output"] == 2 and last["Feedthrough.Float64_continuous_output"] == 3


def test_railfmu_run_a_single_fmu_on_the_command_line(reference_dir, tmp_path):
    fmu = reference_fmu("BouncingBall", reference_dir)
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", str(fmu), "-q",
                          "--set", "BouncingBall.e=0.5", "--out", str(out)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    head = (out / "signals.csv").read_text().splitlines()[0].split(",")
    rows = np.loadtxt(out / "signals.csv", delimiter=",", skiprows=1)
    data = {h: rows[:, j] for j, h in enumerate(head)}
    assert data["time"][-1] == pytest.approx(3.0) and len(rows) == 301
    # free fall from 1 m at g = 9.81 m/s2 lands at t = sqrt(2/9.81) = 0.4515 s; with e = 0.5
    # the first rebound is at half the impact speed, so the ball peaks at e^2 = 0.25 m
    t0 = np.sqrt(2 / 9.81)
    after = data["BouncingBall.h"][(data["time"] > t0 + 0.05) & (data["time"] < t0 + 0.3)]
    assert after.max() == pytest.approx(0.25, abs=0.01)  # the 10 ms grid misses the peak by < 1 %
    bad = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", str(fmu), "-q",
                          "--set", "BouncingBall.h=2", "--set", "Ball.e=1", "--out", str(out)],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert bad.stderr.strip().count("\n") == 0 and "no component 'Ball'" in bad.stderr


def _edited(fmu: Path, out: Path, member: str, old: bytes, new: bytes) -> Path:
    import zipfile

    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == member:
                assert old in data
                data = data.replace(old, new)
            dst.writestr(info, data)
    return out


def test_a_source_fmu_with_prefixed_function_names_runs(reference_dir, tmp_path):
    """FMI 2.0 source code prefixes its functions with the model identifier (the Reference-FMUs'
    sources as shipped): the compiled binary gets the standard names as aliases, and runs as
    the unprefixed build does."""
    fmu = reference_fmu("Dahlquist", reference_dir)
    prefixed = _edited(fmu, tmp_path / "Dahlquist.fmu", "sources/all.c", b"#define DISABLE_PREFIX\n", b"")
    a = run(read_system(fmu), "jacobi", progress=False)
    b = run(read_system(prefixed), "jacobi", progress=False)
    np.testing.assert_array_equal(a.data, b.data)


def test_a_missing_fmi_function_is_one_line(reference_dir, tmp_path):
    """A binary that lacks an FMI function (here fmi2CancelStep, made static in the sources):
    one line naming the FMU and the function, not FMPy's traceback."""
    fmu = _edited(reference_fmu("Dahlquist", reference_dir), tmp_path / "Dahlquist.fmu",
                  "sources/fmi2Functions.c", b"fmi2Status fmi2CancelStep(fmi2Component c) {",
                  b"static fmi2Status no_cancel_step(fmi2Component c) {")
    with pytest.raises(UserError) as info:
        run(read_system(fmu), "jacobi", progress=False)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("Dahlquist.fmu (Dahlquist): ") and "fmi2CancelStep" in msg, msg


def test_validate_separates_conformance_from_railfmu_packaging(reference_dir, tmp_path):
    import zipfile

    from railfmu.fmus.generate.build import describe, validate
    from railfmu.fmus.ssp import validate_ssp

    add = SSPS["omsimulator/LinearTransformation"] / "resources" / "Add.fmu"
    # a conformant OpenModelica FMU (linux64 binary, no sources) and a source-only Reference-FMU
    assert validate(add) == []
    assert validate(reference_fmu("Dahlquist", reference_dir)) == []
    # railfmu's packaging rules only on request for another tool's FMU
    assert validate(add, packaging=True) == ["no C sources in sources/ (railfmu's packaging)"]
    assert describe(SSPS["libcosim/linear_transformation"].parents[1] / "fmi1" / "identity.fmu") \
        == "FMI 1.0 Co-Simulation"
    # a folder and the same files zipped as .ssp validate alike
    for case in ("omsimulator/LinearTransformation", "omsimulator/import_export_parameters1"):
        ssp = tmp_path / f"{case.rpartition('/')[2]}.ssp"
        with zipfile.ZipFile(ssp, "w") as z:
            for p in sorted(SSPS[case].rglob("*")):
                if p.is_file():
                    z.write(p, p.relative_to(SSPS[case]).as_posix())
        assert validate_ssp(SSPS[case]) == [] == validate_ssp(ssp), case


@pytest.mark.slow  # FMPy takes ~30 s to validate CraneController.fmu
def test_validate_checks_the_fmus_an_ssd_names_outside_its_folder():
    from railfmu.fmus.ssp import validate_ssp

    # 20-sim's crane FMUs lack the InitialUnknowns FMPy expects: a conformance finding, per FMU
    problems = validate_ssp(SSPS["libcosim/demo"])
    assert len(problems) == 2 and all("ModelStructure/InitialUnknowns" in p for p in problems), problems


NESTED_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="2.0" name="nested"
  xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
  xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
  xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">
  <ssd:System name="top">
    <ssd:Connectors><ssd:Connector name="x" kind="input"><ssc:Float64/></ssd:Connector></ssd:Connectors>
    <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
      <ssv:ParameterSet version="2.0" name="p"><ssv:Parameters>
        <ssv:Parameter name="x"><ssv:Float64 value="2"/></ssv:Parameter>
      </ssv:Parameters></ssv:ParameterSet>
    </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:System name="sub">
        <ssd:Connectors>
          <ssd:Connector name="in" kind="input"><ssc:Float64/></ssd:Connector>
          <ssd:Connector name="out" kind="output"><ssc:Float64/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="2.0" name="q"><ssv:Parameters>
            <ssv:Parameter name="Gain1.k"><ssv:Float64 value="3"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
        <ssd:Elements>
          <ssd:Component name="Gain1" source="resources/Gain.fmu"/>
        </ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startConnector="in" endElement="Gain1" endConnector="u"/>
          <ssd:Connection startElement="Gain1" startConnector="y" endConnector="out"/>
        </ssd:Connections>
      </ssd:System>
      <ssd:Component name="Add1" source="resources/Add.fmu"/>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="" startConnector="x" endElement="sub" endConnector="in"/>
      <ssd:Connection startElement="sub" startConnector="out" endElement="Add1" endConnector="u1"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.1"/>
</ssd:SystemStructureDescription>
"""


def test_a_nested_system_is_flattened_through_its_connectors(tmp_path):
    """x (a top-level input, bound to 2) -> sub.in -> sub.Gain1 (k = 3, bound inside sub) ->
    sub.out -> Add1.u1: Add1.y = k1 * 6 + k2 * 0 = 6 (k1 = 1); --set changes x."""
    import shutil

    (tmp_path / "resources").mkdir()
    for f in ("Add.fmu", "Gain.fmu"):
        shutil.copy(SSPS["omsimulator/LinearTransformation"] / "resources" / f, tmp_path / "resources" / f)
    (tmp_path / "SystemStructure.ssd").write_text(NESTED_SSD)
    system = read_system(tmp_path, step_size=0.01)
    assert [c.name for c in system.components] == ["sub.Gain1", "Add1"]
    assert [str(c) for c in system.connections] == ["sub.Gain1.y -> Add1.u1"]
    assert system.component("sub.Gain1").parameters == {"k": 3.0, "u": 2.0}
    system.record = ["sub.Gain1.y", "Add1.u1", "Add1.y"]
    res = run(system, "jacobi", progress=False)
    assert dict(zip(res.columns, res.data[-1])) == {"time": pytest.approx(0.1), "sub.Gain1.y": 6.0,
                                                     "Add1.u1": 6.0, "Add1.y": 6.0}
    again = read_system(tmp_path, step_size=0.01, overrides={"top": {"x": "5"}, "sub": {"Gain1.k": "2"}})
    assert again.component("sub.Gain1").parameters == {"k": 2.0, "u": 5.0}
    # a transformation on the way from a system connector's value would be lost: refused
    (tmp_path / "SystemStructure.ssd").write_text(NESTED_SSD.replace(
        'endElement="sub" endConnector="in"/>',
        'endElement="sub" endConnector="in"><ssc:LinearTransformation factor="2"/></ssd:Connection>'))
    with pytest.raises(UserError, match="a transformation on a connection to a system connector is not supported"):
        read_system(tmp_path, step_size=0.01)


def test_the_container_master_runs_a_system_fmpys_container_crashes_on(tmp_path):
    """FMPy's container FMU segfaults on libcosim's crane demo (FMI 2.0). The container master
    runs FMI 2.0 systems in its own C loop, which makes the Jacobi master's calls: no trial, no
    warning, Jacobi's rows. The trial in a child (still run before FMPy's container takes a
    system with FMI 3.0 components and an FMU railfmu did not build) says so in one line."""
    rows = {}
    for master in ("jacobi", "container"):
        out = tmp_path / master
        res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "-q",
                              str(SSPS["libcosim/demo"]), "--master", master, "--stop-time", "0.01",
                              "--out", str(out)], capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
        assert "Traceback" not in res.stderr and "container master not used" not in res.stderr, res.stderr
        rows[master] = (out / "signals.csv").read_text()
    assert len(rows["container"].splitlines()) == 1 + 101  # 0.01 s at 0.1 ms
    assert rows["container"] == rows["jacobi"]
    trial = ("import sys; from railfmu.fmus.ssp import read_system; "
             "from railfmu.fmus.cosim.masters import _run_container; "
             "from railfmu.fmus.cosim.trial import container_refusal; "
             "print(container_refusal(read_system(sys.argv[1], stop_time=0.01), _run_container))")
    res = subprocess.run([sys.executable, "-c", trial, str(SSPS["libcosim/demo"])], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "a 10-step trial run of the container crashed (SIGSEGV)", res.stdout


def test_an_enumeration_signal_is_connected_and_recorded(reference_dir, tmp_path):
    """Feedthrough (Reference-FMUs) passes its Enumeration input to its output; two in a row,
    the first's input set to "Option 2" by name: the second outputs 2 (FMI 2.0 carries an
    Enumeration as an Integer), under every master (the container master's C loop gets and
    sets it as an Integer too)."""
    import shutil

    (tmp_path / "resources").mkdir()
    shutil.copy(reference_fmu("Feedthrough", reference_dir), tmp_path / "resources" / "Feedthrough.fmu")
    comps = "".join(f'<ssd:Component name="{n}" source="resources/Feedthrough.fmu"><ssd:Connectors>'
                    '<ssd:Connector name="Enumeration_input" kind="input"><ssc:Enumeration name="Option"/></ssd:Connector>'
                    '<ssd:Connector name="Enumeration_output" kind="output"><ssc:Enumeration name="Option"/></ssd:Connector>'
                    '</ssd:Connectors></ssd:Component>' for n in ("a", "b"))
    (tmp_path / "SystemStructure.ssd").write_text(
        '<?xml version="1.0" encoding="UTF-8"?><ssd:SystemStructureDescription version="1.0" name="enum" '
        'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
        'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"><ssd:System name="s">'
        f'<ssd:Elements>{comps}</ssd:Elements><ssd:Connections><ssd:Connection startElement="a" '
        'startConnector="Enumeration_output" endElement="b" endConnector="Enumeration_input"/>'
        '</ssd:Connections></ssd:System><ssd:DefaultExperiment startTime="0" stopTime="0.1"/>'
        '</ssd:SystemStructureDescription>')
    for master in MASTERS:
        system = read_system(tmp_path, step_size=0.01, overrides={"a": {"Enumeration_input": "Option 2"}})
        system.record = ["a.Enumeration_output", "b.Enumeration_output"]
        res = run(system, master, progress=False)
        assert res.master == master
        # Jacobi: b sees a's output one step later; Gauss-Seidel at once
        assert res.data[-1, 1:].tolist() == [2, 2] and res.data[0, 1] == 2, master
    # an Integer output may feed an Enumeration input (both fmi2Integer; Dymola's and Simulink's
    # FMUs in OMSimulator's examples are joined so)
    ssd = tmp_path / "SystemStructure.ssd"
    ssd.write_text(ssd.read_text().replace('startConnector="Enumeration_output"', 'startConnector="Int32_output"'))
    system = read_system(tmp_path, step_size=0.01, overrides={"a": {"Int32_input": "2"}})
    system.record = ["b.Enumeration_output"]
    assert run(system, "jacobi", progress=False).data[-1, 1] == 2


@pytest.mark.parametrize("case, h0", [("vico/bouncingBall", 2.0), ("vico/bouncingBall/external_ssv", 5.0)])
def test_vico_bouncing_ball_equals_fmpy(case, h0):
    """Vico's FMI 1.0 BouncingBall SSPs (Vico's step annotation, 10 ms; h bound inline or in an
    .ssv): every sample equals ``fmpy.simulate_fmu`` from the same start height (Vico itself
    is a Java tool, not run here); the ball first lands at sqrt(2 h0 / 9.81)."""
    import fmpy

    system = read_system(SSPS[case])
    assert system.step_size == 0.01 and system.step_size_from.startswith("the com.github.ntnu-ihb.vico annotation")
    system.record = ["bouncingBall.h", "bouncingBall.v"]
    res = run(system, "jacobi", progress=False)
    theirs = fmpy.simulate_fmu(str(system.components[0].fmu), start_values={"h": h0}, stop_time=10.0,
                               output_interval=0.01, step_size=0.01, fmi_type="CoSimulation")
    assert len(res.data) == len(theirs) == 1001
    for j, name in enumerate(["time", "h", "v"]):
        np.testing.assert_array_equal(res.data[:, j], theirs[name], err_msg=name)
    t, v = res.data[:, 0], res.data[:, 2]
    first_bounce = t[np.argmax(v > 0)]
    assert first_bounce == pytest.approx(np.sqrt(2 * h0 / 9.81), abs=0.02)  # the FMU's Euler steps, 10 ms rows


def test_an_fmu_fmpy_validation_rejects_is_read_with_one_warning(tmp_path):
    """OSP's DP ship: DPController.fmu repeats three variable names, which FMPy's
    validation rejects; the FMU is read without it, one warning line names the problem."""
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "-q",
                          str(SSPS["vico/dp-ship"]), "--stop-time", "0.2", "--out", str(tmp_path / "out")],
                         capture_output=True, text=True)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    lines = [line for line in res.stderr.splitlines() if "validation" in line]
    assert len(lines) == 1 and "DPController.fmu" in lines[0] and '"iex"' in lines[0] and "not unique" in lines[0], lines
    assert len((tmp_path / "out" / "signals.csv").read_text().splitlines()) == 1 + 6  # 0.2 s at 0.04 s


def test_dp_ship_controller_acts_when_sampled_before_the_transfer(tmp_path):
    """`--sampling before-transfer` reads no output between setting an FMU's inputs and its next
    doStep: OSP's DP controller (FMI 1.0) then acts from 2 s, as in libcosim (compared row by
    row in tests/interop); the option is the Jacobi master's, refused in one line elsewhere."""
    def cli(*args):
        return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "-q",
                               str(SSPS["vico/dp-ship"]), "--stop-time", "3", *args],
                              capture_output=True, text=True)

    res = cli("--sampling", "before-transfer", "--out", str(tmp_path / "out"))
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    with open(tmp_path / "out" / "signals.csv") as f:
        rows = list(csv.DictReader(f))
    mz = [float(r["DP Controller.ControlMz"]) for r in rows]
    assert len(rows) == 76 and mz[:50] == [0.0] * 50 and min(mz) < -100.0  # acts from 2 s (row 50)
    res = cli("--sampling", "before-transfer", "--master", "container", "--out", str(tmp_path / "c"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines() == [
        "railfmu: error: --sampling before-transfer: only the Jacobi master reads its rows before the transfer "
        "(the container master samples after it); use --master jacobi"], res.stderr
