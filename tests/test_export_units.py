"""An exported SSP shows every importer the units the SSD gives generic channels.

StepSource, SensorNoise and SignalTable declare no unit (the unit is the connection's); the
SSD gives one on the connector. Importers that compare the FMUs' units across a connection
(OMSimulator 3.0: "Unit mismatch in connection fault.y -> coach.k1") need the FMU to declare
it: ``write_ssp`` packs such a component with its own copy of the FMU whose modelDescription
declares the connectors' units (railfmu.fmus.ssp.writer). Checked here without OMSimulator:
both ends of every connection agree in the archive's FMUs (or the connection carries the
complete map), the copies pass ``fmpy validate``, and railfmu reads the same system back.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from railfmu.experiments.engine.api import export_system
from railfmu.fmus.generate.build import validate
from railfmu.fmus.ssp import read_system

CASES = [("suspension_fault", "step_fault"), ("train_resistance", "standard"),
         ("train_resistance_measured", "measured"), ("alignment_replay", "measured")]


def _signature(system):
    """What must survive the round trip: connections with their maps, numeric parameters,
    the observers' signal units (file names and FMU paths change by design)."""
    conns = [(str(k), k.factor, k.offset) for k in system.connections]
    params = {c.name: {k: v for k, v in c.parameters.items() if not isinstance(v, str)}
              for c in system.components}
    units = {o.name: {s: (u.name, u.exponents, u.factor, u.offset) for s, u in o.units.items()}
             for o in system.observers}
    return conns, params, units


@pytest.mark.parametrize("experiment,variant", CASES)
def test_connection_units_agree_in_the_archive(fmu_dir, tmp_path, experiment, variant):
    # 20 s: the measured log's rows are 10 s apart, and its replay steps at them
    ssp, system = export_system(experiment, tmp_path / "x.ssp", variant, stop_time=20.0)
    out = tmp_path / "x"
    with zipfile.ZipFile(ssp) as zf:
        zf.extractall(out)
    again = read_system(ssp)
    mds = {c.name: read_model_description(str(out / "resources" / c.fmu.name)) for c in again.components}
    for c in again.components:
        assert validate(out / "resources" / c.fmu.name) == [], c.fmu.name
    units = {name: {v.name: v.unit for v in md.modelVariables} for name, md in mds.items()}
    given = {(c.name, n) for c in system.components for n, v in c.variables.items()
             if v.type == "Real" and not v.unit and units[c.name][n]}
    assert given, "the case has generic channels that the SSD gives a unit"
    for k in again.connections:
        su, du = units[k.src][k.src_var], units[k.dst][k.dst_var]
        if su == du:
            continue
        assert su and du, f"{k}: one end declares {su or du!r}, the other no unit"
        # different units: the connection carries the complete map (suppressUnitConversion)
        assert not k.identity, f"{k}: {su} -> {du} without a map"
    assert _signature(again) == _signature(system)


def _copy(ssp, component: str, out):
    """The FMU file the archive's SSD gives ``component``, extracted to ``out``."""
    from lxml import etree

    with zipfile.ZipFile(ssp) as zf:
        ssd = etree.fromstring(zf.read("SystemStructure.ssd"))
        source = next(e.get("source") for e in ssd.iter("{*}Component") if e.get("name") == component)
        path = out / source.rpartition("/")[2]
        path.write_bytes(zf.read(source))
        return ssd, path


def _first_outputs(fmu, guid: str | None = None) -> dict[str, float]:
    """The Real outputs at t = 0 of ``fmu`` (FMI 2 or 3) run in FMPy with no parameter set (its
    start values)."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(str(fmu))
    unzipped = extract(str(fmu))
    three = md.fmiVersion.startswith("3")
    s = (FMU3Slave if three else FMU2Slave)(guid=guid or md.guid, unzipDirectory=unzipped,
                                            modelIdentifier=md.coSimulation.modelIdentifier, instanceName="copy")
    s.instantiate()
    try:
        if three:
            s.enterInitializationMode(startTime=0.0)
        else:
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
        s.exitInitializationMode()
        outs = [v for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")]
        values = (s.getFloat64 if three else s.getReal)([v.valueReference for v in outs])
        return dict(zip((v.name for v in outs), values))
    finally:
        s.terminate()
        s.freeInstance()


@pytest.mark.parametrize("fmi", [2, 3])
def test_string_parameters_are_the_copy_s_own_start_values(tmp_path, fmi):
    """OMSimulator 3.0 reads no ssv:String: the SSD has none, and each SignalTable's own FMU copy
    finds its table and columns with nothing set (the runtime reads the copy's start values:
    FMI 2's ``start``, FMI 3's ``<Start value=...>``), under a GUID (instantiationToken) of its
    own that extends the binary's (libcosim unpacks once per GUID)."""
    ssp, system = export_system("trolley_imu_replay", tmp_path / "x.ssp", "recorded", stop_time=2.0,
                                fmi_version=fmi)
    guids, seen = {}, []
    for comp in ("imu", "truth"):
        ssd, fmu = _copy(ssp, comp, tmp_path)
        assert not list(ssd.iter("{*}String")) or all(
            s.getparent().getparent().getparent().getparent().get("type") == "org.railfmu.strings"
            for s in ssd.iter("{*}String"))
        md = read_model_description(str(fmu))
        guids[comp] = md.guid
        assert validate(fmu) == []
        c = next(c for c in system.components if c.name == comp)
        with zipfile.ZipFile(fmu) as zf:
            rows = zf.read(f"resources/{Path(c.parameters['file']).name}").decode().splitlines()
        header = [h.strip() for h in rows[0].split(",")]
        first = {f"y_{k}": float(rows[1].split(",")[header.index(c.parameters[f"column_{k}"])])
                 for k in range(1, 17) if c.parameters.get(f"column_{k}")}
        seen += [v for v in first.values() if v != 0.0]
        got = _first_outputs(fmu)
        assert {y: got[y] for y in first} == first
    assert seen  # tables read, not the zeros of no table (the IMU's increments start at 0, the truth does not)
    base = read_model_description(str(next(c.fmu for c in system.components if c.name == "imu"))).guid
    assert guids["imu"] != guids["truth"] and all(g.startswith(base + "-") for g in guids.values())
    # railfmu reads the values back from the SSD
    again = read_system(ssp)
    for c in system.components:
        strings = {k: v for k, v in c.parameters.items() if isinstance(v, str)}
        mine = next(a for a in again.components if a.name == c.name).parameters
        assert {k: Path(v).name for k, v in strings.items()} == {k: Path(mine[k]).name for k in strings}


def test_a_guid_that_only_starts_like_the_binary_s_is_refused(fmu_dir):
    fmu = fmu_dir / "SignalTable.fmu"
    guid = read_model_description(str(fmu)).guid
    assert _first_outputs(fmu, guid + "-0a1b") == _first_outputs(fmu)  # a copy's GUID
    for other in (guid + "0a1b", guid + "-", guid[:-2] + "}"):
        with pytest.raises(Exception, match="Failed to instantiate"):
            _first_outputs(fmu, other)


def test_a_start_value_with_xml_entities_reaches_the_fmu(fmu_dir, tmp_path):
    """The runtime decodes what lxml escapes in an attribute (& < > " and a tab as &#9;)."""
    from railfmu.fmus.ssp.writer import _instance_copy

    column, name = "a&b <c> 'd'\tü", 't&"x".csv'  # the CSV reader takes no quoted header: the quote is in the file name
    table = tmp_path / "t.csv"
    table.write_text(f"time,{column}\n0,2.5\n1,3.5\n", encoding="utf-8")
    copy = tmp_path / "copy.fmu"
    copy.write_bytes(_instance_copy(fmu_dir / "SignalTable.fmu", "x", {table: name}, None,
                                    {"file": name, "column_1": column}))
    with zipfile.ZipFile(copy) as zf:
        md = zf.read("modelDescription.xml").decode()
    assert "a&amp;b &lt;c&gt; 'd'&#9;ü" in md and "t&amp;&quot;x&quot;.csv" in md  # what the runtime decodes
    assert _first_outputs(copy)["y_1"] == 2.5
