"""An estimator's design model read from the cache (railfmu.models.design.DesignModel): the
model's own numbers bit for bit, built only on a miss, and a run with them cached imports no
sympy (the main job's set-up)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from railfmu.models import design
from railfmu.models.design import DesignModel
from railfmu.models.vehicle.wheelset import WHEELSET


def _fresh(tmp_path, monkeypatch):
    monkeypatch.setenv("RAILFMU_CACHE", str(tmp_path))
    return DesignModel("railfmu.models.vehicle.wheelset", "WHEELSET")


def test_the_model_numbers_bit_for_bit_from_a_miss_and_from_the_cache(tmp_path, monkeypatch):
    p = {"V": 30.0, "alpha": 0.2}
    for dm in (_fresh(tmp_path, monkeypatch), _fresh(tmp_path, monkeypatch)):  # derived and stored, then read
        assert dm.identifier == WHEELSET.identifier
        assert dm.default_parameters() == WHEELSET.default_parameters()
        assert [type(v) for v in dm.default_parameters().values()] == [type(q.start) for q in WHEELSET.parameters]
        assert dm.inputs == [u.name for u in WHEELSET.inputs] and dm.outputs == [o.name for o in WHEELSET.outputs]
        assert dm.states == [s.name for s in WHEELSET.states]
        for args in ((), (p,), (p, {"xi": 0.0})):
            for a, b in zip(dm.linearize(*args), WHEELSET.linearize(*args), strict=True):
                assert a.dtype == b.dtype and np.array_equal(a, b)
    assert len(list((tmp_path / "design").glob("*.npz"))) == 2  # the defaults and p (u0 at its start: same key)


def test_parameter_checks_as_the_model(tmp_path, monkeypatch):
    dm = _fresh(tmp_path, monkeypatch)
    for bad in ({"alpha": -0.1}, {"m": 0.0}, {"V": float("nan")}):
        with pytest.raises(ValueError) as a:
            dm.check_parameters(bad)
        with pytest.raises(ValueError) as b:
            WHEELSET.check_parameters(bad)
        assert str(a.value) == str(b.value)
    dm.check_parameters({"alpha": 0.3})


def test_the_key_follows_the_model_sources(tmp_path, monkeypatch):
    (tmp_path / "m.py").write_text("A = 1\n")
    monkeypatch.setattr(design, "_MODELS", tmp_path)
    k1 = design._sources_key("m:A")
    (tmp_path / "m.py").write_text("A = 2\n")
    assert design._sources_key("m:A") != k1 and design._sources_key("m:B") != design._sources_key("m:A")


def test_an_alignment_filter_with_its_design_cached_imports_no_sympy(tmp_path):
    code = ("import sys\n"
            "from railfmu.estimators.track.alignment import AlignmentKalmanFilter\n"
            "f = AlignmentKalmanFilter(1e-3, V=25.0); f.prepare()\n"
            "print(sorted(m for m in ('sympy', 'numba', 'railfmu.models.base') if m in sys.modules))\n"
            "print(repr(f.K.tobytes()))\n")
    env = {**os.environ, "RAILFMU_CACHE": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env) for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[0].stderr + runs[1].stderr
    first, second = (r.stdout.splitlines() for r in runs)
    assert first[0] == "['railfmu.models.base', 'sympy']"  # a miss: the model built once
    assert second[0] == "[]"
    assert first[1] == second[1]  # the same gain bit for bit


def test_a_damaged_cache_entry_is_derived_again(tmp_path, monkeypatch):
    """A linearisation file cut short (a full disk, a copied cache) is no crash: the model
    derives it again, bit for bit."""
    from railfmu.models.design import DesignModel

    monkeypatch.setenv("RAILFMU_CACHE", str(tmp_path))
    first = DesignModel("railfmu.models.vehicle.wheelset", "WHEELSET").linearize()
    for f in (tmp_path / "design").glob("*.npz"):
        f.write_bytes(f.read_bytes()[:100])
    again = DesignModel("railfmu.models.vehicle.wheelset", "WHEELSET").linearize()
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
