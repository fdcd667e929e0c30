"""Sinks for the samples of a run (see :class:`railfmu.fmus.cosim.system.Sink`).

:class:`CsvRecorder` writes ``signals.csv`` as the run goes, so an interrupted or failed run
leaves a readable file; :class:`ArrayRecorder` keeps the rows in memory (tests, metrics).
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def _signals_held():
    """Hold SIGINT/SIGTERM until the block is done (they arrive right after it). Main
    thread on POSIX only; elsewhere a no-op."""
    held = {signal.SIGINT, signal.SIGTERM}
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class CsvRecorder:
    """Header line, then one line per sample with ``repr()`` floats (they round-trip exactly);
    Integer signals as integers and Boolean ones as 0/1 (``types``: column -> FMI type, e.g.
    :meth:`railfmu.fmus.cosim.system.System.signal_types`; columns not in it are Real).

    Rows are formatted into memory and written with one ``write`` of whole lines to an
    unbuffered file at least once a second, so the file never ends in half a row, even if
    the process is killed. ``rows_written`` and ``last_time`` describe what the file holds
    (final after :meth:`close`), for messages like ``interrupted at t = ...; N rows``.
    """

    FLUSH_INTERVAL_S = 1.0

    def __init__(self, path: Path, types: dict[str, str] | None = None):
        self.path = Path(path)
        self.types = dict(types or {})
        self._format = None
        self.rows_written = 0
        self.last_time: float | None = None
        self.complete: bool | None = None
        self._file = None
        self._pending: list[str] = []
        self._pending_last: float | None = None
        self._last_flush = 0.0

    def open(self, columns: list[str]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb", buffering=0)  # noqa: SIM115 (open until close())
        self._file.write((",".join(columns) + "\n").encode())
        kinds = [self.types.get(c, "Real") for c in columns]
        if all(k == "Real" for k in kinds):
            self._format = lambda values: ",".join(map(repr, values))
        else:
            fmt = [repr if k == "Real" else (lambda x: str(int(x))) for k in kinds]
            self._format = lambda values: ",".join(f(x) for f, x in zip(fmt, values))
        self.rows_written = 0
        self.last_time = None
        self._last_flush = time.monotonic()

    def write(self, row: np.ndarray) -> None:
        values = row.tolist()
        self._pending.append(self._format(values))
        self._pending_last = values[0]
        now = time.monotonic()
        if now - self._last_flush >= self.FLUSH_INTERVAL_S:
            self._flush(now)

    def write_block(self, rows: np.ndarray) -> None:
        if len(rows) == 0:
            return
        self._pending.extend(map(self._format, rows.tolist()))
        self._pending_last = float(rows[-1, 0])
        now = time.monotonic()
        if now - self._last_flush >= self.FLUSH_INTERVAL_S:
            self._flush(now)

    def _flush(self, now: float) -> None:
        if self._pending:
            view = memoryview(("\n".join(self._pending) + "\n").encode())
            with _signals_held():  # Ctrl-C mid-write would leave half a row, or write rows twice
                while view:  # a raw write may be partial
                    view = view[self._file.write(view):]
                self.rows_written += len(self._pending)
                self.last_time = self._pending_last
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


class ArrayRecorder:
    """Keeps every row in memory; ``data`` is the (n_samples, n_columns) array so far."""

    def __init__(self) -> None:
        self.columns: list[str] = []
        self.complete: bool | None = None
        self._blocks: list[np.ndarray] = []

    def open(self, columns: list[str]) -> None:
        self.columns = list(columns)
        self._blocks = []
        self.complete = None

    def write(self, row: np.ndarray) -> None:
        self._blocks.append(np.array(row, dtype=float, copy=True).reshape(1, -1))

    def write_block(self, rows: np.ndarray) -> None:
        self._blocks.append(np.array(rows, dtype=float, copy=True))

    def close(self, complete: bool) -> None:
        self.complete = complete

    @property
    def data(self) -> np.ndarray:
        if not self._blocks:
            return np.empty((0, len(self.columns)))
        return np.concatenate(self._blocks, axis=0)

    @property
    def rows(self) -> int:
        return sum(len(b) for b in self._blocks)
