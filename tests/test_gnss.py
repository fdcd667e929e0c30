"""GnssReceiver FMU: fixes exactly every sample_period whatever the master's clock, equal to
its Python twin, the position noise the counter-based Gaussian of railfmu.models.sources.sensors.noise and the
speed rounded to 1 km/h (Cunillera et al. (2022) §4.1-4.2)."""

from __future__ import annotations

import numpy as np
import pytest

from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.models.train.gnss import Gnss
from railfmu.models.sources.sensors import noise


def truth(t):
    return 1000.0 + 27.3 * t, 27.3 + 0.01 * t  # s (m), v (m/s): 98.28 km/h rising


@pytest.mark.parametrize("h, clock", [(1.0, "grid"), (0.01, "grid"), (0.01, "accumulated")])
def test_fixes_every_10_s_and_equal_to_the_twin(fmu_dir, h, clock):
    n = round(100 / h)
    fmu = Slave(fmu_dir / "GnssReceiver.fmu")
    fmu.initialize(0.0, parameters={"seed": 7})
    twin = Gnss({"seed": 7})
    fixes = [0.0] if fmu.get("valid") else []
    t = 0.0
    for k in range(n):
        s, v = truth(t)
        fmu.set("s_true", s), fmu.set("v_true", v)
        fmu.do_step(t, h)
        t = t + h if clock == "accumulated" else (k + 1) * h
        out = twin.outputs(t, h, s, v)  # inputs held over the step: those set at its start
        assert fmu.get("valid") == out["valid"] and fmu.get("sample") == out["sample"]
        assert fmu.get("position") == out["position"] and fmu.get("speed_kmh") == out["speed_kmh"]
        if out["valid"]:
            fixes.append(t)
    assert np.allclose(fixes, np.arange(0, 101, 10), atol=1e-9) and len(fixes) == 11
    fmu.close()


def test_measurement_equation():
    g = Gnss({"seed": 3})
    out = g.outputs(20.0, 1.0, 500.0, 100.4 / 3.6)
    assert out["sample"] == 2 and out["valid"]
    assert out["position"] == 500.0 + 4.0 * float(noise(3, 1, [2])[0])
    assert out["speed_kmh"] == 100.0 and out["speed"] == 100.0 / 3.6
    assert g.outputs(20.0, 1.0, 0, 100.6 / 3.6)["speed_kmh"] == 101.0
    assert not g.outputs(21.0, 1.0, 0, 0)["valid"]
    w = noise(3, 1, np.arange(20000), exact=False)  # the noise is N(0, 1): 4 m after scaling
    assert abs(w.mean()) < 0.03 and abs(w.std() - 1) < 0.02


def test_a_non_positive_sample_period_is_refused(fmu_dir):
    fmu = Slave(fmu_dir / "GnssReceiver.fmu")
    with pytest.raises(FMUError, match="sample_period"):
        fmu.initialize(0.0, parameters={"sample_period": 0.0})
