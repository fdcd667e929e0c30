"""``railfmu export --ssp 2.0``: an SSP 2.0 archive, valid against the standard's 2.0 schemas,
that railfmu reads back into the run the 1.0 export gives.

SSP 2.0 keeps 1.0's namespaces; a 2.0 document says ``version="2.0"`` (the SSD and each
parameter set). An FMI 3.0 component's connectors and parameters carry its variables' sized
types (``ssc:Float64``, ``ssv:Int32``); an FMI 2.0 component keeps ``Real`` and ``Integer``.
The archive's SSD and its inline parameter sets are checked here against the 2.0 XSDs directly
(lxml, fmus/ssp/schema2), not through the writer's own check.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

import railfmu
from railfmu.experiments.engine.api import read_ssp
from railfmu.experiments.engine.runner import experiment_names, find_experiment
from railfmu.fmus.ssp.writer import write_ssp
from railfmu.fmus.ssp.xmltools import NS, SCHEMA_DIR_2
from railfmu.models.errors import UserError

SSD_XSD = etree.XMLSchema(etree.parse(str(SCHEMA_DIR_2 / "SystemStructureDescription.xsd")))
SSV_XSD = etree.XMLSchema(etree.parse(str(SCHEMA_DIR_2 / "SystemStructureParameterValues.xsd")))
SIZED = {"Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}


def _ssd(ssp: Path):
    with zipfile.ZipFile(ssp) as zf:
        return etree.fromstring(zf.read("SystemStructure.ssd"))


def _schema_errors(doc) -> list[str]:
    """The 2.0 schemas' complaints about an SSD and each of its inline parameter sets (the SSD
    schema takes their content as lax ``any``)."""
    errors = [] if SSD_XSD.validate(doc) else [str(e) for e in SSD_XSD.error_log]
    for pset in doc.iterfind(".//ssd:ParameterValues/ssv:ParameterSet", NS):
        if not SSV_XSD.validate(etree.fromstring(etree.tostring(pset))):
            errors += [str(e) for e in SSV_XSD.error_log]
    return errors


def _types(doc) -> set[str]:
    """The type elements of the connectors and parameter values."""
    found = {etree.QName(t).localname for t in doc.iterfind(".//ssd:Connector/*", NS)}
    return found | {etree.QName(t).localname for t in doc.iterfind(".//ssv:Parameter/*", NS)}


def _variants(first_only: bool) -> list[tuple[str, str]]:
    out = []
    for name in experiment_names():
        variants = find_experiment(name).variants
        out += [(name, v) for v in (variants[:1] if first_only else variants)]
    return out


# every variant as FMI 2 (~0.2 s each), one per experiment as FMI 3 (the writer's other types)
@pytest.mark.parametrize("fmi,experiment,variant", [(2, e, v) for e, v in _variants(False)]
                         + [(3, e, v) for e, v in _variants(True)])
def test_every_exported_variant_validates_against_the_ssp2_schemas(fmu_dir, tmp_path, fmi, experiment, variant):
    system = read_ssp(experiment, variant, fmi_version=fmi)
    doc = _ssd(write_ssp(system, tmp_path / "x.ssp", "2.0"))
    assert _schema_errors(doc) == []
    assert doc.get("version") == "2.0"
    psets = doc.findall(".//ssv:ParameterSet", NS)
    assert psets and {p.get("version") for p in psets} == {"2.0"}
    types = _types(doc)
    if fmi == 3:  # the FMI 3 variables' own types, never FMI 2's names
        assert "Float64" in types and not types & {"Real", "Integer"}
    else:
        assert "Real" in types and not types & SIZED
    # a unit a parameter names is defined in its parameter set (units are file-scoped)
    for pset in psets:
        defined = {u.get("name") for u in pset.iterfind("ssv:Units/ssc:Unit", NS)}
        named = {t.get("unit") for t in pset.iterfind("ssv:Parameters/ssv:Parameter/*", NS) if t.get("unit")}
        if pset.getparent().tag != f"{{{NS['ssc']}}}Annotation":
            assert named <= defined, named - defined


def test_the_1_0_export_is_still_ssp_1_0(fmu_dir, tmp_path):
    doc = _ssd(railfmu.export("suspension_fault", tmp_path / "x.ssp", "step_fault", stop_time=0.1))
    assert doc.get("version") == "1.0" and not _types(doc) & SIZED
    assert {p.get("version") for p in doc.iterfind(".//ssv:ParameterSet", NS)} == {"1.0"}


def test_an_unknown_ssp_version_is_one_line(tmp_path, capsys):
    from railfmu.experiments.engine.cli import main

    with pytest.raises(UserError, match="--ssp 1.1: railfmu writes SSP 1.0 and 2.0"):
        railfmu.export("track_wheelset", tmp_path / "x.ssp", ssp_version="1.1")
    with pytest.raises(SystemExit) as exit_:
        main(["export", "track_wheelset", "--ssp", "3.0", "-o", str(tmp_path / "y.ssp")])
    assert exit_.value.code == 2 and "--ssp" in capsys.readouterr().err
    assert not (tmp_path / "x.ssp").exists() and not (tmp_path / "y.ssp").exists()


# short runs: the observers, a replay's tables (String values in the FMU copies and in our
# annotation), the FMI 3 builds' sized types read back
ROUND_TRIP = [("lateral_alignment", "standard", 2, 2.0), ("trolley_imu_replay", "recorded", 2, 2.0),
              ("suspension_fault", "step_fault", 3, 2.0)]


@pytest.mark.parametrize("experiment,variant,fmi,stop", ROUND_TRIP)
def test_the_2_0_export_runs_as_the_1_0_export(fmu_dir, tmp_path, experiment, variant, fmi, stop):
    runs = {}
    for version in ("1.0", "2.0"):
        ssp = railfmu.export(experiment, tmp_path / f"{version}.ssp", variant, stop_time=stop, fmi_version=fmi,
                             ssp_version=version)
        assert _ssd(ssp).get("version") == version
        runs[version] = railfmu.run(ssp)
    one, two = runs["1.0"], runs["2.0"]
    # a replay runs to its table's end, whatever the archive says
    assert two.system.stop_time == one.system.stop_time and len(two.signals["time"]) > 10
    # the same System, so the same numbers: equal, not close
    assert one.signals.keys() == two.signals.keys()
    for name, x in one.signals.items():
        assert np.array_equal(x, two.signals[name], equal_nan=True), name
    assert one.estimates.keys() == two.estimates.keys()
    for obs, est in one.estimates.items():
        for name, x in est.items():
            assert np.array_equal(x, two.estimates[obs][name], equal_nan=True), (obs, name)
    params = {c.name: {k: v for k, v in c.parameters.items() if not isinstance(v, str)}
              for c in one.system.components}
    assert params == {c.name: {k: v for k, v in c.parameters.items() if not isinstance(v, str)}
                      for c in two.system.components}
