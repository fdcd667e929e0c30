"""Estimator settings as frozen dataclasses: type, unit, default and range of each declared once.

An estimator declares its settings as a frozen dataclass of :class:`Settings` whose fields are
made by :func:`setting`, and builds them from the keyword arguments it was given (from an SSD:
text already parsed to bool/int/float/str by the SSP reader, or from Python)::

    @dataclass(frozen=True)
    class FilterSettings(Settings):
        sigma_acc: float = setting(0.01, "m/s2", "accelerometer noise std", gt=0)
        heading0: float = setting(0.0, "rad", "initial heading", given_in="deg")

    cfg = FilterSettings.from_mapping(settings, "MyFilter")

:meth:`Settings.from_mapping` is the one place of the checks, each failure a ValueError of one
line naming the estimator and the setting:

* an unknown key, with the closest known names (``difflib``); keys in ``extra`` (e.g. the
  parameters of a design model, which checks them itself) are left to the caller;
* type coercion by the field's annotation: ``float`` (finite; not a bool), ``int`` (an
  integral number), ``bool`` (also "true"/"false"/"1"/"0"/"yes"/"no"), ``str``,
  ``tuple[float, ...]`` (a sequence of numbers, ``length`` of them), ``X | None``; other
  annotations pass the value to the field's ``convert``, if any;
* unit conversion: a field ``given_in`` another unit than its ``unit`` (degrees in the file,
  radians in the filter) is multiplied by the factor of :data:`FACTORS` (``value_filter =
  factor * value_given``);
* range checks ``gt``, ``ge``, ``le`` (in the field's ``unit``, after the conversion; on every
  element of a tuple) and ``choices``.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from typing import Any, ClassVar, TypeVar

#: ``(given, unit) -> factor``: ``value in unit = factor * value given``
FACTORS: dict[tuple[str, str], float] = {
    ("deg", "rad"): math.pi / 180.0,
    ("deg/s", "rad/s"): math.pi / 180.0,
    ("deg/h", "rad/s"): math.pi / 180.0 / 3600.0,
    ("km/h", "m/s"): 1.0 / 3.6,
    ("mm", "m"): 1e-3,
}

S = TypeVar("S", bound="Settings")


def setting(default: Any, unit: str = "", doc: str = "", *, gt: float | None = None, ge: float | None = None,
            le: float | None = None, choices: Iterable | None = None, length: int | None = None,
            given_in: str | None = None, convert: Callable[[Any], Any] | None = None) -> Any:
    """A settings field: its default, ``unit`` (the estimator's, '' dimensionless), a short
    ``doc``, and its checks (module docstring). ``convert`` maps the given value (not None)
    to the field's value, raising ValueError with the reason."""
    if given_in is not None and (given_in, unit) not in FACTORS:
        raise ValueError(f"no conversion from {given_in!r} to {unit!r} (estimators/core/settings.py FACTORS)")
    meta = {"unit": unit, "doc": doc, "gt": gt, "ge": ge, "le": le, "length": length, "given_in": given_in,
            "choices": None if choices is None else tuple(choices), "convert": convert}
    return dataclasses.field(default=default, metadata=meta)


@dataclasses.dataclass(frozen=True)
class Settings:
    """Base of an estimator's settings (module docstring)."""

    _hints: ClassVar[dict[type, dict[str, Any]]] = {}

    @classmethod
    def from_mapping(cls: type[S], mapping: Mapping[str, Any], where: str, extra: Iterable[str] = ()) -> S:
        """The settings from ``mapping`` (missing keys: the defaults), checked; ``where`` (the
        estimator) starts every message. Keys in ``extra`` are ignored (the caller's)."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        extra = set(extra)
        unknown = sorted(k for k in mapping if k not in fields and k not in extra)
        if unknown:
            known = [*fields, *extra]
            close = list(dict.fromkeys(c for k in unknown for c in difflib.get_close_matches(k, known, n=2)))
            raise ValueError(f"{where}: unknown setting{'s' if len(unknown) > 1 else ''} "
                             f"{', '.join(map(repr, unknown))}" + (f" (closest: {', '.join(close)})" if close else ""))
        hints = cls._hints.get(cls) or cls._hints.setdefault(cls, typing.get_type_hints(cls))
        return cls(**{k: _coerce(f, hints[k], mapping[k], where) for k, f in fields.items() if k in mapping})

    @classmethod
    def describe(cls) -> list[str]:
        """One line per setting: ``name (unit, default): doc`` (for docs and help texts)."""
        return [f"{f.name} ({f.metadata.get('unit') or '-'}, {f.default!r}): {f.metadata.get('doc', '')}"
                for f in dataclasses.fields(cls)]


def _coerce(f: dataclasses.Field, hint: Any, raw: Any, where: str) -> Any:
    """``raw`` as the field's type and unit, checked (module docstring)."""
    m, name = f.metadata, f.name
    args = typing.get_args(hint) if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union else ()
    optional = type(None) in args
    base = next((a for a in args if a is not type(None)), hint) if args else hint
    if raw is None:
        if optional or base is Any:
            return None
        raise ValueError(f"{where}: setting {name} must be given (not None)")
    try:
        if m.get("convert") is not None:
            value = m["convert"](raw)
        elif typing.get_origin(base) is tuple:
            if isinstance(raw, (str, bytes, Mapping)) or not isinstance(raw, Iterable):
                raise ValueError("is not a sequence of numbers")
            value = tuple(_number(x, float) for x in raw)
            if m.get("length") is not None and len(value) != m["length"]:
                raise ValueError(f"must have {m['length']} values, not {len(value)}")
        elif base is bool:
            value = _bool(raw)
        elif base in (float, int):
            value = _number(raw, base)
        elif base is str:
            if not isinstance(raw, str):
                raise ValueError("is not text")
            value = raw
        else:
            value = raw
    except ValueError as exc:
        raise ValueError(f"{where}: setting {name} = {raw!r} {exc}") from None
    if m.get("given_in") is not None:
        factor = FACTORS[(m["given_in"], m["unit"])]
        value = tuple(factor * v for v in value) if isinstance(value, tuple) else factor * value
    _check_range(m, name, value, where)
    return value


def _number(raw: Any, kind: type) -> float | int:
    if isinstance(raw, bool):  # True would pass as 1
        raise ValueError("is not a number")
    try:
        value = float(raw)
    except (TypeError, ValueError):
        raise ValueError("is not a number") from None
    if not math.isfinite(value):
        raise ValueError("is not a finite number")
    if kind is int:
        if value != int(value):
            raise ValueError("is not an integer")
        return int(value)
    return value


def _bool(raw: Any) -> bool:
    if isinstance(raw, str):
        text = raw.strip().lower()
        if text in ("true", "1", "yes", "false", "0", "no"):
            return text in ("true", "1", "yes")
        raise ValueError("must be true or false")
    return bool(raw)


def _check_range(m: Mapping[str, Any], name: str, value: Any, where: str) -> None:
    if m.get("choices") is not None and value not in m["choices"]:
        raise ValueError(f"{where}: setting {name} must be one of {', '.join(map(repr, m['choices']))}, "
                         f"not {value!r}")
    for v in value if isinstance(value, tuple) else (value,):
        for key, ok, text in (("gt", lambda b: v > b, ">"), ("ge", lambda b: v >= b, ">="),
                              ("le", lambda b: v <= b, "<=")):
            if m.get(key) is not None and isinstance(v, (int, float)) and not ok(m[key]):
                raise ValueError(f"{where}: setting {name} must be {text} {m[key]:g}"
                                 f"{' ' + m['unit'] if m['unit'] else ''}, not {value!r}")


def number_or_inf(raw: Any) -> float:
    """A ``convert`` for a number that may be infinite (``inf``, also as text: "no limit",
    e.g. a random constant's correlation time); NaN and bools refused."""
    if isinstance(raw, bool):
        raise ValueError("is not a number")
    try:
        value = float(raw.strip() if isinstance(raw, str) else raw)
    except (TypeError, ValueError):
        raise ValueError("is not a number (or inf)") from None
    if math.isnan(value):
        raise ValueError("is not a number (or inf)")
    return value
