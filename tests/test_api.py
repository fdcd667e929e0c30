"""The public Python API (railfmu.run & co., experiments/engine/api.py): what it returns in
memory equals what the CLI writes, the worked example runs, a copied or exported experiment
keeps its study, and the numbers would catch a wrong model."""

import csv
import json
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import railfmu
from railfmu.experiments.engine.result import TIMING_KEYS, json_default
from railfmu.experiments.engine.studies import HERE
from railfmu.models.errors import UserError

ROOT = Path(__file__).resolve().parents[1]
STOP = 0.5  # s: 501 samples of track_wheelset, ~1 s per run


@pytest.fixture(scope="module")
def tw(fmu_dir):
    """One short track_wheelset run, seed 1."""
    return railfmu.run("track_wheelset", seed=1, stop_time=STOP)


def _csv(path: Path) -> dict[str, np.ndarray]:
    with open(path) as f:
        rows = list(csv.reader(f))
    data = np.array(rows[1:], dtype=float)
    return {c: data[:, j] for j, c in enumerate(rows[0])}


def _untimed(metrics: dict) -> dict:
    """metrics as metrics.json holds them, without the wall-clock measurements."""
    def strip(m):
        if isinstance(m, dict):
            return {k: strip(v) for k, v in m.items()
                    if k not in TIMING_KEYS and not k.endswith(("wall_time_s", "seconds", "_per_call"))}
        return m

    return strip(json.loads(json.dumps(metrics, default=json_default)))


def test_import_is_cheap_and_all_names_resolve():
    code = "import sys, railfmu; print(sorted(m for m in ('numpy', 'fmpy', 'matplotlib') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    for name in railfmu.__all__:
        assert getattr(railfmu, name) is not None, name
    assert {"run", "study", "export", "read_ssp", "parameters", "Run"} <= set(railfmu.__all__)
    assert isinstance(railfmu.__version__, str)


def test_run_holds_signals_estimates_metrics_and_system(tw):
    t = tw.signals["time"]
    assert len(t) == 501 and t[0] == 0.0 and t[-1] == pytest.approx(STOP)
    assert tw.signals["wheelset.y"].shape == t.shape
    est = tw.estimates["alignment"]
    assert set(est) >= {"time", "xi", "y", "psi"} and len(est["xi"]) == len(t)
    assert tw.system.study == "track_wheelset" and tw.system.stop_time == STOP
    assert tw.metrics["seed"] == 1 and tw.metrics["variant"] == "psd"
    # the metrics are computed from these arrays: rms of a signal, the filter's raw error
    y = tw.signals["wheelset.y"]
    assert tw.metrics["rms"]["wheelset.y"] == pytest.approx(np.sqrt(np.mean(y ** 2)), rel=1e-12)
    score = tw.metrics["observers"]["alignment"]["xi"]
    after = t >= score["from_time_s"]  # the raw error after the filter's transient
    err = est["xi"][after] - tw.signals["track.alignment_1"][after]
    assert score["rms_error"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)
    assert "track_wheelset/psd" in repr(tw)


def test_save_writes_the_cli_files_and_the_signals_in_memory(tw, tmp_path):
    written = tw.save(tmp_path)
    assert written == ["signals.csv", "estimates.csv", "metrics.json", "report.md", "track_input.png",
                       "sensors.png", "estimates_alignment.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(written)
    saved = _csv(tmp_path / "signals.csv")
    assert list(saved) == list(tw.signals)
    for name, values in tw.signals.items():  # repr() floats: exact
        assert np.array_equal(saved[name], values), name
    est = _csv(tmp_path / "estimates.csv")
    assert np.array_equal(est["alignment.xi"], tw.estimates["alignment"]["xi"])
    assert (tmp_path / "metrics.json").read_text() == json.dumps(tw.metrics, indent=2, default=json_default) + "\n"
    assert (tmp_path / "report.md").read_text() == tw.report()
    assert "![sensors.png](sensors.png)" in tw.report()


def test_metrics_equal_the_cli_for_the_same_seed(tw, tmp_path):
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "-q", "run", "track_wheelset",
                          "--seed", "1", "--stop-time", str(STOP), "--out", str(tmp_path)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""  # -q: no progress, no "running"/"wrote" lines
    cli = json.loads((tmp_path / "metrics.json").read_text())
    assert _untimed(cli) == _untimed(tw.metrics)
    assert (tmp_path / "signals.csv").read_bytes() == _saved_signals(tw, tmp_path / "api")


def _saved_signals(run, folder: Path) -> bytes:
    run.save(folder)
    return (folder / "signals.csv").read_bytes()


def test_the_model_responds_at_the_harmonic_wave_frequency(fmu_dir):
    """harmonic: a 1 mm, 20 m alignment wave at 20 m/s -> 1 Hz; at 10 m/s (parameters=) 0.5 Hz."""
    def dominant(r):
        t, y = r.signals["time"], r.signals["wheelset.y"]
        y = y[t >= 2.0] - y[t >= 2.0].mean()  # after the start-up transient
        f = np.fft.rfftfreq(len(y), t[1] - t[0])
        return f[np.argmax(np.abs(np.fft.rfft(y * np.hanning(len(y)))))]

    r = railfmu.run("track_wheelset", "harmonic", stop_time=6.0)
    assert np.max(np.abs(r.signals["track.alignment_1"])) == pytest.approx(1e-3, rel=1e-3)
    assert dominant(r) == pytest.approx(1.0, abs=0.25)
    slow = railfmu.run("track_wheelset", "harmonic", stop_time=6.0,
                       parameters={"run.V": 10.0})  # the track's, vehicle's and filter's speed
    assert slow.metrics["parameters"]["wheelset"]["V"] == 10.0
    assert dominant(slow) == pytest.approx(0.5, abs=0.25)


def test_unknown_parameter_suggests_the_closest_names(fmu_dir):
    with pytest.raises(UserError, match=r"no variable 'VV' \(did you mean 'V'\?\)"):
        railfmu.run("track_wheelset", parameters={"wheelset.VV": 3}, stop_time=0.01)
    with pytest.raises(UserError, match=r"no component 'wheelst' \(did you mean 'wheelset'\?\)"):
        railfmu.read_ssp("track_wheelset", parameters={"wheelst.V": 3})
    with pytest.raises(UserError, match="expected 'COMPONENT.PARAM'"):
        railfmu.run("track_wheelset", parameters={"V": 3})


def test_parameters_lists_units_defaults_and_the_variants_values(fmu_dir):
    params = {p.name: p for p in railfmu.parameters("track_wheelset", "harmonic")}
    v = params["wheelset.V"]
    assert (v.kind, v.type, v.unit, v.default, v.value) == ("parameter", "Real", "m/s", 20.0, 20.0)
    amp = params["track.harmonic_lateral_amplitude"]
    assert amp.unit == "m" and amp.value == 0.001 and amp.default != amp.value
    assert params["alignment.V"].kind == "setting"
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "parameters", "track_wheelset",
                          "--variant", "harmonic"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    line = next(x for x in res.stdout.splitlines() if "track.harmonic_lateral_amplitude" in x)
    assert line.split()[1:4] == ["Real", "m", "0.001"] and "(default" in line


def test_cli_version_and_verbose(tmp_path):
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "--version"],
                         capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip() == f"railfmu {railfmu.__version__}"
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run", "track_wheelset", "-v",
                          "--stop-time", "0.05", "--out", str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "study: track_wheelset (TrackWheelset)" in res.stderr and "timing: setup" in res.stderr


def _copy(tmp_path: Path, study: str | None, name: str = "my_copy") -> Path:
    folder = tmp_path / name
    shutil.copytree(HERE / "track_wheelset", folder, ignore=shutil.ignore_patterns("__init__.py", "__pycache__"))
    ssd = folder / "SystemStructure.ssd"
    text = ssd.read_text()
    assert '<rf:Study name="track_wheelset"/>' in text
    if study is None:
        start = text.index('      <ssc:Annotation type="org.railfmu.study">')
        end = text.index("</ssc:Annotation>", start) + len("</ssc:Annotation>\n")
        text = text[:start] + text[end:]
    else:
        text = text.replace('<rf:Study name="track_wheelset"/>', f'<rf:Study name="{study}"/>')
    ssd.write_text(text)
    return folder


def test_a_copied_experiment_keeps_its_study_whatever_its_folder_is_called(tmp_path, fmu_dir):
    r = railfmu.run(_copy(tmp_path, "track_wheelset"), stop_time=0.05)
    assert r.variant == "psd" and r.metrics["roles"]["alignment"] == "track.alignment_1"
    assert r.metrics["warnings"] == []
    assert "track_input.png" in r.save(tmp_path / "out")


@pytest.mark.parametrize("study, why", [(None, "names no study"), ("no_such_study", "not registered")])
def test_no_or_an_unknown_study_is_a_warning_and_plain_ssp_metrics(tmp_path, fmu_dir, study, why):
    with pytest.warns(RuntimeWarning, match=why):
        r = railfmu.run(_copy(tmp_path, study), stop_time=0.05)
    assert r.variant is None and "roles" in r.metrics and r.metrics["roles"] == {}
    assert any(why in w and "plain SSP metrics only" for w in r.metrics["warnings"])
    assert "signals.png" in r.save(tmp_path / "out")  # the default study's figure
    res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "run",
                          str(tmp_path / "my_copy"), "--stop-time", "0.05", "--out", str(tmp_path / "cli")],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    warning = [x for x in res.stderr.splitlines() if x.startswith("railfmu: warning:")]
    assert len(warning) == 1 and why in warning[0]


def test_a_registered_study_runs_for_the_ssd_that_names_it(tmp_path, fmu_dir):
    class Counting(railfmu.Study):
        def metrics(self, run):
            return {"samples": len(run.signals["time"])}

    railfmu.register_study("counting", Counting("counts samples"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a known study: no warning
        r = railfmu.run(_copy(tmp_path, "counting"), stop_time=0.05)
    assert r.metrics["samples"] == 51


def test_an_exported_ssp_names_its_study_and_gets_its_figures(tmp_path, fmu_dir):
    ssp = railfmu.export("track_wheelset", tmp_path / "tw.ssp", "harmonic", parameters={"track.s_start": 5.0})
    system = railfmu.read_ssp(ssp)
    assert system.study == "track_wheelset" and system.component("track").parameters["s_start"] == 5.0
    r = railfmu.run(ssp, stop_time=0.05)
    assert r.metrics["warnings"] == [] and "track_input.png" in r.save(tmp_path / "out")


def test_to_pandas(tw, monkeypatch):
    frames = tw.to_pandas()
    assert list(frames) == ["signals", "alignment"]
    assert frames["signals"]["wheelset.y"].to_numpy().tolist() == tw.signals["wheelset.y"].tolist()
    assert frames["alignment"].index.name == "time"
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="needs pandas: pip install pandas"):
        tw.to_pandas()


def test_the_quickstart_example_runs(tmp_path, fmu_dir):
    script = ROOT / "docs" / "examples" / "quickstart.py"
    assert 20 <= len(script.read_text().splitlines()) <= 50
    res = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "5001 samples" in res.stdout and "alignment estimate: rms error" in res.stdout
    assert (tmp_path / "quickstart.png").stat().st_size > 10_000
    assert {"signals.csv", "metrics.json", "report.md"} <= {p.name for p in tmp_path.iterdir()}
