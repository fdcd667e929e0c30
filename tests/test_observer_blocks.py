"""Observers fed in blocks: ``step_block`` (the compiled fixed-gain alignment filter, the
strapdown INS in one kernel call per block) gives bit for bit what ``step`` gives row by row,
on hand-made records with gaps, missing sensors and masks, and on a study's default variant
run by the masters (the row-by-row reference: every row handed over alone, ``step`` only)."""

import numpy as np
import pytest

import railfmu
from railfmu.estimators.core import fixed_gain
from railfmu.estimators.core.observer import Observer
from railfmu.estimators.inertial.ins_observer import StrapdownINS
from railfmu.estimators.track.alignment import AlignmentKalmanFilter
from railfmu.fmus.cosim import masters


def _rows(obs, t, Z, U=None, mask=None):
    obs.reset(float(t[0]))
    return np.array([obs.step(float(t[k]), Z[k], None if U is None else U[k], None if mask is None else mask[k])
                     for k in range(len(t))])


def _blocks(obs, t, Z, U=None, mask=None, sizes=(1, 7, 500, 3, 1000)):
    obs.reset(float(t[0]))
    out, i, j = [], 0, 0
    while i < len(t):
        m = sizes[j % len(sizes)]
        sl = slice(i, i + m)
        out.append(obs.step_block(t[sl], Z[sl], None if U is None else U[sl], None if mask is None else mask[sl]))
        i, j = i + m, j + 1
    return np.vstack(out)


def test_alignment_filter_blocks_equal_rows_bit_for_bit():
    rng = np.random.default_rng(5)
    n, dt = 6000, 1e-3
    t = np.arange(n) * dt
    t = np.delete(t, [2500, 2501])  # a dropped sample: two predictions in one step
    Z = rng.standard_normal((t.size, 3)) * [0.3, 0.01, 0.05]
    Z[100, 1] = np.nan  # a missing gyro sample: the update with the rows present
    mask = np.ones(Z.shape, dtype=bool)
    mask[4000:4010, 0] = False
    a, b = AlignmentKalmanFilter(dt), AlignmentKalmanFilter(dt)
    rows, blocks = _rows(a, t, Z, mask=mask), _blocks(b, t, Z, mask=mask)
    assert np.array_equal(rows, blocks)
    assert a.finish() == b.finish()
    if fixed_gain._dgemv is not None:  # numpy's OpenBLAS: the compiled recursion ran
        assert isinstance(b._block, fixed_gain.BlockFilter)


def test_strapdown_ins_blocks_equal_rows_bit_for_bit():
    rng = np.random.default_rng(6)
    n, dt = 4000, 0.005
    t = np.delete(np.arange(n) * dt, [1500])
    U = rng.standard_normal((t.size, 6)) * [1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3] + [0, 0, 0, 0, 0, -9.8 * dt]
    U[700, 2] = np.nan  # a missing increment: bridged by the held one
    Z = np.empty((t.size, 0))
    for settings in ({"heading_error": 1e-3}, {"alignment": "coarse", "alignment_time": 1.0}):
        s = {"latitude": 0.9, "longitude": 0.2, "height": 100.0, "heading": 0.3, **settings}
        a, b = StrapdownINS(dt, **s), StrapdownINS(dt, **s)
        assert np.array_equal(_rows(a, t, Z, U), _blocks(b, t, Z, U), equal_nan=True)
        assert a.finish() == b.finish()


def _row_by_row(monkeypatch):
    """The reference path: each row handed to the sinks alone, every observer through step."""
    monkeypatch.setattr(masters, "HAND_OVER_ROWS", 1)
    for cls in (AlignmentKalmanFilter, StrapdownINS):
        monkeypatch.setattr(cls, "step_block", Observer.step_block)


@pytest.mark.parametrize("experiment, master, stop_time", [
    ("lateral_alignment", "jacobi", 3.0), ("lateral_alignment", "container", 3.0),
    ("trolley_imu_replay", None, None)])
def test_default_variant_row_by_row_equals_blocks(fmu_dir, monkeypatch, experiment, master, stop_time):
    block = railfmu.run(experiment, master=master, stop_time=stop_time, seed=1 if stop_time else None)
    with monkeypatch.context() as m:
        _row_by_row(m)
        rows = railfmu.run(experiment, master=master, stop_time=stop_time, seed=1 if stop_time else None)
    online = [s.name for s in block.system.observers if not s.offline and s.enabled]
    assert online
    for name in online:
        eb, er = block.estimates[name], rows.estimates[name]
        assert eb.keys() == er.keys()
        for k in eb:
            assert np.array_equal(eb[k], er[k], equal_nan=True), (name, k)


@pytest.mark.slow
def test_a_run_that_compiles_a_kernel_says_so_once(tmp_path):
    """With an empty numba cache the INS says in one line that it compiles; with the cache that
    run left, nothing."""
    import os
    import subprocess
    import sys

    code = ("from railfmu.estimators.inertial.ins_observer import StrapdownINS\n"
            "StrapdownINS(0.005).prepare()\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    first, second = (subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
                     for _ in range(2))
    lines = [ln for ln in first.stderr.splitlines() if "compiling" in ln]
    assert lines == ["railfmu: compiling the strapdown kernel with numba (once per machine, then cached)"]
    assert "compiling" not in second.stderr
