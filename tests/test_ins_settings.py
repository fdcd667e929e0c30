"""The inertial estimators' settings as frozen dataclasses (railfmu.estimators.core.settings):
the defaults of the hand-written checks they replace, units, the shipped SSDs and variants
valid unchanged, and one-line errors with exit 2 through the command line."""

from __future__ import annotations

import dataclasses
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from railfmu.estimators.core.settings import Settings
from railfmu.estimators.inertial.aided_ins import (
    AidedInsSettings,
    AidedInsSmoother,
    ImuGradeSettings,
    covariance_analysis,
)
from railfmu.estimators.inertial.aiding import AIDINGS
from railfmu.estimators.inertial.ins_error_model import ImuGrade
from railfmu.estimators.inertial.ins_observer import StrapdownINS, StrapdownSettings
from railfmu.estimators.inertial.rail_play import BUTTERWORTH

ROOT = Path(__file__).resolve().parents[1]
DEG = math.pi / 180.0
DT = 0.005

#: ``aided_ins._DEFAULTS`` before the dataclasses (nhc_sigma: its default with play_model="white")
OLD_SMOOTHER_DEFAULTS = {
    "latitude": 0.0, "longitude": 0.0, "height": 0.0, "vn": 0.0, "ve": 0.0, "vd": 0.0,
    "roll": 0.0, "pitch": 0.0, "heading": 0.0,
    "tilt_error_north": 0.0, "tilt_error_east": 0.0, "heading_error": 0.0,
    "velocity_error_north": 0.0, "velocity_error_east": 0.0, "velocity_error_down": 0.0,
    "tilt_sigma": 0.006 * DEG, "heading_sigma": 0.06 * DEG, "velocity_sigma": 1e-4, "position_sigma": 0.1,
    "gyro_arw_deg_sqrt_h": 0.005, "gyro_bias_instability_deg_h": 0.01, "gyro_bias_correlation_time": 3600.0,
    "accel_noise_ug_sqrt_hz": 10.0, "accel_bias_instability_ug": 50.0, "accel_bias_correlation_time": 3600.0,
    "gyro_turn_on_bias_sigma_deg_h": 0.0, "accel_turn_on_bias_sigma_ug": 0.0,
    "error_model": "paper12", "filter_period": 0.05, "feedback": True,
    "zupt": True, "zupt_sigma": 1e-4, "zupt_interval": 0.0, "zupt_source": "flag",
    "nhc": False, "nhc_sigma": 1e-3, "odometer": False, "odometer_sigma": 1e-3,
    "landmarks": False, "landmark_sigma": 0.1, "memory_budget_mb": 320.0,
    "play_model": "white", "play_sigma_lateral": 1e-3, "play_sigma_vertical": 5e-4, "play_wavelength": 2.0,
    "play_damping": BUTTERWORTH,
}
#: ``ins_observer._DEFAULTS`` before
OLD_STRAPDOWN_DEFAULTS = {
    "latitude": 0.0, "longitude": 0.0, "height": 0.0, "vn": 0.0, "ve": 0.0, "vd": 0.0,
    "roll": 0.0, "pitch": 0.0, "heading": 0.0,
    "tilt_error_north": 0.0, "tilt_error_east": 0.0, "heading_error": 0.0,
    "alignment": "given", "alignment_time": 60.0,
}


def test_defaults_are_the_old_ones():
    assert dataclasses.asdict(AidedInsSettings()) == OLD_SMOOTHER_DEFAULTS
    assert dataclasses.asdict(AidedInsSmoother(DT).config) == OLD_SMOOTHER_DEFAULTS
    assert dataclasses.asdict(StrapdownSettings()) == OLD_STRAPDOWN_DEFAULTS
    assert dataclasses.asdict(StrapdownINS(DT).config) == OLD_STRAPDOWN_DEFAULTS
    # the grade's defaults and names are ImuGrade's
    assert dataclasses.asdict(ImuGradeSettings().grade()) == dataclasses.asdict(ImuGrade())
    # the NHC's default follows the play model, unless given
    assert AidedInsSettings.from_mapping({"play_model": "shaping"}, "t").nhc_sigma == 1e-4
    assert AidedInsSettings.from_mapping({"play_model": "shaping", "nhc_sigma": 3e-3}, "t").nhc_sigma == 3e-3


def test_every_field_has_a_doc_and_each_aiding_its_block():
    for cls in (AidedInsSettings, StrapdownSettings):
        for f in dataclasses.fields(cls):
            assert f.metadata.get("doc"), f"{cls.__name__}.{f.name} has no doc"
            assert "unit" in f.metadata
    names = {f.name for f in dataclasses.fields(AidedInsSettings)}
    for aiding in AIDINGS:  # composed: an aiding's settings are the smoother's
        assert issubclass(aiding.settings, Settings) and issubclass(AidedInsSettings, aiding.settings)
        assert {f.name for f in dataclasses.fields(aiding.settings)} <= names
    assert len(AidedInsSettings.describe()) == len(OLD_SMOOTHER_DEFAULTS)
    assert "zupt_sigma (m/s, 0.0001): ZUPT noise std per axis" in AidedInsSettings.describe()


def test_units_degrees_of_the_grade_arrive_in_si_and_angles_stay_rad():
    """The grade is given in the datasheet's deg/h, deg/sqrt(h), µg: the filter's noise model
    holds rad/s, rad/sqrt(s), m/s2. Angles of the state are rad (the files give rad)."""
    obs = AidedInsSmoother(DT, gyro_bias_instability_deg_h="0.01", gyro_arw_deg_sqrt_h=0.005,
                           accel_bias_instability_ug=50, gyro_bias_correlation_time="inf",
                           tilt_error_north=1.0471975511965978e-4)
    grade = obs.model.grade
    assert grade.gyro_bias_sigma == pytest.approx(1.076 * 0.01 * DEG / 3600.0, rel=1e-3)
    assert grade.gyro_noise == pytest.approx(0.005 * DEG / 60.0, rel=1e-12)
    assert grade.accel_bias_sigma == pytest.approx(1.076 * 50e-6 * 9.80665, rel=1e-3)
    assert math.isinf(obs.config.gyro_bias_correlation_time)
    assert obs.config.tilt_error_north == 1.0471975511965978e-4  # as given: rad
    assert AidedInsSettings().heading_sigma == pytest.approx(0.06 * DEG, rel=1e-15)  # the paper's 0.06 deg
    assert AidedInsSmoother(DT, zupt_interval="inf").config.zupt_interval == math.inf  # an SSV String


@pytest.mark.parametrize("cls, settings, message", [
    (AidedInsSmoother, {"zupt_sigam": 1e-4}, "AidedInsSmoother: unknown setting 'zupt_sigam' (closest: zupt_sigma"),
    (AidedInsSmoother, {"nhc_sigma": -1.0}, "AidedInsSmoother: setting nhc_sigma must be > 0 m/s, not -1.0"),
    (AidedInsSmoother, {"feedback": "maybe"}, "AidedInsSmoother: setting feedback = 'maybe' must be true or false"),
    (StrapdownINS, {"alignment_time": -1}, "StrapdownINS: setting alignment_time must be > 0 s, not -1.0"),
    (StrapdownINS, {"latitude": 2.0}, "StrapdownINS: setting latitude must be <= 1.5708 rad, not 2.0"),
    (StrapdownINS, {"headng": 0.1}, "StrapdownINS: unknown setting 'headng' (closest: heading"),
])
def test_bad_settings_one_line(cls, settings, message):
    with pytest.raises(ValueError) as exc:
        cls(DT, **settings)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_covariance_analysis_keeps_its_keywords_through_the_dataclass():
    kw = dict(times=[0.0, 0.05, 0.1], f_n=(0.0, 0.0, -9.8), C_bn=[[1, 0, 0], [0, 1, 0], [0, 0, 1]], latitude=0.5,
              velocity=(1.0, 0.0, 0.0), zupt=[True, False, True])
    a = covariance_analysis(**kw, zupt_sigma=2e-4, error_model="full15")
    assert a.P_filter.shape == (3, 15, 15)
    with pytest.raises(ValueError, match=r"^covariance_analysis: unknown setting 'zupt_sigam' \(closest: zupt_sigma"):
        covariance_analysis(**kw, zupt_sigam=2e-4)
    with pytest.raises(ValueError, match="^covariance_analysis: setting landmark_sigma must be > 0 m"):
        covariance_analysis(**kw, landmark_sigma=0)


def _variants(experiment: str) -> list[str | None]:
    return [None, *sorted(p.stem for p in (ROOT / "experiments" / experiment / "variants").glob("*.ssv"))]


@pytest.mark.parametrize("experiment", ["trolley_survey", "trolley_imu_replay"])
def test_shipped_ssds_and_variants_are_valid_unchanged(experiment, fmu_dir):
    from railfmu.experiments.engine.observer_bank import make_observer
    from railfmu.fmus.ssp.reader import read_system

    for variant in _variants(experiment):
        system = read_system(ROOT / "experiments" / experiment, variant=variant, fmu_dirs=[fmu_dir])
        for spec in system.observers:
            obs, _ = make_observer(spec, DT, f"{experiment}/{variant}")
            assert isinstance(obs.config, (AidedInsSettings, StrapdownSettings))
            given = {k: v for k, v in spec.class_settings.items() if not isinstance(v, str)}
            for k, v in given.items():  # numbers and flags arrive as the file gives them (no unit change)
                assert getattr(obs.config, k) == v, (variant, spec.name, k)


def _railfmu(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "railfmu.experiments.engine.cli", *args], capture_output=True, text=True, timeout=300)


def _copy(experiment: str, to: Path) -> Path:
    folder = to / experiment
    shutil.copytree(ROOT / "experiments" / experiment, folder, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    return folder


@pytest.mark.parametrize("experiment, old, new, message", [
    ("trolley_imu_replay", '<rf:Setting name="tilt_error_north" value="0"/>',
     '<rf:Setting name="tilt_eror_north" value="0"/>',
     "Observer 'ins': bad settings: StrapdownINS: unknown setting 'tilt_eror_north' "
     "(closest: tilt_error_north, tilt_error_east)"),
    ("trolley_imu_replay", '<rf:Setting name="heading_error" value="0"/>',
     '<rf:Setting name="heading_error" value="0"/>\n            <rf:Setting name="alignment_time" value="-5"/>',
     "Observer 'ins': bad settings: StrapdownINS: setting alignment_time must be > 0 s, not -5.0"),
    ("trolley_survey", '<rf:Setting name="play_wavelength" parameter="trolley.wobble_wavelength"/>',
     '<rf:Setting name="play_wavelenght" parameter="trolley.wobble_wavelength"/>',
     "Observer 'smoother': bad settings: AidedInsSmoother: unknown setting 'play_wavelenght' "
     "(closest: play_wavelength"),
    ("trolley_survey", '<rf:Setting name="play_wavelength" parameter="trolley.wobble_wavelength"/>',
     '<rf:Setting name="play_wavelength" parameter="trolley.wobble_wavelength"/>\n'
     '            <rf:Setting name="zupt_sigma" value="-1e-4"/>',
     "Observer 'smoother': bad settings: AidedInsSmoother: setting zupt_sigma must be > 0 m/s, not -0.0001"),
])
def test_cli_bad_setting_is_one_line_and_exit_2(tmp_path, experiment, old, new, message):
    folder = _copy(experiment, tmp_path)
    ssd = folder / "SystemStructure.ssd"
    text = ssd.read_text()
    assert text.count(old) == 1
    ssd.write_text(text.replace(old, new))
    res = _railfmu("run", str(folder), "--out", str(tmp_path / "out"))
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("railfmu: error:")]
    assert len(errors) == 1 and message in errors[0], res.stderr


def test_cli_misspelled_setting_in_a_variant_is_one_line_and_exit_2(tmp_path):
    folder = _copy("trolley_survey", tmp_path)
    (folder / "variants" / "typo.ssv").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<ssv:ParameterSet version="1.0" name="typo" '
        'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">\n'
        '  <ssv:Parameters>\n'
        '    <ssv:Parameter name="smoother.nhc_sigam"><ssv:Real value="0.0001"/></ssv:Parameter>\n'
        '  </ssv:Parameters>\n</ssv:ParameterSet>\n')
    res = _railfmu("run", str(folder), "--variant", "typo", "--out", str(tmp_path / "out"))
    assert res.returncode == 2, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("railfmu: error:")]
    assert errors == [f"railfmu: error: {folder}: Observer 'smoother': bad settings: AidedInsSmoother: "
                      "unknown setting 'nhc_sigam' (closest: nhc_sigma)"], res.stderr
