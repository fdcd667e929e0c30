"""Measured-data replay: a time-indexed CSV table played as FMU outputs.

An operator's measured run (GNSS fixes every 1-10 s, a 200 Hz IMU, 1 kHz axle-box
accelerations) drives the same observers as a simulated run when it is a component of the
SSP, like any other FMU; other tools (libcosim, OMSimulator) run it too.

The file (parameter ``file``: an absolute path, or relative to the FMU's ``resources/``)::

    time,position,speed,gnss_valid,regime      <- header: first column "time" (s), then names
                                                  ("time_s" too: the standard imu.csv, truth.csv)
    0.0,0.0,0.0,1,0
    1.0,0.5,1.0,1,1

Channels: ``y_1 .. y_16`` (Real) play the columns named by ``column_1 .. column_16``;
``boolean_1 .. boolean_4`` play 0/1 columns named by ``boolean_column_k``; ``integer_1 ..
integer_4`` play integer columns named by ``integer_column_k``. An empty name leaves the
channel unbound (0, false). Only bound columns are read as numbers; every row must have as
many fields as the header.

At simulation time t the table is read at tau = t - time_offset (``time_offset``: the
simulation time at which the table's time 0 plays). With rows (tau_k, y_k):

    y(tau) = y_k                                          tau = tau_k (exactly the file's value)
    y(tau) = y_k                                          tau_k < tau < tau_k+1, interpolation = 0
    y(tau) = y_k + (y_k+1 - y_k) (tau - tau_k)/(tau_k+1 - tau_k)             interpolation = 1
    y(tau) = y_0                                          tau < tau_0 (the first row is held)
    y(tau) = y_n-1                                        tau > tau_n-1, after_end = 0
    end of the simulation at tau_n-1 + time_offset        tau > tau_n-1, after_end = 1

Boolean and Integer channels are always sample-and-hold. ``tau = tau_k`` holds within
min(1e-9 max(1, |tau|), 1e-3 min_k(tau_k+1 - tau_k)): a master that accumulates t += h
(OMSimulator) reaches 10.000000000000002 for a row at 10 s, and must still get that row,
not the previous one (t += h over 10^6 steps of 1 ms or 0.1 ms drifts at most 1.7e-11 and
2.2e-11 relative to k h: 50 times below the tolerance). With ``after_end = 1`` the FMU ends the co-simulation the FMI 2.0 way
(fmi2DoStep returns fmi2Discard, fmi2Terminated is true, the last successful time is the
table's end): a measured run that is shorter than the experiment ends it cleanly.

The file is read once when initialisation ends (the times must increase strictly; no NaN,
no text where a number belongs, no ragged row: otherwise fmi2ExitInitializationMode fails
with one message naming the file, line and column); each step looks the time up from the
row of the previous step (binary search when it moved further), so a 20,000-row run costs
the same per step as a 20-row one.

A replayed channel has no unit in modelDescription.xml (FMI 2.0 fixes units at build time,
the column's unit is the file's): the SSD connector or the connected input gives it.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from railfmu.models.base import Model, Output, Parameter

N_REAL = 16  # Real channels: e.g. 8 axle boxes x (lateral, vertical), or IMU + GNSS
N_BOOLEAN = 4  # Boolean channels: GNSS valid, zero-velocity, ...
N_INTEGER = 4  # Integer channels: driving regime, ...
TIME_TOLERANCE = 1e-9  # relative (with max(1, |tau|)), and at most 1e-3 of the smallest row step
GAP_FRACTION = 1e-3

HERE = Path(__file__).resolve().parents[1]  # models/
EXAMPLE = HERE / "data" / "signal_table_example.csv"


def build() -> Model:
    src = "experiment (.ssv)"
    parameters = [
        Parameter("time_offset", "Simulation time at which the table's time 0 plays: the table is "
                  "read at t - time_offset", "s", 0.0, source=src),
        Parameter("interpolation", "Real channels between rows: 0 = sample-and-hold, 1 = linear "
                  "(Boolean and Integer channels always hold)", start=1, type="Integer", min=0, max=1,
                  source=src),
        Parameter("after_end", "After the table's last time: 0 = hold the last row, 1 = end the "
                  "co-simulation there (fmi2Discard, fmi2Terminated)", start=0, type="Integer",
                  min=0, max=1, source=src),
        Parameter("file", "CSV table: header line with 'time' or 'time_s' (s) first, then named columns; an "
                  "absolute path or relative to the FMU's resources/ (example.csv is shipped); "
                  "empty = no table, every channel 0 (then no column may be bound, unless optional)",
                  start="", type="String", source=src),
        Parameter("optional", "True: an empty file is an optional table left out (every channel 0 "
                  "although columns are bound, e.g. reference positions a user may not have); false: "
                  "a bound column needs a file", "", False, type="Boolean", source=src),
    ]
    parameters += [Parameter(f"column_{k}", f"Name of the CSV column that y_{k} plays (empty: "
                             "unbound, 0)", start="", type="String", source=src)
                   for k in range(1, N_REAL + 1)]
    parameters += [Parameter(f"boolean_column_{k}", f"Name of the 0/1 CSV column that boolean_{k} "
                             "plays (empty: unbound, false)", start="", type="String", source=src)
                   for k in range(1, N_BOOLEAN + 1)]
    parameters += [Parameter(f"integer_column_{k}", f"Name of the integer CSV column that "
                             f"integer_{k} plays (empty: unbound, 0)", start="", type="String",
                             source=src) for k in range(1, N_INTEGER + 1)]
    outputs = [Output(f"y_{k}", f"The column named by column_{k}, in that column's unit (the "
                      "file's); exactly the file's value at its times", "") for k in range(1, N_REAL + 1)]
    outputs += [Output(f"boolean_{k}", f"The 0/1 column named by boolean_column_{k} (held between "
                       "rows)", type="Boolean") for k in range(1, N_BOOLEAN + 1)]
    outputs += [Output(f"integer_{k}", f"The integer column named by integer_column_{k} (held "
                       "between rows)", type="Integer") for k in range(1, N_INTEGER + 1)]
    return Model(
        identifier="SignalTable",
        description="Replay of a measured, time-indexed CSV table: Real channels held or linearly "
                    "interpolated, Boolean and Integer channels held; optionally ends the "
                    "co-simulation at the table's end",
        parameters=parameters,
        outputs=outputs,
        c_sources=["SignalTable.c"],
        c_constants={"N_REAL_CHANNELS": N_REAL, "N_BOOLEAN_CHANNELS": N_BOOLEAN,
                     "N_INTEGER_CHANNELS": N_INTEGER},
        resources={"example.csv": EXAMPLE},
        documentation=__doc__,
    )


SIGNAL_TABLE = build()


# ---- Python twin of SignalTable.c (tests prove the FMU equals it) ---------------------------
@dataclass
class Table:
    """The rows of the bound columns: ``time`` (n,), ``real`` (n, N_REAL), ``boolean`` and
    ``integer`` (n, N_BOOLEAN / N_INTEGER); unbound channels are 0."""

    time: np.ndarray
    real: np.ndarray
    boolean: np.ndarray
    integer: np.ndarray

    @classmethod
    def read(cls, path: Path | str, columns: dict[str, str]) -> Table:
        """``columns`` maps a string parameter (``column_2``, ``boolean_column_1``, ...) to a
        column name, as the FMU's parameters do. Values are Python's float() of the text: the
        same double as C's strtod (both round correctly)."""
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
        header = [h.strip() for h in rows[0]]
        data = [r for r in rows[1:] if any(c.strip() for c in r)]
        n = len(data)
        t = np.array([float(r[0]) for r in data])
        if not np.all(np.diff(t) > 0):
            raise ValueError(f"{path}: time must increase strictly")
        out = cls(t, np.zeros((n, N_REAL)), np.zeros((n, N_BOOLEAN), bool), np.zeros((n, N_INTEGER), int))
        for param, name in columns.items():
            if not name:
                continue
            j = header.index(name)
            prefix, _, index = param.rpartition("_")
            kind, k = {"column": "real", "boolean_column": "boolean",
                       "integer_column": "integer"}[prefix], int(index) - 1
            if kind == "boolean":
                out.boolean[:, k] = [float(r[j]) == 1.0 for r in data]
            elif kind == "integer":
                out.integer[:, k] = [int(r[j]) for r in data]
            else:
                out.real[:, k] = [float(r[j]) for r in data]
        return out

    def tolerance(self, tau: float) -> float:
        gap = float(np.min(np.diff(self.time))) if len(self.time) > 1 else math.inf
        return min(TIME_TOLERANCE * max(1.0, abs(tau)), GAP_FRACTION * gap)

    def at(self, t: float, interpolation: int = 1, time_offset: float = 0.0):
        """(real, boolean, integer, ended) at simulation time t; ``ended``: past the last row
        (an FMU with after_end = 1 ends the simulation at the last row's time)."""
        tau = t - time_offset
        tol = self.tolerance(tau)
        k = int(np.searchsorted(self.time, tau + tol, side="right")) - 1
        last = len(self.time) - 1
        if k < 0:
            return self.real[0], self.boolean[0], self.integer[0], False
        ended = k == last and tau > self.time[last] + tol
        if k == last or abs(tau - self.time[k]) <= tol or interpolation == 0:
            return self.real[k], self.boolean[k], self.integer[k], ended
        w = (tau - self.time[k]) / (self.time[k + 1] - self.time[k])
        real = self.real[k] + (self.real[k + 1] - self.real[k]) * w
        return real, self.boolean[k], self.integer[k], False
