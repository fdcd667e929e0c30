"""The trolley survey (Jiang et al. 2017), free-inertial part: experiments/trolley_survey and
experiments/trolley_imu_replay, and the "Done when" checks of the survey's data.

* ideal IMU: the INS reproduces the trolley's truth to < 0.01 mm and 1e-6 rad over the first
  120 s (the rest, the first run to the 60 m stop, the transition into the 400 m curve at
  80 m) at 5, 2.5 and 10 ms, and over the whole 700 s run (slow, ``test_whole_run``: 0.0013,
  0.0003, 0.0054 mm). That needs the shipped track's bloss transitions: at the ends of linear
  cant ramps and parabolic vertical curves the angular rate jumps, and the two-sample coning
  and sculling of any strapdown INS leave 3.4e-8 m/s per jump at 5 ms (0.0386 mm over the
  run), although the data are exact there;
* python-ins's integrator reproduces our truth.csv from our imu.csv (the files, not the FMU);
* imu.csv and truth.csv are signals.csv's numbers, in the standard form; the replay
  experiment on them gives the online INS's estimates;
* the grade variants carry the grade .ssv files whole;
* Trolley + ImuErrors in libcosim give our numbers;
* bad input through the CLI: one line, exit 2.
"""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import fmpy
import numpy as np
import pandas as pd
import pytest

from railfmu.estimators.inertial.strapdown import Strapdown
from railfmu.experiments.engine.runner import run_experiment
from railfmu.experiments.trolley_survey import NAV, TRUTH_COLUMNS, navigation_errors
from railfmu.models import earth

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or fmpy.platform != "linux64",
                                reason="needs gcc on linux64")

ROOT = Path(__file__).resolve().parents[1]
EXP = ROOT / "experiments" / "trolley_survey"
REPLAY = ROOT / "experiments" / "trolley_imu_replay"
FAST = 120.0  # s: 10 s rest, the first run to the stop at 60 m, into the second (the clothoid at 80 m)
BAR_M, BAR_RAD = 0.01e-3, 1e-6  # the ideal IMU's bar: 0.01 mm, 1e-6 rad
DEG = math.pi / 180


def railfmu(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True, text=True,
                          cwd=cwd)


def survey_run(out: Path, step: float, stop: float = FAST, variant: str = "ideal_imu", **kw) -> dict:
    return run_experiment("trolley_survey", variant, out=out, stop_time=stop, step_size=step, master="container",
                          progress=False, log=io.StringIO(), **kw)


@pytest.fixture(scope="module")
def survey(tmp_path_factory, fmu_dir):
    """120 s of the ideal-IMU survey at 5 ms: its folder and metrics."""
    out = tmp_path_factory.mktemp("survey") / "ideal"
    return out, survey_run(out, 0.005)


def truth_array(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """truth.csv -> times and NAV rows (rad, m, m/s)."""
    tr = pd.read_csv(path)
    nav = np.column_stack([tr.lat_deg * DEG, tr.lon_deg * DEG, tr.height_m, tr.vn, tr.ve, tr.vd,
                           tr.roll_deg * DEG, tr.pitch_deg * DEG, tr.heading_deg * DEG])
    return tr.time_s.to_numpy(), nav


# -- ideal IMU: the numerical floor ------------------------------------------------------------

def check_bar(m: dict) -> None:
    assert m["ins_position_error_max_mm"] < BAR_M * 1e3, m["ins_position_error_max_mm"]
    assert m["ins_attitude_error_max_deg"] < BAR_RAD / DEG, m["ins_attitude_error_max_deg"]
    assert m["ins_velocity_error_max_mm_s"] < 1e-3  # 1 um/s


def test_ideal_imu_at_5_ms(survey):
    """Measured (120 s): 1.0 um position (during the first stop), 1.8e-13 rad, 2.2e-7 mm/s.
    The metrics and their 30 s / 60 s forms are there."""
    _, m = survey
    check_bar(m)
    assert m["motion_start_s"] == 10.0
    for kind, unit in (("position", "mm"), ("velocity", "mm_s"), ("attitude", "deg")):
        whole, at30, at60 = (m[f"ins_{kind}_error_max_{unit}{s}"] for s in ("", "_30s", "_60s"))
        assert 0 < at30 <= at60 <= whole


@pytest.mark.parametrize("step", [0.0025, 0.01])
def test_ideal_imu_at_other_steps(tmp_path, fmu_dir, step):
    """The same bar at 2.5 ms and 10 ms communication steps (the Trolley integrates over the
    step it is given; the INS's interval is the step)."""
    m = survey_run(tmp_path / "run", step, write_files=False)
    assert m["step_size_s"] == step
    check_bar(m)


def test_metrics_against_an_independent_reading_of_the_files(survey):
    """The metrics equal the errors computed here from estimates.csv and truth.csv (to the
    1e-16 of truth.csv's degrees: 4e-10 m in latitude)."""
    out, m = survey
    t, true = truth_array(out / "truth.csv")
    est = pd.read_csv(out / "estimates.csv")
    nav = est[[f"ins.{k}" for k in NAV]].to_numpy()
    rn, re = earth.principal_radii(true[:, 0], true[:, 2])
    d = np.column_stack([(nav[:, 0] - true[:, 0]) * rn, (nav[:, 1] - true[:, 1]) * re * np.cos(true[:, 0]),
                         nav[:, 2] - true[:, 2]])
    assert np.linalg.norm(d, axis=1).max() * 1e3 == pytest.approx(m["ins_position_error_max_mm"], abs=2e-6)
    upto = t <= 40.0 + 1e-9
    assert np.linalg.norm(d[upto], axis=1).max() * 1e3 == pytest.approx(m["ins_position_error_max_mm_30s"],
                                                                      abs=2e-6)
    assert (np.abs(nav[:, 3:6] - true[:, 3:6]).max() * 1e3
            <= m["ins_velocity_error_max_mm_s"] * (1 + 1e-6) + 1e-9)


def _velocity_step(folder: Path, t_jump: float, aware: bool) -> float:
    """The free INS (5 ms) from the truth on ``folder``'s imu.csv: the change of its velocity
    error from the 20 steps before the step after ``t_jump`` to those after (m/s); ``aware``:
    it restarts its two-sample memory with the interval after ``t_jump``."""
    t, true = truth_array(folder / "truth.csv")
    imu = pd.read_csv(folder / "imu.csv").to_numpy()
    k_jump = int(np.flatnonzero(np.isclose(t, t_jump))[0]) + 1
    ins = Strapdown.from_rph(*true[0, :3], true[0, 3:6], true[0, 6:9], 0.005)
    ins.prime(imu[0, 1:4], imu[0, 4:7])
    err = []
    for k in range(1, k_jump + 40):
        if aware and k == k_jump:
            ins.prime(imu[k, 1:4], imu[k, 4:7])
        ins.update(*imu[k, 1:])
        if k >= k_jump - 20:
            err.append(np.array(ins.navigation()[3:6]) - true[k, 3:6])
    err = np.array(err)
    return float(np.linalg.norm(err[25:].mean(axis=0) - err[:15].mean(axis=0)))


def test_an_angular_rate_jump_costs_the_two_sample_ins_a_velocity_step(survey, tmp_path):
    """Why the shipped track's transitions are bloss (models/track/geometry.py): at 80 m
    (t = 101 s) a transition starts. With a linear cant ramp the roll rate jumps there by
    v 0.1 m / (1.5 m 40 m) = 1.67e-3 rad/s; the INS's two-sample coning and sculling take the
    rates as linear over two intervals, so across the jump its sculling term is off by about
    |d omega| h |dv| / 12 = 1.67e-3 0.005 0.049 / 12 = 3.4e-8 m/s, a velocity step that
    integrates into position (0.0386 mm over the whole run at 5 ms). The data are exact there:
    an INS told the instant (it restarts its two-sample memory) has no step. With the bloss
    ramp (the shipped table) the roll rate is continuous and the plain INS has no step either."""
    from railfmu.models.track.geometry import DEFAULT_TRACK

    lin = tmp_path / "linear.csv"
    lin.write_text(DEFAULT_TRACK.read_text().replace(",bloss", ",linear"))
    out_lin = tmp_path / "linear"
    survey_run(out_lin, 0.005, stop=102.0, sets={"trolley": {"track_file": str(lin)}})
    plain, aware = _velocity_step(out_lin, 101.0, False), _velocity_step(out_lin, 101.0, True)
    assert 2.5e-8 < plain < 4.5e-8, plain
    assert aware < 5e-10, aware  # measured 1.6e-10
    bloss = _velocity_step(survey[0], 101.0, False)
    assert bloss < 1e-10, bloss  # measured 1.5e-11


# -- the standard files --------------------------------------------------------------------------

def test_standard_files_are_the_recorded_signals(survey):
    """imu.csv: the measured increments (ImuErrors' outputs), text for text as signals.csv has
    them; truth.csv: the trolley's state, angles in degrees, stopped 0/1; the first row is t0."""
    out, _ = survey
    with open(out / "imu.csv") as f:
        imu = list(csv.reader(f))
    with open(out / "truth.csv") as f:
        truth = list(csv.reader(f))
    with open(out / "signals.csv") as f:
        rows = list(csv.reader(f))
    head, sig = rows[0], rows[1:]
    assert imu[0] == ["time_s", "dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z"]
    assert tuple(truth[0]) == TRUTH_COLUMNS
    assert len(imu) == len(truth) == len(rows) == round(FAST / 0.005) + 2
    for j, name in enumerate(imu[0][1:], 1):
        col = head.index(f"imu.{name}")
        assert [r[j] for r in imu[1:]] == [r[col] for r in sig], name
    assert imu[1] == ["0.0"] + ["0.0"] * 6  # the initial point: no interval yet
    t, nav = truth_array(out / "truth.csv")
    s = pd.read_csv(out / "signals.csv")
    for j, name in enumerate(NAV):
        assert np.abs(nav[:, j] - s[f"trolley.{name}"]).max() <= 4e-16 * max(1.0, np.abs(nav[:, j]).max()), name
    assert {r[-1] for r in truth[1:]} == {"0", "1"}
    assert np.array_equal(pd.read_csv(out / "truth.csv").stopped, s["trolley.stopped"].astype(int))


def test_python_ins_reproduces_the_truth_from_the_files(survey, tmp_path, fmu_dir):
    """python-ins (its own coning and sculling, Coriolis at the interval's start velocity: a
    first-order error) from imu.csv and the first row of truth.csv, against truth.csv over
    120 s. Measured: 0.029 mm at 5 ms, 0.0144 mm at 2.5 ms (first order in the step), the
    Richardson extrapolation 2 x(2.5 ms) - x(5 ms) 0.64 um: below the bar, so the files are
    right, not only consistent with our INS. Attitude: 4e-12 rad. (Over the whole 700 s run
    python-ins reaches 0.23 mm at 5 ms, benchmarks/trolley_survey.py; tests/test_trolley.py
    has its Richardson extrapolation there.)"""
    from pyins import strapdown

    def pyins_errors(folder: Path):
        imu = pd.read_csv(folder / "imu.csv", index_col="time_s")
        imu.columns = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
        tr = pd.read_csv(folder / "truth.csv")
        first = tr.iloc[0]
        pva = pd.Series({"lat": first.lat_deg, "lon": first.lon_deg, "alt": first.height_m, "VN": first.vn,
                         "VE": first.ve, "VD": first.vd, "roll": first.roll_deg, "pitch": first.pitch_deg,
                         "heading": first.heading_deg})
        ins = strapdown.Integrator(pva)
        ins.integrate(strapdown.compute_increments_from_imu(imu, "increment"))  # row 0: the interval before
        traj = ins.trajectory.to_numpy()
        est = traj.copy()
        est[:, [0, 1, 6, 7, 8]] *= DEG
        _, true = truth_array(folder / "truth.csv")
        return navigation_errors(est, true)

    run25 = tmp_path / "run25"
    survey_run(run25, 0.0025)
    e5, e25 = pyins_errors(survey[0]), pyins_errors(run25)
    e25 = {k: v[::2] for k, v in e25.items()}  # at the 5 ms points
    p5, p25 = (np.linalg.norm(e["position"], axis=1) for e in (e5, e25))
    rich = np.linalg.norm(2 * e25["position"] - e5["position"], axis=1)
    print(f"python-ins over {FAST:g} s: {p5.max() * 1e3:.4f} mm (5 ms), {p25.max() * 1e3:.4f} mm (2.5 ms), "
          f"Richardson {rich.max() * 1e3:.5f} mm; attitude {np.linalg.norm(e5['attitude'], axis=1).max():.1e} rad")
    assert p5.max() < 0.04e-3 and p25.max() < 0.02e-3
    assert 1.7 < p5[-1] / p25[-1] < 2.3  # first order in the step: python-ins's Coriolis term
    assert rich.max() < 0.2 * BAR_M
    assert np.linalg.norm(e5["attitude"], axis=1).max() < BAR_RAD


# -- the replay of imu.csv -------------------------------------------------------------------------

def test_replay_of_the_survey_files_gives_the_online_estimates(survey, tmp_path):
    """``railfmu run trolley_imu_replay --set imu.file=... --set truth.file=...`` on the
    survey's files: the INS started from truth.csv's first row (degrees, converted by the
    SSD's unit) gives the survey's online estimates to the last bits."""
    out, m = survey
    res = railfmu("run", "trolley_imu_replay", "--set", f"imu.file={out / 'imu.csv'}", "--set",
                  f"truth.file={out / 'truth.csv'}", "--out", str(tmp_path / "replay"))
    assert res.returncode == 0, res.stderr
    ours = pd.read_csv(out / "estimates.csv")
    replayed = pd.read_csv(tmp_path / "replay" / "estimates.csv")
    assert len(replayed) == len(ours)
    for k in NAV:
        a, b = ours[f"ins.{k}"].to_numpy(), replayed[f"ins.{k}"].to_numpy()
        assert np.abs(a - b).max() <= 1e-14 * max(1.0, np.abs(a).max()), k
    import json
    rm = json.loads((tmp_path / "replay" / "metrics.json").read_text())
    assert rm["early_end"] is None and rm["end_time_s"] == FAST == rm["stop_time_s"]  # the table's end: a normal end
    assert rm["ins_position_error_max_mm"] == pytest.approx(m["ins_position_error_max_mm"], abs=2e-6)  # degrees


def test_shipped_record_replays(tmp_path, fmu_dir):
    """The shipped 15 s (``railfmu run trolley_imu_replay``), and with the paper's initial
    attitude errors: 0.06 deg of heading error turns the 0.3 m/s of the first run's speed by
    0.06 deg, so the position error grows, and the tilt shows as the initial attitude error."""
    res = railfmu("run", "trolley_imu_replay", "--out", str(tmp_path / "a"))
    assert res.returncode == 0, res.stderr
    import json
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())
    check_bar(m)
    res = railfmu("run", "trolley_imu_replay", "--variant", "paper_initial_errors", "--out", str(tmp_path / "b"))
    assert res.returncode == 0, res.stderr
    m = json.loads((tmp_path / "b" / "metrics.json").read_text())
    tilt, heading = 0.006, 0.06
    assert m["ins_attitude_error_max_deg"] == pytest.approx(math.hypot(math.hypot(tilt, tilt), heading), rel=0.02)
    assert m["ins_position_error_max_mm"] > 0.01


# -- the variants carry whole grades -------------------------------------------------------------

def _ssv(path: Path) -> dict[str, float]:
    import xml.etree.ElementTree as ET
    ns = {"ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
    return {p.get("name"): float(p[0].get("value")) for p in ET.parse(path).getroot().iterfind(
        "ssv:Parameters/ssv:Parameter", ns)}


@pytest.mark.parametrize("variant, grade", [("ideal_imu", "ideal"), ("navigation_grade", "navigation_grade"),
                                            ("tactical_grade", "tactical_grade"), ("mems_grade", "mems_grade")])
def test_variant_is_the_grade_ssv(variant, grade):
    from railfmu.models.inertial.imu_errors import GRADES
    v = _ssv(EXP / "variants" / f"{variant}.ssv")
    g = _ssv(EXP / "parameters" / f"imu_{grade}.ssv")
    assert v == {f"imu.{k}": x for k, x in g.items()}
    if grade in GRADES:
        assert g == GRADES[grade]


def test_navigation_grade_short_run(tmp_path, fmu_dir):
    """The paper's grade over the first 60 s: the errors are the grade's, far above the
    ideal IMU's floor (gyro ARW 0.005 deg/sqrt(h) alone tilts the INS by ~6e-5 deg in 60 s)."""
    m = survey_run(tmp_path / "nav", 0.005, stop=60.0, variant="navigation_grade", write_files=False)
    assert 1e-6 < m["ins_attitude_error_max_deg"] < 1e-2
    assert m["ins_position_error_max_mm"] > 0.01


# -- observer settings bound to signals --------------------------------------------------------------

def test_bound_settings_survive_export_and_a_value_overrides_them(tmp_path, fmu_dir):
    from railfmu.models.errors import UserError
    from railfmu.fmus.ssp import read_system, write_ssp
    from railfmu.fmus.generate.build import default_out

    system = read_system(REPLAY, fmu_dirs=[default_out()])
    spec = system.observers[0]
    assert spec.setting_signals["latitude"] == "truth.y_1" and "latitude" not in spec.settings
    write_ssp(system, tmp_path / "r.ssp")
    again = read_system(tmp_path / "r.ssp").observers[0]
    assert again.setting_signals == spec.setting_signals and again.settings == spec.settings
    given = read_system(REPLAY, fmu_dirs=[default_out()], overrides={"ins": {"latitude": 0.5}}).observers[0]
    assert given.settings["latitude"] == 0.5 and "latitude" not in given.setting_signals
    bad = (REPLAY / "SystemStructure.ssd").read_text().replace(
        '<rf:Setting name="height" connector="truth.y_3"/>',
        '<rf:Setting name="height" connector="truth.y_3" value="1"/>')
    folder = tmp_path / "bad"
    shutil.copytree(REPLAY, folder)
    (folder / "SystemStructure.ssd").write_text(bad)
    with pytest.raises(UserError, match="Setting 'height': give one of value, connector or parameter, not value and connector"):
        read_system(folder, fmu_dirs=[default_out()])


# -- libcosim ------------------------------------------------------------------------------------

def test_trolley_and_imu_errors_in_libcosim(tmp_path, fmu_dir):
    """``railfmu export trolley_survey --variant navigation_grade`` run by libcosim (2 s at
    5 ms): the trolley's outputs are ours (its clock is integer nanoseconds: to 1e-12 of each
    signal's range), and the IMU errors ImuErrors adds (its output minus the input it held over
    the step) are ours to 1e-18. libcosim reads ImuErrors' outputs before the next transfer, so
    its input there is the trolley's increment one step earlier than in our recorder (the
    Jacobi ordering seen from outside, tests/test_libcosim.py)."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    from railfmu.fmus.cosim.masters import run as run_master
    from railfmu.fmus.ssp import read_system

    ssp = tmp_path / "survey.ssp"
    res = railfmu("export", "trolley_survey", "--variant", "navigation_grade", "--stop-time", "2", "-o", str(ssp))
    assert res.returncode == 0, res.stderr
    system = read_system(ssp)
    ours = run_master(system, master="jacobi", progress=False)
    col = {c: ours.data[:, j] for j, c in enumerate(ours.columns)}
    n = system.n_steps
    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_ssp_file(str(ssp), step_size=round(system.step_size * 1e9))
    index = {s.name.decode(): s.index for s in ex.slave_infos()}
    obs = CosimObserver.create_time_series(buffer_size=n + 10)
    assert ex.add_observer(obs)
    vrs = {c.name: {v.name: v.valueReference for v in fmpy.read_model_description(str(c.fmu)).modelVariables}
           for c in system.components}
    names = [("trolley", k) for k in ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z", *NAV)]
    names += [("imu", k) for k in ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")]
    for comp, var in names:
        assert obs.start_time_series(index[comp], vrs[comp][var], CosimVariableType.REAL)
    assert ex.simulate_until(n * round(system.step_size * 1e9))

    def lib(comp, var):
        i, vr = index[comp], vrs[comp][var]
        _, _, x0 = obs.time_series_real_samples(i, vr, from_step=0, sample_count=2)
        _, _, x = obs.time_series_real_samples(i, vr, from_step=1, sample_count=n)
        return np.array([x0[0], *x])

    for var in ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z", *NAV):
        a, b = lib("trolley", var), col[f"trolley.{var}"]
        assert np.abs(a - b).max() <= 1e-12 * max(np.ptp(b), 1e-300) + 1e-18, var
    for var in ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z"):
        ideal_lib = lib("trolley", var)
        err_lib = lib("imu", var)[2:] - ideal_lib[1:-1]  # libcosim: the input held is one step older
        err_ours = col[f"imu.{var}"][2:] - col[f"trolley.{var}"][2:]
        assert np.abs(err_ours).max() > 0  # the grade adds errors
        assert np.abs(err_lib - err_ours).max() <= 1e-18 + 1e-12 * np.abs(err_ours).max(), var


# -- bad input: one line, exit 2 -----------------------------------------------------------------

GOOD_TRACK = ("kind,start_m,end_m,radius_m,cant_mm,gradient_permille\n"
              "straight,0,50,,,\nstraight,50,100,,,\ngrade,0,100,,,0\n")


def _bad_track(tmp_path: Path) -> list[str]:
    p = tmp_path / "track.csv"
    p.write_text(GOOD_TRACK.replace("straight,50,100", "straight,40,100"))
    return ["run", "trolley_survey", "--set", f"trolley.track_file={p}", "--stop-time", "1"]


def _bad_grade(tmp_path: Path) -> list[str]:
    """A copy of the experiment whose navigation grade has a negative accelerometer noise."""
    folder = tmp_path / "survey"
    shutil.copytree(EXP, folder, ignore=shutil.ignore_patterns("__pycache__"))
    grade = folder / "variants" / "navigation_grade.ssv"
    text = grade.read_text()
    bad = text.replace('name="imu.accel_noise_ug_sqrt_hz"><ssv:Real value="10.0"',
                       'name="imu.accel_noise_ug_sqrt_hz"><ssv:Real value="-10.0"')
    assert bad != text
    grade.write_text(bad)
    return ["run", str(folder), "--variant", "navigation_grade", "--stop-time", "1"]


def _bad_imu_csv(tmp_path: Path) -> list[str]:
    p = tmp_path / "imu.csv"
    lines = (REPLAY / "resources" / "imu.csv").read_text().splitlines()[:50]
    p.write_text("\n".join(",".join(line.split(",")[:6]) for line in lines) + "\n")  # no dv_z
    return ["run", "trolley_imu_replay", "--set", f"imu.file={p}"]


@pytest.mark.parametrize("make, message", [
    (_bad_track, "start_m"),
    (lambda tmp: ["run", "trolley_survey", "--set", "trolley.stop_spacing=-60", "--stop-time", "1"], "stop_spacing"),
    (_bad_grade, "accel_noise_ug_sqrt_hz"),
    (_bad_imu_csv, "dv_z"),
], ids=["track-non-monotonic", "negative-stop-spacing", "grade-negative-noise", "imu-csv-missing-column"])
def test_bad_input_is_one_line_and_exit_2(tmp_path, fmu_dir, make, message):
    res = railfmu(*make(tmp_path), "--out", str(tmp_path / "out"))
    errors = [line for line in res.stderr.splitlines() if not line.startswith(("running ", "  "))]
    assert res.returncode == 2, res.stderr
    assert len(errors) == 1 and errors[0].startswith("railfmu: error: ") and message in errors[0], res.stderr
    assert "Traceback" not in res.stderr


# -- the whole run (slow) ------------------------------------------------------------------------

@pytest.mark.slow
def test_whole_run(tmp_path, fmu_dir):
    """The whole 600 m, 700 s ideal-IMU run at 5, 2.5 and 10 ms on the shipped track (bloss
    transitions and vertical curves: the angular rates are continuous everywhere). Measured:
    position 0.00135, 0.00034 and 0.0054 mm (second order in the step), attitude 5.6e-13,
    1.4e-13 and 2.2e-12 rad, velocity 1.5e-9, 3.6e-10 and 6.5e-9 m/s: the ideal IMU's bar at all
    three steps. With linear transitions (``test_an_angular_rate_jump_...``) the same runs
    gave 0.0386, 0.00966 and 0.154 mm, from the eight angular-rate jumps met in motion
    (3.4e-8 m/s at each cant-ramp end of the 400 m curve at 5 ms, 2.0e-8 at the 600 m
    curve's, 2.7e-9 and 3.1e-9 at the vertical curves', each integrating for the rest of the
    run)."""
    results = {}
    for step in (0.005, 0.0025, 0.01):
        m = survey_run(tmp_path / f"run{step}", step, stop=700.0, write_files=False)
        results[step] = m
        check_bar(m)
    print({h: (m["ins_position_error_max_mm"], m["ins_attitude_error_max_deg"] * DEG) for h, m in results.items()})
    # second order in the step, well inside the bar
    assert results[0.005]["ins_position_error_max_mm"] < 0.003
    assert results[0.0025]["ins_position_error_max_mm"] < 0.001
    assert results[0.01]["ins_position_error_max_mm"] < 0.008


# -- the aided survey: smoother, chords, variants, Monte Carlo ------------------------------------

PAPER = {"alignment": 0.99, "level": 0.70}  # Jiang et al. (2017), Fig. 12: RMS over 500 runs of the max (mm)


def test_variants_are_what_variants_py_writes():
    """variants/*.ssv are exactly what `python -m railfmu.experiments.trolley_survey.variants` writes:
    4 grades, paper_montecarlo, 5 aidings x 3 grades."""
    from railfmu.experiments.trolley_survey.variants import AIDINGS, variants

    written = variants()
    assert {p.stem: p.read_text() for p in (EXP / "variants").glob("*.ssv")} == written
    assert len(written) == 4 + 1 + 3 * len(AIDINGS) == 20
    assert {"zupt_nhc_odometer", "zupt_nhc_odometer_tactical", "landmarks_mems"} <= set(written)


def test_the_smoother_follows_the_grade_and_the_variant(fmu_dir):
    """The smoother's noise model is the grade the variant selects (settings bound to imu.*),
    also after a --set; paper_montecarlo shortens the run, switches the INS off and takes one
    ZUPT per stop; the experiment prefers the container master."""
    from railfmu.fmus.generate.build import default_out
    from railfmu.fmus.ssp import read_system
    from railfmu.models.inertial.imu_errors import GRADES

    s = read_system(EXP, variant="zupt_nhc_mems", fmu_dirs=[default_out()])
    smoother = next(o for o in s.observers if o.name == "smoother")
    for k in ("gyro_arw_deg_sqrt_h", "gyro_bias_instability_deg_h", "accel_noise_ug_sqrt_hz",
              "accel_bias_instability_ug", "gyro_bias_correlation_time", "accel_bias_correlation_time"):
        assert smoother.settings[k] == GRADES["mems_grade"][k] == s.component("imu").parameters[k]
    assert smoother.settings["nhc"] is True and smoother.settings["nhc_sigma"] == 1e-4
    # the play model: the wobble's rms and, bound to the trolley's parameter, its wavelength
    assert smoother.settings["play_model"] == "shaping"
    assert smoother.settings["play_sigma_lateral"] == pytest.approx(1e-3 / math.sqrt(2), rel=1e-15)
    assert smoother.settings["play_sigma_vertical"] == pytest.approx(5e-4 / math.sqrt(2), rel=1e-15)
    assert smoother.setting_parameters["play_wavelength"] == "trolley.wobble_wavelength"
    assert smoother.settings["play_wavelength"] == s.component("trolley").parameters["wobble_wavelength"] == 2.0
    s = read_system(EXP, variant="zupt_nhc", fmu_dirs=[default_out()], overrides={"trolley": {"wobble_wavelength": 3.0}})
    assert next(o for o in s.observers if o.name == "smoother").settings["play_wavelength"] == 3.0
    assert not next(o for o in s.observers if o.name == "ins").enabled
    assert s.master == "container" and s.stop_time == 700.0
    s = read_system(EXP, variant="paper_montecarlo", fmu_dirs=[default_out()],
                    overrides={"imu": {"accel_noise_ug_sqrt_hz": "20"}})
    smoother = next(o for o in s.observers if o.name == "smoother")
    assert smoother.settings["accel_noise_ug_sqrt_hz"] == 20.0 and smoother.settings["gyro_arw_deg_sqrt_h"] == 0.005
    assert smoother.settings["zupt_interval"] == math.inf
    assert (s.stop_time, s.stop_time_from) == (31.5, "variant paper_montecarlo (experiment.stopTime)")
    assert s.component("trolley").parameters["track_file"] == "trolley_straight_30m.csv"
    assert smoother.setting_signals["tilt_error_north"] == "initial_errors.y_1"


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory, fmu_dir):
    """One paper_montecarlo run with its files (seed 3), and its chord survey (the run's
    metrics, figures and series share it: the study module keeps the last one)."""
    import railfmu.experiments.trolley_survey as ts

    out = tmp_path_factory.mktemp("paper") / "run"
    m = run_experiment("trolley_survey", "paper_montecarlo", out=out, seed=3, progress=False, log=io.StringIO())
    return out, m, ts._LAST_SURVEY[1]


def test_paper_run_is_the_papers_nominal_run(paper_run):
    """paper_montecarlo's short ramps (5 m/s2) and rest (0.1 s) make it the paper's run at
    constant speed between two velocity updates: the largest pointwise sigma of its chord
    errors (exact, the smoother's joint covariance) within 3 % of the covariance analysis of
    the paper's nominal run (0.979 / 0.695 mm); measured 0.998 / 0.712 mm (1.019 / 1.025). With
    the Trolley's default ramps (0.5 m/s2) it was 1.17 / 0.90. The ramps stay inside the 30 m:
    the one chord has all its 51 points, 0 to 25 m."""
    from railfmu.estimators.inertial.chord_accuracy import (
        NOMINAL,
        nominal_chord_accuracy,
        nominal_run,
    )

    _, m, sr = paper_run
    assert (m["chords_surveyed"], m["chord_points"]) == (1, 51)
    assert sr.grid.s[0] == 0.0 and sr.grid.s[-1] == 25.0 and sr.grid.distance[-1] == 30.0
    sy, sz = sr.pointwise_sigma()
    nominal = nominal_chord_accuracy(nominal_run(), **NOMINAL)
    print(f"peak pointwise sigma {sy.max():.4f} / {sz.max():.4f} mm, nominal {nominal['alignment_mm']:.4f} / "
          f"{nominal['level_mm']:.4f}")
    assert sy.max() == pytest.approx(nominal["alignment_mm"], rel=0.03)
    assert sz.max() == pytest.approx(nominal["level_mm"], rel=0.03)
    # the per-run sampled prediction of the same (500 draws: ~3 % per point, the max biased up a little)
    assert m["predicted_peak_sigma_alignment_mm"] == pytest.approx(sy.max(), rel=0.08)
    assert m["predicted_peak_sigma_level_mm"] == pytest.approx(sz.max(), rel=0.08)


def test_a_run_without_seed_predicts_the_same_every_time(tmp_path, fmu_dir):
    """The prediction samples the smoother's error distribution: without ``--seed`` its draws
    take seed 0, so the same command writes the same metrics.json (it drew fresh numbers each
    time before)."""
    ms = [run_experiment("trolley_survey", "paper_montecarlo", out=tmp_path / f"r{i}", progress=False,
                         log=io.StringIO()) for i in range(2)]
    for key in ("predicted_sigma_alignment_mm", "predicted_sigma_level_mm", "predicted_peak_sigma_level_mm"):
        assert ms[0][key] == ms[1][key]


def test_paper_run_chord_errors_from_its_files(paper_run):
    """The chord metrics of a paper_montecarlo run, recomputed from signals.csv and
    estimates_smoother.csv by hand: the one 30 m chord from the record samples nearest to
    0, 0.5, ..., 30 m, eq. 14 of the surveyed and the true points against their chords."""
    out, m, _ = paper_run
    sig = pd.read_csv(out / "signals.csv")
    est = pd.read_csv(out / "estimates_smoother.csv")
    assert np.array_equal(sig.time.to_numpy(), est.time.to_numpy()) and sig.time.iloc[-1] == 31.5
    d = sig["trolley.distance"].to_numpy()
    rn, re = earth.principal_radii(sig["trolley.latitude"].to_numpy(), sig["trolley.height"].to_numpy())
    err = np.column_stack([(est["smoother.latitude"] - sig["trolley.latitude"]) * rn,
                           (est["smoother.longitude"] - sig["trolley.longitude"]) * re * np.cos(sig["trolley.latitude"]),
                           -(est["smoother.height"] - sig["trolley.height"])])
    true = sig[["trolley.north", "trolley.east", "trolley.down"]].to_numpy()
    rows = [int(np.argmin(np.abs(d - x))) for x in np.arange(0.0, 30.0 + 1e-9, 0.5)]
    assert d[rows[-1]] == pytest.approx(30.0, abs=0.01)

    def irregularity(p):  # d_s - d_{s+5}, eq. 14 against the chord p[0] -> p[-1]
        c = p[-1] - p[0]
        az, sl = math.atan2(c[1], c[0]), -c[2] / np.linalg.norm(c)
        cl = math.sqrt(1 - sl * sl)
        e = p - p[0]
        y = -e[:, 0] * math.sin(az) + e[:, 1] * math.cos(az)
        z = e[:, 0] * sl * math.cos(az) + e[:, 1] * sl * math.sin(az) + e[:, 2] * cl
        return y[:51] - y[10:], z[:51] - z[10:]

    ya, za = irregularity(true[rows] + err[rows])
    yt, zt = irregularity(true[rows])
    assert m["chord_alignment_max_error_mm"] == pytest.approx(1e3 * np.abs(ya - yt).max(), rel=1e-9)
    assert m["chord_level_max_error_mm"] == pytest.approx(1e3 * np.abs(za - zt).max(), rel=1e-9)
    assert m["chord_level_rms_error_mm"] == pytest.approx(1e3 * np.sqrt(np.mean((za - zt) ** 2)), rel=1e-9)
    assert (m["chords_surveyed"], m["chord_points"]) == (1, 51)
    assert m["observers"]["smoother"]["zupt_updates"] == 2  # one per stop: the start and the end
    assert "ins" not in m["observers"] and "ins_position_error_max_mm" not in m
    for f in ("chord_irregularity.png", "trajectory_3d.png", "smoother_errors.png", "sensitivity_fig8.png",
              "sensitivity_fig11.png", "imu.csv", "truth.csv"):
        assert (out / f).is_file(), f
    assert "max \\|error\\|" in (out / "report.md").read_text()


def test_pooled_peak_rms_of_hand_made_series():
    """The pointwise RMS over runs and its peak, by hand: three runs on two chord points with
    errors (mm) whose RMS over runs is 2 mm at 0.5 m and sqrt(14/3) mm at 1.0 m for alignment,
    sqrt(14/3) and sqrt(11/3) for level; runs of different chord points (or none) are refused, naming
    both; runs without chords give nothing."""
    from railfmu.experiments.trolley_survey.survey_accuracy import pooled_peak_rms

    s = np.array([0.5, 1.0], dtype=np.float32)

    def run(a, v, at=s):
        return {"chord_s": at, "chord_alignment_error": np.float32(1e-3) * np.array(a, np.float32),
                "chord_level_error": np.float32(1e-3) * np.array(v, np.float32)}

    series = {1: run([2, 1], [1, -3]), 2: run([-2, 2], [-2, 1]), 3: run([2, -3], [3, 1])}
    out = pooled_peak_rms(series)
    assert out["chord_alignment_peak_rms_error_mm"] == pytest.approx(math.sqrt(14 / 3), rel=1e-6)
    assert out["chord_alignment_peak_rms_s_m"] == 1.0
    assert out["chord_level_peak_rms_error_mm"] == pytest.approx(math.sqrt(14 / 3), rel=1e-6)
    assert out["chord_level_peak_rms_s_m"] == 0.5
    assert out["chord_peak_rms_runs"] == 3
    series[2] = run([0, 0], [1, 1])
    assert pooled_peak_rms(series)["chord_alignment_peak_rms_error_mm"] == pytest.approx(math.sqrt(10 / 3), rel=1e-6)
    with pytest.raises(ValueError, match=r"run 4 surveys 2 points from 0\.5 to 1\.5 m, run 1 2 points from 0\.5 to 1 m"):
        pooled_peak_rms({**series, 4: run([1, 1], [1, 1], np.array([0.5, 1.5], np.float32))})
    with pytest.raises(ValueError, match="run 5 surveys no chord points"):
        pooled_peak_rms({**series, 5: {}})
    assert pooled_peak_rms({1: {}, 2: {}}) == {}
    # the study keeps its table and says why it did not pool
    from railfmu.experiments.trolley_survey import STUDY

    table = {"v": {"runs": {}, "summary": {}}}
    md = STUDY.study_tables(table, {"v": {**series, 5: {}}})
    assert "run 5 surveys no chord points" in table["v"]["summary"]["chord_peak_rms_refused"]
    assert "`v`: no peak RMS: cannot pool" in md


@pytest.fixture(scope="module")
def reduced_monte_carlo(tmp_path_factory, fmu_dir):
    """20 runs of paper_montecarlo through the study (two Dask workers)."""
    from railfmu.experiments.engine.study import run_study

    out = tmp_path_factory.mktemp("mc20")
    table = run_study("trolley_survey", out, variants=["paper_montecarlo"], runs=20, log=io.StringIO())
    return out, table


def test_reduced_monte_carlo_agrees_with_its_prediction(reduced_monte_carlo):
    """20 runs: the mean of the per-run predictions within 30 % of the RMS over runs of the
    max chord errors (the study's 15 % at 500 runs; 20 runs leave ~12 % sampling error on an
    RMS of a max, std(M^2) / mean(M^2) ~ 1.3), and the Monte Carlo's peak RMS (the paper's
    statistic) within 30 % of the predicted peak pointwise sigma and of the paper's 0.99 / 0.70
    mm: an RMS over 20 runs at one point has a relative standard error of 1 / sqrt(40) = 16 %
    (Gaussian errors), so 30 % is ~2 of them, and the other statistic, 1.5-1.7 times larger, is
    outside. Measured (seeds 1-20): RMS of max 1.53 / 1.14 mm, predicted 1.51 / 1.19 (ratios
    0.99 / 1.04); peak RMS 1.12 / 0.73 mm, predicted peak sigma 1.02 / 0.73 (0.91 / 1.00)."""
    out, table = reduced_monte_carlo
    s = table["paper_montecarlo"]["summary"]
    for kind in ("alignment", "level"):
        mc = s[f"chord_{kind}_max_error_mm"]["rms"]
        predicted = s[f"predicted_sigma_{kind}_mm"]["mean"]
        assert abs(predicted / mc - 1.0) < 0.30, (kind, mc, predicted)
        assert s[f"chord_{kind}_max_error_mm"]["min"] > 0
        assert s[f"predicted_sigma_{kind}_mm"]["std"] < 0.06 * predicted  # 500 draws per run: ~1.7 %
        peak, peak_predicted = s[f"chord_{kind}_peak_rms_error_mm"], s[f"predicted_peak_sigma_{kind}_mm"]["mean"]
        print(kind, "RMS of max", mc, predicted, "peak RMS", peak, peak_predicted)
        assert abs(peak_predicted / peak - 1.0) < 0.30, (kind, peak, peak_predicted)
        assert abs(peak / PAPER[kind] - 1.0) < 0.30, (kind, peak)
        assert peak <= mc  # every run's max is at least its error at the peak point
    assert s["chord_peak_rms_runs"] == 20 and 0.0 <= s["chord_level_peak_rms_s_m"] <= 25.0
    md = (out / "table.md").read_text()
    assert "| paper_montecarlo | alignment |" in md and "predicted / MC" in md and "0.99" in md and "0.70" in md
    assert "peak RMS" in md and "are the peak RMS" in md
    saved = json.loads((out / "table.json").read_text())["paper_montecarlo"]["summary"]
    assert saved["chord_alignment_peak_rms_error_mm"] == s["chord_alignment_peak_rms_error_mm"]
    assert (out / "max_error_histograms.png").is_file()
    runs = table["paper_montecarlo"]["runs"]
    assert len(runs) == 20 and all(m["master"] == "container" and m["stop_time_s"] == 31.5 for m in runs.values())


@pytest.mark.slow
def test_the_500_run_monte_carlo(tmp_path, fmu_dir):
    """`railfmu study trolley_survey --variant paper_montecarlo --runs 500`: the prediction from
    the smoother's joint covariance within 15 % of the Monte Carlo RMS of the max chord errors,
    and the Monte Carlo's peak RMS (the paper's statistic) within 10 % of the predicted peak
    pointwise sigma and of the paper's 0.99 / 0.70 mm (an RMS over 500 runs at one point: 3.2 %
    relative standard error). Measured (seeds 1-500; 81 s on the 2-core machine at load ~3):
    RMS of max 1.511 / 1.169 mm (alignment / level), predicted 1.505 / 1.190 (ratios 1.00 /
    1.02); peak RMS 0.975 / 0.698 mm, predicted peak sigma 1.012 / 0.725 (1.04 / 1.04), the
    paper's 0.99 / 0.70 to 1.5 % / 0.3 %."""
    from railfmu.experiments.engine.study import run_study

    table = run_study("trolley_survey", tmp_path, variants=["paper_montecarlo"], runs=500, log=sys.stderr)
    s = table["paper_montecarlo"]["summary"]
    for kind in ("alignment", "level"):
        mc, predicted = s[f"chord_{kind}_max_error_mm"]["rms"], s[f"predicted_sigma_{kind}_mm"]["mean"]
        peak, peak_predicted = s[f"chord_{kind}_peak_rms_error_mm"], s[f"predicted_peak_sigma_{kind}_mm"]["mean"]
        print(kind, "RMS of max", mc, predicted, "peak RMS", peak, peak_predicted)
        assert abs(predicted / mc - 1.0) < 0.15
        assert abs(peak_predicted / peak - 1.0) < 0.10
        assert abs(peak / PAPER[kind] - 1.0) < 0.10
        assert peak < mc


@pytest.mark.slow
def test_nhc_and_odometer_reach_half_a_millimetre(tmp_path, fmu_dir):
    """Issue 14's second target: ``zupt_nhc_odometer`` (navigation grade, the trolley wobbling
    1 mm / 0.5 mm across the rail, the NHC with the play as shaping states) keeps the RMS over
    runs of the max chord error <= 0.5 mm, alignment and level; the prediction is conservative
    (the wobble is one sinusoid, narrower than the filter's play process) but not by more than
    2.5 times. 16 runs (75 s): 0.367 / 0.199 mm, predicted 0.599 / 0.388; over 500 runs
    (29 min): 0.352 / 0.198 mm, predicted 0.599 / 0.389. The white NHC (3 mm/s) gave 1.56 / 1.44 mm."""
    from railfmu.experiments.engine.study import run_study

    table = run_study("trolley_survey", tmp_path, variants=["zupt_nhc_odometer"], runs=16, log=sys.stderr)
    s = table["zupt_nhc_odometer"]["summary"]
    for kind in ("alignment", "level"):
        mc, predicted = s[f"chord_{kind}_max_error_mm"]["rms"], s[f"predicted_sigma_{kind}_mm"]["mean"]
        print(kind, "RMS of max", mc, "predicted", predicted)
        assert mc <= 0.5, (kind, mc)
        assert 1.0 <= predicted / mc <= 2.5, (kind, mc, predicted)


def test_repeatability_over_six_runs_of_the_same_track(tmp_path, fmu_dir):
    """--runs 6 of an aided survey keeps the track (irregularity_seed) and draws new IMU errors
    (seed): the first 80 s of zupt_60m (two chords); Table 1's differences G1j and Fig. 15."""
    from railfmu.experiments.engine.study import run_study

    table = run_study("trolley_survey", tmp_path, variants=["zupt_60m"], runs=6, stop_time=80.0, log=io.StringIO())
    rows = table["zupt_60m"]["repeatability"]
    assert [r["pair"] for r in rows] == ["G12", "G13", "G14", "G15", "G16"]
    runs = table["zupt_60m"]["runs"]
    assert len({m["parameters"]["trolley"]["irregularity_seed"] for m in runs.values()}) == 1
    assert len({m["chord_alignment_max_error_mm"] for m in runs.values()}) == 6  # new IMU errors each run
    for r in rows:
        for kind in ("alignment", "level"):
            assert 0 < r[kind]["std"] <= r[kind]["max"] < 20.0
    md = (tmp_path / "table.md").read_text()
    assert "Repeatability of `zupt_60m`" in md and "| G12 |" in md
    assert (tmp_path / "repeatability_zupt_60m.png").is_file()


@pytest.mark.parametrize("variant, counts", [
    ("zupt_nhc_odometer", ("nhc_updates", "odometer_updates")),
    ("landmarks", ("landmark_updates",)),
])
def test_aided_variants_use_their_aiding(tmp_path, fmu_dir, variant, counts):
    """The first 80 s of two aided variants: the smoother takes the aiding's updates, the INS
    is off, the chords of the first 60 m are scored; the landmark fixes come one per stop."""
    m = survey_run(tmp_path / variant, 0.005, stop=80.0, variant=variant, write_files=False, seed=2)
    sm = m["observers"]["smoother"]
    assert sm["zupt_updates"] > 0 and all(sm[c] > 0 for c in counts)
    if variant == "landmarks":
        assert sm["landmark_updates"] == 2  # the initial rest and the stop at 60 m
    assert "ins" not in m["observers"] and m["chords_surveyed"] == 2
    assert 0 < m["chord_alignment_max_error_mm"] < 20 and 0 < m["predicted_sigma_level_mm"] < 20


@pytest.mark.parametrize("args, message", [
    (["--variant", "paper_montecarlo", "--set", "smoother.zupt_interval=-1"], "zupt_interval must be >= 0"),
    (["--variant", "paper_montecarlo", "--set", "smoother.error_model=paper13"], "error_model must be one of"),
    (["--variant", "paper_montecarlo", "--set", "experiment.stopTime=soon"], "experiment.stopTime 'soon' must be"),
    (["--variant", "paper_montecarlo", "--set", "ins.enabled=maybe"], "setting enabled='maybe' must be true or false"),
], ids=["negative-zupt-interval", "unknown-error-model", "bad-stop-time", "bad-enabled"])
def test_bad_aided_survey_input_is_one_line_and_exit_2(tmp_path, fmu_dir, args, message):
    res = railfmu("run", "trolley_survey", *args, "--out", str(tmp_path / "out"))
    errors = [line for line in res.stderr.splitlines() if not line.startswith(("running ", "  t ="))]
    assert res.returncode == 2, res.stderr
    assert len(errors) == 1 and message in errors[0], res.stderr
