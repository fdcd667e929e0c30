"""A run's PNG figures drawn in a second process, so that matplotlib's import and drawing do not
hold up the run.

:func:`start` starts the worker (``railfmu run`` does at its start, before set-up: its
matplotlib import then runs on another core while the run sets up and steps); one worker
serves the whole process, every :meth:`Run.save <railfmu.experiments.engine.result.Run.save>`
of it. Inside :func:`batch` (``Run.save``), :func:`railfmu.experiments.engine.plots.figure`
hands the worker its figure (the decimated curves and labels, :func:`plots.figure_spec`) and
returns at once; the worker sends back the PNG's bytes and the batch writes each file when it
ends (write and rename: never half a PNG), so every file ``Run.save`` lists exists when it
returns.

Nothing is lost to the worker: a figure it fails to draw, or every figure still pending when
it dies or sends nothing for :data:`TIMEOUT_S`, is drawn in this process as without a worker
(its error then raised as the drawing raises it). Where no worker starts (or
``RAILFMU_FIGURE_WORKER=0``) figures are drawn in-process, as they come.

The worker is a new interpreter (``subprocess``, this process's ``sys.path``), not a
multiprocessing child: ``fork`` would copy a parent that may hold threads, and ``spawn`` and
``forkserver`` import the parent's ``__main__`` again in the child (a user's script without a
main guard would run once more there). It reads and writes through two pipes, each drained
by a thread of its own, so neither side blocks on the other's sends; it exits when this
process closes its pipe (or dies).
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import pickle
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path

#: seconds without a reply from a busy worker before its pending figures are drawn in-process
TIMEOUT_S = 60.0
#: environment variable: "0" draws every figure in-process
ENV = "RAILFMU_FIGURE_WORKER"

_lock = threading.Lock()  # the worker's pipes and table of replies
_worker: _Worker | None = None
_local = threading.local()  # this thread's open batch


class _Worker:
    """The parent's end: the process, the pipes, the replies received by job number."""

    def __init__(self):
        req_r, req_w = os.pipe()
        rep_r, rep_w = os.pipe()
        code = ("import sys, json; sys.path[:] = json.loads(sys.argv[1]); "
                "from railfmu.experiments.engine.figure_worker import serve; serve(int(sys.argv[2]), int(sys.argv[3]))")
        try:
            self.proc = subprocess.Popen([sys.executable, "-c", code, json.dumps(sys.path), str(req_r), str(rep_w)],
                                         pass_fds=(req_r, rep_w), stdin=subprocess.DEVNULL,
                                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        except BaseException:
            os.close(req_w)
            os.close(rep_r)
            raise
        finally:  # the child's ends: the parent holds only its own, so a dead child reads as EOF
            os.close(req_r)
            os.close(rep_w)
        self.pid = os.getpid()  # a forked child of this process must not talk to its parent's worker
        self.requests = Connection(req_w, readable=False)
        self.replies = Connection(rep_r, writable=False)
        self.results: dict[int, tuple[bool, object]] = {}
        self.next_job = 0
        self.dead = False

    def send(self, spec) -> int | None:
        """The job's number; None when the worker is gone."""
        with _lock:
            if self.dead:
                return None
            job, self.next_job = self.next_job, self.next_job + 1
            try:
                self.requests.send_bytes(pickle.dumps((job, spec), protocol=pickle.HIGHEST_PROTOCOL))
            except OSError:  # the worker has died: its pipe is closed
                self._stop()
                return None
            return job

    def wait(self, jobs: list[int], timeout: float) -> dict[int, tuple[bool, object]]:
        """The replies to ``jobs`` that arrive before the worker dies or stays silent for
        ``timeout`` s (then it is stopped)."""
        with _lock:
            last = time.monotonic()
            while not self.dead and any(j not in self.results for j in jobs):
                left = timeout - (time.monotonic() - last)
                try:
                    if left <= 0 or not self.replies.poll(left):
                        self._stop()  # silent too long: hung
                        break
                    job, ok, payload = pickle.loads(self.replies.recv_bytes())
                except (EOFError, OSError, pickle.UnpicklingError):  # died, or died half-way through a reply
                    self._stop()
                    break
                self.results[job] = (ok, payload)
                last = time.monotonic()
            return {j: self.results.pop(j) for j in jobs if j in self.results}

    def drop(self, jobs: list[int]) -> None:
        """Forget jobs a failed batch no longer waits for (their replies are dropped when they come)."""
        with _lock:
            for j in jobs:
                self.results.pop(j, None)

    def _stop(self) -> None:
        self.dead = True
        for conn in (self.requests, self.replies):
            conn.close()
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


def enabled() -> bool:
    return os.environ.get(ENV, "1") != "0"


def start() -> bool:
    """Start the process's figure worker if it has none (or its last one died); False where
    none can start (the figures are then drawn in-process)."""
    global _worker
    with _lock:
        if _worker is not None and not _worker.dead and _worker.pid == os.getpid():
            return True
        if not enabled() or os.environ.get("_RAILFMU_IN_FIGURE_WORKER"):
            return False
        try:
            _worker = _Worker()
        except (OSError, subprocess.SubprocessError):
            _worker = None
            return False
        return True


@atexit.register
def stop() -> None:
    """End the worker (at exit; every batch has written its files by then)."""
    global _worker
    with _lock:
        if _worker is not None and not _worker.dead and _worker.pid == os.getpid():
            _worker._stop()
        _worker = None


class Batch:
    """The figures of one ``Run.save``: each drawn by the worker, written at :meth:`finish`."""

    def __init__(self, worker: _Worker | None):
        self.worker = worker
        self.pending: list[tuple[int, object, Path]] = []  # (job, spec, path)

    def submit(self, spec, path: Path) -> None:
        from railfmu.experiments.engine.plots import render, write_png

        job = self.worker.send(spec) if self.worker is not None else None
        if job is None:  # no worker: drawn here, now, as without one
            write_png(path, render(spec))
        else:
            self.pending.append((job, spec, path))

    def finish(self) -> None:
        """Wait for the worker's PNGs and write them; draw here whatever it did not draw."""
        from railfmu.experiments.engine.plots import render, write_png

        if not self.pending:
            return
        replies = self.worker.wait([job for job, _, _ in self.pending], TIMEOUT_S)
        for job, spec, path in self.pending:
            ok, png = replies.get(job, (False, None))
            write_png(path, png if ok else render(spec))  # a figure the worker could not draw: drawn here
        self.pending = []

    def abandon(self) -> None:
        if self.pending and self.worker is not None:
            self.worker.drop([job for job, _, _ in self.pending])
        self.pending = []


@contextlib.contextmanager
def batch():
    """Inside: :func:`plots.figure` hands its figures to the worker (started if need be); at
    the end every one of them is written. Nested: the outer batch collects them."""
    if getattr(_local, "batch", None) is not None:
        yield _local.batch
        return
    b = Batch(_worker if start() else None)
    _local.batch = b
    try:
        yield b
    except BaseException:
        b.abandon()
        raise
    else:
        b.finish()
    finally:
        _local.batch = None


def current() -> Batch | None:
    """The batch open in this thread, if any."""
    return getattr(_local, "batch", None)


# --- the worker's side ---

def serve(requests_fd: int, replies_fd: int) -> None:
    """The worker's loop: draw each figure received, send back its PNG (or why not)."""
    import queue

    os.environ["_RAILFMU_IN_FIGURE_WORKER"] = "1"
    requests, replies = Connection(requests_fd, writable=False), Connection(replies_fd, readable=False)
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    outbox: queue.SimpleQueue = queue.SimpleQueue()

    def read():
        try:
            while True:
                inbox.put(requests.recv_bytes())
        except (EOFError, OSError):  # the parent closed its end, or died
            inbox.put(None)

    def write():
        try:
            while (reply := outbox.get()) is not None:
                replies.send_bytes(reply)
        except OSError:  # the parent is gone
            os._exit(0)

    threading.Thread(target=read, daemon=True).start()
    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    from railfmu.experiments.engine.plots import render, warm_up

    warm_up()  # matplotlib's import and fonts, while the parent sets up and steps
    while (msg := inbox.get()) is not None:
        job, spec = pickle.loads(msg)
        try:
            reply = (job, True, render(spec))
        except Exception as exc:  # noqa: BLE001 - the parent draws it again, and raises it there
            reply = (job, False, f"{type(exc).__name__}: {exc}")
        outbox.put(pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL))
    outbox.put(None)
    writer.join()
