"""Fixed-step co-simulation masters for a :class:`railfmu.fmus.cosim.system.System`.

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
    Jacobi's coupling without Python in the loop. A system of FMI 2.0 FMUs runs in a C loop of
    our own (:mod:`railfmu.fmus.cosim.native_loop`): the FMUs loaded and initialised as the
    Jacobi master does it, then coupled, sampled and stepped 1000 rows per call through their
    own fmi2 functions, LinearTransformations included; no trial run (it makes the Jacobi
    master's calls). A system with an FMI 3.0 component runs as one FMPy container FMU
    (:mod:`railfmu.fmus.cosim.container`, :func:`_run_container`) stepped by a small C driver,
    after a trial in a child process when an FMU is not railfmu's
    (:mod:`railfmu.fmus.cosim.trial`). Either way the samples equal the ``jacobi`` master's bit
    for bit (asserted by tests/test_masters.py).

What a sample at t_k holds, for every master: every FMU has stepped to t_k (Gauss-Seidel:
with its own coupling); then every connection has been copied from the outputs at t_k
(Jacobi and container: in connection order; Gauss-Seidel: in the order of the
input -> output dependencies, so a chain of direct-feedthrough components is consistent end
to end); then the signals are read. So an input reads its source's output at t_k, and a
direct-feedthrough output (the wheelset's ``ddy`` depends on ``xi``) is the one the FMU
computes from the inputs it holds at that moment. (The Jacobi master can instead read the row
right after the step, before any input is set: :func:`run`'s ``sampling``.) For Gauss-Seidel, this post-sweep copy
sets the same values the next sweep would set for every input whose source steps later,
and is overwritten by the t_k+1 value for the others before their FMU steps; it changes no
trajectory, only makes the sample consistent. The row at t_0 is taken after the initial
copy (all FMUs in their initial state, out of Initialization Mode).

Signals are Real, Integer or Boolean (a connection joins two of the same type; the rows hold
Integer values and Boolean 0/1 as numbers). The Python masters call the FMUs'
``fmi2Get*``/``fmi2Set*``/``fmi2DoStep`` through ctypes with prebuilt arrays (FMPy's wrappers
build ctypes arrays on every call), and each Real sample lands straight in the preallocated
result array.

FMI 1.0, 2.0 and 3.0 Co-Simulation FMUs run in the Python masters alike (through
:class:`railfmu.fmus.cosim.slave.Slave`); the container master takes FMI 2.0 and 3.0 components
(its samples equal Jacobi's for both) and hands a system with an FMI 1.0 FMU to ``jacobi``,
which couples the same way. FMI 2.0 status semantics, in every master: ``fmi2Discard`` from ``fmi2DoStep`` followed by
``fmi2GetBooleanStatus(fmi2Terminated) = true`` ends the run normally at that communication
point (``RunResult.early_end``; every row up to it is there and the sinks close as
complete); any other ``fmi2Discard``, ``fmi2Error`` or ``fmi2Fatal`` is an error naming the
component and the status (``X.fmu (name): what failed: <what the FMU logged, or the status>``,
the wording of :class:`railfmu.fmus.cosim.slave.Slave`; the container master's C loop says which
call of which component failed, so its words are Jacobi's). FMPy's container reports one
status for all its components, so on either the run up to that step is replayed with the
Jacobi master (same samples, bit for bit) to name the inner component. FMI 3.0: ``terminateSimulation``
from ``fmi3DoStep`` ends the run the same way; FMI 1.0 has no terminate status, so any
``fmiDiscard`` is an error.
"""

from __future__ import annotations

import contextlib
import ctypes
import heapq
import sys
import time
from collections.abc import Mapping, Sequence

import numpy as np

from railfmu.models.errors import UserError
from railfmu.fmus.cosim.coupling import (  # noqa: F401 (RunResult, fmu_stop_time, BLOCK_ROWS: this module's API)
    _C_TYPES,
    BLOCK_ROWS,
    HAND_OVER_ROWS,
    RunResult,
    _check_names,
    _Fmu,
    _links,
    _non_finite,
    _Progress,
    _row_buffer,
    _Sampler,
    _Terminated,
    fmu_stop_time,
)
from railfmu.fmus.cosim.slave import Slave, Status
from railfmu.fmus.cosim.system import Connection, Sink, System, carried_type, check_system, recorded_signals

MASTERS = ("jacobi", "gauss-seidel", "container")
#: when the Jacobi master reads a row (:func:`run`'s ``sampling``): after every connection is
#: copied (the default, every master), or right after the step, before any input is set
SAMPLINGS = ("after-transfer", "before-transfer")
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

def _run_python(system: System, master: str, sinks: Sequence[Sink], progress: bool,
                max_steps: int | None = None, sampling: str = "after-transfer") -> RunResult:
    """``max_steps``: stop after that many steps (the container's replay of a failure)."""
    n = check_system(system)
    if max_steps is not None:
        n = min(n, max_steps)
    start, stop, h = system.start_time, system.stop_time, system.step_size
    slaves: dict[str, Slave] = {}
    opened: list[Sink] = []
    notes: list[str] = []
    wall0 = time.perf_counter()
    bar = _Progress(progress, start, stop)
    sampler: _Sampler | None = None
    sent = 0  # rows 0 .. sent-1 are checked and with the sinks
    ended: _Terminated | None = None
    try:
        for comp in system.components:
            s = slaves[comp.name] = Slave(comp.fmu, comp.name, md=comp.md)
            s.enter_initialization(start, fmu_stop_time(stop, h))
            for name, value in comp.parameters.items():
                s.set(name, value)
        fmus = {name: _Fmu(s) for name, s in slaves.items()}
        if master == "gauss-seidel":
            mds = {c.name: c.md for c in system.components}
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
        record = recorded_signals(system)
        columns = ["time", *record]
        data = _row_buffer(n, columns)
        sampler = _Sampler(record, fmus, data, system)
        for s in slaves.values():
            s.exit_initialization()
        for sink in sinks:
            sink.open(columns)
            opened.append(sink)

        every = 1 if any(getattr(s, "every_step", False) for s in opened) else HAND_OVER_ROWS

        def hand_over(upto: int) -> None:
            """Check rows sent .. upto-1 (all finite) and pass them to the sinks as one block;
            in blocks, because a per-row numpy check (and a per-row observer step) would cost
            more than the FMUs."""
            nonlocal sent
            block = data[sent:upto]
            bad = ~np.isfinite(block).all(axis=1) if not np.isfinite(block).all() else None
            stop_at = sent + int(np.argmax(bad)) if bad is not None else upto
            if stop_at > sent:
                for sink in opened:
                    sink.write_block(data[sent:stop_at])
            sent = stop_at
            if bad is not None:
                raise _non_finite(columns, data[stop_at])

        steppers = list(fmus.values())
        try:
            for k in range(n + 1):
                t = start + k * h
                if master == "jacobi" and sampling == "before-transfer":
                    sampler.sample(k, t)  # no output is read once an input is set, until the step
                    if k == n:
                        break
                    for link in links:
                        link.fetch(t)
                    for link in links:
                        link.put(t)
                    for f in steppers:
                        f.step(t, h)
                elif master == "jacobi":
                    for link in links:  # all outputs at t first, then all steps
                        link.transfer(t)
                    sampler.sample(k, t)
                    if k == n:
                        break
                    for f in steppers:
                        f.step(t, h)
                else:
                    if k > 0:
                        for f, inputs in sweep:  # step t - h -> t, one component after the other
                            for link in inputs:
                                link.transfer(t - h)
                            f.step(start + (k - 1) * h, h)
                    for link in links:  # consistent sample: every input from its source at t
                        link.transfer(t)
                    sampler.sample(k, t)
                if k % every == 0:
                    hand_over(k + 1)
                    bar.update(t)
        except _Terminated as end:  # a normal end: the rows so far are the result
            ended = end
        hand_over(sampler.count)
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
    data = data[:sampler.count]
    if ended is not None:
        notes.append(str(ended))
    return RunResult(columns, data, True, time.perf_counter() - wall0, master, notes,
                     end_time=float(data[-1, 0]), early_end=str(ended) if ended else None,
                     step_size=h, step_size_from=system.step_size_from)


# -- FMPy's container: the container master on systems with FMI 3.0 components --------------

class _Signals(ctypes.Structure):
    """``Signals`` of fmus/native/runtime/container_driver.c."""
    _fields_ = [(name, ctypes.c_void_p) for name in
                ("do_step", "get_real", "get_integer", "get_boolean", "get_boolean_status",
                 "rvrs", "ivrs", "bvrs", "rcols", "icols", "bcols")] + \
               [("nr", ctypes.c_size_t), ("ni", ctypes.c_size_t), ("nb", ctypes.c_size_t),
                ("rbuf", ctypes.c_void_p), ("ibuf", ctypes.c_void_p)]


DRIVER_OK, DRIVER_DO_STEP_FAILED, DRIVER_GET_FAILED, DRIVER_NON_FINITE, DRIVER_TERMINATED = range(5)


def _run_container(system: System, sinks: Sequence[Sink], progress: bool) -> RunResult:
    """``system`` as one FMPy container FMU stepped by the C driver (FMI 2.0 and 3.0 components;
    identity connections only); FMI 2.0 systems take :mod:`railfmu.fmus.cosim.native_loop`."""
    from railfmu.fmus.cosim.container import (
        ContainerSlave,
        apply_parameters,
        cached_container_dir,
        load_driver,
        parameter_values,
    )

    n = check_system(system)
    start, stop, h = system.start_time, system.stop_time, system.step_size
    wall0 = time.perf_counter()
    notes = ["container FMU (fmpy.container_fmu) couples like Jacobi: outputs copied after every step"]
    slave = None
    opened: list[Sink] = []
    bar = _Progress(progress, start, stop)
    ended: str | None = None
    try:
        values = parameter_values(system)  # a bad value is refused before anything is written
        unzipdir = cached_container_dir(system)  # one folder for every run of this structure
        slave = ContainerSlave(unzipdir, system.name or "system", keep_dir=True)
        names = {v.name: v for v in slave.md.modelVariables}
        record = recorded_signals(system)
        columns = ["time", *record]
        typed: dict[str, tuple[list[int], list[int]]] = {t: ([], []) for t in _C_TYPES}
        for col, signal in enumerate(record, start=1):
            v = names[signal]
            typed[carried_type(v.type)][0].append(v.valueReference)
            typed[carried_type(v.type)][1].append(col)
        slave.enter_initialization(start, fmu_stop_time(stop, h))
        apply_parameters(slave, values)
        slave.exit_initialization()
        f = _Fmu(slave)
        keep = []  # ctypes arrays the driver points into

        def arr(ctype, values):
            a = (ctype * max(len(values), 1))(*values)
            keep.append(a)
            return ctypes.addressof(a)

        (rv, rc), (iv, ic), (bv, bc) = typed["Real"], typed["Integer"], typed["Boolean"]
        contiguous = rc == list(range(1, len(rc) + 1))
        sig = _Signals(
            do_step=ctypes.cast(f.do_step, ctypes.c_void_p), get_real=ctypes.cast(f.get["Real"], ctypes.c_void_p),
            get_integer=ctypes.cast(f.get["Integer"], ctypes.c_void_p),
            get_boolean=ctypes.cast(f.get["Boolean"], ctypes.c_void_p),
            # FMPy's container does not implement fmi2GetBooleanStatus (it logs an error): a
            # discard is told apart by the replay below
            get_boolean_status=None,
            rvrs=arr(ctypes.c_uint, rv), ivrs=arr(ctypes.c_uint, iv), bvrs=arr(ctypes.c_uint, bv),
            rcols=None if contiguous else arr(ctypes.c_size_t, rc), icols=arr(ctypes.c_size_t, ic),
            bcols=arr(ctypes.c_size_t, bc), nr=len(rv), ni=len(iv), nb=len(bv),
            rbuf=arr(ctypes.c_double, [0.0] * len(rv)), ibuf=arr(ctypes.c_int, [0] * max(len(iv), len(bv))))
        data = _row_buffer(n, columns)
        base, row_bytes = data.ctypes.data, data.strides[0]
        st = _sample_signals(sig, f, data[0])
        if st > Status.WARNING:
            raise f.fail(f"reading the recorded signals at t = {start:.9g} s", st)
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
        f.get_real(f.c, (ctypes.c_uint * 1)(0), 1, ctypes.addressof(t_fmu))
        done_c, status_c = ctypes.c_long(), ctypes.c_int()
        k = 0  # rows 0..k are written
        while k < n:
            m = min(BLOCK_ROWS, n - k)
            if driver is not None:
                code = driver(ctypes.byref(sig), f.c, ctypes.byref(t_fmu), h, start, k, m,
                              base + (k + 1) * row_bytes, len(columns), ctypes.byref(done_c),
                              ctypes.byref(status_c))
                done, status = done_c.value, status_c.value
            else:
                code, done, status = _ctypes_steps(sig, f, t_fmu, h, start, k, m, data)
            if done:
                for sink in opened:
                    sink.write_block(data[k + 1:k + 1 + done])
            t_fail = start + (k + done) * h
            if code in (DRIVER_DO_STEP_FAILED, DRIVER_TERMINATED):
                ended = _inner_outcome(system, k + done, f.fail(f"fmi2DoStep at t = {t_fail:.9g} s", status))
                data = data[:k + done + 1]
                break
            if code == DRIVER_GET_FAILED:
                raise f.fail(f"reading the recorded signals at t = {t_fail + h:.9g} s", status)
            if code == DRIVER_NON_FINITE:
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
    if ended:
        notes.append(ended)
    return RunResult(columns, data, True, time.perf_counter() - wall0, "container", notes,
                     end_time=float(data[-1, 0]), early_end=ended, step_size=h,
                     step_size_from=system.step_size_from)


def _inner_outcome(system: System, k: int, container_error: UserError) -> str:
    """The container's fmi2DoStep from step ``k`` failed or discarded: FMPy's container
    returns one status for all its components and implements no fmi2GetBooleanStatus, so
    steps 0..k are replayed with the Jacobi master, whose samples equal the container's bit
    for bit. Returns the early-end message (an inner FMU terminated), or raises the inner
    FMU's error; the container's own error if the replay does not reproduce it."""
    replay = _run_python(system, "jacobi", (), False, max_steps=k + 1)
    if replay.early_end:
        return replay.early_end
    raise container_error


def _sample_signals(sig: _Signals, f: _Fmu, row: np.ndarray) -> int:
    """The driver's ``sample`` in Python: one row of the recorded signals."""
    for vrs, cols, n, get, ctype in ((sig.rvrs, sig.rcols, sig.nr, f.get["Real"], ctypes.c_double),
                                     (sig.ivrs, sig.icols, sig.ni, f.get["Integer"], ctypes.c_int),
                                     (sig.bvrs, sig.bcols, sig.nb, f.get["Boolean"], ctypes.c_int)):
        if n == 0:
            continue
        buf = (ctype * n)()
        s = get(f.c, vrs, n, buf)
        if s > Status.WARNING:
            return s
        idx = list(range(1, n + 1)) if not cols else list((ctypes.c_size_t * n).from_address(cols))
        values = np.array(buf[:], dtype=float)
        row[idx] = (values != 0) if get is f.get["Boolean"] else values
    return 0


def _ctypes_steps(sig: _Signals, f: _Fmu, t_fmu, h, start, k0, m, data) -> tuple[int, int, int]:
    """The C driver's loop in Python (no C compiler): same calls, same rows, same codes."""
    time_vr = (ctypes.c_uint * 1)(0)
    for i in range(m):
        s = f.do_step(f.c, t_fmu.value, h, 1)
        if s > Status.WARNING:
            return DRIVER_DO_STEP_FAILED, i, s
        row = k0 + 1 + i
        s = f.get_real(f.c, time_vr, 1, ctypes.addressof(t_fmu))
        if s <= Status.WARNING:
            s = _sample_signals(sig, f, data[row])
        if s > Status.WARNING:
            return DRIVER_GET_FAILED, i, s
        data[row, 0] = start + (k0 + i + 1) * h
        if not np.isfinite(data[row]).all():
            return DRIVER_NON_FINITE, i, 0
    return DRIVER_OK, m, 0


# -- entry point -----------------------------------------------------------------------------

def run(system: System, master: str = "jacobi", sinks: Sequence[Sink] = (), progress: bool = True,
        sampling: str = "after-transfer") -> RunResult:
    """Run ``system`` with ``master`` (one of :data:`MASTERS`), feeding ``sinks`` as it goes.

    ``sampling`` (:data:`SAMPLINGS`): ``after-transfer``, the row at t_k is read after every
    connection is copied (every master); ``before-transfer`` (Jacobi only), the row at t_k is
    read right after the step to t_k, then all connections' sources are read, then all their
    destinations set, then every FMU steps: no output is read between setting an FMU's inputs
    and its next doStep (libcosim's order; an FMU may sample its inputs on that read), and a
    direct-feedthrough output in the row reflects the inputs of t_k-1.

    Sinks get ``open(columns)``, then the rows (``write_block``: the Python masters every
    :data:`HAND_OVER_ROWS` steps, or every step when a sink sets ``every_step``; the container
    per C call, every step for such a sink in its C loop), then ``close(complete)``. An FMU that ends
    the simulation (fmi2Discard + fmi2Terminated) ends the run normally at that communication
    point: ``RunResult.early_end`` says who and when, the sinks close as complete. On an error
    (UserError: a failed FMU call with what the FMU logged, a non-finite sample) or
    Ctrl-C the sinks are closed with ``complete=False`` first, so what they hold stays
    readable, and the exception propagates. FMUs and temporary folders are always freed.
    """
    if master not in MASTERS:
        raise UserError(f"unknown master {master!r}; choose one of {', '.join(MASTERS)}")
    if sampling not in SAMPLINGS:
        raise UserError(f"unknown sampling {sampling!r}; choose one of {', '.join(SAMPLINGS)}")
    if sampling != "after-transfer":
        if master != "jacobi":
            raise UserError(f"sampling {sampling}: only the Jacobi master reads its rows before the transfer "
                            f"(the {master} master samples after it); use --master jacobi")
        return _run_python(system, master, sinks, progress, sampling=sampling)
    if master == "container":
        from railfmu.fmus.cosim import native_loop
        from railfmu.fmus.cosim.trial import container_refusal

        if native_loop.takes(system):  # all FMI 2.0: our C loop, no trial (it calls as jacobi does)
            result = native_loop.run_native(system, sinks, progress)
            if result is None:  # no C compiler
                result = _run_python(system, "jacobi", sinks, progress)
                result.master = "container"
                result.notes.insert(0, "no C compiler: the container master ran the Jacobi master's Python loop "
                                       "(the same samples, slower)")
            return result
        others = [f"{c.name} (FMI {c.md.fmiVersion})" for c in system.components
                  if str(c.md.fmiVersion) not in ("2.0", "3.0")]
        why = (f"the container master takes FMI 2.0 and 3.0 components, not {', '.join(others)}"
               if others else container_refusal(system, _run_container))
        if why is None:
            return _run_container(system, sinks, progress)
        line = f"container master not used: {why}; running the Jacobi master instead"
        system.warnings.append(line)
        print(f"railfmu: warning: {line}", file=sys.stderr)
        result = _run_python(system, "jacobi", sinks, progress)
        result.notes.insert(0, line)
        return result
    return _run_python(system, master, sinks, progress)
