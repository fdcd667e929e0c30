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
main guard would run once more there). It reads its pipe and writes the other each in a
thread of its own, so the parent's sends never wait for a drawing and its replies never wait
for the parent; every send and wait of the parent has a deadline. It exits when this process
closes its pipe (or dies), and is killed at this process's exit.
"""

from __future__ import annotations

import atexit
import builtins
import contextlib
import dataclasses
import importlib
import json
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import warnings
from pathlib import Path

#: seconds without a reply from a busy worker before its pending figures are drawn in-process
TIMEOUT_S = 60.0
#: environment variable: "0" draws every figure in-process
ENV = "RAILFMU_FIGURE_WORKER"

_lock = threading.Lock()  # the worker's pipes and table of replies
_worker: _Worker | None = None
_local = threading.local()  # this thread's open batch


class _Worker:
    """The parent's end: the process, the pipes (non-blocking: every send and wait has a
    deadline), the replies received by job number."""

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
        self.requests, self.replies = req_w, rep_r
        os.set_blocking(req_w, False)
        os.set_blocking(rep_r, False)
        self.received = bytearray()  # reply bytes not yet a whole frame
        self.results: dict[int, tuple[bool, object]] = {}
        self.dropped: set[int] = set()  # jobs no batch waits for any more: their replies are not kept
        self.next_job = 0
        self.dead = False

    def send(self, spec, timeout: float) -> int | None:
        """The job's number; None when the worker is gone (or took no bytes for ``timeout`` s:
        then it is stopped)."""
        with _lock:
            if self.dead:
                return None
            job, self.next_job = self.next_job, self.next_job + 1
            # the task pickled on its own: the worker reads the job's number even when the task
            # does not load there (then it answers with the error at once)
            task = pickle.dumps(spec, protocol=pickle.HIGHEST_PROTOCOL)
            data = memoryview(_frame(pickle.dumps((job, task), protocol=pickle.HIGHEST_PROTOCOL)))
            try:
                while data:
                    if not _ready(self.requests, select.POLLOUT, timeout):
                        raise TimeoutError
                    data = data[os.write(self.requests, data):]
            except (OSError, TimeoutError):  # died (its pipe is closed) or hung
                self._stop()
                return None
            return job

    def wait(self, jobs: list[int], timeout: float) -> dict[int, tuple[bool, object]]:
        """The replies to ``jobs`` that arrive before the worker dies or sends nothing for
        ``timeout`` s (then it is stopped)."""
        with _lock:
            while not self.dead and any(j not in self.results for j in jobs):
                try:
                    if not _ready(self.replies, select.POLLIN, timeout):
                        raise TimeoutError
                    chunk = os.read(self.replies, 1 << 20)
                    if not chunk:
                        raise EOFError
                    self.received += chunk
                    while len(self.received) >= HEADER.size:
                        n = HEADER.unpack_from(self.received)[0]
                        if len(self.received) < HEADER.size + n:
                            break
                        job, ok, payload = pickle.loads(self.received[HEADER.size:HEADER.size + n])
                        del self.received[:HEADER.size + n]
                        if job in self.dropped:
                            self.dropped.discard(job)
                        else:
                            self.results[job] = (ok, payload)
                except (OSError, EOFError, TimeoutError, pickle.UnpicklingError):  # died (maybe half-way), hung
                    self._stop()
            return {j: self.results.pop(j) for j in jobs if j in self.results}

    def drop(self, jobs: list[int]) -> None:
        """Forget jobs a failed batch no longer waits for (their replies are dropped when they come)."""
        with _lock:
            self.dropped.update(jobs)
            for j in jobs:
                self.results.pop(j, None)

    def _stop(self) -> None:
        self.dead = True
        for fd in (self.requests, self.replies):
            os.close(fd)
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


def _ready(fd: int, event: int, timeout: float) -> bool:
    """Whether ``fd`` becomes ready (or its other end closes) within ``timeout`` s."""
    p = select.poll()  # not select.select: no limit on the descriptor's number
    p.register(fd, event)
    return bool(p.poll(timeout * 1000))


HEADER = struct.Struct("!Q")  # a frame: its length, then the pickle


def _frame(data: bytes) -> bytes:
    return HEADER.pack(len(data)) + data


def _read_frame(fd: int) -> bytes | None:
    """The next frame from a blocking pipe; None at its end."""
    def exactly(n: int) -> bytes | None:
        buf = bytearray()
        while len(buf) < n:
            chunk = os.read(fd, n - len(buf))
            if not chunk:
                return None
            buf += chunk
        return bytes(buf)

    head = exactly(HEADER.size)
    return None if head is None else exactly(HEADER.unpack(head)[0])


def enabled() -> bool:
    """Whether figures may go to a worker (:data:`ENV` is not "0")."""
    return os.environ.get(ENV, "1") != "0"


def start() -> bool:
    """Start the process's figure worker if it has none (or its last one died); False where
    none can start (the figures are then drawn in-process)."""
    global _worker
    with _lock:
        if _alive():
            return True
        if not enabled() or os.environ.get("_RAILFMU_IN_FIGURE_WORKER") or not hasattr(select, "poll") \
                or os.name != "posix":  # pass_fds and poll: POSIX
            return False
        try:
            _worker = _Worker()
        except (OSError, ValueError, subprocess.SubprocessError):  # no interpreter to start, ...
            _worker = None
            return False
        return True


@atexit.register
def stop() -> None:
    """End the worker (at exit; every batch has written its files by then)."""
    global _worker
    with _lock:
        if _alive():
            _worker._stop()
        _worker = None


class Batch:
    """The figures of one ``Run.save``: each drawn by the worker, written at :meth:`finish`."""

    def __init__(self, worker: _Worker | None, ahead: bool = False):
        self.worker = worker
        self.ahead = ahead  # figures for a later batch (:meth:`take`): nothing written here
        self.pending: list[tuple[int | None, object, Path]] = []  # (job, or None: draw here; spec; path)

    def submit(self, spec, path: Path) -> None:
        from railfmu.experiments.engine.figure_png import render, write_png

        job = self.worker.send(spec, TIMEOUT_S) if self.worker is not None else None
        if job is None and not self.ahead:  # no worker: drawn here, now, as without one
            write_png(path, render(spec))
        else:
            self.pending.append((job, spec, path))

    def take(self, ahead: Batch, folder: Path) -> None:
        """The figures ``ahead`` handed to the worker, written into ``folder`` with this batch's."""
        for job, spec, path in ahead.pending:
            self.pending.append((job if ahead.worker is self.worker else None, spec, folder / path.name))
        ahead.pending = []

    def finish(self) -> None:
        """Wait for the worker's PNGs and write them; draw here whatever it did not draw."""
        from railfmu.experiments.engine.figure_png import render, write_png

        jobs = [job for job, _, _ in self.pending if job is not None]
        replies = self.worker.wait(jobs, TIMEOUT_S) if jobs else {}
        for job, spec, path in self.pending:
            ok, reply = replies.get(job, (False, None))
            if ok:
                png, said = reply
                for category, message in said:  # what matplotlib warned about in the worker
                    warnings.warn(message, getattr(builtins, category, UserWarning), stacklevel=2)
            write_png(path, png if ok else render(spec))  # one the worker did not draw: drawn here
        self.pending = []

    def abandon(self) -> None:
        if self.worker is not None:
            self.worker.drop([job for job, _, _ in self.pending if job is not None])
        self.pending = []


@contextlib.contextmanager
def batch():
    """Inside: :func:`plots.figure` hands its figures to the worker; at the end every one of
    them is written. Nested: the outer batch collects them. With no worker running, one is
    started unless this process has matplotlib already (a batch waits for its figures, so a
    worker started now only draws what this process would, after its own import)."""
    if getattr(_local, "batch", None) is not None:
        yield _local.batch
        return
    b = Batch(_worker if running() or ("matplotlib" not in sys.modules and start()) else None)
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


@contextlib.contextmanager
def ahead():
    """Inside: :func:`plots.figure` hands its figures to a running worker for a later
    :func:`batch` to write (:meth:`Batch.take`: the figures it draws do not depend on the
    folder). Yields None, and nothing is drawn, when no worker runs."""
    if not running() or getattr(_local, "batch", None) is not None:
        yield None
        return
    b = Batch(_worker, ahead=True)
    _local.batch = b
    try:
        yield b
    except BaseException:
        b.abandon()
        raise
    finally:
        _local.batch = None


def running() -> bool:
    """Whether this process's worker is up (:func:`start`)."""
    with _lock:
        return _alive()


def _alive() -> bool:
    return _worker is not None and not _worker.dead and _worker.pid == os.getpid()


def current() -> Batch | None:
    """The batch open in this thread, if any."""
    return getattr(_local, "batch", None)


@dataclasses.dataclass
class Imports:
    """A task: import these modules now (a study's :attr:`figure_imports`, while the run steps)."""
    modules: tuple[str, ...]


@dataclasses.dataclass
class StudyFigures:
    """A task: ``study.figures(run, folder)`` drawn in the worker; the reply is each PNG's name
    and bytes."""
    study: object
    run: object


def prefetch(modules) -> None:
    """Have the running worker import ``modules`` (nothing when none runs); no reply is kept."""
    if modules and running():
        job = _worker.send(Imports(tuple(modules)), TIMEOUT_S)
        if job is not None:
            _worker.drop([job])


def submit_study(study, run) -> int | None:
    """``study.figures(run, ...)`` handed to the running worker; its job number for
    :func:`study_pngs`, or None when none runs (or ``run`` cannot be sent)."""
    if not running():
        return None
    try:
        return _worker.send(StudyFigures(study, run), TIMEOUT_S)
    except (pickle.PicklingError, TypeError, AttributeError):  # a study or run that does not travel
        return None


def drop(jobs: list[int]) -> None:
    """Replies to ``jobs`` that nobody will wait for: not kept when they come."""
    if running():
        _worker.drop(jobs)


def study_pngs(job: int) -> list[tuple[str, bytes]] | None:
    """The PNGs (name, bytes) of :func:`submit_study`'s job, in the order the study drew them;
    None when the worker failed or died (the caller draws them itself). Warnings the worker
    saw are raised here."""
    if not running():
        return None
    ok, reply = _worker.wait([job], TIMEOUT_S).get(job, (False, None))
    if not ok:
        return None
    pngs, said = reply
    for category, message in said:
        warnings.warn(message, getattr(builtins, category, UserWarning), stacklevel=2)
    return pngs


def _study_figures(task: StudyFigures) -> list[tuple[str, bytes]]:
    """The worker's side of :class:`StudyFigures`: drawn into a folder of its own, read back."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="railfmu-figures-") as tmp:
        names = task.study.figures(task.run, Path(tmp))
        return [(name, (Path(tmp) / name).read_bytes()) for name in names]


# --- the worker's side ---

def serve(requests_fd: int, replies_fd: int) -> None:
    """The worker's loop: draw each figure received, send back its PNG (or why not)."""
    import queue

    os.environ["_RAILFMU_IN_FIGURE_WORKER"] = "1"
    # Ctrl-C in a terminal reaches the whole process group: the parent decides what ends (it
    # closes the pipe, or kills this process, at its exit)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    outbox: queue.SimpleQueue = queue.SimpleQueue()

    def read():
        try:
            while (msg := _read_frame(requests_fd)) is not None:
                inbox.put(msg)
        except OSError:
            pass
        inbox.put(None)  # the parent closed its end, or died

    def write():
        try:
            while (reply := outbox.get()) is not None:
                data = memoryview(_frame(reply))
                while data:
                    data = data[os.write(replies_fd, data):]
        except OSError:  # the parent is gone
            os._exit(0)

    threading.Thread(target=read, daemon=True).start()
    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    from railfmu.experiments.engine.figure_png import render, warm_up

    warm_up()  # matplotlib's import and fonts, while the parent sets up and steps
    while (msg := inbox.get()) is not None:
        job, task = pickle.loads(msg)
        try:
            with warnings.catch_warnings(record=True) as said:
                spec = pickle.loads(task)  # a StudyFigures task imports the study's module here
                if isinstance(spec, Imports):
                    for name in spec.modules:
                        importlib.import_module(name)
                    png = None
                elif isinstance(spec, StudyFigures):
                    png = _study_figures(spec)
                else:
                    png = render(spec)
            reply = (job, True, (png, [(w.category.__name__, str(w.message)) for w in said]))
        except Exception as exc:  # noqa: BLE001 - the parent draws it again, and raises it there
            reply = (job, False, f"{type(exc).__name__}: {exc}")
        outbox.put(pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL))
    outbox.put(None)
    writer.join()
