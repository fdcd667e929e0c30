"""The trolley survey's strapdown INS offline on a recorded imu.csv, started from and scored against truth.csv.

``SystemStructure.ssd``: a SignalTable FMU plays ``imu.csv`` (the standard form of
``trolley_survey``: ``time_s, dtheta_x, dtheta_y, dtheta_z, dv_x, dv_y, dv_z``) into the
free-inertial strapdown INS (:class:`railfmu.estimators.inertial.ins_observer.StrapdownINS`); a second one plays
``truth.csv``, whose first row is the INS's initial state (settings bound to its channels)
and against which it is scored, with the metrics and figures of ``trolley_survey``. The IMU
table's end ends the run. Shipped: the first 15 s of an ideal-IMU ``trolley_survey`` run
(``record.py``). Your data: ``--set imu.file=/path/imu.csv --set truth.file=/path/truth.csv``
and ``--step-size`` at your IMU interval (the SSD's comment says more). Variants:
``recorded`` (the SSD as it is) and ``paper_initial_errors`` (the INS started with the
0.006 deg tilt and 0.06 deg heading errors of Jiang et al. (2017)).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.replay import imu_increments
from railfmu.experiments.engine.study_protocol import RunData, Study, _num, observers_md, output
from railfmu.experiments.trolley_survey import (
    ERRORS,
    NAV,
    UNITS,
    error_metrics,
    ins_error_figure,
    metric_name,
    navigation_errors,
)

DEG = math.pi / 180
#: truth.csv's channels on the truth table: (column, NAV name or None, factor to rad/m/(m/s))
TRUTH = (("lat_deg", "latitude", DEG), ("lon_deg", "longitude", DEG), ("height_m", "height", 1.0),
         ("vn", "vn", 1.0), ("ve", "ve", 1.0), ("vd", "vd", 1.0), ("roll_deg", "roll", DEG),
         ("pitch_deg", "pitch", DEG), ("heading_deg", "heading", DEG), ("distance_m", None, 1.0))

ROLES = {**{f"truth_{c}": output("truth", f"y_{k}") for k, (c, _, _) in enumerate(TRUTH, 1)},
         "truth_stopped": output("truth", "boolean_1")}


def _arrays(run: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, INS estimates (n, 9) and the replayed truth (n, 9) in rad, m, m/s."""
    t = np.asarray(run.estimates["time"])
    n = len(t)
    est = np.column_stack([np.asarray(run.estimates[f"ins.{k}"])[:n] for k in NAV])
    true = np.column_stack([np.asarray(run.signals[run.roles[f"truth_{c}"]])[:n] * f
                            for c, name, f in TRUTH if name])
    return t, est, true


class TrolleyImuReplay(Study):
    """The INS on a replayed imu.csv, scored as ``trolley_survey`` scores it."""
    default_variant = "recorded"
    roles = ROLES
    figures_of_signals = {"imu.png": ("Replayed IMU increments (body x, y, z)",
                                      [[(f"imu.y_{k}", f"angle increment {a}") for k, a in enumerate("xyz", 1)],
                                       [(f"imu.y_{k}", f"velocity increment {a}") for k, a in enumerate("xyz", 4)]])}
    #: the INS's outputs on its estimates figure, in the units a survey reads
    quantities = {"latitude": "latitude [deg]", "longitude": "longitude [deg]", "height": "height",
                  "vn": "velocity north", "ve": "velocity east", "vd": "velocity down", "roll": "roll [deg]",
                  "pitch": "pitch [deg]", "heading": "heading [deg]"}
    summary_metrics = tuple(metric_name(k, s) for k in ERRORS for s in ("", "_30s", "_60s")) + ("wall_time_s",)
    #: imu.csv's velocity increments must fit the step (|dv| ~ g x step): a 100 Hz file at 5 ms counts each twice
    replay_checks = (imu_increments("imu", ("y_4", "y_5", "y_6")),)

    def metrics(self, run: RunData) -> dict:
        t, est, true = _arrays(run)
        stopped = np.asarray(run.signals[run.roles["truth_stopped"]])[:len(t)]
        moving = np.flatnonzero(stopped == 0)
        start = float(t[moving[0] - 1]) if moving.size and moving[0] > 0 else float(t[0])
        out = error_metrics(t, navigation_errors(est, true), start)
        if "truth" in (run.base.get("replay") or {}).get("unscored", []):  # a start point is no truth: no score
            out = {k: (v if k == "motion_start_s" else None) for k, v in out.items()}
        return out

    def figures(self, run: RunData, out: Path) -> list[str]:
        if "truth" in (run.base.get("replay") or {}).get("unscored", []):
            return []  # errors against a start point are no errors
        t, est, true = _arrays(run)
        return [ins_error_figure(out, "Free-inertial INS errors on the replayed IMU (INS minus truth)", t, est, true)]

    def report_md(self, metrics: dict) -> str:
        L = ["## Free-inertial INS on the replayed IMU, against truth.csv", "",
             f"Motion starts at {metrics['motion_start_s']:g} s.", "",
             "| error | whole record | up to 30 s | up to 60 s | final |", "|---|---|---|---|---|"]
        for kind in ERRORS:
            L.append(f"| {kind} [{UNITS[kind].replace('_', '/')}] | {_num(metrics[metric_name(kind)], '.4g')} | "
                     f"{_num(metrics[metric_name(kind, '_30s')], '.4g')} | {_num(metrics[metric_name(kind, '_60s')], '.4g')} | "
                     f"{_num(metrics[f'ins_{kind}_error_final_{UNITS[kind]}'], '.4g')} |")
        return "\n".join(L + ["", observers_md(metrics)])


STUDY = TrolleyImuReplay(__doc__.strip().splitlines()[0])
