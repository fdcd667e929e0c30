"""SignalTable FMU (measured-data replay): exact at the table's times, linear or hold between,
Boolean and Integer channels, a clean end at the table's end, and one line naming file, line
and column for every bad CSV, through FMPy, our Slave and `railfmu run`."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2LastSuccessfulTime, fmi2Terminated

from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.fmus.generate.build import validate
from railfmu.models.sources.signal_table import EXAMPLE, N_BOOLEAN, N_INTEGER, N_REAL, Table

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64",
                                reason="needs gcc on linux64")
DISCARD = 2


@pytest.fixture(scope="module")
def fmu(fmu_dir):
    return fmu_dir / "SignalTable.fmu"


@pytest.fixture
def slave(fmu):
    """Factory: FMU2Slave instances of SignalTable (fmpy's own calls, no wrapper)."""
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    d = extract(str(fmu))
    made = []

    def make(params: dict, start=0.0, stop=None):
        s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="SignalTable",
                      instanceName=f"table{len(made)}")
        s.instantiate()
        made.append(s)
        s.setupExperiment(startTime=start, stopTime=stop)
        s.enterInitializationMode()
        for name, value in params.items():
            {str: s.setString, int: s.setInteger, float: s.setReal}[type(value)]([vr[name]], [value])
        s.exitInitializationMode()
        s.vr = vr
        return s

    yield make
    for s in made:
        s.freeInstance()
    shutil.rmtree(d, ignore_errors=True)


def reals(s, n=N_REAL):
    return np.array(s.getReal([s.vr[f"y_{k}"] for k in range(1, n + 1)]))


def write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in rows))
    return path


def test_fmu_is_valid_with_units_and_descriptions(fmu):
    assert validate(fmu) == []
    md = read_model_description(str(fmu))
    for v in md.modelVariables:
        assert v.description, v.name
    assert {v.name: v.unit for v in md.modelVariables}["time_offset"] == "s"
    # channel value references are consecutive (SignalTable.c indexes them so)
    for prefix, n in (("y_", N_REAL), ("boolean_", N_BOOLEAN), ("integer_", N_INTEGER),
                      ("column_", N_REAL), ("boolean_column_", N_BOOLEAN), ("integer_column_", N_INTEGER)):
        vrs = [v.valueReference for v in md.modelVariables
               if v.name.startswith(prefix) and v.name[len(prefix):].isdigit()]
        assert vrs == list(range(vrs[0], vrs[0] + n)), prefix


@pytest.fixture(scope="module")
def axlebox_csv(tmp_path_factory):
    """A 400 m run at 20 m/s sampled at 1 kHz (20,001 rows): awkward decimals (full 17-digit
    reprs, short ones such as 0.1, -0.0, tiny and huge magnitudes), the times as a logger
    writes them."""
    rng = np.random.default_rng(7)
    n = 20_001
    t = [f"{k / 1000:.3f}" for k in range(n)]
    a = rng.normal(0.0, 3.0, n)
    a[:6] = [0.1, -0.0, 1e-300, -2.5e300, 5e-324, 1 / 3]
    cols = [[repr(float(x)) for x in a], [f"{x:.6g}" for x in rng.normal(0, 1, n)]]
    path = write(tmp_path_factory.mktemp("axlebox") / "axlebox run.csv", ["time", "ddy_1", "ddz_1"],
                 zip(t, *cols))
    return path, np.array([float(x) for x in t]), np.array([[float(x) for x in c] for c in cols]).T


def test_replay_is_bit_identical_at_every_table_time_through_fmpy(fmu, axlebox_csv):
    path, t, y = axlebox_csv
    res = fmpy.simulate_fmu(str(fmu), stop_time=20.0, step_size=1e-3, output_interval=1e-3,
                            start_values={"file": str(path), "column_1": "ddz_1", "column_3": "ddy_1"},
                            output=["y_1", "y_2", "y_3"])
    assert len(res) == len(t)
    assert np.array_equal(res["y_3"].view(np.int64), y[:, 0].view(np.int64))  # -0.0 included
    assert np.array_equal(res["y_1"].view(np.int64), y[:, 1].view(np.int64))
    assert not res["y_2"].any()  # unbound channel


def test_accumulated_master_time_still_hits_every_row(slave, axlebox_csv):
    """A master that accumulates t += h (OMSimulator) is 1e-13 off the rows after 20 s: the
    rows are matched within the tolerance, so sample-and-hold does not slip one row."""
    path, t, y = axlebox_csv
    s = slave({"file": str(path), "column_1": "ddy_1", "interpolation": 0})
    ti, got, off = 0.0, [s.getReal([s.vr["y_1"]])[0]], []
    for _ in range(len(t) - 1):
        s.doStep(ti, 1e-3)
        ti += 1e-3
        off.append(ti)
        got.append(s.getReal([s.vr["y_1"]])[0])
    assert np.any(np.array(off) != t[1:])  # the accumulated time does drift off the grid
    assert np.array_equal(np.array(got).view(np.int64), y[:, 0].view(np.int64))


# GNSS-like: fixes at irregular times, a valid flag, a driving regime, a text column nobody binds
GNSS = Path(__file__).parent / "data" / "gnss_replay.csv"
BINDING = {"column_1": "gnss_x", "column_2": "speed", "boolean_column_2": "valid",
           "integer_column_3": "regime"}


@pytest.mark.parametrize("interpolation", [0, 1])
@pytest.mark.parametrize("offset", [0.0, 100.25])
def test_linear_and_hold_between_rows_equal_the_python_twin(slave, interpolation, offset):
    path = GNSS
    twin = Table.read(path, BINDING)
    s = slave({"file": str(path), "interpolation": interpolation, "time_offset": offset, **BINDING},
              start=offset - 0.5)
    ti, h = offset - 0.5, 0.01
    for _ in range(500):  # from before the first row to past the last (held)
        real, boolean, integer, ended = twin.at(ti, interpolation, offset)
        assert np.array_equal(reals(s), real)  # bit-identical to the twin
        assert s.getBoolean([s.vr[f"boolean_{k}"] for k in range(1, 5)]) == list(boolean)
        assert s.getInteger([s.vr[f"integer_{k}"] for k in range(1, 5)]) == list(integer)
        s.doStep(ti, h)
        ti += h
    # the twin against closed forms: 1.0 s is 3/13 of the way from 0.7 to 2.0
    real, boolean, integer, _ = twin.at(offset + 1.0, interpolation, offset)
    want = [12.5 + (11.0 - 12.5) * (0.3 / 1.3), 1.5 + (-3.0 - 1.5) * (0.3 / 1.3)] if interpolation \
        else [12.5, 1.5]
    assert real[:2] == pytest.approx(want, rel=1e-14)
    assert list(boolean) == [False, True, False, False] and list(integer) == [0, 0, 1, 0]
    assert list(twin.at(offset - 0.3, interpolation, offset)[0][:2]) == [10.0, 0.0]  # first row held
    assert twin.at(offset + 4.5, interpolation, offset)[3]  # past the end


@pytest.mark.parametrize("h, last_start", [(0.5, 4.0), (0.3, 3.9)])
def test_end_of_table_ends_the_simulation_cleanly(slave, h, last_start):
    path = GNSS
    s = slave({"file": str(path), "after_end": 1, **BINDING})
    ti = 0.0
    with pytest.raises(FMICallException) as e:
        for _ in range(100):
            s.doStep(ti, h)
            ti += h
    assert e.value.status == DISCARD
    assert s.getBooleanStatus(fmi2Terminated) is True
    # the step that reaches past 4.0 s ends at 4.0 s exactly, with the last row
    assert s.getRealStatus(fmi2LastSuccessfulTime) == 4.0
    assert s.getReal([0]) == [4.0]
    assert list(reals(s, 2)) == [20.0, 4.25]
    assert s.getInteger([s.vr["integer_3"]]) == [3]
    assert ti == pytest.approx(last_start)  # the step from here ended early (or at once)
    s.terminate()
    # after_end = 0 holds the last row instead
    hold = slave({"file": str(path), **BINDING})
    for k in range(10):
        hold.doStep(k * 0.5, 0.5)
    assert hold.getBooleanStatus(fmi2Terminated) is False
    assert list(reals(hold, 2)) == [20.0, 4.25]


def test_relative_file_is_read_from_resources_and_fmpy_stops_at_the_end(fmu):
    res = fmpy.simulate_fmu(str(fmu), stop_time=10.0, output_interval=0.5,
                            start_values={"file": "example.csv", "column_1": "position",
                                          "boolean_column_1": "gnss_valid", "integer_column_1": "regime",
                                          "after_end": 1},
                            output=["y_1", "boolean_1", "integer_1"])
    assert res["time"][-1] == 5.0  # the example table ends at 5 s; FMPy stops there
    twin = Table.read(EXAMPLE, {"column_1": "position", "boolean_column_1": "gnss_valid",
                                "integer_column_1": "regime"})
    for row in res:
        real, boolean, integer, _ = twin.at(row["time"])
        assert (row["y_1"], row["boolean_1"], row["integer_1"]) == (real[0], boolean[0], integer[0])


def test_no_file_gives_zeros_and_runs(slave):
    s = slave({})
    s.doStep(0.0, 1.0)
    assert not reals(s).any() and s.getBooleanStatus(fmi2Terminated) is False


# ---- bad CSV: one message naming file, line and column -----------------------------------

GOOD = "time,x,flag,n\n0.0,1.0,0,1\n0.5,2.0,1,2\n1.0,3.0,1,3\n"
BAD = [  # (file text or None = missing, parameters, the message after the path)
    (None, {}, ": cannot open (No such file or directory)"),
    (GOOD, {"column_2": "speed"},
     ", line 1: no column 'speed' (named by parameter column_2); the header has: time, x, flag, n"),
    (GOOD.replace("0.5,2.0", "1.5,2.0"), {},
     ", line 4, column 1 (time): 1 is before the previous row's time 1.5 (times must increase strictly)"),
    (GOOD.replace("0.5,2.0", "0.0,2.0"), {},
     ", line 3, column 1 (time): 0 repeats the previous row's time 0 (times must increase strictly)"),
    (GOOD.replace("2.0,1,2", "nan,1,2"), {}, ", line 3, column 2 (x): 'nan' is not a finite number"),
    (GOOD.replace("3.0,1,3", "3.O,1,3"), {}, ", line 4, column 2 (x): '3.O' is not a number"),
    (GOOD.replace("0.5,2.0,1,2", "0.5,2.0,1"), {}, ", line 3: 3 fields, but the header has 4 columns"),
    (GOOD.replace("2.0,1,2", "2.0,2,2"), {}, ", line 3, column 3 (flag): '2' is not 0 or 1"),
    (GOOD.replace("1.0,3.0,1,3", "1.0,3.0,1,3.5"), {}, ", line 4, column 4 (n): '3.5' is not an integer"),
    (GOOD.replace("time,", "t,"), {}, ", line 1, column 1: the first column must be 'time' or 'time_s' (s), not 't'"),
    ("time,x,flag,n\n", {}, ", line 2: no data rows after the header"),
]
BAD_IDS = ["missing-file", "missing-column", "non-monotonic", "repeated-time", "nan", "text", "ragged",
           "boolean-not-0-1", "integer-not-integer", "no-time-column", "no-rows"]


@pytest.mark.parametrize("text, params, message", BAD, ids=BAD_IDS)
def test_bad_csv_is_one_message_naming_file_line_and_column(fmu, tmp_path, text, params, message):
    path = tmp_path / "run.csv"
    if text is not None:
        path.write_text(text)
    with Slave(fmu, "gnss") as s:
        with pytest.raises(FMUError) as e:
            s.initialize(0.0, 1.0, {"file": str(path), "column_1": "x", "boolean_column_1": "flag",
                                    "integer_column_1": "n", **params})
        errors = [m for st, _, m in s.messages if st == "Error"]
    assert errors == [f"file {path}{message}"]  # the FMU logged exactly this one line
    assert str(e.value) == f"SignalTable.fmu (gnss): fmi2ExitInitializationMode failed: file {path}{message}"


def test_bad_csv_in_an_ssd_run_is_one_line_and_exit_2(fmu, tmp_path):
    """The whole chain: SSD -> railfmu run -> the FMU's message as the one error line."""
    bad = tmp_path / "gnss.csv"
    bad.write_text(GOOD.replace("3.0,1,3", "3.0,1,3,4"))
    good = GNSS
    ssd = tmp_path / "replay" / "SystemStructure.ssd"
    ssd.parent.mkdir()
    ssd.write_text(SSD.format(file=bad))
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", str(ssd.parent),
                          "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("railfmu: error:")]
    assert len(errors) == 1, res.stderr
    assert errors[0].startswith(  # (what follows the FMU's message is the masters' business)
        f"railfmu: error: SignalTable.fmu (gnss): fmi2ExitInitializationMode failed: file {bad}, "
        "line 4: 5 fields, but the header has 4 columns"), errors[0]
    # the same SSD with a good file runs
    ssd.write_text(SSD.format(file=good).replace('"x"', '"gnss_x"'))
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", str(ssd.parent),
                          "--out", str(tmp_path / "out2")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    rows = (tmp_path / "out2" / "signals.csv").read_text().splitlines()
    assert rows[0].split(",")[:2] == ["time", "gnss.y_1"]
    assert [float(v) for v in rows[1].split(",")[:2]] == [0.0, 10.0]
    assert [float(v) for v in rows[-1].split(",")[:2]] == [2.0, 11.0]


SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="replay"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:rf="https://railfmu.org/ssp/1">
  <ssd:System name="replay">
    <ssd:Elements>
      <ssd:Component name="gnss" source="resources/SignalTable.fmu" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors>
          <ssd:Connector name="y_1" kind="output"><ssc:Real unit="m"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="gnss">
                <ssv:Parameters>
                  <ssv:Parameter name="file"><ssv:String value="{file}"/></ssv:Parameter>
                  <ssv:Parameter name="column_1"><ssv:String value="x"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Annotations>
      <ssc:Annotation type="org.railfmu.recorder">
        <rf:Recorder><rf:Record connector="gnss.y_1"/></rf:Recorder>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="2">
    <ssd:Annotations>
      <ssc:Annotation type="org.railfmu.experiment"><rf:FixedStep stepSize="0.01"/></ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def test_saved_state_replays_the_same_rows(slave):
    """The table is not part of the FMU state: set state reads it again from the restored
    parameters, and the continuation is the same (the cursor is only a hint)."""
    path = GNSS
    s = slave({"file": str(path), **BINDING})
    for k in range(10):
        s.doStep(k * 0.1, 0.1)
    state = s.getFMUstate()
    first = []
    for k in range(10, 40):
        s.doStep(k * 0.1, 0.1)
        first.append(reals(s, 2))
    s.setFMUstate(state)
    s.freeFMUstate(state)
    again = []
    for k in range(10, 40):
        s.doStep(k * 0.1, 0.1)
        again.append(reals(s, 2))
    assert np.array_equal(np.array(first), np.array(again))
