"""Estimator settings as frozen dataclasses (railfmu.estimators.core.settings): coercion of SSD
values, unit conversion, range checks, unknown keys with close matches; and the estimators
that declare theirs that way."""

import dataclasses
import math
from typing import Any

import pytest

from railfmu.estimators.core.settings import Settings, setting
from railfmu.estimators.suspension.stiffness import SuspensionJoint, SuspensionWLS, WLSSettings
from railfmu.estimators.track.alignment import AlignmentKalmanFilter, AlignmentSettings
from railfmu.estimators.train.running_resistance import ImprovedEstimator, PaperUKF


@dataclasses.dataclass(frozen=True)
class Demo(Settings):
    sigma: float = setting(0.1, "m/s2", "noise std", gt=0)
    heading0: float = setting(0.0, "rad", "initial heading", given_in="deg", ge=-math.pi, le=math.pi)
    window: int = setting(10, "samples", "window", ge=1)
    smooth: bool = setting(True, "", "smooth too")
    mode: str = setting("fast", "", "how", choices=("fast", "exact"))
    p0: tuple[float, ...] | None = setting(None, "m", "initial stds", gt=0, length=3)
    extra: Any = setting(None, "", "anything, converted", convert=lambda v: str(v).upper())


def make(**kw):
    return Demo.from_mapping(kw, "Demo")


def test_defaults_coercion_and_unit_conversion():
    assert make() == Demo()
    d = make(sigma="0.5", heading0=90, window=12.0, smooth="false", mode="exact", p0=[1, 2, 3], extra="x")
    assert (d.sigma, d.window, d.smooth, d.mode, d.p0, d.extra) == (0.5, 12, False, "exact", (1.0, 2.0, 3.0), "X")
    assert d.heading0 == pytest.approx(math.pi / 2)  # given in degrees, held in radians
    assert isinstance(d.window, int) and isinstance(d.sigma, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.sigma = 1.0


@pytest.mark.parametrize("kw, message", [
    ({"sigma": 0.0}, "Demo: setting sigma must be > 0 m/s2, not 0.0"),
    ({"sigma": "abc"}, "Demo: setting sigma = 'abc' is not a number"),
    ({"sigma": float("nan")}, "Demo: setting sigma = nan is not a finite number"),
    ({"sigma": True}, "Demo: setting sigma = True is not a number"),
    ({"sigma": None}, "Demo: setting sigma must be given"),
    ({"heading0": 270}, "Demo: setting heading0 must be <= 3.14159 rad"),  # the range in the filter's unit
    ({"window": 2.5}, "Demo: setting window = 2.5 is not an integer"),
    ({"window": 0}, "Demo: setting window must be >= 1 samples, not 0"),
    ({"smooth": "maybe"}, "Demo: setting smooth = 'maybe' must be true or false"),
    ({"mode": "slow"}, "Demo: setting mode must be one of 'fast', 'exact', not 'slow'"),
    ({"p0": [1, 2]}, "Demo: setting p0 = [1, 2] must have 3 values, not 2"),
    ({"p0": [1, -2, 3]}, "Demo: setting p0 must be > 0 m, not (1.0, -2.0, 3.0)"),
    ({"sigmaa": 1.0}, "Demo: unknown setting 'sigmaa' (closest: sigma)"),
    ({"sigmaa": 1.0, "windw": 2}, "Demo: unknown settings 'sigmaa', 'windw' (closest: sigma, window)"),
])
def test_each_check_is_one_line_naming_the_setting(kw, message):
    with pytest.raises(ValueError) as exc:
        make(**kw)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_extra_keys_are_left_to_the_caller_and_describe_lists_units():
    assert Demo.from_mapping({"V": 20.0}, "Demo", extra={"V"}) == Demo()
    assert Demo.describe()[0] == "sigma (m/s2, 0.1): noise std"
    with pytest.raises(ValueError, match="no conversion from 'deg' to 'm'"):
        setting(0.0, "m", given_in="deg")


def test_estimators_hold_their_checked_settings():
    kf = AlignmentKalmanFilter(1e-3, sigma_acc="0.02", steady_state="false", P0=[1e-3] * 7, V=20)
    assert isinstance(kf.config, AlignmentSettings) and kf.config.sigma_acc == 0.02 and kf.steady_state is False
    assert kf.params["V"] == 20.0  # the design model's parameter, beside the filter's settings
    with pytest.raises(ValueError, match=r"AlignmentKalmanFilter: unknown setting 'sigma_ac' \(closest: sigma_acc"):
        AlignmentKalmanFilter(1e-3, sigma_ac=0.01)
    wls = SuspensionWLS(0.01, window="50", sigma={"ddz_c": 0.02}, residual="literal")
    assert isinstance(wls.config, WLSSettings) and wls.window == 50 and wls.sigma[0] == 0.02 and not wls.gradient
    with pytest.raises(ValueError, match="SuspensionWLS: setting window = 1.5 is not an integer"):
        SuspensionWLS(0.01, window=1.5)
    with pytest.raises(ValueError, match="SuspensionJoint: setting q_theta must be >= 0"):
        SuspensionJoint(0.01, q_theta=-1.0)
    with pytest.raises(ValueError, match=r"PaperUKF: unknown setting 'sigma_sped' \(closest: sigma_speed"):
        PaperUKF(10.0, sigma_sped=0.3)
    assert PaperUKF(10.0, line_file="").config.line_file is None  # an SSD's empty value: the shipped line
    assert ImprovedEstimator(10.0, min_coast="60").config.min_coast == 60.0
