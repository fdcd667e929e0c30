r"""The aiding measurements of the trolley's INS (:mod:`railfmu.estimators.inertial.aided_ins`),
one class per sensor in the manner of pyins' ``measurements``: at an epoch ``k`` each gives
its :class:`Measurement` ``(z, H, R)`` -- or ``None`` when it has none there -- from the
epoch's nominal navigation (an :class:`EpochBlock`), the filter's error model and its own
data (its columns of the record). The filter loop asks every active aiding in turn, stacks
what they give in that order (:func:`stack`) and makes one Joseph update; it knows no sensor.
A new aiding is a new class here, appended to :data:`AIDINGS`.

The error state ``dx`` is the filter's (``PHI, DV, DR`` first, then biases and play states);
``z`` is the INS's computed quantity minus the sensor's, ``z = H dx + noise``, noise
``N(0, R)``. The rows are the error model's (``FilterModel.velocity_rows``,
``position_rows``, ``body_velocity_rows``, padded to the filter's state).

Interface of an aiding:

* ``settings``: its frozen :class:`~railfmu.estimators.core.settings.Settings` dataclass (the
  switch and the noise, SSD keys of their own); the smoother's settings class is composed of
  those of :data:`AIDINGS` (``AidedInsSettings``), so a new aiding brings its block with it;
* ``name``: its count in ``AidedInsSmoother.finish()`` is ``f"{name}_updates"``;
  ``columns``, ``units``: its measurements of the record (``AidedInsSmoother.measurements``
  is their concatenation over :data:`AIDINGS`);
* ``from_record(rec)``: the aiding of a run (a :class:`Record`), or ``None`` when the
  settings switch it off; the plain constructor, with a boolean ``epochs`` mask and no data,
  is the one :func:`~railfmu.estimators.inertial.aided_ins.covariance_analysis` uses;
* ``prepare(block)``: the block's quantities formed at once (vectorised over its epochs);
* ``rows(j, k, block)``: ``(H, R)`` at epoch ``k`` (row ``j`` of the block) or ``None``:
  all that the covariance recursion needs;
* ``innovation(j, k, block)``: ``z``, from the data; ``measure`` is ``rows`` and ``z``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar, NamedTuple

import numpy as np

from railfmu.estimators.core.settings import Settings, number_or_inf, setting
from railfmu.estimators.inertial.ins_error_model import ned_difference
from railfmu.estimators.inertial.rail_play import BUTTERWORTH

#: the NHC's sigma when the play is modelled (``play_model="shaping"``): only the unmodelled rest
NHC_SIGMA_SHAPING = 1e-4


@dataclass(frozen=True)
class ZuptSettings(Settings):
    """Zero-velocity updates (:class:`Zupt`; the smoother picks the epochs)."""

    zupt: bool = setting(True, "", "zero-velocity updates at the stopped epochs")
    zupt_sigma: float = setting(1e-4, "m/s", "ZUPT noise std per axis", gt=0)
    zupt_interval: float = setting(0.0, "s", "0: every stopped epoch; T: the first of a stop, then every T s; "
                                   "inf: one per stop (the paper's)", ge=0, convert=number_or_inf)
    zupt_source: str = setting("flag", "", "the stops: 'flag' (the stopped measurement) or 'detector' "
                               "(detect_stationary on the increments)", choices=("flag", "detector"))


@dataclass(frozen=True)
class NhcSettings(Settings):
    """Non-holonomic constraint (:class:`Nhc`) and the wheel-rail play in it
    (:mod:`railfmu.estimators.inertial.rail_play`, with ``play_model="shaping"``)."""

    nhc: bool = setting(False, "", "non-holonomic constraint (no sideways or vertical body velocity)")
    nhc_sigma: float | None = setting(None, "m/s", f"NHC noise std; default 1e-3, with play_model='shaping' "
                                      f"{NHC_SIGMA_SHAPING:g} (only what the play model leaves out)", gt=0)
    play_model: str = setting("white", "", "the body's cross-track velocity: 'white' (noise of nhc_sigma) or "
                              "'shaping' (four play states)", choices=("white", "shaping"))
    play_sigma_lateral: float = setting(1e-3, "m", "stationary sigma of the lateral play (a sinusoid of "
                                        "amplitude a: a / sqrt(2))", ge=0)
    play_sigma_vertical: float = setting(5e-4, "m", "stationary sigma of the vertical play", ge=0)
    play_wavelength: float = setting(2.0, "m", "the play's natural wavelength 2 pi / k", gt=0)
    play_damping: float = setting(BUTTERWORTH, "", "the play oscillator's damping zeta (smaller: narrower "
                                  "spectrum)", gt=0)

    def __post_init__(self) -> None:
        if self.nhc_sigma is None:  # its default depends on the play model
            object.__setattr__(self, "nhc_sigma", NHC_SIGMA_SHAPING if self.play_model == "shaping" else 1e-3)


@dataclass(frozen=True)
class OdometerSettings(Settings):
    """Odometer speed (:class:`Odometer`)."""

    odometer: bool = setting(False, "", "odometer speed updates")
    odometer_sigma: float = setting(1e-3, "m/s", "odometer speed noise std", gt=0)


@dataclass(frozen=True)
class LandmarkSettings(Settings):
    """Landmark position fixes (:class:`Landmark`)."""

    landmarks: bool = setting(False, "", "landmark position fixes")
    landmark_sigma: float = setting(0.1, "m", "landmark fix noise std per axis", gt=0)


class Measurement(NamedTuple):
    """One aiding's update at an epoch: ``z`` ``(m,)``, ``H`` ``(m, n)``, ``R`` ``(m, m)``."""

    z: np.ndarray
    H: np.ndarray
    R: np.ndarray


@dataclass
class Record:
    """What a run gives the aidings: the settings ``s`` (``AidedInsSettings``), the filter's ``model``
    (``FilterModel``), the measurements ``Z`` ``(n_samples, len(names))`` with their
    ``mask`` (present), their ``names``, the samples ``idx`` of the epochs and the epochs
    with a ZUPT (``zupt``, ``(N,)`` bool: the observer's choice, flag or detector)."""

    s: Any
    model: Any
    Z: np.ndarray
    mask: np.ndarray
    names: tuple[str, ...]
    idx: np.ndarray
    zupt: np.ndarray

    def _at(self, columns: tuple[str, ...]) -> slice:
        i = self.names.index(columns[0])
        if self.names[i:i + len(columns)] != columns:
            raise ValueError(f"Record: columns {columns} are not adjacent in {self.names}")
        return slice(i, i + len(columns))

    def columns(self, columns: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        """``(Z, mask)`` of the named adjacent columns (views)."""
        c = self._at(columns)
        return self.Z[:, c], self.mask[:, c]

    def after_start_without_zupt(self) -> np.ndarray:
        """The epochs after the first without a ZUPT (where the motion constraints apply)."""
        out = ~self.zupt
        out[:1] = False
        return out


class EpochBlock:
    """The nominal navigation of consecutive epochs ``first .. first + M - 1`` (the INS
    before that epoch's feedback): ``C`` ``(M, 3, 3)`` attitude ``C_b^n`` and ``vel``
    ``(M, 3)`` NED velocity (m/s) at each epoch; with data also ``epoch_nav`` ``(M, 9)`` the
    INS's navigation at the epochs (``strapdown.NAV``), ``C_m`` ``(M, 3, 3)`` the
    mid-interval attitude, ``T`` ``(M,)`` (s) the intervals ending at the epochs (``None``
    for the initial epoch), ``start`` the INS's ``(lat, lon, h)`` (rad, rad, m) where the
    block's first interval starts, ``nav`` the INS's navigation at every sample so far."""

    def __init__(self, model: Any, first: int, C: np.ndarray, vel: np.ndarray, *, epoch_nav: np.ndarray | None = None,
                 C_m: np.ndarray | None = None, T: np.ndarray | None = None, start: tuple | None = None,
                 nav: np.ndarray | None = None) -> None:
        self.model, self.first, self.C, self.vel = model, first, C, vel
        self.epoch_nav, self.C_m, self.T, self.start, self.nav = epoch_nav, C_m, T, start, nav

    @cached_property
    def body_rows(self) -> np.ndarray:
        """``(M, 3, n)``: ``H`` of the body velocity (x, y, z) at each epoch, formed once for
        the aidings that share it (NHC, odometer)."""
        return self.model.body_velocity_rows(self.C, self.vel)

    @cached_property
    def body_velocity(self) -> np.ndarray:
        """``(M, 3)``: the INS's body velocity ``v~^b = C^T v~^n`` (m/s)."""
        return np.einsum("kji,kj->ki", self.C, self.vel)


class Aiding:
    """An aiding sensor (module docstring). Subclasses set ``name``, ``columns``, ``units``,
    ``R`` and give ``rows``, ``innovation``; ``epochs`` ``(N,)`` bool: where it has a
    measurement."""

    name: ClassVar[str]
    settings: ClassVar[type[Settings]]
    columns: ClassVar[tuple[str, ...]] = ()
    units: ClassVar[dict[str, str]] = {}
    R: np.ndarray

    def __init__(self, epochs: np.ndarray) -> None:
        self.epochs = np.asarray(epochs, dtype=bool)

    @classmethod
    def from_record(cls, rec: Record) -> Aiding | None:
        raise NotImplementedError

    def prepare(self, block: EpochBlock) -> None:
        """The block's vectorised quantities (none by default)."""

    def rows(self, j: int, k: int, block: EpochBlock) -> tuple[np.ndarray, np.ndarray] | None:
        raise NotImplementedError

    def innovation(self, j: int, k: int, block: EpochBlock) -> np.ndarray:
        raise NotImplementedError

    def measure(self, j: int, k: int, block: EpochBlock) -> Measurement | None:
        rows = self.rows(j, k, block)
        return None if rows is None else Measurement(self.innovation(j, k, block), *rows)


class Zupt(Aiding):
    r"""Zero-velocity update at the epochs the trolley stands still (the observer picks them:
    ``zupt_interval``, ``zupt_source``)::

        z = v~^n (m/s),   H = [0 I 0 ...] (rows of dv),   R = zupt_sigma^2 I_3
    """

    name = "zupt"
    settings = ZuptSettings
    columns = ("stopped",)
    units = {"stopped": ""}

    def __init__(self, epochs: np.ndarray, sigma: float, model: Any) -> None:
        super().__init__(epochs)
        self.H = model.velocity_rows()
        self.R = sigma ** 2 * np.eye(3)

    @classmethod
    def from_record(cls, rec: Record) -> Zupt | None:
        return cls(rec.zupt, rec.s.zupt_sigma, rec.model) if rec.s.zupt else None

    def rows(self, j, k, block):
        return (self.H, self.R) if self.epochs[k] else None

    def innovation(self, j, k, block):
        return block.vel[j]


class Nhc(Aiding):
    r"""Non-holonomic constraint: the body neither slips sideways nor lifts off the rail
    (``x_b`` the rail tangent), at the epochs without a ZUPT (after the first)::

        z = (v~^b_y, v~^b_z) (m/s),   H = rows y, z of FilterModel.body_velocity_rows
            (-C_n^b [v^n x] phi + C_n^b dv, and v_s (y', z') with the play states),
        R = nhc_sigma^2 I_2
    """

    name = "nhc"
    settings = NhcSettings

    def __init__(self, epochs: np.ndarray, sigma: float) -> None:
        super().__init__(epochs)
        self.R = sigma ** 2 * np.eye(2)

    @classmethod
    def from_record(cls, rec: Record) -> Nhc | None:
        return cls(rec.after_start_without_zupt(), rec.s.nhc_sigma) if rec.s.nhc else None

    def rows(self, j, k, block):
        return (block.body_rows[j, 1:], self.R) if self.epochs[k] else None

    def innovation(self, j, k, block):
        return block.body_velocity[j, 1:]


class Odometer(Aiding):
    r"""Odometer speed over each epoch (the cumulative distance ``s``, m, at both ends
    present), at the epochs without a ZUPT (after the first)::

        z = x_b^T (r_k - r_{k-1}) / T - (s_k - s_{k-1}) / T   (m/s; x_b at mid-epoch, r NED)
        H = row x of FilterModel.body_velocity_rows at the epoch's end,   R = odometer_sigma^2

    The INS's mean body-x speed differs from its end velocity error by ``|dv'| T / 2``, below
    ``odometer_sigma``; the odometer's scale factor is not a state."""

    name = "odometer"
    settings = OdometerSettings
    columns = ("odometer",)
    units = {"odometer": "m"}

    def __init__(self, epochs: np.ndarray, sigma: float, distance: np.ndarray | None = None,
                 idx: np.ndarray | None = None) -> None:
        super().__init__(epochs)
        self.R = np.array([[sigma ** 2]])
        self.distance, self.idx = distance, idx

    @classmethod
    def from_record(cls, rec: Record) -> Odometer | None:
        if not rec.s.odometer:
            return None
        Z, mask = rec.columns(cls.columns)
        ok = np.zeros(rec.idx.size, dtype=bool)
        ok[1:] = mask[rec.idx[1:], 0] & mask[rec.idx[:-1], 0]  # a speed needs both ends
        return cls(ok & rec.after_start_without_zupt(), rec.s.odometer_sigma, Z[:, 0], rec.idx)

    def prepare(self, block):
        if block.T is None or self.distance is None:
            return
        first, M, T = block.first, block.T.size, block.T
        pos = np.vstack((block.start, block.epoch_nav[:, :3]))
        dr = ned_difference(pos[1:, 0], pos[1:, 1], pos[1:, 2], pos[:-1, 0], pos[:-1, 1], pos[:-1, 2])
        self.v_ins = np.einsum("ki,ki->k", block.C_m[:, :, 0], dr) / T
        self.v_odo = (self.distance[self.idx[first:first + M]] - self.distance[self.idx[first - 1:first - 1 + M]]) / T

    def rows(self, j, k, block):
        return (block.body_rows[j, :1], self.R) if self.epochs[k] else None

    def innovation(self, j, k, block):
        return np.array([self.v_ins[j] - self.v_odo[j]])


class Landmark(Aiding):
    r"""Landmark position fix (``landmark_latitude``, ``landmark_longitude`` (rad),
    ``landmark_height`` (m)) at the epoch that ends the chunk with the fix's sample ``t_j``::

        z = r~(t_j) - r_landmark (local NED, m; the INS at t_j itself),
        H = [0 0 I ...] (rows of dr),   R = landmark_sigma^2 I_3

    The error moves by ``dv (t_k - t_j)`` < 1e-5 m in between. A fix held over consecutive
    samples (the same three values) is one fix, used once; of two fixes in one chunk the
    last."""

    name = "landmark"
    settings = LandmarkSettings
    columns = ("landmark_latitude", "landmark_longitude", "landmark_height")
    units = {"landmark_latitude": "rad", "landmark_longitude": "rad", "landmark_height": "m"}

    def __init__(self, epochs: np.ndarray, sigma: float, model: Any, fix_at: np.ndarray | None = None,
                 fixes: np.ndarray | None = None) -> None:
        super().__init__(epochs)
        self.H = model.position_rows()
        self.R = sigma ** 2 * np.eye(3)
        self.fix_at, self.fixes = fix_at, fixes

    @classmethod
    def from_record(cls, rec: Record) -> Landmark | None:
        if not rec.s.landmarks:
            return None
        Z, mask = rec.columns(cls.columns)
        fix_at = np.full(rec.idx.size, -1)  # the sample of the fix an epoch uses
        present = mask.all(axis=1)
        new = present.copy()
        new[1:] &= ~(present[:-1] & np.all(Z[1:] == Z[:-1], axis=1))  # a held fix is one fix
        for j in np.flatnonzero(new):
            fix_at[np.searchsorted(rec.idx, j, side="left")] = j  # the last fix of a chunk wins
        return cls(fix_at >= 0, rec.s.landmark_sigma, rec.model, fix_at, Z)

    def rows(self, j, k, block):
        return (self.H, self.R) if self.epochs[k] else None

    def innovation(self, j, k, block):
        i = int(self.fix_at[k])
        nav, fix = block.nav, self.fixes[i]
        return ned_difference(nav[i, 0], nav[i, 1], nav[i, 2], fix[0], fix[1], fix[2])


#: every aiding, in the order their rows are stacked at an epoch
AIDINGS: tuple[type[Aiding], ...] = (Zupt, Nhc, Odometer, Landmark)


def aidings_from_record(rec: Record) -> list[Aiding]:
    """The aidings the run's settings switch on, in :data:`AIDINGS` order."""
    return [a for a in (cls.from_record(rec) for cls in AIDINGS) if a is not None]


def update_counts() -> dict[str, int]:
    """``{f"{name}_updates": 0}`` of every aiding in :data:`AIDINGS` (those off stay 0)."""
    return {f"{cls.name}_updates": 0 for cls in AIDINGS}


def stack(measurements: list[Measurement]) -> Measurement:
    """One measurement of several: ``z``, ``H`` stacked in order, ``R`` block diagonal (the
    aidings' noises are independent)."""
    if len(measurements) == 1:
        return measurements[0]
    z = np.concatenate([m.z for m in measurements])
    H = np.vstack([m.H for m in measurements])
    R = np.zeros((z.size, z.size))
    o = 0
    for m in measurements:
        r = m.R.shape[0]
        R[o:o + r, o:o + r] = m.R
        o += r
    return Measurement(z, H, R)
