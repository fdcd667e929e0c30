"""Estimators by registered name: what the ``class`` of an SSD's ``rf:Observer`` names.

An estimator is registered in the entry-point group ``railfmu.estimators`` of its
distribution (the built-in ones in railfmu's ``pyproject.toml``; a third party the same way)::

    [project.entry-points."railfmu.estimators"]
    alignment_kf = "railfmu.estimators.track.alignment:AlignmentKalmanFilter"

and an SSD names it ``<rf:Observer name="alignment" class="alignment_kf">``. Nothing else is
imported because an SSD says so: a dotted path ``package.module.Class`` still loads, with a
:class:`DeprecatedEstimatorPath` warning naming the registered name, only when it is the path
of a registered estimator (its current path, or the one before the layout's move, e.g.
``estimators.alignment.AlignmentKalmanFilter``); any other name or path is a UserError of one
line with the closest registered names.
"""

from __future__ import annotations

import difflib
import warnings
from importlib.metadata import EntryPoint, entry_points

from railfmu.models.errors import UserError

GROUP = "railfmu.estimators"

#: modules that held estimators before the package layout moved (old -> new, railfmu.*)
MOVED = {
    "estimators.alignment": "estimators.track.alignment",
    "estimators.suspension": "estimators.suspension.stiffness",
    "estimators.running_resistance": "estimators.train.running_resistance",
    "estimators.ins_observer": "estimators.inertial.ins_observer",
    "estimators.aided_ins": "estimators.inertial.aided_ins",
    "experiments.fmu_process": "experiments.engine.fmu_process",
}


class DeprecatedEstimatorPath(DeprecationWarning):
    """An SSD names a registered estimator by its module path instead of its name."""


def _registered() -> dict[str, EntryPoint]:
    """Every entry point of the group by name; the same name from two different classes is
    a UserError (which one an SSD means would depend on the install order)."""
    out: dict[str, EntryPoint] = {}
    for ep in entry_points(group=GROUP):  # read each time: a distribution installed since counts
        if ep.name in out and out[ep.name].value != ep.value:
            raise UserError(f"estimator {ep.name!r} is registered twice ({out[ep.name].value} and {ep.value}); "
                            f"uninstall one")
        out[ep.name] = ep
    return out


def names() -> dict[str, str]:
    """The registered estimators, ``{name: "module:Class"}`` sorted by name."""
    return {k: ep.value for k, ep in sorted(_registered().items())}


def _path_name(path: str, registered: dict[str, EntryPoint]) -> str | None:
    """The registered name whose class lives at the dotted ``path`` (current or pre-move,
    with or without the ``railfmu.`` prefix), else None."""
    module, _, attr = path.removeprefix("railfmu.").rpartition(".")
    module = "railfmu." + MOVED.get(module, module)
    for name, ep in registered.items():
        if ep.value in (f"{module}:{attr}", f"{path.rpartition('.')[0]}:{attr}"):
            return name
    return None


def load(ref: str, where: str = "", warn: bool = True) -> type:
    """The estimator class an SSD's ``class`` attribute ``ref`` names: a registered name, or
    (deprecated, warned unless ``warn`` is false) the dotted path of a registered estimator.
    ``where`` (file and element) starts every message. A UserError for anything else."""
    label = f"{where}: " if where else ""
    registered = _registered()
    name = ref if ref in registered else _path_name(ref, registered) if "." in ref else None
    if name is None:
        close = difflib.get_close_matches(ref.rpartition(".")[2].lower(), registered, n=3)
        close += [k for k, ep in registered.items() if k not in close
                  and ep.value.rpartition(":")[2] == ref.rpartition(".")[2]]  # a moved class
        hint = f"closest: {', '.join(close)}" if close else f"registered: {', '.join(sorted(registered)) or '(none)'}"
        what = "is not the module path of a registered estimator" if "." in ref else "is not a registered estimator"
        raise UserError(f"{label}class {ref!r} {what} (entry points {GROUP}); {hint}")
    if name != ref and warn:
        warnings.warn(f"{label}class {ref!r} is deprecated: name the estimator {name!r}",
                      DeprecatedEstimatorPath, stacklevel=2)
    try:
        cls = registered[name].load()
    except (ImportError, AttributeError) as exc:  # a broken third-party registration
        raise UserError(f"{label}estimator {name!r} ({registered[name].value}) cannot be loaded: {exc}") from None
    if not isinstance(cls, type):
        raise UserError(f"{label}estimator {name!r} ({registered[name].value}) is not a class")
    return cls
