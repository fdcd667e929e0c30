"""Integer and Boolean signals and FMI 2.0 status semantics through the three masters, on the
self-contained test FMU tests/data/stair/ (counter = floor(t), odd, sum = counter + offset,
gated = odd and enable, y = u; fmi2Discard + fmi2Terminated past stop_time).

Two instances: ``a`` (stop_time 9 s) feeds ``b``: a.counter -> b.offset (Integer),
a.odd -> b.enable (Boolean). At 0.25 s steps, every master samples b.sum = b.counter +
a.counter = 2 floor(t) and b.gated = odd(floor(t)) exactly (the inputs are piecewise
constant, so the coupling delay of Jacobi does not show at whole seconds... except on the
step that crosses one: asserted row by row against the closed form with the one-step delay
of each master).
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from railfmu.fmus.cosim.masters import MASTERS, run
from railfmu.experiments.engine.recorder import ArrayRecorder, CsvRecorder
from railfmu.fmus.cosim.system import Component, Connection, System, check_system
from railfmu.models.errors import UserError

from stair_fmu import build_stair


@pytest.fixture(scope="module")
def stair(tmp_path_factory):
    return build_stair(tmp_path_factory.mktemp("stair"))


REC = ["a.counter", "a.odd", "b.offset", "b.enable", "b.sum", "b.gated", "a.level"]


def pair(fmu, stop_time=12.0, a=None, b=None, h=0.25):
    return System("stairs", [Component("a", fmu, dict(a or {})), Component("b", fmu, dict(b or {"stop_time": 100.0}))],
                  [Connection("a", "counter", "b", "offset"), Connection("a", "odd", "b", "enable")],
                  stop_time=stop_time, step_size=h, record=list(REC))


def col(res, name):
    return res.data[:, res.columns.index(name)]


@pytest.mark.parametrize("master", MASTERS)
def test_integer_and_boolean_connections_and_the_early_end(stair, tmp_path, master):
    system = pair(stair)
    sink, mem = CsvRecorder(tmp_path / "signals.csv", types=system.signal_types()), ArrayRecorder()
    res = run(system, master, sinks=[sink, mem], progress=False)
    # a ends the simulation at 9 s: 37 rows (0 .. 9 s), complete, named
    assert res.complete and res.end_time == 9.0 and len(res.data) == 37
    assert res.early_end.startswith("stair.fmu (a) ended the simulation at t = 9 s")
    assert sink.complete is True and mem.complete is True and sink.last_time == 9.0
    t = res.data[:, 0]
    np.testing.assert_array_equal(t, 0.25 * np.arange(37))
    counter = np.floor(t + 1e-9)
    np.testing.assert_array_equal(col(res, "a.counter"), counter)
    np.testing.assert_array_equal(col(res, "a.level"), counter)
    np.testing.assert_array_equal(col(res, "a.odd"), counter % 2)
    # the sample holds every input from its source at t (all masters)
    np.testing.assert_array_equal(col(res, "b.offset"), counter)
    np.testing.assert_array_equal(col(res, "b.enable"), counter % 2)
    np.testing.assert_array_equal(col(res, "b.sum"), 2 * counter)  # direct feedthrough of offset
    np.testing.assert_array_equal(col(res, "b.gated"), counter % 2)
    # signals.csv: integers and 0/1, exactly the rows of the result
    rows = list(csv.reader(open(tmp_path / "signals.csv", newline="")))
    assert rows[0] == ["time", *REC]
    assert len(rows) - 1 == 37 == sink.rows_written
    assert rows[1 + 4 * 3] == ["3.0", "3", "1", "3", "1", "6", "1", "3.0"]  # t = 3 s
    np.testing.assert_array_equal(np.array(rows[1:], dtype=float), res.data)
    np.testing.assert_array_equal(mem.data, res.data)


def test_masters_agree_bit_for_bit_on_integer_and_boolean(stair):
    system = pair(stair, b={"stop_time": 100.0, "u": 0.5})
    system.record = [*REC, "b.y"]
    res = {m: run(system, m, progress=False) for m in MASTERS}
    np.testing.assert_array_equal(res["container"].data, res["jacobi"].data)
    np.testing.assert_array_equal(res["gauss-seidel"].data, res["jacobi"].data)
    assert (col(res["jacobi"], "b.y") == 0.5).all()  # a Real parameter-set input echoed


@pytest.mark.parametrize("master", MASTERS)
def test_fmi2_error_names_the_component_and_the_status(stair, master):
    system = pair(stair, a={"error_time": 2.0})
    with pytest.raises(UserError, match=r"^stair\.fmu \(a\): fmi2DoStep at t = 2 s failed: fmi2Error "):
        run(system, master, progress=False)


@pytest.mark.parametrize("master", MASTERS)
def test_discard_without_termination_is_an_error(stair, master):
    system = pair(stair, b={"stop_time": 100.0, "discard_time": 3.0})
    with pytest.raises(UserError, match=r"^stair\.fmu \(b\): fmi2DoStep at t = 3 s failed: fmi2Discard "):
        run(system, master, progress=False)


def test_real_integer_mismatch_and_maps_on_integers_are_refused(stair):
    system = pair(stair)
    system.connections.append(Connection("a", "level", "b", "offset"))
    with pytest.raises(UserError, match=r"a\.level -> b\.offset: type mismatch: Real -> Integer"):
        check_system(system)
    system = pair(stair)
    system.connections[0].factor = 2.0
    with pytest.raises(UserError, match=r"a\.counter -> b\.offset: a LinearTransformation .* not Integer"):
        check_system(system)


def test_an_fmu_without_binary_is_compiled_from_its_sources(tmp_path):
    fmu = build_stair(tmp_path, binary=False)
    system = pair(fmu, stop_time=2.0)
    res = run(system, "jacobi", progress=False)
    assert res.complete and res.early_end is None and res.end_time == 2.0
    assert math.isclose(col(res, "b.sum")[-1], 4.0)


SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="one">
  <ssd:System name="one">
    <ssd:Elements>
      <ssd:Component name="s" source="stair.fmu">
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="offset"><ssv:Integer value="5"/></ssv:Parameter>
            <ssv:Parameter name="enable"><ssv:Boolean value="true"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="4"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("master", MASTERS)
def test_integer_and_boolean_inputs_set_from_ssv_and_set(stair, tmp_path, master):
    from railfmu.fmus.ssp import read_system

    build_stair(tmp_path)
    (tmp_path / "SystemStructure.ssd").write_text(SSD)
    system = read_system(tmp_path)
    assert system.components[0].parameters == {"offset": 5, "enable": True}
    assert system.step_size == 0.25  # the FMU's DefaultExperiment
    res = run(system, master, progress=False)
    counter = np.floor(res.data[:, 0] + 1e-9)
    np.testing.assert_array_equal(col(res, "s.sum"), counter + 5)
    np.testing.assert_array_equal(col(res, "s.gated"), counter % 2)
    # --set overrides, as text
    system = read_system(tmp_path, overrides={"s": {"offset": "-2", "enable": "false"}})
    res = run(system, master, progress=False)
    np.testing.assert_array_equal(col(res, "s.sum"), np.floor(res.data[:, 0] + 1e-9) - 2)
    assert (col(res, "s.gated") == 0).all()


def test_stair_is_a_valid_fmu(stair):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(stair)) == []


def test_container_without_c_compiler_gives_the_same_rows(stair, monkeypatch):
    """Without a C compiler the container master runs the Jacobi master's Python loop, and
    FMPy's container path (systems with FMI 3.0 components) the ctypes loop that replaces its
    C driver: same Integer/Boolean rows, same early end."""
    import railfmu.fmus.cosim.container as container
    import railfmu.fmus.cosim.native_loop as native_loop
    from railfmu.fmus.cosim.masters import _run_container

    system = pair(stair)
    jac = run(system, "jacobi", progress=False)
    monkeypatch.setattr(native_loop, "load_loop", lambda: None)
    monkeypatch.setattr(container, "load_driver", lambda: None)
    for con in (run(system, "container", progress=False), _run_container(system, (), False)):
        assert con.master == "container" and any("no C compiler" in n for n in con.notes)
        assert con.early_end == jac.early_end and con.end_time == 9.0
        np.testing.assert_array_equal(con.data, jac.data)
