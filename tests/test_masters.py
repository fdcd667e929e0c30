"""The three masters of railfmu.fmus.cosim.masters on track -> wheelset (2 s at 1 ms).

What is asserted (and measured when this was written):

* container equals jacobi bit for bit (tolerance 0: states, inputs and the
  direct-feedthrough outputs ddy/ddpsi alike), also with a String parameter (a measured
  profile file found in the track FMU's resources inside the container);
* gauss-seidel equals jacobi exactly on the track (a source: nothing to couple) and on a
  system without connections; on the wheelset it differs by O(h): halving h halves the
  largest difference in y (ratio 2.0 +- 0.3 asserted);
* a LinearTransformation factor 2 on xi and xi_rate doubles the response to a 1 mm step
  of the alignment (linear model: y(2) = 2 y(1) to 1e-12; settled near 2 mm after 4 s);
* an algebraic loop (two wheelsets, ddy -> xi both ways; ddy depends on xi in the
  ModelStructure) is refused by gauss-seidel, naming both connections; a cycle through y
  (no feedthrough) runs, with the delayed connection in the notes;
* the CSV recorder writes n_steps + 1 rows that read back to the result exactly; a run
  stopped by an overflow (factor 1e308 on xi, a 1 mm step at t = 1 s) raises UserError
  naming wheelset.ddy at t = 1 s and leaves a readable CSV of the rows before it;
* the container master (a C loop over the FMUs' own fmi2 functions on FMI 2.0 systems) runs a
  LinearTransformation (factor and offset) to Jacobi's samples bit for bit, names the inner
  component of a failed call as Jacobi does, hands a sink that sets every_step each row
  alone; FMPy's container (the exported FMU) refuses a non-identity connection, suggesting
  --master jacobi;
* Monte Carlo members (lateral_alignment, two seeds, and Integer and Boolean values other
  than the variant's) equal their Jacobi runs bit for bit in the container master and in
  FMPy's container path, which shares one cached container folder holding the FMUs' own
  start values; a refused value is one line;
* the exported container (build_container) carries the values as start values: FMPy's
  simulate_fmu runs it alone to the Jacobi samples bit for bit.
"""

from __future__ import annotations

import csv
import itertools
import math

import numpy as np
import pytest
from fmpy import read_model_description

from railfmu.models.errors import UserError
from railfmu.fmus.cosim.masters import MASTERS, gauss_seidel_order, run
from railfmu.experiments.engine.recorder import ArrayRecorder, CsvRecorder
from railfmu.fmus.cosim.system import Component, Connection, System

TRACK = {"psd_level": 1, "seed": 3, "harmonic_lateral_amplitude": 1e-3, "harmonic_wavelength": 15.66}
STEP = {"psd_level": 0, "step_lateral": 1e-3, "step_position": 2.0}  # 1 mm at t = 0.1 s (20 m/s)


def track_wheelset(fmu_dir, track=TRACK, factor=1.0, step_size=1e-3, stop_time=2.0, record=()):
    return System(
        name="track_wheelset",
        components=[Component("track", fmu_dir / "TrackIrregularity.fmu", dict(track)),
                    Component("wheelset", fmu_dir / "WheelsetLateral.fmu", {})],
        connections=[Connection("track", "alignment_1", "wheelset", "xi", factor=factor),
                     Connection("track", "alignment_rate_1", "wheelset", "xi_rate", factor=factor)],
        stop_time=stop_time, step_size=step_size, record=list(record))


@pytest.fixture(scope="module")
def results(fmu_dir):
    system = track_wheelset(fmu_dir)
    return {m: run(system, m, progress=False) for m in MASTERS}


def col(result, name):
    return result.data[:, result.columns.index(name)]


def test_container_equals_jacobi_bit_for_bit(results):
    jac, con = results["jacobi"], results["container"]
    assert con.columns == jac.columns and con.complete
    np.testing.assert_array_equal(con.data, jac.data)  # tolerance 0, ddy (feedthrough) included
    # the samples are "after the transfer": the input holds its source's output at t
    np.testing.assert_array_equal(col(con, "wheelset.xi") if "wheelset.xi" in con.columns
                                  else col(con, "track.alignment_1"), col(jac, "track.alignment_1"))


def test_container_with_string_parameter(fmu_dir):
    # a measured profile from the track FMU's resources/: the container extracts the FMU
    # and passes the String start value
    system = track_wheelset(fmu_dir, track={"psd_level": 0, "profile_file": "isolated_alignment_defect.csv",
                                                   "s_start": 30.0},
                            record=["track.alignment_1", "wheelset.xi", "wheelset.y", "wheelset.ddy"])
    jac, con = run(system, "jacobi", progress=False), run(system, "container", progress=False)
    assert np.abs(col(jac, "track.alignment_1")).max() > 0
    np.testing.assert_array_equal(con.data, jac.data)
    np.testing.assert_array_equal(col(con, "wheelset.xi"), col(con, "track.alignment_1"))


def test_monte_carlo_members_share_one_cached_container(tmp_path, monkeypatch):
    # lateral_alignment (Muñoz et al.) with two seeds: TrackIrregularity.seed and
    # SensorNoise.seed change, and Real, Integer and Boolean parameters are bound. The
    # container master (the C loop: no container folder at all) and FMPy's container path
    # (systems with FMI 3.0 components; here run directly) equal the Jacobi run bit for bit;
    # FMPy's cache holds one folder, without the runs' values.
    from railfmu.experiments.engine.runner import find_experiment, load_system
    from railfmu.fmus.cosim.masters import _run_container

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("RAILFMU_CACHE", raising=False)  # it would win over XDG_CACHE_HOME
    exp = find_experiment("lateral_alignment")
    runs = {}
    # and an Integer and a Boolean value other than the variant's: no noise, PSD level 2
    sets = {11: None, 12: None, "other": {"sensors": {"enabled": "false"}, "track": {"psd_level": "2"}}}
    for key, overrides in sets.items():
        system = load_system(exp, "standard", overrides, seed=11 if key == "other" else key, stop_time=0.3)
        native = run(system, "container", progress=False)
        assert runs or not (tmp_path / "railfmu" / "containers").exists()
        runs[key] = run(system, "jacobi", progress=False), _run_container(system, (), False), native
    folders = sorted((tmp_path / "railfmu" / "containers").iterdir())
    assert len(folders) == 1
    for jac, con, native in runs.values():
        assert con.columns == jac.columns == native.columns and len(con.data) == 301
        np.testing.assert_array_equal(con.data, jac.data)
        np.testing.assert_array_equal(native.data, jac.data)
    # the values reached the FMUs: other track and other noise
    a, b, c = (runs[k][1] for k in sets)
    for signal in ("track.alignment_1", "sensors.y_1"):
        assert not np.array_equal(col(a, signal), col(b, signal)), signal
        assert not np.array_equal(col(a, signal), col(c, signal)), signal
    # the cached container carries the FMUs' own start values, not a run's
    start = {v.name: v.start for v in read_model_description(str(folders[0])).modelVariables}
    own = {c.name: {v.name: v.start for v in c.md.modelVariables} for c in system.components}
    for comp in ("track", "sensors"):
        assert start[f"{comp}.seed"] == own[comp]["seed"] not in ("11", "12")


def test_exported_container_runs_alone_with_the_values(fmu_dir, tmp_path):
    # build_container bakes the values in as start values: FMPy's own simulate_fmu, which
    # sets no parameter, runs it to the Jacobi master's samples bit for bit
    from fmpy import simulate_fmu

    from railfmu.fmus.cosim.container import build_container

    record = ["track.alignment_1", "wheelset.y", "wheelset.ddy"]
    system = track_wheelset(fmu_dir, track={**TRACK, "seed": 21}, stop_time=0.5, record=record)
    fmu = build_container(system, tmp_path / "track_wheelset.fmu")
    start = {v.name: v.start for v in read_model_description(str(fmu)).modelVariables}
    assert start["track.seed"] == "21" and start["track.psd_level"] == "1"
    alone = simulate_fmu(str(fmu), stop_time=0.5, step_size=1e-3, output_interval=1e-3, output=record)
    jac = run(system, "jacobi", progress=False)
    np.testing.assert_array_equal(alone["time"], col(jac, "time"))
    for signal in record:
        np.testing.assert_array_equal(alone[signal], col(jac, signal))


def test_container_runs_affine_connections_as_jacobi(fmu_dir, tmp_path):
    # the C loop computes factor * src + offset in double as Python does (no fma): bit for bit;
    # FMPy's container (the exported FMU, the path of FMI 3.0 systems) copies values unchanged
    # and refuses the map
    from railfmu.fmus.cosim.container import build_container

    system = track_wheelset(fmu_dir, factor=1.1, stop_time=0.5)  # not a power of 2: factor * src rounds
    system.connections[1].offset = 1e-4 / 3
    jac, con = run(system, "jacobi", progress=False), run(system, "container", progress=False)
    assert con.master == "container" and not con.early_end
    np.testing.assert_array_equal(con.data, jac.data)
    with pytest.raises(UserError, match=r"track\.alignment_1 -> wheelset\.xi.*--master jacobi"):
        build_container(system, tmp_path / "affine.fmu")


def test_container_reports_a_bad_parameter(fmu_dir):
    # the value is set in initialisation mode; the track refuses it when leaving it
    with pytest.raises(UserError) as err:
        run(track_wheelset(fmu_dir, track={"psd_level": 7}), "container", progress=False)
    assert str(err.value) == ("TrackIrregularity.fmu (track): fmi2ExitInitializationMode failed: "
                              "parameter psd_level = 7 must be 0, 1 or 2")  # the component, as jacobi says it


class EveryStep(ArrayRecorder):
    """A sink that must see every row before the next step: the size of every block it gets."""

    every_step = True

    def __init__(self):
        super().__init__()
        self.blocks = []

    def write_block(self, rows):
        self.blocks.append(len(rows))
        super().write_block(rows)


def test_container_hands_an_every_step_sink_each_row(fmu_dir, results):
    sink = EveryStep()
    res = run(track_wheelset(fmu_dir), "container", sinks=[sink], progress=False)
    assert sink.blocks == [1] * 2001 and sink.complete is True
    np.testing.assert_array_equal(sink.data, results["jacobi"].data)
    np.testing.assert_array_equal(res.data, results["jacobi"].data)


def test_gauss_seidel_exact_where_nothing_is_coupled(fmu_dir, results):
    gs, jac = results["gauss-seidel"], results["jacobi"]
    assert gs.notes[0] == "Gauss-Seidel order: track -> wheelset"
    track_cols = [i for i, c in enumerate(jac.columns) if c == "time" or c.startswith("track.")]
    np.testing.assert_array_equal(gs.data[:, track_cols], jac.data[:, track_cols])
    # the sample holds the input from the source at t, as for Jacobi
    xi = run(track_wheelset(fmu_dir, record=["track.alignment_1", "wheelset.xi"]), "gauss-seidel", progress=False)
    np.testing.assert_array_equal(col(xi, "wheelset.xi"), col(xi, "track.alignment_1"))
    # no connections at all: the same calls in another order
    loose = track_wheelset(fmu_dir)
    loose.connections = []
    loose.components[1].parameters = {"y": 1e-3}
    np.testing.assert_array_equal(run(loose, "gauss-seidel", progress=False).data,
                                  run(loose, "jacobi", progress=False).data)


def test_gauss_seidel_converges_to_jacobi_with_h(fmu_dir):
    diffs = []
    for h in (1e-3, 5e-4, 2.5e-4):
        system = track_wheelset(fmu_dir, step_size=h, record=["wheelset.y"])
        gs, jac = run(system, "gauss-seidel", progress=False), run(system, "jacobi", progress=False)
        d = np.abs(col(gs, "wheelset.y") - col(jac, "wheelset.y")).max()
        assert d > 0
        diffs.append(d)
    y_range = np.ptp(col(jac, "wheelset.y"))
    assert diffs[0] < 0.01 * y_range  # O(h): ~0.4 % of the range at 1 ms
    for coarse, fine in itertools.pairwise(diffs):
        assert coarse / fine == pytest.approx(2.0, abs=0.3)


@pytest.mark.parametrize("master", ["jacobi", "gauss-seidel"])
def test_factor_two_doubles_the_response(fmu_dir, master):
    rec = ["track.alignment_1", "wheelset.xi", "wheelset.y"]
    one = run(track_wheelset(fmu_dir, track=STEP, stop_time=4.0, record=rec), master, progress=False)
    two = run(track_wheelset(fmu_dir, track=STEP, factor=2.0, stop_time=4.0, record=rec), master, progress=False)
    np.testing.assert_array_equal(col(two, "track.alignment_1"), col(one, "track.alignment_1"))
    np.testing.assert_array_equal(col(two, "wheelset.xi"), 2 * col(one, "track.alignment_1"))
    y1, y2 = col(one, "wheelset.y"), col(two, "wheelset.y")
    np.testing.assert_allclose(y2, 2 * y1, rtol=0, atol=1e-12 * np.abs(y1).max())
    assert y2[-1] == pytest.approx(2e-3, rel=0.05)  # follows the doubled 1 mm step


def two_wheelsets(fmu_dir, out_var):
    ws = fmu_dir / "WheelsetLateral.fmu"
    return System("pair", [Component("a", ws, {"y": 1e-3}), Component("b", ws, {})],
                  [Connection("a", out_var, "b", "xi"), Connection("b", out_var, "a", "xi")],
                  stop_time=0.1)


def test_algebraic_loop_is_refused(fmu_dir):
    md = read_model_description(str(fmu_dir / "WheelsetLateral.fmu"))
    ddy = next(o for o in md.outputs if o.variable.name == "ddy")
    assert [d.name for d in ddy.dependencies] == ["xi"]  # direct feedthrough, per ModelStructure
    system = two_wheelsets(fmu_dir, "ddy")
    msg = r"algebraic loop: a\.ddy -> b\.xi, b\.ddy -> a\.xi; Gauss-Seidel does not iterate"
    with pytest.raises(UserError, match=msg):
        gauss_seidel_order(system, {"a": md, "b": md})
    with pytest.raises(UserError, match=msg):
        run(system, "gauss-seidel", progress=False)
    # Jacobi couples it with one step of delay, and the container master with it
    np.testing.assert_array_equal(run(system, "container", progress=False).data,
                                  run(system, "jacobi", progress=False).data)


def test_cycle_without_feedthrough_is_broken(fmu_dir):
    system = two_wheelsets(fmu_dir, "y")
    md = read_model_description(str(fmu_dir / "WheelsetLateral.fmu"))
    order, delayed = gauss_seidel_order(system, {"a": md, "b": md})
    assert order == ["a", "b"] and [str(c) for c in delayed] == ["b.y -> a.xi"]
    res = run(system, "gauss-seidel", progress=False)
    assert any("delayed connection b.y -> a.xi" in n for n in res.notes)
    # b's input is a's y at t (the consistent sample), a's input b's y at t
    np.testing.assert_array_equal(col(res, "b.y")[1:] != 0, np.ones(100, bool))


def test_csv_recorder_and_array_recorder(fmu_dir, tmp_path, results):
    system = track_wheelset(fmu_dir)
    csv_sink, mem = CsvRecorder(tmp_path / "signals.csv"), ArrayRecorder()
    res = run(system, "jacobi", sinks=[csv_sink, mem], progress=False)
    with open(tmp_path / "signals.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == res.columns
    assert len(rows) - 1 == csv_sink.rows_written == system.n_steps + 1
    assert csv_sink.last_time == 2.0 and csv_sink.complete is True
    np.testing.assert_array_equal(np.array(rows[1:], dtype=float), res.data)  # repr round-trips
    assert mem.complete is True
    np.testing.assert_array_equal(mem.data, res.data)
    # the container hands blocks to the same sinks
    mem2 = ArrayRecorder()
    run(system, "container", sinks=[mem2], progress=False)
    np.testing.assert_array_equal(mem2.data, res.data)


@pytest.mark.parametrize("master", MASTERS)
def test_non_finite_stops_the_run_and_keeps_the_csv(fmu_dir, tmp_path, master):
    # xi = 1e308 * (1 mm step at t = 1 s): finite, but ddy = D xi overflows
    system = track_wheelset(fmu_dir, track={"psd_level": 0, "step_lateral": 1e-3, "step_position": 20.0})
    system.connections = [Connection("track", "alignment_1", "wheelset", "xi", factor=1e308)]
    sink, mem = CsvRecorder(tmp_path / "signals.csv"), ArrayRecorder()
    with pytest.raises(UserError, match=r"wheelset|WheelsetLateral") as err:
        run(system, master, sinks=[sink, mem], progress=False)
    if master != "gauss-seidel":
        assert str(err.value).startswith("wheelset.ddy = inf at t = 1 s: a non-finite value left an FMU")
    assert sink.complete is False and mem.complete is False
    with open(tmp_path / "signals.csv", newline="") as f:
        rows = list(csv.reader(f))
    data = np.array(rows[1:], dtype=float)
    assert len(data) == sink.rows_written == mem.rows == 1000
    assert sink.last_time == data[-1, 0] == 0.999
    assert np.isfinite(data).all()


@pytest.mark.parametrize("master", ["jacobi", "container"])
def test_nan_offset_is_refused_by_the_fmu(fmu_dir, master):
    system = track_wheelset(fmu_dir)
    system.connections[0].offset = math.nan
    with pytest.raises(UserError) as err:
        run(system, master, progress=False)
    assert str(err.value).startswith("WheelsetLateral.fmu (wheelset): fmi2SetReal of track.alignment_1 -> "
                                     "wheelset.xi, track.alignment_rate_1 -> wheelset.xi_rate at t = 0 s failed: ")
    assert "not finite" in str(err.value)


class Interrupting(ArrayRecorder):
    """A sink whose user presses Ctrl-C once the run passes t = 0.5 s."""

    def write(self, row):
        if row[0] >= 0.5:
            raise KeyboardInterrupt
        super().write(row)

    def write_block(self, rows):
        if rows[-1, 0] >= 0.5:
            raise KeyboardInterrupt
        super().write_block(rows)


@pytest.mark.parametrize("master", MASTERS)
def test_interrupt_closes_sinks_incomplete(fmu_dir, tmp_path, master):
    stop, sink = Interrupting(), CsvRecorder(tmp_path / "signals.csv")
    with pytest.raises(KeyboardInterrupt):
        run(track_wheelset(fmu_dir), master, sinks=[sink, stop], progress=False)
    assert stop.complete is False and sink.complete is False
    with open(tmp_path / "signals.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert 0 < len(rows) - 1 == sink.rows_written < 2001


def test_step_size_must_divide(fmu_dir):
    for master in MASTERS:
        with pytest.raises(UserError, match="does not divide"):
            run(track_wheelset(fmu_dir, step_size=0.3), master, progress=False)


def test_unknown_master(fmu_dir):
    with pytest.raises(UserError, match="unknown master"):
        run(track_wheelset(fmu_dir), "newton")


def test_sampling_before_the_transfer(fmu_dir):
    """``sampling="before-transfer"`` (libcosim's order) reads each row right after the step,
    before any input is set: the trajectory is the Jacobi master's (the same inputs reach
    every step), so every output that does not pass an input straight through is equal bit
    for bit; the wheelset's ddy (direct feedthrough of xi) is read while the FMU still holds
    the input of the step before, so it differs (by less than its range: the same states)."""
    system = track_wheelset(fmu_dir, record=["wheelset.y", "wheelset.dy", "wheelset.ddy", "wheelset.xi",
                                             "track.alignment_1"])
    default = run(system, "jacobi", progress=False)
    before = run(system, "jacobi", progress=False, sampling="before-transfer")
    for name in ("wheelset.y", "wheelset.dy", "track.alignment_1"):
        np.testing.assert_array_equal(col(before, name), col(default, name), err_msg=name)
    # the input as the FMU held it during the step that ended at t_k: its source's value at t_k-1
    np.testing.assert_array_equal(col(before, "wheelset.xi")[1:], col(default, "track.alignment_1")[:-1])
    assert col(before, "wheelset.xi")[0] == 0.0  # the start value: row 0 is read before the first copy
    ddy_b, ddy_d = col(before, "wheelset.ddy"), col(default, "wheelset.ddy")
    assert not np.array_equal(ddy_b, ddy_d) and np.max(np.abs(ddy_b - ddy_d)) < 0.5 * np.ptp(ddy_d)


@pytest.mark.parametrize("master", ["gauss-seidel", "container"])
def test_sampling_before_the_transfer_is_the_jacobi_masters(fmu_dir, master):
    with pytest.raises(UserError, match="only the Jacobi master"):
        run(track_wheelset(fmu_dir), master, progress=False, sampling="before-transfer")
    with pytest.raises(UserError, match="unknown sampling"):
        run(track_wheelset(fmu_dir), "jacobi", progress=False, sampling="after-step")


@pytest.mark.parametrize("master", MASTERS)
def test_a_parameter_value_of_the_wrong_type_is_one_line(fmu_dir, master):
    """A System built in Python with a value its variable cannot take: a UserError naming the
    FMU, the variable and the value, in every master (never a traceback from a conversion)."""
    system = track_wheelset(fmu_dir, track={**TRACK, "psd_level": "two"}, stop_time=0.01)
    with pytest.raises(UserError, match=r"TrackIrregularity.fmu \(track\).*psd_level = 'two' is not a valid Integer"):
        run(system, master, progress=False)
