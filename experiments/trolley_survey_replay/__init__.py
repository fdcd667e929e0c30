"""The aided trolley survey (Jiang et al. 2017) on a measured imu.csv: ZUPTs from the IMU itself, 30 m chords with predicted sigma, differences against reference positions.

``SystemStructure.ssd``: SignalTable FMUs play ``imu.csv`` (increments, optional odometer),
``start.csv`` (the start state) and, for the study only, ``reference.csv`` (reference
positions, optional 0/1 ``stopped``); the offline observer ``smoother``
(:class:`railfmu.estimators.inertial.aided_ins.AidedInsSmoother`, ``zupt_source="detector"``:
the zero-velocity epochs from :func:`railfmu.estimators.inertial.zupt_detector.detect_stationary`)
runs on the whole record. Variants: ``example`` (default: the shipped files with their
reference and odometer), ``navigation_grade`` (the SSD as it is), ``tactical_grade``,
``mems_grade`` (the smoother's noise model), ``odometer``, ``nhc`` (the NHC with a stated
wheel-rail play), ``nhc_odometer``. Shipped: 85 s of a simulated ``trolley_survey`` run
(``record.py``; ``resources/README.md``).

Outputs: ``chords.csv`` and ``chords.png`` (:mod:`.chords`): per chord point the smoothed
trajectory's alignment and level (mm) and their predicted sigma, with a reference its chords and
the differences (Fig. 14). Metrics: ``predicted_sigma_alignment_mm``, ``predicted_sigma_level_mm``
(RMS over runs of the max |chord error|, from the smoother's joint covariance),
``predicted_peak_sigma_*_mm`` (largest pointwise sigma); with a reference
``chord_alignment_max_error_mm``, ``chord_level_max_error_mm``, ``chord_*_rms_error_mm`` (the
differences); with a reference ``stopped`` column ``detector_misses``, ``detector_false_alarms``,
``detector_missed_stops``, ``detector_false_stops`` (samples and runs; the detector recomputed on
the recorded increments with the smoother's settings), and always ``zupt_epochs``,
``detected_rest_s``. (The smoother's own ``zupt_detector_*`` entries score against no flag: it
reads none.)
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.study_protocol import RunData, Study, observers_md, output, parameter

SMOOTHER = "smoother"
INCREMENTS = tuple(output("imu", f"y_{k}") for k in range(1, 7))
ROLES = {**{f"imu_{k}": r for k, r in enumerate(INCREMENTS, 1)}, "odometer": output("imu", "y_7"),
         "ref_lat": output("reference", "y_1"), "ref_lon": output("reference", "y_2"),
         "ref_height": output("reference", "y_3"), "ref_stopped": output("reference", "boolean_1"),
         "reference_file": parameter("reference", "file"), "stopped_column": parameter("reference", "boolean_column_1"),
         "odometer_column": parameter("imu", "column_7")}
DEG = math.pi / 180.0

_LAST: list = [None, None]  # (key, result): metrics, files and figures of one run share it


def _record(run: RunData) -> dict:
    """The run's arrays on the smoother's samples and its chords (built once per run)."""
    from railfmu.experiments.trolley_survey_replay.chords import local_ned, path_length, replay_chords

    obs = run.observers[SMOOTHER]
    key = (id(run.signals), id(obs))
    if _LAST[0] == key:
        return _LAST[1]
    s, r = run.signals, run.roles
    est = np.column_stack([np.asarray(run.estimates[f"{SMOOTHER}.{k}"]) for k in ("latitude", "longitude", "height")])
    n = est.shape[0]
    stride = max(1, -(-np.asarray(s["time"]).size // n))
    rows = slice(0, stride * n, stride)
    t = np.asarray(s["time"])[rows]
    origin = est[0]
    est_ned = local_ned(*est.T, origin)
    ref_ned = None
    if str(r.get("reference_file") or ""):
        ref = np.column_stack([np.asarray(s[r[k]])[rows] * f for k, f in (("ref_lat", DEG), ("ref_lon", DEG),
                                                                           ("ref_height", 1.0))])
        ref_ned = local_ned(*ref.T, origin)
    # the odometer's distance when imu.csv has one (aiding or not): the design's chainage; else
    # the smoothed path length (a MEMS trajectory's is off by decimetres over 600 m)
    distance = np.asarray(s[r["odometer"]])[rows] if str(r.get("odometer_column") or "") else path_length(est_ned)
    distance = np.maximum.accumulate(distance - distance[0])
    out = {"t": t, "distance": distance, "est": est_ned, "ref": ref_ned, "chords": None, "detector": {}}
    try:
        out["chords"] = replay_chords(t, distance, est_ned, obs, ref_ned, run.base.get("seed") or 0)
    except ValueError:  # shorter than one grid spacing
        pass
    out["detector"] = _detector(run, obs, rows)
    _LAST[:] = [key, out]
    return out


def _detector(run: RunData, obs, rows) -> dict:
    """The smoother's detector recomputed on the recorded increments (its arguments as
    AidedInsSmoother passes them), scored against the reference's stopped column if any."""
    from railfmu.estimators.inertial.zupt_detector import detect_stationary, detector_scores, noise_sigmas

    s, r = run.signals, run.roles
    U = np.column_stack([np.asarray(s[r[f"imu_{k}"]])[rows] for k in range(1, 7)])
    sa, sg = noise_sigmas(dataclasses.asdict(obs.config), obs.dt)
    det = detect_stationary(U, obs.dt, **({"sigma_a": sa, "sigma_g": sg} if min(sa, sg) > 0 else {}))
    out = {"zupt_epochs": int(np.count_nonzero(obs.zupt_epochs)), "detected_rest_s": float(det.sum() * obs.dt)}
    if str(r.get("reference_file") or "") and str(r.get("stopped_column") or ""):
        flag = np.asarray(s[r["ref_stopped"]])[rows] >= 0.5
        sc = detector_scores(det, flag)
        out.update({f"detector_{k}": sc[k] for k in ("samples_at_rest", "samples_moving", "misses", "false_alarms",
                                                     "stops", "missed_stops", "false_stops", "early_samples",
                                                     "late_samples")})
    return out


class TrolleySurveyReplay(Study):
    """The aided survey on a replayed record: chords, their sigma, differences, detector scores."""
    default_variant = "example"
    roles = ROLES
    figures_of_signals: dict = {}
    summary_metrics = ("chord_*_error_mm", "predicted_sigma_*_mm", "detector_*", "wall_time_s")

    def metrics(self, run: RunData) -> dict:
        if SMOOTHER not in run.observers:
            return {}
        rec = _record(run)
        obs = run.observers[SMOOTHER]
        out = {**rec["detector"], "filter_seconds": float(obs.filter_seconds),
               "smoother_seconds": float(obs.smoother_seconds), "surveyed_distance_m": float(rec["distance"][-1])}
        if rec["chords"] is not None:
            out.update(rec["chords"].metrics)
        return out

    def files(self, run: RunData, out: Path) -> list[str]:
        from railfmu.experiments.trolley_survey_replay.chords import write_csv

        rec = _record(run) if SMOOTHER in run.observers else {"chords": None}
        if rec["chords"] is None:
            return []
        write_csv(out / "chords.csv", rec["chords"])
        return ["chords.csv"]

    def figures(self, run: RunData, out: Path) -> list[str]:
        from railfmu.experiments.trolley_survey_replay.chords import figure

        rec = _record(run) if SMOOTHER in run.observers else {"chords": None}
        if rec["chords"] is None:
            return []
        return [figure(out, rec["chords"], f"{run.base.get('variant')}: 30 m chord alignment and level (smoother)")]

    def report_md(self, metrics: dict) -> str:
        m = metrics
        L = ["## Aided survey on the replayed IMU", "",
             f"{m.get('surveyed_distance_m', 0):.1f} m surveyed; {m.get('zupt_epochs', 0)} ZUPT epochs, "
             f"{m.get('detected_rest_s', 0):.1f} s detected at rest.", ""]
        if "chord_points" in m:
            L += [f"{m['chords_surveyed']} chords, {m['chord_points']} points (chords.csv, chords.png).", "",
                  "| | alignment [mm] | level [mm] |", "|---|---|---|",
                  f"| predicted RMS of the max \\|chord error\\| | {m['predicted_sigma_alignment_mm']:.3f} | "
                  f"{m['predicted_sigma_level_mm']:.3f} |",
                  f"| largest pointwise predicted σ | {m['predicted_peak_sigma_alignment_mm']:.3f} | "
                  f"{m['predicted_peak_sigma_level_mm']:.3f} |"]
            if "chord_alignment_max_error_mm" in m:
                L += [f"| max \\|difference to the reference\\| | {m['chord_alignment_max_error_mm']:.3f} | "
                      f"{m['chord_level_max_error_mm']:.3f} |",
                      f"| RMS difference to the reference | {m['chord_alignment_rms_error_mm']:.3f} | "
                      f"{m['chord_level_rms_error_mm']:.3f} |"]
            L.append("")
        if "detector_misses" in m:
            L += [f"Detector against the reference's stopped flag: {m['detector_misses']} of "
                  f"{m['detector_samples_at_rest']} samples at rest missed, {m['detector_false_alarms']} of "
                  f"{m['detector_samples_moving']} moving taken for rest; {m['detector_missed_stops']} of "
                  f"{m['detector_stops']} stops missed, {m['detector_false_stops']} false stops.", ""]
        return "\n".join(L + [observers_md(metrics)])


STUDY = TrolleySurveyReplay(__doc__.strip().splitlines()[0])
