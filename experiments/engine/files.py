"""Output files that survive a kill and folders that fail in one line."""

from __future__ import annotations

import os
from pathlib import Path

from railfmu.models.errors import UserError


def write_atomic(path: Path, text: str) -> None:
    """Write-then-rename: a reader, or a study resumed after kill -9, sees the old file or the
    whole new one, never half of one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.part")
    try:
        with open(tmp, "w") as f:
            f.write(text)
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
