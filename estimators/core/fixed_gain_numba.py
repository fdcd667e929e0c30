"""The loop of :mod:`railfmu.estimators.core.fixed_gain` in numba: its fallback where no C
compiler works (imported only then: numba's import and cached kernel cost a few tenths of a
second). Each product calls numpy's own ``cblas_dgemv`` as a numba external function."""

from __future__ import annotations

import numba
import numpy as np

from railfmu.estimators.core.compiled import cache_note

_TRANS = 112
_SYMBOL = "railfmu_numpy_dgemv"
_dgemv = None  # numpy's cblas_dgemv as a numba external function, once bound


def bind(address: int, bits: int) -> None:
    """Bind numpy's ``cblas_dgemv`` (its address and integer width in bits) for the kernel,
    then load (or, once per machine, compile, and say so) the kernel."""
    global _dgemv
    if _dgemv is None:
        from llvmlite import binding as llvm

        llvm.add_symbol(_SYMBOL, address)
        i, f, p = (numba.types.int64 if bits == 64 else numba.types.int32), numba.types.float64, numba.types.intp
        _dgemv = numba.types.ExternalFunction(_SYMBOL, numba.types.void(numba.types.int32, numba.types.int32, i, i, f,
                                                                        p, i, p, i, f, p, i))
    cache_note("fixed-gain filter", _run)


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
