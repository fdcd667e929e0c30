r"""The strapdown INS of :mod:`railfmu.estimators.inertial.strapdown` as an online observer, and offline on a
user's ``imu.csv``: free-inertial navigation from the six IMU increments (the trolley survey
of Jiang et al. (2017); the aided filter builds on it).

Known inputs: ``dtheta_x, dtheta_y, dtheta_z`` (rad) and ``dv_x, dv_y, dv_z`` (m/s), the
increments over the IMU interval that *ends* at the sample time (body forward-right-down).
No measurements. Outputs: ``latitude, longitude`` (rad), ``height`` (m), ``vn, ve, vd`` (m/s),
``roll, pitch, heading`` (rad).

Offline on a user's data (``imu.csv`` and, for the initial state, ``truth.csv``; the formats of
the trolley survey)::

    ins = StrapdownINS(0.005, **initial_state_from_truth_csv("truth.csv"), heading_error=1e-3)
    t, nav = ins.run_imu_csv("imu.csv")        # nav: (n, 9), columns NAV

A bad file raises ``ValueError`` with one line naming file, line and column (estimators do
not import ``fmus``; the experiment that calls this turns it into a ``UserError``, exit 2).

The observer's ``dt`` is the IMU interval. The first sample (time ``t0``) carries the interval
*before* the initial state: it only primes the coning and sculling terms. A sample whose
input is missing (NaN), or a skipped sample time, is bridged by holding the last increment
(a constant rate), so a gap costs accuracy, not the time base.

Settings (all optional; SSD ``rf:Setting`` or keyword arguments): :class:`StrapdownSettings`,
as ``self.config`` (units, defaults and checks there; ``StrapdownSettings.describe()`` lists
them). Angles are in rad, as the SSDs bind them to the trolley's (rad) signals; Jiang et al.
(2017)'s 0.006 deg tilt and 0.06 deg heading errors are ``1.047e-4`` and ``1.047e-3`` rad.
With ``alignment="coarse"`` the position is held, the velocity zero and the given attitude
shown until the first increment; its heading error is ``eps / (Omega cos L)``
(``railfmu.estimators.inertial.attitude``).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from railfmu.estimators.inertial.attitude import (
    coarse_alignment,
    dcm_from_rph,
    perturb,
    rph_from_dcm,
)
from railfmu.estimators.core.observer import Observer
from railfmu.estimators.core.settings import Settings, setting
from railfmu.estimators.inertial.strapdown import NAV, Strapdown

#: the known inputs (and the columns of ``imu.csv`` after ``time_s``)
INCREMENTS = ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")



@dataclass(frozen=True)
class InitialState(Settings):
    """The true navigation state at ``t0`` and the INS's initial attitude error (shared by
    :class:`StrapdownINS` and the aided smoother). The error is a NED rotation vector
    ``(e_N, e_E, e_D)``: the INS starts at ``perturb(C_true, e)`` (e_D adds to the heading)."""

    latitude: float = setting(0.0, "rad", "initial latitude at t0", ge=-math.pi / 2, le=math.pi / 2)
    longitude: float = setting(0.0, "rad", "initial longitude")
    height: float = setting(0.0, "m", "initial height above the WGS-84 ellipsoid")
    vn: float = setting(0.0, "m/s", "initial north velocity")
    ve: float = setting(0.0, "m/s", "initial east velocity")
    vd: float = setting(0.0, "m/s", "initial down velocity")
    roll: float = setting(0.0, "rad", "initial true roll")
    pitch: float = setting(0.0, "rad", "initial true pitch")
    heading: float = setting(0.0, "rad", "initial true heading")
    tilt_error_north: float = setting(0.0, "rad", "initial attitude error e_N (paper: 0.006 deg = 1.047e-4 rad)")
    tilt_error_east: float = setting(0.0, "rad", "initial attitude error e_E")
    heading_error: float = setting(0.0, "rad", "initial attitude error e_D (paper: 0.06 deg = 1.047e-3 rad)")


@dataclass(frozen=True)
class StrapdownSettings(InitialState):
    """:class:`StrapdownINS`'s settings: the initial state and how the attitude is found."""

    alignment: str = setting("given", "", "'given': the attitude above plus its errors; 'coarse': static "
                             "coarse alignment from the first alignment_time s (body at rest)",
                             choices=("given", "coarse"))
    alignment_time: float = setting(60.0, "s", "length of the coarse alignment", gt=0)


class StrapdownINS(Observer):
    """Free-inertial strapdown INS (module docstring): ``StrapdownINS(dt, **settings)``."""

    inputs: ClassVar[tuple[str, ...]] = INCREMENTS
    measurements: ClassVar[tuple[str, ...]] = ()
    outputs: ClassVar[tuple[str, ...]] = NAV
    units: ClassVar[dict[str, str]] = {
        **{k: "rad" for k in INCREMENTS[:3]}, **{k: "m/s" for k in INCREMENTS[3:]},
        "latitude": "rad", "longitude": "rad", "height": "m", "vn": "m/s", "ve": "m/s", "vd": "m/s",
        "roll": "rad", "pitch": "rad", "heading": "rad"}

    def __init__(self, dt: float, **settings: Any) -> None:
        super().__init__(dt, **settings)
        self.config = s = StrapdownSettings.from_mapping(settings, "StrapdownINS")
        # a cross-check with dt, not a range: stays here
        if s.alignment == "coarse" and s.alignment_time < self.dt:
            raise ValueError(f"StrapdownINS: alignment_time {s.alignment_time!r} s is shorter than one "
                             f"IMU interval ({self.dt!r} s)")
        self.ins: Strapdown | None = None

    # -- initial state -------------------------------------------------------------------------
    def initial_attitude(self) -> np.ndarray:
        """C_b^n the INS starts from with ``alignment="given"``: the true attitude rotated by
        the configured errors."""
        s = self.config
        return perturb(dcm_from_rph(s.roll, s.pitch, s.heading),
                       [s.tilt_error_north, s.tilt_error_east, s.heading_error])

    def _start(self, C: np.ndarray, v_ned) -> Strapdown:
        s = self.config
        return Strapdown.from_rph(s.latitude, s.longitude, s.height, v_ned, rph_from_dcm(C), self.dt)

    def _reset(self) -> None:
        s = self.config
        self._pending = 0
        self._held: list[float] | None = None
        self._aligning = s.alignment == "coarse"
        if self._aligning:
            self._sum = np.zeros(6)
            self._n_align = 0
            self._n_align_target = max(1, round(s.alignment_time / self.dt))
            self._rph = (s.roll, s.pitch, s.heading)
            self.ins = None
        else:
            self.ins = self._start(self.initial_attitude(), (s.vn, s.ve, s.vd))

    # -- the observer hooks --------------------------------------------------------------------
    def _predict(self) -> None:
        self._pending += 1  # integrated when the increment of this interval arrives

    def _input(self, u: np.ndarray) -> None:
        row = u.tolist()
        if self._held is None and self._pending == 0:  # the interval before t0
            self._held = row
            if self.ins is not None:
                self.ins.prime(row[:3], row[3:])
            return
        if self._held is None:
            self._held = row
        for _ in range(self._pending - 1):  # skipped samples: hold the last increment
            self._interval(self._held)
        self._interval(row)
        self._pending = 0
        self._held = row

    def _interval(self, row: list[float]) -> None:
        if not self._aligning:
            self.ins.update(*row)
            return
        self._sum += row
        self._n_align += 1
        C = coarse_alignment(self._sum[3:], self._sum[:3])
        self._rph = tuple(rph_from_dcm(C))
        if self._n_align >= self._n_align_target:
            self._aligning = False
            self.ins = self._start(C, (0.0, 0.0, 0.0))
            self.ins.prime(row[:3], row[3:])

    def step(self, t: float, z: np.ndarray, u: np.ndarray | None = None,
             mask: np.ndarray | None = None) -> np.ndarray:
        """:meth:`Observer.step`; the common sample (one interval after the last, a finite
        input, navigating) takes a short path with the same arithmetic."""
        if (self._t is not None and not self._pending and not self._aligning and u is not None
                and len(z) == 0 and abs(t - self._t - self.dt) <= 1e-6 * self.dt):
            row = u.tolist() if isinstance(u, np.ndarray) else [float(x) for x in u]
            if len(row) == 6 and all(map(math.isfinite, row)):
                self.ins.update(*row)
                self._held = row
                self._t = t
                self.steps += 1
                return np.array(self.ins.navigation())
        return super().step(t, z, u, mask)

    def prepare(self) -> None:
        """Load the compiled mechanisation (one interval on a scratch state)."""
        Strapdown(0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), self.dt).navigate(np.zeros((1, 6)))

    def step_block(self, t: np.ndarray, Z: np.ndarray, U: np.ndarray | None = None,
                   mask: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`Observer.step_block`: each stretch of samples that :meth:`step` would take
        by its short path (one interval apart, finite increments, navigating) is one call of
        the compiled mechanisation (:meth:`Strapdown.navigate`), bit for bit the same; any
        other sample goes through :meth:`step`."""
        t = np.asarray(t, dtype=float)
        n = t.shape[0]
        if out is None:
            out = np.empty((n, len(self.outputs)))
        if U is None or n == 0 or len(Z[0]) != 0:
            return super().step_block(t, Z, U, mask, out)
        U = np.asarray(U, dtype=float)
        if U.shape != (n, 6):
            return super().step_block(t, Z, U, mask, out)
        prev = np.empty(n)
        prev[0] = np.nan if self._t is None else self._t
        prev[1:] = t[:-1]
        ok = (np.abs(t - prev - self.dt) <= 1e-6 * self.dt) & np.isfinite(U).all(axis=1)
        i = 0
        while i < n:
            if not (ok[i] and self._t is not None and not self._pending and not self._aligning):
                try:
                    super().step_block(t[i:i + 1], Z[i:i + 1], U[i:i + 1], None if mask is None else mask[i:i + 1],
                                       out[i:i + 1])
                except (ArithmeticError, ValueError) as exc:
                    exc.rows_done = i
                    raise
                i += 1
                continue
            j = i + int(np.argmin(ok[i:])) if not ok[i:].all() else n
            self.ins.navigate(U[i:j], out[i:j])
            self._held = U[j - 1].tolist()
            self._t = float(t[j - 1])
            self.steps += j - i
            i = j
        return out

    def _update(self, z: np.ndarray, mask: np.ndarray) -> None:
        pass  # free-inertial: no measurements

    def _estimate(self) -> np.ndarray:
        if self._pending and self._held is not None:  # a missing input: bridge with the held one
            for _ in range(self._pending):
                self._interval(self._held)
            self._pending = 0
        if self._aligning:
            s = self.config
            return np.array([s.latitude, s.longitude, s.height, 0.0, 0.0, 0.0, *self._rph])
        return np.array(self.ins.navigation())

    # -- offline on imu.csv --------------------------------------------------------------------
    def run_imu_csv(self, path: str | Path) -> tuple[np.ndarray, np.ndarray]:
        """Offline on an ``imu.csv`` (:func:`read_imu_csv`) whose rows are ``dt`` apart (or
        whole multiples of it): ``(t, estimates)``, estimates ``(n, 9)`` in :data:`NAV` order."""
        t, inc, lines = read_imu_csv(path)
        if t.shape[0] > 1:
            steps = np.diff(t) / self.dt
            bad = np.flatnonzero((np.abs(steps - np.round(steps)) > 1e-6) | (np.round(steps) < 1))
            if bad.size:
                k = int(bad[0])
                raise ValueError(f"{path}: line {lines[k + 1]}, column time_s: {float(t[k + 1])!r} is not a whole "
                                 f"number of IMU intervals ({self.dt!r} s) after {float(t[k])!r}")
        return t, self.run(t, np.empty((t.shape[0], 0)), inc)


def read_imu_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An ``imu.csv``: header ``time_s,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z`` (any column
    order, extra columns ignored), increments over the interval ending at ``time_s`` (rad,
    m/s, body forward-right-down) -> ``(t (n,), increments (n, 6), line numbers (n,))``. A missing column, a
    non-numeric or empty cell, or times that do not increase: ``ValueError`` with one line
    naming the file, the line and the column."""
    path = Path(path)
    try:
        f = open(path, newline="")
    except OSError as e:
        raise ValueError(f"{path}: cannot read ({e.strerror})") from None
    with f:
        reader = csv.reader(f)
        header = [h.strip() for h in next(reader, [])]
        if not header:
            raise ValueError(f"{path}: empty file (expected the header time_s,{','.join(INCREMENTS)})")
        names = ("time_s", *INCREMENTS)
        missing = [c for c in names if c not in header]
        if missing:
            raise ValueError(f"{path}: no column(s) {', '.join(missing)} (the header has {', '.join(header)})")
        cols = [header.index(c) for c in names]
        rows, lines = [], []
        for line, r in enumerate(reader, start=2):
            if not r or all(not x.strip() for x in r):
                continue
            try:
                rows.append([float(r[i]) for i in cols])
                lines.append(line)
            except (ValueError, IndexError):
                for c, i in zip(names, cols):
                    cell = r[i].strip() if i < len(r) else ""
                    try:
                        float(cell)
                    except ValueError:
                        raise ValueError(f"{path}: line {line}, column {c}: not a number: {cell!r}") from None
    data = np.array(rows, dtype=float).reshape(-1, 7)
    finite = np.isfinite(data)
    if not finite.all():
        k, j = np.argwhere(~finite)[0]
        raise ValueError(f"{path}: line {lines[k]}, column {names[j]}: not a finite number: {float(data[k, j])!r}")
    if data.shape[0] > 1 and np.any(np.diff(data[:, 0]) <= 0):
        k = int(np.flatnonzero(np.diff(data[:, 0]) <= 0)[0])
        raise ValueError(f"{path}: line {lines[k + 1]}, column time_s: {float(data[k + 1, 0])!r} does not increase "
                         f"after {float(data[k, 0])!r}")
    return data[:, 0], data[:, 1:], np.array(lines, dtype=int)


#: ``truth.csv`` columns that give the INS its initial state, with their factor to SI/rad
_TRUTH_START = {"lat_deg": ("latitude", math.pi / 180), "lon_deg": ("longitude", math.pi / 180),
                "height_m": ("height", 1.0), "vn": ("vn", 1.0), "ve": ("ve", 1.0), "vd": ("vd", 1.0),
                "roll_deg": ("roll", math.pi / 180), "pitch_deg": ("pitch", math.pi / 180),
                "heading_deg": ("heading", math.pi / 180)}


def initial_state_from_truth_csv(path: str | Path, time_s: float | None = None) -> dict[str, float]:
    """The :class:`StrapdownINS` settings of the initial state (rad, m, m/s) from a
    ``truth.csv`` (``time_s, lat_deg, lon_deg, height_m, vn, ve, vd, roll_deg, pitch_deg,
    heading_deg, ...``): its row at ``time_s`` (default: the first row). ValueError (one line,
    file and column) if a column is missing, a cell is not a number or no row has that time."""
    path = Path(path)
    try:
        f = open(path, newline="")
    except OSError as e:
        raise ValueError(f"{path}: cannot read ({e.strerror})") from None
    with f:
        reader = csv.reader(f)
        header = [h.strip() for h in next(reader, [])]
        missing = [c for c in ("time_s", *_TRUTH_START) if c not in header]
        if missing:
            raise ValueError(f"{path}: no column(s) {', '.join(missing)} "
                             f"(the header has {', '.join(header) or 'nothing'})")
        for line, r in enumerate(reader, start=2):
            if not r or all(not x.strip() for x in r):
                continue
            values = {}
            for c in ("time_s", *_TRUTH_START):
                cell = r[header.index(c)].strip() if header.index(c) < len(r) else ""
                try:
                    values[c] = float(cell)
                except ValueError:
                    raise ValueError(f"{path}: line {line}, column {c}: not a number: {cell!r}") from None
            if time_s is None or abs(values["time_s"] - time_s) <= 1e-9 * max(1.0, abs(time_s)):
                return {name: values[c] * k for c, (name, k) in _TRUTH_START.items()}
    raise ValueError(f"{path}: column time_s: no row at {time_s!r} s" if time_s is not None
                     else f"{path}: no data rows")
