"""The SSP reader/writer (fmus/ssp/) on the example experiment and on small SSDs written here.

Every SSD below uses the two real FMUs (built by the session fixture ``fmu_dir``): sources
``resources/<name>.fmu`` that are not in the test folder are found through ``fmu_dirs``.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
import zipfile
from pathlib import Path

import pytest

from railfmu.models.errors import UserError
from railfmu.fmus.ssp import list_variants, read_system, validate_ssp, write_ssp
from railfmu.fmus.ssp.units import OURS, UnitError, Units, conversion, from_ssc

EXP = Path(__file__).resolve().parents[1] / "experiments" / "track_wheelset"

NAMESPACES = """xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    xmlns:rf="https://railfmu.org/ssp/1"
    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations\""""

ALIGNMENT = '<ssd:Connection startElement="track" startConnector="alignment_1" endElement="wheelset" endConnector="xi"/>'
RATE = ('<ssd:Connection startElement="track" startConnector="alignment_rate_1" endElement="wheelset" '
        'endConnector="xi_rate"/>')
MM = '<ssd:Units><ssc:Unit name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit></ssd:Units>'
STEP = ('<ssd:Annotations><ssc:Annotation type="org.railfmu.experiment"><rf:FixedStep stepSize="{step}"/>'
        '</ssc:Annotation></ssd:Annotations>')


def ssd_text(track="", wheelset="", connections=ALIGNMENT + RATE, system="", units="", annotations="",
             stop="1", step="0.001", track_source="resources/TrackIrregularity.fmu", elements="") -> str:
    step_el = STEP.format(step=step) if step else ""
    stop_attr = f' stopTime="{stop}"' if stop else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="small" description="a test system" {NAMESPACES}>
  <ssd:System name="small">
    {system}
    <ssd:Elements>
      <ssd:Component name="track" source="{track_source}" type="application/x-fmu-sharedlibrary">
        {track}
      </ssd:Component>
      <ssd:Component name="wheelset" source="resources/WheelsetLateral.fmu">
        {wheelset}
      </ssd:Component>
      {elements}
    </ssd:Elements>
    <ssd:Connections>
      {connections}
    </ssd:Connections>
    {annotations}
  </ssd:System>
  {units}
  <ssd:DefaultExperiment startTime="0"{stop_attr}>{step_el}</ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def write_ssd(folder: Path, **kw) -> Path:
    path = folder / "SystemStructure.ssd"
    path.write_text(ssd_text(**kw))
    return path


def parameter_set(name: str, body: str, extra: str = "") -> str:
    return (f'<ssv:ParameterSet version="1.0" name="{name}" '
            f'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
            f'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">'
            f"<ssv:Parameters>{body}</ssv:Parameters>{extra}</ssv:ParameterSet>")


def inline(body: str) -> str:
    """A ParameterBindings element with one inline parameter set."""
    return (f"<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>{parameter_set('p', body)}"
            "</ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>")


def real(name, value, unit=None) -> str:
    u = f' unit="{unit}"' if unit else ""
    return f'<ssv:Parameter name="{name}"><ssv:Real value="{value}"{u}/></ssv:Parameter>'


def integer(name, value) -> str:
    return f'<ssv:Parameter name="{name}"><ssv:Integer value="{value}"/></ssv:Parameter>'


def user_error(fn, *args, **kw) -> str:
    """The message of the UserError that fn raises; it must be one line."""
    with pytest.raises(UserError) as info:
        fn(*args, **kw)
    message = str(info.value)
    assert "\n" not in message and message.strip() == message
    return message


def without_paths(system):
    """A System with FMU paths and source dropped, to compare a round trip."""
    comps = [dataclasses.replace(c, fmu=Path(c.fmu.name)) for c in system.components]
    return dataclasses.replace(system, components=comps, source=None)


# -- the example experiment ---------------------------------------------------------------

def test_example_experiment(fmu_dir):
    s = read_system(EXP, variant="harmonic", fmu_dirs=[fmu_dir])
    assert s.name == "track_wheelset" and s.description.startswith("Track irregularity")
    assert [c.name for c in s.components] == ["track", "wheelset"]
    assert [str(c) for c in s.connections] == ["track.alignment_1 -> wheelset.xi",
                                              "track.alignment_rate_1 -> wheelset.xi_rate"]
    assert all(c.identity for c in s.connections)
    assert (s.start_time, s.stop_time, s.step_size, s.n_steps) == (0.0, 20.0, 1e-3, 20000)
    track, wheelset = s.component("track"), s.component("wheelset")
    assert track.parameters["psd_level"] == 0 and isinstance(track.parameters["psd_level"], int)
    assert track.parameters["harmonic_lateral_amplitude"] == 1e-3
    assert track.parameters["V"] == 20.0 and track.parameters["seed"] == 1  # parameters/track.ssv
    assert wheelset.parameters == {"V": 20.0}
    assert len(s.record) == 11
    (obs,) = s.observers
    assert obs.cls == "alignment_kf"
    assert list(obs.measurements) == ["ddy", "dpsi", "ddy_f"] and obs.truth == {"xi": "track.alignment_1"}
    assert obs.settings == {"V": 20}
    assert s.warnings == [] and s.source == EXP
    assert list_variants(EXP) == ["harmonic", "psd"]
    assert read_system(EXP, variant="psd", fmu_dirs=[fmu_dir]).component("track").parameters["psd_level"] == 1


def test_example_as_ssp_archive(fmu_dir, tmp_path):
    """An .ssp zip of the experiment folder with its FMUs in resources/: variants inside it work."""
    archive = tmp_path / "tw.ssp"
    with zipfile.ZipFile(archive, "w") as zf:
        for f in EXP.rglob("*"):
            if f.suffix in (".ssd", ".ssv"):
                zf.write(f, f.relative_to(EXP).as_posix())
        for f in fmu_dir.glob("*.fmu"):
            zf.write(f, f"resources/{f.name}")
    assert list_variants(archive) == ["harmonic", "psd"]
    s = read_system(archive, variant="harmonic")
    assert s.component("track").parameters["psd_level"] == 0
    assert s.component("track").fmu.is_file() and s.source == archive
    assert validate_ssp(archive) == []


# -- parameter priorities -----------------------------------------------------------------

def test_priority_binding_system_variant_overrides(fmu_dir, tmp_path):
    # two component-level bindings (document order), then system-level, variant, overrides
    first = inline(real("harmonic_phase", 0.1) + real("harmonic_wavelength", 10) + integer("psd_level", 2)
                   + real("step_lateral", 0.5) + real("step_vertical", 0.1))
    second = inline(real("step_vertical", 0.2))
    track = first.replace("</ssd:ParameterBindings>", "") + second.replace("<ssd:ParameterBindings>", "")
    system = inline(real("track.harmonic_wavelength", 11) + integer("track.psd_level", 1)
                    + real("track.step_lateral", 0.6))
    write_ssd(tmp_path, track=track, system=system)
    (tmp_path / "variants").mkdir()
    (tmp_path / "variants" / "v.ssv").write_text(
        parameter_set("v", real("track.harmonic_wavelength", 12) + real("track.step_lateral", 0.7)))
    s = read_system(tmp_path, variant="v", fmu_dirs=[fmu_dir], overrides={"track": {"step_lateral": 0.8}})
    p = s.component("track").parameters
    assert p == {"harmonic_phase": 0.1, "step_vertical": 0.2, "psd_level": 1, "harmonic_wavelength": 12.0,
                 "step_lateral": 0.8}
    # without the variant and overrides the system-level values stand
    p = read_system(tmp_path, fmu_dirs=[fmu_dir]).component("track").parameters
    assert (p["harmonic_wavelength"], p["step_lateral"]) == (11.0, 0.6)
    # a variant given as a path to an .ssv
    p = read_system(tmp_path, variant=str(tmp_path / "variants" / "v.ssv"), fmu_dirs=[fmu_dir])
    assert p.component("track").parameters["harmonic_wavelength"] == 12.0


def test_ssv_file_units_and_ssm_mapping(fmu_dir, tmp_path):
    """A .ssv source with its own unit (mm), renamed and scaled by an .ssm: the unit is
    converted first, then the mapping's LinearTransformation."""
    (tmp_path / "parameters").mkdir()
    units = ('<ssv:Units><ssc:Unit name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit>'
             '<ssc:Unit name="km/h"><ssc:BaseUnit m="1" s="-1" factor="0.2777777777777778"/></ssc:Unit></ssv:Units>')
    (tmp_path / "parameters" / "t.ssv").write_text(parameter_set(
        "t", real("amp", 2, "mm") + real("V", 72, "km/h") + integer("seed", 7), units))
    (tmp_path / "parameters" / "t.ssm").write_text(
        '<ssm:ParameterMapping version="1.0" xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"'
        ' xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">'
        '<ssm:MappingEntry source="amp" target="harmonic_lateral_amplitude">'
        '<ssc:LinearTransformation factor="0.5" offset="0.0001"/></ssm:MappingEntry>'
        '<ssm:MappingEntry source="seed" target="seed"><ssc:IntegerMappingTransformation>'
        '<ssc:MapEntry source="7" target="9"/></ssc:IntegerMappingTransformation></ssm:MappingEntry>'
        '</ssm:ParameterMapping>')
    track = ('<ssd:ParameterBindings><ssd:ParameterBinding source="parameters/t.ssv">'
             '<ssd:ParameterMapping source="parameters/t.ssm"/></ssd:ParameterBinding></ssd:ParameterBindings>')
    write_ssd(tmp_path, track=track)
    p = read_system(tmp_path, fmu_dirs=[fmu_dir]).component("track").parameters
    assert p["harmonic_lateral_amplitude"] == pytest.approx(0.5 * 0.002 + 0.0001, rel=1e-15)
    assert p["V"] == pytest.approx(20.0, rel=1e-15) and p["seed"] == 9


def test_overrides_convert_cli_values(fmu_dir, tmp_path, monkeypatch):
    write_ssd(tmp_path)
    monkeypatch.chdir(tmp_path)  # a file a user names is relative to the current directory
    (tmp_path / "p.csv").write_text("x\n")
    s = read_system(tmp_path, fmu_dirs=[fmu_dir], overrides={
        "track": {"psd_level": 2.0, "seed": "5", "profile_file": "p.csv", "V": "25"},
        "wheelset": {"y": 1e-3}})  # a state's start value (output, initial="exact")
    p = s.component("track").parameters
    assert p == {"psd_level": 2, "seed": 5, "profile_file": str((tmp_path / "p.csv").resolve()), "V": 25.0}
    assert isinstance(p["psd_level"], int) and s.component("wheelset").parameters == {"y": 1e-3}
    for bad, words in [({"track": {"psd_level": 2.5}}, "--set track.psd_level: 2.5 is not a valid Integer"),
                       ({"track": {"V": "fast"}}, "--set track.V: 'fast' is not a valid Real"),
                       ({"track": {"V": float("nan")}}, "--set track.V: non-finite value nan"),
                       ({"track": {"profile_file": 3.0}}, "not a valid String"),
                       ({"track": {"position": 1.0}}, "variable 'position' is an output computed by the FMU"),
                       ({"track": {"time": 1.0}}, "is the independent variable")]:
        assert words in user_error(read_system, tmp_path, fmu_dirs=[fmu_dir], overrides=bad)


# -- connections and units ----------------------------------------------------------------

def test_units_table():
    mm = Units(from_ssc(None), {"mm": from_ssc_unit("mm", 'm="1" factor="0.001"')}).then(OURS)
    assert conversion("mm", mm, "m", OURS) == (0.001, 0.0)
    assert conversion("m", OURS, "mm", mm) == (1000.0, 0.0)
    celsius = Units({"degC": from_ssc_unit("degC", 'K="1" offset="273.15"')})
    kelvin = Units({"K": from_ssc_unit("K", 'K="1"')})
    assert conversion("degC", celsius, "K", kelvin) == (1.0, 273.15)
    assert conversion(None, OURS, "m", OURS) == (1.0, 0.0)  # a side without a unit: nothing to check
    with pytest.raises(UnitError, match="'m' .m. cannot be converted to 'm/s' .m s-1."):
        conversion("m", OURS, "m/s", OURS)
    with pytest.raises(UnitError, match="'furlong' is not defined"):
        conversion("furlong", OURS, "m", OURS)


def from_ssc_unit(name, attrs):
    from lxml import etree
    el = etree.fromstring(f'<ssd:Units {NAMESPACES}><ssc:Unit name="{name}"><ssc:BaseUnit {attrs}/>'
                          f"</ssc:Unit></ssd:Units>")
    return from_ssc(el)[name]


def test_linear_transformation_and_units(fmu_dir, tmp_path):
    # LinearTransformation alone
    lt = ALIGNMENT.replace("/>", '><ssc:LinearTransformation factor="2"/></ssd:Connection>')
    write_ssd(tmp_path, connections=lt + RATE)
    (c, _) = read_system(tmp_path, fmu_dirs=[fmu_dir]).connections
    assert (c.factor, c.offset) == (2.0, 0.0)
    # connectors show their variables in mm: the unit conversion comes first, the transformation's
    # offset is in the end connector's unit (1 mm), and the FMU variables stay in metres
    lt = ALIGNMENT.replace("/>", '><ssc:LinearTransformation factor="2" offset="1"/></ssd:Connection>')
    mm_out = '<ssd:Connectors><ssd:Connector name="alignment_1" kind="output"><ssc:Real unit="mm"/></ssd:Connector></ssd:Connectors>'
    mm_in = '<ssd:Connectors><ssd:Connector name="xi" kind="input"><ssc:Real unit="mm"/></ssd:Connector></ssd:Connectors>'
    write_ssd(tmp_path, connections=lt + RATE, track=mm_out, wheelset=mm_in, units=MM)
    (c, _) = read_system(tmp_path, fmu_dirs=[fmu_dir]).connections
    assert c.factor == pytest.approx(2.0, rel=1e-15) and c.offset == pytest.approx(1e-3, rel=1e-15)
    # suppressUnitConversion: the mm number goes through as is, then into the metre input
    lt = ALIGNMENT.replace("/>", ' suppressUnitConversion="true"/>')
    write_ssd(tmp_path, connections=lt + RATE, track=mm_out, units=MM)
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert s.connections[0].factor == pytest.approx(1000.0, rel=1e-15)
    # ... and survives a write/read round trip
    again = read_system(write_ssp(s, tmp_path / "out.ssp"))
    assert again.connections[0].factor == s.connections[0].factor
    assert without_paths(again) == without_paths(s)


def test_unit_mismatch(fmu_dir, tmp_path):
    wrong = ('<ssd:Connection startElement="track" startConnector="alignment_rate_1" endElement="wheelset" '
             'endConnector="xi"{}/>')
    write_ssd(tmp_path, connections=wrong.format(""))
    msg = user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])
    assert msg.startswith(f"{tmp_path / 'SystemStructure.ssd'}:")
    assert "Connection track.alignment_rate_1 -> wheelset.xi: unit mismatch: unit 'm/s' (m s-1) " \
           "cannot be converted to 'm' (m)" in msg
    write_ssd(tmp_path, connections=wrong.format(' suppressUnitConversion="true"'))
    assert read_system(tmp_path, fmu_dirs=[fmu_dir]).connections[0].identity
    # a connector declared in a unit of another dimension than its FMU variable
    bad = '<ssd:Connectors><ssd:Connector name="xi" kind="input"><ssc:Real unit="m/s"/></ssd:Connector></ssd:Connectors>'
    write_ssd(tmp_path, wheelset=bad)
    assert "Connector wheelset.xi: unit 'm' (m) cannot be converted to 'm/s'" in user_error(
        read_system, tmp_path, fmu_dirs=[fmu_dir])


def test_unconnected_input_warns(fmu_dir, tmp_path):
    write_ssd(tmp_path, connections=ALIGNMENT)
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert s.warnings == ["track.distance: input not connected; keeps its start value 0",
                          "track.speed: input not connected; keeps its start value 0",
                          "wheelset.xi_rate: input not connected; keeps its start value 0"]
    # an input given a value on purpose (a binding, a variant or --set) is not warned about
    bound = read_system(tmp_path, fmu_dirs=[fmu_dir], overrides={"wheelset": {"xi_rate": 0.0},
                                                                 "track": {"distance": 0.0, "speed": 0.0}})
    assert bound.warnings == [] and bound.component("wheelset").parameters["xi_rate"] == 0.0


# -- annotations and time -------------------------------------------------------------------

def test_recorder_and_observers(fmu_dir, tmp_path):
    annotations = """<ssd:Annotations>
      <ssc:Annotation type="com.example.other"><Whatever/></ssc:Annotation>
      <ssc:Annotation type="org.railfmu.recorder"><rf:Recorder><rf:Record connector="track.position"/>
      </rf:Recorder></ssc:Annotation>
      <ssc:Annotation type="org.railfmu.observers"><rf:Observers>
        <rf:Observer name="o" class="alignment_kf"><rf:Input name="a" connector="wheelset.ddy"/>
          <rf:Truth name="xi" connector="track.alignment_1"/><rf:Setting name="on" value="true"/>
          <rf:Setting name="q" value="1e-3"/><rf:Setting name="label" value="left"/></rf:Observer>
      </rf:Observers></ssc:Annotation></ssd:Annotations>"""
    write_ssd(tmp_path, annotations=annotations)
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert s.record == ["track.position", "wheelset.ddy", "track.alignment_1"]
    assert s.observers[0].settings == {"on": True, "q": 1e-3, "label": "left"}
    write_ssd(tmp_path, annotations=annotations.replace("wheelset.ddy", "wheelset.dddy"))
    msg = user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])
    assert "Observer 'o' Input 'a' 'wheelset.dddy': WheelsetLateral.fmu has no variable 'dddy'" in msg
    write_ssd(tmp_path, annotations=annotations.replace("track.position", "rail.position"))
    assert "Record 'rail.position': no component 'rail'; known components: track, wheelset" in user_error(
        read_system, tmp_path, fmu_dirs=[fmu_dir])


def _without_default_step(fmu: Path, out: Path) -> None:
    """A copy of ``fmu`` whose DefaultExperiment has no stepSize."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = re.sub(rb' stepSize="[^"]*"', b"", data)
            dst.writestr(item, data)


def test_time(fmu_dir, tmp_path):
    write_ssd(tmp_path, stop="2", step="0.01")
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert (s.start_time, s.stop_time, s.step_size, s.n_steps) == (0.0, 2.0, 0.01, 200)
    s = read_system(tmp_path, fmu_dirs=[fmu_dir], start_time=1.0, stop_time=3.0, step_size=0.5)
    assert (s.start_time, s.stop_time, s.step_size) == (1.0, 3.0, 0.5)
    # libcosim's annotation when ours is absent
    text = ssd_text(step="").replace("<ssd:DefaultExperiment startTime=\"0\" stopTime=\"1\">",
                                     '<ssd:DefaultExperiment startTime="0" stopTime="1"><ssd:Annotations>'
                                     '<ssc:Annotation type="com.opensimulationplatform"><osp:Algorithm>'
                                     '<osp:FixedStepAlgorithm baseStepSize="0.25"/></osp:Algorithm>'
                                     "</ssc:Annotation></ssd:Annotations>")
    (tmp_path / "SystemStructure.ssd").write_text(text)
    assert read_system(tmp_path, fmu_dirs=[fmu_dir]).step_size == 0.25
    write_ssd(tmp_path, step="")
    # no annotation: the smallest DefaultExperiment stepSize of the FMUs (both say 1 ms)
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert s.step_size == 0.001 and "smallest DefaultExperiment stepSize" in s.step_size_from
    s = read_system(tmp_path, fmu_dirs=[fmu_dir], step_size=0.1)
    assert s.step_size == 0.1 and s.step_size_from == "--step-size"
    # ... and none there either: one line
    (tmp_path / "resources").mkdir()
    for name in ("TrackIrregularity.fmu", "WheelsetLateral.fmu"):
        _without_default_step(fmu_dir / name, tmp_path / "resources" / name)
    msg = user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])
    assert msg.startswith(f"{tmp_path / 'SystemStructure.ssd'}: no step size: ") and "--step-size" in msg
    assert read_system(tmp_path, fmu_dirs=[fmu_dir], step_size=0.1).step_size == 0.1
    shutil.rmtree(tmp_path / "resources")
    write_ssd(tmp_path, stop="")
    assert "no stop time" in user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])
    write_ssd(tmp_path, stop="1", step="0.3")
    assert user_error(read_system, tmp_path, fmu_dirs=[fmu_dir]) == (
        f"{tmp_path / 'SystemStructure.ssd'}: step size 0.3 s does not divide the interval [0, 1] s")
    write_ssd(tmp_path, step="-0.1")
    assert "must be positive" in user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])
    write_ssd(tmp_path, step="fast")
    assert "FixedStep stepSize='fast' is not a number" in user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])


# -- bad input: one line naming the file and the element ---------------------------------------

MISSING_END = ALIGNMENT.replace(' endConnector="xi"', "")
BAD_SSDS = {
    "malformed XML": (lambda: ssd_text().replace("</ssd:Elements>", ""), "malformed XML"),
    "schema": (lambda: ssd_text(connections=MISSING_END),
               "schema: Element 'ssd:Connection': The attribute 'endConnector' is required but missing."),
    "missing FMU": (lambda: ssd_text(track_source="resources/Nope.fmu"),
                    "Component 'track': FMU resources/Nope.fmu not found (run `railfmu build`)"),
    "unknown component": (lambda: ssd_text(connections=ALIGNMENT.replace('"track"', '"rail"')),
                          ("Connection rail.alignment_1 -> wheelset.xi: no component 'rail'; "
                           "known components: track, wheelset")),
    "unknown connector": (lambda: ssd_text(connections=ALIGNMENT.replace("alignment_1", "nope")),
                          ("Connection track.nope -> wheelset.xi: TrackIrregularity.fmu (Component 'track') "
                           "has no variable 'nope'")),
    "type mismatch": (lambda: ssd_text(connections=ALIGNMENT.replace("alignment_1", "psd_level")),
                      "Connection track.psd_level -> wheelset.xi: type mismatch: Integer -> Real"),
    "input as start": (lambda: ssd_text(connections=ALIGNMENT.replace('"track" startConnector="alignment_1"',
                                                                      '"wheelset" startConnector="xi_rate"')),
                       "start wheelset.xi_rate is an input"),
    "infinite factor": (lambda: ssd_text(connections=ALIGNMENT.replace(
        "/>", '><ssc:LinearTransformation factor="INF"/></ssd:Connection>')), "non-finite factor or offset"),
    "connected twice": (lambda: ssd_text(connections=ALIGNMENT + ALIGNMENT), "is already connected (line"),
    "connector kind": (lambda: ssd_text(wheelset='<ssd:Connectors><ssd:Connector name="y" kind="input"/>'
                                                 "</ssd:Connectors>"),
                       "Connector wheelset.y: kind 'input' does not match the FMU variable's causality 'output'"),
    "connector type": (lambda: ssd_text(track='<ssd:Connectors><ssd:Connector name="psd_level" kind="parameter">'
                                              "<ssc:Real/></ssd:Connector></ssd:Connectors>"),
                       "Connector track.psd_level: type ssc:Real does not match the FMU variable's type Integer"),
    "unknown parameter": (lambda: ssd_text(track=inline(real("nope", 1))),
                          "Parameter 'nope' of Component 'track': TrackIrregularity.fmu has no variable 'nope'"),
    "Real for Integer": (lambda: ssd_text(track=inline(real("psd_level", 1.5))),
                         "Parameter 'psd_level' of Component 'track': a Real value does not fit variable 'psd_level' (Integer)"),
    "parameter unit": (lambda: ssd_text(track=inline(real("V", 20, "m"))),
                       "Parameter 'V' of Component 'track': unit 'm' (m) cannot be converted to 'm/s' (m s-1)"),
    "system-level name": (lambda: ssd_text(system=inline(real("rail.V", 20))),
                          "Parameter 'rail.V': no component 'rail'"),
    "nested system name": (lambda: ssd_text(elements='<ssd:System name="sub.a"/>'),
                           "System 'sub.a': a nested system needs a name without '.'"),
    "undeclared system connector": (lambda: ssd_text(connections=ALIGNMENT.replace(' startElement="track"', "")),
                                    "no system connector 'alignment_1'"),
    "other component type": (lambda: ssd_text().replace('type="application/x-fmu-sharedlibrary"',
                                                        'type="application/x-ssp-package"'),
                             "Component 'track': type 'application/x-ssp-package' is not supported"),
}


@pytest.mark.parametrize("case", list(BAD_SSDS))
def test_bad_ssd(case, fmu_dir, tmp_path):
    make, words = BAD_SSDS[case]
    path = tmp_path / "SystemStructure.ssd"
    path.write_text(make())
    msg = user_error(read_system, path, fmu_dirs=[fmu_dir])
    assert msg.startswith(f"{path}:"), msg
    assert words in msg


def test_bad_ssv_names_its_file(fmu_dir, tmp_path):
    write_ssd(tmp_path)
    (tmp_path / "variants").mkdir()
    (tmp_path / "variants" / "x.ssv").write_text(parameter_set("x", real("track.nope", 1)))
    msg = user_error(read_system, tmp_path, variant="x", fmu_dirs=[fmu_dir])
    assert msg == f"{tmp_path / 'variants' / 'x.ssv'}:1: Parameter 'track.nope': TrackIrregularity.fmu has no variable 'nope'"
    (tmp_path / "variants" / "x.ssv").write_text(parameter_set("x", integer("track.psd_level", "one")))
    msg = user_error(read_system, tmp_path, variant="x", fmu_dirs=[fmu_dir])
    assert msg.startswith(f"{tmp_path / 'variants' / 'x.ssv'}:1: schema:") and "'one'" in msg
    msg = user_error(read_system, tmp_path, variant="y", fmu_dirs=[fmu_dir])
    assert msg.endswith("unknown variant 'y'; known variants: x")


def test_bad_overrides(fmu_dir):
    assert user_error(read_system, EXP, fmu_dirs=[fmu_dir], overrides={"wheelset": {"mass": 1.0}}) == \
        "--set wheelset.mass: WheelsetLateral.fmu has no variable 'mass'"
    assert user_error(read_system, EXP, fmu_dirs=[fmu_dir], overrides={"bogie": {"m": 1.0}}) == \
        "--set bogie.m: no component 'bogie'; known components: track, wheelset"


def test_bad_paths(tmp_path):
    assert user_error(read_system, tmp_path / "nothing") == f"{tmp_path / 'nothing'}: no such file or directory"
    assert "no SystemStructure.ssd in this folder" in user_error(read_system, tmp_path)
    (tmp_path / "x.ssp").write_text("not a zip")
    assert user_error(read_system, tmp_path / "x.ssp") == f"{tmp_path / 'x.ssp'}: not an SSP archive (not a ZIP file)"
    broken_fmu = tmp_path / "resources" / "TrackIrregularity.fmu"
    broken_fmu.parent.mkdir()
    broken_fmu.write_text("not a zip either")
    write_ssd(tmp_path)
    assert "Component 'track': cannot read TrackIrregularity.fmu" in user_error(read_system, tmp_path)


# -- writing and validating ---------------------------------------------------------------------

def test_write_read_round_trip(fmu_dir, tmp_path):
    s = read_system(EXP, variant="harmonic", fmu_dirs=[fmu_dir],
                    overrides={"wheelset": {"alpha": 0.15, "y": 1e-3}, "track": {"seed": 3.0}})
    out = write_ssp(s, tmp_path / "sub" / "tw.ssp")
    with zipfile.ZipFile(out) as zf:
        assert sorted(zf.namelist()) == ["SystemStructure.ssd", "resources/TrackIrregularity.fmu",
                                         "resources/WheelsetLateral.fmu"]
    again = read_system(out)
    assert without_paths(again) == without_paths(s)
    assert again.component("track").fmu.parent.name == "resources"
    assert validate_ssp(out) == []


def test_written_ssd_for_libcosim(fmu_dir, tmp_path):
    """What libcosim reads: the OSP step annotation and one inline ssv set per component."""
    from lxml import etree

    s = read_system(EXP, variant="harmonic", fmu_dirs=[fmu_dir])
    with zipfile.ZipFile(write_ssp(s, tmp_path / "tw.ssp")) as zf:
        doc = etree.fromstring(zf.read("SystemStructure.ssd"))
    ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
          "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
          "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}
    (fixed,) = doc.findall("ssd:DefaultExperiment/ssd:Annotations/*/osp:Algorithm/osp:FixedStepAlgorithm", ns)
    assert float(fixed.get("baseStepSize")) == 1e-3
    track = doc.find("ssd:System/ssd:Elements/ssd:Component[@name='track']", ns)
    assert len(track.findall("ssd:ParameterBindings/ssd:ParameterBinding", ns)) == 1
    amp = track.find(".//ssv:Parameter[@name='harmonic_lateral_amplitude']/ssv:Real", ns)
    assert float(amp.get("value")) == 1e-3


def test_written_ssd_for_omsimulator(fmu_dir, tmp_path):
    """What OMSimulator 3.0 reads: its org.openmodelica annotation FIRST among the system's
    annotations (it reads only the first), a fixed-step master with the step; the SSD stays
    valid against the SSP 1.0 schema, ours stay after it."""
    from lxml import etree

    from railfmu.fmus.ssp.xmltools import schema_problems

    s = read_system(EXP, variant="harmonic", fmu_dirs=[fmu_dir], step_size=5e-4)
    with zipfile.ZipFile(write_ssp(s, tmp_path / "tw.ssp")) as zf:
        text = zf.read("SystemStructure.ssd")
    doc = etree.fromstring(text)
    ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
          "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
          "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"}
    annotations = doc.findall("ssd:System/ssd:Annotations/ssc:Annotation", ns)
    assert [a.get("type") for a in annotations] == ["org.openmodelica", "org.railfmu.observers",
                                                    "org.railfmu.study", "org.railfmu.recorder"]
    (master,) = annotations[0].findall("oms:Annotations/oms:SimulationInformation/oms:FixedStepMaster", ns)
    assert master.get("description") == "oms-ma" and float(master.get("stepSize")) == 5e-4
    assert b"<oms:FixedStepMaster" in text  # OMSimulator (pugixml) matches the prefix literally
    assert schema_problems(doc, "ssd", "SystemStructure.ssd") == []
    assert read_system(tmp_path / "tw.ssp").step_size == 5e-4


def test_validate_ssp(fmu_dir, tmp_path):
    s = read_system(EXP, fmu_dirs=[fmu_dir])
    good = write_ssp(s, tmp_path / "good.ssp")
    assert validate_ssp(good) == []
    # a broken copy: a connection loses its end connector, an FMU is not an FMU
    bad = tmp_path / "bad.ssp"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "SystemStructure.ssd":
                data = data.replace(b' endConnector="xi"', b"")
            if name.endswith("WheelsetLateral.fmu"):
                data = b"garbage"
            dst.writestr(name, data)
    problems = validate_ssp(bad)
    assert any("SystemStructure.ssd" in p and "endConnector" in p for p in problems), problems
    assert any("WheelsetLateral.fmu" in p for p in problems), problems
    assert all("\n" not in p for p in problems)
    (tmp_path / "x.ssp").write_text("no zip")
    assert validate_ssp(tmp_path / "x.ssp") == [f"{tmp_path / 'x.ssp'}: not an SSP archive (not a ZIP file)"]
    with pytest.raises(UserError):
        validate_ssp(tmp_path / "missing.ssp")
    # the experiment folder itself: its FMUs live in build/, not in resources/
    folder = tmp_path / "exp"
    shutil.copytree(EXP, folder)
    (folder / "resources").mkdir()
    for f in fmu_dir.glob("*.fmu"):
        shutil.copy(f, folder / "resources")
    assert validate_ssp(folder) == []


def test_variant_and_set_override_observer_settings(fmu_dir, tmp_path):
    """Our extension: `observer.setting` in a variant or --set sets an observer's setting (the
    filter's conicity in a robustness study); a component of that name would take precedence."""
    ssv = tmp_path / "faster.ssv"
    ssv.write_text(parameter_set("faster", real("alignment.V", 21) + integer("track.psd_level", 2)))
    s = read_system(EXP, variant=str(ssv), fmu_dirs=[fmu_dir])
    assert s.observers[0].settings == {"V": 21.0}
    assert s.component("track").parameters["psd_level"] == 2
    s = read_system(EXP, variant=str(ssv), fmu_dirs=[fmu_dir], overrides={"alignment": {"V": "22.5"}})
    assert s.observers[0].settings == {"V": 22.5}
    assert "no component 'filter'" in user_error(read_system, EXP, fmu_dirs=[fmu_dir],
                                                 overrides={"filter": {"V": "1"}})


# -- observer settings bound to parameters, the experiment's master and stop time -----------

BOUND = """<ssd:Annotations><ssc:Annotation type="org.railfmu.observers"><rf:Observers>
  <rf:Observer name="o" class="alignment_kf"><rf:Input name="a" connector="wheelset.ddy"/>
    <rf:Setting name="conicity" parameter="wheelset.alpha"/><rf:Setting name="mass" parameter="wheelset.m"/>
    <rf:Setting name="level" parameter="track.psd_level"/>{extra}</rf:Observer>
</rf:Observers></ssc:Annotation></ssd:Annotations>"""


def test_observer_setting_bound_to_a_parameter(fmu_dir, tmp_path):
    """`<rf:Setting name parameter="component.parameter"/>` takes the parameter's final value:
    the FMU start value, an SSD binding, the variant, --set, in that order; a value given to
    the setting itself wins; export keeps the binding."""
    write_ssd(tmp_path, annotations=BOUND.format(extra=""), wheelset=inline(real("alpha", 0.2)))
    (tmp_path / "variants").mkdir()
    (tmp_path / "variants" / "heavy.ssv").write_text(parameter_set("heavy", real("wheelset.m", 1500.0)))
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert s.observers[0].settings == {"conicity": 0.2, "mass": 1109.0, "level": 1}  # binding, start, start
    assert s.observers[0].setting_parameters == {"conicity": "wheelset.alpha", "mass": "wheelset.m",
                                                 "level": "track.psd_level"}
    s = read_system(tmp_path, variant="heavy", fmu_dirs=[fmu_dir],
                    overrides={"wheelset": {"alpha": "0.3"}, "track": {"psd_level": "2"}})
    assert s.observers[0].settings == {"conicity": 0.3, "mass": 1500.0, "level": 2}
    s = read_system(tmp_path, variant="heavy", fmu_dirs=[fmu_dir], overrides={"o": {"mass": "7"}})
    assert s.observers[0].settings["mass"] == 7 and "mass" not in s.observers[0].setting_parameters
    archive = write_ssp(read_system(tmp_path, variant="heavy", fmu_dirs=[fmu_dir]), tmp_path / "bound.ssp")
    again = read_system(archive, overrides={"wheelset": {"m": "1600"}})
    assert again.observers[0].settings == {"conicity": 0.2, "mass": 1600.0, "level": 1}
    for bad, expected in (
            ('<rf:Setting name="k" parameter="bogie.m"/>', "Setting 'k': parameter 'bogie.m': no component 'bogie'"),
            ('<rf:Setting name="k" parameter="wheelset.mass"/>',
             "Setting 'k': parameter 'wheelset.mass': WheelsetLateral.fmu has no variable 'mass'"),
            ('<rf:Setting name="k" parameter="wheelset.ddy"/>',
             "Setting 'k': parameter 'wheelset.ddy' is a(n) output, not a parameter"),
            ('<rf:Setting name="k" parameter="wheelset.m" value="1"/>',
             "Setting 'k': give one of value, connector or parameter, not value and parameter")):
        write_ssd(tmp_path, annotations=BOUND.format(extra=bad))
        assert expected in user_error(read_system, tmp_path, fmu_dirs=[fmu_dir])


def test_an_observer_is_switched_off_by_enabled(fmu_dir, tmp_path):
    """The reserved setting `enabled`: a Boolean, false from the SSD, a variant or --set."""
    write_ssd(tmp_path, annotations=BOUND.format(extra=""))
    assert read_system(tmp_path, fmu_dirs=[fmu_dir]).observers[0].enabled
    s = read_system(tmp_path, fmu_dirs=[fmu_dir], overrides={"o": {"enabled": "false"}})
    assert not s.observers[0].enabled and "enabled" not in s.observers[0].class_settings
    write_ssd(tmp_path, annotations=BOUND.format(extra='<rf:Setting name="enabled" value="false"/>'))
    assert not read_system(tmp_path, fmu_dirs=[fmu_dir]).observers[0].enabled
    assert read_system(tmp_path, fmu_dirs=[fmu_dir], overrides={"o": {"enabled": "true"}}).observers[0].enabled
    assert "Observer 'o': setting enabled='no' must be true or false" in user_error(
        read_system, tmp_path, fmu_dirs=[fmu_dir], overrides={"o": {"enabled": "no"}})


MASTER = ('<ssd:Annotations><ssc:Annotation type="org.railfmu.experiment"><rf:FixedStep stepSize="0.001" '
          'master="{name}"/></ssc:Annotation></ssd:Annotations>')


def test_experiment_prefers_a_master(fmu_dir, tmp_path):
    write_ssd(tmp_path)
    assert read_system(tmp_path, fmu_dirs=[fmu_dir]).master is None
    (tmp_path / "SystemStructure.ssd").write_text(
        ssd_text(step="").replace("</ssd:DefaultExperiment>", MASTER.format(name="container") + "</ssd:DefaultExperiment>"))
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert s.master == "container" and s.step_size == 0.001
    assert read_system(write_ssp(s, tmp_path / "m.ssp")).master == "container"  # export keeps it
    (tmp_path / "SystemStructure.ssd").write_text(
        ssd_text(step="").replace("</ssd:DefaultExperiment>", MASTER.format(name="euler") + "</ssd:DefaultExperiment>"))
    assert "FixedStep master='euler': choose one of jacobi, gauss-seidel, container" in user_error(
        read_system, tmp_path, fmu_dirs=[fmu_dir])


def test_a_variant_sets_the_stop_time(fmu_dir, tmp_path):
    """The reserved variant name experiment.stopTime (s) < --set experiment.stopTime < --stop-time."""
    write_ssd(tmp_path, stop="2", step="0.01")
    (tmp_path / "variants").mkdir()
    (tmp_path / "variants" / "short.ssv").write_text(parameter_set("short", real("experiment.stopTime", 0.5, "s")))
    (tmp_path / "variants" / "bad.ssv").write_text(parameter_set("bad", real("experiment.stopTime", 500, "ms")))
    s = read_system(tmp_path, fmu_dirs=[fmu_dir])
    assert (s.stop_time, s.stop_time_from) == (2.0, "ssd:DefaultExperiment")
    s = read_system(tmp_path, variant="short", fmu_dirs=[fmu_dir])
    assert (s.stop_time, s.stop_time_from) == (0.5, "variant short (experiment.stopTime)")
    assert s.n_steps == 50
    s = read_system(tmp_path, variant="short", fmu_dirs=[fmu_dir], overrides={"experiment": {"stopTime": "0.7"}})
    assert (s.stop_time, s.stop_time_from) == (0.7, "--set (experiment.stopTime)")
    s = read_system(tmp_path, variant="short", fmu_dirs=[fmu_dir], stop_time=1.5)
    assert (s.stop_time, s.stop_time_from) == (1.5, "--stop-time")
    assert "experiment.stopTime is in s, not 'ms'" in user_error(read_system, tmp_path, variant="bad",
                                                                 fmu_dirs=[fmu_dir])
    assert "--set experiment.stopTime: experiment.stopTime 'soon' must be a number of seconds" in user_error(
        read_system, tmp_path, fmu_dirs=[fmu_dir], overrides={"experiment": {"stopTime": "soon"}})
    assert "does not divide" in user_error(read_system, tmp_path, fmu_dirs=[fmu_dir],
                                           overrides={"experiment": {"stopTime": "0.555"}})
