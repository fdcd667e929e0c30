"""Writes ``variants/*.ssv`` of the trolley survey: ``python -m railfmu.experiments.trolley_survey.variants``.

Every variant carries one whole IMU grade (the ``ImuErrors`` parameters of
``parameters/imu_<grade>.ssv``, each as ``imu.<parameter>``; the smoother's noise model follows
them through its settings bound to ``imu.*``) and, for the aided surveys, what the aiding
changes in the trolley, the observers and the run:

* the grade variants (``ideal_imu``, ``navigation_grade``, ``tactical_grade``, ``mems_grade``):
  the 600 m survey as the SSD has it, free-inertial INS and ZUPT-aided smoother;
* ``paper_montecarlo``: Jiang et al. (2017), §5's simulation: 30 m straight at N45°E
  (``trolley_straight_30m.csv``), no irregularities, 1 m/s after a 0.1 s rest, one stop at the
  end, the run ends 1 s after it (``experiment.stopTime`` = 0.1 + 30.4 + 1 = 31.5 s); one ZUPT
  per stop (at the epoch next to the motion), the initial velocity sigma the ZUPT's; navigation
  grade with the paper's "piecewise constant" biases (§2: a turn-on bias per run of 0.01 deg/h
  and 50 ug, no in-run drift); the INS off. The paper's trolley is at 1 m/s from the first to
  the last epoch, its velocity observed while moving; here a velocity observation is a ZUPT,
  which needs the trolley at rest, so it starts and stops with short ramps (``trolley.acceleration``
  5 m/s2: 0.4 s and 0.2 m each, the 30 s of the paper's run become 30.4 s) and the initial rest
  is short (the chord's first point is the record's first sample, 0.1 s before the ZUPT). With
  them the largest pointwise sigma of the chord errors (exact, from the smoother's joint
  covariance) is within a few percent of the covariance analysis of the paper's constant-speed
  run (``railfmu.estimators.inertial.chord_accuracy.nominal_chord_accuracy``; the ratio is
  asserted in ``tests/test_trolley_survey.py``); with the Trolley's default ramps (0.5 m/s2:
  4 s and 2 m) and a 1 s rest it is clearly larger, and the steeper the ramps the closer it
  comes. The ramps lie inside the 30 m: the chord grid still has all 51 points, 0 to 25 m;
* the aided 600 m surveys, navigation grade unless the name ends in ``_tactical`` or
  ``_mems``: ``zupt_60m`` (ZUPT at the stops every 60 m), ``zupt_nhc`` (+ non-holonomic
  constraint), ``zupt_odometer`` (+ odometer), ``zupt_nhc_odometer`` (+ both), ``landmarks``
  (+ a position fix, 0.1 m, at every stop); all with the trolley wobbling off the rail (1 mm
  lateral, 0.5 mm vertical, 2 m wavelength: a body velocity of up to 3.1 and 1.6 mm/s across
  the rail at 1 m/s, rms 2.2 and 1.1 mm/s) and an odometer scale-factor error of 100 ppm (not
  a state of the filter: 0.1 mm/s at 1 m/s, under its 1 mm/s sigma); the INS off. With the NHC
  or the odometer the smoother runs the 15-state error model (``full15``: they observe the
  tilts, so the horizontal accelerometer biases can no longer hide in them, and the 12-state
  model becomes overconfident in height; ``railfmu.estimators.inertial.aided_ins``). The NHC knows the wobble
  as the wheel-rail play (``play_model="shaping"``, ``railfmu.estimators.inertial.rail_play``): four states,
  the body's lateral and vertical offset from the rail and their slopes, stationary sigmas the
  wobble's rms (a sinusoid of amplitude ``a``: ``a / sqrt(2)``, 0.71 and 0.35 mm), wavelength
  the trolley's ``wobble_wavelength`` (the SSD binds ``play_wavelength`` to it), damping 0.1
  (the wobble is one sinusoid, a line spectrum: a narrowband oscillator fits it; the default
  ``1/sqrt(2)`` spreads the play over all wavelengths above 2 m and leaves the NHC less to
  say: larger max chord errors of ``zupt_nhc_odometer``), the NHC's sigma 0.1 mm/s (what the
  play model leaves out). The white NHC that covers the wobble (3 mm/s) does worse than
  either. The chord errors are measured by ``railfmu study trolley_survey --variant
  zupt_nhc_odometer`` (docs/studies/trolley_survey.md).

``tests/test_trolley_survey.py`` checks that the files are what this writes.
"""

from __future__ import annotations

import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
GRADES = {  # variant suffix -> (parameters/imu_<file>.ssv, what it is)
    "navigation": ("navigation_grade", "the navigation grade of Jiang et al. (2017), §3 (0.01 °/h, 0.005 °/√h, "
                                       "50 µg, 10 µg/√Hz)"),
    "tactical": ("tactical_grade", "a tactical grade (HG1700 class; sources in parameters/imu_tactical_grade.ssv)"),
    "mems": ("mems_grade", "a MEMS grade (OpenIMU300ZA class; sources in parameters/imu_mems_grade.ssv)"),
    "ideal": ("ideal", "the ideal IMU (no errors: the numerical floor)"),
}
GRADE_VARIANTS = {"ideal_imu": "ideal", "navigation_grade": "navigation", "tactical_grade": "tactical",
                  "mems_grade": "mems"}

#: the aided 600 m surveys: what every one of them changes, then each aiding's own settings
AIDED_SURVEY = {"ins.enabled": False, "trolley.wobble_lateral": 0.001, "trolley.wobble_vertical": 0.0005,
                "trolley.wobble_wavelength": 2.0, "trolley.odometer_scale_ppm": 100.0}
#: the NHC with the play as shaping-filter states (railfmu.estimators.inertial.rail_play; module docstring)
NHC = {"smoother.nhc": True, "smoother.play_model": "shaping",
       "smoother.play_sigma_lateral": AIDED_SURVEY["trolley.wobble_lateral"] / math.sqrt(2.0),
       "smoother.play_sigma_vertical": AIDED_SURVEY["trolley.wobble_vertical"] / math.sqrt(2.0),
       "smoother.play_damping": 0.1, "smoother.nhc_sigma": 1e-4}
AIDINGS = {
    "zupt_60m": ("ZUPT at the stops every 60 m", {}),
    "zupt_nhc": ("ZUPT + non-holonomic constraint", {**NHC, "smoother.error_model": "full15"}),
    "zupt_odometer": ("ZUPT + odometer", {"smoother.odometer": True, "smoother.error_model": "full15"}),
    "zupt_nhc_odometer": ("ZUPT + non-holonomic constraint + odometer",
                          {**NHC, "smoother.odometer": True, "smoother.error_model": "full15"}),
    "landmarks": ("ZUPT + a landmark position fix (0.1 m) at every stop", {"smoother.landmarks": True}),
}
PAPER_MONTECARLO = {
    # the paper's biases are "piecewise constant" (§2): a constant per run (turn-on) of the grade's
    # 0.01 deg/h and 50 ug, no in-run Gauss-Markov drift
    "imu.gyro_bias_instability_deg_h": 0.0, "imu.gyro_turn_on_bias_sigma_deg_h": 0.01,
    "imu.accel_bias_instability_ug": 0.0, "imu.accel_turn_on_bias_sigma_ug": 50.0,
    "trolley.track_file": "trolley_straight_30m.csv", "trolley.irregularity_level": 0,
    # short ramps and rest: the paper's constant 1 m/s between the two velocity updates (docstring)
    "trolley.acceleration": 5.0, "trolley.static_duration": 0.1, "trolley.stop_spacing": 30.0,
    "experiment.stopTime": 31.5,
    "ins.enabled": False, "smoother.zupt_interval": "inf", "smoother.velocity_sigma": 0.0001,
}


def grade_parameters(grade: str) -> list[tuple[str, str, str, str | None]]:
    """``(name, ssv type, value, unit)`` of ``parameters/imu_<grade>.ssv``, in file order."""
    root = ET.parse(HERE / "parameters" / f"imu_{GRADES[grade][0]}.ssv").getroot()
    out = []
    for p in root.iterfind(f"{{{SSV}}}Parameters/{{{SSV}}}Parameter"):
        typed = p[0]
        out.append((p.get("name"), typed.tag.split("}")[1], typed.get("value"), typed.get("unit")))
    return out


def _typed(value) -> tuple[str, str]:
    if isinstance(value, bool):
        return "Boolean", str(value).lower()
    if isinstance(value, int):
        return "Integer", str(value)
    if isinstance(value, float):
        return "Real", repr(value)
    return "String", str(value)


def variant_text(name: str, grade: str, extra: dict, what: str) -> str:
    """The ``.ssv`` of one variant: the grade's parameters as ``imu.*`` (an ``imu.*`` of ``extra``
    replaces the grade's value in place), then the rest of ``extra``."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f"<!-- {what}, with {GRADES[grade][1]}.",
             f"     Written by experiments/trolley_survey/variants.py (the ImuErrors parameters of "
             f"parameters/imu_{GRADES[grade][0]}.ssv",
             "     as imu.<parameter>, then the variant's own; tests/test_trolley_survey.py checks them). -->",
             f'<ssv:ParameterSet version="1.0" name="{name}" xmlns:ssv="{SSV}">', "  <ssv:Parameters>"]
    has_unit = False
    extra = dict(extra)
    for pname, kind, value, unit in grade_parameters(grade):
        if f"imu.{pname}" in extra:
            kind, value = _typed(extra.pop(f"imu.{pname}"))
        u = f' unit="{unit}"' if unit else ""
        has_unit |= bool(unit)
        lines.append(f'    <ssv:Parameter name="imu.{pname}"><ssv:{kind} value="{value}"{u}/></ssv:Parameter>')
    for pname, value in extra.items():
        kind, text = _typed(value)
        lines.append(f'    <ssv:Parameter name="{pname}"><ssv:{kind} value="{text}"/></ssv:Parameter>')
    lines.append("  </ssv:Parameters>")
    if has_unit:
        lines += ["  <ssv:Units>", '    <ssc:Unit name="s" xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">'
                  '<ssc:BaseUnit s="1"/></ssc:Unit>', "  </ssv:Units>"]
    lines.append("</ssv:ParameterSet>")
    return "\n".join(lines) + "\n"


def variants() -> dict[str, str]:
    """``{variant: .ssv text}`` of every variant (module docstring)."""
    out = {}
    for name, grade in GRADE_VARIANTS.items():
        out[name] = variant_text(name, grade, {}, "The 600 m survey (free-inertial INS and ZUPT-aided smoother)")
    out["paper_montecarlo"] = variant_text(
        "paper_montecarlo", "navigation", PAPER_MONTECARLO,
        "Jiang et al. (2017), §5's Monte Carlo run: 30 m straight at N45°E, 1 m/s, ZUPT at both ends")
    for aiding, (what, settings) in AIDINGS.items():
        for suffix in ("navigation", "tactical", "mems"):
            name = aiding if suffix == "navigation" else f"{aiding}_{suffix}"
            out[name] = variant_text(name, suffix, {**AIDED_SURVEY, **settings},
                                     f"The 600 m survey, {what}")
    return out


def main(folder: Path = HERE / "variants") -> list[Path]:
    folder.mkdir(exist_ok=True)
    written = []
    for name, text in variants().items():
        path = folder / f"{name}.ssv"
        path.write_text(text)
        written.append(path)
    return written


if __name__ == "__main__":
    for p in main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "variants"):
        print(p)
