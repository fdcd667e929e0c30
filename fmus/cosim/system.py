"""A co-simulation system ready to run: what the SSP reader produces and the masters consume.

Everything here is resolved: FMU files exist, each component carries its FMU's model
description (read once, :func:`read_model`; the masters, the container and the writer take
the variables from there), parameter values are final (FMU defaults < SSD bindings < variant
.ssv < command line), each connection carries one affine map ``dst = factor * src + offset``
(the SSD's LinearTransformation composed with any unit conversion; Real only), and the
experiment's time grid is fixed. :func:`check_system` is the one set of checks every master,
``railfmu validate`` and the writer apply to it.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import sys
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from railfmu.models.errors import UserError

Value = float | int | bool | str
SIGNAL_TYPES = ("Real", "Integer", "Boolean", "Enumeration")  # what a connection carries and signals.csv records


def carried_type(fmi_type: str) -> str:
    """The FMI 2.0 accessor type of a variable: an Enumeration is read and set as an Integer
    (fmi2GetInteger, fmi2SetInteger)."""
    return "Integer" if fmi_type == "Enumeration" else fmi_type
RESERVED_SETTINGS = ("enabled",)  # observer settings the platform reads, not the estimator class


@dataclass
class Component:
    name: str
    fmu: Path
    parameters: dict[str, Value] = field(default_factory=dict)  # FMU variable name -> value
    model: object | None = field(default=None, repr=False, compare=False)  # fmpy ModelDescription
    # units the SSD's connectors give variables the FMU declares without one (a generic
    # channel): name -> railfmu.fmus.ssp.units.Unit; an exported SSP declares them in the FMU
    units: dict = field(default_factory=dict, repr=False, compare=False)
    _by_name: dict | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def md(self):
        """The FMU's model description (read on first use when the component was built by hand)."""
        if self.model is None:
            self.fmu, self.model = read_model(self.fmu, f"Component {self.name!r}")
        return self.model

    @property
    def variables(self) -> dict:
        """The FMU's model variables by name."""
        if self._by_name is None:
            self._by_name = {v.name: v for v in self.md.modelVariables}
        return self._by_name

    def variable(self, name: str, where: str = ""):
        try:
            return self.variables[name]
        except KeyError:
            raise UserError(f"{where + ': ' if where else ''}{Path(self.fmu).name} ({self.name}): "
                            f"no variable {name!r}") from None


@dataclass
class Connection:
    src: str  # component name
    src_var: str
    dst: str
    dst_var: str
    factor: float = 1.0  # dst = factor * src + offset
    offset: float = 0.0

    @property
    def identity(self) -> bool:
        return self.factor == 1.0 and self.offset == 0.0

    def __str__(self) -> str:
        return f"{self.src}.{self.src_var} -> {self.dst}.{self.dst_var}"


@dataclass
class ObserverSpec:
    """An estimator attached to the run (declared in the SSD's railfmu annotation).

    ``cls`` is the estimator's registered name (entry-point group ``railfmu.estimators``,
    resolved by the run engine; a registered class's dotted path is deprecated), kept as the
    SSD writes it so that an export writes what it read; ``measurements`` and ``inputs`` (its
    known inputs) map the observer's names to recorded signals ``component.variable``;
    ``valid`` maps a measurement to a flag signal (nonzero: the measurement is there);
    ``truth`` maps estimate names to the recorded signals they are scored against (metrics
    only, never fed to the estimator); ``settings`` are keyword arguments of the class;
    ``setting_signals`` maps a setting to the recorded signal whose value at the observer's
    first sample it takes (converted to the unit the observer declares for that name);
    ``setting_parameters`` maps a setting to the component parameter ``component.parameter``
    whose value (as the SSP binds it after the variant and ``--set``, else the FMU's start
    value, in the FMU's unit) the reader has put into ``settings`` (an estimator's noise model
    following the IMU grade a variant selects). The reserved setting ``enabled`` (default
    true) is not passed to the class: false leaves the observer out of the run.
    ``period``: its sample period in s (None: the system's step); ``event``: its
    measurements arrive as events (None: as its class declares); ``offline``: run once on
    the whole record after the run. ``units``: the unit of each bound signal that has one
    (an ``railfmu.fmus.ssp.units.Unit``), for the bank's unit checks.
    """
    name: str
    cls: str
    measurements: dict[str, str] = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)
    truth: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Value] = field(default_factory=dict)
    setting_signals: dict[str, str] = field(default_factory=dict)
    setting_parameters: dict[str, str] = field(default_factory=dict)
    valid: dict[str, str] = field(default_factory=dict)
    period: float | None = None
    event: bool | None = None
    offline: bool = False
    units: dict[str, object] = field(default_factory=dict)
    period_from: str = "ssd"  # where ``period`` came from: "ssd", or the variant / --set that set it

    @property
    def enabled(self) -> bool:
        """False when the setting ``enabled`` is false: the bank does not build it."""
        return self.settings.get("enabled", True) is not False

    @property
    def class_settings(self) -> dict[str, Value]:
        """The settings passed to the estimator class (without the reserved ones)."""
        return {k: v for k, v in self.settings.items() if k not in RESERVED_SETTINGS}

    @property
    def signals(self) -> list[str]:
        """Every recorded signal it reads (fed or scored)."""
        return [*self.measurements.values(), *self.inputs.values(), *self.valid.values(), *self.truth.values(),
                *self.setting_signals.values()]


@dataclass
class System:
    name: str
    components: list[Component]
    connections: list[Connection]
    start_time: float = 0.0
    stop_time: float = 1.0
    step_size: float = 1e-3
    record: list[str] = field(default_factory=list)  # "component.variable"; empty: every output
    observers: list[ObserverSpec] = field(default_factory=list)
    source: Path | None = None  # the SSD (or .ssp) it came from, for messages
    description: str = ""
    warnings: list[str] = field(default_factory=list)  # e.g. an unconnected input keeping its start
    step_size_from: str = "given"  # where the step size came from (annotation, --step-size, the FMUs)
    master: str | None = None  # the master the experiment prefers (rf:FixedStep master=); None: the caller's
    stop_time_from: str = "given"  # where the stop time came from (--stop-time, the variant, the SSD)
    study: str | None = None  # the study it names (org.railfmu.study annotation); None: plain SSP
    #: file parameters a user gave (variant, --set, parameters=): name -> (absolute path, how it was resolved)
    files: dict[str, tuple[str, str]] = field(default_factory=dict, compare=False)
    #: what the run engine derived from the data (a replay's stop time, step, time shift), for the heading
    notes: list[str] = field(default_factory=list, compare=False)
    #: system parameters (org.railfmu.parameters): name -> [target "component.param" / "observer.setting"]
    shared: dict[str, list[str]] = field(default_factory=dict, compare=False)  # not written by write_ssp

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def n_steps(self) -> int:
        return n_steps(self.start_time, self.stop_time, self.step_size)

    def signal(self, signal: str, where: str = ""):
        """The model variable of ``component.variable`` (the longest component name that fits)."""
        names = sorted((c.name for c in self.components), key=len, reverse=True)
        comp = next((n for n in names if signal.startswith(n + ".")), None)
        if comp is None:
            raise UserError(f"{where or 'signal'} {signal!r}: no component {signal.partition('.')[0]!r} "
                            "(expected component.variable)")
        return self.component(comp), self.component(comp).variable(signal[len(comp) + 1:], where)

    def signal_types(self) -> dict[str, str]:
        """FMI type of every recorded signal (``time`` is Real)."""
        return {"time": "Real", **{s: self.signal(s)[1].type for s in recorded_signals(self)}}


def recorded_signals(system: System) -> list[str]:
    """``system.record``, or every output of type Real, Integer, Boolean or Enumeration of
    every component, in component order."""
    if system.record:
        for signal in system.record:
            if "." not in signal:
                raise UserError(f"recorded signal {signal!r}: expected component.variable")
        return list(system.record)
    return [f"{c.name}.{v.name}" for c in system.components for v in c.md.modelVariables
            if v.causality == "output" and v.type in SIGNAL_TYPES]


# -- reading an FMU once -----------------------------------------------------------------------

def _platform(version: int = 2) -> str:
    """The binaries/ folder of this platform: ``linux64`` (FMI 1 and 2), ``x86_64-linux`` (FMI 3)."""
    import fmpy

    return fmpy.platform if version < 3 else fmpy.platform_tuple


def read_model(fmu: Path | str, where: str):
    """``(path, model description)`` of an FMI 2.0 co-simulation FMU; UserError (one line) for
    a missing file, an unreadable or non-FMI-2.0-CS FMU, or one without a binary for this
    platform and without ``sources/``. An FMU with ``sources/`` but no binary is compiled once
    (``fmpy.build.build_platform_binary``) into a cached copy, whose path is returned."""
    fmu = Path(fmu)
    if not fmu.is_file():
        raise UserError(f"{where}: FMU {fmu} not found (run `railfmu build`)")
    st = fmu.stat()
    key = (str(fmu.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _MODELS:  # once per process and FMU file: every Monte Carlo member reads the same
        _MODELS[key] = _read_model(fmu, where)
    return _MODELS[key]


_MODELS: dict[tuple[str, int, int], tuple] = {}


def _read_model(fmu: Path, where: str):
    from fmpy import read_model_description

    try:
        md = read_model_description(str(fmu))
    except Exception as exc:  # noqa: BLE001 - fmpy raises anything from BadZipFile to ValidationError
        md = _unvalidated(fmu, exc)
        if md is None:
            raise UserError(f"{where}: cannot read {fmu.name}: {' '.join(str(exc).split())}") from None
        print(f"railfmu: warning: {where}: {fmu.name}: {_validation_problems(exc)}; read without FMPy's "
              "validation (a repeated variable name means the last variable of that name)", file=sys.stderr)
    from railfmu.fmus.cosim.slave import fmi2_types, fmi_version

    if fmi_version(md) is None or md.coSimulation is None:
        raise UserError(f"{where}: {fmu.name} is not an FMI 1.0, 2.0 or 3.0 co-simulation FMU "
                        f"(fmiVersion {md.fmiVersion})")
    fmi2_types(md)  # FMI 3 Float64/Int32 as Real/Integer: one set of type names
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
    binary = f"binaries/{_platform(fmi_version(md))}/{md.coSimulation.modelIdentifier}"
    if any(n.startswith(binary + ".") for n in names):
        return fmu, md
    if not any(n.startswith("sources/") and n.endswith(".c") for n in names):
        raise UserError(f"{where}: {fmu.name} has no binary for this platform ({_platform(fmi_version(md))}) and no "
                        "sources/ to compile one from")
    return _compiled(fmu, where), md


def _unvalidated(fmu: Path, exc: Exception):
    """The model description without FMPy's validation when only the validation failed (an FMU
    that repeats a variable name runs all the same), else None."""
    from fmpy import read_model_description
    from fmpy.model_description import ValidationError

    if not isinstance(exc, ValidationError):
        return None
    try:
        return read_model_description(str(fmu), validate=False)
    except Exception:  # noqa: BLE001 - unreadable without validation too: the first error stands
        return None


def _validation_problems(exc: Exception) -> str:
    problems = [" ".join(p.split()) for p in getattr(exc, "problems", [])] or [" ".join(str(exc).split())]
    shown = "; ".join(problems[:3]) + (f"; and {len(problems) - 3} more" if len(problems) > 3 else "")
    return f"modelDescription.xml fails FMPy's validation ({shown})"


def _compiled(fmu: Path, where: str) -> Path:
    """A copy of ``fmu`` with a binary for this platform built from its ``sources/`` (cached by
    the FMU's bytes)."""
    from fmpy.build import build_platform_binary

    # the FMU's bytes and how it is compiled (a copy built before the aliases of _unprefixed differs)
    key = hashlib.sha256(fmu.read_bytes() + b"unprefixed aliases, FMI 2 and 3").hexdigest()[:20]
    from railfmu.fmus.cache import cache_root

    out = cache_root() / "compiled" / key / fmu.name  # with the built FMUs ($RAILFMU_CACHE)
    if out.is_file():
        return out
    work = Path(tempfile.mkdtemp(prefix="railfmu-compile-"))
    try:
        with zipfile.ZipFile(fmu) as z:
            z.extractall(work / "fmu")
        (work / "build").mkdir()
        saved = os.dup(1)
        try:
            # cmake talks on the process's stdout: keep it off the user's terminal
            with open(work / "build.log", "wb") as log:
                os.dup2(log.fileno(), 1)
                build_platform_binary(work / "fmu", build_dir=work / "build")
                for attempt in range(3):  # checked after every build: a copy without aliases is never cached
                    aliases = _unprefixed(work / "fmu")
                    if not aliases:
                        break
                    if attempt == 2:
                        raise RuntimeError("the binary built from them exports only prefixed FMI function names")
                    # once more, with the standard names as aliases of the prefixed ones; the binary
                    # built first goes, or cmake's install may keep it as "up to date"
                    shutil.rmtree(work / "build")
                    (work / "build").mkdir()
                    for so in (work / "fmu" / "binaries").rglob("*.so"):
                        so.unlink()
                    build_platform_binary(work / "fmu", build_dir=work / "build",
                                          cmake_options={"CMAKE_SHARED_LINKER_FLAGS": aliases})
        except Exception as exc:  # noqa: BLE001 - cmake, the compiler, a bad build description
            raise UserError(f"{where}: {fmu.name} has no binary for {_platform()} and compiling its "
                            f"sources/ failed: {' '.join(str(exc).split())[:300]}") from None
        finally:
            os.dup2(saved, 1)  # the terminal back
            os.close(saved)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + f".{os.getpid()}.part")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for p in sorted((work / "fmu").rglob("*")):
                if p.is_file():
                    z.write(p, p.relative_to(work / "fmu").as_posix())
        os.replace(tmp, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


def _unprefixed(unzipped: Path) -> str:
    """FMI 2.0 and 3.0 source code names its functions ``<modelIdentifier>_fmi2DoStep`` (for
    static linking) unless the FMU's own build says otherwise (the Reference-FMUs' FMI 3
    buildDescription.xml does not); a binary built from such sources exports no
    ``fmi2DoStep``, which every importer looks for. Linker flags that add the standard names as
    aliases of the prefixed ones (GNU ld ``--defsym``), or "" when the binary needs none (or
    ``nm`` cannot tell)."""
    import subprocess

    from fmpy import read_model_description

    md = read_model_description(str(unzipped), validate=False)
    if md.fmiVersion not in ("2.0", "3.0") or md.coSimulation is None:
        return ""
    fmi = "fmi2" if md.fmiVersion == "2.0" else "fmi3"
    mid = md.coSimulation.modelIdentifier
    binary = unzipped / "binaries" / _platform(int(md.fmiVersion[0])) / f"{mid}.so"
    try:
        out = subprocess.run(["nm", "-D", "--defined-only", str(binary)], capture_output=True, text=True,
                             timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return ""
    names = {line.split()[-1] for line in out.splitlines() if line.strip()}
    if f"{fmi}DoStep" in names or f"{mid}_{fmi}DoStep" not in names:
        return ""
    return " ".join(f"-Wl,--defsym={n.removeprefix(mid + '_')}={n}" for n in sorted(names)
                    if n.startswith(f"{mid}_{fmi}"))


# -- the one set of checks ---------------------------------------------------------------------

MAX_STEPS = 2**40  # ~35 years at 1 ms; far past what the masters' row buffer could hold


def n_steps(start: float, stop: float, h: float, where: str = "") -> int:
    """The number of communication steps of ``[start, stop]`` at ``h``: UserError unless ``h``
    divides the interval to 1e-9 of a step."""
    at = f"{where}: " if where else ""
    if not all(map(math.isfinite, (start, stop, h))):
        raise UserError(f"{at}start {start:g}, stop {stop:g} and step {h:g} s must be finite")
    if h <= 0:
        raise UserError(f"{at}step size {h:g} s must be positive")
    if stop <= start:
        raise UserError(f"{at}stop time {stop:g} s must be after the start time {start:g} s")
    if (stop - start) / h > MAX_STEPS:
        raise UserError(f"{at}[{start:g}, {stop:g}] s at {h:g} s is {(stop - start) / h:.3g} steps: more than "
                        f"the {MAX_STEPS:,} a run can take (shorten the stop time or lengthen the step)")
    n = round((stop - start) / h)
    if n < 1 or abs((stop - start) / h - n) > 1e-9 * max(n, 1):
        raise UserError(f"{at}step size {h:g} s does not divide the interval [{start:g}, {stop:g}] s")
    return n


def check_system(system: System) -> int:
    """Every check of a system before it runs, the same for every master and for ``railfmu
    validate``: unique component names, FMUs found and FMI 2.0 CS, connections between known
    variables (output or parameter -> input, Real -> Real, Integer -> Integer, Boolean ->
    Boolean; a map other than the identity only on Real), parameters that exist, recorded
    signals that exist and are Real, Integer or Boolean, a step size that divides the run.
    Returns the number of steps."""
    seen: set[str] = set()
    for c in system.components:
        if c.name in seen:
            raise UserError(f"component {c.name!r} appears twice")
        seen.add(c.name)
        c.md  # noqa: B018 - reads (and checks) the FMU once
        for name in c.parameters:
            c.variable(name, f"parameter {c.name}.{name}")
    for k in system.connections:
        for comp in (k.src, k.dst):
            if comp not in seen:
                raise UserError(f"connection {k}: unknown component {comp!r}")
        sv = system.component(k.src).variable(k.src_var, f"connection {k}")
        dv = system.component(k.dst).variable(k.dst_var, f"connection {k}")
        if dv.causality != "input":
            raise UserError(f"connection {k}: {k.dst}.{k.dst_var} is a(n) {dv.causality}; a connection ends at an input")
        if carried_type(sv.type) != carried_type(dv.type):  # an Enumeration travels as an Integer
            raise UserError(f"connection {k}: type mismatch: {sv.type} -> {dv.type}")
        if sv.type not in SIGNAL_TYPES:
            raise UserError(f"connection {k}: {sv.type} connections are not supported "
                            f"({', '.join(SIGNAL_TYPES)})")
        if sv.type != "Real" and not k.identity:
            raise UserError(f"connection {k}: a LinearTransformation or unit conversion needs Real "
                            f"connectors, not {sv.type}")
    for s in recorded_signals(system):
        _, v = system.signal(s, "recorded signal")
        if v.type not in SIGNAL_TYPES:
            raise UserError(f"recorded signal {s} is {v.type}: only {', '.join(SIGNAL_TYPES)} can be recorded")
    return n_steps(system.start_time, system.stop_time, system.step_size)


class Sink(Protocol):
    """Receives the recorded samples of a run: the CSV recorder, observers.

    ``columns`` are ``time`` followed by the recorded signals; Integer and Boolean signals
    arrive as numbers (0/1 for Boolean) in the same float rows. Every master calls
    :meth:`write_block` with many rows at once (the Python masters every few hundred
    communication points, the container path per C call); a sink whose class sets
    ``every_step = True`` (one that must see each point before the next step) gets each row
    as soon as it is sampled. ``close(complete)`` says whether the run
    ended normally: at its stop time, or earlier because an FMU ended the simulation
    (fmi2Discard + fmi2Terminated); then the rows up to that time are all there.
    """

    def open(self, columns: list[str]) -> None: ...

    def write(self, row: np.ndarray) -> None: ...

    def write_block(self, rows: np.ndarray) -> None: ...

    def close(self, complete: bool) -> None: ...
