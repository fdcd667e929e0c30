"""The railfmu command line: the main job's outputs through every master, and one-line errors
with exit code 2 for every kind of bad input (docs/architecture.md, "Command line")."""

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

EXPERIMENT = Path(__file__).resolve().parents[1] / "experiments" / "track_wheelset"


def railfmu(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True,
                          text=True, cwd=cwd)


@pytest.mark.parametrize("master", ["jacobi", "gauss-seidel", "container"])
def test_run_writes_signals_estimates_metrics_report_and_plots(tmp_path, master):
    out = tmp_path / "run"
    res = railfmu("run", "track_wheelset", "--variant", "harmonic", "--stop-time", "2",
                  "--master", master, "--out", str(out))
    assert res.returncode == 0, res.stderr
    for f in ("signals.csv", "estimates.csv", "metrics.json", "report.md", "track_input.png", "sensors.png",
              "estimates_alignment.png"):
        assert (out / f).is_file(), f
    rows = list(csv.DictReader(open(out / "signals.csv")))
    assert len(rows) == 2001 and float(rows[-1]["time"]) == pytest.approx(2.0)
    est = list(csv.DictReader(open(out / "estimates.csv")))
    assert len(est) == 2001 and "alignment.xi" in est[0]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["master"] == master
    # 1 mm harmonic alignment: rms 1/sqrt(2) mm under the leading wheelset
    assert metrics["rms"]["track.alignment_1"] == pytest.approx(1e-3 / 2**0.5, rel=0.01)
    assert metrics["observers"]["alignment"]["xi"]["rel_error"] < 0.5


def test_container_master_matches_jacobi_through_the_cli(tmp_path):
    data = {}
    for master in ("jacobi", "container"):
        res = railfmu("run", "track_wheelset", "--stop-time", "1", "--master", master, "--out", str(tmp_path / master))
        assert res.returncode == 0, res.stderr
        data[master] = list(csv.reader(open(tmp_path / master / "signals.csv")))
    assert data["jacobi"] == data["container"]  # same header, same repr() of every sample


def test_list_shows_experiments_and_variants():
    res = railfmu("list")
    assert res.returncode == 0
    assert "track_wheelset" in res.stdout and "psd (default)" in res.stdout and "harmonic" in res.stdout


def test_export_writes_a_valid_self_contained_ssp(tmp_path):
    ssp = tmp_path / "tw.ssp"
    res = railfmu("export", "track_wheelset", "--variant", "harmonic", "-o", str(ssp))
    assert res.returncode == 0, res.stderr
    res = railfmu("validate", str(ssp))
    assert res.returncode == 0, res.stdout + res.stderr
    # runnable by path, away from the repository's build folder
    res = railfmu("run", str(ssp), "--stop-time", "0.5", "--out", str(tmp_path / "run"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr


def test_study_runs_every_variant_through_dask(tmp_path):
    out = tmp_path / "study"
    res = railfmu("study", "track_wheelset", "--stop-time", "1", "--out", str(out))
    assert res.returncode == 0, res.stderr
    table = json.loads((out / "table.json").read_text())
    assert sorted(table) == ["harmonic", "psd"]
    assert table["harmonic"]["rms"]["track.alignment_1"] == pytest.approx(1e-3 / 2**0.5, rel=0.02)
    assert "| harmonic |" in (out / "table.md").read_text()
    assert (out / "psd" / "signals.csv").is_file()


def _broken_experiment(tmp_path, old: str, new: str, file: str = "SystemStructure.ssd") -> Path:
    """A copy of the track_wheelset experiment with one edit, FMUs taken from the build folder."""
    exp = tmp_path / "exp"
    shutil.copytree(EXPERIMENT, exp, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    text = (exp / file).read_text()
    assert old in text, old
    (exp / file).write_text(text.replace(old, new, 1))
    return exp


SSD_EDITS = [  # (old, new, file, expected message part)
    ('<ssd:System name="track_wheelset">', '<ssd:System name="track_wheelset"', "SystemStructure.ssd",
     "malformed XML"),
    ('endConnector="xi"/>', "/>", "SystemStructure.ssd", "endConnector"),
    ("resources/WheelsetLateral.fmu", "resources/NoSuchModel.fmu", "SystemStructure.ssd", "NoSuchModel.fmu"),
    ('endElement="wheelset" endConnector="xi"', 'endElement="bogie" endConnector="xi"', "SystemStructure.ssd",
     "bogie"),
    ('startConnector="alignment_1"', 'startConnector="alignment_9"', "SystemStructure.ssd", "alignment_9"),
    ('<ssd:Connector name="xi" kind="input"><ssc:Real unit="m"/>',
     '<ssd:Connector name="xi" kind="input"><ssc:Integer/>', "SystemStructure.ssd", "xi"),
    ('startConnector="alignment_rate_1"', 'startConnector="alignment_1"', "SystemStructure.ssd", "unit"),
    ('name="track.psd_level"', 'name="track.psd_levels"', "variants/psd.ssv", "psd_levels"),
    ('stepSize="0.001"', 'stepSize="0.3"', "SystemStructure.ssd", "does not divide"),
    ('startConnector="alignment_1" endElement="wheelset" endConnector="xi"/>',
     'startConnector="alignment_1" endElement="wheelset" endConnector="xi">'
     '<ssc:LinearTransformation factor="1e308"/></ssd:Connection>', "SystemStructure.ssd",
     "a non-finite value left an FMU"),
    ('class="alignment_kf"', 'class="alignment_kalman"', "SystemStructure.ssd",
     "Observer 'alignment': class 'alignment_kalman' is not a registered estimator (entry points "
     "railfmu.estimators); closest: alignment_kf"),
    ('class="alignment_kf"', 'class="os.system"', "SystemStructure.ssd",  # nothing else is imported
     "Observer 'alignment': class 'os.system' is not the module path of a registered estimator"),
    ('<rf:Setting name="V" value="20"/>', '<rf:Setting name="V" value="20"/><rf:Setting name="sigma_ac" value="0.1"/>',
     "SystemStructure.ssd", "Observer 'alignment': bad settings: AlignmentKalmanFilter: unknown setting 'sigma_ac' "
     "(closest: sigma_acc"),
]


@pytest.mark.parametrize("old, new, file, message", SSD_EDITS, ids=[
    "malformed-xml", "schema", "missing-fmu", "unknown-component", "unknown-connector", "type-mismatch",
    "unit-mismatch", "unknown-parameter-in-variant", "step-size", "nan-from-fmu", "unknown-estimator",
    "unregistered-module-path", "unknown-setting"])
def test_bad_ssp_is_one_line_and_exit_2(tmp_path, old, new, file, message):
    exp = _broken_experiment(tmp_path, old, new, file)
    res = railfmu("run", str(exp), "--variant", "psd", "--stop-time", "1", "--out", str(tmp_path / "out"))
    _assert_one_line_error(res, message)


@pytest.mark.parametrize("args, message", [
    (["run", "no_such_experiment"], "unknown experiment 'no_such_experiment'"),
    (["run", "track_wheelset", "--variant", "nope"], "unknown variant 'nope'"),
    (["run", "track_wheelset", "--master", "newton"], "--master 'newton'"),
    (["run", "track_wheelset", "--set", "wheelset.m"], "expected COMPONENT.PARAM=VALUE"),
    (["run", "track_wheelset", "--set", "bogie.m=1"], "bogie"),
    (["run", "track_wheelset", "--set", "wheelset.mass=1"], "mass"),
    (["run", "track_wheelset", "--set", "wheelset.m=-1"], "parameter m = -1 must be > 0"),
    (["run", "track_wheelset", "--set", "track.profile_file=/nonexistent/p.csv"], "p.csv: no such file"),
    (["run", "track_wheelset", "--stop-time", "1", "--step-size", "0.3"], "does not divide"),
    (["run", "track_wheelset", "--stop-time", "0"], "--stop-time 0: must be a positive"),
    (["run", "track_wheelset", "--step-size", "nan"], "--step-size nan: must be a positive"),
    (["run", "track_wheelset", "--seed", "many"], "invalid int value"),
    (["validate", "/nonexistent.fmu"], "no such file"),
])
def test_bad_command_line_is_one_line_and_exit_2(tmp_path, args, message):
    res = railfmu(*args, "--out", str(tmp_path)) if args[0] == "run" else railfmu(*args)
    _assert_one_line_error(res, message)


_RUN = ["run", "track_wheelset", "--stop-time", "0.2"]
_STUDY = ["study", "track_wheelset", "--variant", "psd", "--stop-time", "0.2"]


@pytest.mark.parametrize("args, message", [
    (["run", "track_wheelset", "--stop-time", "1e300"], "more than the 1,099,511,627,776 a run can take"),
    (["run", "track_wheelset", "--stop-time", "1e9"], "GiB, more than this machine's"),
    (["run", "track_wheelset", "--stop-time", "inf"], "--stop-time inf: must be a positive"),
    (["run", "track_wheelset", "--stop-time", "-1"], "--stop-time -1: must be a positive"),
    (["run", "track_wheelset", "--stop-time", "soon"], "invalid float value"),
    (["run", "track_wheelset", "--step-size", "0"], "--step-size 0: must be a positive"),
    (["run", "track_wheelset", "--step-size", "-1e-3"], "--step-size: expected one argument"),
    (["run", "track_wheelset", "--step-size=-1e-3"], "--step-size -0.001: must be a positive"),
    ([*_STUDY, "--set", "wheelset.m=-1"], "variant psd: WheelsetLateral.fmu (wheelset): fmi2ExitInitializationMode"),
    (["run", "track_wheelset", "--step-size", "inf"], "--step-size inf: must be a positive"),
    (["run", "track_wheelset", "--stop-time", "1", "--step-size", "1e-300"], "more than the"),
    ([*_RUN, "--seed", "-1"], "--seed -1: must be an integer from 0 to 2147483647"),
    ([*_RUN, "--seed", str(2**40)], f"--seed {2**40}: must be an integer from 0"),
    ([*_RUN, "--set", "track.seed=1e30"], "out of range for variable 'seed'"),
    ([*_RUN, "--set", "track.seed=99999999999999999999"], "out of range for variable 'seed'"),
    ([*_RUN, "--set", "track.psd_level=3"], "3 is out of range for variable 'psd_level' (must be >= 0 and <= 2)"),
    ([*_RUN, "--set", "track.V=-1"], "out of range for variable 'V' (must be >= 0)"),
    ([*_RUN, "--set", "track.V=nan"], "non-finite value nan"),
    ([*_RUN, "--set", "track.V=-inf"], "non-finite value -inf"),
    ([*_RUN, "--set", "track.V=fast"], "'fast' is not a valid Real value"),
    ([*_RUN, "--set", "track.psd_level=1.5"], "'1.5' is not a valid Integer value"),
    ([*_RUN, "--set", "wheelset.integrator_step=0"], "integrator_step = 0 must be > 0"),
    (["run", "track_wheelset", "--set", "experiment.stopTime=nan"], "must be a number of seconds"),
    (["run", "track_wheelset", "--set", "experiment.stopTime=-5"], "stop time -5 s must be after"),
    ([*_RUN, "--out", "{file}/sub"], "cannot create the folder (Not a directory)"),
    ([*_RUN, "--out", "{file}"], "a file of that name exists"),
    ([*_STUDY, "--runs", "0"], "--runs 0: must be from 1 to 1,000,000"),
    ([*_STUDY, "--runs", "-1"], "--runs -1: must be from 1"),
    ([*_STUDY, "--runs", str(10**12)], f"--runs {10**12}: must be from 1 to 1,000,000"),
    ([*_STUDY, "--runs", "many"], "invalid int value"),
    ([*_STUDY, "--workers", "0"], "--workers 0: must be from 1 to 1024"),
    ([*_STUDY, "--workers", "-2"], "--workers -2: must be from 1"),
    ([*_STUDY, "--workers", str(10**6)], f"--workers {10**6}: must be from 1 to 1024"),
    ([*_STUDY, "--seed", "-1"], "--seed -1: must be an integer"),
    ([*_STUDY, "--runs", "3", "--seed", "2147483647"], "the last seed 2147483649: must be an integer"),
    ([*_STUDY, "--out", "{file}/sub"], "cannot create the folder"),
    ([*_STUDY, "--stop-time", "-1"], "--stop-time -1: must be a positive"),
    (["export", "track_wheelset", "-o", "{file}/x.ssp"], "a file of that name exists"),
    (["build", "--out", "{file}/fmus"], "cannot create the folder"),
])
def test_every_option_with_a_bad_value_is_one_line_and_exit_2(tmp_path, args, message):
    file = tmp_path / "a_file"
    file.write_text("")
    args = [a.replace("{file}", str(file)) for a in args]
    if args[0] in ("run", "study") and "--out" not in args:
        args += ["--out", str(tmp_path / "out")]
    res = railfmu(*args)
    if args[0] == "study":  # a member's error comes after the study's progress line and Dask's notes
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        errors = [line for line in res.stderr.splitlines() if line.startswith("railfmu: error:")]
        assert len(errors) == 1 and message in errors[0], res.stderr
    else:
        _assert_one_line_error(res, message)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes anywhere")
def test_a_read_only_output_folder_is_one_line(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _assert_one_line_error(railfmu(*_RUN, "--out", str(ro / "x")), f"--out {ro / 'x'}: cannot create")
        _assert_one_line_error(railfmu(*_RUN, "--out", str(ro)), f"--out {ro}: the folder is not writable")
    finally:
        ro.chmod(0o755)


def test_an_ssp_that_is_not_a_zip_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.ssp"
    bad.write_bytes(b"not a zip")
    _assert_one_line_error(railfmu("run", str(bad), "--out", str(tmp_path / "out")), "bad.ssp")


def _assert_one_line_error(res, message):
    assert res.returncode == 2, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    errors = [line for line in res.stderr.strip().splitlines() if line.startswith("railfmu: error:")]
    assert len(errors) == 1, res.stderr
    assert message in errors[0], errors[0]
    others = [line for line in res.stderr.strip().splitlines()
              if not line.startswith(("railfmu: error:", "railfmu: warning:", "running "))]
    assert not others, res.stderr


def test_validate_reports_problems_of_a_broken_fmu(tmp_path):
    bad = tmp_path / "Broken.fmu"
    bad.write_bytes(b"not a zip")
    res = railfmu("validate", str(bad))
    assert res.returncode == 1
    assert "problems" in res.stdout


def test_an_interrupted_run_keeps_complete_rows_and_says_so(tmp_path):
    """Ctrl-C in the middle of the main job: exit 130, a message with the time reached and
    the rows kept, and a signals.csv of complete rows only."""
    import re
    import signal
    import time

    out = tmp_path / "run"
    # 2000 s (minutes of wall time): the signal must land while the run is still going, also on
    # a loaded machine (200 s once finished first, and 20 s before that)
    proc = subprocess.Popen([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "track_wheelset", "--stop-time", "2000",
                             "--out", str(out)], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # wait until the run is well under way
        f = out / "signals.csv"
        if f.is_file() and f.stat().st_size > 200_000:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    m = re.search(r"interrupted at t = ([\d.]+) s; \S+ holds (\d+) complete rows", stderr)
    assert m, stderr
    rows = list(csv.reader(open(out / "signals.csv")))
    header, body = rows[0], rows[1:]
    assert len(body) == int(m.group(2)) and 100 < len(body) < 2000001
    assert all(len(r) == len(header) for r in body)
    assert float(body[-1][0]) == pytest.approx(float(m.group(1)))
    assert "Traceback" not in stderr


# -- the test FMU stair (tests/data/stair/): Integer/Boolean signals, an early end --------------

STAIR_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="stairs">
  <ssd:System name="stairs">
    <ssd:Elements>
      <ssd:Component name="a" source="stair.fmu"/>
      <ssd:Component name="b" source="stair.fmu"/>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="a" startConnector="counter" endElement="b" endConnector="offset"/>
      <ssd:Connection startElement="a" startConnector="odd" endElement="b" endConnector="enable"/>
      {extra}
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="12"/>
</ssd:SystemStructureDescription>
"""


def _stair_ssp(tmp_path, extra: str = "") -> Path:
    from stair_fmu import build_stair

    exp = tmp_path / "stairs"
    exp.mkdir()
    build_stair(exp)
    (exp / "SystemStructure.ssd").write_text(STAIR_SSD.format(extra=extra))
    return exp / "SystemStructure.ssd"


@pytest.mark.parametrize("master", ["jacobi", "container"])
def test_an_fmu_that_ends_the_simulation_ends_the_run_cleanly(tmp_path, master):
    """stair stops at 9 s (fmi2Discard + fmi2Terminated), 3 s before the SSD's stop time; no
    step-size annotation: the FMUs' DefaultExperiment stepSize (0.25 s)."""
    ssd = _stair_ssp(tmp_path)
    out = tmp_path / "run"
    res = railfmu("run", str(ssd), "--master", master, "--out", str(out), "--set", "b.stop_time=100")
    assert res.returncode == 0, res.stderr
    assert f"running system 'stairs' of {ssd}, no variant: 12 s at 0.25 s (from the smallest " \
           "DefaultExperiment stepSize of the FMUs (a: stair.fmu, 0.25 s))" in res.stderr
    assert "early end: stair.fmu (a) ended the simulation at t = 9 s" in res.stderr
    rows = list(csv.reader(open(out / "signals.csv")))
    assert rows[0] == ["time", "a.level", "a.counter", "a.sum", "a.odd", "a.gated", "a.y",
                       "b.level", "b.counter", "b.sum", "b.odd", "b.gated", "b.y"]
    assert len(rows) - 1 == 37 and rows[-1][0] == "9.0"
    assert rows[1 + 12][:6] == ["3.0", "3.0", "3", "3", "1", "0"]  # t = 3 s; Integer, Boolean 0/1
    assert rows[1 + 12][8:11] == ["3", "6", "1"]  # b.counter, b.sum = counter + a.counter, b.odd
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["end_time_s"] == 9.0 and metrics["simulated_seconds"] == 9.0
    assert metrics["early_end"].startswith("stair.fmu (a) ended the simulation at t = 9 s")
    assert metrics["step_size_s"] == 0.25 and "DefaultExperiment" in metrics["step_size_from"]
    assert "**Early end** at t = 9 s of 12 s" in (out / "report.md").read_text()


def test_validate_reports_a_real_to_integer_connection(tmp_path):
    ssd = _stair_ssp(tmp_path, '<ssd:Connection startElement="a" startConnector="level" endElement="b" '
                               'endConnector="sum"/>')
    res = railfmu("validate", str(ssd.parent))
    assert res.returncode == 1
    assert "a.level -> b.sum" in res.stdout  # sum is an output
    ssd.write_text(STAIR_SSD.format(extra='<ssd:Connection startElement="a" startConnector="level" '
                                          'endElement="b" endConnector="u"/>').replace(
        'endConnector="offset"', 'endConnector="u"'))
    res = railfmu("validate", str(ssd.parent))
    assert res.returncode == 1
    assert "Connection a.counter -> b.u: type mismatch: Integer -> Real" in res.stdout


def test_fmi2_error_in_a_run_names_component_and_status_and_cites_no_unwritten_file(tmp_path):
    ssd = _stair_ssp(tmp_path)
    out = tmp_path / "run"
    res = railfmu("run", str(ssd), "--master", "container", "--out", str(out), "--set", "b.error_time=2")
    _assert_one_line_error(res, "stair.fmu (b): fmi2DoStep at t = 2 s failed: fmi2Error")
    assert "partial results: " in res.stderr and "9 rows up to t = 2 s" in res.stderr
    # a refusal before the first row: no file to cite (m declares no min: the FMU refuses it)
    res = railfmu("run", "track_wheelset", "--set", "wheelset.m=-1", "--out", str(out))
    _assert_one_line_error(res, "parameter m = -1 must be > 0")
    assert "partial results" not in res.stderr


def test_out_naming_a_file_is_one_line(tmp_path):
    f = tmp_path / "taken"
    f.write_text("")
    _assert_one_line_error(railfmu("run", "track_wheelset", "--out", str(f)), f"--out {f}: a file")


def test_an_fmu_without_binary_or_sources_is_one_line(tmp_path):
    import zipfile

    ssd = _stair_ssp(tmp_path)
    fmu = ssd.parent / "stair.fmu"
    with zipfile.ZipFile(fmu) as z:
        md = z.read("modelDescription.xml")
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", md)
    res = railfmu("run", str(ssd), "--out", str(tmp_path / "run"))
    _assert_one_line_error(res, "stair.fmu has no binary for this platform (linux64) and no sources/")


def test_the_experiment_names_its_master_and_a_variant_its_stop_time(tmp_path):
    """`<rf:FixedStep master="container"/>` in the SSD is used when --master is not given; a variant's
    experiment.stopTime shortens the run, --stop-time still wins; --set NAME.enabled=false
    switches an observer off."""
    exp = _broken_experiment(tmp_path, '<rf:FixedStep stepSize="0.001"/>',
                             '<rf:FixedStep stepSize="0.001" master="container"/>')
    (exp / "variants" / "short.ssv").write_text(
        (exp / "variants" / "harmonic.ssv").read_text().replace(
            "<ssv:Parameters>", '<ssv:Parameters><ssv:Parameter name="experiment.stopTime">'
                                '<ssv:Real value="0.5"/></ssv:Parameter>'))
    res = railfmu("run", str(exp), "--variant", "short", "--out", str(tmp_path / "a"),
                  "--set", "alignment.enabled=false")
    assert res.returncode == 0, res.stderr
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert (m["master"], m["stop_time_s"], m["stop_time_from"]) == ("container", 0.5,
                                                                   "variant short (experiment.stopTime)")
    assert m["observers"] == {} and "(to 0.5 s from variant short" in res.stderr
    assert next(csv.reader(open(tmp_path / "a" / "estimates.csv"))) == ["time"]
    res = railfmu("run", str(exp), "--variant", "short", "--master", "jacobi", "--stop-time", "0.2",
                  "--out", str(tmp_path / "b"))
    assert res.returncode == 0, res.stderr
    m = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert (m["master"], m["stop_time_s"]) == ("jacobi", 0.2) and "alignment" in m["observers"]
    bad = _broken_experiment(tmp_path / "bad", '<rf:FixedStep stepSize="0.001"/>',
                             '<rf:FixedStep stepSize="0.001" master="newton"/>')
    _assert_one_line_error(railfmu("run", str(bad), "--out", str(tmp_path / "c")),
                           "FixedStep master='newton': choose one of jacobi, gauss-seidel, container")
