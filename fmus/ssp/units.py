"""Units for the SSP reader: definitions by name and the affine maps between compatible units.

SSP 1.0 (``ssc:Unit/ssc:BaseUnit``) and FMI 2.0 (``UnitDefinitions/Unit/BaseUnit``) define a
unit the same way: SI base-unit exponents plus ``factor`` and ``offset``, with
``value_SI = factor * value + offset``. Two units are compatible when their exponents agree;
the conversion between them is then affine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from railfmu.fmus.units import UNITS

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

Affine = tuple[float, float]  # (a, b): y = a * x + b
IDENTITY: Affine = (1.0, 0.0)


@dataclass(frozen=True)
class Unit:
    name: str
    exponents: tuple[int, ...]  # in BASE order
    factor: float = 1.0
    offset: float = 0.0

    def dims(self) -> str:
        """The SI dimensions as text for messages, e.g. 'm s-2'; '1' when dimensionless."""
        parts = [b if e == 1 else f"{b}{e}" for b, e in zip(BASE, self.exponents) if e]
        return " ".join(parts) or "1"


class UnitError(ValueError):
    """Two units that cannot be converted, or a unit without a definition."""


def compose(first: Affine, then: Affine) -> Affine:
    """The map x -> then(first(x))."""
    a1, b1 = first
    a2, b2 = then
    return a2 * a1, a2 * b1 + b2


def tidy(m: Affine) -> Affine:
    """Snap a factor that is 1 up to rounding (m -> mm -> m) back to exactly 1, so an identity
    connection stays an identity."""
    a, b = m
    return (1.0 if math.isclose(a, 1.0, rel_tol=1e-14) else a), b


class Units:
    """Unit definitions by name, searched in order (e.g. an .ssv's own, the SSD's, the FMU's,
    then railfmu's own table in fmus/units.py)."""

    def __init__(self, *tables: dict[str, Unit]):
        self.tables = [t for t in tables if t]

    def then(self, other: Units) -> Units:
        return Units(*self.tables, *other.tables)

    def get(self, name: str) -> Unit | None:
        for t in self.tables:
            if name in t:
                return t[name]
        return None


OURS = Units({name: Unit(name, tuple(exps.get(b, 0) for b in BASE)) for name, exps in UNITS.items()})


def from_ssc(units_el) -> dict[str, Unit]:
    """The ``ssc:Unit`` definitions inside an ``ssd:Units``/``ssv:Units`` element (or None)."""
    out: dict[str, Unit] = {}
    if units_el is None:
        return out
    for u in units_el:
        if not isinstance(u.tag, str) or not u.tag.endswith("}Unit"):
            continue
        base = next((c for c in u if isinstance(c.tag, str) and c.tag.endswith("}BaseUnit")), None)
        if base is None:
            continue
        out[u.get("name")] = Unit(u.get("name"), tuple(int(base.get(b, 0)) for b in BASE),
                                  float(base.get("factor", 1.0)), float(base.get("offset", 0.0)))
    return out


def from_fmu(md) -> dict[str, Unit]:
    """The UnitDefinitions of an FMU (fmpy's ``ModelDescription``) that carry a BaseUnit."""
    out: dict[str, Unit] = {}
    for u in md.unitDefinitions or []:
        b = u.baseUnit
        if b is not None:
            out[u.name] = Unit(u.name, tuple(int(getattr(b, n) or 0) for n in BASE),
                               float(b.factor), float(b.offset))
    return out


def conversion(src: str | None, src_units: Units, dst: str | None, dst_units: Units) -> Affine:
    """The map from a value in unit ``src`` to the same quantity in ``dst``.

    No conversion when either side has no unit (nothing to check) or both names are equal.
    Raises :class:`UnitError` for incompatible or undefined units.
    """
    if not src or not dst or src == dst:
        return IDENTITY
    s, d = src_units.get(src), dst_units.get(dst)
    for name, unit in ((src, s), (dst, d)):
        if unit is None:
            raise UnitError(f"unit {name!r} is not defined (declare it in ssd:Units with its ssc:BaseUnit)")
    if s.exponents != d.exponents:
        raise UnitError(f"unit {src!r} ({s.dims()}) cannot be converted to {dst!r} ({d.dims()})")
    # x_SI = fs * x + os = fd * y + od  ->  y = fs/fd * x + (os - od)/fd
    return tidy((s.factor / d.factor, (s.offset - d.offset) / d.factor))
