"""The observer interface (estimators/observer.py) on data from the real FMUs: online step by
step equals offline, CSV equals arrays, non-finite measurements are skipped and counted."""

import numpy as np
import pytest

from estimators.alignment import AlignmentKalmanFilter
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


@pytest.mark.parametrize("steady_state", [True, False])
def test_nonfinite_measurements_are_skipped(recorded, steady_state):
    t, Z, _, _ = recorded
    clean = AlignmentKalmanFilter(DT, steady_state=steady_state).run(t, Z)
    bad = Z.copy()
    bad[100, 0] = np.nan
    bad[200, 2] = np.inf
    bad[300:310, :] = np.nan
    kf = AlignmentKalmanFilter(DT, steady_state=steady_state)
    X = kf.run(t, bad)
    assert kf.skipped == 12 and kf.finish()["skipped"] == 12 and kf.finish()["steps"] == len(t)
    assert np.all(np.isfinite(X))
    assert np.array_equal(X[:100], clean[:100])  # nothing leaks backwards
    assert not np.array_equal(X[100], clean[100])  # the bad row was not used
    if steady_state:
        # a skipped row is a prediction only: the same as a row that never arrived
        X_gap = AlignmentKalmanFilter(DT).run(np.delete(t, 100), np.delete(Z, 100, axis=0))
        assert np.array_equal(X_gap[100:199], X[101:200])


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
    assert set(kf.units) == {*kf.inputs, *kf.outputs}
