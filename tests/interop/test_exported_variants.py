"""Every exported variant of every experiment runs unedited in OMSimulator 3.0 and in libcosim
(libcosimpy, FMI 2) and gives railfmu's trajectories.

For each variant: ``railfmu export --stop-time T`` writes the archive; our Jacobi master runs
it (:func:`railfmu.fmus.ssp.read_system` on the archive alone; for OMSimulator with the
connections copied in dependency order, as OMSimulator passes them: see ``exported``); each
tool runs the same file.

* OMSimulator (``OMSimulator --stopTime=T --resultFile=x.mat``): it exits 0 even after
  errors, so its log is read and any ``error:`` line fails. The .mat result holds doubles (its
  CSV prints 12 digits). It advances time as t += h, which falls short of T by rounding
  (2000 steps of 1 ms end at 2 - 1.1e-13), then steps the rest to T: one extra final row, a
  few 1e-13 s after the previous one, which is dropped; the others match ours by time (to
  1e-9 of the step). Rows written again at one time (after an event) count once.
* libcosim (``CosimExecution.from_ssp_file`` with the archive's step): its own SSP loader,
  time in integer nanoseconds; any ``[error]`` line in its log fails too, but for its FMI
  Library's "Start attribute is required" about each FMU's ``time`` (FMI 2.0 forbids that
  start value: the FMUs are right).

Compared, signal by signal, relative to the signal's range over the run: every Real signal
railfmu records that neither feeds through an input nor is one (an input or a direct-
feedthrough output is sampled on the other side of the transfer by each master: see
tests/test_libcosim.py). The same binaries take the same steps, so the numbers agree to the
rounding of the time argument (t += h, k h, nanoseconds): ``RTOL`` for every experiment. A replay's table signals (SignalTable outputs, what the
estimators read) agree to 1e-12.

Needs OMSimulator (RAILFMU_OMSIMULATOR or ``OMSimulator`` on PATH) and libcosimpy; each tool's
cases skip in one line without it. The whole matrix (two tools x every variant, 116 runs of
2 s) takes ~2.5 min on two shared cores: CI runs it all.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

OMS = os.environ.get("RAILFMU_OMSIMULATOR") or shutil.which("OMSimulator")
try:
    import libcosimpy  # noqa: F401
    HAVE_LIBCOSIM = True
except ImportError:
    HAVE_LIBCOSIM = False

pytestmark = pytest.mark.interop

STOP = 2.0  # s of simulated time: enough for every signal to move, short for CI
# a measured train run has a GNSS fix every 10 s (its replay steps at them): three steps
STOP_OF = {"train_resistance_measured": 30.0}
# of a signal's range, for every experiment: same binaries, same steps, only the time argument's
# rounding differs (measured worst per experiment: 0 .. 5.3e-12, docs/interoperability.md)
RTOL = 1e-9
# OMSimulator's fixed-step master steps every FMU, then passes the outputs on in the order of
# its dependency graph, so an output that feeds through an input (the driver's command from
# the train's speed) reaches its receiver in the same exchange: our Jacobi master with the
# connections copied in that order (as our Gauss-Seidel master orders its transfer). libcosim
# copies every output read after the step at once, as our Jacobi master in the SSD's order does
# here (the driver's command before the train's speed reaches the driver).
TABLE_RTOL = 1e-12  # a replay's table signals: a held or interpolated row, the same in any master


def _variants() -> list[tuple[str, str]]:
    from railfmu.experiments.engine.runner import experiment_names, find_experiment

    return [(name, v) for name in experiment_names() for v in find_experiment(name).variants]


ALL = _variants()
TOOLS = ("omsimulator", "libcosim")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """(experiment, variant, ordered) -> (archive, system read back, our Jacobi run, with the
    connections copied in dependency order if ``ordered``): once per module."""
    cache: dict = {}
    folder = tmp_path_factory.mktemp("exported")

    def get(experiment: str, variant: str, ordered: bool = False):
        key = (experiment, variant, ordered)
        if key not in cache:
            from railfmu.fmus.cosim.masters import _transfer_order
            from railfmu.fmus.cosim.masters import run as run_master
            from railfmu.fmus.ssp import read_system

            stop = STOP_OF.get(experiment, STOP)
            ssp = folder / f"{experiment}__{variant}.ssp"
            if not ssp.is_file():
                res = subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", "export", experiment,
                                      "--variant", variant, "--stop-time", f"{stop:g}", "-o", str(ssp)],
                                     capture_output=True, text=True)
                assert res.returncode == 0, res.stderr
            system = read_system(ssp)
            assert system.stop_time == stop
            if ordered:  # the order Gauss-Seidel's consistent transfer uses
                order = _transfer_order(system, {c.name: c.md for c in system.components})
                system.connections = [system.connections[i] for i in order]
            cache[key] = ssp, system, run_master(system, master="jacobi", progress=False)
        return cache[key]

    return get


def _feedthrough(md) -> set[str]:
    """Inputs, and outputs that depend directly on an input (no dependency list: on all)."""
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    out = set(inputs)
    for o in md.outputs:
        deps = o.dependencies
        if deps is None or any(d.name in inputs for d in deps):
            out.add(o.variable.name)
    return out


def _compared(system, ours) -> dict[str, tuple[str, str]]:
    """Recorded signal -> (component, variable): Real, not an input nor fed through one."""
    out = {}
    for c in system.components:
        md = read_model_description(str(c.fmu))
        skip, real = _feedthrough(md), {v.name for v in md.modelVariables if v.type == "Real"}
        for signal in ours.columns[1:]:
            if signal.startswith(c.name + "."):
                var = signal[len(c.name) + 1:]
                if var in real and var not in skip and var != "time":
                    out[signal] = (c.name, var)
    return out


def _tables(system) -> set[str]:
    """The Real outputs of the SignalTable components (a replay's measured signals)."""
    return {f"{c.name}.{v.name}" for c in system.components
            if read_model_description(str(c.fmu)).coSimulation.modelIdentifier == "SignalTable"
            for v in read_model_description(str(c.fmu)).modelVariables
            if v.causality == "output" and v.type == "Real"}


def run_omsimulator(ssp: Path, stop: float) -> tuple[str, np.ndarray, dict[str, np.ndarray]]:
    """(log, times, {component.variable: samples}) of OMSimulator on ``ssp``."""
    import scipy.io

    result = ssp.with_suffix(".mat")
    res = subprocess.run([OMS, f"--stopTime={stop:g}", f"--resultFile={result.name}", str(ssp)],
                         capture_output=True, text=True, timeout=600, cwd=ssp.parent)
    log = res.stdout + res.stderr
    if not result.is_file():
        return log, np.empty(0), {}
    m = scipy.io.loadmat(str(result))  # OpenModelica result format, transposed ('binTrans')
    width = max(len(r) for r in m["name"])
    names = ["".join(col).rstrip("\x00 ") for col in zip(*(r.ljust(width) for r in m["name"]))]
    info, data = m["dataInfo"], m["data_2"]
    t = data[0]
    keep = np.r_[np.diff(t) > 0, True]  # of rows repeated at one time (an event), the last
    out = {}
    for j, name in enumerate(names):
        if info[0, j] == 2 and j > 0:
            col = abs(int(info[1, j])) - 1
            short = name.split(".", 2)[-1]  # 'model.root.comp.var' -> 'comp.var'
            out[short] = np.sign(info[1, j]) * data[col][keep]
    return log, t[keep], out


def run_libcosim(ssp: Path, system, signals: dict[str, tuple[str, str]]) -> dict[str, np.ndarray]:
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    step_ns, n = round(system.step_size * 1e9), system.n_steps
    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_ssp_file(str(ssp), step_size=step_ns)
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    assert sorted(index) == sorted(c.name for c in system.components)
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    assert execution.add_observer(observer)
    vrs = {}
    for signal, (comp, var) in signals.items():
        md = read_model_description(str(next(c.fmu for c in system.components if c.name == comp)))
        vrs[signal] = index[comp], next(v.valueReference for v in md.modelVariables if v.name == var)
        assert observer.start_time_series(*vrs[signal], CosimVariableType.REAL)
    assert execution.simulate_until(n * step_ns), "libcosim simulation failed"
    out = {}
    for signal, (i, vr) in vrs.items():
        # libcosimpy 0.0.6 trims a read from step 0 by its last sample: step 0 on its own
        _, _, x0 = observer.time_series_real_samples(i, vr, from_step=0, sample_count=2)
        _, steps, x = observer.time_series_real_samples(i, vr, from_step=1, sample_count=n)
        assert list(steps) == list(range(1, n + 1))
        out[signal] = np.array([x0[0], *x])
    return out


@pytest.mark.parametrize("tool,experiment,variant", [(t, e, v) for t in TOOLS for e, v in ALL])
def test_exported_variant_runs_like_railfmu(exported, capfd, tool, experiment, variant):
    if tool == "omsimulator" and not (OMS and Path(OMS).is_file()):
        pytest.skip("OMSimulator not found (set RAILFMU_OMSIMULATOR or PATH)")
    if tool == "libcosim" and not HAVE_LIBCOSIM:
        pytest.skip("libcosimpy is not installed")
    ssp, system, ours = exported(experiment, variant, ordered=tool == "omsimulator")
    signals = _compared(system, ours)
    if tool == "omsimulator":
        log, t, theirs = run_omsimulator(ssp, system.stop_time)
        errors = [line for line in log.splitlines() if "error:" in line.lower()]
        assert not errors, "\n".join(errors[:10])
        assert "terminate called" not in log, log[-2000:]
        n = len(ours.data)
        # t += h: one extra final row where the sum falls short of the stop time (module docstring)
        assert n <= len(t) <= n + 1 and np.allclose(t[:n], ours.data[:, 0], rtol=0, atol=1e-9 * system.step_size)
        theirs = {s: x[:n] for s, x in theirs.items() if s in signals}
        assert set(theirs) == set(signals), sorted(set(signals) - set(theirs))[:5]
    else:
        capfd.readouterr()
        theirs = run_libcosim(ssp, system, signals)
        log = capfd.readouterr()
        # its FMI Library's line for each FMU's `time` (FMI 2.0 forbids the start value it asks for)
        errors = [line for line in (log.out + log.err).splitlines()
                  if "[error]" in line and "Start attribute is required for this causality" not in line]
        assert not errors, "\n".join(errors[:10])
    columns = {c: ours.data[:, j] for j, c in enumerate(ours.columns)}
    worst = {}
    for s in signals:
        ref = columns[s]
        if np.ptp(ref) > 1e-12:  # SI units: below, a signal is rounding noise (a pitch of ~1e-18 rad)
            worst[s] = float(np.max(np.abs(theirs[s] - ref)) / np.ptp(ref))
    assert worst, "no signal that moves to compare"
    top = max(worst, key=worst.get)
    print(f"{tool} {experiment}/{variant}: {len(worst)} signals, worst {worst[top]:.1e} of range ({top})")
    tables = _tables(system) & set(worst)
    if tables:
        assert max(worst[s] for s in tables) <= TABLE_RTOL, {s: worst[s] for s in tables}
    assert worst[top] <= RTOL, sorted(worst.items(), key=lambda kv: -kv[1])[:5]


REPLAYS = ["alignment_replay", "suspension_replay", "train_resistance_measured", "trolley_imu_replay",
           "trolley_survey_replay"]  # the experiments that play a measured table


@pytest.mark.parametrize("experiment", REPLAYS)
def test_a_replay_runs_to_its_data_end(tmp_path, experiment):
    """Exported without a stop time, a replay's SSD ends where the table that ends the run does
    (its last row), so a tool that runs the archive as it is reads the whole table and nothing
    after it."""
    from railfmu.experiments.engine.api import export_system
    from railfmu.experiments.engine.replay import read_replay, replays_of
    from railfmu.fmus.ssp import read_system

    ssp, _ = export_system(experiment, tmp_path / "a.ssp")
    system = read_system(ssp)
    tables = [read_replay(c, f, {}) for c, f in replays_of(system)]
    ends = [t.time[-1] for t in tables if t.ends_run]
    assert len(ends) == 1 and ends[0] > 1.0
    assert system.stop_time == pytest.approx(ends[0], rel=1e-15)


def _break_table(ssp: Path, component: str, table: str, how: str, out: Path) -> Path:
    """A copy of ``ssp`` whose ``component`` FMU has its ``table`` removed or emptied."""
    import io
    import zipfile

    with zipfile.ZipFile(ssp) as z, zipfile.ZipFile(out, "w") as o:
        for info in z.infolist():
            data = z.read(info)
            if info.filename == f"resources/{component}_SignalTable.fmu":
                buf = io.BytesIO()
                with zipfile.ZipFile(io.BytesIO(data)) as f, zipfile.ZipFile(buf, "w") as g:
                    for item in f.infolist():
                        if item.filename != f"resources/{table}":
                            g.writestr(item, f.read(item))
                        elif how == "empty":
                            g.writestr(item, b"")
                data = buf.getvalue()
            o.writestr(info, data)
    return out


@pytest.mark.parametrize("how,message", [("missing", "cannot open"), ("empty", "empty file")])
@pytest.mark.parametrize("tool", TOOLS)
def test_a_missing_or_empty_table_fails_initialisation_naming_the_parameter(tmp_path, tool, how, message):
    """Never a silent run on zeros: the replay's table FMU refuses fmi2ExitInitializationMode
    and logs ``file <path>: ...`` (the parameter's name). OMSimulator logs it and simulates
    nothing; libcosim throws from its worker thread, which ends the process (std::terminate),
    hence a child process."""
    if tool == "omsimulator" and not (OMS and Path(OMS).is_file()):
        pytest.skip("OMSimulator not found (set RAILFMU_OMSIMULATOR or PATH)")
    if tool == "libcosim" and not HAVE_LIBCOSIM:
        pytest.skip("libcosimpy is not installed")
    from railfmu.experiments.engine.api import export_system

    ssp, system = export_system("alignment_replay", tmp_path / "a.ssp", "measured", stop_time=1.0)
    table = Path(next(c for c in system.components if c.name == "replay").parameters["file"]).name
    broken = _break_table(ssp, "replay", table, how, tmp_path / "broken.ssp")
    if tool == "omsimulator":
        log, t, _ = run_omsimulator(broken, 1.0)
        assert "exitInitializationMode failed" in log and t.size == 0, log[-2000:]
    else:
        code = ("from libcosimpy.CosimExecution import CosimExecution\n"
                "from libcosimpy.CosimLogging import CosimLogLevel, log_output_level\n"
                "log_output_level(CosimLogLevel.WARNING)\n"
                f"e = CosimExecution.from_ssp_file({str(broken)!r}, step_size=1_000_000)\n"
                "print('ran' if e.simulate_until(1_000_000_000) else 'refused')\n")
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
        log = res.stdout + res.stderr
        assert "ran" not in res.stdout.split(), log[-2000:]
    # the parameter's name, then the resolved path in the FMU's unpacked resources/
    assert re.search(rf"\bfile \S+/resources/{re.escape(table)}(, line 1)?: {message}", log), log[-2000:]
