r"""A fixed-gain (stationary) linear filter over a block of samples, compiled::

    x^-_k = F x^+_{k-1},    x^+_k = x^-_k + K (z_k - H x^-_k)

the recursion of :class:`railfmu.estimators.track.alignment.AlignmentKalmanFilter` with every
sensor present, one sample per ``dt``.

Bit for bit equal to the numpy loop (``x = F @ x``; ``x = x + K @ (z - H @ x)``): the loop
runs compiled, but each matrix-vector product calls the very BLAS routine numpy's ``@``
calls (``cblas_dgemv`` of the OpenBLAS numpy ships, with numpy's order and leading
dimension for the array's layout), and the sums and differences are the same IEEE
operations. A BLAS sums in its own order (blocked, fused multiply-adds); a hand-written
product would round differently. :func:`block_filter` checks the equality on the filter's
own matrices once (random states), and is None where it cannot hold (a numpy built on
another BLAS): the caller then loops in numpy.

The loop is ``fixed_gain.c``, compiled by the system's C compiler into railfmu's cache on first
use (:func:`railfmu.estimators.core.compiled.shared_library`) and called through ctypes; without
a working compiler, the same loop in numba (:mod:`railfmu.estimators.core.fixed_gain_numba`).
Neither imports anything heavy: a run loads a cached library in a millisecond, where importing
numba and loading its cached kernel took a few tenths of a second.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np

from railfmu.estimators.core.compiled import shared_library

_ROW_MAJOR, _COL_MAJOR = 101, 102
_SOURCE = Path(__file__).with_name("fixed_gain.c")
_WHAT = "fixed-gain filter"


def _numpy_dgemv() -> tuple[int, int] | None:
    """(address, integer width in bits) of numpy's own ``cblas_dgemv``, or None. Only the
    symbols of numpy's OpenBLAS wheels, whose integer width is known from the name."""
    try:
        from numpy._core import _multiarray_umath as core
        lib = ctypes.CDLL(core.__file__)
    except (ImportError, OSError):
        return None
    for name, bits in (("scipy_cblas_dgemv64_", 64), ("scipy_cblas_dgemv", 32)):
        fn = getattr(lib, name, None)
        if fn is not None:
            return ctypes.cast(fn, ctypes.c_void_p).value, bits
    return None


_dgemv = None if os.environ.get("RAILFMU_NO_BLAS_KERNEL") else _numpy_dgemv()
_kernel = None  # ("c", function) | ("numba", module) once loaded; False: neither


class _Matrices(ctypes.Structure):
    """``struct railfmu_fixed_gain`` of fixed_gain.c."""

    _fields_ = [("gemv", ctypes.c_void_p), ("F", ctypes.c_void_p), ("fo", ctypes.c_int), ("fl", ctypes.c_long),
                ("H", ctypes.c_void_p), ("ho", ctypes.c_int), ("hl", ctypes.c_long), ("K", ctypes.c_void_p),
                ("ko", ctypes.c_int), ("kl", ctypes.c_long), ("n", ctypes.c_long), ("m", ctypes.c_long)]


def _load_kernel():
    """The C kernel, else the numba one, else None; looked for once per process."""
    global _kernel
    if _kernel is None:
        _kernel = False
        lib = shared_library(_SOURCE, _WHAT)
        if lib is not None:
            fn = getattr(lib, f"railfmu_fixed_gain{_dgemv[1]}")
            p, n = ctypes.c_void_p, ctypes.c_long
            fn.argtypes = [ctypes.POINTER(_Matrices), p, p, n, n, p, n, n]
            fn.restype = ctypes.c_int
            _kernel = ("c", fn)
        else:
            try:
                from railfmu.estimators.core import fixed_gain_numba
            except ImportError:  # no numba: the caller loops in numpy
                pass
            else:
                fixed_gain_numba.bind(*_dgemv)
                _kernel = ("numba", fixed_gain_numba)
    return _kernel or None


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

    def __init__(self, F: np.ndarray, H: np.ndarray, K: np.ndarray, kernel=None):
        self.F, self.H, self.K = F, H, K
        self._lay = [_layout(F), _layout(H), _layout(K)]
        self._kind, self._fn = kernel or _load_kernel()
        if self._kind == "c":
            (fo, fl), (ho, hl), (ko, kl) = self._lay
            self._c = _Matrices(_dgemv[0], F.ctypes.data, fo, fl, H.ctypes.data, ho, hl, K.ctypes.data, ko, kl,
                                F.shape[0], H.shape[0])
            self._cref = ctypes.byref(self._c)
            self._x = self._xp = None  # the last state vector and its address (one array across blocks)

    def run(self, x: np.ndarray, Z: np.ndarray, out: np.ndarray) -> None:
        Z = np.ascontiguousarray(Z, dtype=np.float64)
        if self._kind == "numba":
            (fo, fl), (ho, hl), (ko, kl) = self._lay
            self._fn._run(self.F, fo, fl, self.H, ho, hl, self.K, ko, kl, x, Z, out)
            return
        n, rows = self._c.n, Z.shape[0]
        xs = x
        if x is not self._x:
            if x.dtype == np.float64 and x.flags.c_contiguous and x.flags.writeable and x.shape == (n,):
                self._x, self._xp = x, x.ctypes.data
            else:  # worked on a copy
                xs = np.array(x, dtype=np.float64)
        o = out
        if (out.dtype != np.float64 or out.shape != (rows, n) or not out.flags.writeable
                or out.strides[0] % 8 or out.strides[1] % 8):
            o = np.empty((rows, n))
        if self._fn(self._cref, self._xp if xs is x else xs.ctypes.data, Z.ctypes.data, rows, Z.shape[1],
                    o.ctypes.data, o.strides[0] // 8, o.strides[1] // 8) != 0:
            raise MemoryError("fixed-gain filter: no memory for the scratch vectors")
        if xs is not x:
            x[...] = xs
        if o is not out:
            out[...] = o


def block_filter(F: np.ndarray, H: np.ndarray, K: np.ndarray, n_measured: int) -> BlockFilter | None:
    """The compiled fixed-gain recursion for these matrices (``n_measured`` rows of ``H``
    measured) if it equals the numpy loop bit for bit here (checked on 64 random samples),
    else None. The first call in a process loads (or, once per machine, compiles, and says so
    in one line) the kernel."""
    if _dgemv is None or any(_layout(A) is None for A in (F, H, K)):
        return None
    kernel = _load_kernel()
    if kernel is None:
        return None
    bf = BlockFilter(F, H, K, kernel)
    rng = np.random.default_rng(0)
    scale = np.abs(np.diag(F)).max() or 1.0
    x0 = rng.standard_normal(F.shape[0]) * scale
    Z = rng.standard_normal((64, n_measured))
    a, b = np.empty((64, F.shape[0])), np.empty((64, F.shape[0]))
    x1 = x0.copy()
    bf.run(x1, Z, a)
    _numpy_loop(F, H, K, x0.copy(), Z, b)
    return bf if np.array_equal(a, b) else None
