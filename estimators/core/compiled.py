"""Kernels compiled once per machine: numba's (``cache=True``, next to their module or in numba's
user cache) and small C files (:func:`shared_library`, into railfmu's per-user cache). A run that
has to compile one says so in one line on stderr, since compiling takes seconds (numba) or a
tenth of one (C) where loading the cached one takes milliseconds."""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

_noted: set[str] = set()


def cache_cold(dispatcher) -> bool:
    """True if numba has no usable on-disk cache of ``dispatcher`` yet (the next call
    compiles); False if it has one, or when numba's cache cannot be inspected."""
    try:
        index = dispatcher._cache._cache_file._load_index()  # {} when missing or stale
    except Exception:  # numba's private layout changed: say nothing rather than fail
        return False
    return not index


def _note(what: str, how: str) -> None:
    if f"{what} {how}" not in _noted:
        _noted.add(f"{what} {how}")
        print(f"railfmu: compiling the {what} kernel with {how} (once per machine, then cached)",
              file=sys.stderr, flush=True)


def cache_note(what: str, *dispatchers) -> None:
    """Print ``railfmu: compiling the <what> kernel ...`` once per process if any of
    ``dispatchers`` is about to be compiled rather than loaded."""
    if f"{what} numba" in _noted:
        return
    if any(cache_cold(d) for d in dispatchers):
        _note(what, "numba")
    _noted.add(f"{what} numba")


def cache_root() -> Path:
    """railfmu's per-user cache, as :func:`railfmu.fmus.cache.cache_root` finds it (the
    estimation core imports nothing of fmus): ``$RAILFMU_CACHE``, else
    ``$XDG_CACHE_HOME/railfmu``, else ``~/.cache/railfmu``."""
    if os.environ.get("RAILFMU_CACHE"):
        return Path(os.environ["RAILFMU_CACHE"]).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache").expanduser() / "railfmu"


#: what :func:`shared_library` compiles with: no fast-math, no contraction of a*b+c (results
#: must equal numpy's bit for bit)
C_FLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC", "-ffp-contract=off")


def shared_library(source: Path, what: str) -> ctypes.CDLL | None:
    """``source`` (one C file) compiled by the system's C compiler (``$CC``, else ``gcc``) into
    ``<cache>/kernels/<stem>-<key>.so`` and loaded; the key hashes the source, the compiler and
    the flags, so a changed file is a new library, and the file appears by an atomic rename
    (a parallel run loads a whole library or compiles its own). A compile says so in one line
    (``what`` names the kernel). None when there is no working compiler or the cache is not
    writable: the caller falls back."""
    cc = os.environ.get("CC") or "gcc"
    try:
        key = hashlib.sha256(source.read_bytes() + " ".join((cc, *C_FLAGS)).encode()).hexdigest()[:16]
        lib = cache_root() / "kernels" / f"{source.stem}-{key}.so"
        if not lib.is_file():
            if shutil.which(cc) is None:
                return None
            lib.parent.mkdir(parents=True, exist_ok=True)
            tmp = lib.with_suffix(f".{os.getpid()}.tmp")
            _note(what, Path(cc).name)
            res = subprocess.run([cc, *C_FLAGS, str(source), "-o", str(tmp)], check=False, capture_output=True,
                                 text=True)
            if res.returncode != 0:
                tmp.unlink(missing_ok=True)
                return None
            os.replace(tmp, lib)
        return ctypes.CDLL(str(lib))
    except OSError:  # no source, a read-only cache, a library that does not load
        return None
