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
