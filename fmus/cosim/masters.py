"""Fixed-step co-simulation masters for a :class:`fmus.cosim.system.System`.

Three masters, one time grid ``t_k = start + k h`` (k = 0 .. n), one sample per grid point
(n + 1 rows: ``time`` and the recorded signals), handed to the sinks as the run goes:

``jacobi``
    At every t_k: copy every connection (``dst = factor * src + offset``, in the order of
    ``system.connections``), sample, then step every FMU from t_k to t_k+1. Every FMU sees
    its inputs as the sources' outputs at the start of the step. This is the coupling of
    libcosim's fixed-step algorithm and of FMPy's container FMU.

``gauss-seidel``
    Components step one after the other in the order of the connection graph (sources
    first, :func:`gauss_seidel_order`); right before a component steps, its inputs are set
    from its sources' current outputs, so a source that already stepped gives its value at
    t_k+1. A cycle of connections is broken at one connection (reported in
    ``RunResult.notes``) whose destination then sees the source's value at t_k, as in
    Jacobi. An algebraic loop (a cycle in which every component passes its input straight to
    its output) is refused: Gauss-Seidel does not iterate.

``container``
    The system as one FMPy container FMU (:mod:`fmus.cosim.container`), stepped by a small C loop
    (doStep + getReal into a numpy buffer; a ctypes loop without a C compiler). The
    container couples like Jacobi, and its samples equal the ``jacobi`` master's bit for bit
    (asserted by tests/test_masters.py); see :mod:`fmus.cosim.container`.

What a sample at t_k holds, for every master: every FMU has stepped to t_k (Gauss-Seidel:
with its own coupling); then every connection has been copied from the outputs at t_k
(Jacobi and container: in connection order; Gauss-Seidel: in the order of the
input -> output dependencies, so a chain of direct-feedthrough components is consistent end
to end); then the signals are read. So an input reads its source's output at t_k, and a
direct-feedthrough output (the wheelset's ``ddy`` depends on ``xi``) is the one the FMU
computes from the inputs it holds at that moment. For Gauss-Seidel, this post-sweep copy
sets the same values the next sweep would set for every input whose source steps later,
and is overwritten by the t_k+1 value for the others before their FMU steps; it changes no
trajectory, only makes the sample consistent. The row at t_0 is taken after the initial
copy (all FMUs in their initial state, out of Initialization Mode).

The Python masters call the FMUs' ``fmi2GetReal``/``fmi2SetReal``/``fmi2DoStep`` through
ctypes with prebuilt arrays (FMPy's wrappers build ctypes arrays on every call), and each
sample lands straight in the preallocated result array. FMU errors keep the wording of
:class:`fmus.cosim.slave.Slave` (``X.fmu (name): what failed: <what the FMU logged>``).
"""

from __future__ import annotations

import contextlib
import ctypes
import heapq
import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import UserError
from .slave import Slave
from .system import Connection, Sink, System, recorded_signals

MASTERS = ("jacobi", "gauss-seidel", "container")
BLOCK_ROWS = 1000  # container path: rows per C call / per write_block
HAND_OVER_ROWS = 1  # Python masters: rows checked (finite) and handed to the sinks at once; 1 = every step, as an online observer expects

_c_uint_p = ctypes.POINTER(ctypes.c_uint)
_c_double_p = ctypes.POINTER(ctypes.c_double)


@dataclass
class RunResult:
    columns: list[str]  # "time", then "component.variable" recorded
    data: np.ndarray  # (n_samples, len(columns)); the rows sampled so far
    complete: bool  # reached stop_time
    wall_time_s: float
    master: str
    notes: list[str] = field(default_factory=list)


# -- checks shared by every master -----------------------------------------------------------

def _n_steps(system: System) -> int:
    start, stop, h = system.start_time, system.stop_time, system.step_size
    if not (math.isfinite(start) and math.isfinite(stop) and math.isfinite(h)) or h <= 0:
        raise UserError(f"step size {h} s does not divide the interval [{start}, {stop}] s")
    n = round((stop - start) / h)
    if n < 1 or not math.isclose(start + n * h, stop, rel_tol=1e-9, abs_tol=1e-12):
        raise UserError(f"step size {h} s does not divide the interval [{start}, {stop}] s")
    return n


def _check_names(system: System) -> None:
    names = [c.name for c in system.components]
    for name in names:
        if names.count(name) > 1:
            raise UserError(f"component {name!r} appears twice")
    for c in system.connections:
        for comp in (c.src, c.dst):
            if comp not in names:
                raise UserError(f"connection {c}: unknown component {comp!r}")


def _non_finite(columns: list[str], row: np.ndarray) -> UserError:
    j = next(j for j in range(1, len(row)) if not math.isfinite(row[j]))
    return UserError(f"{columns[j]} = {row[j]} at t = {row[0]:.6g} s: a non-finite value left an FMU")


class _Progress:
    """``\\r  t = ... / stop s (xx.x %)`` on stderr about once a second, once the run has
    taken more than a second."""

    def __init__(self, enabled: bool, start: float, stop: float):
        self.enabled, self.start, self.stop = enabled, start, stop
        self.t0 = self.last = time.monotonic()
        self.shown = False

    def update(self, t: float) -> None:
        now = time.monotonic()
        if self.enabled and now - self.last > 1.0:
            frac = (t - self.start) / (self.stop - self.start)
            print(f"\r  t = {t:8.3f} / {self.stop:g} s ({100 * frac:5.1f} %)", end="", file=sys.stderr)
            self.last = now
            self.shown = True

    def done(self) -> None:
        if self.enabled and (self.shown or time.monotonic() - self.t0 > 1.0):
            print(f"\r  t = {self.stop:8.3f} / {self.stop:g} s (100.0 %)", file=sys.stderr)

    def abort(self) -> None:
        if self.shown:
            print(file=sys.stderr)


# -- Gauss-Seidel ordering -------------------------------------------------------------------

def _feedthrough(md, out_name: str, in_name: str) -> bool:
    """Does output ``out_name`` depend directly on input ``in_name`` (ModelStructure)?"""
    for unknown in md.outputs:
        if unknown.variable.name == out_name:
            deps = unknown.dependencies
            return deps is None or any(d.name == in_name for d in deps)
    return True  # not in ModelStructure/Outputs: no declared dependencies, assume any


def _transfer_order(system: System, mds: Mapping) -> list[int]:
    """Indices of ``system.connections`` in the order a consistent transfer needs: a
    connection out of ``b.v`` after every connection into an input of ``b`` that ``v``
    depends on directly (ties: the given order). UserError naming an algebraic loop."""
    conns = system.connections
    after: list[list[int]] = [[] for _ in conns]  # i -> the connections that must follow i
    indeg = [0] * len(conns)
    for i, ci in enumerate(conns):
        for j, cj in enumerate(conns):
            if cj.src == ci.dst and _feedthrough(mds[ci.dst], cj.src_var, ci.dst_var):
                after[i].append(j)
                indeg[j] += 1
    ready = [i for i in range(len(conns)) if indeg[i] == 0]
    heapq.heapify(ready)
    order = []
    while ready:
        i = heapq.heappop(ready)
        order.append(i)
        for j in after[i]:
            indeg[j] -= 1
            if indeg[j] == 0:
                heapq.heappush(ready, j)
    if len(order) < len(conns):
        left = {i for i in range(len(conns)) if i not in set(order)}
        loop = _find_cycle(left, after)
        raise UserError("algebraic loop: " + ", ".join(str(conns[i]) for i in loop)
                        + "; Gauss-Seidel does not iterate")
    return order


def _find_cycle(nodes: set[int], after: list[list[int]]) -> list[int]:
    """One cycle of the graph restricted to ``nodes`` (every node there lies on or leads to one)."""
    start = min(nodes)
    path, seen = [start], {start: 0}
    while True:
        nxt = min(j for j in after[path[-1]] if j in nodes)
        if nxt in seen:
            cycle = path[seen[nxt]:]
            k = cycle.index(min(cycle))
            return cycle[k:] + cycle[:k]
        seen[nxt] = len(path)
        path.append(nxt)


def gauss_seidel_order(system: System, model_descriptions: Mapping) -> tuple[list[str], list[Connection]]:
    """The order in which Gauss-Seidel steps the components, and the connections it delays.

    ``model_descriptions`` maps component names to FMPy model descriptions. Kahn's
    algorithm on the component graph (ties: the order of ``system.components``); when every
    remaining component waits for another (a cycle), the next one is the component with no
    direct feedthrough from its connected inputs to its connected outputs (else the fewest
    waiting inputs, then system order), and its inputs from components not yet ordered
    become delayed: they carry the source's value at the start of the step. A connection of
    a component to itself is always delayed. Raises UserError for an algebraic loop.
    """
    _check_names(system)
    _transfer_order(system, model_descriptions)  # refuses algebraic loops
    names = [c.name for c in system.components]
    remaining = list(names)
    order: list[str] = []
    delayed: list[Connection] = [c for c in system.connections if c.src == c.dst]

    def waiting(comp: str) -> list[Connection]:
        return [c for c in system.connections if c.dst == comp and c.src != comp and c.src in remaining]

    def passes_through(comp: str) -> bool:
        md = model_descriptions[comp]
        ins = [c.dst_var for c in system.connections if c.dst == comp]
        outs = [c.src_var for c in system.connections if c.src == comp]
        return any(_feedthrough(md, o, i) for o in outs for i in ins)

    while remaining:
        ready = [c for c in remaining if not waiting(c)]
        if ready:
            nxt = ready[0]
        else:
            nxt = min(remaining, key=lambda c: (passes_through(c), len(waiting(c)), names.index(c)))
            delayed.extend(waiting(nxt))
        order.append(nxt)
        remaining.remove(nxt)
    delayed.sort(key=lambda c: system.connections.index(c))
    return order, delayed


# -- the Python masters ----------------------------------------------------------------------

class _Fmu:
    """Raw ctypes entry points of one instantiated Slave (FMPy's own function objects keep
    their argtypes; these are fresh ones with cheap argument conversion)."""

    def __init__(self, slave: Slave):
        self.slave = slave
        dll = slave.fmu.dll
        self.c = ctypes.c_void_p(slave.fmu.component)
        self.get_real = dll["fmi2GetReal"]
        self.get_real.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
        self.get_real.restype = ctypes.c_int
        self.set_real = dll["fmi2SetReal"]
        self.set_real.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
        self.set_real.restype = ctypes.c_int
        self.do_step = dll["fmi2DoStep"]
        self.do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        self.do_step.restype = ctypes.c_int

    def fail(self, what: str, status: int):
        return self.slave.failure(what, f"status {status}")


class _Link:
    """Consecutive connections between one pair of components: one fmi2GetReal, one
    fmi2SetReal (an affine map applied in Python, only where it is not the identity)."""

    def __init__(self, conns: list[Connection], src: _Fmu, dst: _Fmu, src_vrs: list[int], dst_vrs: list[int]):
        self.conns, self.src, self.dst = conns, src, dst
        n = len(conns)
        self.n = n
        self.src_vrs = (ctypes.c_uint * n)(*src_vrs)
        self.dst_vrs = (ctypes.c_uint * n)(*dst_vrs)
        self.src_buf = (ctypes.c_double * n)()
        self.maps = [(i, c.factor, c.offset) for i, c in enumerate(conns) if not c.identity]
        self.dst_buf = (ctypes.c_double * n)() if self.maps else self.src_buf

    def transfer(self, t: float) -> None:
        s = self.src.get_real(self.src.c, self.src_vrs, self.n, self.src_buf)
        if s > 1:
            raise self.src.fail(f"fmi2GetReal of {', '.join(str(c) for c in self.conns)} at t = {t:.9g} s", s)
        if self.maps:
            src, dst = self.src_buf, self.dst_buf
            for i in range(self.n):
                dst[i] = src[i]
            for i, factor, offset in self.maps:
                dst[i] = factor * src[i] + offset
        s = self.dst.set_real(self.dst.c, self.dst_vrs, self.n, self.dst_buf)
        if s > 1:
            raise self.dst.fail(f"fmi2SetReal of {', '.join(str(c) for c in self.conns)} at t = {t:.9g} s", s)


def _links(conns: list[Connection], fmus: dict[str, _Fmu]) -> list[_Link]:
    groups: list[list[Connection]] = []
    for c in conns:
        if groups and c.src != c.dst and (groups[-1][0].src, groups[-1][0].dst) == (c.src, c.dst):
            groups[-1].append(c)
        else:
            groups.append([c])
    out = []
    for g in groups:
        src, dst = fmus[g[0].src], fmus[g[0].dst]
        svars = [src.slave.var(c.src_var) for c in g]
        dvars = [dst.slave.var(c.dst_var) for c in g]
        for c, sv, dv in zip(g, svars, dvars):
            if sv.type != "Real" or dv.type != "Real":
                raise UserError(f"connection {c}: only Real connections are supported ({sv.type} -> {dv.type})")
        out.append(_Link(g, src, dst, [v.valueReference for v in svars], [v.valueReference for v in dvars]))
    return out


class _Sampler:
    """Reads the recorded signals into row k of ``data``: one fmi2GetReal per run of
    consecutive columns of the same FMU, written straight into the array."""

    def __init__(self, record: list[str], fmus: dict[str, _Fmu], data: np.ndarray):
        self.data = data
        self.row_bytes = data.strides[0]
        self.base = data.ctypes.data
        runs: list[tuple[_Fmu, list[int], int]] = []
        for col, signal in enumerate(record, start=1):
            comp, name = signal.split(".", 1)
            if comp not in fmus:
                raise UserError(f"recorded signal {signal}: unknown component {comp!r}")
            fmu = fmus[comp]
            v = fmu.slave.var(name)
            if v.type != "Real":
                raise UserError(f"recorded signal {signal} is {v.type}: only Real signals can be recorded")
            if runs and runs[-1][0] is fmu:
                runs[-1][1].append(v.valueReference)
            else:
                runs.append((fmu, [v.valueReference], col))
        self.runs = [(f, (ctypes.c_uint * len(vrs))(*vrs), len(vrs), col * 8) for f, vrs, col in runs]
        self.count = 0  # rows sampled

    def sample(self, k: int, t: float) -> None:
        addr = self.base + k * self.row_bytes
        for f, vrs, n, off in self.runs:
            s = f.get_real(f.c, vrs, n, addr + off)
            if s > 1:
                raise f.fail(f"fmi2GetReal at t = {t:.9g} s", s)
        self.data[k, 0] = t
        self.count = k + 1


def _run_python(system: System, master: str, sinks: Sequence[Sink], progress: bool) -> RunResult:
    n = _n_steps(system)
    _check_names(system)
    start, stop, h = system.start_time, system.stop_time, system.step_size
    slaves: dict[str, Slave] = {}
    opened: list[Sink] = []
    notes: list[str] = []
    wall0 = time.perf_counter()
    bar = _Progress(progress, start, stop)
    sampler: _Sampler | None = None
    sent = 0  # rows 0 .. sent-1 are checked and with the sinks
    try:
        for comp in system.components:
            s = slaves[comp.name] = Slave(comp.fmu, comp.name)
            s.enter_initialization(start, stop)
            for name, value in comp.parameters.items():
                s.set(name, value)
        fmus = {name: _Fmu(s) for name, s in slaves.items()}
        if master == "gauss-seidel":
            mds = {name: s.md for name, s in slaves.items()}
            order, delayed = gauss_seidel_order(system, mds)
            transfer = [system.connections[i] for i in _transfer_order(system, mds)]
            notes.append("Gauss-Seidel order: " + " -> ".join(order))
            for c in delayed:
                notes.append(f"delayed connection {c}: its destination steps with the source's "
                             "value at the start of the step (a cycle is broken here)")
            delayed_ids = {id(c) for c in delayed}
            sweep = [(fmus[name], _links([c for c in transfer if c.dst == name and id(c) not in delayed_ids],
                                         fmus)) for name in order]
        else:
            transfer = list(system.connections)
        links = _links(transfer, fmus)
        record = recorded_signals(system, {n: s.vars for n, s in slaves.items()})
        columns = ["time", *record]
        data = np.empty((n + 1, len(columns)))
        sampler = _Sampler(record, fmus, data)
        for s in slaves.values():
            s.exit_initialization()
        for sink in sinks:
            sink.open(columns)
            opened.append(sink)

        def hand_over(upto: int) -> None:
            """Check rows sent .. upto-1 (all finite) and pass them to the sinks, row by row;
            in blocks, because a per-row numpy check would cost more than the FMUs."""
            nonlocal sent
            block = data[sent:upto]
            bad = ~np.isfinite(block).all(axis=1) if not np.isfinite(block).all() else None
            stop_at = sent + int(np.argmax(bad)) if bad is not None else upto
            for j in range(sent, stop_at):
                for sink in opened:
                    sink.write(data[j])
            sent = stop_at
            if bad is not None:
                raise _non_finite(columns, data[stop_at])

        steppers = [(f, "fmi2DoStep at t = {:.9g} s") for f in fmus.values()]
        for k in range(n + 1):
            t = start + k * h
            if master == "jacobi":
                for link in links:  # all outputs at t first, then all steps
                    link.transfer(t)
                sampler.sample(k, t)
                if k == n:
                    break
                for f, what in steppers:
                    s = f.do_step(f.c, t, h, 1)
                    if s > 1:
                        raise f.fail(what.format(t), s)
            else:
                if k > 0:
                    for f, inputs in sweep:  # step t - h -> t, one component after the other
                        for link in inputs:
                            link.transfer(t - h)
                        s = f.do_step(f.c, start + (k - 1) * h, h, 1)
                        if s > 1:
                            raise f.fail(f"fmi2DoStep at t = {start + (k - 1) * h:.9g} s", s)
                for link in links:  # consistent sample: every input from its source at t
                    link.transfer(t)
                sampler.sample(k, t)
            if k % HAND_OVER_ROWS == 0:
                hand_over(k + 1)
                bar.update(t)
        hand_over(n + 1)
        bar.done()
    except BaseException as exc:
        bar.abort()
        earlier = None
        if sampler is not None and sampler.count > sent:  # rows sampled before the failure
            with contextlib.suppress(Exception, KeyboardInterrupt):  # a sink failing again
                try:
                    hand_over(sampler.count)
                except UserError as bad:  # a non-finite sample comes before the failure: report it
                    earlier = bad
        for sink in opened:
            with contextlib.suppress(Exception):  # close the others all the same
                sink.close(False)
        if earlier is not None and not isinstance(exc, KeyboardInterrupt):
            raise earlier from None
        raise
    finally:
        for s in slaves.values():
            s.close()
    for sink in opened:
        sink.close(True)
    return RunResult(columns, data, True, time.perf_counter() - wall0, master, notes)


# -- the container master --------------------------------------------------------------------

def _run_container(system: System, sinks: Sequence[Sink], progress: bool) -> RunResult:
    from .container import (
        ContainerSlave,
        cached_container_dir,
        load_driver,
    )

    n = _n_steps(system)
    _check_names(system)
    start, stop, h = system.start_time, system.stop_time, system.step_size
    wall0 = time.perf_counter()
    notes = ["container FMU (fmpy.container_fmu) couples like Jacobi: outputs copied after every step"]
    slave = None
    opened: list[Sink] = []
    bar = _Progress(progress, start, stop)
    try:
        unzipdir = cached_container_dir(system)
        slave = ContainerSlave(unzipdir, system.name or "system", keep_dir=True)
        names = {v.name: v for v in slave.md.modelVariables}
        record = recorded_signals(system, {c.name: _variables(c.fmu) for c in system.components})
        columns = ["time", *record]
        vrs = (ctypes.c_uint * len(record))(*[names[s].valueReference for s in record])
        nvr = len(record)
        slave.enter_initialization(start, stop)
        slave.exit_initialization()
        f = _Fmu(slave)
        data = np.empty((n + 1, len(columns)))
        base, row_bytes = data.ctypes.data, data.strides[0]
        st = f.get_real(f.c, vrs, nvr, base + 8)
        if st > 1:
            raise f.fail(f"fmi2GetReal at t = {start:.9g} s", st)
        data[0, 0] = start
        for sink in sinks:
            sink.open(columns)
            opened.append(sink)
        if not np.isfinite(data[0]).all():
            raise _non_finite(columns, data[0])
        for sink in opened:
            sink.write_block(data[0:1])

        driver = load_driver()
        if driver is None:
            notes.append("no C compiler: the container is stepped through ctypes (slower)")
        t_fmu = ctypes.c_double()
        st = f.get_real(f.c, (ctypes.c_uint * 1)(0), 1, ctypes.addressof(t_fmu))
        done_c, status_c = ctypes.c_long(), ctypes.c_int()
        time_vr = (ctypes.c_uint * 1)(0)
        k = 0  # rows 0..k are written
        while k < n:
            m = min(BLOCK_ROWS, n - k)
            if driver is not None:
                code = driver(ctypes.cast(f.do_step, ctypes.c_void_p), ctypes.cast(f.get_real, ctypes.c_void_p),
                              f.c, ctypes.byref(t_fmu), h, start, k, m, vrs, nvr,
                              base + (k + 1) * row_bytes, len(columns), ctypes.byref(done_c),
                              ctypes.byref(status_c))
                done, status = done_c.value, status_c.value
            else:
                code, done, status = _ctypes_steps(f, t_fmu, time_vr, h, start, k, m, vrs, nvr, data)
            if done:
                for sink in opened:
                    sink.write_block(data[k + 1:k + 1 + done])
            if code == 1:
                raise f.fail(f"fmi2DoStep at t = {start + (k + done) * h:.9g} s", status)
            if code == 2:
                raise f.fail(f"fmi2GetReal at t = {start + (k + done + 1) * h:.9g} s", status)
            if code == 3:
                raise _non_finite(columns, data[k + 1 + done])
            k += m
            bar.update(start + k * h)
        bar.done()
    except BaseException:
        bar.abort()
        for sink in opened:
            with contextlib.suppress(Exception):  # close the others all the same
                sink.close(False)
        raise
    finally:
        if slave is not None:
            slave.close()
    for sink in opened:
        sink.close(True)
    return RunResult(columns, data, True, time.perf_counter() - wall0, "container", notes)


def _ctypes_steps(f: _Fmu, t_fmu, time_vr, h, start, k0, m, vrs, nvr, data) -> tuple[int, int, int]:
    """The C driver's loop in Python (no C compiler): same calls, same rows."""
    base, row_bytes = data.ctypes.data, data.strides[0]
    for i in range(m):
        s = f.do_step(f.c, t_fmu.value, h, 1)
        if s > 1:
            return 1, i, s
        row = k0 + 1 + i
        s = f.get_real(f.c, time_vr, 1, ctypes.addressof(t_fmu))
        if s <= 1:
            s = f.get_real(f.c, vrs, nvr, base + row * row_bytes + 8)
        if s > 1:
            return 2, i, s
        data[row, 0] = start + (k0 + i + 1) * h
        if not np.isfinite(data[row]).all():
            return 3, i, 0
    return 0, m, 0


def _variables(fmu: Path) -> dict:
    from fmpy import read_model_description

    if not Path(fmu).is_file():
        raise UserError(f"{fmu}: FMU not found (run `railfmu build`)")
    return {v.name: v for v in read_model_description(str(fmu)).modelVariables}


# -- entry point -----------------------------------------------------------------------------

def run(system: System, master: str = "jacobi", sinks: Sequence[Sink] = (), progress: bool = True) -> RunResult:
    """Run ``system`` with ``master`` (one of :data:`MASTERS`), feeding ``sinks`` as it goes.

    Sinks get ``open(columns)``, then the rows (``write`` per sample from the Python
    masters, ``write_block`` from the container), then ``close(complete)``. On an error
    (UserError: a failed FMU call with what the FMU logged, a non-finite sample) or
    Ctrl-C the sinks are closed with ``complete=False`` first, so what they hold stays
    readable, and the exception propagates. FMUs and temporary folders are always freed.
    """
    if master not in MASTERS:
        raise UserError(f"unknown master {master!r}; choose one of {', '.join(MASTERS)}")
    if master == "container":
        return _run_container(system, sinks, progress)
    return _run_python(system, master, sinks, progress)
