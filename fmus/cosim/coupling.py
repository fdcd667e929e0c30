"""What every master is built of: the run's result, the progress line, the FMUs' raw entry
points (:class:`_Fmu`), the connections grouped into get/set calls (:class:`_Link`), the
sampler and the row buffer. :mod:`railfmu.fmus.cosim.masters` (the Python masters and the
dispatch) and :mod:`railfmu.fmus.cosim.native_loop` (the container master's C loop) both
build on them; semantics are documented in :mod:`railfmu.fmus.cosim.masters`."""

from __future__ import annotations

import ctypes
import math
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from railfmu.models.errors import UserError
from railfmu.fmus.cosim.slave import Slave, Status
from railfmu.fmus.cosim.system import Connection, System, carried_type

BLOCK_ROWS = 1000  # container master: rows per C call / per write_block
HAND_OVER_ROWS = 500  # Python masters: rows checked (finite) and handed to the sinks at once (observers are passive); 1 if a sink sets every_step

_c_uint_p = ctypes.POINTER(ctypes.c_uint)
_c_double_p = ctypes.POINTER(ctypes.c_double)


@dataclass
class RunResult:
    columns: list[str]  # "time", then "component.variable" recorded
    data: np.ndarray  # (n_samples, len(columns)); the rows sampled (all of them when complete)
    complete: bool  # ended normally: at stop_time, or earlier when an FMU ended it (early_end)
    wall_time_s: float
    master: str
    notes: list[str] = field(default_factory=list)
    end_time: float | None = None  # the last row's time
    early_end: str | None = None  # "X.fmu (name) ended the simulation at t = ... s (...)"
    step_size: float | None = None
    step_size_from: str | None = None  # where the step size came from (System.step_size_from)


def fmu_stop_time(stop: float, h: float) -> float:
    """The stop time the FMUs are told (fmi2SetupExperiment): the run's, plus a millionth of a
    step. The last step starts at start + (n-1) h, and start + (n-1) h + h can exceed the stop
    time by an ulp; an FMU that checks its steps against its stop time (OpenModelica's) then
    refuses the last step with fmi2Error, where OMSimulator's run reaches the end."""
    return stop + 1e-6 * h


class _Terminated(Exception):
    """fmi2DoStep from ``t`` returned fmi2Discard and the FMU says it terminated."""

    def __init__(self, slave: Slave, t: float):
        how = ("fmi3DoStep returned terminateSimulation = true" if slave.version == 3 else
               "fmi2DoStep returned fmi2Discard, fmi2Terminated = true")
        super().__init__(f"{slave.path.name} ({slave.name}) ended the simulation at t = {t:.9g} s ({how})")
        self.t = t


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


_C_TYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int}  # fmi2Boolean is int
# the C type of a Boolean per FMI version: fmiBoolean is char, fmi2Boolean int, fmi3Boolean bool
_C_BOOLEAN = {1: ctypes.c_ubyte, 2: ctypes.c_int, 3: ctypes.c_bool}


class _Fmu:
    """Raw ctypes entry points of one instantiated Slave (FMPy's own function objects keep
    their argtypes; these are fresh ones with cheap argument conversion). ``get``/``set``
    take (instance, vrs, n, values) for every FMI version (FMI 3's nValues = n added);
    ``ctype`` is the C type of a value of each kind; :meth:`step` steps with the FMI 2.0
    semantics of the module docstring."""

    def __init__(self, slave: Slave):
        self.slave = slave
        self.version = slave.version
        dll = slave.fmu.dll
        self.c = ctypes.c_void_p(slave.fmu.component)
        self.ctype = {**_C_TYPES, "Boolean": _C_BOOLEAN[self.version]}

        def bind(name, *argtypes):
            fn = dll[name]
            fn.argtypes = [ctypes.c_void_p, *argtypes]
            fn.restype = ctypes.c_int
            return fn

        array = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
        if self.version == 3:
            def with_n(fn):  # fmi3Get/Set*(instance, vrs, nvr, values, nValues): scalars, nValues = nvr
                return lambda c, vrs, n, values: fn(c, vrs, n, values, n)

            names = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
            self.get = {t: with_n(bind(f"fmi3Get{names[t]}", *array, ctypes.c_size_t)) for t in _C_TYPES}
            self.set = {t: with_n(bind(f"fmi3Set{names[t]}", *array, ctypes.c_size_t)) for t in _C_TYPES}
            # FMI 3.0 carries an Enumeration as an Int64 (FMI 1.0 and 2.0 as an Integer)
            self.get["Enumeration"] = with_n(bind("fmi3GetInt64", *array, ctypes.c_size_t))
            self.set["Enumeration"] = with_n(bind("fmi3SetInt64", *array, ctypes.c_size_t))
            self.ctype["Enumeration"] = ctypes.c_int64
            self._do_step3 = bind("fmi3DoStep", ctypes.c_double, ctypes.c_double, ctypes.c_bool,
                                  *[ctypes.c_void_p] * 4)
            self._flags = [ctypes.c_bool() for _ in range(3)]
            self._last_time = ctypes.c_double()
            self._out_args = [ctypes.addressof(a) for a in (*self._flags, self._last_time)]
        else:
            prefix = "fmi2" if self.version == 2 else f"{slave.md.coSimulation.modelIdentifier}_fmi"
            self.get = {t: bind(f"{prefix}Get{t}", *array) for t in _C_TYPES}
            self.set = {t: bind(f"{prefix}Set{t}", *array) for t in _C_TYPES}
            self.do_step = bind(f"{prefix}DoStep", ctypes.c_double, ctypes.c_double, self.ctype["Boolean"])
        self.get_real = self.get["Real"]

    def fail(self, what: str, status: int):
        return self.slave.status_failure(what, status)

    def step(self, t: float, h: float) -> None:
        """fmi2DoStep from ``t`` with FMI 2.0 semantics: _Terminated or an error naming the status."""
        if self.version == 3:
            s = self._do_step3(self.c, t, h, True, *self._out_args)
            if s <= Status.DISCARD and self._flags[1].value:  # terminateSimulation
                self.slave.terminate_requested = True
                raise _Terminated(self.slave, t)
        else:
            s = self.do_step(self.c, t, h, 1)
        if s > Status.WARNING:
            if s == Status.DISCARD and self.version == 2 and self.slave.terminated():
                raise _Terminated(self.slave, t)
            raise self.fail(f"{self.slave.fmi('DoStep')} at t = {t:.9g} s", s)


class _Link:
    """Consecutive connections of one type between one pair of components: one fmi2Get*, one
    fmi2Set* (an affine map applied in Python, only where it is not the identity: Real only)."""

    def __init__(self, conns: list[Connection], src: _Fmu, dst: _Fmu, src_vrs: list[int], dst_vrs: list[int],
                 kind: str = "Real"):
        self.conns, self.src, self.dst = conns, src, dst
        n = len(conns)
        self.n = n
        self.get, self.set = src.get[kind], dst.set[kind]
        self.src_vrs = (ctypes.c_uint * n)(*src_vrs)
        self.dst_vrs = (ctypes.c_uint * n)(*dst_vrs)
        self.src_buf = (src.ctype[kind] * n)()
        self.maps = [(i, c.factor, c.offset) for i, c in enumerate(conns) if not c.identity]
        # a second buffer for an affine map, or a Boolean between FMI versions (int <-> bool)
        self.convert = bool(self.maps) or src.ctype[kind] is not dst.ctype[kind]
        self.dst_buf = (dst.ctype[kind] * n)() if self.convert else self.src_buf
        self.what = f"{kind} of {', '.join(str(c) for c in conns)}"

    def transfer(self, t: float) -> None:
        self.fetch(t)
        self.put(t)

    def fetch(self, t: float) -> None:
        """Read the sources' values (:meth:`put` sets them on the destinations)."""
        s = self.get(self.src.c, self.src_vrs, self.n, self.src_buf)
        if s > Status.WARNING:
            raise self.src.fail(f"fmi2Get{self.what} at t = {t:.9g} s", s)

    def put(self, t: float) -> None:
        if self.convert:
            src, dst = self.src_buf, self.dst_buf
            for i in range(self.n):
                dst[i] = src[i]
            for i, factor, offset in self.maps:
                dst[i] = factor * src[i] + offset
        s = self.set(self.dst.c, self.dst_vrs, self.n, self.dst_buf)
        if s > Status.WARNING:
            raise self.dst.fail(f"fmi2Set{self.what} at t = {t:.9g} s", s)


def _links(conns: list[Connection], fmus: dict[str, _Fmu]) -> list[_Link]:
    """Connections grouped into links (types checked by :func:`check_system`)."""
    def kind(c: Connection) -> str:
        src, dst = fmus[c.src], fmus[c.dst]
        t = src.slave.var(c.src_var).type
        if t == "Enumeration" and src.version == dst.version == 3 and dst.slave.var(c.dst_var).type == t:
            return t  # fmi3GetInt64 -> fmi3SetInt64
        return carried_type(t)

    groups: list[list[Connection]] = []
    for c in conns:
        g = groups[-1] if groups else None
        if g and c.src != c.dst and (g[0].src, g[0].dst, kind(g[0])) == (c.src, c.dst, kind(c)):
            g.append(c)
        else:
            groups.append([c])
    out = []
    for g in groups:
        src, dst = fmus[g[0].src], fmus[g[0].dst]
        out.append(_Link(g, src, dst, [src.slave.var(c.src_var).valueReference for c in g],
                         [dst.slave.var(c.dst_var).valueReference for c in g], kind(g[0])))
    return out


def signal_runs(system: System, record: list[str], fmus: dict[str, _Fmu]) -> list[tuple[_Fmu, str, list[int], list[int]]]:
    """The recorded signals as runs of consecutive columns (from 1) of one FMU and carried type,
    one get each: ``(fmu, type, value references, columns)``."""
    runs: list[tuple[_Fmu, str, list[int], list[int]]] = []
    for col, signal in enumerate(record, start=1):
        comp, v = system.signal(signal, "recorded signal")
        fmu = fmus[comp.name]
        t = "Enumeration" if fmu.version == 3 and v.type == "Enumeration" else carried_type(v.type)
        if runs and runs[-1][0] is fmu and runs[-1][1] == t and runs[-1][3][-1] == col - 1:
            runs[-1][2].append(v.valueReference)
            runs[-1][3].append(col)
        else:
            runs.append((fmu, t, [v.valueReference], [col]))
    return runs


class _Sampler:
    """Reads the recorded signals into row k of ``data``: one fmi2Get* per run of consecutive
    columns of the same FMU and type; Real values written straight into the array."""

    def __init__(self, record: list[str], fmus: dict[str, _Fmu], data: np.ndarray, system: System):
        self.data = data
        self.row_bytes = data.strides[0]
        self.base = data.ctypes.data
        runs = signal_runs(system, record, fmus)
        self.runs = [(f, f.get[t], (ctypes.c_uint * len(vrs))(*vrs), len(vrs), cols[0] * 8,
                      None if t == "Real" else ((f.ctype[t] * len(vrs))(), slice(cols[0], cols[-1] + 1),
                                                t == "Boolean"))
                     for f, t, vrs, cols in runs]
        self.count = 0  # rows sampled

    def sample(self, k: int, t: float) -> None:
        addr = self.base + k * self.row_bytes
        for f, get, vrs, n, off, ints in self.runs:
            if ints is None:
                s = get(f.c, vrs, n, addr + off)
            else:
                buf, cols, boolean = ints
                s = get(f.c, vrs, n, buf)
                self.data[k, cols] = np.not_equal(buf, 0) if boolean else buf  # fmi2True may be any non-zero
            if s > Status.WARNING:
                raise f.fail(f"reading the recorded signals at t = {t:.9g} s", s)
        self.data[k, 0] = t
        self.count = k + 1


def _physical_memory() -> int | None:
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _row_buffer(n: int, columns: list[str]) -> np.ndarray:
    """The (n + 1) x columns rows of a run, or a one-line error when they cannot fit in
    this machine's memory (numpy would raise, or the kernel kill the run half-way)."""
    need, have = (n + 1) * len(columns) * 8, _physical_memory()
    if have is not None and need > have:
        raise UserError(f"{n:,} steps x {len(columns)} recorded signals need {need / 2**30:,.1f} GiB, more "
                        f"than this machine's {have / 2**30:,.1f} GiB of memory: shorten the stop time, "
                        "lengthen the step or record fewer signals")
    try:
        return np.empty((n + 1, len(columns)))
    except (MemoryError, ValueError):
        raise UserError(f"{n:,} steps x {len(columns)} recorded signals ({need / 2**30:,.1f} GiB) do not fit "
                        "in memory: shorten the stop time, lengthen the step or record fewer signals") from None
