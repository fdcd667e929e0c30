"""railfmu's per-user cache as the models find it (they import nothing of fmus, whose
:func:`railfmu.fmus.cache.cache_root` is the same rule), and an atomic write into it."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def cache_root() -> Path:
    """``$RAILFMU_CACHE``, else ``$XDG_CACHE_HOME/railfmu``, else ``~/.cache/railfmu``."""
    if os.environ.get("RAILFMU_CACHE"):
        return Path(os.environ["RAILFMU_CACHE"]).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache").expanduser() / "railfmu"


def write_atomic(path: Path, write) -> bool:
    """``write(f)`` into a temporary file beside ``path``, then renamed onto it: a parallel run
    reads a whole file or none. False (and nothing written) when the cache is not writable."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=path.suffix + ".tmp")
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
        return True
    except OSError:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        return False
