"""SSP 1.0 and 2.0 experiments as a :class:`railfmu.fmus.cosim.system.System`: read, check, validate, write back.

:func:`read_system` applies what FMPy's own SSP support skips: parameter bindings in the SSD
(inline and ``.ssv``), ``.ssm`` mappings, ``ssc:LinearTransformation``, unit checks and
conversions, ``ssd:DefaultExperiment`` and a fixed step size (``--step-size``, else our or the
OSP or Vico annotation, else OMSimulator's, else the smallest DefaultExperiment stepSize of the
FMUs). Nested systems are flattened and system connectors become parameters of the run
(:mod:`railfmu.fmus.ssp.nested`); a single ``.fmu`` is a system of its own
(:mod:`railfmu.fmus.ssp.single_fmu`). Parameter
values, lowest priority first:

    FMU start values < component-level bindings (document order) < system-level bindings
    (``component.param``) < the variant (``variants/<v>.ssv``) < ``overrides`` (``--set``)

A String value ``resources/...`` (from any of them) names a file of the SSP and is passed to
the FMU as an absolute path (:meth:`_Reader._resource`).

The experiment (our ``org.railfmu.experiment`` annotation on ``ssd:DefaultExperiment``) may
name the fixed-step master it runs best on, ``<rf:FixedStep stepSize="0.005"
master="container"/>`` (``System.master``: used when the command line names none; an
ssc:Annotation holds one element, so the master is an attribute of the step's). A variant may
shorten or lengthen the run with the reserved parameter name ``experiment.stopTime`` (s; also
``--set experiment.stopTime=T``); ``--stop-time`` still wins. Other tools ignore both (an SSD
annotation; a variant is ours).

Every problem a user can cause is a one-line :class:`UserError` naming the file (with its
line), the element and what is wrong; the system read is checked as every master checks it
(:func:`railfmu.fmus.cosim.system.check_system`), so ``railfmu validate`` reports what a run would
refuse. Unknown parameter names are errors even where SSP lets a tool ignore them: a typo in
a study must not pass silently.

Helpers: ``ssp_xml`` (files, XML, schemas), ``ssp_units`` (unit algebra), ``ssp_params``
(parameter sets, mappings, value checks), ``ssp_write`` (the ``.ssp`` writer).
"""

from __future__ import annotations

import difflib
import math
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

from railfmu.models.errors import UserError
from railfmu.fmus.ssp.params import (
    ParamValue,
    apply_mapping,
    from_cli,
    from_ssv,
    read_mapping,
    read_parameter_set,
    why_not_settable,
)
from railfmu.fmus.ssp.units import (
    IDENTITY,
    OURS,
    Affine,
    Unit,
    UnitError,
    Units,
    compose,
    conversion,
    from_fmu,
    from_ssc,
    tidy,
)
from railfmu.fmus.ssp.nested import flatten
from railfmu.fmus.ssp.writer import write_ssp
from railfmu.fmus.ssp.xmltools import (
    NS,
    SIZED_TYPES,
    SSC_NS,
    Root,
    children,
    local,
    locate,
    one_line,
    parse_checked,
    parse_xml,
    schema_problems,
)
from railfmu.fmus.cosim.system import (
    Component,
    Connection,
    ObserverSpec,
    System,
    Value,
    carried_type,
    check_system,
    n_steps,
    read_model,
)

__all__ = ["list_variants", "read_system", "study_name", "validate_ssp", "write_ssp"]

FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET = "application/x-ssp-parameter-set"
RESOURCES = "resources/"  # SSP 1.0: an SSP's own files (FMUs, and any file a parameter names)
PARAMETERS = "org.railfmu.parameters"
RECORDER, OBSERVERS, EXPERIMENT, OSP = ("org.railfmu.recorder", "org.railfmu.observers",
                                        "org.railfmu.experiment", "com.opensimulationplatform")
VICO = "com.github.ntnu-ihb.vico"
#: the study whose metrics and figures a run gets: ``<rf:Study name="..."/>`` (System.study)
STUDY = "org.railfmu.study"
OMS = "org.openmodelica"  # OMSimulator's annotation type
STRINGS = "org.railfmu.strings"
#: reserved name of a variant parameter (or ``--set``) giving the run's stop time in s
STOP_TIME = "experiment.stopTime"


def read_system(path, variant: str | None = None, fmu_dirs=(), overrides: dict[str, dict[str, object]] | None = None,
                start_time: float | None = None, stop_time: float | None = None,
                step_size: float | None = None) -> System:
    """The system of an SSP (a ``.ssd``, a folder holding ``SystemStructure.ssd``, or a
    ``.ssp``) with ``variant`` (a name in ``variants/`` or a path to an ``.ssv``) and
    ``overrides`` ({component: {parameter: value}}) applied. FMUs missing from the SSP are
    looked up by file name in ``fmu_dirs``. Time arguments override the SSD's. A single
    ``.fmu`` is a system of its own (:func:`railfmu.fmus.ssp.single_fmu.system_of_fmu`)."""
    if _is_fmu(path):
        from railfmu.fmus.ssp.single_fmu import system_of_fmu

        if variant is not None:
            raise UserError(f"{path}: a single FMU has no variants (--set sets its parameters)")
        return system_of_fmu(path, overrides, start_time, stop_time, step_size)
    root = locate(path)
    try:
        system = _Reader(root, fmu_dirs).read(variant, overrides or {}, (start_time, stop_time, step_size))
    except (etree.LxmlError, zipfile.BadZipFile, KeyError, ValueError, TypeError) as exc:
        # a safety net: whatever slipped through the checks still becomes one line
        raise UserError(f"{root.show(root.ssd)}: cannot read the SSP ({type(exc).__name__}: "
                        f"{one_line(exc)})") from None
    system.source = Path(path)
    return system


def study_name(path) -> str | None:
    """The study an SSP names (our ``org.railfmu.study`` annotation, ``<rf:Study name=...>``),
    or None; reads the SSD only, without FMUs or schema."""
    if _is_fmu(path):
        return None
    root = locate(path)
    system = parse_xml(root.ssd, root.show(root.ssd)).find("ssd:System", NS)
    return _study(system) if system is not None else None


def _study(system_el) -> str | None:
    a = _Reader._annotation(system_el, STUDY)
    el = a.find("rf:Study", NS) if a is not None else None
    return (el.get("name") or None) if el is not None else None


def list_variants(path) -> list[str]:
    """The names of ``variants/*.ssv`` of an experiment folder, ``.ssd`` or ``.ssp``, sorted."""
    return [] if _is_fmu(path) else _variants(locate(path))


def _is_fmu(path) -> bool:
    return Path(path).suffix.lower() == ".fmu" and Path(path).is_file()


def _variants(root: Root) -> list[str]:
    folder = root.dir / "variants"
    return sorted(p.stem for p in folder.glob("*.ssv")) if folder.is_dir() else []


def validate_ssp(path, fmu_dirs=(), packaging: bool | None = None) -> list[str]:
    """Every problem found in an SSP: schema errors of each .ssd/.ssv/.ssm, unresolved
    references (the first per variant), and the problems of each FMU it holds or its
    components name (:func:`railfmu.fmus.generate.build.validate`: FMI conformance, and
    railfmu's packaging rules for the FMUs railfmu built, or for all with ``packaging``), so
    a folder and the same files zipped as ``.ssp`` validate alike. [] if none. Raises only if
    ``path`` does not exist. ``fmu_dirs``: where to look for FMUs the SSP does not contain
    (an experiment folder: railfmu's build, validated by ``railfmu build``)."""
    from railfmu.fmus.generate.build import validate

    given = Path(path)
    if not given.exists():
        raise UserError(f"{given}: no such file or directory")
    try:
        root = locate(given)
    except UserError as exc:
        return [str(exc)]
    problems: list[str] = []
    fmus: list[Path] = []
    kinds = {".ssd": "ssd", ".ssv": "ssv", ".ssm": "ssm"}
    for f in sorted(root.dir.rglob("*")):
        if f.suffix in kinds and f.is_file():
            try:
                problems += schema_problems(parse_xml(f, root.show(f)), kinds[f.suffix], root.show(f))
            except UserError as exc:
                problems.append(str(exc))
        elif f.suffix == ".fmu" and f.is_file():
            fmus.append(f)
    for variant in [None, *_variants(root)]:
        try:
            reader = _Reader(root, fmu_dirs)
            try:
                reader.read(variant, {}, (None, None, None), need_time=False)
            finally:  # the FMUs the components name, outside the SSP's folder too (../fmi2/X.fmu)
                fmus += [f for f in reader._mds if not any(f.is_relative_to(Path(d).resolve()) for d in fmu_dirs)]
        except UserError as exc:
            problems.append(str(exc))
        except Exception as exc:  # noqa: BLE001 - validation reports, it does not crash
            problems.append(f"{root.show(root.ssd)}: cannot read the SSP ({type(exc).__name__}: {one_line(exc)})")
    top = root.dir.resolve()
    for f in dict.fromkeys(Path(f).resolve() for f in fmus):
        shown = root.show(root.dir / f.relative_to(top)) if f.is_relative_to(top) else os.path.relpath(f)
        try:
            problems += [f"{shown}: {one_line(p)}" for p in validate(f, packaging)]
        except Exception as exc:  # noqa: BLE001 - a broken FMU is a finding here, not a crash
            problems.append(f"{shown}: cannot validate: {one_line(exc)}")
    return list(dict.fromkeys(problems))  # a schema error also stops the reader: report it once


# -- the reader ------------------------------------------------------------------------------

@dataclass
class _Comp:
    name: str
    fmu: Path
    md: object  # fmpy ModelDescription
    units: Units  # the FMU's unit definitions, then ours
    connectors: dict[str, str | None] = field(default_factory=dict)  # declared: name -> unit
    params: dict[str, Value] = field(default_factory=dict)

    def __post_init__(self):
        self.vars = {v.name: v for v in self.md.modelVariables}


class _Reader:
    def __init__(self, root: Root, fmu_dirs=()):
        self.root = root
        self.fmu_dirs = [Path(d) for d in fmu_dirs]
        self.file = root.show(root.ssd)
        self.doc = parse_checked(root.ssd, "ssd", self.file)
        self.system = self.doc.find("ssd:System", NS)
        self.flat = flatten(self.system, self.file)  # nested systems' components join the top level
        self.ssd_units = Units(from_ssc(self.doc.find("ssd:Units", NS)))
        self.comps: dict[str, _Comp] = {}
        self._mds: dict[Path, object] = {}
        self.aliases: dict[str, tuple[list[tuple[str, str, str]], str]] = {}
        self.stop_time: tuple[float, str] | None = None  # (s, where) from experiment.stopTime
        self.user: str | None = None  # while reading a variant or --set: its label (paths are the user's)
        self.files: dict[str, tuple[str, str]] = {}  # user file parameters: name -> (absolute, how)

    def at(self, el) -> str:
        return f"{self.file}:{el.sourceline}"

    def known(self) -> str:
        return f"known components: {', '.join(self.comps) or '(none)'}"

    def read(self, variant, overrides, times, need_time: bool = True) -> System:
        elements = self._components()
        connections = self._connections()
        self._port_parameters()
        for el, comp in elements:  # component level: bare names
            for v in self._bindings(el, f"Component {comp.name!r}"):
                self._set(comp, v)
        a = self._annotation(self.system, STRINGS)  # an exported archive's String values (writer.py)
        pset = a.find("ssv:ParameterSet", NS) if a is not None else None
        for v in read_parameter_set(pset, self.file, self.ssd_units) if pset is not None else []:
            self._set(*self._split(v))
        ported = []  # values of system connectors (so far the only aliases): after every binding,
        for v in self._bindings(self.system, ""):  # since the connection to a target outranks its binding
            if v.name in self.aliases:
                ported.append(v)
            else:
                self._set(*self._split(v))
        for v in ported:
            self._alias(v.name, v.value, v.where)
        record, observers = self._annotations()
        self.observers = {o.name: o for o in observers}
        self._aliases()
        if variant is not None:
            self.user = f"variant {Path(variant).stem}"
            self._variant(variant)
        self.user = "--set"
        self._overrides(overrides)
        self.user = None
        for spec in observers:  # after the variant and --set: the parameters' final values
            self._setting_parameters(spec)
        self._shared_agree()
        start, stop, step = self._time(*times, need=need_time)
        system = System(name=self.doc.get("name") or self.system.get("name"),
                        components=[Component(c.name, c.fmu, dict(c.params), model=c.md,
                                              units=self._generic_units(c))
                                    for c in self.comps.values()],
                        connections=connections, start_time=start, stop_time=stop, step_size=step,
                        record=record, observers=observers,
                        description=self.doc.get("description") or self.system.get("description") or "",
                        warnings=self._unconnected(connections), step_size_from=self.step_from,
                        master=self._master(), stop_time_from=self.stop_from, study=_study(self.system),
                        files=dict(self.files),
                        shared={n: [f"{o}.{p}" for _, o, p in t] for n, (t, _) in self.aliases.items()})
        try:  # what every master checks, so that `railfmu validate` reports what a run would refuse
            check_system(system)
        except UserError as exc:
            raise UserError(f"{self.file}: {exc}") from None
        return system

    # -- components and their FMUs ---------------------------------------------------------
    def _components(self) -> list:
        out = []
        elements = self.system.find("ssd:Elements", NS)
        for el in children(elements) if elements is not None else []:
            kind, name = local(el), el.get("name")
            if kind != "Component":
                raise UserError(f"{self.at(el)}: {kind} {name!r} is not supported")
            out.append((el, self._component(el)))
        return out

    def _component(self, el) -> _Comp:
        name = el.get("name")
        where = f"{self.at(el)}: Component {name!r}"
        if name in self.comps:
            raise UserError(f"{where}: a second element with this name")
        if el.get("type", FMU_TYPE) != FMU_TYPE:
            raise UserError(f"{where}: type {el.get('type')!r} is not supported (only {FMU_TYPE})")
        if el.get("implementation", "any") not in ("any", "CoSimulation"):
            raise UserError(f"{where}: implementation {el.get('implementation')!r} is not supported "
                            "(co-simulation FMUs only)")
        fmu, md = self._model_description(self._fmu_file(el.get("source"), where), where)
        comp = _Comp(name, fmu, md, Units(from_fmu(md)).then(OURS))
        self.comps[name] = comp
        for c in el.iterfind("ssd:Connectors/ssd:Connector", NS):
            self._connector(comp, c)
        return comp

    def _fmu_file(self, source: str, where: str) -> Path:
        path = self.root.resolve(source, where)
        if path.is_file():
            return path
        for d in self.fmu_dirs:  # an experiment folder refers to FMUs built elsewhere
            if (d / path.name).is_file():
                return d / path.name
        raise UserError(f"{where}: FMU {source} not found (run `railfmu build`)")

    def _model_description(self, fmu: Path, where: str):
        """(path, model description) of an FMU, read once per file (:func:`read_model`: a
        binary compiled from ``sources/`` when this platform has none)."""
        key = fmu.resolve()
        if key not in self._mds:
            self._mds[key] = read_model(fmu, where)
        return self._mds[key]

    def _generic_units(self, comp: _Comp) -> dict:
        """Connector units of Real variables the FMU declares without a unit."""
        view = self.ssd_units.then(comp.units)
        return {n: view.get(u) for n, u in comp.connectors.items()
                if u and not comp.vars[n].unit and view.get(u) is not None}

    def _connector(self, comp: _Comp, el) -> None:
        """A declared connector must match its FMU variable: kind vs causality (FMI 2.0), type,
        and a unit of the same dimension (then the connector shows the variable in its unit)."""
        name, kind = el.get("name"), el.get("kind")
        where = f"{self.at(el)}: Connector {comp.name}.{name}"
        var = comp.vars.get(name)
        if var is None:
            raise UserError(f"{where}: {comp.fmu.name} has no variable {name!r}")
        if kind != var.causality:
            raise UserError(f"{where}: kind {kind!r} does not match the FMU variable's causality "
                            f"{var.causality!r}")
        typed = next(iter(children(el, SSC_NS)), None)
        unit = None
        if typed is not None:
            if SIZED_TYPES.get(local(typed), local(typed)) != var.type:
                raise UserError(f"{where}: type ssc:{local(typed)} does not match the FMU variable's "
                                f"type {var.type}")
            unit = typed.get("unit") if var.type == "Real" else None
            try:
                conversion(var.unit, comp.units, unit, self.ssd_units.then(comp.units))
            except UnitError as exc:
                raise UserError(f"{where}: {exc} (the FMU variable's unit is {var.unit!r})") from None
        comp.connectors[name] = unit or var.unit

    # -- connections ----------------------------------------------------------------------
    def _connections(self) -> list[Connection]:
        """The connections between components: one that ends at a system's connector (a port,
        :mod:`railfmu.fmus.ssp.nested`) only carries the signal on; each component input is
        followed back through ports to the component output that feeds it, or to a port that
        nothing feeds, which makes it a parameter of the run (:meth:`_port_parameters`)."""
        out, fed = [], {}
        into: dict[tuple[str, str], list] = {}  # port -> the connections that end at it
        ends = []
        for el in self.system.iterfind("ssd:Connections/ssd:Connection", NS):
            d, dc = el.get("endElement", ""), el.get("endConnector")
            if (d, dc) in self.flat.ports and d not in self.comps:
                into.setdefault((d, dc), []).append(el)
            else:
                ends.append(el)
        self.port_targets: dict[tuple[str, str], list] = {}
        for el in ends:
            src, chain = (el.get("startElement", ""), el.get("startConnector")), [el]
            while src in self.flat.ports and src[0] not in self.comps:
                feeders = into.get(src, [])
                if len(feeders) > 1:
                    raise UserError(f"{self.at(feeders[1])}: connector {self.flat.ports[src].name} of a system "
                                    f"is already fed (line {feeders[0].sourceline})")
                if not feeders:
                    break
                chain.append(feeders[0])
                src = (feeders[0].get("startElement", ""), feeders[0].get("startConnector"))
                if len(chain) > len(self.flat.ports) + 1:
                    raise UserError(f"{self.at(el)}: Connection: a loop of system connectors")
            unfed = src in self.flat.ports and src[0] not in self.comps
            for k in chain[1:] if not unfed else chain:  # a system connector's value is set as it is
                if children(k, SSC_NS):
                    raise UserError(f"{self.at(k)}: a transformation on a connection to a system connector "
                                    "is not supported")
            if unfed:  # fed by nothing: a parameter of the run
                self.port_targets.setdefault(src, []).append(el)
                continue
            c = self._connection(el, src)
            if (c.dst, c.dst_var) in fed:
                raise UserError(f"{self.at(el)}: Connection {c}: input {c.dst}.{c.dst_var} is already "
                                f"connected (line {fed[c.dst, c.dst_var]})")
            fed[c.dst, c.dst_var] = el.sourceline
            out.append(c)
        return out

    def _port_parameters(self) -> None:
        """A system connector that nothing feeds (OMSimulator's top-level ``Input_cref``, a
        parameter connector of a nested system) is a parameter of the run: its value, bound
        by its name (``Input_cref``, ``sub.c``; ``--set <system>.Input_cref=...``), is set on
        every component input it reaches. Unbound, the inputs keep their start values."""
        self.aliases = {}
        for key, port in self.flat.ports.items():  # a value bound to a connector that reaches nothing is inert
            targets = []
            for el in self.port_targets.get(key, []):
                d, dc = el.get("endElement"), el.get("endConnector")
                where = f"{self.at(el)}: Connection {port.name} -> {d}.{dc}"
                comp, _ = self._end(d, dc, where)
                self._settable(comp, dc, where)
                targets.append(("connector", comp.name, dc))
            self.aliases[port.name] = (targets, f"{self.file}:{port.line}: Connector {port.name!r}")

    def _connection(self, el, src: tuple[str, str] | None = None) -> Connection:
        """``el`` as a connection; ``src``: its start when it comes through system connectors."""
        s, sc, d, dc = (el.get(a) for a in ("startElement", "startConnector", "endElement", "endConnector"))
        if src is not None:
            s, sc = src
        where = f"{self.at(el)}: Connection {s or ''}.{sc} -> {d or ''}.{dc}"
        if not s or not d:
            raise UserError(f"{where}: no system connector {sc if not s else dc!r}")
        src, svar = self._end(s, sc, where)
        dst, dvar = self._end(d, dc, where)
        if svar.causality not in ("output", "parameter", "calculatedParameter"):
            raise UserError(f"{where}: start {s}.{sc} is an {svar.causality}; a connection starts at "
                            "an output (or a parameter)")
        if dvar.causality != "input":
            raise UserError(f"{where}: end {d}.{dc} is a(n) {dvar.causality}; a connection ends at an input")
        if carried_type(svar.type) != carried_type(dvar.type):  # Integer <-> Enumeration: both fmi2Integer
            raise UserError(f"{where}: type mismatch: {svar.type} -> {dvar.type} (a connection joins "
                            "two variables of one type)")
        factor, offset = self._connection_map(el, where, src, svar, dst, dvar)
        return Connection(s, sc, d, dc, factor, offset)

    def _end(self, name: str, connector: str, where: str):
        comp = self.comps.get(name)
        if comp is None:
            raise UserError(f"{where}: no component {name!r}; {self.known()}")
        var = comp.vars.get(connector)
        if var is None:
            raise UserError(f"{where}: {comp.fmu.name} (Component {name!r}) has no variable {connector!r}")
        return comp, var

    def _connection_map(self, el, where, src: _Comp, svar, dst: _Comp, dvar) -> Affine:
        """The connection's dst = factor * src + offset.

        SSP 1.0 (ssc:LinearTransformation): unit conversion comes first, "the value of source is
        already converted to the target unit", so target = factor * converted + offset; with
        suppressUnitConversion="true" the transformation replaces that conversion. A connector
        shows its FMU variable in the connector's unit, so the whole chain is
            start variable -> start connector -> [unit conversion] -> LinearTransformation
            -> end connector -> end variable,
        where the outer two steps are identities unless a connector declares another unit.
        """
        linear = IDENTITY
        for t in children(el, SSC_NS):
            if local(t) != "LinearTransformation":
                raise UserError(f"{where}: ssc:{local(t)} on a connection is not supported")
            linear = (float(t.get("factor", 1.0)), float(t.get("offset", 0.0)))
        if svar.type != "Real":
            if linear != IDENTITY:
                raise UserError(f"{where}: a LinearTransformation needs Real connectors, not {svar.type}")
            s_unit, d_unit = src.connectors.get(svar.name), dst.connectors.get(dvar.name)
            if s_unit != d_unit:
                raise UserError(f"{where}: a unit conversion ({s_unit} -> {d_unit}) needs Real connectors, "
                                f"not {svar.type}")
            return IDENTITY
        s_unit, d_unit = src.connectors.get(svar.name, svar.unit), dst.connectors.get(dvar.name, dvar.unit)
        s_view, d_view = self.ssd_units.then(src.units), self.ssd_units.then(dst.units)
        try:
            m = conversion(svar.unit, src.units, s_unit, s_view)
            if el.get("suppressUnitConversion") not in ("true", "1"):
                m = compose(m, conversion(s_unit, s_view, d_unit, d_view))
            m = compose(compose(m, linear), conversion(d_unit, d_view, dvar.unit, dst.units))
        except UnitError as exc:
            raise UserError(f"{where}: unit mismatch: {exc}") from None
        if not all(map(math.isfinite, m)):  # INF/NaN are valid xs:double, not a valid signal map
            raise UserError(f"{where}: non-finite factor or offset ({m[0]!r}, {m[1]!r})")
        return tidy(m)

    # -- parameter values -------------------------------------------------------------------
    def _bindings(self, owner, label: str) -> list[ParamValue]:
        """The values of ``owner``'s ParameterBindings in document order, names as written
        (with the binding's prefix)."""
        out = []
        for b in owner.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            where = f"{self.at(b)}: ParameterBinding" + (f" of {label}" if label else "")
            if b.get("type", PARAMETER_SET) != PARAMETER_SET:
                raise UserError(f"{where}: type {b.get('type')!r} is not supported (only {PARAMETER_SET})")
            if b.get("sourceBase", "SSD") != "SSD":
                raise UserError(f"{where}: sourceBase={b.get('sourceBase')!r} is not supported")
            if b.get("source"):
                file = self._file(b.get("source"), where)
                shown = self.root.show(file)
                pset = parse_checked(file, "ssv", shown)
            else:
                shown, pset = self.file, b.find("ssd:ParameterValues/ssv:ParameterSet", NS)
                if pset is None:
                    raise UserError(f"{where}: neither a source nor an inline ssv:ParameterSet")
            values = read_parameter_set(pset, shown, self.ssd_units, label)
            pm = b.find("ssd:ParameterMapping", NS)
            if pm is not None:
                values = apply_mapping(values, self._mapping(pm, where))
            for v in values:
                v.name = b.get("prefix", "") + v.name
            out += values
        return out

    def _mapping(self, el, where: str):
        if el.get("sourceBase", "SSD") != "SSD":
            raise UserError(f"{where}: ParameterMapping sourceBase={el.get('sourceBase')!r} is not supported")
        if el.get("source"):
            file = self._file(el.get("source"), where)
            return read_mapping(parse_checked(file, "ssm", self.root.show(file)), self.root.show(file))
        pm = el.find("ssm:ParameterMapping", NS)
        if pm is None:
            raise UserError(f"{where}: ParameterMapping has neither a source nor an inline ssm:ParameterMapping")
        return read_mapping(pm, self.file)

    def _file(self, source: str, where: str) -> Path:
        path = self.root.resolve(source, where)
        if not path.is_file():
            raise UserError(f"{where}: {source} not found")
        return path

    def _split(self, v: ParamValue) -> tuple[_Comp, ParamValue]:
        """A system-level name ``component.parameter``: the component and the bare name."""
        for name in sorted(self.comps, key=len, reverse=True):  # the longest matching name
            if v.name.startswith(name + "."):
                v.name = v.name[len(name) + 1:]
                return self.comps[name], v
        raise UserError(f"{v.where}: no component {v.name.partition('.')[0]!r} (system-level names are "
                        f"component.parameter); {self.known()}")

    def _settable(self, comp: _Comp, name: str, where: str):
        var = comp.vars.get(name)
        if var is None:
            settable = [n for n, v in comp.vars.items() if not why_not_settable(v)]
            raise UserError(f"{where}: {comp.fmu.name} has no variable {name!r}{_closest(name, settable)}")
        why = why_not_settable(var)
        if why:
            raise UserError(f"{where}: {comp.fmu.name} variable {name!r} {why}; it cannot be set")
        return var

    def _set(self, comp: _Comp, v: ParamValue) -> None:
        var = self._settable(comp, v.name, v.where)
        if self.user is not None:  # a variant: the SSD's own bindings may set a shared parameter's targets
            self._not_shared(f"{comp.name}.{var.name}", v.value, v.where, "a <ssv:Parameter name=\"{}\"> in the variant")
        comp.params[var.name] = self._resource(var, from_ssv(v, var, comp.units), v.where, f"{comp.name}.{var.name}")

    def _not_shared(self, ref: str, value, where: str, how: str) -> None:
        """A component parameter or observer setting that is a target of a system parameter
        (``org.railfmu.parameters``, e.g. the run's speed ``run.V``) is set through that name
        only: one copy set on its own would contradict the others (the track at 30 m/s, the
        vehicle and the filter at 20). A one-line error naming the system parameter."""
        for name, (targets, _) in self.aliases.items():
            refs = [f"{o}.{p}" for _, o, p in targets]
            if ref in refs and len(refs) > 1:
                raise UserError(f"{where}: {ref} is one of the targets of the system parameter {name} "
                                f"({', '.join(refs)}), which must agree; set {how.format(name)} instead")

    def _user_path(self, name: str, value, where: str):
        """A file a user names (a variant, ``--set``, ``parameters=``) for a parameter or setting
        called ``file`` or ``*_file``: a relative path means the current directory (not the FMU's
        unpack folder, where an FMU would look); the FMU gets the absolute path. ``resources/...``
        keeps meaning the SSP's files (:meth:`_resource`). Recorded in :attr:`files`."""
        param = name.rpartition(".")[2]
        if (self.user is None or not isinstance(value, str) or not value or value.startswith(RESOURCES)
                or not (param == "file" or param.endswith("_file"))):
            return value
        path = Path(value).expanduser()
        how = f"{self.user}: as given" if path.is_absolute() else f"{self.user}: {value} relative to {Path.cwd()}"
        path = path if path.is_absolute() else Path.cwd() / path
        if name in self.files and self.files[name][0] == str(path.resolve()):  # a second target of one name
            return self.files[name][0]
        if not path.is_file():
            if self._fmu_resource(name, value):  # a table the FMU ships (a shipped track by name)
                return value
            raise UserError(f"{where}: {value}: no such file ({path}{'' if Path(value).is_absolute() else ', relative to the current directory'})")
        self.files[name] = (str(path.resolve()), how)
        return str(path.resolve())

    def _fmu_resource(self, name: str, value: str) -> bool:
        """Whether ``value``, a bare file name, is in the ``resources/`` of the FMU of the
        component that ``name`` (``component.parameter``) sets: the FMU finds it there."""
        comp = self.comps.get(name.rpartition(".")[0])
        if comp is None or "/" in value or "\\" in value:
            return False
        try:
            with zipfile.ZipFile(comp.fmu) as zf:
                return f"resources/{value}" in zf.namelist()
        except (OSError, zipfile.BadZipFile):
            return (Path(comp.fmu) / "resources" / value).is_file()

    def _resource(self, var, value, where: str, name: str = ""):
        """A String parameter whose value is a relative path under ``resources/`` names a
        file of the SSP (a measured table, a track profile), as the SSD's FMU sources do: it
        is resolved against the SSP root, and the FMU gets the absolute path (an FMU resolves
        a relative one against its own ``resources/``, which the SSP's files are not in).
        ``write_ssp`` puts such a file into the FMU's own ``resources/``, where any importer
        lets the FMU find it."""
        if var.type != "String" or not isinstance(value, str):
            return value
        if not value.startswith(RESOURCES):
            return self._user_path(name or var.name, value, where)
        path = self.root.resolve(value, where)
        if not path.is_file():
            raise UserError(f"{where}: {value} not found in the SSP ({self.root.show(path)})")
        return str(path.resolve())

    def _variant(self, variant: str) -> None:
        file = Path(variant)
        if file.suffix != ".ssv":
            file = self.root.dir / "variants" / f"{variant}.ssv"
            if not file.is_file():
                known = ", ".join(_variants(self.root)) or "(none)"
                raise UserError(f"{self.file}: unknown variant {variant!r}; known variants: {known}")
        elif not file.is_file():
            raise UserError(f"{file}: variant file not found")
        shown = self.root.show(file)
        for v in read_parameter_set(parse_checked(file, "ssv", shown), shown, self.ssd_units):
            if (not self._stop_time(v.name, v.value, v.where, f"variant {Path(variant).stem}", v.unit)
                    and not self._alias(v.name, v.value, v.where)
                    and not self._observer_setting(v.name, v.value, v.where)):
                self._set(*self._split(v))

    def _stop_time(self, name: str, value, where: str, label: str, unit: str | None = None) -> bool:
        """The reserved name ``experiment.stopTime`` (:data:`STOP_TIME`; unless a component or
        observer is called ``experiment``): the run's stop time in s. False for other names."""
        group = STOP_TIME.partition(".")[0]
        if name != STOP_TIME or group in self.comps or group in self.observers:
            return False
        if unit not in (None, "s"):
            raise UserError(f"{where}: {STOP_TIME} is in s, not {unit!r}")
        try:
            stop = float(value)
        except (TypeError, ValueError):
            stop = math.nan
        if isinstance(value, bool) or not math.isfinite(stop):
            raise UserError(f"{where}: {STOP_TIME} {value!r} must be a number of seconds")
        self.stop_time = (stop, f"{label} ({STOP_TIME})")
        return True

    def _observer_setting(self, name: str, value, where: str = "") -> bool:
        """Our extension: a variant or ``--set`` name ``observer.setting`` (an observer of the
        railfmu annotation, not a component) overrides that observer's setting, e.g. the
        filter's conicity in a robustness variant. Other tools see no such component.
        ``observer.samplePeriod`` sets its sample period (s), e.g. to follow a faster GNSS."""
        obs, dot, setting = name.partition(".")
        if not dot or obs in self.comps or obs not in self.observers:
            return False
        spec = self.observers[obs]
        if setting == "samplePeriod":
            try:
                period = float(value)
            except (TypeError, ValueError):
                period = math.nan
            if not (period > 0 and math.isfinite(period)):
                raise UserError(f"{where or name}: samplePeriod {value!r} must be a positive number of seconds")
            spec.period = period
            spec.period_from = self.user or "the SSD"
            return True
        # an observer's copy of a system parameter may differ on purpose (a filter built for another speed)
        value = self._user_path(name, value, where or name)
        spec.settings[setting] = _setting(str(value)) if isinstance(value, str) else value
        spec.setting_signals.pop(setting, None)  # a value given on purpose wins
        spec.setting_parameters.pop(setting, None)
        return True

    def _aliases(self) -> dict[str, tuple[list[tuple[str, str, str]], str]]:
        """Our extension (annotation ``org.railfmu.parameters``): a system parameter with one
        name that sets several targets, e.g. the line profile that the train, the driver and
        every observer read::

            <rf:Parameter name="line.file" value="resources/line.csv">
              <rf:Target connector="train.line_file"/>  <rf:Target setting="ukf_paper.line_file"/>

        A variant or ``--set line.file=...`` sets every target; ``value`` (optional) is applied
        with the system-level bindings. A String ``resources/...`` names a file of the SSP for
        an observer setting too. Returns ``{name: ([(kind, owner, name)], where)}``."""
        out: dict = dict(self.aliases)  # the system connectors' (_port_parameters)
        a = self._annotation(self.system, PARAMETERS)
        for el in a.iterfind("rf:Parameters/rf:Parameter", NS) if a is not None else []:
            name, where = el.get("name") or "", f"{self.at(el)}: Parameter {el.get('name')!r}"
            if "." not in name or name.partition(".")[0] in self.comps or name.partition(".")[0] in self.observers:
                raise UserError(f"{where}: the name must be group.parameter and the group no component or observer")
            targets = []
            for t in el.iterfind("rf:Target", NS):
                ref, setting = t.get("connector"), t.get("setting")
                if bool(ref) == bool(setting):
                    raise UserError(f"{self.at(t)}: Target needs one of connector= or setting=")
                owner, _, param = (ref or setting).partition(".")
                if ref:
                    self._settable(self._comp_of(ref, self.at(t)), param, f"{self.at(t)}: Target {ref!r}")
                elif owner not in self.observers:
                    raise UserError(f"{self.at(t)}: Target setting {setting!r}: no Observer {owner!r}")
                targets.append(("connector" if ref else "setting", owner, param))
            if not targets:
                raise UserError(f"{where}: no rf:Target")
            out[name] = (targets, where)
        self.aliases = out
        for el in a.iterfind("rf:Parameters/rf:Parameter", NS) if a is not None else []:
            if el.get("value") is not None:
                self._alias(el.get("name"), el.get("value"), f"{self.at(el)}: Parameter {el.get('name')!r}")
        return out

    def _shared_agree(self) -> None:
        """The targets of a system parameter that the SSD binds must hold one value (a track at
        one speed, the vehicle and the filter at another would be a wrong run, not a variant)."""
        for name, (targets, where) in self.aliases.items():
            seen = []
            for kind, owner, param in targets:
                if kind != "connector":  # the models must agree; an observer may be mistuned by a variant
                    continue
                held = self.comps[owner].params
                if param in held and not isinstance(held[param], bool):
                    seen.append((f"{owner}.{param}", held[param]))
            if len({_show(v) if isinstance(v, (int, float)) else str(v) for _, v in seen}) > 1:
                raise UserError(f"{where}: its targets disagree ({', '.join(f'{r} = {_show(v)}' for r, v in seen)}); "
                                f"bind the value once, to {name}")

    def _comp_of(self, ref: str, where: str) -> _Comp:
        comp = self.comps.get(ref.partition(".")[0])
        if comp is None:
            raise UserError(f"{where}: no component {ref.partition('.')[0]!r}; {self.known()}")
        return comp

    def _alias(self, name: str, value, where: str) -> bool:
        """Set every target of the system parameter ``name`` (:meth:`_aliases`); False if none."""
        top = self.system.get("name") or ""
        if name not in self.aliases and name.startswith(top + ".") and name[len(top) + 1:] in self.aliases:
            name = name[len(top) + 1:]  # a system connector as --set names it: <system>.Input_cref
        if name not in self.aliases:
            return False
        targets, _ = self.aliases[name]
        for kind, owner, param in targets:
            if kind == "connector":
                comp = self.comps[owner]
                var = self._settable(comp, param, where)
                comp.params[param] = self._resource(var, from_cli(value, var, where), where, name)
            else:
                value = self._user_path(name, value, where)
                if isinstance(value, str) and value.startswith(RESOURCES):
                    path = self.root.resolve(value, where)
                    if not path.is_file():
                        raise UserError(f"{where}: {value} not found in the SSP ({self.root.show(path)})")
                    value = str(path.resolve())
                self.observers[owner].settings[param] = _setting(str(value)) if isinstance(value, str) else value
                self.observers[owner].setting_signals.pop(param, None)
                self.observers[owner].setting_parameters.pop(param, None)
        return True

    def _overrides(self, overrides: dict) -> None:
        for cname, values in overrides.items():
            values = {k: v for k, v in values.items()
                      if not self._stop_time(f"{cname}.{k}", v, f"--set {cname}.{k}", "--set")
                      and not self._alias(f"{cname}.{k}", v, f"--set {cname}.{k}")
                      and not self._observer_setting(f"{cname}.{k}", v, f"--set {cname}.{k}")}
            if not values:
                continue
            comp = self.comps.get(cname)
            nested = [c for c in self.comps if c.startswith(cname + ".")]
            if comp is None and nested:  # a nested system's component: --set sub.comp.param=...
                for key, value in values.items():
                    comp, v = self._split(ParamValue(f"{cname}.{key}", "", value, None, None, f"--set {cname}.{key}"))
                    where = f"--set {comp.name}.{v.name}"
                    var = self._settable(comp, v.name, where)
                    comp.params[v.name] = self._resource(var, from_cli(value, var, where), where, f"{comp.name}.{v.name}")
                continue
            if comp is None:
                first = next(iter(values), "?")
                raise UserError(f"--set {cname}.{first}: no component {cname!r}"
                                f"{_closest(cname, [*self.comps, *self.observers])}; {self.known()}")
            for name, value in values.items():
                where = f"--set {cname}.{name}"
                var = self._settable(comp, name, where)
                typed = from_cli(value, var, where)  # a bad value is named first, as before
                self._not_shared(f"{cname}.{name}", value, where, f"--set {{}}={value}")
                comp.params[name] = self._resource(var, typed, where, f"{cname}.{name}")

    # -- time ---------------------------------------------------------------------------------
    def _time(self, start, stop, step, need: bool):
        """Start, stop and step; ``self.step_from`` says where the step came from: --step-size,
        our annotation or the OSP one on ssd:DefaultExperiment, else the smallest
        DefaultExperiment stepSize of the components' FMUs."""
        self.step_from = "--step-size" if step is not None else ""
        self.stop_from = "--stop-time" if stop is not None else "ssd:DefaultExperiment"
        if stop is None and self.stop_time is not None:
            stop, self.stop_from = self.stop_time
        de = self.doc.find("ssd:DefaultExperiment", NS)
        if de is not None:
            start = start if start is not None else self._number(de, "startTime")
            stop = stop if stop is not None else self._number(de, "stopTime")
        if step is None:
            step, self.step_from = self._step(de)
        if step is None:
            step, self.step_from = self._fmu_step()
        start = 0.0 if start is None else float(start)
        if not need and (stop is None or step is None):
            return start, stop if stop is not None else start + 1.0, step or 1.0
        if stop is None:
            raise UserError(f"{self.file}: no stop time: ssd:DefaultExperiment has no stopTime "
                            "and none was given (--stop-time)")
        if step is None:
            raise UserError(f"{self.file}: no step size: no {EXPERIMENT} (rf:FixedStep), {OSP} or {VICO} annotation "
                            "on ssd:DefaultExperiment, no DefaultExperiment stepSize in any FMU, and no "
                            "--step-size")
        stop, step = float(stop), float(step)
        n_steps(start, stop, step, self.file)
        return start, stop, step

    def _master(self) -> str | None:
        """The master the experiment prefers: ``<rf:FixedStep master="container"/>`` in our
        annotation on ssd:DefaultExperiment (a one-line error for a master railfmu lacks)."""
        de = self.doc.find("ssd:DefaultExperiment", NS)
        a = self._annotation(de, EXPERIMENT) if de is not None else None
        el = a.find("rf:FixedStep", NS) if a is not None else None
        if el is None or el.get("master") is None:
            return None
        from railfmu.fmus.cosim.masters import MASTERS

        name = el.get("master")
        if name not in MASTERS:
            raise UserError(f"{self.at(el)}: FixedStep master={name!r}: choose one of {', '.join(MASTERS)}")
        return name

    def _step(self, de) -> tuple[float | None, str]:
        """Our rf:FixedStep, else libcosim's osp:FixedStepAlgorithm (on ssd:DefaultExperiment),
        else OMSimulator's oms:FixedStepMaster on the top-level system (what ``railfmu
        export`` writes too), else on a nested one (the smallest)."""
        if de is not None:
            a = self._annotation(de, EXPERIMENT)
            fs = a.find("rf:FixedStep", NS) if a is not None else None
            if fs is not None and fs.get("stepSize") is not None:  # it may name just the master
                return self._number(fs, "stepSize"), f"the {EXPERIMENT} annotation"
            a = self._annotation(de, OSP)
            fs = a.find("osp:Algorithm/osp:FixedStepAlgorithm", NS) if a is not None else None
            if fs is not None:
                return self._number(fs, "baseStepSize"), f"the {OSP} annotation"
            # Vico's (its files use two namespaces and two element names for it)
            a = self._annotation(de, VICO)
            fs = next((el for el in (a.iter() if a is not None else [])
                       if isinstance(el.tag, str) and etree.QName(el).localname in ("FixedStepAlgorithm", "FixedStepMaster")
                       and el.get("baseStepSize") is not None), None)
            if fs is not None:
                return self._number(fs, "baseStepSize"), f"the {VICO} annotation"
        for systems in ([self.system], self.flat.systems):
            steps = []
            for el in systems:
                a = self._annotation(el, OMS)
                fs = a.find("oms:Annotations/oms:SimulationInformation/oms:FixedStepMaster", NS) if a is not None else None
                if fs is not None and fs.get("stepSize") is not None:
                    steps.append(self._number(fs, "stepSize"))
            if steps:
                return min(steps), f"the {OMS} annotation (oms:FixedStepMaster)"
        return None, ""

    def _fmu_step(self) -> tuple[float | None, str]:
        """The smallest DefaultExperiment stepSize among the components' FMUs."""
        steps = []
        for c in self.comps.values():
            de = c.md.defaultExperiment
            text = de.stepSize if de is not None else None
            try:
                value = float(text) if text is not None else None
            except ValueError:
                raise UserError(f"{self.file}: Component {c.name!r}: {c.fmu.name} DefaultExperiment "
                                f"stepSize={text!r} is not a number") from None
            if value is not None and value > 0 and math.isfinite(value):
                steps.append((value, c.name, c.fmu.name))
        if not steps:
            return None, ""
        h, name, fmu = min(steps)
        return h, f"the smallest DefaultExperiment stepSize of the FMUs ({name}: {fmu}, {h:g} s)"

    def _number(self, el, attr: str) -> float | None:
        text = el.get(attr)
        if text is None:
            return None
        try:
            return float(text)
        except ValueError:
            raise UserError(f"{self.at(el)}: {local(el)} {attr}={text!r} is not a number") from None

    # -- our annotations: recorder and observers ------------------------------------------
    @staticmethod
    def _annotation(parent, kind: str):
        return next((a for a in parent.iterfind("ssd:Annotations/ssc:Annotation", NS)
                     if a.get("type") == kind), None)

    def _annotations(self) -> tuple[list[str], list[ObserverSpec]]:
        record: list[str] = []
        a = self._annotation(self.system, RECORDER)
        for r in a.iterfind("rf:Recorder/rf:Record", NS) if a is not None else []:
            record.append(self._signal(r, f"{self.at(r)}: Record"))
        a = self._annotation(self.system, OBSERVERS)
        observers = [self._observer(o) for o in a.iterfind("rf:Observers/rf:Observer", NS)] if a is not None else []
        if record:  # observers read recorded signals: make sure theirs are recorded
            record += [s for o in observers for s in o.signals]
        return list(dict.fromkeys(record)), observers

    def _signal(self, el, where: str, attr: str = "connector") -> str:
        ref = el.get(attr)
        if not ref:
            raise UserError(f"{where}: no connector attribute (component.variable)")
        for name in sorted(self.comps, key=len, reverse=True):
            if ref.startswith(name + "."):
                comp, var = self.comps[name], ref[len(name) + 1:]
                if var not in comp.vars:
                    raise UserError(f"{where} {ref!r}: {comp.fmu.name} has no variable {var!r}")
                return ref
        raise UserError(f"{where} {ref!r}: no component {ref.partition('.')[0]!r}; {self.known()}")

    def _observer(self, el) -> ObserverSpec:
        """``rf:Observer name class [samplePeriod] [sampling="periodic|event"] [offline]`` with
        ``rf:Measurement name connector [valid]``, ``rf:Input`` (known inputs), ``rf:Truth``
        and ``rf:Setting`` children (``value``, or ``connector``: the signal's value at the
        observer's first sample, e.g. an INS's initial state from the vehicle's start)."""
        name, cls = el.get("name"), el.get("class")
        where = f"{self.at(el)}: Observer {name!r}"
        if not name or not cls:
            raise UserError(f"{where}: needs a name and a class attribute")

        def named(tag: str) -> dict:
            out = {}
            for e in el.iterfind(f"rf:{tag}", NS):
                if not e.get("name"):
                    raise UserError(f"{self.at(e)}: Observer {name!r}: {tag} without a name")
                out[e.get("name")] = e
            return out

        def bound(tag: str) -> dict[str, str]:
            return {k: self._signal(e, f"{self.at(e)}: Observer {name!r} {tag} {k!r}") for k, e in named(tag).items()}

        period = self._number(el, "samplePeriod")
        if period is not None and not (period > 0 and math.isfinite(period)):
            raise UserError(f"{where}: samplePeriod {period:g} must be a positive number of seconds")
        sampling = el.get("sampling")
        if sampling not in (None, "periodic", "event"):
            raise UserError(f"{where}: sampling {sampling!r} must be 'periodic' or 'event'")
        offline = el.get("offline", "false")
        if offline not in ("true", "false"):
            raise UserError(f"{where}: offline {offline!r} must be true or false")
        valid = {}
        for k, e in named("Measurement").items():
            if e.get("valid") is not None:
                flag = self._signal(e, f"{self.at(e)}: Observer {name!r} Measurement {k!r} valid",
                                    attr="valid")
                valid[k] = flag
        settings, setting_signals, setting_parameters = {}, {}, {}
        for k, e in named("Setting").items():
            given = [a for a in ("value", "connector", "parameter") if e.get(a) is not None]
            if len(given) > 1:
                raise UserError(f"{self.at(e)}: Observer {name!r} Setting {k!r}: give one of value, connector "
                                f"or parameter, not {' and '.join(given)}")
            if e.get("connector") is not None:  # the signal's value at the observer's first sample
                setting_signals[k] = self._signal(e, f"{self.at(e)}: Observer {name!r} Setting {k!r}")
            elif e.get("parameter") is not None:  # the parameter's final value (after variant, --set)
                setting_parameters[k] = self._parameter_ref(e, f"{self.at(e)}: Observer {name!r} Setting {k!r}")
            else:
                settings[k] = _setting(e.get("value", ""))
        spec = ObserverSpec(
            name, cls, measurements=bound("Measurement"), inputs=bound("Input"), truth=bound("Truth"),
            settings=settings, setting_signals=setting_signals, setting_parameters=setting_parameters,
            valid=valid, period=period, event=None if sampling is None else sampling == "event",
            offline=offline == "true")
        spec.units = {sig: u for sig in spec.signals if (u := self._signal_unit(sig, where)) is not None}
        return spec

    def _parameter_ref(self, el, where: str) -> str:
        """``component.parameter`` of an ``rf:Setting parameter=``: a parameter of a component."""
        ref = el.get("parameter")
        for name in sorted(self.comps, key=len, reverse=True):
            if ref.startswith(name + "."):
                comp, param = self.comps[name], ref[len(name) + 1:]
                var = comp.vars.get(param)
                if var is None:
                    raise UserError(f"{where}: parameter {ref!r}: {comp.fmu.name} has no variable {param!r}")
                if var.causality != "parameter":
                    raise UserError(f"{where}: parameter {ref!r} is a(n) {var.causality}, not a parameter")
                return ref
        raise UserError(f"{where}: parameter {ref!r}: no component {ref.partition('.')[0]!r}; {self.known()}")

    def _setting_parameters(self, spec: ObserverSpec) -> None:
        """Put each parameter-bound setting's value into ``spec.settings``: the parameter as the
        SSP binds it (after the variant and ``--set``), else its FMU start value, in the FMU's
        unit. Then the reserved setting ``enabled`` must be a Boolean."""
        for k, ref in spec.setting_parameters.items():
            name = next(n for n in sorted(self.comps, key=len, reverse=True) if ref.startswith(n + "."))
            comp, param = self.comps[name], ref[len(name) + 1:]
            if param in comp.params:
                spec.settings[k] = comp.params[param]
            else:
                var = comp.vars[param]
                convert = {"Real": float, "Integer": int, "Boolean": lambda x: str(x).lower() in ("true", "1"),
                           "String": str}.get(var.type, str)
                spec.settings[k] = convert(var.start) if var.start is not None else None
        enabled = spec.settings.get("enabled", True)
        if not isinstance(enabled, bool):
            raise UserError(f"{self.file}: Observer {spec.name!r}: setting enabled={enabled!r} must be true or false")

    def _signal_unit(self, signal: str, where: str) -> Unit | None:
        """The unit of a recorded signal: its FMU variable's, else the one its SSD connector
        declares (an FMU variable without a unit, e.g. a generic sensor channel)."""
        comp = next(c for n, c in sorted(self.comps.items(), key=lambda nc: -len(nc[0]))
                    if signal.startswith(n + "."))
        var = comp.vars[signal[len(comp.name) + 1:]]
        name = var.unit or comp.connectors.get(var.name)
        if not name:
            return None
        unit = self.ssd_units.then(comp.units).get(name)
        if unit is None:
            raise UserError(f"{where}: {signal}: unit {name!r} is not defined (declare it in ssd:Units)")
        return unit

    def _unconnected(self, connections: list[Connection]) -> list[str]:
        fed = {(c.dst, c.dst_var) for c in connections}
        ported = {(o, p) for targets, _ in self.aliases.values() for kind, o, p in targets if kind == "connector"}
        out = []
        for comp in self.comps.values():
            for var in comp.md.modelVariables:
                # an input the SSD/SSV binds to a value is unconnected on purpose: no warning
                if (var.causality == "input" and (comp.name, var.name) not in fed
                        and var.name not in comp.params and (comp.name, var.name) not in ported):
                    out.append(f"{comp.name}.{var.name}: input not connected; keeps its start value "
                               f"{_show(var.start)}")
        return out


def _closest(name: str, names: list[str]) -> str:
    """`` (did you mean 'a' or 'b'?)`` for the names closest to a mistyped one (difflib), else ''."""
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.6)
    return f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""


def _setting(text: str) -> Value:
    """An observer setting as bool, int, float or str (in that order of preference)."""
    t = text.strip()
    if t in ("true", "false"):
        return t == "true"
    for parse in (int, float):
        try:
            return parse(t)
        except ValueError:
            pass
    return text


def _show(value) -> str:
    try:
        return f"{float(value):g}" if not isinstance(value, bool) else str(value).lower()
    except (TypeError, ValueError):
        return repr(value)
