"""What ``--set`` (and :func:`railfmu.run`'s ``parameters``) can change in an experiment:
each component's FMU parameters and each observer's settings, with units, the FMU's
default and the value the variant runs with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from railfmu.experiments.engine.runner import find_experiment, load_system

_TYPES = {"Real": float, "Integer": int, "Enumeration": int,
          "Boolean": lambda s: str(s).lower() in ("true", "1"), "String": str}


@dataclass(frozen=True)
class Parameter:
    """One settable name of an experiment.

    Attributes
    ----------
    name : str
        ``component.parameter`` or ``observer.setting``, as ``--set`` takes it.
    kind : str
        ``"parameter"`` (an FMU parameter) or ``"setting"`` (an observer's setting).
    type : str
        FMI type (Real, Integer, Boolean, String, Enumeration); a setting's Python type.
    unit : str or None
        The unit the value is in (an FMU variable's unit; None when it has none).
    default : object
        The FMU's start value (a setting: None).
    value : object
        What the experiment runs with (its SSD and the variant), or ``default``.
    description : str
        The FMU variable's description.
    """
    name: str
    kind: str
    type: str
    unit: str | None
    default: Any
    value: Any
    description: str = ""


def _typed(var, text):
    if text is None:
        return None
    try:
        return _TYPES.get(var.type, str)(text)
    except ValueError:
        return text


def list_parameters(experiment: str, variant: str | None = None) -> list[Parameter]:
    """Every parameter and observer setting of ``experiment`` (a name or an SSP path), with
    ``variant`` applied (default: the experiment's default variant)."""
    exp = find_experiment(experiment)
    system = load_system(exp, variant or exp.default_variant)
    out = []
    for c in system.components:
        for v in c.variables.values():
            if v.causality != "parameter" or v.variability == "constant":
                continue
            unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
            default = _typed(v, v.start)
            out.append(Parameter(f"{c.name}.{v.name}", "parameter", v.type, unit or None, default,
                                 c.parameters.get(v.name, default), v.description or ""))
    for o in system.observers:
        for k, value in o.settings.items():
            unit = o.units.get(o.setting_signals.get(k, ""))
            out.append(Parameter(f"{o.name}.{k}", "setting", type(value).__name__,
                                 unit.name if unit is not None else None, None, value, f"setting of {o.cls}"))
    return out
