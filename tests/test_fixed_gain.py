"""The fixed-gain filter kernel (estimators/core/fixed_gain.c, compiled into the user's cache on
first use): bit for bit the numpy loop and the numba fallback, a first run that compiles says
so in one line, and without a C compiler the numba kernel takes over."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from railfmu.estimators.core import fixed_gain
from railfmu.estimators.track.alignment import AlignmentKalmanFilter

needs_blas = pytest.mark.skipif(fixed_gain._dgemv is None, reason="numpy built on another BLAS")


def _matrices():
    f = AlignmentKalmanFilter(1e-3, q_xi=8e-4, sigma_virtual=8.0)
    return f.F, f.H, f.K


@needs_blas
def test_c_kernel_equals_the_numpy_loop_and_numba_bit_for_bit():
    F, H, K = _matrices()
    bf = fixed_gain.block_filter(F, H, K, 3)
    if shutil.which(os.environ.get("CC") or "gcc") is None:
        pytest.skip("no C compiler")
    assert bf is not None and bf._kind == "c"
    from railfmu.estimators.core import fixed_gain_numba

    fixed_gain_numba.bind(*fixed_gain._dgemv)
    nb = fixed_gain.BlockFilter(F, H, K, ("numba", fixed_gain_numba))
    Z = np.random.default_rng(3).standard_normal((3000, 3)) * [0.3, 0.01, 0.05]
    ref = np.empty((3000, 7))
    fixed_gain._numpy_loop(F, H, K, np.zeros(7), Z, ref)
    wide_c, wide_nb = np.zeros((3000, 11)), np.zeros((3000, 11))  # out as a strided view
    for out_c, out_nb in ((np.empty((3000, 7)), np.empty((3000, 7))), (wide_c[:, 2:9], wide_nb[:, 2:9])):
        xc, xn = np.zeros(7), np.zeros(7)
        bf.run(xc, Z, out_c)
        nb.run(xn, Z, out_nb)
        assert np.array_equal(out_c, ref) and np.array_equal(out_nb, ref)
        assert np.array_equal(xc, ref[-1]) and np.array_equal(xn, ref[-1])
    assert not wide_c[:, :2].any() and not wide_c[:, 9:].any()


def _first_use(cache, **env):
    code = ("from railfmu.estimators.track.alignment import AlignmentKalmanFilter\n"
            "import sys\n"
            "f = AlignmentKalmanFilter(1e-3); f.prepare()\n"
            "print(f._block._kind if f._block else None, 'numba' in sys.modules)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "RAILFMU_CACHE": str(cache), **env})
    assert res.returncode == 0, res.stderr
    return res.stdout.split(), res.stderr


@needs_blas
def test_first_use_compiles_once_and_says_so(tmp_path):
    if shutil.which(os.environ.get("CC") or "gcc") is None:
        pytest.skip("no C compiler")
    out, err = _first_use(tmp_path)
    assert out == ["c", "False"]  # numba not even imported
    assert err.count("railfmu: compiling the fixed-gain filter kernel with gcc (once per machine, then cached)") == 1
    assert len(list((tmp_path / "kernels").glob("fixed_gain-*.so"))) == 1
    out, err = _first_use(tmp_path)
    assert out == ["c", "False"] and "compiling" not in err


@needs_blas
def test_without_a_c_compiler_the_numba_kernel_runs(tmp_path):
    out, err = _first_use(tmp_path, CC=str(tmp_path / "no-such-compiler"))
    assert out == ["numba", "True"]
    assert not (tmp_path / "kernels").exists() or not list((tmp_path / "kernels").glob("*.so"))
