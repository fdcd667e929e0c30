"""FMI unit definitions: every unit name a model may use, as SI base-unit exponents.

fmpy's validation rejects a variable whose unit is not declared in <UnitDefinitions>; we
declare each used unit with its BaseUnit so importers can check and convert units.
"""

# name: {base unit: exponent} (kg, m, s, A, K, mol, cd, rad)
UNITS: dict[str, dict[str, int]] = {
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "rad/m": {"rad": 1, "m": -1},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m2": {"kg": 1, "m": 3, "s": -2},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "Hz": {"s": -1},
    "W": {"kg": 1, "m": 2, "s": -3},
    "N/kg": {"m": 1, "s": -2},  # mass-specific effort and resistance (Cunillera et al. 2022)
    "N.s/(m.kg)": {"s": -1},  # Davis r1, mass-specific
    "N.s2/(m2.kg)": {"m": -1},  # Davis r2, mass-specific
}


def check_unit(unit: str, where: str) -> None:
    if unit and unit not in UNITS:
        raise ValueError(f"{where}: unit {unit!r} is not in fmus/units.py; add it with its SI base units")
