"""The per-user cache of built FMUs, container FMUs and the container driver."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """``$RAILFMU_CACHE``, else ``$XDG_CACHE_HOME/railfmu``, else ``~/.cache/railfmu``. Never
    inside the installed package (read-only on a shared install, and not in pip's record)."""
    if os.environ.get("RAILFMU_CACHE"):
        return Path(os.environ["RAILFMU_CACHE"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "railfmu"


def compiled_library(source: Path, flags: list[str]):
    """``source`` (one C file) compiled by ``$CC`` (else gcc) with ``flags`` into
    ``<cache>/<stem>-<key>.so`` and loaded (a ``ctypes.CDLL``); the key hashes the source and
    the command, and the file appears by an atomic rename, so a concurrent run loads a whole
    library or compiles its own. None when no compiler works or the library does not load:
    the caller falls back to its Python loop."""
    import ctypes
    import hashlib
    import subprocess

    cmd = [os.environ.get("CC", "gcc"), *flags, "-shared", "-fPIC"]
    try:
        key = hashlib.sha256(source.read_bytes() + " ".join(cmd).encode()).hexdigest()[:16]
        lib = cache_root() / f"{source.stem}-{key}.so"
        if not lib.is_file():
            lib.parent.mkdir(parents=True, exist_ok=True)
            tmp = lib.with_suffix(f".{os.getpid()}.tmp")
            res = subprocess.run([*cmd, str(source), "-o", str(tmp), "-lm"], check=False, capture_output=True,
                                 text=True)
            if res.returncode != 0:
                tmp.unlink(missing_ok=True)
                return None
            os.replace(tmp, lib)
        return ctypes.CDLL(str(lib))
    except OSError:  # no compiler, a read-only cache, a library that does not load
        return None
