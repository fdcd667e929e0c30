"""Output files that survive a kill, folders that fail in one line, and the range of seeds."""

from __future__ import annotations

import math
import os
from pathlib import Path

from railfmu.models.errors import UserError


def write_atomic(path: Path, data: str | bytes, sync: bool = True) -> None:
    """Write-then-rename: a reader, or a study resumed after kill -9, sees the old file or the
    whole new one, never half of one. ``sync``: on disk before the rename (a file a resumed
    study relies on), not only in the page cache."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.part")
    try:
        with open(tmp, "wb" if isinstance(data, bytes) else "w") as f:
            f.write(data)
            if sync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None


def ensure_folder(folder: Path | str, what: str = "--out") -> Path:
    """``folder`` created if missing; a file of that name, or a folder that cannot be created
    or written to, is a one-line error naming it."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{what} {folder}: a file of that name exists; give a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{what} {folder}: cannot create the folder ({exc.strerror or exc})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UserError(f"{what} {folder}: the folder is not writable")
    return folder


SEED_MAX = 2**31 - 1  # a seed is an FMU Integer parameter (a C int): larger ones would wrap


def check_seed(seed, what: str = "--seed") -> None:
    if seed is None:
        return
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= SEED_MAX:
        raise UserError(f"{what} {seed!r}: must be an integer from 0 to {SEED_MAX}")


def check_times(stop_time: float | None, step_size: float | None) -> None:
    for flag, value in (("--stop-time", stop_time), ("--step-size", step_size)):
        if value is not None and not (value > 0 and math.isfinite(value)):
            raise UserError(f"{flag} {value:g}: must be a positive number of seconds")
