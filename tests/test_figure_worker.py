"""The figure worker (experiments/engine/figure_worker.py): a batch's PNGs exist when it ends,
are the PNGs drawn in-process, and nothing the worker does (dies, hangs, fails) loses one or
hangs the run; a Monte Carlo member starts no worker."""

from __future__ import annotations

import io
import os
import signal

import numpy as np
import pytest

from railfmu.experiments.engine import figure_worker
from railfmu.experiments.engine.plots import figure, figure_labels, figure_spec, render

T = np.linspace(0.0, 10.0, 5000)
AXES = [[("left rail", np.sin(T), "mm"), ("right rail", np.cos(T), "mm")], [("speed", 20 + 0 * T, "m/s")]]


def _figures(folder, n=3):
    return [figure(folder, f"f{i}.png", f"figure {i}", T, "time [s]", AXES, quantities=["rail height", None])
            for i in range(n)]


@pytest.fixture
def worker():
    """A worker of this test's own, stopped at the end."""
    figure_worker.stop()
    assert figure_worker.start()
    yield figure_worker._worker
    figure_worker.stop()


def test_a_batch_writes_what_the_worker_drew_and_it_is_the_in_process_png(worker, tmp_path):
    with figure_worker.batch():
        names = _figures(tmp_path)
        assert not any((tmp_path / n).exists() for n in names)  # handed over, not drawn here
    assert names == ["f0.png", "f1.png", "f2.png"]
    here = render(figure_spec("figure 0", T, "time [s]", AXES, quantities=["rail height", None]))
    assert (tmp_path / "f0.png").read_bytes() == here
    assert [a["y"] for a in figure_labels(tmp_path / "f1.png")] == ["rail height [mm]", "speed [m/s]"]
    assert sorted(p.name for p in tmp_path.iterdir()) == names  # no temporary file left
    pid = worker.proc.pid
    (tmp_path / "again").mkdir()
    with figure_worker.batch():  # the next batch: the same worker
        _figures(tmp_path / "again", 1)
    assert figure_worker._worker.proc.pid == pid and (tmp_path / "again" / "f0.png").is_file()


def test_a_worker_that_dies_loses_no_figure(worker, tmp_path):
    with figure_worker.batch():
        names = _figures(tmp_path)
        worker.proc.kill()
    assert all((tmp_path / n).stat().st_size > 10_000 for n in names)
    assert worker.dead and not figure_worker.running()
    assert figure_worker.start() and figure_worker._worker is not worker  # a new one when asked


def test_a_worker_that_hangs_is_stopped_and_its_figures_drawn_here(worker, tmp_path, monkeypatch):
    monkeypatch.setattr(figure_worker, "TIMEOUT_S", 1.0)
    os.kill(worker.proc.pid, signal.SIGSTOP)  # alive, silent
    with figure_worker.batch():
        names = _figures(tmp_path, 2)
    assert all((tmp_path / n).is_file() for n in names)
    assert worker.dead and worker.proc.returncode == -signal.SIGKILL


def test_a_figure_the_worker_cannot_draw_raises_as_drawn_here(worker, tmp_path):
    bad = [[("a", T, "m", {"color": "no such colour"}), ("b", T, "m")]]
    with pytest.raises(ValueError, match="no such colour"):
        with figure_worker.batch():
            figure(tmp_path, "bad.png", "title", T, "time [s]", bad)
    assert not (tmp_path / "bad.png").exists()
    assert figure_worker.running()  # the worker survives a figure it could not draw


def test_without_a_worker_figures_are_drawn_in_process(tmp_path, monkeypatch):
    figure_worker.stop()
    monkeypatch.setenv(figure_worker.ENV, "0")
    with figure_worker.batch():
        names = _figures(tmp_path, 1)
        assert (tmp_path / names[0]).is_file()  # drawn at once, as without a batch
    assert not figure_worker.running()


def test_a_save_in_a_process_with_matplotlib_draws_in_process_unless_a_worker_runs(tmp_path):
    import matplotlib  # noqa: F401  (as a notebook that plotted something)

    figure_worker.stop()
    with figure_worker.batch():
        _figures(tmp_path, 1)
        assert (tmp_path / "f0.png").is_file()  # drawn here, at once: no worker to wait for
    assert not figure_worker.running()


def test_a_monte_carlo_member_starts_no_worker(fmu_dir):
    from railfmu.experiments.engine.runner import run_experiment

    figure_worker.stop()
    run_experiment("track_wheelset", seed=1, stop_time=0.2, progress=False, log=io.StringIO(), write_files=False)
    assert not figure_worker.running()


def test_a_saved_run_lists_files_that_exist_and_the_engine_figures_come_ahead(fmu_dir, tmp_path):
    """railfmu.run(out=...) hands the signal and estimate figures to the worker as the run
    ends; every file save lists exists when it returns, and an in-memory run saves the same."""
    import railfmu

    figure_worker.stop()
    r = railfmu.run("track_wheelset", seed=1, stop_time=0.5, out=tmp_path / "a")
    assert figure_worker.running()
    written = r.save(tmp_path / "b")  # a second save draws them again
    assert all((tmp_path / "b" / f).is_file() for f in written)
    for png in (f for f in written if f.endswith(".png")):
        assert (tmp_path / "a" / png).read_bytes() == (tmp_path / "b" / png).read_bytes(), png
    figure_worker.stop()


class _Study:
    """A study whose figures read only the run (``figures_from_run``), drawn by the worker."""

    def __init__(self, fail: bool = False):
        self.fail = fail

    def figures(self, run, out):
        if self.fail:
            raise ValueError("no such band")
        return [figure(out, "study.png", "study", run.signals["time"], "time [s]",
                       [[("left rail", run.signals["y"], "mm")]])]


def _run():
    from railfmu.experiments.engine.study_protocol import RunData

    return RunData({"time": T, "y": np.sin(T)}, {}, {}, {}, {})


def test_a_studys_figures_drawn_by_the_worker_are_its_in_process_pngs(worker, tmp_path):
    job = figure_worker.submit_study(_Study(), _run())
    assert job is not None
    pngs = figure_worker.study_pngs(job)
    assert [name for name, _ in pngs] == ["study.png"]
    assert _Study().figures(_run(), tmp_path) == ["study.png"]  # no batch open: drawn here
    assert pngs[0][1] == (tmp_path / "study.png").read_bytes()


def test_a_studys_figures_the_worker_cannot_draw_are_none_and_the_worker_lives_on(worker, tmp_path):
    """None: the caller (Run.save) draws them itself, and raises the study's error there."""
    assert figure_worker.study_pngs(figure_worker.submit_study(_Study(fail=True), _run())) is None
    assert figure_worker.submit_study(lambda: None, _run()) is None  # a study that cannot travel
    assert figure_worker.running()
    with figure_worker.batch():
        _figures(tmp_path, 1)
    assert (tmp_path / "f0.png").is_file()


def test_the_main_jobs_study_figures_come_from_the_worker_and_equal_in_process_ones(fmu_dir, tmp_path, monkeypatch):
    """lateral_alignment draws its figures from the run alone: with a worker they are drawn
    while the run is scored, byte for byte the PNGs drawn in-process without one."""
    import railfmu

    calls = []
    from railfmu.experiments import lateral_alignment

    original = lateral_alignment.LateralAlignment.figures
    monkeypatch.setattr(lateral_alignment.LateralAlignment, "figures",
                        lambda self, run, out: calls.append(out) or original(self, run, out))
    figure_worker.stop()
    railfmu.run("lateral_alignment", stop_time=2.0, out=tmp_path / "w")
    assert calls == []  # not drawn in this process
    figure_worker.stop()
    monkeypatch.setenv(figure_worker.ENV, "0")
    railfmu.run("lateral_alignment", stop_time=2.0, out=tmp_path / "here")
    assert calls == [tmp_path / "here"]
    for png in ("alignment.png", "alignment_bands.png"):
        assert (tmp_path / "w" / png).read_bytes() == (tmp_path / "here" / png).read_bytes(), png
