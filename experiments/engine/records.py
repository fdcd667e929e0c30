"""A run's records (signals, estimates) as CSV, Parquet or MATLAB ``.mat``.

* ``csv`` (default): :class:`railfmu.experiments.engine.recorder.CsvRecorder`, written as the run goes.
* ``parquet`` (pyarrow; float64 columns, byte-stream-split + zstd) and ``mat`` (scipy.io
  ``savemat``, MATLAB v5 with compression; one column vector per signal, the names made valid
  MATLAB names, the original names in ``columns``): a binary file cannot be appended to row by
  row and stay readable after a kill (Parquet's footer, the .mat header are written last), so
  :class:`SpoolRecorder` spools the rows as raw float64 to ``NAME.EXT.spool`` as the run goes
  (whole rows, at least once a second, never half a row on Ctrl-C) and writes ``NAME.EXT``
  from it when the run closes (completed, failed or interrupted) and removes the spool. A
  killed run (SIGKILL, power loss) leaves the spool: :func:`read_table` reads its complete rows.

Every format keeps the float64 values bit for bit (CSV through ``repr``).
"""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.recorder import CsvRecorder, _signals_held
from railfmu.models.errors import UserError

FORMATS = ("csv", "parquet", "mat")
_SPOOL = ".spool"


def check_format(fmt: str) -> str:
    if fmt not in FORMATS:
        raise UserError(f"--format {fmt!r}: choose one of {', '.join(FORMATS)}")
    return fmt


def record_path(folder: Path, name: str, fmt: str) -> Path:
    """``folder/name.<ext>`` of a record in ``fmt``."""
    return Path(folder) / f"{name}.{fmt}"


def recorder(path: Path, fmt: str = "csv", types: dict[str, str] | None = None):
    """The sink that writes ``path`` in ``fmt`` as the run goes."""
    return CsvRecorder(path, types=types) if fmt == "csv" else SpoolRecorder(path, fmt)


class SpoolRecorder:
    """Raw float64 rows to ``path.spool`` as the run goes, ``path`` (Parquet or .mat) at close."""

    FLUSH_INTERVAL_S = 1.0

    def __init__(self, path: Path, fmt: str):
        self.path, self.fmt = Path(path), check_format(fmt)
        self.spool = self.path.with_name(self.path.name + _SPOOL)
        self.rows_written = 0
        self.last_time: float | None = None
        self.complete: bool | None = None
        self._file = None
        self._pending: list[np.ndarray] = []
        self._last_flush = 0.0

    def open(self, columns: list[str]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.columns = list(columns)
        self._file = open(self.spool, "wb", buffering=0)  # noqa: SIM115 (open until close())
        self._file.write((json.dumps({"columns": self.columns}) + "\n").encode())
        self.rows_written, self.last_time = 0, None
        self._last_flush = time.monotonic()

    def write(self, row: np.ndarray) -> None:
        self.write_block(np.asarray(row, dtype=float)[None, :])

    def write_block(self, rows: np.ndarray) -> None:
        if len(rows) == 0:
            return
        self._pending.append(np.array(rows, dtype="<f8", copy=True))
        now = time.monotonic()
        if now - self._last_flush >= self.FLUSH_INTERVAL_S:
            self._flush(now)

    def _flush(self, now: float) -> None:
        if self._pending:
            block = np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0]
            view = memoryview(block.tobytes())
            with _signals_held():  # whole rows: a reader drops only what a SIGKILL cut off
                while view:
                    view = view[self._file.write(view):]
                self.rows_written += block.shape[0]
                self.last_time = float(block[-1, 0])
                self._pending.clear()
        self._last_flush = now

    def close(self, complete: bool) -> None:
        if self._file is None:
            return
        try:
            self._flush(time.monotonic())
        finally:
            self._file.close()
            self._file = None
            self.complete = complete
        columns, data = read_table(self.spool)
        write_table(self.path, columns, data, self.fmt)
        self.spool.unlink()


def _mat_names(columns: list[str]) -> list[str]:
    """Valid, distinct MATLAB variable names (``wheelset.y`` -> ``wheelset_y``)."""
    names, seen = [], set()
    for c in columns:
        n = re.sub(r"\W", "_", c)
        n = n if re.match(r"[A-Za-z]", n) else f"x_{n}"
        base, i = n[:60], 1
        while n in seen or n == "columns":
            n, i = f"{base}_{i}", i + 1
        seen.add(n)
        names.append(n)
    return names


def write_table(path: Path, columns: list[str], rows: np.ndarray, fmt: str | None = None,
                types: dict[str, str] | None = None) -> None:
    """All of ``rows`` (n, len(columns)) to ``path`` in ``fmt`` (default: from its suffix)."""
    path = Path(path)
    fmt = check_format(fmt or path.suffix.lstrip("."))
    rows = np.asarray(rows, dtype=float).reshape(-1, len(columns))
    tmp = path.with_name(path.name + ".tmp")
    if fmt == "csv":
        rec = CsvRecorder(path, types=types)
        rec.open(columns)
        rec.write_block(rows)
        rec.close(True)
        return
    if fmt == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({c: rows[:, j] for j, c in enumerate(columns)})
        pq.write_table(table, tmp, compression="zstd", use_byte_stream_split=True, use_dictionary=False)
    else:
        from scipy.io import savemat

        names = _mat_names(columns)
        with open(tmp, "wb") as f:
            savemat(f, {"columns": np.array(columns, dtype=object),
                        **{n: rows[:, j].copy() for j, n in enumerate(names)}},
                    do_compression=True, oned_as="column")
    os.replace(tmp, path)  # never half a file under the final name


def read_table(path: str | Path) -> tuple[list[str], np.ndarray]:
    """``(columns, rows)`` of a record: ``.csv``, ``.parquet``, ``.mat`` or a killed run's
    ``.spool`` (its complete rows). ValueError (one line) for what it cannot read."""
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        if suffix == _SPOOL:
            with open(path, "rb") as f:
                head = json.loads(f.readline())
                raw = f.read()
            columns = head["columns"]
            n = len(raw) // (8 * len(columns))  # a row cut by a kill is left out
            return columns, np.frombuffer(raw[:n * 8 * len(columns)], dtype="<f8").reshape(n, len(columns)).copy()
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(path)
            return list(table.column_names), np.column_stack(
                [table.column(c).to_numpy().astype(float) for c in table.column_names]) if table.num_columns else np.empty((0, 0))
        if suffix == ".mat":
            from scipy.io import loadmat

            m = loadmat(path, squeeze_me=False)
            columns = [str(np.asarray(c).reshape(-1)[0]) for c in np.asarray(m["columns"]).reshape(-1)]
            names = _mat_names(columns)
            return columns, np.column_stack([np.asarray(m[n], dtype=float).reshape(-1) for n in names])
        if suffix == ".csv":
            with open(path) as f:
                columns = [c.strip() for c in f.readline().strip().split(",")]
            data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
            return columns, data.reshape(-1, len(columns))
    except (OSError, ValueError, KeyError, IndexError) as exc:
        raise ValueError(f"{path}: not a readable record ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    raise ValueError(f"{path}: unknown record format {suffix or '(no suffix)'} (one of .csv, .parquet, .mat, .spool)")


def read_signals(path: str | Path) -> dict[str, np.ndarray]:
    """A record (signals or estimates; ``.csv``, ``.parquet``, ``.mat`` or a killed run's
    ``.spool``) as ``{column: array}``, bit for bit what the run held in memory."""
    columns, data = read_table(path)
    return {c: data[:, j].copy() for j, c in enumerate(columns)}
