"""Parameter values of an SSP: ``ssv`` parameter sets, ``ssm`` mappings, and the checks that
turn a value into what an FMU variable accepts (type, unit, settable at all).

A value keeps where it came from (``file:line: Parameter 'x'``) so every error names it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from railfmu.models.errors import UserError
from railfmu.fmus.ssp.units import Affine, UnitError, Units, conversion, from_ssc
from railfmu.fmus.ssp.xmltools import NS, SIZED_TYPES, SSC_NS, SSV_NS, children, local
from railfmu.fmus.cosim.system import Value

_TRANSFORMS = ("LinearTransformation", "BooleanMappingTransformation", "IntegerMappingTransformation",
               "EnumerationMappingTransformation")


@dataclass
class ParamValue:
    name: str  # as the target sees it (after mapping and prefix)
    kind: str  # ssv type: Real, Integer, Boolean, String, Enumeration
    value: Value
    unit: str | None
    units: Units  # unit definitions visible where the value was written
    where: str  # "file:line: Parameter 'x'"
    linear: Affine | None = None  # an ssm LinearTransformation, applied after the unit conversion
    suppress_units: bool = False


def read_parameter_set(pset, shown: str, outer: Units, owner: str = "") -> list[ParamValue]:
    """The parameters of an ``ssv:ParameterSet`` element, in document order; ``owner``
    (e.g. "Component 'track'") is added to each value's place in messages."""
    units = Units(from_ssc(pset.find("ssv:Units", NS))).then(outer)
    out = []
    for p in pset.iterfind("ssv:Parameters/ssv:Parameter", NS):
        name = p.get("name")
        where = f"{shown}:{p.sourceline}: Parameter {name!r}" + (f" of {owner}" if owner else "")
        typed = next((c for c in children(p, SSV_NS) if local(c) != "Annotations"), None)
        kind = local(typed) if typed is not None else None
        kind = SIZED_TYPES.get(kind, kind)  # SSP 2.0: ssv:Float64 is a Real, ssv:Int32 an Integer
        raw = typed.get("value") if typed is not None else None
        if kind is not None and raw is None:  # SSP 2.0: ssv:Value children (an array) or a Binary
            raise UserError(f"{where}: ssv:{local(typed)} without a value attribute (an array or binary "
                            "value) is not supported")
        if kind == "Real":
            value: Value = float(raw)
        elif kind == "Integer":
            value = int(raw)
        elif kind == "Boolean":
            value = raw.strip() in ("true", "1")
        elif kind in ("String", "Enumeration"):
            value = raw
        else:
            raise UserError(f"{where}: {kind or 'a missing'} value is not supported "
                            "(Real, Integer, Boolean, String, Enumeration and SSP 2.0's Float64, Int32, ...)")
        out.append(ParamValue(name, kind, value, typed.get("unit") if kind == "Real" else None, units, where))
    return out


@dataclass
class MappingEntry:
    target: str
    where: str
    transform: object = None  # lxml element of the ssc transformation, or None
    suppress_units: bool = False


def read_mapping(pm, shown: str) -> dict[str, MappingEntry]:
    """``ssm:MappingEntry source -> target`` of an ``ssm:ParameterMapping`` element."""
    out = {}
    for e in pm.iterfind("ssm:MappingEntry", NS):
        t = next((c for c in children(e, SSC_NS) if local(c) in _TRANSFORMS), None)
        out[e.get("source")] = MappingEntry(e.get("target"), f"{shown}:{e.sourceline}: MappingEntry "
                                            f"{e.get('source')!r} -> {e.get('target')!r}", t,
                                            e.get("suppressUnitConversion") in ("true", "1"))
    return out


def apply_mapping(values: list[ParamValue], mapping: dict[str, MappingEntry]) -> list[ParamValue]:
    """Rename mapped parameters and attach their transformation; names not in the mapping pass
    unchanged (SSP 1.0: a mapping only adds to name-based binding)."""
    for v in values:
        m = mapping.get(v.name)
        if m is None:
            continue
        v.name, v.where, v.suppress_units = m.target, f"{v.where} (via {m.where})", m.suppress_units
        if m.transform is None:
            continue
        kind = local(m.transform)
        if kind == "LinearTransformation":
            if v.kind not in ("Real", "Integer"):
                raise UserError(f"{m.where}: a LinearTransformation needs a Real value, not {v.kind}")
            # applied once the target's unit is known: the spec converts units first
            v.linear = (float(m.transform.get("factor", 1.0)), float(m.transform.get("offset", 0.0)))
        else:
            v.value = _map_value(m.transform, v, m.where)
    return values


def _map_value(transform, v: ParamValue, where: str) -> Value:
    """ssc:Boolean/Integer/EnumerationMappingTransformation: a table source -> target;
    values not in the table pass unchanged."""
    kind = local(transform).removesuffix("MappingTransformation")
    if kind != v.kind:
        raise UserError(f"{where}: ssc:{local(transform)} does not apply to a {v.kind} value")
    parse = {"Boolean": lambda s: s.strip() in ("true", "1"), "Integer": int, "Enumeration": str}[kind]
    table = {parse(e.get("source")): parse(e.get("target")) for e in transform.iterfind("ssc:MapEntry", NS)}
    return table.get(v.value, v.value)


# -- what an FMU variable accepts ------------------------------------------------------------

def why_not_settable(var) -> str | None:
    """None if FMI 2.0 allows setting the variable before initialisation; else why not.

    Settable: parameters and inputs, and any variable with initial exact/approx (the start
    value of a state: our FMUs export states as outputs with initial="exact").
    """
    if var.variability == "constant":
        return "is a constant"
    if var.causality == "independent":
        return "is the independent variable"
    if var.causality == "calculatedParameter":
        return "is a calculated parameter"
    if var.causality in ("parameter", "input") or var.initial in ("exact", "approx"):
        return None
    if var.initial is None and var.start is not None and var.causality != "input":
        return None  # FMI 1.0 has no initial: a start value is set before fmiInitializeSlave
    return f"is an {var.causality} computed by the FMU (initial={var.initial or 'calculated'!r})"


def _enum_items(var) -> dict[str, int]:
    items = getattr(var.declaredType, "items", None) or []
    return {i.name: int(i.value) for i in items}


def from_ssv(v: ParamValue, var, var_units: Units) -> Value:
    """An ssv value as the FMU variable takes it: Real values converted to the variable's unit
    (then the mapping's LinearTransformation, as for connections), Integer widened to Real."""
    t, fmu = var.type, f"{var.name!r} ({var.type})"
    if t == "Real" and v.kind in ("Real", "Integer"):
        x = float(v.value)
        if v.kind == "Real" and not v.suppress_units:
            try:
                a, b = conversion(v.unit, v.units.then(var_units), var.unit, var_units)
            except UnitError as exc:
                raise UserError(f"{v.where}: {exc} (variable {var.name!r} is in {var.unit!r})") from None
            x = a * x + b
        if v.linear:
            x = v.linear[0] * x + v.linear[1]
        return in_range(_finite(x, v.where), var, v.where)
    if v.kind == "Integer" and t in ("Integer", "Enumeration"):
        value = v.value if not v.linear else v.linear[0] * v.value + v.linear[1]
        if not math.isfinite(value) or value != int(value):
            raise UserError(f"{v.where}: {value!r} is not an integer for variable {fmu}")
        return in_range(int(value), var, v.where)
    if v.kind == t and t in ("Boolean", "String"):
        return v.value
    if v.kind == "Enumeration" and t == "Enumeration":
        items = _enum_items(var)
        if v.value not in items:
            raise UserError(f"{v.where}: {v.value!r} is not an item of variable {fmu}; "
                            f"items: {', '.join(items) or '(none)'}")
        return items[v.value]
    raise UserError(f"{v.where}: a {v.kind} value does not fit variable {fmu}")


def from_cli(value, var, where: str) -> Value:
    """A command-line value (float or str) as the FMU variable takes it."""
    t = var.type
    text = value.strip() if isinstance(value, str) else None
    number = value if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    if text is not None and t in ("Real", "Integer", "Enumeration"):
        try:
            number = float(text)
        except ValueError:
            pass
    if t == "Real" and number is not None:
        return in_range(_finite(float(number), where), var, where)
    if t in ("Integer", "Enumeration") and text is not None:
        try:
            number = int(text)  # exactly: float() would round 2**53 + 1
        except ValueError:
            pass
    if t in ("Integer", "Enumeration") and number is not None and math.isfinite(number) \
            and float(number).is_integer():
        return in_range(int(number), var, where)
    if t == "Enumeration" and text in _enum_items(var):
        return _enum_items(var)[text]
    if t == "Boolean":
        if isinstance(value, bool):
            return value
        key = text.lower() if text is not None else number
        if key in ("true", "1", 1):  # 1.0 == 1
            return True
        if key in ("false", "0", 0):
            return False
    if t == "String" and text is not None:
        return value
    raise UserError(f"{where}: {value!r} is not a valid {t} value for variable {var.name!r}")


INT32 = (-(2**31), 2**31 - 1)  # fmi2Integer is a C int: a larger value would wrap silently


def in_range(x, var, where: str):
    """``x`` within the variable's declared min and max (and an Integer's C int range)."""
    lo, hi = (float(b) if b not in (None, "") else None
              for b in (getattr(var, "min", None), getattr(var, "max", None)))
    if var.type in ("Integer", "Enumeration"):
        lo = INT32[0] if lo is None else max(lo, INT32[0])
        hi = INT32[1] if hi is None else min(hi, INT32[1])
    if (lo is not None and x < lo) or (hi is not None and x > hi):
        def show(b: float) -> str:
            return str(int(b)) if float(b).is_integer() else repr(b)

        bounds = " and ".join(b for b in (f">= {show(lo)}" if lo is not None else "",
                                          f"<= {show(hi)}" if hi is not None else "") if b)
        raise UserError(f"{where}: {x!r} is out of range for variable {var.name!r} (must be {bounds})")
    return x


def _finite(x: float, where: str) -> float:
    if not math.isfinite(x):
        raise UserError(f"{where}: non-finite value {x!r}")
    return x
