"""A table FMU asked to read a file that is missing, unreadable or empty fails
fmi2ExitInitializationMode with a logged message naming the parameter (in FMPy): never a
silent run on zeros. Where no file is a valid configuration it stays one:

* SignalTable ``file`` empty with no column bound: a source of zeros (train_resistance's
  headwind outside its drift variant); empty with a bound column: an error.
* TrackIrregularity ``profile_file`` and Trolley ``irregularity_file`` empty: no measured
  profile (the spectrum, harmonic and step parts alone).
* TrainLongitudinal and Driver ``line_file``, Trolley ``track_file``: default to a shipped
  table; empty is an error.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

HEADERS = {
    "signal": "time,a\n",
    "line": "position_m,gradient_permille,speed_limit_kmh\n",
    "profile": "s,alignment,vertical_left,vertical_right\n",
    "track": "kind,start_m,end_m,radius_m,cant_mm,gradient_permille\n",
}
# (FMU, parameter, header of its format, other String parameters)
TABLES = [
    ("SignalTable", "file", "signal", {"column_1": "a"}),
    ("TrackIrregularity", "profile_file", "profile", {}),
    ("TrainLongitudinal", "line_file", "line", {}),
    ("Driver", "line_file", "line", {}),
    ("Trolley", "track_file", "track", {}),
    ("Trolley", "irregularity_file", "profile", {}),
]
OPTIONAL = {("TrackIrregularity", "profile_file"), ("Trolley", "irregularity_file")}  # "": no table


def exit_init(fmu_dir: Path, tmp: Path, identifier: str, strings: dict) -> bool:
    fmu = Path(fmu_dir) / f"{identifier}.fmu"
    md = read_model_description(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu, unzipdir=tmp / identifier),
                  modelIdentifier=identifier, instanceName="t")
    s.instantiate(loggingOn=True)
    try:
        s.setupExperiment(startTime=0.0)
        for name, value in strings.items():
            s.setString([vr[name]], [str(value)])
        s.enterInitializationMode()
        try:
            s.exitInitializationMode()
        except Exception:
            return False
        s.terminate()
        return True
    finally:
        s.freeInstance()


def _files(tmp: Path, kind: str) -> dict[str, str]:
    (tmp / "empty.csv").write_text("")
    (tmp / "header_only.csv").write_text(HEADERS[kind])
    return {"empty name": "", "missing": str(tmp / "no_such.csv"), "empty file": str(tmp / "empty.csv"),
            "header only": str(tmp / "header_only.csv"), "a folder": str(tmp)}


@pytest.mark.parametrize("identifier,param,kind,extra", TABLES, ids=[f"{t[0]}.{t[1]}" for t in TABLES])
@pytest.mark.parametrize("case", ["empty name", "missing", "empty file", "header only", "a folder"])
def test_a_missing_table_fails_naming_the_parameter(fmu_dir, tmp_path, capfd, identifier, param, kind,
                                                    extra, case):
    value = _files(tmp_path, kind)[case]
    if case == "empty name" and (identifier, param) in OPTIONAL:
        pytest.skip("no file is a valid configuration here (module docstring)")
    assert not exit_init(fmu_dir, tmp_path, identifier, {param: value, **extra})
    log = capfd.readouterr().out
    assert param in log, f"{identifier}: the message names {param}: {log!r}"


@pytest.mark.parametrize("identifier,param", [("SignalTable", "file"), ("TrackIrregularity", "profile_file"),
                                              ("Trolley", "irregularity_file")])
def test_no_file_stays_valid_where_it_means_no_table(fmu_dir, tmp_path, identifier, param):
    assert exit_init(fmu_dir, tmp_path, identifier, {param: ""})


def test_a_bound_signal_column_without_a_file_names_both(fmu_dir, tmp_path, capfd):
    assert not exit_init(fmu_dir, tmp_path, "SignalTable", {"file": "", "boolean_column_2": "valid"})
    log = capfd.readouterr().out
    assert "file" in log and "boolean_column_2 = 'valid'" in log
