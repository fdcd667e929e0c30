"""Load one co-simulation FMU through FMPy with its log messages captured.

The FMU reports what went wrong (a bad parameter, an illegal call) through the logger
callback; :class:`Slave` keeps those messages so the importer can raise an error that says
why, instead of FMPy's bare "fmi2ExitInitializationMode failed with status 3".

One interface for FMI 1.0, 2.0 and 3.0 Co-Simulation FMUs (FMPy's FMU1Slave, FMU2Slave,
FMU3Slave): the masters call set/get by variable name, enter/exit initialisation and
do_step the same way for each. FMI 3 variables are seen under the FMI 2 type names
(:func:`fmi2_types`: Float64 as Real, Int32 as Integer), so the system, the SSP reader and
the masters need no second set of type names; FMI 3 types with no FMI 2 counterpart
(Float32, Int8, ...) keep their names and are refused where a connection or a recorded
signal needs a Real, Integer or Boolean.
"""

from __future__ import annotations

import atexit
import shutil
from enum import IntEnum
from pathlib import Path

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import (FMICallException, FMU1Slave, fmi1CallbackAllocateMemoryTYPE,
                       fmi1CallbackFreeMemoryTYPE, fmi1CallbackFunctions, fmi1CallbackLoggerTYPE)
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.fmi3 import FMU3Slave

from railfmu.models.errors import UserError



class Status(IntEnum):
    """fmi2Status (FMI 2.0, section 2.1.3; FMI 1.0 and 3.0 number them alike); ``str()``
    gives the FMI 2 name, :meth:`name_of` the name in a given FMI version."""
    OK = 0
    WARNING = 1
    DISCARD = 2
    ERROR = 3
    FATAL = 4
    PENDING = 5

    def __str__(self) -> str:
        return "fmi2" + ("OK" if self is Status.OK else self.name.capitalize())

    @classmethod
    def name_of(cls, status: int, version: int = 2) -> str:
        """``fmi2Discard`` etc. (``fmi3Discard``, FMI 1.0 ``fmiDiscard`` for ``version``); an
        integer outside the enum as ``status <n>``."""
        try:
            name = str(cls(status))
        except ValueError:
            return f"status {status}"
        return name.replace("fmi2", {1: "fmi", 2: "fmi2", 3: "fmi3"}.get(version, "fmi2"), 1)


FMI2_TERMINATED = 3  # fmi2StatusKind fmi2Terminated, for fmi2GetBooleanStatus
FMI_VERSIONS = {"1.0": 1, "2.0": 2, "3.0": 3}
# FMI 3 types under the FMI 2 name the rest of railfmu uses; the FMI 3 name back
_FMI2_NAME = {"Float64": "Real", "Int32": "Integer"}
FMI3_NAME = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String",
             "Enumeration": "Int64"}  # FMI 3.0 carries an Enumeration as an Int64


def fmi_version(md) -> int | None:
    """1, 2 or 3 for a model description of that FMI version, else None."""
    return FMI_VERSIONS.get(str(md.fmiVersion)) or FMI_VERSIONS.get(str(md.fmiVersion)[:3])


def fmi2_types(md):
    """``md`` (FMPy's model description) with the FMI 3 types Float64 and Int32 named Real
    and Integer (in place, idempotent; FMI 1 and 2 unchanged). Boolean and String keep
    their names; FMI 3's other types too."""
    if fmi_version(md) == 3:
        for v in md.modelVariables:
            v.type = _FMI2_NAME.get(v.type, v.type)
    return md


class FMUError(UserError):
    """An FMI call failed; the message carries what the FMU logged."""


# (FMU path, mtime, size) -> its unzipped folder, once per process: a Monte Carlo worker
# instantiates the same FMUs for every member, and unzipping and removing them cost a fifth
# of a 20-minute train run (measured). Instances share the folder (FMI 2.0 lets one
# unzipped FMU serve several instances; ours keep no state outside their instance); it is
# removed when the process exits.
_UNZIPPED: dict[tuple[str, int, int], str] = {}


def _unzipped(fmu: Path) -> str:
    st = fmu.stat()
    key = (str(fmu.resolve()), st.st_mtime_ns, st.st_size)
    folder = _UNZIPPED.get(key)
    if folder is None or not Path(folder).is_dir():
        if not _UNZIPPED:
            atexit.register(lambda: [shutil.rmtree(d, ignore_errors=True) for d in _UNZIPPED.values()])
        folder = _UNZIPPED[key] = extract(str(fmu))
    return folder


def _load_failure(exc: Exception) -> str:
    """What FMPy's loader raised, as one line naming the FMI function when one is missing."""
    import re

    text = " ".join(str(exc).split())
    m = re.search(r"undefined symbol: (\w+)", text)
    if m:
        return (f"its binary does not export the FMI function {m.group(1)} (a source FMU compiled with "
                "prefixed function names, or an incomplete FMI implementation)")
    return f"cannot load its binary: {text}"


class Slave:
    """An instantiated FMI 1.0, 2.0 or 3.0 co-simulation FMU (``version``); ``messages``
    holds (status, category, text)."""

    version = 2  # a subclass that loads its own FMI 2 FMU (the container) needs no more
    terminate_requested = False

    def __init__(self, fmu: Path | str, instance_name: str = "instance", logging_on: bool = False,
                 md=None):
        """``md``: the FMU's model description when the caller has read it already
        (:attr:`railfmu.fmus.cosim.system.Component.md`)."""
        fmu = Path(fmu)
        if not fmu.is_file():
            raise UserError(f"{fmu}: FMU not found (run `railfmu build`)")
        self.path = fmu
        self.name = instance_name
        self.md = fmi2_types(md if md is not None else read_model_description(str(fmu)))
        self.version = fmi_version(self.md)
        if self.version is None or self.md.coSimulation is None:
            raise UserError(f"{fmu.name}: not an FMI 1.0, 2.0 or 3.0 Co-Simulation FMU "
                            f"(fmiVersion {self.md.fmiVersion})")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.dir = _unzipped(fmu)
        self._shared_dir = self.dir  # not removed by close (_UNZIPPED)
        self.messages: list[tuple[str, str, str]] = []
        self._start_stop = (0.0, None)  # FMI 1.0: the experiment goes to fmiInitializeSlave
        self.terminate_requested = False  # FMI 3.0: the last fmi3DoStep's terminateSimulation
        kind = {1: FMU1Slave, 2: FMU2Slave, 3: FMU3Slave}[self.version]
        try:
            self.fmu = kind(guid=self.md.guid, unzipDirectory=self.dir,
                            modelIdentifier=self.md.coSimulation.modelIdentifier,
                            instanceName=instance_name)
        except (AttributeError, OSError) as exc:  # a binary that lacks an FMI function, or will not load
            raise FMUError(f"{fmu.name} ({instance_name}): {_load_failure(exc)}") from None
        self._callbacks = self._make_callbacks()
        try:
            if self.version == 1:
                self.fmu.instantiate(functions=self._callbacks, loggingOn=logging_on)
            elif self.version == 2:
                self.fmu.instantiate(callbacks=self._callbacks, loggingOn=logging_on)
            else:
                self.fmu.instantiate(loggingOn=logging_on, logMessage=self._keep3)
        except FMICallException as exc:
            raise self.failure(self.fmi("Instantiate"), exc) from None
        except Exception as exc:  # noqa: BLE001 - FMPy 3: "Failed to instantiate FMU"
            if self.fmu.component:
                raise
        if not self.fmu.component:
            raise self.failure(self.fmi("Instantiate"), "the FMU returned no instance")

    def fmi(self, function: str) -> str:
        """The standard's name of ``function`` in this FMU's version: ``DoStep`` ->
        ``fmiDoStep``, ``fmi2DoStep``, ``fmi3DoStep``."""
        return {1: "fmi", 2: "fmi2", 3: "fmi3"}[self.version] + function

    def _make_callbacks(self):
        def log(_env, _name, status, category, message):
            self.messages.append((Status.name_of(status).removeprefix("fmi2"),
                                  (category or b"").decode(errors="replace"),
                                  (message or b"").decode(errors="replace").replace("%%", "%")))

        def log3(_env, status, category, message):  # FMI 3: no instance name, no format
            self.messages.append((Status.name_of(status).removeprefix("fmi2"),
                                  (category or b"").decode(errors="replace"),
                                  (message or b"").decode(errors="replace")))

        self._keep3 = log3
        if self.version == 1:
            cb1 = fmi1CallbackFunctions()
            cb1.logger = fmi1CallbackLoggerTYPE(log)
            cb1.allocateMemory = fmi1CallbackAllocateMemoryTYPE(calloc)
            cb1.freeMemory = fmi1CallbackFreeMemoryTYPE(free)
            self._keep = log
            return cb1

        # our FMUs pass finished text ('%' doubled, no varargs), so no formatting proxy is needed
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._keep = log  # the C side holds a pointer: keep the Python function alive
        return cb

    # -- calls that turn a failed status into an error with the FMU's own words --------------
    def failure(self, what: str, fallback, since: int = 0) -> FMUError:
        """``X.fmu (name): what failed: <the errors the FMU logged since message ``since``>``
        (``fallback`` when it logged none): the one wording of every FMU call error."""
        logged = "; ".join(m for s, _, m in self.messages[since:] if s in ("Error", "Fatal"))
        return FMUError(f"{self.path.name} ({self.name}): {what} failed: {logged or fallback}")

    def status_failure(self, what: str, status: int, since: int = 0) -> FMUError:
        """A call that returned ``status`` (worse than fmi2Warning), named as the standard names it."""
        return self.failure(what, f"{Status.name_of(status, self.version)} (the FMU logged no reason)", since)

    def terminated(self) -> bool:
        """fmi2GetBooleanStatus(fmi2Terminated): after a fmi2Discard from fmi2DoStep, whether the
        FMU ended the simulation (False if it cannot tell). FMI 3.0: the terminateSimulation
        of the last fmi3DoStep; FMI 1.0 has no such status: False."""
        import ctypes

        if self.version != 2:
            return self.terminate_requested

        value = ctypes.c_int(0)
        try:
            fn = self.fmu.dll["fmi2GetBooleanStatus"]
            fn.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
            fn.restype = ctypes.c_int
            status = fn(ctypes.c_void_p(self.fmu.component), FMI2_TERMINATED, ctypes.byref(value))
        except (AttributeError, OSError):
            return False
        return status <= Status.WARNING and value.value != 0

    def call(self, what: str, fn, *args):
        n = len(self.messages)
        try:
            return fn(*args)
        except FMICallException as exc:
            raise self.failure(what, exc, since=n) from None

    def var(self, name: str):
        try:
            return self.vars[name]
        except KeyError:
            raise UserError(f"{self.path.name} ({self.name}): no variable {name!r}") from None

    def set(self, name: str, value) -> None:
        v = self.var(name)
        f = self.fmu
        if self.version == 3 and v.type in FMI3_NAME:
            setter, conv = {"Real": (f.setFloat64, float), "Integer": (f.setInt32, int),
                            "Enumeration": (f.setInt64, int),
                            "Boolean": (f.setBoolean, bool), "String": (f.setString, str)}[v.type]
        else:
            setter, conv = {"Real": (f.setReal, float), "Integer": (f.setInteger, int),
                            "Enumeration": (f.setInteger, int),  # FMI 1.0/2.0 set an Enumeration as an Integer
                            "Boolean": (f.setBoolean, bool), "String": (f.setString, str)}[v.type]
        try:
            if conv is bool and isinstance(value, str):  # bool("false") is True
                if value.strip().lower() not in ("true", "false", "1", "0"):
                    raise ValueError(value)
                typed = value.strip().lower() in ("true", "1")
            else:
                typed = conv(value)
        except (TypeError, ValueError, OverflowError):
            raise UserError(f"{self.path.name} ({self.name}): {name} = {value!r} is not a valid {v.type} value") from None
        self.call(f"setting {name}", setter, [v.valueReference], [typed])

    def get(self, name: str):
        v = self.var(name)
        f = self.fmu
        if self.version == 3 and v.type in FMI3_NAME:
            getter = {"Real": f.getFloat64, "Integer": f.getInt32, "Enumeration": f.getInt64,
                      "Boolean": f.getBoolean, "String": f.getString}[v.type]
        else:
            getter = {"Real": f.getReal, "Integer": f.getInteger, "Enumeration": f.getInteger,
                      "Boolean": f.getBoolean, "String": f.getString}[v.type]
        return self.call(f"reading {name}", getter, [v.valueReference])[0]

    def enter_initialization(self, start_time: float = 0.0, stop_time: float | None = None) -> None:
        """Parameters and start values may be set from here on. FMI 1.0 has no
        initialisation mode (values are set before fmiInitializeSlave, at the exit)."""
        if self.version == 1:
            self._start_stop = (start_time, stop_time)
        elif self.version == 2:
            self.call("fmi2SetupExperiment", self.fmu.setupExperiment, None, start_time, stop_time)
            self.call("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)
        else:
            self.call("fmi3EnterInitializationMode", self.fmu.enterInitializationMode, None,
                      start_time, stop_time)

    def exit_initialization(self) -> None:
        if self.version == 1:
            self.call("fmiInitializeSlave", self.fmu.initialize, *self._start_stop)
        else:
            self.call(self.fmi("ExitInitializationMode"), self.fmu.exitInitializationMode)

    def initialize(self, start_time: float = 0.0, stop_time: float | None = None,
                   parameters: dict | None = None) -> None:
        """Setup, set parameters (name -> value), end initialisation."""
        self.enter_initialization(start_time, stop_time)
        for k, v in (parameters or {}).items():
            self.set(k, v)
        self.exit_initialization()

    def do_step(self, t: float, h: float) -> None:
        result = self.call(f"{self.fmi('DoStep')} at t = {t:.9g} s", self.fmu.doStep, t, h)
        if self.version == 3:
            self.terminate_requested = bool(result[1])

    def close(self) -> None:
        try:
            if self.fmu.component is not None:
                self.fmu.terminate()
                self.fmu.freeInstance()
        except Exception:
            pass
        finally:
            if self.dir is not None and self.dir != getattr(self, "_shared_dir", None):
                shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

