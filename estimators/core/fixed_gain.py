r"""A fixed-gain (stationary) linear filter over a block of samples, compiled::

    x^-_k = F x^+_{k-1},    x^+_k = x^-_k + K (z_k - H x^-_k)

the recursion of :class:`railfmu.estimators.track.alignment.AlignmentKalmanFilter` with every
sensor present, one sample per ``dt``.

Bit for bit equal to the numpy loop (``x = F @ x``; ``x = x + K @ (z - H @ x)``): the loop
runs in numba, but each matrix-vector product calls the very BLAS routine numpy's ``@``
calls (``cblas_dgemv`` of the OpenBLAS numpy ships, with numpy's order and leading
dimension for the array's layout), and the sums and differences are the same IEEE
operations. A BLAS sums in its own order (blocked, fused multiply-adds); a hand-written
product would round differently. :func:`block_filter` checks the equality on the filter's
own matrices once (random states), and is None where it cannot hold (a numpy built on
another BLAS): the caller then loops in numpy.
"""

from __future__ import annotations

import ctypes
import os

import numba
import numpy as np

from railfmu.estimators.core.compiled import cache_note

_ROW_MAJOR, _COL_MAJOR, _TRANS = 101, 102, 112
_SYMBOL = "railfmu_numpy_dgemv"


def _bind_numpy_dgemv():
    """numpy's own ``cblas_dgemv`` as a numba external function, or None. Only the symbols of
    numpy's OpenBLAS wheels, whose integer width is known from the name."""
    try:
        from numpy._core import _multiarray_umath as core
        from llvmlite import binding as llvm
        lib = ctypes.CDLL(core.__file__)
    except (ImportError, OSError):
        return None
    for name, blasint in (("scipy_cblas_dgemv64_", numba.types.int64), ("scipy_cblas_dgemv", numba.types.int32)):
        fn = getattr(lib, name, None)
        if fn is not None:
            llvm.add_symbol(_SYMBOL, ctypes.cast(fn, ctypes.c_void_p).value)
            i, f, p = blasint, numba.types.float64, numba.types.intp
            return numba.types.ExternalFunction(
                _SYMBOL, numba.types.void(numba.types.int32, numba.types.int32, i, i, f, p, i, p, i, f, p, i))
    return None


_dgemv = None if os.environ.get("RAILFMU_NO_BLAS_KERNEL") else _bind_numpy_dgemv()


def _layout(A: np.ndarray) -> tuple[int, int] | None:
    """numpy's (order, lda) for ``A @ x`` (numpy/_core/src/umath/matmul.c.src: gemv after
    is_blasable2d), None where numpy would not call BLAS."""
    if A.ndim != 2 or A.dtype != np.float64:
        return None
    (m, n), (sm, sn), size = A.shape, A.strides, A.itemsize
    if sn == size and sm % size == 0 and n <= sm // size:
        return _COL_MAJOR, sm // size
    if sm == size and sn % size == 0 and m <= sn // size:
        return _ROW_MAJOR, sn // size
    return None


if _dgemv is not None:
    @numba.njit(cache=True)
    def _mv(A, order, lda, x, y):
        _dgemv(order, _TRANS, A.shape[1], A.shape[0], 1.0, A.ctypes.data, lda, x.ctypes.data, 1, 0.0,
               y.ctypes.data, 1)

    @numba.njit(cache=True)
    def _run(F, fo, fl, H, ho, hl, K, ko, kl, x, Z, out):
        n, m, nz = x.shape[0], H.shape[0], Z.shape[1]
        xp = np.empty(n)
        hx = np.empty(m)
        nu = np.zeros(m)  # rows beyond Z's columns: a virtual reading of 0
        kn = np.empty(n)
        zb = np.zeros(m)
        for k in range(Z.shape[0]):
            _mv(F, fo, fl, x, xp)
            for j in range(nz):
                zb[j] = Z[k, j]
            _mv(H, ho, hl, xp, hx)
            for j in range(m):
                nu[j] = zb[j] - hx[j]
            _mv(K, ko, kl, nu, kn)
            for j in range(n):
                x[j] = xp[j] + kn[j]
                out[k, j] = x[j]


def _numpy_loop(F, H, K, x, Z, out):
    zb = np.zeros(H.shape[0])
    for k in range(Z.shape[0]):
        x = F @ x
        zb[:Z.shape[1]] = Z[k]
        x = x + K @ (zb - H @ x)
        out[k] = x
    return x


class BlockFilter:
    """The compiled recursion for one ``(F, H, K)``; ``run(x, Z, out)`` advances ``x`` (in
    place) over the rows of ``Z`` (the first ``Z.shape[1]`` rows of ``H`` measured, the rest
    read as 0) and writes each ``x^+`` into ``out``."""

    def __init__(self, F: np.ndarray, H: np.ndarray, K: np.ndarray):
        self.F, self.H, self.K = F, H, K
        self._lay = [_layout(F), _layout(H), _layout(K)]

    def run(self, x: np.ndarray, Z: np.ndarray, out: np.ndarray) -> None:
        (fo, fl), (ho, hl), (ko, kl) = self._lay
        _run(self.F, fo, fl, self.H, ho, hl, self.K, ko, kl, x, np.ascontiguousarray(Z), out)


def block_filter(F: np.ndarray, H: np.ndarray, K: np.ndarray, n_measured: int) -> BlockFilter | None:
    """The compiled fixed-gain recursion for these matrices (``n_measured`` rows of ``H``
    measured) if it equals the numpy loop bit for bit here (checked on 64 random samples),
    else None. The first call in a process
    loads (or, once per machine, compiles) the kernel; :func:`cache_note` says which."""
    if _dgemv is None or any(_layout(A) is None for A in (F, H, K)):
        return None
    cache_note("fixed-gain filter", _run)
    bf = BlockFilter(F, H, K)
    rng = np.random.default_rng(0)
    scale = np.abs(np.diag(F)).max() or 1.0
    x0 = rng.standard_normal(F.shape[0]) * scale
    Z = rng.standard_normal((64, n_measured))
    a, b = np.empty((64, F.shape[0])), np.empty((64, F.shape[0]))
    x1 = x0.copy()
    bf.run(x1, Z, a)
    _numpy_loop(F, H, K, x0.copy(), Z, b)
    return bf if np.array_equal(a, b) else None
