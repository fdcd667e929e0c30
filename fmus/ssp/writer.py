"""A :class:`railfmu.fmus.cosim.system.System` as a self-contained ``.ssp``: ``SystemStructure.ssd`` plus its
FMUs in ``resources/``.

What other importers need is kept explicit: every component carries ONE inline
``ssv:ParameterSet`` with its final values (libcosim applies component-level bindings only),
the step size is written as our ``rf:FixedStep``, as libcosim's ``osp:FixedStepAlgorithm``
and as OMSimulator's fixed-step master (an ``org.openmodelica`` annotation, the FIRST of the
system's annotations: OMSimulator 3.0 reads only the first ``ssc:Annotation`` of a system),
and each connection's affine map is a ``ssc:LinearTransformation``.

String parameters (a measured table's file and column names, a track profile, a line file)
reach the FMU without ``ssv:String``, which OMSimulator 3.0 does not read (it logs
"Failed to import ssv:Parameter: Unknown ParameterBinding-type" for each): a component whose
String values differ from its FMU's start values gets its own copy of the FMU whose
modelDescription.xml has them as start values, with the files they name in the copy's
``resources/`` and named relative to there (our runtime takes its String start values from
the unpacked modelDescription.xml and resolves a relative file against ``resources/``,
which every importer provides). The copy's GUID is the binary's plus ``-`` and a suffix (the
runtime accepts that), so importers that unpack an FMU once per GUID (libcosim) keep the
copies apart. The SSD keeps the String values for railfmu in an ``org.railfmu.strings``
annotation (an ``ssv:ParameterSet`` of ``component.parameter`` names), which other tools
ignore; reading the archive back gives an equal System (apart from paths and file names).

``ssp_version="2.0"`` writes the same archive as SSP 2.0 (same namespaces, ``version="2.0"`` on
the SSD and on each parameter set); an FMI 3.0 component's connectors and parameters carry
the sized types of its variables (``ssc:Float64``/``ssv:Float64``, ``Int32``), since SSP 2.0
wants a connector's type to be its variable's; an FMI 2.0 component keeps ``Real`` and
``Integer``, which SSP 2.0 keeps as FMI 2.0's types. Each inline parameter set of a 2.0
archive defines the units its values name (``ssv:Units``: a unit is file-scoped).

A generic FMU (StepSource, SensorNoise, SignalTable) has unit-less channels; the SSD gives
them a unit on its connectors. Importers that take a connection's units from the FMUs
(OMSimulator 3.0: "Unit mismatch in connection") would refuse ``fault.y -> coach.k1``, so
such a component gets its own copy of the FMU whose modelDescription declares those units
(a unit is no part of the C code: same binary). The SSD connectors keep the units, so
railfmu reads the same System.
"""

from __future__ import annotations

import hashlib
import io
import os
import zipfile
from pathlib import Path

from lxml import etree

from railfmu.fmus.ssp.units import BASE, OURS, Units, from_fmu
from railfmu.fmus.ssp.xmltools import (
    NS,
    OMS_NS,
    OSP_NS,
    RF_NS,
    SSC_NS,
    SSD_NS,
    SSV_NS,
    schema_problems,
)
from railfmu.fmus.cosim.slave import FMI3_NAME, fmi_version
from railfmu.fmus.cosim.system import System, check_system
from railfmu.models.errors import UserError

_KINDS = ("input", "output", "parameter", "calculatedParameter")  # causalities a connector can show
SSP_VERSIONS = ("1.0", "2.0")


def write_ssp(system: System, out: Path, ssp_version: str = "1.0") -> Path:
    """Write ``system`` to the zip archive ``out`` (replaced atomically) as SSP ``ssp_version``
    ("1.0" or "2.0") and return its path."""
    out = Path(out)
    if ssp_version not in SSP_VERSIONS:
        raise UserError(f"--ssp {ssp_version}: railfmu writes SSP 1.0 and 2.0 (1.0 or 2.0)")
    check_system(system)
    mds = {c.name: c.md for c in system.components}
    files = {c.name: _parameter_files(c) for c in system.components}
    strings = {c.name: _string_values(c, files[c.name]) for c in system.components}
    baked = {c.name: _baked(c, strings[c.name]) for c in system.components}
    generic = _generic_units(system)
    own = {c.name for c in system.components if generic.get(c.name) or baked[c.name] or files[c.name]}
    resources = _resource_names(system, own)
    doc = _document(system, mds, resources, strings, generic, ssp_version)
    problems = schema_problems(doc, "ssd", "SystemStructure.ssd")
    if problems:  # our own output: a bug, not a user error
        raise RuntimeError(f"write_ssp produced an invalid SSD: {problems[0]}")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("SystemStructure.ssd", etree.tostring(doc, xml_declaration=True, encoding="UTF-8",
                                                              pretty_print=True))
            written = set()
            for c in system.components:
                if resources[c.name] in written:
                    continue
                written.add(resources[c.name])
                if c.name in own:
                    zf.writestr(resources[c.name], _instance_copy(Path(c.fmu), c.name, dict(files[c.name].values()),
                                                                  generic.get(c.name), baked[c.name]))
                else:
                    zf.write(c.fmu, resources[c.name])
        os.replace(tmp, out)  # a reader never sees half an archive
    finally:
        tmp.unlink(missing_ok=True)
    return out


def _generic_units(system: System) -> dict[str, dict]:
    """Component -> {variable: Unit} for the Real variables its FMU declares without a unit that
    the system gives one: the SSD's connector (Component.units), else an observer's signal."""
    observed = {sig: u for o in system.observers for sig, u in o.units.items()}
    out: dict[str, dict] = {}
    for c in system.components:
        units = dict(c.units)
        for v in c.md.modelVariables:
            if v.type == "Real" and not v.unit and v.name not in units and f"{c.name}.{v.name}" in observed:
                units[v.name] = observed[f"{c.name}.{v.name}"]
        units = {n: u for n, u in units.items()
                 if n in c.variables and c.variables[n].type == "Real" and not c.variables[n].unit}
        if units:
            out[c.name] = units
    return out


def _resource_names(system: System, own: set[str] = frozenset()) -> dict[str, str]:
    """Component -> 'resources/<file>.fmu': one copy per FMU file, distinct names; a component
    in ``own`` (units or String start values of its own) has its own copy."""
    by_file: dict[Path, str] = {}
    out = {}
    for c in system.components:
        if c.name in own:
            out[c.name] = f"resources/{c.name}_{Path(c.fmu).name}"
            continue
        fmu = Path(c.fmu).resolve()
        if fmu not in by_file:
            name = f"resources/{fmu.name}"
            by_file[fmu] = name if name not in by_file.values() else f"resources/{c.name}_{fmu.name}"
        out[c.name] = by_file[fmu]
    return out


def _string_values(c, files: dict[str, tuple[Path, str]]) -> dict[str, str]:
    """The component's String parameter values as the archive gives them: a file it names by
    its name in the FMU copy's resources/."""
    out = {}
    for name, value in c.parameters.items():
        var = c.variables.get(name)
        if var is not None and var.type == "String":
            out[name] = files[name][1] if name in files else str(value)
    return out


def _baked(c, strings: dict[str, str]) -> dict[str, str]:
    """The String values that differ from the FMU's start values (its copy declares them)."""
    start = {v.name: v.start or "" for v in c.md.modelVariables if v.type == "String"}
    return {n: v for n, v in strings.items() if v != start.get(n, "")}


def _parameter_files(c) -> dict[str, tuple[Path, str]]:
    """String parameter -> (the existing file it names by absolute path, its name in the
    FMU's resources/); names are made distinct from each other and from the FMU's own."""
    with zipfile.ZipFile(c.fmu) as z:
        taken = {n.removeprefix("resources/") for n in z.namelist() if n.startswith("resources/")}
    out: dict[str, tuple[Path, str]] = {}
    for name, value in c.parameters.items():
        var = c.variables.get(name)
        if (var is None or var.type != "String" or not isinstance(value, str) or not value
                or not Path(value).is_absolute() or not Path(value).is_file()):
            continue
        path = Path(value).resolve()
        same = next((inner for p, inner in out.values() if p == path), None)
        inner = same or (path.name if path.name not in taken else f"{name}_{path.name}")
        taken.add(inner)
        out[name] = (path, inner)
    return out


def _instance_copy(fmu: Path, component: str, files: dict[Path, str], units: dict | None,
                   strings: dict[str, str]) -> bytes:
    """The FMU archive with ``files`` ({path: name}) added to its resources/, and in its
    modelDescription ``units`` ({variable: Unit}) declared, ``strings`` ({variable: value})
    as start values and a GUID of its own (the rest copied unchanged)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "modelDescription.xml":
                data = _instance_md(data, component, units or {}, strings)
            dst.writestr(info, data)
        for path, inner in files.items():
            dst.write(path, f"resources/{inner}")
    return buf.getvalue()


_MD_AFTER_UNITS = ("TypeDefinitions", "LogCategories", "DefaultExperiment", "VendorAnnotations",
                   "ModelVariables")  # FMI 2.0 order: UnitDefinitions comes before these


def _instance_md(md_xml: bytes, component: str, units: dict, strings: dict[str, str]) -> bytes:
    """modelDescription.xml with ``unit`` on the Real of each variable in ``units`` (each unit
    defined in UnitDefinitions with its SI base units, factor and offset), ``start`` on the
    String of each variable in ``strings``, and the GUID followed by "-" and a digest of the
    component's name and these changes (the runtime accepts such a GUID)."""
    root = etree.fromstring(md_xml)
    for sv in root.iterfind("ModelVariables/ScalarVariable"):
        if sv.get("name") in units:
            sv.find("Real").set("unit", units[sv.get("name")].name)
        if sv.get("name") in strings:
            sv.find("String").set("start", strings[sv.get("name")])
    for var in root.iterfind("ModelVariables/Float64"):  # FMI 3.0: the unit on the variable itself
        if var.get("name") in units:
            var.set("unit", units[var.get("name")].name)
    for var in root.iterfind("ModelVariables/String"):  # FMI 3.0: <Start value=.../> children
        if var.get("name") in strings:
            for old in var.findall("Start"):
                var.remove(old)
            etree.SubElement(var, "Start", value=strings[var.get("name")])
    digest = hashlib.sha256(repr((component, sorted((n, u.name) for n, u in units.items()),
                                  sorted(strings.items()))).encode()).hexdigest()[:12]
    token = "guid" if root.get("guid") is not None else "instantiationToken"  # FMI 2.0 / 3.0
    root.set(token, f"{root.get(token)}-{digest}")
    if not units:
        return etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    defs = root.find("UnitDefinitions")
    if defs is None:
        defs = etree.Element("UnitDefinitions")
        nxt = next(el for el in root if el.tag in _MD_AFTER_UNITS)
        nxt.addprevious(defs)
    have = {u.get("name") for u in defs.iterfind("Unit")}
    for u in sorted({u.name: u for u in units.values()}.values(), key=lambda u: u.name):
        if u.name in have:
            continue
        base = etree.SubElement(etree.SubElement(defs, "Unit", name=u.name), "BaseUnit")
        for b, e in zip(BASE, u.exponents):
            if e:
                base.set(b, str(e))
        if u.factor != 1.0:
            base.set("factor", _num(u.factor))
        if u.offset != 0.0:
            base.set("offset", _num(u.offset))
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8")


def _sub(parent, tag: str, **attrs):
    prefix, _, name = tag.partition(":")
    el = etree.SubElement(parent, f"{{{NS[prefix]}}}{name}")
    for k, v in attrs.items():
        if v is not None:
            el.set(k, v)
    return el


def _num(x: float) -> str:
    return repr(float(x))  # shortest text that reads back to the same double


def _type(v, md, version: str) -> str:
    """The SSP type of a variable: SSP 2.0 names an FMI 3.0 variable's sized type."""
    return FMI3_NAME.get(v.type, v.type) if version == "2.0" and fmi_version(md) == 3 else v.type


def _document(system: System, mds: dict, resources: dict[str, str], strings: dict, generic: dict,
              version: str = "1.0"):
    nsmap = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": SSV_NS, "rf": RF_NS, "osp": OSP_NS, "oms": OMS_NS}
    doc = etree.Element(f"{{{SSD_NS}}}SystemStructureDescription", nsmap=nsmap, version=version,
                        name=system.name)
    if system.description:
        doc.set("description", system.description)
    sys_el = _sub(doc, "ssd:System", name=system.name)
    elements = _sub(sys_el, "ssd:Elements")
    used_units: dict[str, Units] = {}
    shown = _shown_variables(system)
    for c in system.components:
        md = mds[c.name]
        units = Units(from_fmu(md)).then(OURS)
        comp = _sub(elements, "ssd:Component", name=c.name, source=resources[c.name],
                    type="application/x-fmu-sharedlibrary")
        declared = [v for v in md.modelVariables if v.name in shown.get(c.name, ()) and v.causality in _KINDS]
        if declared:
            connectors = _sub(comp, "ssd:Connectors")
            for v in declared:
                conn = _sub(connectors, "ssd:Connector", name=v.name, kind=v.causality)
                unit, where = v.unit, units
                given = generic.get(c.name, {}).get(v.name)
                if not unit and given is not None:  # now declared by this component's FMU copy
                    unit, where = given.name, Units({given.name: given}).then(OURS)
                _sub(conn, f"ssc:{_type(v, md, version)}", unit=unit if v.type == "Real" and unit else None)
                if v.type == "Real" and unit:
                    used_units[unit] = where
        if set(c.parameters) - set(strings[c.name]):
            _parameters(comp, c, {v.name: v for v in md.modelVariables}, strings[c.name], version,
                        units if version == "2.0" else None)
    if system.connections:
        conns = _sub(sys_el, "ssd:Connections")
        variables = {c.name: {v.name: v for v in mds[c.name].modelVariables} for c in system.components}
        for k in system.connections:
            su = variables[k.src][k.src_var].unit or _unit_name(generic, k.src, k.src_var)
            du = variables[k.dst][k.dst_var].unit or _unit_name(generic, k.dst, k.dst_var)
            # the map below is complete: a reader must not convert units on top of it
            suppress = "true" if su and du and su != du else None
            el = _sub(conns, "ssd:Connection", startElement=k.src, startConnector=k.src_var,
                      endElement=k.dst, endConnector=k.dst_var, suppressUnitConversion=suppress)
            if not k.identity:
                _sub(el, "ssc:LinearTransformation", factor=_num(k.factor), offset=_num(k.offset))
    _system_annotations(sys_el, system, strings, version)
    _units(doc, used_units)
    _experiment(doc, system)
    return doc


def _unit_name(generic: dict, comp: str, var: str) -> str | None:
    u = generic.get(comp, {}).get(var)
    return u.name if u is not None else None


def _shown_variables(system: System) -> dict[str, set[str]]:
    """Variables that get a connector: connected, recorded, or read by an observer."""
    out: dict[str, set[str]] = {}
    refs = [(k.src, k.src_var) for k in system.connections] + [(k.dst, k.dst_var) for k in system.connections]
    names = [c.name for c in system.components]
    signals = list(system.record) + [s for o in system.observers for s in o.signals]
    for s in signals:
        comp = next((n for n in sorted(names, key=len, reverse=True) if s.startswith(n + ".")), None)
        if comp:
            refs.append((comp, s[len(comp) + 1:]))
    for comp, var in refs:
        out.setdefault(comp, set()).add(var)
    return out


def _parameters(comp_el, c, variables: dict, strings: dict[str, str], version: str = "1.0",
                units: Units | None = None) -> None:
    """One inline parameter set with the component's final values (what libcosim reads),
    except its String values (``strings``: the FMU copy's start values, see the module
    docstring); with ``units`` (SSP 2.0), an ``ssv:Units`` defining the units its values name."""
    sized = version == "2.0" and fmi_version(c.md) == 3
    binding = _sub(_sub(comp_el, "ssd:ParameterBindings"), "ssd:ParameterBinding")
    pset = _sub(_sub(binding, "ssd:ParameterValues"), "ssv:ParameterSet", version=version, name=c.name)
    params = _sub(pset, "ssv:Parameters")
    named: dict[str, Units] = {}
    for name, value in c.parameters.items():
        if name in strings:
            continue
        var = variables.get(name)
        p = _sub(params, "ssv:Parameter", name=name)
        t = var.type if var is not None else {bool: "Boolean", int: "Integer", str: "String"}.get(type(value))
        if t == "Boolean":
            _sub(p, "ssv:Boolean", value="true" if value else "false")
        elif t in ("Integer", "Enumeration"):
            _sub(p, "ssv:Int32" if sized else "ssv:Integer", value=str(int(value)))
        elif t == "String":
            _sub(p, "ssv:String", value=str(value))
        else:
            unit = var.unit if var is not None and var.unit else None
            _sub(p, "ssv:Float64" if sized else "ssv:Real", value=_num(value), unit=unit)
            if unit and units is not None:
                named[unit] = units
    if named:
        _units(pset, named, "ssv:Units")


def _units(doc, used: dict[str, Units], tag: str = "ssd:Units") -> None:
    """ssd:Units for every unit a connector names (the schema wants them defined in the file),
    or a parameter set's ssv:Units after its ssv:Parameters."""
    defined = [(name, units.get(name)) for name, units in sorted(used.items())]
    defined = [(n, u) for n, u in defined if u is not None]
    if not defined:
        return
    prefix, _, name = tag.partition(":")
    units_el = etree.Element(f"{{{NS[prefix]}}}{name}")
    # order: System, Enumerations, Units, DefaultExperiment; Parameters, Enumerations, Units
    doc.find("ssd:System" if prefix == "ssd" else "ssv:Parameters", NS).addnext(units_el)
    for name, u in defined:
        base = {b: str(e) for b, e in zip(BASE, u.exponents) if e}
        if u.factor != 1.0:
            base["factor"] = _num(u.factor)
        if u.offset != 0.0:
            base["offset"] = _num(u.offset)
        _sub(_sub(units_el, "ssc:Unit", name=name), "ssc:BaseUnit", **base)


def _experiment(doc, system: System) -> None:
    de = _sub(doc, "ssd:DefaultExperiment", startTime=_num(system.start_time), stopTime=_num(system.stop_time))
    annotations = _sub(de, "ssd:Annotations")
    a = _sub(annotations, "ssc:Annotation", type="org.railfmu.experiment")
    _sub(a, "rf:FixedStep", stepSize=_num(system.step_size), master=system.master)
    a = _sub(annotations, "ssc:Annotation", type="com.opensimulationplatform")  # what libcosim reads
    _sub(_sub(a, "osp:Algorithm"), "osp:FixedStepAlgorithm", baseStepSize=_num(system.step_size))


def _system_annotations(sys_el, system: System, strings: dict[str, dict[str, str]], version: str = "1.0") -> None:
    annotations = _sub(sys_el, "ssd:Annotations")
    # OMSimulator 3.0 (SystemWC) reads only the first annotation of a system, and without its
    # own it has no step size: its fixed-step master comes first, ours are ignorable after it
    oms = _sub(_sub(_sub(annotations, "ssc:Annotation", type="org.openmodelica"), "oms:Annotations"),
               "oms:SimulationInformation")
    _sub(oms, "oms:FixedStepMaster", description="oms-ma", stepSize=_num(system.step_size))
    if any(strings.values()):  # String values for railfmu's reader (the FMU copies carry them for the rest)
        pset = _sub(_sub(annotations, "ssc:Annotation", type="org.railfmu.strings"), "ssv:ParameterSet",
                    version=version, name="strings")
        params = _sub(pset, "ssv:Parameters")
        for comp, values in strings.items():
            for name, value in values.items():
                _sub(_sub(params, "ssv:Parameter", name=f"{comp}.{name}"), "ssv:String", value=value)
    if system.observers:
        observers = _sub(_sub(annotations, "ssc:Annotation", type="org.railfmu.observers"), "rf:Observers")
        for o in system.observers:
            el = _sub(observers, "rf:Observer", name=o.name)
            el.set("class", o.cls)
            if o.period is not None:
                el.set("samplePeriod", _num(o.period))
            if o.event is not None:
                el.set("sampling", "event" if o.event else "periodic")
            if o.offline:
                el.set("offline", "true")
            for tag, table in (("rf:Measurement", o.measurements), ("rf:Input", o.inputs), ("rf:Truth", o.truth)):
                for k, ref in table.items():
                    _sub(el, tag, name=k, connector=ref, valid=o.valid.get(k) if tag == "rf:Measurement" else None)
            for k, v in o.settings.items():  # a parameter-bound one stays bound (a --set on the archive moves it)
                if k in o.setting_parameters:
                    _sub(el, "rf:Setting", name=k, parameter=o.setting_parameters[k])
                else:
                    _sub(el, "rf:Setting", name=k, value=str(v).lower() if isinstance(v, bool) else str(v))
            for k, ref in o.setting_signals.items():
                _sub(el, "rf:Setting", name=k, connector=ref)
    if system.study:  # a copied or exported experiment keeps its study's metrics and figures
        _sub(_sub(annotations, "ssc:Annotation", type="org.railfmu.study"), "rf:Study", name=system.study)
    if system.record:
        recorder = _sub(_sub(annotations, "ssc:Annotation", type="org.railfmu.recorder"), "rf:Recorder")
        for ref in system.record:
            _sub(recorder, "rf:Record", connector=ref)
