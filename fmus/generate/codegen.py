"""Model definition (models/) -> modelDescription.xml + C sources for the shared runtime.

Value references (per FMI type): Real 0 is ``time``; then Real parameters, the internal
integrator step (models with states), inputs, states, outputs. Integer, Boolean and String
variables are numbered from 0 in their own types, in the same order (parameters, inputs,
outputs); Integer and Boolean inputs and outputs are ``discrete``.

For models with expressions, the C equations come from sympy ``ccode`` after common
subexpression elimination, so the FMU computes exactly what :meth:`Model.rhs` lambdifies.
"""

from __future__ import annotations

import hashlib
import re
import uuid
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import sympy as sp

from railfmu.models.base import STEP_SIZE, Model, Output, Parameter, Variable

from railfmu.fmus.generate import GENERATOR
from railfmu.fmus.units import UNITS, check_unit

TAU = sp.Symbol("tau", real=True)  # time since the inputs were set (first-order hold)
LOG_CATEGORIES = {
    "logStatusError": "Errors: bad parameters, illegal call sequences, non-finite values",
    "logStatusWarning": "Warnings",
    "logEvents": "Initialisation and table loading",
    "logAll": "Everything",
}
INTEGRATOR_STEP = "integrator_step"


@dataclass
class Slot:
    var: Variable
    vr: int
    causality: str
    variability: str
    initial: str | None


def layout(model: Model) -> list[Slot]:
    """Every ScalarVariable of the FMU in modelDescription order, with its value reference."""
    for v in model.variables:
        check_unit(v.unit, f"{model.identifier}.{v.name}")
        if v.name in ("time", INTEGRATOR_STEP, "t", STEP_SIZE.name):  # t, h: free symbols
            raise ValueError(f"{model.identifier}: variable name {v.name!r} is reserved")
    counters = {"Real": 1, "Integer": 0, "Boolean": 0, "String": 0}

    def take(t: str) -> int:
        counters[t] += 1
        return counters[t] - 1

    slots = [Slot(Variable("time", "Simulation time", "s", None), 0, "independent", "continuous", None)]
    for p in model.parameters:
        var = "tunable" if p.tunable else "fixed"
        slots.append(Slot(p, take(p.type), "parameter", var, "exact"))
    if model.states:
        step = Parameter(INTEGRATOR_STEP, "Fixed step of the RK4 integrator inside fmi2DoStep; a "
                         "communication step is split into equal sub-steps no longer than this",
                         "s", model.integrator_step, positive=True, source="numerics")
        slots.append(Slot(step, take("Real"), "parameter", "fixed", "exact"))
    for u in model.inputs:
        slots.append(Slot(u, take(u.type), "input", _signal_variability(u), None))
    for s in model.states:
        slots.append(Slot(s, take("Real"), "output", "continuous", "exact"))
    for o in model.outputs:
        slots.append(Slot(o, take(o.type), "output", _signal_variability(o), "calculated"))
    return slots


def _signal_variability(v: Variable) -> str:
    """FMI 2.0 allows variability="continuous" for Real only."""
    return "continuous" if v.type == "Real" else "discrete"


# -- modelDescription.xml --------------------------------------------------------------------
def _fmt(x, type_: str = "Real") -> str:
    if type_ == "Boolean" or isinstance(x, bool):
        return "true" if x else "false"
    if type_ == "Integer":
        return str(int(x))
    if isinstance(x, float):
        return repr(x)
    return str(x)


def _output_dependencies(model: Model, slots: list[Slot]) -> dict[str, str]:
    """Direct feedthrough (Model.feedthrough): from the expression, or as a hand-written model
    declares it; states never depend on inputs."""
    index = {s.var.name: i + 1 for i, s in enumerate(slots)}
    return {s.var.name: " ".join(str(index[n]) for n in
                                 (model.feedthrough(s.var) if isinstance(s.var, Output) else []))
            for s in slots if s.causality == "output"}


def _initial_dependencies(model: Model, o: Output, index: dict[str, int]) -> str | None:
    """InitialUnknowns: the knowns (time, parameters, state starts, inputs) a generated output
    reads in initialisation mode, from its expression; None (omitted: FMI's "all knowns") for
    hand-written C, whose parameter use no definition states."""
    if not model.generated or o.expr is None:
        return None
    free = model.reads(o.expr)
    names = ["time"] if "t" in free else []
    names += [v.name for v in (*model.parameters, *model.inputs, *model.states) if v.name in free]
    return " ".join(str(i) for i in sorted(index[n] for n in names))


def model_description(model: Model, guid: str, source_files: list[str]) -> str:
    slots = layout(model)
    units = sorted({s.var.unit for s in slots if s.var.unit})
    L = ['<?xml version="1.0" encoding="UTF-8"?>',
         f'<fmiModelDescription fmiVersion="2.0" modelName="{model.identifier}" guid="{guid}"',
         f'  description={quoteattr(model.description)} generationTool="{GENERATOR}"',
         '  variableNamingConvention="flat" numberOfEventIndicators="0">',
         f'  <CoSimulation modelIdentifier="{model.identifier}" canHandleVariableCommunicationStepSize="true"',
         '    canGetAndSetFMUstate="true" canSerializeFMUstate="true" canNotUseMemoryManagementFunctions="true"',
         '    providesDirectionalDerivative="false" canInterpolateInputs="false" maxOutputDerivativeOrder="0">',
         '    <SourceFiles>']
    L += [f'      <File name="{f}"/>' for f in source_files]
    L += ['    </SourceFiles>', '  </CoSimulation>', '  <UnitDefinitions>']
    for u in units:
        base = " ".join(f'{k}="{e}"' for k, e in UNITS[u].items())
        L.append(f'    <Unit name="{u}"><BaseUnit {base}/></Unit>')
    L += ['  </UnitDefinitions>', '  <LogCategories>']
    L += [f'    <Category name="{n}" description={quoteattr(d)}/>' for n, d in LOG_CATEGORIES.items()]
    start, stop, step = model.default_experiment
    L += ['  </LogCategories>',
          f'  <DefaultExperiment startTime="{start!r}" stopTime="{stop!r}" stepSize="{step!r}"/>',
          '  <ModelVariables>']
    for i, s in enumerate(slots):
        v = s.var
        desc = v.description + (f" [source: {v.source}]" if v.source else "")
        attrs = (f'name="{v.name}" valueReference="{s.vr}" description={quoteattr(desc)} '
                 f'causality="{s.causality}" variability="{s.variability}"')
        if s.initial and not (s.causality == "parameter"):
            attrs += f' initial="{s.initial}"'
        t = v.type
        ta = []
        if t == "Real" and v.unit:
            ta.append(f'unit="{v.unit}"')
        if t in ("Real", "Integer"):
            if v.min is not None:
                ta.append(f'min="{_fmt(v.min, t)}"')
            if v.max is not None:
                ta.append(f'max="{_fmt(v.max, t)}"')
        if s.initial != "calculated" and s.causality != "independent":
            ta.append(f"start={quoteattr(_fmt(v.start if v.start is not None else '', t))}")
        L.append(f'    <!-- {i + 1} --><ScalarVariable {attrs}><{t} {" ".join(ta)}/></ScalarVariable>')
    L += ['  </ModelVariables>', '  <ModelStructure>', '    <Outputs>']
    index = {s.var.name: i + 1 for i, s in enumerate(slots)}
    deps = _output_dependencies(model, slots)
    for s in slots:
        if s.causality == "output":
            L.append(f'      <Unknown index="{index[s.var.name]}" dependencies="{deps[s.var.name]}"/>')
    L += ['    </Outputs>', '    <InitialUnknowns>']
    for s in slots:
        if s.causality == "output" and s.initial == "calculated":
            init = _initial_dependencies(model, s.var, index)
            L.append(f'      <Unknown index="{index[s.var.name]}"' +
                     (f' dependencies="{init}"/>' if init is not None else '/>'))
    L += ['    </InitialUnknowns>', '  </ModelStructure>', '</fmiModelDescription>', '']
    return "\n".join(L)


# -- FMI 3.0 modelDescription.xml -------------------------------------------------------------
FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
_FMI3_ORDER = ("Real", "Integer", "Boolean", "String")


def fmi3_value_references(slots: list[Slot]) -> dict[str, int]:
    """FMI 3 value references are unique across types (FMI 3.0, 2.4.7.3): Float64 keeps the
    FMI 2 Real numbers (time is 0), Int32, Boolean and String follow in that order, as
    fmus/native/runtime/fmi3_runtime.c maps them back."""
    count = {t: sum(1 for s in slots if s.var.type == t) for t in _FMI3_ORDER}
    base, acc = {}, 0
    for t in _FMI3_ORDER:
        base[t], acc = acc, acc + count[t]
    return {s.var.name: base[s.var.type] + s.vr for s in slots}


def model_description_fmi3(model: Model, token: str) -> str:
    """The FMI 3.0 Co-Simulation modelDescription.xml of the same variables: one element per
    type (Float64, Int32, Boolean, String), ``<ModelStructure>`` with ``Output`` and
    ``InitialUnknown`` whose dependencies are value references (the FMI 2 file's indices
    mapped). The sources are listed in sources/buildDescription.xml (FMI 3 has no
    ``<SourceFiles>``)."""
    slots = layout(model)
    vr3 = fmi3_value_references(slots)
    by_index = {str(i + 1): str(vr3[s.var.name]) for i, s in enumerate(slots)}
    units = sorted({s.var.unit for s in slots if s.var.unit})
    L = ['<?xml version="1.0" encoding="UTF-8"?>',
         f'<fmiModelDescription fmiVersion="3.0" modelName="{model.identifier}" instantiationToken="{token}"',
         f'  description={quoteattr(model.description)} generationTool="{GENERATOR}"',
         '  variableNamingConvention="flat">',
         f'  <CoSimulation modelIdentifier="{model.identifier}" canHandleVariableCommunicationStepSize="true"',
         '    canGetAndSetFMUState="true" canSerializeFMUState="true" providesDirectionalDerivatives="false"',
         '    providesAdjointDerivatives="false" hasEventMode="false" maxOutputDerivativeOrder="0"/>',
         '  <UnitDefinitions>']
    for u in units:
        base = " ".join(f'{k}="{e}"' for k, e in UNITS[u].items())
        L.append(f'    <Unit name="{u}"><BaseUnit {base}/></Unit>')
    L += ['  </UnitDefinitions>', '  <LogCategories>']
    L += [f'    <Category name="{n}" description={quoteattr(d)}/>' for n, d in LOG_CATEGORIES.items()]
    start, stop, step = model.default_experiment
    L += ['  </LogCategories>',
          f'  <DefaultExperiment startTime="{start!r}" stopTime="{stop!r}" stepSize="{step!r}"/>',
          '  <ModelVariables>']
    for s in slots:
        v, t = s.var, s.var.type
        desc = v.description + (f" [source: {v.source}]" if v.source else "")
        attrs = [f'name="{v.name}"', f'valueReference="{vr3[v.name]}"', f"description={quoteattr(desc)}",
                 f'causality="{s.causality}"', f'variability="{s.variability}"']
        if s.initial and s.causality != "parameter":
            attrs.append(f'initial="{s.initial}"')
        if t == "Real" and v.unit:
            attrs.append(f'unit="{v.unit}"')
        if t in ("Real", "Integer"):
            if v.min is not None:
                attrs.append(f'min="{_fmt(v.min, t)}"')
            if v.max is not None:
                attrs.append(f'max="{_fmt(v.max, t)}"')
        has_start = s.initial != "calculated" and s.causality != "independent"
        value = _fmt(v.start if v.start is not None else "", t) if has_start else None
        if t == "String":  # FMI 3: a String's start is a child element (arrays of strings)
            inner = f"<Start value={quoteattr(value)}/>" if has_start else ""
            L.append(f'    <String {" ".join(attrs)}>{inner}</String>')
        else:
            if has_start:
                attrs.append(f"start={quoteattr(value)}")
            L.append(f'    <{FMI3_TYPE[t]} {" ".join(attrs)}/>')
    L += ['  </ModelVariables>', '  <ModelStructure>']
    deps = _output_dependencies(model, slots)
    index = {s.var.name: i + 1 for i, s in enumerate(slots)}

    def as_vrs(indices: str) -> str:
        return " ".join(by_index[i] for i in indices.split())

    for s in slots:
        if s.causality == "output":
            L.append(f'    <Output valueReference="{vr3[s.var.name]}" dependencies="{as_vrs(deps[s.var.name])}"/>')
    for s in slots:
        if s.causality == "output" and s.initial == "calculated":
            init = _initial_dependencies(model, s.var, index)
            L.append(f'    <InitialUnknown valueReference="{vr3[s.var.name]}"' +
                     (f' dependencies="{as_vrs(init)}"/>' if init is not None else '/>'))
    L += ['  </ModelStructure>', '</fmiModelDescription>', '']
    return "\n".join(L)


def build_description_fmi3(model: Model, source_files: list[str]) -> str:
    """sources/buildDescription.xml (FMI 3.0, 2.5.1): the C files to compile, in C99."""
    L = ['<?xml version="1.0" encoding="UTF-8"?>', '<fmiBuildDescription fmiVersion="3.0">',
         f'  <BuildConfiguration modelIdentifier="{model.identifier}">',
         '    <SourceFileSet language="C99">']
    L += [f'      <SourceFile name="{f}"/>' for f in source_files]
    L += ['    </SourceFileSet>', '  </BuildConfiguration>', '</fmiBuildDescription>', '']
    return "\n".join(L)


def guid_of(model: Model, sources: dict[str, str], fmi_version: int = 2) -> str:
    """Deterministic GUID: a hash of everything the archive holds (interface, code, and the
    documentation and resources, so a new example table is packed, not skipped as unchanged)."""
    h = hashlib.sha256()
    h.update(model_description(model, "", list(sources)).encode())
    if fmi_version == 3:
        h.update(model_description_fmi3(model, "").encode())
    for name in sorted(sources):
        h.update(name.encode())
        h.update(sources[name].encode())
    h.update(model.documentation.encode())
    for name in sorted(model.resources):
        h.update(name.encode())
        h.update(model.resources[name].read_bytes())
    return "{" + str(uuid.UUID(bytes=h.digest()[:16], version=5)) + "}"


# -- C ---------------------------------------------------------------------------------------
_CAUS = {"parameter": "CAUSALITY_PARAMETER", "calculatedParameter": "CAUSALITY_CALCULATED_PARAMETER",
         "input": "CAUSALITY_INPUT", "output": "CAUSALITY_OUTPUT", "local": "CAUSALITY_LOCAL",
         "independent": "CAUSALITY_INDEPENDENT"}
_VARI = {"constant": "VARIABILITY_CONSTANT", "fixed": "VARIABILITY_FIXED", "tunable": "VARIABILITY_TUNABLE",
         "discrete": "VARIABILITY_DISCRETE", "continuous": "VARIABILITY_CONTINUOUS"}
_PREFIX = {"Real": "VR", "Integer": "VRI", "Boolean": "VRB", "String": "VRS"}
_ARRAY = {"Real": "r", "Integer": "i", "Boolean": "b", "String": "s"}


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_start(v: Variable) -> str:
    if v.type == "Real":
        return "0.0" if v.start is None else repr(float(v.start))
    if v.type == "Boolean":
        return "fmi2True" if v.start else "fmi2False"
    if v.type == "String":
        return _c_string(v.start or "")
    return str(int(v.start or 0))


def model_config_h(model: Model, guid: str) -> str:
    slots = layout(model)
    n = {t: sum(1 for s in slots if s.var.type == t) for t in _PREFIX}
    step_vr = next((s.vr for s in slots if s.var.name == INTEGRATOR_STEP), 0)
    L = [f"/* Generated by {GENERATOR} from models/ for {model.identifier}: do not edit. */",
         "#ifndef MODEL_CONFIG_H", "#define MODEL_CONFIG_H",
         f"#define MODEL_IDENTIFIER {model.identifier}", f'#define MODEL_GUID "{guid}"',
         f"#define N_REAL {n['Real']}", f"#define N_INTEGER {n['Integer']}",
         f"#define N_BOOLEAN {n['Boolean']}", f"#define N_STRING {n['String']}",
         f"#define N_STATES {len(model.states)}", f"#define VR_INTEGRATOR_STEP {step_vr}"]
    L += [f"#define {k} {int(v)}" for k, v in model.c_constants.items()]
    for s in slots[1:]:
        L.append(f"#define {_PREFIX[s.var.type]}_{s.var.name} {s.vr}")
    L += ["#endif", ""]
    return "\n".join(L)


def variables_c(model: Model) -> str:
    """Variable tables (names, causality, variability, start values) and the state list."""
    slots = layout(model)
    L = [f"/* Generated by {GENERATOR} from models/ for {model.identifier}: do not edit. */",
         '#include "model.h"', ""]
    for t, ctype in [("Real", "fmi2Real"), ("Integer", "fmi2Integer"), ("Boolean", "fmi2Boolean"),
                     ("String", "char *")]:
        of_type = [s for s in slots if s.var.type == t]
        if not of_type:
            continue
        name = t.lower()
        L.append(f"const VariableInfo model_{name}_info[N_{t.upper()}] = {{")
        L += [f'    {{"{s.var.name}", {_CAUS[s.causality]}, {_VARI[s.variability]}}},' for s in of_type]
        L.append("};")
        decl = "const char *const" if t == "String" else f"const {ctype}"
        L.append(f"{decl} model_{name}_start[N_{t.upper()}] = {{")
        L += [f"    {_c_start(s.var)}, /* {s.var.name} */" for s in of_type]
        L += ["};", ""]
    if model.states:
        vrs = ", ".join(f"VR_{s.name}" for s in model.states)
        L += [f"const fmi2ValueReference model_state_vrs[N_STATES] = {{{vrs}}};", ""]
    return "\n".join(L)


def _c_name(v: Variable) -> str:
    return "v_" + v.name


def _check_parameters_c(model: Model) -> list[str]:
    """Range checks of Real and Integer parameters, from a table (lower bound, upper bound,
    strict >)."""
    rows = []
    for p in model.parameters:
        if p.type in ("Real", "Integer") and (p.type == "Real" or p.positive or p.min is not None
                                              or p.max is not None):
            lo = 0.0 if p.positive else (-1e308 if p.min is None else float(p.min))
            hi = 1e308 if p.max is None else float(p.max)
            rows.append(f'        {{{_PREFIX[p.type]}_{p.name}, {int(p.type == "Integer")}, "{p.name}", '
                        f'{lo!r}, {hi!r}, {int(p.positive)}}},')
    if not rows:
        return ["int model_check_parameters(ModelInstance *m) {", "    (void)m;", "    return 0;", "}", ""]
    has_int = any(p.type == "Integer" for p in model.parameters)
    value = "c[k].integer ? (double)m->i[c[k].vr] : m->r[c[k].vr]" if has_int else "m->r[c[k].vr]"
    return [
        "int model_check_parameters(ModelInstance *m) {",
        "    static const struct { fmi2ValueReference vr; int integer; const char *name; double lo, hi; "
        "int strict; } c[] = {",
        *rows,
        "    };",
        "    for (size_t k = 0; k < sizeof c / sizeof c[0]; k++) {",
        f"        const double v = {value};",
        "        if (!isfinite(v)) {",
        '            model_error(m, "parameter %s = %g is not finite", c[k].name, v);',
        "            return 1;",
        "        }",
        "        if (c[k].strict ? !(v > c[k].lo) : !(v >= c[k].lo)) {",
        '            model_error(m, "parameter %s = %g must be %s %g", c[k].name, v, c[k].strict ? ">" : ">=", c[k].lo);',
        "            return 1;",
        "        }",
        "        if (!(v <= c[k].hi)) {",
        '            model_error(m, "parameter %s = %g must be <= %g", c[k].name, v, c[k].hi);',
        "            return 1;",
        "        }",
        "    }",
        "    return 0;",
        "}",
        "",
    ]


def _assign_block(model: Model, exprs: list[sp.Expr], targets: list[str],
                  source: dict[str, str]) -> tuple[list[str], set[str]]:
    """C statements computing ``targets[i] = exprs[i]`` with shared subexpressions hoisted.
    Only the model variables an expression uses are read (so -Wunused stays quiet); ``source``
    maps a variable name to the C lvalue it is read from. Returns the lines and the names of
    the free symbols that are not model variables (``t``, ``tau``)."""
    rename = {v.symbol: sp.Symbol(_c_name(v), real=True) for v in model.variables}
    rename[TAU] = sp.Symbol("v_tau", real=True)
    exprs = [sp.sympify(e).xreplace(rename) for e in exprs]
    subexprs, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("w"), optimizations="basic")
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    L = [f"    const double {_c_name(v)} = {source[v.name]};" for v in model.variables if rename[v.symbol] in used]
    L += [f"    const double {w} = {sp.ccode(e)};" for w, e in subexprs]
    L += [f"    {tgt} = {sp.ccode(e)};" for tgt, e in zip(targets, reduced)]
    model_syms = set(rename.values()) - {rename[TAU]}
    return L, {s.name for s in used - model_syms}


def _output_target(o: Output) -> str:
    return f"m->{_ARRAY[o.type]}[{_PREFIX[o.type]}_{o.name}]"


def _convert_discrete(line: str, model: Model) -> str:
    """``m->i[VRI_n] = e;`` -> lround(e); ``m->b[VRB_f] = e;`` -> (e) != 0 (module docstring of
    railfmu.models.base); ``end_now = e;`` likewise."""
    head, sep, expr = line.partition(" = ")
    target = head.strip()
    if not sep or not expr.endswith(";"):
        return line
    expr = expr[:-1]
    if target.startswith("m->i["):
        return f"{head} = (fmi2Integer)lround({expr});"
    if target.startswith("m->b[") or target == "end_now":
        cast = "" if target == "end_now" else "(fmi2Boolean)"
        return f"{head} = {cast}(({expr}) != 0);"
    return line


def equations_c(model: Model) -> str:
    """model_* functions for a model defined by expressions."""
    state_index = {s.name: k for k, s in enumerate(model.states)}

    def source(in_derivatives: bool) -> dict[str, str]:
        src = {v.name: f"m->{_ARRAY[v.type]}[{_PREFIX[v.type]}_{v.name}]" for v in model.variables}
        if in_derivatives:
            src.update({n: f"x[{k}]" for n, k in state_index.items()})
        return src

    L = [f"/* Generated by {GENERATOR} from models/ for {model.identifier}: do not edit. */",
         "#include <math.h>", '#include "model.h"', ""]
    L += _check_parameters_c(model)
    L += ["int model_initialize(ModelInstance *m) {", "    (void)m;", "    return 0;", "}", ""]
    # derivatives: states from x[], inputs held over the step, or first-order hold with a rate
    ders = model.derivative_exprs(hold_tau=TAU)
    body, free = _assign_block(model, ders, [f"dx[{k}]" for k in range(len(ders))], source(True))
    if STEP_SIZE.name in free:
        raise ValueError(f"{model.identifier}: the communication step h is for output expressions only")
    L.append("void model_derivatives(ModelInstance *m, double t, const double *x, double *dx) {")
    if "v_tau" in free:
        L.append("    const double v_tau = t - m->inputTime; /* first-order hold of the inputs */")
    if "t" not in free and "v_tau" not in free:
        L.append("    (void)t;")
    if not model.states:
        L.append("    (void)m; (void)x; (void)dx;")
    else:  # derivatives that read no state (dx/dt = u), or only t and x
        if not any(re.search(r"\bx\[", line) for line in body):
            L.append("    (void)x;")
        if not any("m->" in line for line in body):
            L.append("    (void)m;")
    L += body + ["}", ""]
    # outputs at r[0]: after a step the inputs are extrapolated as in the derivatives (the
    # FMU's best knowledge of them there); once new inputs are set, tau = 0
    outs = [model._substitute_held_inputs(sp.sympify(o.expr), TAU) for o in model.outputs]
    targets = [_output_target(o) for o in model.outputs]
    if model.terminate_when is not None:
        outs.append(model._substitute_held_inputs(sp.sympify(model.terminate_when), TAU))
        targets.append("end_now")
    body, free = _assign_block(model, outs, targets, source(False))
    body = [_convert_discrete(line, model) for line in body]
    L.append("int model_outputs(ModelInstance *m) {")
    if "t" in free:
        L.append("    const double t = m->r[0];")
    if STEP_SIZE.name in free:
        L.append(f"    const double {STEP_SIZE.name} = m->stepSize; /* the step that ended at t */")
    if "v_tau" in free:
        L.append("    const double v_tau = m->r[0] - m->inputTime; /* first-order hold of the inputs */")
    if model.terminate_when is not None:
        L.append("    int end_now;")
    L += body
    if model.terminate_when is not None:
        why = _c_string(f"{model.identifier}: {model.terminate_when} holds at t = %.17g")
        L.append(f"    if (end_now) model_terminate(m, m->r[0], {why}, m->r[0]);")
    L += ["    return 0;", "}", ""]
    L += ["int model_state_restored(ModelInstance *m) {", "    (void)m;", "    return 0;", "}", "",
          "void model_free(ModelInstance *m) {", "    (void)m;", "}", ""]
    return "\n".join(L)
