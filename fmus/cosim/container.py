"""The whole system as one FMPy container FMU (``fmpy.container_fmu``): a single FMU of the
system for other tools (:func:`build_container`), and the container master's path for a
system with an FMI 3.0 component (FMI 2.0 systems run in the master's own C loop,
:mod:`railfmu.fmus.cosim.native_loop`, which is faster to set up and takes affine maps).

FMPy's container is a Rust binary that loads the components' FMUs and couples them itself,
driven by a JSON configuration; :func:`build_container` writes it from a :class:`System`:

* every component, with its FMU extracted into the container's ``resources/<stem>/``;
* every connection (all must be identity maps: the container copies values unchanged), Real,
  Integer or Boolean;
* every parameter of ``Component.parameters`` as a container parameter ``component.name``
  (Real, Integer, Boolean and String), which the container forwards to the component: its
  start value is set right after instantiation, and fmi2SetReal/Integer/Boolean/String on
  it are passed on to every inner variable it maps to, in any state (FMPy's container
  checks none);
* every recorded signal as a container output ``component.variable`` of its own type.

What the container does (FMPy 0.3.32; the same order as our Jacobi master, so their
samples can be compared one to one): ``fmi2ExitInitializationMode`` copies every
connection, in the order given, then lets the components leave initialisation; every
``fmi2DoStep`` steps all components from the container's time ``t`` and then copies every
connection (outputs at ``t + h`` into the inputs). Sampling after the container's step is
therefore the Jacobi sample "after the transfer" at ``t + h``, direct-feedthrough outputs
included. The C driver passes the container's own clock (read back from value reference 0
after every step) as the next communication point; on the test systems its time values and
every sample equal the Jacobi master's (``start + k h``) bit for bit.

Pitfalls of fmpy 0.3.32 handled here: a connection's ``variableType`` must be ``Float64`` or
``Int32`` (FMPy copies the FMI 2 type ``Real``/``Integer`` from the connector and the binary
rejects it); the container implements no ``fmi2GetBooleanStatus`` and returns one status for
all its components (the master replays a failed step to name the inner FMU); the
independent ``time`` must be the first model variable (value reference 0) and stay out of
``variableMappings``; start values must be strings in ``container.json``.

:func:`load_driver` compiles ``fmus/native/runtime/container_driver.c`` (a loop of doStep + getReal into
a numpy buffer) at first use into a cache folder; without a C compiler the master falls back
to a ctypes loop.

Two kinds of container are written from one :func:`configuration`. The exported one
(:func:`build_container`) carries the parameter values as start values, so it runs alone.
The one the container master runs (:func:`cached_container_dir`) carries the FMUs' own start
values and is keyed by the system's structure only: the master sets each run's values
(:func:`parameter_values`, :func:`apply_parameters`) after fmi2EnterInitializationMode, the
call order of the Jacobi master, so a Monte Carlo member, which changes only seeds, reuses
the folder of the first member instead of writing its own.
"""

from __future__ import annotations

import copy
import ctypes
import hashlib
import json
import os
import platform
import shutil
import sys
import tempfile
import uuid
import zipfile
from pathlib import Path

import fmpy
import fmpy.container_fmu as fmpy_container
from fmpy import read_model_description
from fmpy.container_fmu import write_configuration
from fmpy.container_fmu.config import Component as CComponent
from fmpy.container_fmu.config import Configuration
from fmpy.container_fmu.config import Connection as CConnection
from fmpy.fmi2 import FMU2Slave
from fmpy.model_description import (
    CoSimulation,
    DefaultExperiment,
    ModelDescription,
    ModelVariable,
    Unknown,
    write_model_description,
)

from railfmu.models.errors import UserError
from railfmu.fmus.cache import cache_root, compiled_library
from railfmu.fmus.cosim.slave import Slave
from railfmu.fmus.cosim.system import System, check_system, recorded_signals

DRIVER_SOURCE = Path(__file__).parent.parent / "native" / "runtime" / "container_driver.c"


def _typed(var: ModelVariable, value, where: str):
    """``value`` as the Python value of ``var``'s FMI type (float, int, bool or str);
    UserError naming ``where`` when it is not one."""
    try:
        if var.type == "Real":
            return float(value)
        if var.type == "Integer":
            return int(value)
        if var.type == "Boolean":
            if isinstance(value, str):
                if value.strip().lower() not in ("true", "false", "1", "0"):
                    raise ValueError(value)
                return value.strip().lower() in ("true", "1")
            return bool(value)
        if var.type == "String":
            return str(value)
    except (TypeError, ValueError):
        raise UserError(f"{where}: {value!r} is not a valid {var.type} value") from None
    raise UserError(f"{where}: variables of type {var.type} cannot be set in a container FMU "
                    "(use --master jacobi)")


def _literal(var: ModelVariable, value, where: str) -> str:
    """The start value as the container's JSON wants it (a string the Rust side parses;
    ``repr`` of a float reads back to the same double)."""
    typed = _typed(var, value, where)
    if var.type == "Real":
        return repr(typed)
    if var.type == "Boolean":
        return "true" if typed else "false"
    return str(typed)


def parameter_values(system: System) -> list[tuple[str, str, object]]:
    """``(container variable, FMI type, value)`` of every ``Component.parameters`` entry,
    converted and checked (UserError for a value that is not of its variable's type)."""
    out = []
    for comp in system.components:
        for name, value in comp.parameters.items():
            where = f"{comp.name}.{name}"
            inner = comp.variable(name, where)
            out.append((where, inner.type, _typed(inner, value, where)))
    return out


def apply_parameters(slave: Slave, values: list[tuple[str, str, object]]) -> None:
    """Set ``values`` (:func:`parameter_values`) on the container ``slave``, which passes each
    on to its component; one call per variable, so a refusal names it. Called between
    fmi2EnterInitializationMode and fmi2ExitInitializationMode, as the Jacobi master sets
    them, so both masters make the same calls on every FMU."""
    f = slave.fmu
    setters = {"Real": f.setReal, "Integer": f.setInteger, "Boolean": f.setBoolean, "String": f.setString}
    for name, type_, value in values:
        slave.call(f"setting {name}", setters[type_], [slave.var(name).valueReference], [value])


def check_containable(system: System) -> None:
    """UserError for what the container cannot run (before anything is built): besides
    :func:`railfmu.fmus.cosim.system.check_system`, maps other than the identity and two FMU files
    of one name."""
    check_system(system)
    for c in system.connections:
        if not c.identity:
            raise UserError(f"connection {c} maps dst = {c.factor!r} * src + {c.offset!r}: FMPy's "
                            "container FMU copies values unchanged, so it cannot run this system; "
                            "use --master jacobi (or gauss-seidel)")
    stems: dict[str, Path] = {}
    for comp in system.components:
        path = Path(comp.fmu).resolve()
        other = stems.setdefault(path.stem, path)
        if other != path:
            raise UserError(f"components use two different FMUs named {path.stem}.fmu ({other} and "
                            f"{path}): the container extracts each FMU by its file name; use --master jacobi")


_PLATFORMS = [  # (folder in fmpy's container_fmu/binaries, FMI 2 platform folder, library)
    ("aarch64-darwin", "darwin64", "container_fmu.dylib"),
    ("x86_64-darwin", "darwin64", "container_fmu.dylib"),
    ("x86_64-linux", "linux64", "container_fmu.so"),
    ("x86_64-windows", "win64", "container_fmu.dll"),
]


def _host_platform() -> str:
    machine = platform.machine().lower()
    arch = "aarch64" if machine in ("arm64", "aarch64") else "x86_64"
    osname = {"darwin": "darwin", "win32": "windows"}.get(sys.platform, "linux")
    return f"{arch}-{osname}"


def configuration(system: System, values: bool = True) -> Configuration:
    """The ``fmpy.container_fmu`` configuration of ``system`` (UserError for what the
    container cannot run or what names nothing). ``values``: the parameters' start values
    are ``Component.parameters``; else the FMUs' own start values (the cached container, to
    which the master applies each run's values), so nothing in it depends on the values."""
    check_containable(system)
    components = {comp.name: CComponent(name=comp.name, filename=Path(comp.fmu).resolve(),
                                        modelDescription=comp.md) for comp in system.components}

    def var(comp: str, name: str) -> ModelVariable:
        return system.component(comp).variable(name)

    mappings: dict[ModelVariable, list] = {}
    by_name: dict[str, ModelVariable] = {}
    for comp in system.components:
        for name, value in comp.parameters.items():
            inner = var(comp.name, name)
            start = _literal(inner, value, f"{comp.name}.{name}") if values else inner.start
            cv = ModelVariable(name=f"{comp.name}.{name}", type=inner.type, causality="parameter",
                               variability="fixed", initial="exact", start=start,
                               description=inner.description)
            mappings[cv] = [(components[comp.name], inner)]
            by_name[cv.name] = cv
    for signal in recorded_signals(system):
        comp, inner = system.signal(signal)
        if signal in by_name:  # a recorded parameter: read through the parameter's variable
            continue
        cv = ModelVariable(name=signal, type=inner.type, causality="output",
                           variability="continuous" if inner.type == "Real" else "discrete",
                           initial="calculated", description=inner.description)
        mappings[cv] = [(components[comp.name], inner)]
        by_name[signal] = cv

    connections = []
    for c in system.connections:
        src, dst = var(c.src, c.src_var), var(c.dst, c.dst_var)
        typed = copy.copy(src)
        # fmpy writes the connector's FMI 2 type; the binary wants its own names
        typed.type = {"Real": "Float64", "Integer": "Int32"}.get(src.type, src.type)
        connections.append(CConnection(components[c.src], [typed], components[c.dst], [dst]))

    token = str(uuid.uuid5(uuid.NAMESPACE_URL, "railfmu-container:" + json.dumps({
        "name": system.name, "step": system.step_size,
        "components": [(c.name, str(Path(c.fmu).resolve()), c.md.guid)
                       for c in system.components],
        "connections": [str(c) for c in system.connections],
        "variables": [(v.name, v.type, v.start) for v in mappings],
    }, sort_keys=True, default=str)))
    md = ModelDescription(
        fmiVersion="2.0", modelName=system.name or "system", instantiationToken=token,
        description=f"railfmu container of {system.name} (FMPy container FMU)",
        generationTool="railfmu (railfmu.fmus.cosim.container)",
        coSimulation=CoSimulation(modelIdentifier="container_fmu", fixedInternalStepSize=system.step_size),
        defaultExperiment=DefaultExperiment(startTime=repr(system.start_time), stopTime=repr(system.stop_time),
                                            stepSize=repr(system.step_size)),
        modelVariables=[ModelVariable(name="time", type="Real", causality="independent",
                                      variability="continuous"), *mappings],
    )
    # the container has no inputs: its outputs depend on nothing but time and parameters
    md.outputs = [Unknown(variable=v, dependencies=[]) for v in mappings if v.causality == "output"]
    md.initialUnknowns = [Unknown(variable=v) for v in mappings if v.causality == "output"]
    return Configuration(parallelDoStep=False, modelDescription=md, components=list(components.values()),
                         connections=connections, variableMappings=mappings)


def write_container_dir(config: Configuration, unzipdir: Path, all_platforms: bool = True) -> Path:
    """The unzipped container FMU in ``unzipdir`` (created): what fmpy's
    ``create_container_fmu`` writes before it zips, with the binary of this machine only
    unless ``all_platforms``. (Its zip step is not used: in 0.3.32 it archives the folder
    into a file inside that folder, so the FMU holds a stray copy of itself, and it deflates
    4 MB of binaries, 0.3 s per run.)"""
    unzipdir = Path(unzipdir)
    unzipdir.mkdir(parents=True, exist_ok=True)
    for component in config.components:
        fmu_path = Path(component.filename)
        target = unzipdir / "resources" / fmu_path.stem
        if not target.is_dir():  # two instances of one FMU share its folder
            with zipfile.ZipFile(fmu_path) as z:
                z.extractall(target)
    config.modelDescription.coSimulation.modelIdentifier = "container_fmu"
    for i, variable in enumerate(config.modelDescription.modelVariables):
        variable.valueReference = i  # time is 0; the binary maps i + 1 to variables[i]
    write_model_description(config.modelDescription, unzipdir / "modelDescription.xml")
    write_configuration(config, unzipdir / "resources" / "container.json")
    binaries = Path(fmpy_container.__file__).parent / "binaries"
    host = _host_platform()
    for tuple_, fmi2_platform, library in _PLATFORMS:
        if all_platforms or tuple_ == host:
            (unzipdir / "binaries" / fmi2_platform).mkdir(parents=True, exist_ok=True)
            shutil.copyfile(binaries / tuple_ / library, unzipdir / "binaries" / fmi2_platform / library)
    return unzipdir


CACHE_KEEP = 16  # container folders kept in the cache (least recently used go first)


def cached_container_dir(system: System) -> Path:
    """The unzipped container FMU of ``system`` in the cache folder, written on first use,
    without the parameter values (``configuration(system, values=False)``): the master
    applies them to each instance (:func:`apply_parameters`).

    Keyed by everything the container is written from: each component's FMU bytes, name
    and the names and types of its bound parameters (not their values), the connections,
    the recorded signals, the time grid, FMPy's version and this module's source. So a
    repeated run (a study, a Monte Carlo member with another seed, a benchmark, another
    variant that binds the same parameters) skips extracting the FMUs and deleting them
    afterwards: on this machine's file system that cost more than stepping 20 s of the
    system."""
    h = hashlib.sha256()
    for c in system.components:
        h.update(hashlib.sha256(Path(c.fmu).read_bytes()).digest())
        h.update(repr((c.name, [(k, c.variable(k).type) for k in c.parameters])).encode())
    h.update(repr([(c.src, c.src_var, c.dst, c.dst_var, c.factor, c.offset) for c in system.connections]).encode())
    h.update(repr((system.name, system.record, system.start_time, system.stop_time, system.step_size)).encode())
    h.update(repr((fmpy.__version__, _host_platform())).encode())
    h.update(Path(__file__).read_bytes())
    root = cache_root() / "containers"
    target = root / h.hexdigest()[:20]
    if not target.is_dir():
        root.mkdir(parents=True, exist_ok=True)
        tmp = root / f"{target.name}.{os.getpid()}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        write_container_dir(configuration(system, values=False), tmp, all_platforms=False)
        try:
            os.replace(tmp, target)  # atomic: a concurrent run never sees half a folder
        except OSError:  # another process got there first
            shutil.rmtree(tmp, ignore_errors=True)
        _prune(root)
    os.utime(target)
    return target


def _prune(root: Path) -> None:
    dirs = sorted((d for d in root.iterdir() if d.is_dir() and not d.name.endswith(".tmp")),
                  key=lambda d: d.stat().st_mtime, reverse=True)
    for d in dirs[CACHE_KEEP:]:
        shutil.rmtree(d, ignore_errors=True)


def build_container(system: System, out: Path) -> Path:
    """Write the container FMU of ``system`` to ``out`` (a ``.fmu`` with the container
    binaries of every platform fmpy ships, the parameter values as start values, so it runs
    alone); returns ``out``."""
    out = Path(out)
    config = configuration(system)
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="railfmu-container-"))
    try:
        write_container_dir(config, work / "fmu")
        tmp = out.with_name(out.name + ".part")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for path in sorted((work / "fmu").rglob("*")):
                z.write(path, path.relative_to(work / "fmu").as_posix())
        os.replace(tmp, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


class ContainerSlave(Slave):
    """The container FMU through :class:`Slave` (its logger, its error messages), loaded
    from an unzipped folder (:func:`write_container_dir`), which :meth:`close` removes
    unless ``keep_dir`` (a cached folder).
    A failed instantiation (the container sets the parameters' start values there, so a
    refused start value fails it) becomes a UserError with what the FMUs logged."""

    def __init__(self, unzipdir: Path, instance_name: str, keep_dir: bool = False):
        self.keep_dir = keep_dir
        self.path = Path(instance_name).with_suffix(".fmu")  # for messages: "<system>.fmu (<name>)"
        self.name = instance_name
        self.dir = str(unzipdir)
        self.md = read_model_description(self.dir)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.messages = []
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance_name)
        self._callbacks = self._make_callbacks()
        try:
            self.fmu.instantiate(callbacks=self._callbacks)
        except Exception as exc:  # noqa: BLE001 (FMPy raises a bare Exception)
            error = self.failure("instantiation", exc)
            self.close()
            raise error from None

    def close(self) -> None:
        if self.keep_dir:
            self.dir = None  # Slave.close removes self.dir
        super().close()


# -- the C driver -------------------------------------------------------------------------

_driver = None  # the loaded library, False when it cannot be built


def load_driver():
    """``railfmu_run_steps`` from the compiled driver (built once per source version), or
    ``None`` when no C compiler works (the master then steps through ctypes)."""
    global _driver
    if _driver is not None:
        return _driver or None
    dll = compiled_library(DRIVER_SOURCE, ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror"])
    if dll is None:
        _driver = False
        return None
    fn = dll.railfmu_run_steps
    fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.POINTER(ctypes.c_double),
                   ctypes.c_double, ctypes.c_double, ctypes.c_long, ctypes.c_long, ctypes.c_void_p,
                   ctypes.c_size_t, ctypes.POINTER(ctypes.c_long), ctypes.POINTER(ctypes.c_int)]
    fn.restype = ctypes.c_int
    fn._keep = dll
    _driver = fn
    return fn
