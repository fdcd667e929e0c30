"""The shared plot helpers: every y-axis names its quantity beside its unit, legends sit off the
data, a replayed channel is named by its file's column and carries its SSD connector's unit;
each PNG carries its axis labels (plots.figure_labels)."""

from __future__ import annotations

import io
import re
import shutil

import fmpy
import numpy as np
import pytest

from railfmu.experiments.engine.plots import columns_of, figure, figure_labels, units_of, x_axis

BAD_LABEL = re.compile(r"\[-\]|\[SI\]|\by_\d+\b|unit not given")


def test_a_figure_names_quantity_and_unit_and_keeps_legends_off_the_data(tmp_path):
    t = np.linspace(0.0, 10.0, 200)
    axes = [[("left rail", np.sin(t), "mm"), ("right rail", np.cos(t), "mm")],
            [("speed", 20 + 0 * t, "m/s")],
            [("velocity increment x", t, "m/s"), ("velocity increment y", -t, "m/s")],
            [("raw channel", t, "-")]]
    figure(tmp_path, "f.png", "title", t, "time [s]", axes, quantities=["rail height", None, None, None])
    labels = figure_labels(tmp_path / "f.png")
    assert [a["y"] for a in labels] == ["rail height [mm]", "speed [m/s]", "velocity increment [m/s]",
                                        "raw channel (unit not given)"]
    assert labels[0]["title"] == "title" and labels[-1]["x"] == "time [s]"
    assert labels[0]["legend"] == ["left rail", "right rail"] and labels[1]["legend"] == []
    assert not any(a["legend_over_data"] for a in labels)


def test_figure_labels_of_a_png_written_elsewhere_are_empty(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="a")
    ax.legend(loc="upper left")
    fig.savefig(tmp_path / "g.png")
    plt.close(fig)
    assert figure_labels(tmp_path / "g.png") == []


def test_distance_from_a_constant_speed():
    x, label = x_axis({"time": np.array([0.0, 0.5, 1.0])}, 20.0)
    assert list(x) == [0.0, 10.0, 20.0] and label.startswith("distance along the track [m]")


def test_a_replayed_channel_has_its_column_and_its_connectors_unit(tmp_path, fmu_dir):
    from railfmu.experiments.engine.runner import find_experiment, load_system

    system = load_system(find_experiment("alignment_replay"), None)
    units, columns = units_of(system), columns_of(system)
    assert [units[f"replay.y_{k}"] for k in (1, 2, 3, 4)] == ["m/s2", "rad/s", "m/s2", "m"]
    assert [columns[f"replay.y_{k}"] for k in (1, 2, 3, 4)] == ["ddy", "dpsi", "ddy_f", "alignment"]
    system = load_system(find_experiment("alignment_replay"), None, {"replay": {"column_1": "acc_y"}})
    assert columns_of(system)["replay.y_1"] == "acc_y"


@pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64", reason="needs gcc on linux64")
def test_the_replayed_imu_plots_say_radians_and_metres_per_second(tmp_path, fmu_dir):
    """2 s of the shipped imu.csv: the increments in the connectors' units under their column
    names, the INS's angles in degrees with the truth (deg in truth.csv) converted as the scores are."""
    from railfmu.experiments.engine.runner import run_experiment

    run_experiment("trolley_imu_replay", None, out=tmp_path, stop_time=2.0, progress=False, log=io.StringIO())
    imu = figure_labels(tmp_path / "imu.png")
    assert [a["y"] for a in imu] == ["angle increment [rad]", "velocity increment [m/s]"]
    assert imu[0]["legend"] == [f"angle increment {a} (dtheta_{a})" for a in "xyz"]
    ins = figure_labels(tmp_path / "estimates_ins.png")
    assert ins[0]["y"] == "latitude [deg]" and ins[0]["legend"] == ["truth (lat_deg)", "ins estimate"]
    for png in tmp_path.glob("*.png"):
        for ax in figure_labels(png):
            assert not BAD_LABEL.search(" ".join([ax["x"], ax["y"], *ax["legend"]])), (png.name, ax)
            assert not ax["legend_over_data"], png.name
    # the truth plotted in the estimate's unit: at the start the INS is the truth (its initial state)
    import pandas as pd

    est = pd.read_csv(tmp_path / "estimates.csv")
    sig = pd.read_csv(tmp_path / "signals.csv")
    assert np.degrees(est["ins.latitude"].iloc[0]) == pytest.approx(sig["truth.y_1"].iloc[0], abs=1e-9)


def test_a_long_curve_is_drawn_from_its_own_extremes():
    """The display envelope keeps every column's minimum and maximum, in order, from the data
    itself: the figure covers the same values with ~4000 of 20,001 points."""
    from railfmu.experiments.engine.plots import envelope

    x = np.arange(20001) * 1e-3
    y = np.sin(50 * x) + 0.1 * np.random.default_rng(1).standard_normal(x.size)
    y[12345] = 7.0  # a spike one sample wide must survive
    xs, ys = envelope(x, y, columns=2000)
    assert len(xs) <= 4002 and np.all(np.diff(xs) > 0)
    assert ys.max() == 7.0 and ys.min() == y.min() and xs[0] == x[0] and xs[-1] == x[-1]
    idx = np.searchsorted(x, xs)
    assert np.array_equal(y[idx], ys)  # points of the data, not averages
    k = 11  # samples per column: ceil(20001 / 2000)
    for c in range(0, 20001, k):  # every column: its extremes are kept
        inside = (idx >= c) & (idx < c + k)
        assert ys[inside].max() == y[c:c + k].max() and ys[inside].min() == y[c:c + k].min()
    short = np.arange(50.0)
    assert envelope(short, short)[1] is short


def test_a_long_y_label_is_wrapped_to_the_axis_height(tmp_path):
    """A y label longer than its axis is high would run into the next axis's: it is broken
    into lines of at most height x Y_LABEL_CHARS_PER_INCH characters, none of its words lost."""
    from railfmu.experiments.engine.plots import Y_LABEL_CHARS_PER_INCH, figure, figure_labels

    t = np.linspace(0.0, 1.0, 100)
    long = "driver's regime (0 standstill .. 4 braking, 5 emergency braking)"
    name = figure(tmp_path, "long.png", "long label", t, "time [s]", [[(long, t, "-")], [("speed", t, "m/s")]])
    first, second = (a["y"] for a in figure_labels(tmp_path / name))
    lines = first.split("\n")
    assert len(lines) >= 2 and all(len(line) <= 2.4 * Y_LABEL_CHARS_PER_INCH for line in lines)
    assert " ".join(lines).startswith(long) and second == "speed [m/s]"
