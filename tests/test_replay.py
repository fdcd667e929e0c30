"""Measured-data replay through an SSP (experiments/alignment_replay): a run of track_wheelset,
written as a measured table and played by the SignalTable FMU, drives the same alignment
filter to the simulated run's estimates bit for bit, in every master; the shipped table runs
from the command line, from any folder and from the exported .ssp; a bad table or a missing
SSP resource is one line and exit 2."""

from __future__ import annotations

import csv
import io
import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest

from railfmu.estimators.track.alignment import AlignmentKalmanFilter
from railfmu.experiments.alignment_replay.record import COLUMNS, TABLE, table_from_signals
from railfmu.experiments.engine.observer_bank import ObserverBank
from railfmu.experiments.engine.runner import run_experiment
from railfmu.fmus.cosim.masters import run as run_master
from railfmu.models.errors import UserError
from railfmu.fmus.ssp import read_system, write_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64",
                                reason="needs gcc on linux64")

EXP = Path(__file__).resolve().parents[1] / "experiments" / "alignment_replay"
CHANNELS = {"replay.y_1": "ddy", "replay.y_2": "dpsi", "replay.y_3": "ddy_f", "replay.y_4": "alignment"}


def railfmu(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True,
                          text=True, cwd=cwd)


def columns(path: Path) -> dict[str, list[str]]:
    """A CSV's columns as the text of their cells (what a bit-for-bit comparison needs)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {name: [r[j] for r in rows[1:]] for j, name in enumerate(rows[0])}


@pytest.fixture(scope="module")
def simulated(tmp_path_factory, fmu_dir):
    """2 s of track_wheelset (ERRI B176 alignment at 20 m/s, 1 kHz) and its measured table,
    written from signals.csv at full precision (a space in the name, as users' files have)."""
    out = tmp_path_factory.mktemp("simulated")
    metrics = run_experiment("track_wheelset", out=out / "run", stop_time=2.0, progress=False,
                             log=io.StringIO())
    return out / "run", table_from_signals(out / "run" / "signals.csv", out / "measured run.csv"), metrics


@pytest.mark.parametrize("master", ["jacobi", "gauss-seidel", "container"])
def test_replayed_run_gives_the_simulated_estimates_bit_for_bit(simulated, tmp_path, master):
    run, table, sim = simulated
    m = run_experiment("alignment_replay", out=tmp_path, master=master, progress=False, log=io.StringIO(),
                       sets={"replay": {"file": str(table)}})
    # every estimate of the online filter, every sample, the same text (repr of the same double)
    assert (tmp_path / "estimates.csv").read_bytes() == (run / "estimates.csv").read_bytes()
    assert m["observers"]["alignment"]["xi"] == sim["observers"]["alignment"]["xi"]
    # the replayed channels are the simulated signals, cell for cell, at the same times
    rep, orig = columns(tmp_path / "signals.csv"), columns(run / "signals.csv")
    assert rep["time"] == orig["time"] and len(rep["time"]) == 2001
    for channel, column in CHANNELS.items():
        assert rep[channel] == orig[COLUMNS[column]], channel
    # the table's last row (2 s) is the run's stop time (not the SSD's 600 s), and its normal end
    assert m["stop_time_s"] == 2.0 and m["end_time_s"] == 2.0 and m["early_end"] is None
    assert m["stop_time_from"] == "the last row of replay.file"


def test_offline_smoother_is_the_filters_rts_smoother_on_the_table(simulated, tmp_path):
    """estimates_smoother.csv against AlignmentKalmanFilter.smooth called on the table directly."""
    _, table, _ = simulated
    run_experiment("alignment_replay", out=tmp_path, progress=False, log=io.StringIO(),
                   sets={"replay": {"file": str(table)}})
    data = {k: np.array([float(x) for x in v]) for k, v in columns(table).items()}
    Z = np.column_stack([data["ddy"], data["dpsi"], data["ddy_f"]])
    want = AlignmentKalmanFilter(1e-3, V=20).smooth(data["time"], Z)
    got = {k: np.array([float(x) for x in v]) for k, v in columns(tmp_path / "estimates_smoother.csv").items()}
    assert np.array_equal(got["time"], data["time"])
    for j, state in enumerate(AlignmentKalmanFilter.outputs):
        assert np.array_equal(got[f"smoother.{state}"], want[:, j]), state


@pytest.fixture(scope="module")
def shipped_run(tmp_path_factory, fmu_dir):
    """`railfmu run alignment_replay` from a folder that is not the repository's."""
    cwd = tmp_path_factory.mktemp("elsewhere")
    res = railfmu("run", "alignment_replay", "--out", str(cwd / "out"), cwd=cwd)
    return res, cwd / "out"


def test_cli_runs_the_shipped_table_from_any_folder(shipped_run):
    res, out = shipped_run
    assert res.returncode == 0, res.stderr
    for f in ("signals.csv", "estimates.csv", "estimates_smoother.csv", "metrics.json", "report.md",
              "sensors.png", "estimates_alignment.png"):
        assert (out / f).is_file(), f
    table, signals = columns(TABLE), columns(out / "signals.csv")
    assert signals["time"] == table["time"] and len(table["time"]) == 3001  # 3 s at 1 kHz
    for channel, column in CHANNELS.items():
        assert signals[channel] == table[column], channel
    m = json.loads((out / "metrics.json").read_text())
    assert m["variant"] == "measured" and m["end_time_s"] == 3.0 and m["early_end"] is None
    assert m["parameters"]["replay"]["file"] == str(TABLE)  # resources/... against the SSP root
    assert len(columns(out / "estimates.csv")["alignment.xi"]) == 3001
    assert 0 < m["observers"]["alignment"]["xi"]["rel_error"] < 0.5
    assert "Early end" not in (out / "report.md").read_text() and m["stop_time_s"] == 3.0


def fmu_resources(ssp: Path, fmu: str) -> dict[str, bytes]:
    """The resources/ of an FMU inside an .ssp archive."""
    with zipfile.ZipFile(ssp) as outer, zipfile.ZipFile(io.BytesIO(outer.read(fmu))) as inner:
        return {n.removeprefix("resources/"): inner.read(n) for n in inner.namelist()
                if n.startswith("resources/") and not n.endswith("/")}


def test_exported_ssp_carries_the_table_and_runs_to_the_same_estimates(shipped_run, tmp_path, fmu_dir):
    """The table goes into the SignalTable FMU's own resources/ (which every importer hands
    the FMU) and `file` names it relative to there: the archive alone runs, to the same files."""
    res, out = shipped_run
    assert res.returncode == 0, res.stderr
    ssp = tmp_path / "replay.ssp"
    res = railfmu("export", "alignment_replay", "-o", str(ssp))
    assert res.returncode == 0, res.stderr
    with zipfile.ZipFile(ssp) as zf:
        # the replay's own copy of the SignalTable FMU, with its connectors' units declared
        assert sorted(zf.namelist()) == ["SystemStructure.ssd", "resources/replay_SignalTable.fmu"]
        ssd = zf.read("SystemStructure.ssd").decode()
    built = fmu_resources_of(fmu_dir / "SignalTable.fmu")
    assert fmu_resources(ssp, "resources/replay_SignalTable.fmu") == {**built, "axlebox_run.csv": TABLE.read_bytes()}
    assert '<ssv:String value="axlebox_run.csv"/>' in ssd and str(EXP) not in ssd
    assert railfmu("validate", str(ssp)).returncode == 0
    res = railfmu("run", str(ssp), "--out", str(tmp_path / "run"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    for f in ("estimates.csv", "estimates_smoother.csv", "signals.csv"):
        assert (tmp_path / "run" / f).read_bytes() == (out / f).read_bytes(), f


def fmu_resources_of(fmu: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu) as z:
        return {n.removeprefix("resources/"): z.read(n) for n in z.namelist()
                if n.startswith("resources/") and not n.endswith("/")}


def test_a_table_named_on_the_command_line_is_bundled_by_export(simulated, tmp_path, fmu_dir):
    """write_ssp puts a file a String parameter names (any absolute path) into the FMU's
    resources/; the archive runs without the original file, to the same estimates."""
    run, table, _ = simulated
    mine = tmp_path / "mine" / "monday run.csv"
    mine.parent.mkdir()
    shutil.copy(table, mine)
    system = read_system(EXP, variant="measured", fmu_dirs=[fmu_dir], overrides={"replay": {"file": str(mine)}})
    ssp = write_ssp(system, tmp_path / "mine.ssp")
    shutil.rmtree(mine.parent)
    assert fmu_resources(ssp, "resources/replay_SignalTable.fmu")["monday run.csv"] == table.read_bytes()
    back = read_system(ssp)
    assert back.component("replay").parameters["file"] == "monday run.csv"
    bank = ObserverBank(back, tmp_path / "estimates.csv")
    result = run_master(back, master="jacobi", sinks=[bank], progress=False)
    assert result.end_time == 2.0
    assert (tmp_path / "estimates.csv").read_bytes() == (run / "estimates.csv").read_bytes()


def test_a_resource_in_a_variant_resolves_against_the_ssp_root_and_a_missing_one_is_one_line(
        simulated, tmp_path, fmu_dir):
    _, table, _ = simulated
    folder = tmp_path / "my replay"
    shutil.copytree(EXP, folder, ignore=shutil.ignore_patterns("__pycache__", "*.py"))
    shutil.copy(table, folder / "resources" / "monday.csv")
    (folder / "variants" / "monday.ssv").write_text(VARIANT.format(file="resources/monday.csv"))
    system = read_system(folder, variant="monday", fmu_dirs=[fmu_dir])
    assert system.component("replay").parameters["file"] == str((folder / "resources" / "monday.csv").resolve())
    (folder / "variants" / "typo.ssv").write_text(VARIANT.format(file="resources/mondya.csv"))
    with pytest.raises(UserError) as e:
        read_system(folder, variant="typo", fmu_dirs=[fmu_dir])
    assert str(e.value) == (f"{folder}/variants/typo.ssv:4: Parameter 'replay.file': resources/mondya.csv "
                            f"not found in the SSP ({folder}/resources/mondya.csv)")


VARIANT = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet version="1.0" name="v" xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">
  <ssv:Parameters>
    <ssv:Parameter name="replay.file"><ssv:String value="{file}"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""


def test_bad_table_or_missing_resource_is_one_line_and_exit_2(tmp_path, fmu_dir):
    bad = tmp_path / "bad run.csv"
    lines = TABLE.read_text().splitlines()
    cells = lines[1001].split(",")  # line 1002 of the file: t = 1.000 s
    cells[2] = "n/a"
    lines[1001] = ",".join(cells)
    bad.write_text("\n".join(lines) + "\n")
    for value, message in (
            (str(bad), f"SignalTable.fmu (replay): fmi2ExitInitializationMode failed: file {bad}, line 1002, "
                       "column 3 (dpsi): 'n/a' is not a number"),
            ("resources/nope.csv", f"--set replay.file: resources/nope.csv not found in the SSP ({EXP}/resources/nope.csv)")):
        res = railfmu("run", "alignment_replay", "--set", f"replay.file={value}", "--out", str(tmp_path / "out"))
        assert res.returncode == 2, res.stderr
        assert "Traceback" not in res.stderr
        errors = [ln for ln in res.stderr.splitlines() if ln.startswith("railfmu: error:")]
        assert errors == [f"railfmu: error: {message}"], res.stderr


def test_list_shows_it_and_study_runs_its_variants(shipped_run, tmp_path):
    res = railfmu("list")
    assert res.returncode == 0
    assert "alignment_replay:" in res.stdout and "measured (default)" in res.stdout
    res = railfmu("study", "alignment_replay", "--out", str(tmp_path / "study"), "--workers", "1")
    assert res.returncode == 0, res.stderr
    table = json.loads((tmp_path / "study" / "table.json").read_text())
    assert sorted(table) == ["conicity_minus10", "measured"]
    # the study's default variant is the CLI run, to the last bit; a 10 % conicity error costs
    run = json.loads((shipped_run[1] / "metrics.json").read_text())
    xi = {v: table[v]["observers"]["alignment"]["xi"] for v in table}
    assert xi["measured"] == run["observers"]["alignment"]["xi"]
    assert xi["conicity_minus10"]["rms_error"] > xi["measured"]["rms_error"]
