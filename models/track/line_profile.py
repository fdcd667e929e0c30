"""A line's gradient and speed limit by position: the Python twin of
``fmus/native/models/LineProfile.h`` (read by the TrainLongitudinal and Driver FMUs).

The file (String parameter ``line_file``: an absolute path, or relative to the FMU's
``resources/``, where ``line.csv`` is shipped)::

    position_m,gradient_permille,speed_limit_kmh
    0,0.0,40
    1200,0.0,140
    ...
    32103,0.0,40          <- the last row: the stopping point at the end of the line

Row k applies from ``position_m[k]`` up to the next row; before the first row the first row
applies, from the last row on the last. The gradient is in per mille, positive uphill (a
rise of 1 m per km is 1); positions increase strictly; limits are > 0. The last row's position
is where the Driver stops the train (the next station). An optional fourth column
``curve_radius_m`` (either sign, 0 = straight, else beyond 55 m) adds the curve resistance
per unit weight of Röckl's formula (standard gauge; as in Wende, *Fahrdynamik des
Schienenverkehrs*, 2003)::

    w_c(R) = 0.65 / (|R| - 55)    |R| >= 300 m
    w_c(R) = 0.5 / (|R| - 30)     55 m < |R| < 300 m

and the train's line term becomes ``g(s) = g0 (i / 1000 + w_c) / gamma``.

The shipped line (:data:`DEFAULT_LINE`, ``models/data/eindhoven_hertogenbosch_like_line.csv``)
is *like* the line of Cunillera et al. (2022) §4.1, not a survey of it: 32,103 m from
Eindhoven Centraal to 's-Hertogenbosch, "predominantly flat, with small, but nonsteep uphill
and downhill gradients" (the values between -1 and +1.2 per mille are this project's choice),
140 km/h line speed and 40 km/h near the departure and arrival stations (the 40 km/h zones'
lengths, 1200 m and 1503 m, are this project's choice). Users replace it with their own line.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # models/
DEFAULT_LINE = HERE / "data" / "eindhoven_hertogenbosch_like_line.csv"
COLUMNS = ("position_m", "gradient_permille", "speed_limit_kmh")
CURVE_COLUMN = "curve_radius_m"
G0 = 9.80665  # m/s2, standard gravity (ISO 80000-3)


@dataclass
class LineProfile:
    position: np.ndarray  # m, strictly increasing
    gradient: np.ndarray  # per mille, positive uphill
    limit: np.ndarray  # m/s (the file's km/h / 3.6)
    curve: np.ndarray  # curve resistance per unit weight (Röckl), 0 on straight track

    @classmethod
    def read(cls, path: Path | str = DEFAULT_LINE) -> LineProfile:
        """The same checks as the C; a problem is a ValueError naming the file, line and column."""
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = [(i + 1, r) for i, r in enumerate(csv.reader(f)) if any(c.strip() for c in r)]
        header = [c.strip() for c in rows[0][1]] if rows else []
        if header not in (list(COLUMNS), [*COLUMNS, CURVE_COLUMN]):
            raise ValueError(f"line_file {path}, line 1: header must be {','.join(COLUMNS)}"
                             f"[,{CURVE_COLUMN}]")
        ncol = len(header)
        vals = []
        for lineno, r in rows[1:]:
            if len(r) != ncol:
                raise ValueError(f"line_file {path}, line {lineno}: {len(r)} fields, expected {ncol}")
            row = []
            for j, c in enumerate(r):
                try:
                    x = float(c.strip())
                except ValueError:
                    x = math.nan
                if not math.isfinite(x):
                    raise ValueError(f"line_file {path}, line {lineno}, column {j + 1} ({header[j]}): "
                                     f"'{c.strip()}' is not a finite number")
                row.append(x)
            if vals and not row[0] > vals[-1][0]:
                raise ValueError(f"line_file {path}, line {lineno}, column 1 (position_m): positions "
                                 "must increase strictly")
            if ncol == 4 and row[3] != 0 and not abs(row[3]) > 55.0:
                raise ValueError(f"line_file {path}, line {lineno}, column 4 ({CURVE_COLUMN}): 0 or beyond 55 m")
            if not row[2] > 0:
                raise ValueError(f"line_file {path}, line {lineno}, column 3 (speed_limit_kmh): must be > 0")
            vals.append(row)
        if not vals:
            raise ValueError(f"line_file {path}: no data rows")
        a = np.array(vals)
        curve = [curve_resistance(R) for R in a[:, 3]] if ncol == 4 else [0.0] * len(a)
        return cls(a[:, 0], a[:, 1], a[:, 2] / 3.6, np.array(curve))

    @property
    def length(self) -> float:
        """The stopping point (m): the last row's position."""
        return float(self.position[-1])

    def row(self, s: float) -> int:
        return max(int(np.searchsorted(self.position, s, side="right")) - 1, 0)

    def gradient_at(self, s: float) -> float:
        return float(self.gradient[self.row(s)])

    def limit_at(self, s: float) -> float:
        return float(self.limit[self.row(s)])

    def curve_at(self, s: float) -> float:
        return float(self.curve[self.row(s)])


def curve_resistance(R: float) -> float:
    """Röckl's curve resistance per unit weight for a radius R (m, either sign; 0 = straight)."""
    R = abs(float(R))
    if R == 0:
        return 0.0
    return 0.65 / (R - 55.0) if R >= 300.0 else 0.5 / (R - 30.0)
