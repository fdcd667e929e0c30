"""FMI 3.0 builds of every FMU, and one slave interface for FMI 1.0, 2.0 and 3.0.

- every FMI 3 FMU passes `fmpy validate` and exports every fmi3 function (FMPy binds them
  all when it loads the library), no fmi2 one; the unsupported ones fail with a log line;
- FMU state get/set/serialize keeps the FMI 2 runtime's checksummed format;
- every experiment's default variant gives the same signals and estimates with the FMI 2
  and the FMI 3 FMUs, bit for bit (short runs here, full length under `slow`): both builds
  compile the same model code and runtime, the FMI 3 layer only maps calls;
- an FMI 1.0 Co-Simulation FMU (tests/data/fmi1_integrator) runs in every master next to
  an FMI 3 FMU, with the analytic result.
"""

from __future__ import annotations

import ctypes
import math
import re
import zipfile

import numpy as np
import pytest
from fmi1_fmu import build_fmi1_integrator
from fmpy.fmi3 import FMU3Slave

import railfmu
from railfmu.experiments.engine.studies import experiment_names
from railfmu.fmus.cosim.masters import MASTERS, run
from railfmu.fmus.cosim.slave import Slave
from railfmu.fmus.cosim.system import Component, Connection, System
from railfmu.fmus.generate.build import build_all, default_out, fmi_header_dir, validate


@pytest.fixture(scope="session")
def fmi3_dir():
    build_all(default_out(3), fmi_version=3, progress=False)
    return default_out(3)


def _fmi3_functions() -> list[str]:
    text = (fmi_header_dir() / "fmi3Functions.h").read_text()
    return re.findall(r"^#define (fmi3\w+)\s+fmi3FullName\(", text, re.M)


def test_every_fmi3_fmu_validates_and_exports_every_fmi3_function(fmi3_dir, tmp_path):
    fmus = sorted(fmi3_dir.glob("*.fmu"))
    assert len(fmus) >= 12
    functions = _fmi3_functions()
    assert len(functions) > 70  # the header's full list (FMPy binds each one)
    for fmu in fmus:
        assert validate(fmu) == [], fmu.name
        with zipfile.ZipFile(fmu) as z:
            z.extractall(tmp_path / fmu.stem)
            md = z.read("modelDescription.xml").decode()
        assert 'fmiVersion="3.0"' in md and "<ModelStructure>" in md
        lib = ctypes.CDLL(str(tmp_path / fmu.stem / "binaries" / "x86_64-linux" / f"{fmu.stem}.so"))
        missing = [f for f in functions if not hasattr(lib, f)]
        assert missing == [], f"{fmu.name} lacks {missing}"
        assert not hasattr(lib, "fmi2DoStep")  # the FMI 2 layer inside stays hidden


def test_fmi3_declares_the_fmi2_units_and_dependencies(fmi3_dir, fmu_dir):
    # tests/test_feedthrough.py measures the FMI 2 declarations; the FMI 3 ones must say the same
    from fmpy import read_model_description

    for fmu3 in sorted(fmi3_dir.glob("*.fmu")):
        md2, md3 = read_model_description(str(fmu_dir / fmu3.name)), read_model_description(str(fmu3))
        assert md3.fmiVersion == "3.0" and md3.instantiationToken
        units2 = {v.name: v.unit for v in md2.modelVariables}
        assert {v.name: v.unit for v in md3.modelVariables} == units2, fmu3.name

        def deps(unknowns):
            return {u.variable.name: None if u.dependencies is None else sorted(d.name for d in u.dependencies)
                    for u in unknowns}

        assert deps(md3.outputs) == deps(md2.outputs), fmu3.name
        assert deps(md3.initialUnknowns) == deps(md2.initialUnknowns), fmu3.name


def test_unsupported_fmi3_function_fails_with_a_log_line(fmi3_dir):
    with Slave(fmi3_dir / "StepSource.fmu", "s") as s:
        f = s.fmu
        assert isinstance(f, FMU3Slave)
        vr = (ctypes.c_uint32 * 1)(0)
        status = f.dll.fmi3GetFloat32(ctypes.c_void_p(f.component), vr, ctypes.c_size_t(1),
                                      (ctypes.c_float * 1)(), ctypes.c_size_t(1))
        assert status == 3  # fmi3Error
        assert any("fmi3GetFloat32" in m and "Float32" in m for _, _, m in s.messages)
        # a value reference of another type is refused by name, with the FMI 3 function's name
        n = len(s.messages)
        status = f.dll.fmi3GetInt32(ctypes.c_void_p(f.component), vr, ctypes.c_size_t(1),
                                    (ctypes.c_int32 * 1)(), ctypes.c_size_t(1))
        assert status == 3 and "not a Int32 variable" in s.messages[n][2]


def test_fmi3_state_is_the_checksummed_format_and_restores(fmi3_dir):
    with Slave(fmi3_dir / "CoachVertical.fmu", "coach") as s:
        s.initialize(0.0, 10.0)
        f = s.fmu
        for k in range(100):
            s.do_step(k * 1e-3, 1e-3)
        state = f.getFMUState()
        data = f.serializeFMUState(state)
        assert bytes(data[:4]) == b"RFMU"  # the FMI 2 runtime's serialization, CRC-32 at the end
        outputs = [v.name for v in s.md.modelVariables if v.causality == "output" and v.type == "Real"]
        for k in range(100, 200):
            s.do_step(k * 1e-3, 1e-3)
        reference = [s.get(n) for n in outputs]
        f.setFMUState(f.deserializeFMUState(data))
        for k in range(100, 200):
            s.do_step(k * 1e-3, 1e-3)
        assert [s.get(n) for n in outputs] == reference  # the same continuation, bit for bit
        damaged = bytearray(data)
        damaged[len(damaged) // 2] ^= 0xFF
        n = len(s.messages)
        with pytest.raises(Exception):
            f.deserializeFMUState(bytes(damaged))
        assert any("CRC-32" in m for _, _, m in s.messages[n:])


# -- FMI 2 and FMI 3 give the same results ----------------------------------------------------

# short runs for CI [s]: long enough for every observer to have estimated (a replay's step
# is its data's; train_resistance_measured samples every 10 s)
SHORT = {"train_resistance": 30.0, "train_resistance_measured": 200.0, "alignment_replay": 0.5}


def _flat(d, prefix=""):
    out = {}
    for k, v in (d or {}).items():
        out.update(_flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {prefix + k: v})
    return out


def _assert_same_results(name, stop_time):
    kw = {} if stop_time is None else {"stop_time": stop_time}
    r2 = railfmu.run(name, **kw)
    r3 = railfmu.run(name, fmi_version=3, **kw)
    assert all("-fmi3" in str(c.fmu.parent) for c in r3.system.components), "the run did not use FMI 3 FMUs"
    for a, b in ((r2.signals, r3.signals), (_flat(r2.estimates), _flat(r3.estimates))):
        assert set(a) == set(b)
        for k in a:
            x, y = np.asarray(a[k], float), np.asarray(b[k], float)
            assert x.shape == y.shape and len(x) > 1, k
            # bit for bit: the same C model code and runtime behind both interfaces
            assert np.array_equal(x, y, equal_nan=True), f"{name}: {k} differs by {np.nanmax(np.abs(x - y))}"
    m2, m3 = _flat(r2.metrics), _flat(r3.metrics)
    timing = re.compile(r"wall_time|realtime|seconds|timing_s|_us_per_")  # measured times
    for k, v in m2.items():
        if isinstance(v, float) and not timing.search(k):
            assert v == m3[k] or (math.isnan(v) and math.isnan(m3[k])), k


@pytest.mark.parametrize("name", experiment_names())
def test_default_variant_fmi3_equals_fmi2_short(name, fmi3_dir, fmu_dir):
    _assert_same_results(name, SHORT.get(name, 2.0))


@pytest.mark.slow
@pytest.mark.parametrize("name", experiment_names())
def test_default_variant_fmi3_equals_fmi2_full_length(name, fmi3_dir, fmu_dir):
    _assert_same_results(name, None)


# -- FMI 1.0 --------------------------------------------------------------------------------

@pytest.mark.parametrize("master", MASTERS)
def test_fmi1_fmu_runs_next_to_an_fmi3_fmu_in_every_master(master, fmi3_dir, tmp_path):
    integrator = build_fmi1_integrator(tmp_path)
    k, h, t_step, final = 3.0, 0.01, 0.25, 2.0
    system = System(
        name="fmi1", start_time=0.0, stop_time=1.0, step_size=h,
        components=[Component("step", fmi3_dir / "StepSource.fmu", {"step_time": t_step, "final_value": final}),
                    Component("int", integrator, {"k": k})],
        connections=[Connection("step", "y", "int", "u")],
        record=["step.y", "int.y", "int.steps", "int.positive"])
    r = run(system, master, progress=False)
    t = r.data[:, 0]
    y = r.data[:, r.columns.index("int.y")]
    # Jacobi (and the container's coupling): the step's value at t_i drives [t_i, t_i + h];
    # Gauss-Seidel: the source steps first, so its value at t_i + h does
    lag = 0 if master == "gauss-seidel" else 1
    held = np.array([sum(final for i in range(n) if (i + 1 - lag) * h >= t_step - 1e-9) for n in range(len(t))])
    expected = k * h * held
    # Euler sums of k h final: rounding of a few hundred additions
    assert np.allclose(y, expected, rtol=0, atol=1e-12), np.max(np.abs(y - expected))
    assert list(r.data[:, r.columns.index("int.steps")]) == list(range(len(t)))
    assert list(r.data[:, r.columns.index("int.positive")]) == [float(v > 0) for v in expected]
    if master == "container":
        assert any("jacobi" in n.lower() and "FMI 1.0" in n for n in r.notes)


def test_container_runs_fmi3_components_as_jacobi(fmi3_dir):
    # FMPy's container FMU loads FMI 3 components itself (fmiMajorVersion in its configuration)
    from railfmu.experiments.engine.runner import find_experiment, load_system

    system = load_system(find_experiment("lateral_alignment"), "standard", stop_time=0.5, fmi_version=3)
    assert {str(c.md.fmiVersion) for c in system.components} == {"3.0"}
    jacobi, container = run(system, "jacobi", progress=False), run(system, "container", progress=False)
    assert container.master == "container" and not any("jacobi master" in n for n in container.notes)
    assert np.array_equal(container.data, jacobi.data)  # the same coupling, bit for bit
