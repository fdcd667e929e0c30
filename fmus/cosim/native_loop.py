"""The container master on FMI 2.0 systems: a C coupling loop over the member FMUs.

The FMUs are loaded, instantiated, parameterised and initialised exactly as the Jacobi master
does it (:class:`railfmu.fmus.cosim.slave.Slave`, the same calls in the same order); then
``fmus/native/host/coupling_loop.c`` couples and steps them, 1000 rows per call, calling
each FMU's own ``fmi2GetReal``/``fmi2SetReal``/... and ``fmi2DoStep`` (the addresses from the
FMUs' loaded libraries). At every ``t_k = start + k h`` it copies every connection in the
order of ``system.connections`` (one get and one set per run of consecutive connections of
one source/destination pair and type, as the Jacobi master's links; an affine map
``factor * src + offset`` in double, rounded as Python rounds it), samples the recorded
signals into row k, then steps every component from ``t_k``: the Jacobi master's loop, so its
samples equal that master's bit for bit, LinearTransformations and unit conversions included.

Status semantics are the Jacobi master's: the loop stops at the first call that returns worse
than ``fmi2Warning`` and says which; ``fmi2Discard`` from ``fmi2DoStep`` with
``fmi2GetBooleanStatus(fmi2Terminated) = true`` is an early end, anything else an error with
the same words (the component, the call, what the FMU logged); a non-finite value in a row
stops the run there. The sinks get the rows in blocks, as from FMPy's container before.

No trial run in a child process (:mod:`railfmu.fmus.cosim.trial`): the trial guarded against
FMPy's Rust container crashing on FMUs it cannot drive. This loop makes the Jacobi master's
calls on the same instances, and that master runs every FMU without a trial; an FMU that
crashes here crashes the Jacobi master too.

Without a C compiler the Jacobi master's Python loop runs instead (the same samples, slower),
and the run's notes say so.
"""

from __future__ import annotations

import contextlib
import ctypes
import time
from collections.abc import Sequence
from pathlib import Path

from railfmu.fmus.cache import compiled_library
from railfmu.fmus.cosim.coupling import (
    BLOCK_ROWS,
    RunResult,
    _Fmu,
    _links,
    _non_finite,
    _Progress,
    _row_buffer,
    _Terminated,
    fmu_stop_time,
    signal_runs,
)
from railfmu.fmus.cosim.slave import Slave, Status
from railfmu.fmus.cosim.system import Sink, System, check_system, recorded_signals

LOOP_SOURCE = Path(__file__).parent.parent / "native" / "host" / "coupling_loop.c"
NOTE = ("container master: the FMUs coupled like Jacobi by a C loop over their own fmi2 functions "
        "(coupling_loop.c)")
LOOP_OK, LOOP_GET_FAILED, LOOP_SET_FAILED, LOOP_SAMPLE_FAILED, LOOP_NON_FINITE, LOOP_STEP_FAILED = range(6)
_RUN_KIND = {"Real": 0, "Integer": 1, "Boolean": 2}


def takes(system: System) -> bool:
    """Whether this loop runs ``system``: every component an FMI 2.0 FMU."""
    return all(str(c.md.fmiVersion) == "2.0" for c in system.components)


class _Component(ctypes.Structure):
    _fields_ = [("instance", ctypes.c_void_p), ("do_step", ctypes.c_void_p)]


class _LinkC(ctypes.Structure):
    _fields_ = [("get", ctypes.c_void_p), ("set", ctypes.c_void_p), ("src", ctypes.c_void_p),
                ("dst", ctypes.c_void_p), ("src_vrs", ctypes.c_void_p), ("dst_vrs", ctypes.c_void_p),
                ("n", ctypes.c_size_t), ("src_buf", ctypes.c_void_p), ("dst_buf", ctypes.c_void_p),
                ("n_maps", ctypes.c_size_t), ("map_index", ctypes.c_void_p), ("factor", ctypes.c_void_p),
                ("offset", ctypes.c_void_p)]


class _Run(ctypes.Structure):
    _fields_ = [("get", ctypes.c_void_p), ("instance", ctypes.c_void_p), ("vrs", ctypes.c_void_p),
                ("n", ctypes.c_size_t), ("col", ctypes.c_size_t), ("kind", ctypes.c_int),
                ("buf", ctypes.c_void_p)]


class _Loop(ctypes.Structure):
    _fields_ = [("components", ctypes.c_void_p), ("n_components", ctypes.c_size_t),
                ("links", ctypes.c_void_p), ("n_links", ctypes.c_size_t),
                ("runs", ctypes.c_void_p), ("n_runs", ctypes.c_size_t),
                ("start", ctypes.c_double), ("h", ctypes.c_double), ("last", ctypes.c_long),
                ("ncols", ctypes.c_size_t)]


_loop = None  # the loaded function, False when it cannot be built


def load_loop():
    """``railfmu_coupled_rows`` from the compiled loop (built once per source version into the
    cache), or ``None`` when no C compiler works."""
    global _loop
    if _loop is not None:
        return _loop or None
    # -ffp-contract=off: factor * src + offset rounded twice, as Python computes it (an fma
    # would round once and differ from the Jacobi master in the last bit)
    dll = compiled_library(LOOP_SOURCE, ["-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror"])
    if dll is None:
        _loop = False
        return None
    fn = dll.railfmu_coupled_rows
    fn.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_long, ctypes.c_void_p,
                   ctypes.POINTER(ctypes.c_long), ctypes.POINTER(ctypes.c_long), ctypes.POINTER(ctypes.c_int)]
    fn.restype = ctypes.c_int
    fn._keep = dll
    _loop = fn
    return fn


def _address(fn) -> int:
    return ctypes.cast(fn, ctypes.c_void_p).value


def run_native(system: System, sinks: Sequence[Sink], progress: bool) -> RunResult | None:
    """The container master on ``system`` (:func:`takes` it): see the module docstring. None
    when the loop cannot be compiled (no C compiler)."""
    loop = load_loop()
    if loop is None:  # the caller runs the Jacobi master's Python loop instead
        return None
    n = check_system(system)
    start, stop, h = system.start_time, system.stop_time, system.step_size
    wall0 = time.perf_counter()
    slaves: dict[str, Slave] = {}
    opened: list[Sink] = []
    bar = _Progress(progress, start, stop)
    ended: _Terminated | None = None
    try:
        for comp in system.components:  # the Jacobi master's calls, in its order
            s = slaves[comp.name] = Slave(comp.fmu, comp.name, md=comp.md)
            s.enter_initialization(start, fmu_stop_time(stop, h))
            for name, value in comp.parameters.items():
                s.set(name, value)
        fmus = {name: _Fmu(s) for name, s in slaves.items()}
        links = _links(list(system.connections), fmus)
        record = recorded_signals(system)
        columns = ["time", *record]
        data = _row_buffer(n, columns)
        keep: list = []  # ctypes objects the loop points into

        def arr(ctype, values) -> int:
            a = (ctype * max(len(values), 1))(*values)
            keep.append(a)
            return ctypes.addressof(a)

        steppers = list(fmus.values())
        comps = (_Component * len(steppers))(*[_Component(f.c.value, _address(f.do_step)) for f in steppers])
        link_c = (_LinkC * max(len(links), 1))()
        for lc, link in zip(link_c, links):
            lc.get, lc.set = _address(link.get), _address(link.set)
            lc.src, lc.dst, lc.n = link.src.c.value, link.dst.c.value, link.n
            lc.src_vrs, lc.dst_vrs = ctypes.addressof(link.src_vrs), ctypes.addressof(link.dst_vrs)
            lc.src_buf, lc.dst_buf = ctypes.addressof(link.src_buf), ctypes.addressof(link.dst_buf)
            if link.convert and link.src_buf._type_ is not ctypes.c_double:
                raise AssertionError(f"{link.what}: only Real values are converted")  # FMI 2.0: never
            lc.n_maps = len(link.maps)
            lc.map_index = arr(ctypes.c_size_t, [i for i, _, _ in link.maps])
            lc.factor = arr(ctypes.c_double, [float(a) for _, a, _ in link.maps])
            lc.offset = arr(ctypes.c_double, [float(b) for _, _, b in link.maps])
        runs = signal_runs(system, record, fmus)
        run_c = (_Run * max(len(runs), 1))()
        for rc, (f, t, vrs, cols) in zip(run_c, runs):
            rc.get, rc.instance, rc.vrs, rc.n = _address(f.get[t]), f.c.value, arr(ctypes.c_uint, vrs), len(vrs)
            rc.col, rc.kind = cols[0], _RUN_KIND[t]
            rc.buf = arr(ctypes.c_int, [0] * len(vrs)) if t != "Real" else None
        spec = _Loop(ctypes.addressof(comps), len(steppers), ctypes.addressof(link_c), len(links),
                     ctypes.addressof(run_c), len(runs), start, h, n, len(columns))
        for s in slaves.values():
            s.exit_initialization()
        for sink in sinks:
            sink.open(columns)
            opened.append(sink)

        rows = 1 if any(getattr(s, "every_step", False) for s in opened) else BLOCK_ROWS
        base, row_bytes = data.ctypes.data, data.strides[0]
        done_c, where_c, status_c = ctypes.c_long(), ctypes.c_long(), ctypes.c_int()
        k = 0  # rows 0 .. k-1 are sampled and with the sinks
        while k <= n:
            m = 1 if k == 0 else min(rows, n + 1 - k)  # row 0 alone first, as the other masters
            code = loop(ctypes.byref(spec), k, m, base + k * row_bytes, ctypes.byref(done_c),
                        ctypes.byref(where_c), ctypes.byref(status_c))
            done, where, status = done_c.value, where_c.value, status_c.value
            if done:
                for sink in opened:
                    sink.write_block(data[k:k + done])
            k += done
            if code == LOOP_OK:
                bar.update(start + (k - 1) * h)
                continue
            t = start + (k if code != LOOP_STEP_FAILED else k - 1) * h
            if code == LOOP_NON_FINITE:
                raise _non_finite(columns, data[k])
            if code == LOOP_STEP_FAILED:
                f = steppers[where]
                if status == Status.DISCARD and f.slave.terminated():
                    ended = _Terminated(f.slave, t)
                    break
                raise f.fail(f"{f.slave.fmi('DoStep')} at t = {t:.9g} s", status)
            if code == LOOP_SAMPLE_FAILED:
                raise runs[where][0].fail(f"reading the recorded signals at t = {t:.9g} s", status)
            link = links[where]
            if code == LOOP_GET_FAILED:
                raise link.src.fail(f"fmi2Get{link.what} at t = {t:.9g} s", status)
            raise link.dst.fail(f"fmi2Set{link.what} at t = {t:.9g} s", status)
        bar.done()
    except BaseException:
        bar.abort()
        for sink in opened:
            with contextlib.suppress(Exception):  # close the others all the same
                sink.close(False)
        raise
    finally:
        for s in slaves.values():
            s.close()
    for sink in opened:
        sink.close(True)
    data = data[:k]
    notes = [NOTE]
    if ended is not None:
        notes.append(str(ended))
    return RunResult(columns, data, True, time.perf_counter() - wall0, "container", notes,
                     end_time=float(data[-1, 0]), early_end=str(ended) if ended else None,
                     step_size=h, step_size_from=system.step_size_from)
