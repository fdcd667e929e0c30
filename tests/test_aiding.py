"""The aiding measurement objects of the aided INS (estimators/inertial/aiding.py): their
epochs and rows, the stacking, and that a new aiding is a new class the filter loop picks up
without an edit (on a 20 s synthetic rest record, no FMU)."""

from __future__ import annotations

import numpy as np
import pytest

from railfmu.estimators.inertial import aiding
from railfmu.estimators.inertial.aided_ins import MEASUREMENTS, AidedInsSettings, AidedInsSmoother, FilterModel
from railfmu.estimators.inertial.aiding import (
    AIDINGS,
    Aiding,
    EpochBlock,
    Landmark,
    Measurement,
    Nhc,
    Odometer,
    Record,
    Zupt,
    aidings_from_record,
    stack,
)
from railfmu.models import earth

DT = 0.005
LAT = 0.5


def _record(n_epochs: int = 6, **settings) -> Record:
    s = AidedInsSettings.from_mapping(settings, "test")
    idx = np.arange(n_epochs) * 10
    Z = np.full((idx[-1] + 1, len(MEASUREMENTS)), np.nan)
    zupt = np.zeros(n_epochs, dtype=bool)
    zupt[[0, 3]] = True
    return Record(s, FilterModel(s), Z, np.isfinite(Z), MEASUREMENTS, idx, zupt)


def test_measurements_are_the_aidings_columns():
    assert MEASUREMENTS == ("stopped", "odometer", "landmark_latitude", "landmark_longitude", "landmark_height")
    assert [cls.name for cls in AIDINGS] == ["zupt", "nhc", "odometer", "landmark"]


def test_the_settings_choose_the_aidings():
    assert [type(a) for a in aidings_from_record(_record())] == [Zupt]
    on = _record(nhc=True, odometer=True, landmarks=True, zupt=False)
    assert [type(a) for a in aidings_from_record(on)] == [Nhc, Odometer, Landmark]


def test_motion_constraints_skip_the_first_epoch_and_the_zupts():
    rec = _record(nhc=True, odometer=True)
    rec.Z[:, 1] = np.arange(rec.Z.shape[0]) * 1e-3
    rec.Z[25, 1] = np.nan  # not at an epoch: no effect
    rec.Z[40, 1] = np.nan  # epoch 4: its speed and epoch 5's lack an end
    rec.mask = np.isfinite(rec.Z)
    nhc, odo = Nhc.from_record(rec), Odometer.from_record(rec)
    assert nhc.epochs.tolist() == [False, True, True, False, True, True]
    assert odo.epochs.tolist() == [False, True, True, False, False, False]


def test_a_held_landmark_fix_is_used_once_and_the_last_of_a_chunk_wins():
    rec = _record(landmarks=True)
    rec.Z[3:8, 2:5] = (0.5, 0.1, 10.0)  # held over five samples: one fix, at epoch 1 (sample 10)
    rec.Z[31, 2:5] = (0.5, 0.1, 11.0)
    rec.Z[33, 2:5] = (0.5, 0.1, 12.0)  # the same chunk (epoch 4): this one
    rec.mask = np.isfinite(rec.Z)
    lm = Landmark.from_record(rec)
    assert np.flatnonzero(lm.epochs).tolist() == [1, 4]
    assert lm.fix_at[1] == 3 and lm.fix_at[4] == 33


def test_rows_and_stack():
    s = AidedInsSettings.from_mapping({"nhc": True, "odometer": True}, "test")
    model = FilterModel(s)
    C = np.repeat(np.eye(3)[None], 2, axis=0)
    vel = np.array([[1.0, 0.01, -0.02], [1.0, 0.0, 0.0]])
    block = EpochBlock(model, 5, C, vel)
    on = np.ones(7, dtype=bool)
    z = Zupt(on, 1e-4, model)
    nhc = Nhc(on, 1e-3)
    odo = Odometer(on, 2e-3)
    assert z.measure(0, 5, block).z.tolist() == vel[0].tolist()
    m_nhc = nhc.measure(0, 5, block)
    assert m_nhc.z.tolist() == [0.01, -0.02]
    assert np.array_equal(m_nhc.H, model.body_velocity_rows(C, vel)[0, 1:])
    assert Zupt(~on, 1e-4, model).measure(0, 5, block) is None
    one = Measurement(np.zeros(3), *z.rows(0, 5, block))
    assert stack([one]) is one
    both = stack([one, Measurement(np.zeros(1), *odo.rows(0, 5, block)), m_nhc])
    assert both.H.shape == (6, model.n) and both.z.shape == (6,)
    assert np.array_equal(both.H[3], block.body_rows[0, 0]) and np.array_equal(both.H[4:], m_nhc.H)
    assert np.array_equal(both.R, np.diag([1e-8] * 3 + [4e-6] + [1e-6] * 2))


def _rest(n: int):
    """A level trolley at rest, heading north: the ideal increments, stopped for the first
    and last 2 s."""
    t = np.arange(n) * DT
    U = np.zeros((n, 6))
    U[:, :3] = earth.earth_rate_n(LAT) * DT
    U[:, 5] = -earth.gravity(LAT, 0.0) * DT
    Z = np.full((n, len(MEASUREMENTS)), np.nan)
    Z[:, 0] = (t < 2) | (t > t[-1] - 2)
    Z[:, 1] = 0.0
    return t, Z, U


class _NoFix(Aiding):
    """An aiding that never measures."""

    name = "nofix"

    def __init__(self) -> None:
        super().__init__(np.zeros(0, dtype=bool))

    @classmethod
    def from_record(cls, rec):
        return cls()

    def rows(self, j, k, block):
        return None


class _Heave(Aiding):
    """A vertical velocity of 0 at every epoch (a stand-in for a new sensor)."""

    name = "heave"

    @classmethod
    def from_record(cls, rec):
        out = cls(np.ones(rec.idx.size, dtype=bool))
        out.H, out.R = rec.model.velocity_rows()[2:], np.array([[1e-6]])
        return out

    def rows(self, j, k, block):
        return self.H, self.R

    def innovation(self, j, k, block):
        return block.vel[j, 2:]


@pytest.mark.parametrize("extra", [_NoFix, _Heave])
def test_a_new_aiding_is_a_new_class(monkeypatch, extra):
    t, Z, U = _rest(4001)
    settings = dict(latitude=LAT, nhc=True, odometer=True, tilt_error_north=1e-4, velocity_error_down=1e-3)
    base = AidedInsSmoother(DT, **settings)
    est0 = base.run(t, Z, U)
    monkeypatch.setattr(aiding, "AIDINGS", (*AIDINGS, extra))
    obs = AidedInsSmoother(DT, **settings)
    est = obs.run(t, Z, U)
    counts = obs.finish()
    for k in ("zupt_updates", "nhc_updates", "odometer_updates", "landmark_updates"):
        assert counts[k] == base.finish()[k]
    if extra is _NoFix:  # the loop unchanged: bit for bit the run without it
        assert counts["nofix_updates"] == 0
        assert np.array_equal(est, est0)
    else:
        assert counts["heave_updates"] == obs.epoch_times.size
        assert counts["zupt_updates"] > 0 and counts["nhc_updates"] > 0
        assert not np.array_equal(est, est0)
        p, p0 = np.asarray(obs.P_filter)[:, 5, 5], np.asarray(base.P_filter)[:, 5, 5]
        assert np.all(p <= p0) and np.all(p[1:] < p0[1:])  # more information on dv_D
