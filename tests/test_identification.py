"""railfmu.estimators.track.identification: the exact first-order-hold SM response against the FMU, recovery
of known primary-suspension parameters, identification on complete-model (CM) data and the
Q/R estimate of Muñoz et al., eqs. 28-31."""

import math

import numpy as np
import pytest

from railfmu.estimators.track import identification as idn
from railfmu.fmus.cosim.masters import run
from railfmu.fmus.cosim.system import Component, Connection, System
from railfmu.models.vehicle.vehicle_lateral import VEHICLE_LATERAL

V = 20.0
DT = 1e-3
PSD_SCALE = 0.7731  # 1.4 mm rms in 3-200 m for seed 1 over 20 s (experiments/lateral_alignment/identify.py)
TRACK = {"V": V, "psd_level": 1, "psd_scale": PSD_SCALE, "seed": 1}


def _columns(res):
    return {c: res.data[:, k] for k, c in enumerate(res.columns)}


def test_sm_response_equals_the_wheelset_fmu(fmu_dir):
    params = {"kx": 6.0e5, "cx": 5.0e4, "ky": 4.12e6, "cy": 1.41e5, "V": V}
    system = System(
        "track_wheelset",
        [Component("track", fmu_dir / "TrackIrregularity.fmu", dict(TRACK)),
         Component("wheelset", fmu_dir / "WheelsetLateral.fmu", dict(params))],
        [Connection("track", "alignment_1", "wheelset", "xi"),
         Connection("track", "alignment_rate_1", "wheelset", "xi_rate")],
        stop_time=5.0, step_size=DT,
        record=["track.alignment_1", "track.alignment_rate_1", "wheelset.y", "wheelset.psi"])
    col = _columns(run(system, "container", progress=False))
    y, psi = idn.sm_response(params, col["time"], col["track.alignment_1"], col["track.alignment_rate_1"])
    for name, mine in (("y", y), ("psi", psi)):
        fmu = col[f"wheelset.{name}"]
        assert np.abs(mine - fmu).max() <= 1e-6 * np.ptp(fmu), name


def test_sm_response_is_fast():
    import time

    t = np.arange(20000) * DT
    xi = 1e-3 * np.sin(2 * np.pi * V * t / 15.66)
    xi_rate = 1e-3 * 2 * np.pi * V / 15.66 * np.cos(2 * np.pi * V * t / 15.66)
    idn.sm_response(None, t, xi, xi_rate)  # lambdify once
    t0 = time.perf_counter()
    y, psi = idn.sm_response(None, t, xi, xi_rate)
    assert time.perf_counter() - t0 < 0.2
    assert np.all(np.isfinite(y)) and np.all(np.isfinite(psi)) and np.ptp(y) > 0


def test_identification_recovers_known_parameters():
    from railfmu.models.track.irregularity import TrackIrregularity

    t = np.arange(5001) * DT
    tr = TrackIrregularity(TRACK).outputs(t)
    xi, xi_rate = tr["alignment_1"], tr["alignment_rate_1"]
    truth = {"kx": 7.95e5, "cx": 1.47e4, "ky": 4.12e6, "cy": 1.41e5}
    y, psi = idn.sm_response({**truth, "V": V}, t, xi, xi_rate)
    initial = {k: v * f for (k, v), f in zip(truth.items(), (1.3, 0.7, 0.7, 1.3), strict=True)}
    res = idn.identify_primary(t, xi, xi_rate, y, psi, initial=initial, V=V)
    for k, v in truth.items():
        assert res.values[k] == pytest.approx(v, rel=0.01), k
    assert res.cost_after < 1e-10 < res.cost_before
    assert res.nrmse_after["y"] < 1e-5 and res.nrmse_after["psi"] < 1e-5


@pytest.fixture(scope="module")
def cm_run(fmu_dir):
    """8 s of the CM with the lateral alignment only (the vertical inputs keep 0)."""
    conns = []
    for j in range(1, 5):
        conns += [Connection("track", f"alignment_{j}", "vehicle", f"alignment_{j}"),
                  Connection("track", f"alignment_rate_{j}", "vehicle", f"alignment_rate_{j}")]
    rec = ["track.alignment_1", "track.alignment_rate_1",
           *(f"vehicle.{v}" for v in ("y_w1", "psi_w1", "dy_w1", "dpsi_w1", "y_b1", "psi_b1", "phi_b1",
                                      "dy_b1", "dpsi_b1", "dphi_b1", "ddy_w1", "ddy_b1"))]
    system = System("cm", [Component("track", fmu_dir / "TrackIrregularity.fmu", dict(TRACK)),
                           Component("vehicle", fmu_dir / "VehicleLateral.fmu", {"V": V})],
                    conns, stop_time=8.0, step_size=DT, record=rec)
    return _columns(run(system, "container", progress=False))


def test_identification_on_cm_data_reduces_the_mismatch(cm_run):
    c = cm_run
    res = idn.identify_primary(c["time"], c["track.alignment_1"], c["track.alignment_rate_1"],
                               c["vehicle.y_w1"], c["vehicle.psi_w1"], V=V)
    print(f"\nCM 8 s: NRMSE y {res.nrmse_before['y']:.4f} -> {res.nrmse_after['y']:.4f}, "
          f"psi {res.nrmse_before['psi']:.4f} -> {res.nrmse_after['psi']:.4f}; {res.values}")
    assert res.success
    assert res.nrmse_after["y"] < 0.7 * res.nrmse_before["y"]
    assert res.nrmse_after["psi"] < 0.7 * res.nrmse_before["psi"]
    assert res.cost_after < res.cost_before and res.J_ls_after < res.J_ls_before


def test_estimate_noise_positive_and_finite(cm_run):
    c = cm_run
    pv = VEHICLE_LATERAL.default_parameters()

    def frame(d):
        return (c[f"vehicle.{d}y_b1"] + pv["sensor_x"] * c[f"vehicle.{d}psi_b1"]
                - pv["sensor_z"] * c[f"vehicle.{d}phi_b1"])

    states = np.column_stack([c["vehicle.y_w1"], c["vehicle.psi_w1"], frame(""), c["vehicle.dy_w1"],
                              c["vehicle.dpsi_w1"], frame("d"), c["track.alignment_1"]])
    sigma = np.array([0.01, 5e-4, 0.01])
    rng = np.random.default_rng(0)
    sensors = np.column_stack([c["vehicle.ddy_w1"], c["vehicle.dpsi_w1"], c["vehicle.ddy_b1"]])
    sensors = sensors + rng.standard_normal(sensors.shape) * sigma
    est = idn.estimate_noise(c["time"], states, sensors, V=V)
    for k in ("q_acc", "q_yaw", "q_xi", "sigma_acc", "sigma_gyro"):
        v = est.settings[k]
        assert math.isfinite(v) and v > 0, (k, v)
    # the gyro row of H picks the CM's own yaw rate: R is the added noise alone
    assert est.settings["sigma_gyro"] == pytest.approx(5e-4, rel=0.05)
    # the accelerometers see the model error on top of the noise
    assert est.settings["sigma_acc"] >= 0.01
    assert est.Q.shape == (7, 7) and est.R.shape == (4, 4)
    assert np.all(np.linalg.eigvalsh(est.Q) > -1e-12 * np.abs(est.Q).max())
    from railfmu.estimators.track.alignment import AlignmentKalmanFilter

    kf = AlignmentKalmanFilter(DT, V=V, **est.settings)  # the settings are accepted as they are
    assert kf.observability_rank() == 7


def test_filter_matrices_match_the_alignment_filter():
    from railfmu.estimators.track.alignment import AlignmentKalmanFilter

    kf = AlignmentKalmanFilter(DT, V=V, kx=6e5, cx=5e4)
    F_c, H = idn.filter_matrices({"kx": 6e5, "cx": 5e4, "V": V})
    np.testing.assert_allclose(F_c, kf.F_c, rtol=1e-12, atol=1e-12 * np.abs(kf.F_c).max())
    np.testing.assert_allclose(H, kf.H, rtol=1e-12, atol=1e-12 * np.abs(kf.H).max())
