"""Every FMU we ship: valid, self-contained, simulates in FMPy, rejects bad parameters with a
clear message, and restores saved states exactly."""

import subprocess
import zipfile

import numpy as np
import pytest
from fmpy import simulate_fmu

from railfmu.fmus.generate.build import CFLAGS, default_platforms, validate
from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.models import all_models

MODELS = [m.identifier for m in all_models()]


@pytest.mark.parametrize("ident", MODELS)
def test_fmu_is_valid_and_complete(fmu_dir, ident):
    path = fmu_dir / f"{ident}.fmu"
    assert validate(path) == []
    names = zipfile.ZipFile(path).namelist()
    assert f"binaries/linux64/{ident}.so" in names
    if "win64" in default_platforms():  # where mingw-w64 is installed (CI): tests/test_win64.py runs it
        assert f"binaries/win64/{ident}.dll" in names
    assert {"sources/fmi2_runtime.c", "sources/model.h", "sources/model_config.h",
            "sources/fmi2Functions.h", "modelDescription.xml", "documentation/_main.html"} <= set(names)


@pytest.mark.parametrize("ident", MODELS)
def test_sources_rebuild_on_their_own(fmu_dir, tmp_path, ident):
    """sources/ alone (no fmpy headers, no repo) compiles warning-free: another platform can
    rebuild the binary."""
    with zipfile.ZipFile(fmu_dir / f"{ident}.fmu") as zf:
        zf.extractall(tmp_path)
    src = sorted(str(p) for p in (tmp_path / "sources").glob("*.c"))
    res = subprocess.run(["gcc", *CFLAGS, "-I", str(tmp_path / "sources"), "-o", str(tmp_path / "x.so"),
                          *src, "-lm"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize("ident", MODELS)
def test_simulates_with_fmpy(fmu_dir, ident):
    start = {"y": 1e-3} if ident == "WheelsetLateral" else {}
    res = simulate_fmu(str(fmu_dir / f"{ident}.fmu"), stop_time=6.0, output_interval=1e-3,
                       step_size=1e-3, start_values=start)
    assert len(res) == 6001
    for name in res.dtype.names:
        assert np.all(np.isfinite(res[name])), name
    if ident == "WheelsetLateral":
        # released from 1 mm on a perfect track it centres itself; the least damped mode
        # (kinematic, sigma = -1.03 1/s) leaves e^(-1.03 * 6) = 0.2 % after 6 s
        assert abs(res["y"][0] - 1e-3) < 1e-12
        assert np.abs(res["y"][-500:]).max() < 0.01e-3


def test_invalid_parameter_is_a_clear_error(fmu_dir):
    with Slave(fmu_dir / "WheelsetLateral.fmu", "ws") as s:
        with pytest.raises(FMUError, match=r"fmi2ExitInitializationMode failed: parameter m = -1 must be > 0"):
            s.initialize(0.0, 1.0, {"m": -1.0})
    with Slave(fmu_dir / "WheelsetLateral.fmu", "ws") as s:
        with pytest.raises(FMUError, match="integrator_step"):
            s.initialize(0.0, 1.0, {"integrator_step": 0.0})


def test_illegal_call_sequence_is_reported(fmu_dir):
    with Slave(fmu_dir / "WheelsetLateral.fmu", "ws") as s:
        with pytest.raises(FMUError, match="fmi2DoStep"):
            s.do_step(0.0, 1e-3)  # before initialisation
        assert any(st == "Error" for st, _, _ in s.messages)


def _drive(s, k0, n, h=1e-3):
    out = []
    for k in range(k0, k0 + n):
        t = k * h
        if "xi" in s.vars:
            s.set("xi", 1e-3 * np.sin(2 * np.pi * t))
            s.set("xi_rate", 2e-3 * np.pi * np.cos(2 * np.pi * t))
        s.do_step(t, h)
        out.append([s.get(v.name) for v in s.md.modelVariables if v.causality == "output"])
    return np.array(out)


@pytest.mark.parametrize("ident", MODELS)
def test_saved_state_reproduces_continuation_exactly(fmu_dir, ident):
    params = {"psd_level": 2, "seed": 3} if ident == "TrackIrregularity" else {}
    with Slave(fmu_dir / f"{ident}.fmu", "a") as s, Slave(fmu_dir / f"{ident}.fmu", "b") as other:
        s.initialize(0.0, None, params)
        _drive(s, 0, 100)
        state = s.fmu.getFMUstate()
        first = _drive(s, 100, 200)
        s.fmu.setFMUstate(state)
        again = _drive(s, 100, 200)
        assert np.array_equal(first, again)
        # serialised, carried to another instance, deserialised
        blob = s.fmu.serializeFMUstate(state)
        s.fmu.freeFMUstate(state)
        other.initialize(0.0, None, params)
        restored = other.fmu.deSerializeFMUstate(blob)
        other.fmu.setFMUstate(restored)
        other.fmu.freeFMUstate(restored)
        assert np.array_equal(first, _drive(other, 100, 200))


def test_outputs_are_computed_in_initialization_mode(fmu_dir):
    """Importers (libcosim) read the initial outputs before initialisation ends to pass
    them on: they must be computed from the parameters and inputs set so far."""
    from railfmu.models.vehicle.wheelset import WHEELSET

    with Slave(fmu_dir / "TrackIrregularity.fmu", "track") as s:
        s.enter_initialization(0.0, 1.0)
        s.set("s_start", 10.0)
        assert s.get("position") == 10.0
        s.set("s_start", 12.5)  # a later set is seen too
        assert s.get("position") == 12.5
    with Slave(fmu_dir / "WheelsetLateral.fmu", "ws") as s:
        s.enter_initialization(0.0, 1.0)
        s.set("xi", 1e-3)
        expected = WHEELSET.outputs_at(0.0, [0.0] * 6, {"xi": 1e-3, "xi_rate": 0.0})["ddy"]
        assert s.get("ddy") == pytest.approx(expected, rel=1e-12) and expected != 0.0
