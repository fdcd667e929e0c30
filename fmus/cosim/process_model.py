r"""An FMU as the process model of a sigma-point filter: the FMU state saved once per filter
step and restored for every sigma point.

A UKF propagates ``2n + 1`` sigma points ``X_i`` of its state through the process model
``f`` over one filter step ``[t, t + dt]`` (known input ``u`` held)::

    Y_i = f(X_i, u, t, dt)

With an FMU as ``f`` every sigma point must start from the same FMU at time ``t``. One
extra instance of the FMU (the parameters of a system component) does it, with the FMU
state of FMI 2.0 (section 2.1.8, ``canGetAndSetFMUstate``)::

    set the known inputs u;  S = fmi2GetFMUstate            snapshot at t (its memory reused)
    for each sigma point i:
        fmi2SetFMUstate(S)                                  (not before the first: it is there)
        set the state inputs from X_i; fmi2DoStep(t, dt)    (noSetFMUStatePriorToCurrentPoint
        Y_i = the state outputs, X_i's held columns          = false: we go back)

The last sigma point leaves the instance at ``t + dt``, where the next filter step takes its
snapshot, so the instance follows the filter's clock; a second call at ``t`` (a filter that
evaluates its process again, e.g. to find an input) restores the snapshot first; a call at
any other time (a restarted filter) resets the instance and initialises it there. The FMU
takes a sigma point's state through inputs (``TrainLongitudinal``: ``s_set``, ``v_set`` with
``set_state`` true): FMI 2.0 lets an importer set a state only before initialisation ends.
Columns of the filter state that the FMU takes as inputs but does not change (a Davis
coefficient) are held: ``Y = X``.

Cost (``benchmarks/process_model.py``, TrainLongitudinal, dt = 10 s: 200 RK4 sub-steps):
about 75 µs per sigma point, 0.85 ms per filter step of 11 points. The FMU's step is most of
it (~45 µs); fmi2SetFMUstate ~10 µs, as the runtime rebuilds the model data on a restore (the
line profile is read again); the ctypes calls and the loop a few µs.
"""

from __future__ import annotations

import ctypes
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2False, fmi2FMUstate, fmi2Real, fmi2ValueReference

from railfmu.models.errors import UserError
from railfmu.fmus.cosim.slave import Slave

# a filter time this close to the instance's (in steps dt) is the same communication point
_SAME_TIME = 1e-6


class ProcessModelError(UserError):
    """The FMU cannot serve as a process model, or a process-model call failed."""


class FmuProcessModel:
    """``Y = model(X, u, t, dt)``: sigma points ``X`` ``(m, n)`` through one step of an FMU.

    ``columns``: one ``(input, output)`` pair per column of ``X``; the FMU takes column ``j``
    as its Real input ``input``, and ``Y[:, j]`` is its output ``output`` after the step, or
    ``X[:, j]`` where ``output`` is None (a held column: a parameter the filter estimates).
    ``known``: the FMU's Real inputs that take ``u`` (held over the step, the same for every
    sigma point). ``fixed``: inputs set once at initialisation (``{"set_state": True}``).
    ``parameters``: the FMU's parameters (a system component's). The instance is created
    here; :meth:`close` frees it (and a later call creates it again).

    Counters: :attr:`steps` calls (one per filter prediction, more where a filter evaluates
    its process again), :attr:`points` sigma points, :attr:`seconds` spent in calls.
    """

    def __init__(self, fmu: Path | str, columns: Sequence[tuple[str, str | None]], known: Sequence[str] = (),
                 fixed: Mapping[str, float | int | bool] | None = None,
                 parameters: Mapping[str, float | int | bool | str] | None = None,
                 name: str = "process_model", md=None) -> None:
        self.fmu_path = Path(fmu)
        self.columns = [(str(i), None if o is None else str(o)) for i, o in columns]
        self.known = [str(k) for k in known]
        self.fixed = dict(fixed or {})
        self.parameters = dict(parameters or {})
        self.name = name
        self._md = md
        self.slave: Slave | None = None
        self.steps = self.points = 0
        self.seconds = 0.0
        self._open()

    # -- instance --------------------------------------------------------------------------
    def _error(self, what: str) -> ProcessModelError:
        return ProcessModelError(f"{self.fmu_path.name} ({self.name}) as a process model: {what}")

    def _open(self) -> None:
        slave = Slave(self.fmu_path, self.name, md=self._md)
        try:
            self._check(slave)
        except Exception:
            slave.close()
            raise
        self.slave = slave
        self._md = slave.md
        self._initialised = False
        self._time: float | None = None  # the instance's time; None: (re)initialise at the next call
        self._snap_time: float | None = None  # the time of the snapshot; None: none valid
        self._snapshot = fmi2FMUstate()  # NULL: fmi2GetFMUstate allocates it the first time
        f = slave.fmu
        # the calls of the inner loop, on ctypes arrays made once
        self._c = f.component
        n = len(self.columns)
        self._vr_in = (fmi2ValueReference * n)(*(slave.vars[i].valueReference for i, _ in self.columns))
        self._in = (fmi2Real * n)()
        self._out_cols = [j for j, (_, o) in enumerate(self.columns) if o is not None]
        self._held_cols = [j for j, (_, o) in enumerate(self.columns) if o is None]
        m = len(self._out_cols)
        self._vr_out = (fmi2ValueReference * m)(*(slave.vars[self.columns[j][1]].valueReference
                                                  for j in self._out_cols))
        self._out = (fmi2Real * m)()
        self._vr_known = (fmi2ValueReference * len(self.known))(*(slave.vars[k].valueReference for k in self.known))
        self._known = (fmi2Real * len(self.known))()

    def _check(self, slave: Slave) -> None:
        md = slave.md
        if not md.coSimulation.canGetAndSetFMUstate:
            raise self._error("it cannot save and restore its state (canGetAndSetFMUstate is not true in its "
                              "modelDescription.xml)")
        for name, kind in ([(i, "input") for i, _ in self.columns] + [(k, "input") for k in self.known]
                           + [(o, "output") for _, o in self.columns if o is not None]
                           + [(k, "input") for k in self.fixed]):
            v = slave.vars.get(name)
            if v is None:
                raise self._error(f"no variable {name!r}")
            if v.causality != kind:
                raise self._error(f"{name} is a(n) {v.causality}, expected an {kind}")
            if v.type != "Real" and name not in self.fixed:
                raise self._error(f"{name} is {v.type}, expected Real")
        for name in self.parameters:
            if name not in slave.vars:
                raise self._error(f"no parameter {name!r}")

    def _start(self, t: float) -> None:
        """(Re)initialise the instance at ``t`` with the parameters and the fixed inputs."""
        s = self.slave
        if self._initialised:  # a filter restarted elsewhere, or a failed step: start again
            self._free_snapshot()
            self._snap_time = None
            s.call(s.fmi("Reset"), s.fmu.reset)
            self._initialised = False
        s.enter_initialization(t)
        for k, v in {**self.parameters, **self.fixed}.items():
            s.set(k, v)
        s.exit_initialization()
        self._initialised = True
        self._time = t

    def _free_snapshot(self) -> None:
        if self._snapshot:
            free_state = self.slave.fmu.freeFMUState if self.slave.version == 3 else self.slave.fmu.freeFMUstate
            self.slave.call(self.slave.fmi("FreeFMUstate"), free_state, self._snapshot)
            self._snapshot = fmi2FMUstate()

    def value(self, name: str):
        """A parameter of the instance: the value given, else the FMU's start value (as text)."""
        if name in self.parameters:
            return self.parameters[name]
        v = self.slave.vars.get(name) if self.slave is not None else None
        if v is None:
            raise self._error(f"no parameter {name!r}")
        return v.start

    def resource(self, path: str) -> Path:
        """A file named by a String parameter, resolved as the FMU resolves it: an absolute path
        as it is, a relative one in the FMU's ``resources/``."""
        p = Path(path)
        return p if p.is_absolute() else Path(self.slave.dir) / "resources" / p

    # -- the process model -----------------------------------------------------------------
    def __call__(self, X: np.ndarray, u: float | Sequence[float] | np.ndarray = (), t: float = 0.0,
                 dt: float = 1.0) -> np.ndarray:
        """The sigma points ``X`` ``(m, len(columns))`` at ``t`` -> their successors at ``t + dt``."""
        t0 = time.perf_counter()
        if self.slave is None:
            self._open()
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != len(self.columns):
            raise ValueError(f"{self.name}: sigma points of shape {X.shape}, expected (m, {len(self.columns)})")
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if u.shape != (len(self.known),):
            raise ValueError(f"{self.name}: known input of shape {u.shape}, expected ({len(self.known)},)")
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"{self.name}: dt = {dt!r} must be a positive number of seconds")
        if self._time is not None and abs(t - self._time) <= _SAME_TIME * dt:
            restore = False  # the instance is at t (the previous call ended there)
        elif self._snap_time is not None and abs(t - self._snap_time) <= _SAME_TIME * dt:
            restore = True  # once more from the snapshot's time (e.g. an effort found by iteration)
        else:
            self._start(float(t))
            restore = False
        t_fmu = self._snap_time if restore else self._time
        s, f, c = self.slave, self.slave.fmu, self._c
        if s.version == 3:  # the same calls in FMI 3.0 (FMPy's wrappers check the status alike)
            set_state, get_state = f.fmi3SetFMUState, f.fmi3GetFMUState
            flags, reached = [ctypes.c_bool() for _ in range(3)], ctypes.c_double()
            outs3 = [ctypes.byref(a) for a in (*flags, reached)]

            def set_real(c, vr, n, v):
                return f.fmi3SetFloat64(c, vr, n, v, n)

            def get_real(c, vr, n, v):
                return f.fmi3GetFloat64(c, vr, n, v, n)

            def do_step(c, t, h, no_set):
                return f.fmi3DoStep(c, t, h, bool(no_set), *outs3)
        else:
            set_state, set_real, get_real, do_step = f.fmi2SetFMUstate, f.fmi2SetReal, f.fmi2GetReal, f.fmi2DoStep
            get_state = f.fmi2GetFMUstate
        vin, vr_in, vout, vr_out, n_in, n_out = self._in, self._vr_in, self._out, self._vr_out, X.shape[1], len(self._out)
        n_msg = len(s.messages)
        what, snapshot_at_t, i = "fmi2SetFMUstate", restore, -1
        outs = []
        try:
            if restore:
                set_state(c, self._snapshot)
            what = "setting the known inputs"
            if self.known:
                self._known[:] = u.tolist()
                set_real(c, self._vr_known, len(self.known), self._known)
            what, snapshot_at_t = "fmi2GetFMUstate", False
            get_state(c, ctypes.byref(self._snapshot))  # overwrites the previous snapshot
            snapshot_at_t = True
            what = "a sigma point"
            for i, row in enumerate(X.tolist()):
                if i:
                    set_state(c, self._snapshot)
                vin[:] = row
                set_real(c, vr_in, n_in, vin)
                do_step(c, t_fmu, dt, fmi2False)
                get_real(c, vr_out, n_out, vout)
                outs.append(vout[:])
        except FMICallException as exc:
            self._time = None  # the next call restores the snapshot at t_fmu, or starts again
            self._snap_time = t_fmu if snapshot_at_t else None
            if i >= 0:
                what = f"sigma point {i} {X[i].tolist()}: {exc.function} (step from t = {t_fmu:.9g} s, dt = {dt:g} s)"
            raise s.failure(what, exc, since=n_msg) from None
        Y = np.empty_like(X)
        Y[:, self._held_cols] = X[:, self._held_cols]
        Y[:, self._out_cols] = outs
        self._time, self._snap_time = t_fmu + dt, t_fmu
        self.steps += 1
        self.points += X.shape[0]
        self.seconds += time.perf_counter() - t0
        return Y

    def close(self) -> None:
        """Free the snapshot and the instance (idempotent)."""
        if self.slave is not None:
            try:
                self._free_snapshot()
            except UserError:
                pass
            self.slave.close()
            self.slave = None

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
