"""resistance_coasting_em (estimators/train/coasting_em.py) recovers the Davis coefficients of
a unit far from the published values it starts from, and the fleet pooling
(estimators/train/fleet.py) calibrates a unit from several runs and flags a change."""

from __future__ import annotations

import numpy as np
import pytest

from railfmu.estimators.train.coasting_em import CoastingEM
from railfmu.estimators.train.fleet import change_test, pool
from railfmu.estimators.train.running_resistance import ImprovedEstimator

from test_running_resistance import THETA0, resistance_rel_error, scattered_run


def _unit_run(fmu_dir, seed, factor):
    """A run of a unit whose coefficients are ``factor`` (3) x the published ones."""
    import test_running_resistance as trr

    rng = np.random.default_rng  # scattered_run draws 10 % scatter: undo it by its own draw
    scatter = 1.0 + 0.1 * rng(1000 + seed).standard_normal(3)
    orig = trr.THETA0
    try:
        trr.THETA0 = THETA0 * np.asarray(factor) / scatter
        run = scattered_run(fmu_dir, seed)
    finally:
        trr.THETA0 = orig
    return run


def _estimate(cls, run):
    e = cls(10.0)
    mask = np.isfinite(run["z"])
    X = e.run(run["t"], run["z"], None, mask)
    return X[-1, 2:5], e


@pytest.fixture(scope="module")
def far_runs(fmu_dir):
    return [_unit_run(fmu_dir, seed, (1.6, 1.6, 1.6)) for seed in (3, 4)]


def test_recovers_a_unit_at_1_6_times_the_published_values(far_runs):
    """At 1.6x the prior-gated estimator ends on the prior (error ~0.37); the EM within 3 %."""
    for run in far_runs:
        assert np.allclose(run["truth"], 1.6 * THETA0)
        theta, e = _estimate(CoastingEM, run)
        assert resistance_rel_error(theta, run["truth"]) < 0.03, (theta / THETA0, e.finish())
        assert e.finish()["coasting_segments"] >= 1
        theta_i, _ = _estimate(ImprovedEstimator, run)
        assert resistance_rel_error(theta_i, run["truth"]) > 0.2  # the failure this estimator mends


def test_fleet_pooling_and_change():
    """(F1): the pooled estimate of identical information is the common value with 1/N the
    covariance; (F2, F3): a step in the runs is flagged at or just after it, not before."""
    rng = np.random.default_rng(1)
    P = np.diag([1e-7, 1e-10, 1e-12])
    th = [THETA0 + rng.multivariate_normal(np.zeros(3), P) for _ in range(20)]
    theta, C = pool(th, [P] * 20)
    assert np.allclose(C, P / 20) and np.allclose(theta, np.mean(th, axis=0))
    assert change_test(th, [P] * 20, inflation=1.0)["first_flag"] is None
    stepped = [t + (np.array([0, 0, 0.2 * THETA0[2]]) if k >= 10 else 0) for k, t in enumerate(th)]
    res = change_test(stepped, [P] * 20, inflation=1.0)
    assert res["first_flag"] in (10, 11) and res["since_run"] == res["first_flag"]
