"""The TrackRecording FMU (models/track/recording.py): it equals its Python twin, records the same
track as TrackIrregularity with the same parameters, its error has the stated spread and is a
function of position, the offset is one bounded draw per seed, and disabled it passes the exact
rails through."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import simulate_fmu

from railfmu.fmus.cosim.slave import Slave
from railfmu.models.track.irregularity import TrackIrregularity
from railfmu.models.track.recording import TrackRecording, offset_draw

OUT = [f"vertical_{side}{rate}_{i}" for i in (1, 2) for side in ("left", "right") for rate in ("", "_rate")]


@pytest.fixture(scope="module")
def recording_fmu(fmu_dir):
    return fmu_dir / "TrackRecording.fmu"


def _sim(fmu, params, stop=5.0, step=0.01):
    return simulate_fmu(str(fmu), start_values=params, stop_time=stop, output_interval=step, step_size=step,
                        output=[*OUT, "position", "offset"])


def test_fmu_equals_python(recording_fmu):
    params = {"seed": 7, "offset_max": 2.5}
    res = _sim(recording_fmu, params)
    twin = TrackRecording(params).outputs(res["time"])
    for name in (*OUT, "position", "offset"):
        # the same sums in another order (numpy's matrix products): round-off only, 1e-12 of mm-scale heights
        assert np.max(np.abs(res[name] - twin[name])) < 1e-12, name


def test_without_error_it_is_the_track_resampled(recording_fmu):
    """No noise, no offset: at its sample positions (every 0.25 m: t = 0.0125 n s at 20 m/s) the
    recording is TrackIrregularity's
    track (its tabulation error bound: 1.9e-8 m); between them the Catmull-Rom error of 1-300 m
    wavelengths sampled at 0.25 m stays in the micrometres."""
    params = {"seed": 3, "noise_sigma": 0.0, "offset_max": 0.0}
    res = _sim(recording_fmu, params, stop=10.0, step=0.0125)
    truth = TrackIrregularity({"seed": 3, "axle_position_2": 19.0}).outputs(res["time"])
    for name in ("vertical_left_1", "vertical_right_2"):
        assert np.max(np.abs(res[name] - truth[name])) < 2e-8, name
    res = _sim(recording_fmu, params, stop=10.0, step=0.01)
    truth = TrackIrregularity({"seed": 3, "axle_position_2": 19.0}).outputs(res["time"])
    err = res["vertical_left_1"] - truth["vertical_left_1"]
    assert 1e-7 < np.sqrt(np.mean(err ** 2)) < 1e-5  # between samples: not the truth, close to it


def test_error_spread_offset_and_position_dependence():
    """The file's samples minus the true rails at x_j + delta: standard deviation noise_sigma
    (4000 samples: the sample std is within 5 % of it with probability > 99.9 %); the offset is
    the seed's uniform draw within +-offset_max; bogie 2 meets bogie 1's recording 19 m later."""
    rec = TrackRecording({"seed": 11, "noise_sigma": 5e-4, "offset_max": 3.0})
    assert abs(rec.offset) <= 3.0 and rec.offset == offset_draw(11, 3.0)
    j = np.arange(-2000, 2000)
    left, right = rec.samples(j)
    track = TrackIrregularity({"seed": 11})
    v = track.random_exact(j * 0.25 + rec.offset)[0]
    b = track.params["half_contact_width"]
    for err in (left - (v[1] + b * v[2]), right - (v[1] - b * v[2])):
        assert np.std(err) == pytest.approx(5e-4, rel=0.05)
        assert abs(np.corrcoef(err[:-1], err[1:])[0, 1]) < 0.1  # independent samples
    offsets = np.array([offset_draw(s, 3.0) for s in range(1, 401)])
    assert offsets.min() >= -3.0 and offsets.max() <= 3.0
    assert np.mean(offsets) == pytest.approx(0.0, abs=0.3)  # uniform: sd 3/sqrt(3)/sqrt(400) = 0.087 m
    t = np.array([1.0, 1.0 + 19.0 / 20.0])
    out = rec.outputs(t)
    assert out["vertical_left_2"][1] == out["vertical_left_1"][0]


def test_disabled_passes_the_exact_rails_through(recording_fmu):
    inputs = [f"exact_{side}{rate}_{i}" for i in (1, 2) for side in ("left", "right") for rate in ("", "_rate")]
    u = np.random.default_rng(5).normal(size=len(inputs)) * 1e-3
    with Slave(recording_fmu, "r") as s:
        s.initialize(0.0, None, {"enabled": False})
        s.fmu.setReal([s.vars[n].valueReference for n in inputs], list(u))
        y = s.fmu.getReal([s.vars[n].valueReference for n in OUT])
    assert np.array_equal(np.array(y), u)
