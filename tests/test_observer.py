"""The observer interface (estimators/core/observer.py) on data from the real FMUs: online step by
step equals offline, CSV equals arrays, missing channels are left out and counted."""

import numpy as np
import pytest

from railfmu.estimators.track.alignment import AlignmentKalmanFilter
from helpers import track_wheelset_signals

DT = 1e-3
COLUMNS = {"ddy": "wheelset.ddy", "dpsi": "wheelset.dpsi", "ddy_f": "wheelset.ddy_f"}


@pytest.fixture(scope="module")
def recorded(fmu_dir, tmp_path_factory):
    """3 s of ERRI B176 low-level alignment at 20 m/s, also written as signals.csv."""
    csv_path = tmp_path_factory.mktemp("observer") / "signals.csv"
    t, Z, xi = track_wheelset_signals(fmu_dir, {"psd_level": 1, "seed": 1, "V": 20.0}, 3.0, csv_path)
    return t, Z, xi, csv_path


@pytest.mark.parametrize("steady_state", [True, False])
def test_online_step_equals_offline_run(recorded, steady_state):
    t, Z, _, _ = recorded
    offline = AlignmentKalmanFilter(DT, steady_state=steady_state).run(t, Z)
    online_kf = AlignmentKalmanFilter(DT, steady_state=steady_state)
    online_kf.reset(t[0])
    online = np.array([online_kf.step(tk, zk) for tk, zk in zip(t, Z)])
    assert offline.shape == (len(t), 7)
    assert np.array_equal(online, offline)
    # a second offline run on the same object resets first
    assert np.array_equal(online_kf.run(t, Z), offline)


def test_run_csv_equals_run(recorded):
    t, Z, _, csv_path = recorded
    kf = AlignmentKalmanFilter(DT)
    t_csv, X_csv = kf.run_csv(csv_path, columns=COLUMNS)
    assert np.array_equal(t_csv, t)
    assert np.array_equal(X_csv, AlignmentKalmanFilter(DT).run(t, Z))
    with pytest.raises(ValueError, match="no column"):
        kf.run_csv(csv_path)  # the CSV names are wheelset.ddy, ...: no column 'ddy'


def test_run_named_equals_run(recorded):
    """Plain arrays by channel name give the matrix run's estimates, output by output; a
    masked channel is missing; a wrong name is one error naming it."""
    t, Z, _, _ = recorded
    kf = AlignmentKalmanFilter(DT)
    X = AlignmentKalmanFilter(DT).run(t, Z)
    named = kf.run_named(t, {"ddy": Z[:, 0], "dpsi": Z[:, 1], "ddy_f": Z[:, 2]})
    assert list(named) == ["time", *kf.outputs]
    assert all(np.array_equal(named[o], X[:, j]) for j, o in enumerate(kf.outputs))
    off = np.zeros(len(t), dtype=bool)
    masked = kf.run_named(t, {"ddy": Z[:, 0], "dpsi": Z[:, 1], "ddy_f": Z[:, 2]}, masks={"dpsi": off})
    Z_nan = Z.copy()
    Z_nan[:, 1] = np.nan
    assert np.array_equal(masked["xi"], AlignmentKalmanFilter(DT).run(t, Z_nan)[:, kf.outputs.index("xi")])
    with pytest.raises(ValueError, match=r"missing channel\(s\) \['ddy_f'\]; unknown channel\(s\) \['ddyf'\]"):
        kf.run_named(t, {"ddy": Z[:, 0], "dpsi": Z[:, 1], "ddyf": Z[:, 2]})


def test_run_csv_empty_cell_is_a_missing_channel(recorded, tmp_path):
    """A measured record replayed from CSV: an empty cell is a missing channel, as NaN."""
    t, Z, _, csv_path = recorded
    lines = csv_path.read_text().splitlines()
    col = lines[0].split(",").index("wheelset.dpsi")
    cells = lines[51].split(",")
    cells[col] = ""
    lines[51] = ",".join(cells)  # row 50 of the data
    gappy = tmp_path / "gappy.csv"
    gappy.write_text("\n".join(lines) + "\n")
    kf = AlignmentKalmanFilter(DT)
    _, X = kf.run_csv(gappy, columns=COLUMNS)
    Z_nan = Z.copy()
    Z_nan[50, 1] = np.nan
    assert np.array_equal(X, AlignmentKalmanFilter(DT).run(t, Z_nan)) and kf.partial == 1


@pytest.mark.parametrize("steady_state", [True, False])
def test_missing_channels_are_left_out(recorded, steady_state):
    """One sensor missing: updated with the others; all missing: a prediction only, the same
    as a row that never arrived; a mask equals NaN in the masked places."""
    t, Z, _, _ = recorded
    clean = AlignmentKalmanFilter(DT, steady_state=steady_state).run(t, Z)
    bad = Z.copy()
    bad[100, 0] = np.nan
    bad[200, 2] = np.inf
    bad[300:310, :] = np.nan
    kf = AlignmentKalmanFilter(DT, steady_state=steady_state)
    X = kf.run(t, bad)
    assert (kf.skipped, kf.partial) == (10, 2) and kf.finish()["skipped"] == 10 and kf.finish()["steps"] == len(t)
    assert np.all(np.isfinite(X))
    assert np.array_equal(X[:100], clean[:100])  # nothing leaks backwards
    assert not np.array_equal(X[100], clean[100])  # the bad channel was not used ...
    X_pred = AlignmentKalmanFilter(DT, steady_state=steady_state).run(t[:101], np.vstack([Z[:100], np.nan * Z[0]]))
    assert not np.array_equal(X[100], X_pred[100])  # ... the other two were
    mask = np.isfinite(bad)
    assert np.array_equal(AlignmentKalmanFilter(DT, steady_state=steady_state).run(t, Z, mask=mask), X)
    # a sample with no sensor is a prediction only: the same as a sample that never arrived
    gap = np.r_[0:300, 310:len(t)]
    X_gap = AlignmentKalmanFilter(DT, steady_state=steady_state).run(t[gap], bad[gap])
    assert np.array_equal(X_gap[300:], X[310:])


def test_masked_channel_is_a_channel_of_infinite_noise(recorded):
    """The time-varying filter with the gyro masked out at every sample equals (to 1e-9) the
    filter whose gyro has a standard deviation of 1e9 rad/s, from the same initial covariance."""
    t, Z, xi, _ = recorded
    std = np.array([1e-3, 1e-4, 1e-3, 1e-2, 1e-2, 1e-2, 1e-3])
    masked = AlignmentKalmanFilter(DT, steady_state=False, P0=std).run(
        t, Z, mask=np.tile([True, False, True], (len(t), 1)))
    deaf = AlignmentKalmanFilter(DT, steady_state=False, P0=std, sigma_gyro=1e9).run(t, Z)
    assert np.abs(masked[:, 6] - deaf[:, 6]).max() < 1e-9 * np.sqrt(np.mean(xi ** 2))
    full = AlignmentKalmanFilter(DT, steady_state=False, P0=std).run(t, Z)
    assert np.abs(masked[:, 6] - full[:, 6]).max() > 1e-3 * np.sqrt(np.mean(xi ** 2))  # the gyro matters


def test_time_and_shape_checks(recorded):
    t, Z, _, _ = recorded
    kf = AlignmentKalmanFilter(DT)
    kf.reset(0.0)
    kf.step(0.0, Z[0])
    with pytest.raises(ValueError, match="sample times"):
        kf.step(0.0015, Z[1])  # not a whole number of steps later
    with pytest.raises(ValueError, match="shape"):
        kf.step(0.001, Z[1, :2])
    with pytest.raises(ValueError, match="do not match"):
        kf.run(t, Z[:, :2])
    with pytest.raises(ValueError, match="unknown setting"):
        AlignmentKalmanFilter(DT, conicity=0.1)
    with pytest.raises(ValueError, match="dt"):
        AlignmentKalmanFilter(0.0)
    assert AlignmentKalmanFilter(DT, steady_state="false").steady_state is False  # SSD text
    assert kf.units["ddy"] == "m/s2" and kf.units["xi"] == "m"
    assert set(kf.units) == {*kf.measurements, *kf.outputs} and kf.inputs == ()
