"""Other tools' example SSPs (tests/data/foreign) in railfmu and in the tool that wrote them.

OMSimulator's examples are zipped to ``.ssp`` and run in OMSimulator 3.0 (where it runs them);
libcosim's crane demo runs in libcosim (libcosimpy). railfmu's Jacobi master on the same files
gives the same trajectories: the OpenModelica examples are algebraic (outputs are gains and
sums of inputs and parameters), so every recorded row is compared to 1e-9 of each signal's
range (both read the same binaries; OMSimulator's ``t += h`` against our ``k h`` does not
matter to them). The crane is a 20-sim model stepped with its own fixed internal step; libcosim
and our Jacobi master order the calls alike (see tests/test_libcosim.py), to 1e-6 of each
signal's range (the measured worst is printed).

Needs OMSimulator (RAILFMU_OMSIMULATOR or PATH) or libcosimpy; each test skips without its tool.
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1]))
from foreign_corpus import SSPS  # noqa: E402

OMS = os.environ.get("RAILFMU_OMSIMULATOR") or shutil.which("OMSimulator")
pytestmark = pytest.mark.interop
RTOL_ALGEBRAIC = 1e-9  # of range: the same binaries, algebraic models (module docstring)
RTOL_CRANE = 1e-6  # of range: libcosim's nanosecond time grid against our k h (tests/test_libcosim.py)

#: OMSimulator's examples it runs here (LinearTransformation and LinearTransformation3, SSP 2.0
#: files of a newer OMSimulator, abort OMSimulator 3.0 in importFromSnapshot: tests/test_foreign.py
#: checks them against the results OMSimulator's own testsuite records)
OMS_CASES = ["omsimulator/import_export_parameters1", "omsimulator/import_export_parameters2",
             "omsimulator/import_export_parameters3", "omsimulator/toplevelparameter1",
             "omsimulator/toplevelparameter2"]


def zipped(folder: Path, out: Path) -> Path:
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(folder).as_posix())
    return out


def read_oms(path: Path, prefix: str) -> dict[str, np.ndarray]:
    """OMSimulator's CSV as {'component.variable': values}; of rows repeated at one time, the last."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head = [h.strip().strip('"').removeprefix(prefix) for h in rows[0]]
    data = np.array([[float(x) for x in r] for r in rows[1:]])
    data = data[np.r_[np.diff(data[:, 0]) > 0, True]]
    return {h: data[:, j] for j, h in enumerate(head)}


def deviation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.ptp(b), np.max(np.abs(b)), 1e-300))


@pytest.mark.skipif(not OMS or not Path(OMS).is_file(), reason="OMSimulator not found (set RAILFMU_OMSIMULATOR or PATH)")
@pytest.mark.parametrize("case", OMS_CASES)
def test_omsimulator_example_agrees_with_omsimulator(tmp_path, case):
    from railfmu.fmus.cosim.masters import run
    from railfmu.fmus.ssp import read_system
    from railfmu.fmus.ssp.xmltools import NS, parse_xml

    ssp = zipped(SSPS[case], tmp_path / "x.ssp")
    system = read_system(ssp)
    # OMSimulator's command line runs 1 s unless told: the SSD's stop time, as railfmu reads it
    res = subprocess.run([OMS, f"--stopTime={system.stop_time:g}", "--resultFile=oms.csv", str(ssp)], capture_output=True, text=True,
                         timeout=300, cwd=tmp_path)
    log = res.stdout + res.stderr
    assert res.returncode == 0 and "error:" not in log.lower(), log[-2000:]
    doc = parse_xml(SSPS[case] / "SystemStructure.ssd", "ssd")
    prefix = f"{doc.get('name')}.{doc.find('ssd:System', NS).get('name')}."
    theirs = read_oms(tmp_path / "oms.csv", prefix)

    system.record = [s for s in theirs if "." in s and s.rpartition(".")[0] in {c.name for c in system.components}]
    ours = run(system, "jacobi", progress=False)
    assert len(ours.data) == len(theirs["time"])
    worst = {s: deviation(ours.data[:, j], theirs[s]) for j, s in enumerate(ours.columns) if s != "time"}
    print(f"{case}: worst deviation from OMSimulator {max(worst.values()):.1e} of range ({len(worst)} signals)")
    assert len(worst) >= 3 and max(worst.values()) <= RTOL_ALGEBRAIC, worst


def test_libcosim_demo_agrees_with_libcosim(tmp_path):
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed")
    from fmpy import read_model_description
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    from railfmu.fmus.cosim.masters import run
    from railfmu.fmus.ssp import read_system

    stop = 1.0  # s: the demo has no stop time; 10 000 steps of 0.1 ms
    system = read_system(SSPS["libcosim/demo"], stop_time=stop)
    ours = run(system, "jacobi", progress=False)
    n, step_ns = system.n_steps, round(system.step_size * 1e9)

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_ssp_file(str(SSPS["libcosim/demo"]))
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    assert execution.add_observer(observer)
    compared = []
    for comp in system.components:
        md = read_model_description(str(comp.fmu))
        # states and outputs the model integrates (not fed through from an input)
        for v in md.modelVariables:
            if v.causality == "output" and v.type == "Real" and f"{comp.name}.{v.name}" in ours.columns:
                assert observer.start_time_series(index[comp.name], v.valueReference, CosimVariableType.REAL)
                compared.append((comp.name, v.name, v.valueReference))
    assert execution.simulate_until(n * step_ns)
    worst = {}
    for comp, var, vr in compared:
        _, _, x0 = observer.time_series_real_samples(index[comp], vr, from_step=0, sample_count=2)
        _, _, x = observer.time_series_real_samples(index[comp], vr, from_step=1, sample_count=n)
        ref = ours.data[:, ours.columns.index(f"{comp}.{var}")]
        if np.ptp(ref) > 1e-9:
            worst[f"{comp}.{var}"] = deviation(np.array([x0[0], *x]), ref)
    print(f"libcosim demo: worst deviation from libcosim {max(worst.values()):.1e} of range ({len(worst)} signals)")
    assert len(worst) >= 2 and max(worst.values()) <= RTOL_CRANE, sorted(worst.items(), key=lambda kv: -kv[1])[:5]


def test_libcosim_fmi1_linear_transformation_agrees_with_libcosim():
    """libcosim's FMI 1.0 example (ViProMa's identity FMU, a LinearTransformation on the
    connection): every row of railfmu's Jacobi master equals libcosim's. libcosim reads the
    first of the component's two .ssv files as its default parameter set (realIn = 2), railfmu
    applies both in order (the later, 4, wins; tests/test_foreign.py): here railfmu is given 2."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    from railfmu.fmus.cosim.masters import run
    from railfmu.fmus.ssp import read_system

    case = SSPS["libcosim/linear_transformation"]
    stop, h = 0.1, 1e-3  # s: the SSD gives neither; libcosim's own test steps 1 ms
    system = read_system(case, stop_time=stop, step_size=h, overrides={"identity1": {"realIn": "2"}})
    signals = ["identity1.realOut", "identity2.realIn", "identity2.realOut"]
    system.record = signals
    ours = run(system, "jacobi", progress=False)
    n = system.n_steps

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_ssp_file(str(case), step_size=round(h * 1e9))
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    vr = {v.name.decode(): v.reference for v in execution.slave_variables(index["identity1"])}
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    assert execution.add_observer(observer)
    for signal in signals:
        comp, var = signal.split(".")
        assert observer.start_time_series(index[comp], vr[var], CosimVariableType.REAL)
    assert execution.simulate_until(round(stop * 1e9))
    for j, signal in enumerate(signals, start=1):
        comp, var = signal.split(".")
        _, _, x = observer.time_series_real_samples(index[comp], vr[var], from_step=1, sample_count=n)
        # libcosim's samples after each step against ours from the second row: the same doubles
        np.testing.assert_array_equal(np.array(x), ours.data[1:, j], err_msg=signal)
    # 2 through factor 1.3 and offset 50
    assert ours.data[-1, 1:].tolist() == [2.0, 52.6, 52.6]


def test_osp_dp_ship_agrees_with_libcosim_when_sampled_before_the_transfer():
    """OSP's dynamic-positioning ship (Vico's test data: FMI 1.0 and 2.0 FMUs, an OSP step
    annotation of 40 ms), 20 s: with ``sampling="before-transfer"`` (libcosim's order: each
    row read right after the step, all connections' sources read before any destination is
    set) every Real output equals libcosim's to 1e-9 of its range, the DP controller's
    commands included. With the default order the DP controller (an FMI 1.0 FMU) never acts:
    it samples its inputs when its outputs are read, and railfmu's default reads them between
    setting its inputs and its next fmiDoStep, so its outputs stay 0 (which is why the option
    exists; docs/interoperability.md)."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    from railfmu.fmus.cosim.masters import run
    from railfmu.fmus.ssp import read_system

    case = SSPS["vico/dp-ship"]
    system = read_system(case, stop_time=20.0)
    system.record = [f"{c.name}.{v.name}" for c in system.components for v in c.md.modelVariables
                     if v.causality == "output" and v.type == "Real"]
    ours = run(system, "jacobi", progress=False, sampling="before-transfer")
    n, step_ns = system.n_steps, round(system.step_size * 1e9)
    assert n == 500
    mz = ours.columns.index("DP Controller.ControlMz")
    assert run(system, "jacobi", progress=False).data[:, mz].tolist() == [0.0] * (n + 1)  # the default: never acts

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_ssp_file(str(case))
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    assert execution.add_observer(observer)
    compared = []
    for comp in system.components:
        for v in comp.md.modelVariables:
            if v.causality == "output" and v.type == "Real":
                assert observer.start_time_series(index[comp.name], v.valueReference, CosimVariableType.REAL)
                compared.append((comp.name, v.name, v.valueReference))
    assert execution.simulate_until(n * step_ns)
    worst = {}
    for comp, var, vr in compared:
        _, _, x = observer.time_series_real_samples(index[comp], vr, from_step=1, sample_count=n)
        ref = ours.data[1:, ours.columns.index(f"{comp}.{var}")]
        if np.ptp(ref) > 1e-12:
            worst[f"{comp}.{var}"] = deviation(np.array(x), ref)
    print(f"DP ship: worst deviation from libcosim {max(worst.values()):.1e} of range ({len(worst)} signals)")
    # the controller acts (its yaw moment swings by kN m) and all 20 moving outputs agree
    assert np.ptp(ours.data[:, mz]) > 1e3 and "DP Controller.ControlMz" in worst
    assert len(worst) >= 20 and max(worst.values()) <= RTOL_ALGEBRAIC, sorted(worst.items(), key=lambda kv: -kv[1])[:5]
