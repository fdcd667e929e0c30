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
