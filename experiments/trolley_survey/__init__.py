"""Trolley survey (Jiang et al. 2017): a pushed trolley's IMU through an IMU grade into a free-inertial INS and a ZUPT-aided smoother.

The system is ``SystemStructure.ssd``: the ``Trolley`` FMU is pushed along 600 m of curved,
graded track with ERRI B176 alignment and level irregularities, stopping every 60 m, and
gives the ideal IMU increments over each 5 ms step (200 Hz) and its true navigation state;
the ``ImuErrors`` FMU adds the errors of one IMU grade; the observer ``ins``
(:class:`railfmu.estimators.inertial.ins_observer.StrapdownINS`) integrates the measured increments from the
trolley's state at the first sample (its settings are bound to the trolley's outputs) and is
scored against the trolley's state. The offline observer ``smoother``
(:class:`railfmu.estimators.inertial.aided_ins.AidedInsSmoother`: error-state Kalman filter with feedback and
RTS smoother) runs on the whole record after the run with ZUPTs from the trolley's
``stopped`` flag (optionally NHC, odometer, landmark fixes), its initial attitude and
velocity errors drawn per run (SensorNoise ``initial_errors``: 0.006°, 0.006°, 0.06°, 1e-4
m/s; the initial position error is not drawn, a common offset does not change a chord), its
noise model the selected grade (settings bound to ``imu.*``). Its accuracy on 30 m chords is
:mod:`railfmu.experiments.trolley_survey.survey_accuracy`.

Variants (written by :mod:`railfmu.experiments.trolley_survey.variants`): ``ideal_imu`` (the numerical
floor: the data and the INS are exact to < 0.01 mm and 1e-6 rad), ``navigation_grade`` (the
paper's IMU), ``tactical_grade``, ``mems_grade``; ``paper_montecarlo`` (the paper's 30 m
simulation; ``railfmu study trolley_survey --variant paper_montecarlo --runs 500``);
``zupt_60m``, ``zupt_nhc``, ``zupt_odometer``, ``zupt_nhc_odometer``, ``landmarks``, each also
``_tactical`` and ``_mems``. The experiment runs on the container master unless ``--master``
says otherwise (its SSD's ``rf:FixedStep master``).

Every run writes, besides ``signals.csv``, the two standard files (documented here, read by
:func:`railfmu.estimators.inertial.ins_observer.read_imu_csv` and by the ``trolley_imu_replay`` experiment):

* ``imu.csv``: ``time_s, dtheta_x, dtheta_y, dtheta_z`` (rad), ``dv_x, dv_y, dv_z`` (m/s):
  the *measured* increments (the ImuErrors outputs), body forward-right-down, each over the
  interval that ends at ``time_s``; the first row (the initial time) carries zeros;
* ``truth.csv``: ``time_s, lat_deg, lon_deg, height_m`` (WGS-84 ellipsoidal), ``vn, ve, vd``
  (m/s), ``roll_deg, pitch_deg, heading_deg`` (body to local NED, ZYX), ``distance_m`` (along
  the design track), ``stopped`` (0/1).

Floats are written with ``repr`` (they read back to the same double).

Metrics (``metrics.json``): with the smoother, those of
:mod:`railfmu.experiments.trolley_survey.survey_accuracy` (``chord_alignment_max_error_mm``,
``chord_level_max_error_mm``, ``chord_alignment_rms_error_mm``, ``chord_level_rms_error_mm``,
``predicted_sigma_alignment_mm``, ``predicted_sigma_level_mm``, ``filter_seconds``,
``smoother_seconds``); over a Monte Carlo (``--runs N``) the study's summary adds the peak RMS
over runs of the chord errors, ``chord_alignment_peak_rms_error_mm`` and
``chord_level_peak_rms_error_mm`` (the paper's Fig. 12 statistic; ``survey_accuracy``). With
the INS (not switched off by ``ins.enabled=false``), the INS against the trolley over the run:
``ins_position_error_max_mm`` (the largest 3-D position error), ``ins_velocity_error_max_mm_s`` (the largest 3-D velocity
error), ``ins_attitude_error_max_deg`` (the largest rotation angle between the INS's and the
true attitude), each also as the largest up to 30 s and 60 s after the start of motion
(``..._30s``, ``..._60s``: the first free-inertial spans between stops), plus
``motion_start_s`` and the final errors ``ins_position_error_final_mm`` etc.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.study_protocol import (
    RunData,
    Study,
    observers_md,
    output,
    parameter,
)
from railfmu.models.errors import UserError

NAV = ("latitude", "longitude", "height", "vn", "ve", "vd", "roll", "pitch", "heading")
INCREMENTS = ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")
TRUTH_COLUMNS = ("time_s", "lat_deg", "lon_deg", "height_m", "vn", "ve", "vd", "roll_deg", "pitch_deg",
                 "heading_deg", "distance_m", "stopped")
AFTER_MOTION = (30.0, 60.0)  # s after the start of motion (Jiang et al. (2017): free-inertial spans)
ERRORS = ("position", "velocity", "attitude")
UNITS = {"position": "mm", "velocity": "mm_s", "attitude": "deg"}

# the trolley's track parameters the irregularity figure needs (models/track/geometry.py)
GEOMETRY = ("track_file", "start_latitude", "start_longitude", "start_height", "azimuth", "irregularity_level",
            "irregularity_scale", "irregularity_lines", "lambda_min", "lambda_max", "irregularity_seed",
            "harmonic_lateral_amplitude", "harmonic_vertical_amplitude", "harmonic_wavelength",
            "irregularity_file", "wobble_lateral", "wobble_vertical", "wobble_wavelength")

ROLES = {
    **{f"true_{k}": output("trolley", k) for k in (*NAV, "north", "east", "down", "distance", "speed_along",
                                                    "stopped")},
    **{f"measured_{k}": output("imu", k) for k in INCREMENTS},
    **{f"track_{k}": parameter("trolley", k) for k in GEOMETRY},
}


def metric_name(kind: str, suffix: str = "") -> str:
    """``ins_position_error_max_mm``, ``ins_velocity_error_max_mm_s_30s``, ..."""
    return f"ins_{kind}_error_max_{UNITS[kind]}{suffix}"


def position_errors(est: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Estimate minus truth of rows of :data:`NAV` (or of latitude, longitude, height): (n, 3)
    NED in m, the latitude and longitude differences times the local radii plus height."""
    from railfmu.estimators.inertial.ins_error_model import ned_difference

    return ned_difference(est[:, 0], est[:, 1], est[:, 2], true[:, 0], true[:, 1], true[:, 2])


def navigation_errors(est: np.ndarray, true: np.ndarray) -> dict[str, np.ndarray]:
    """INS minus truth, rows of :data:`NAV` (rad, m, m/s): ``position`` (n, 3) NED in m (the
    latitude and longitude differences times the local radii plus height), ``velocity``
    (n, 3) NED in m/s, ``attitude`` (n, 3) in rad: the NED rotation vector ``e`` with
    ``C_est = exp([e x]) C_true`` (``railfmu.estimators.inertial.attitude.perturb``'s convention)."""
    from scipy.spatial.transform import Rotation

    from railfmu.estimators.inertial.attitude import dcm_from_rph

    position = position_errors(est, true)
    C = dcm_from_rph(*est[:, 6:9].T) @ np.swapaxes(dcm_from_rph(*true[:, 6:9].T), 1, 2)
    return {"position": position, "velocity": est[:, 3:6] - true[:, 3:6],
            "attitude": Rotation.from_matrix(C).as_rotvec()}


def error_metrics(t: np.ndarray, errors: dict[str, np.ndarray], motion_start: float) -> dict:
    """The metrics of the module docstring from :func:`navigation_errors` at times ``t``."""
    scale = {"position": 1e3, "velocity": 1e3, "attitude": 180.0 / math.pi}
    out: dict = {"motion_start_s": motion_start}
    for kind in ERRORS:
        norm = np.linalg.norm(errors[kind], axis=1) * scale[kind]
        out[metric_name(kind)] = float(norm.max())
        for after in AFTER_MOTION:
            upto = t <= motion_start + after + 1e-9
            out[metric_name(kind, f"_{after:g}s")] = float(norm[upto].max())
        out[f"ins_{kind}_error_final_{UNITS[kind]}"] = float(norm[-1])
    return out



def ins_error_figure(out: Path, title: str, t: np.ndarray, est: np.ndarray, true: np.ndarray) -> str:
    """``ins_errors.png``: position and velocity errors (N, E, D) and attitude errors (tilt N,
    tilt E, heading) of the INS against the truth over time."""
    from railfmu.experiments.engine.plots import figure

    e = navigation_errors(est, true)
    axes = [[(f"position {c}", 1e3 * e["position"][:, j], "mm") for j, c in enumerate("NED")],
            [(f"velocity {c}", 1e3 * e["velocity"][:, j], "mm/s") for j, c in enumerate("NED")],
            [(f"attitude {c}", np.degrees(e["attitude"][:, j]), "deg") for j, c in
             enumerate(("tilt N", "tilt E", "heading"))]]
    return figure(out, "ins_errors.png", title, t, "time [s]", axes)

def _arrays(run: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, INS estimates (n, 9) and truth (n, 9) on the INS's rows."""
    t = np.asarray(run.estimates["time"])
    n = len(t)
    est = np.column_stack([np.asarray(run.estimates[f"ins.{k}"])[:n] for k in NAV])
    true = np.column_stack([np.asarray(run.signals[run.roles[f"true_{k}"]])[:n] for k in NAV])
    return t, est, true


def _motion_start(run: RunData) -> float:
    stopped = np.asarray(run.signals[run.roles["true_stopped"]])
    moving = np.flatnonzero(stopped == 0)
    t = np.asarray(run.signals["time"])
    return float(t[moving[0] - 1]) if moving.size and moving[0] > 0 else float(t[0])


def write_standard_files(run: RunData, out: Path) -> list[str]:
    """``imu.csv`` and ``truth.csv`` (module docstring) of a run."""
    from railfmu.experiments.engine.recorder import CsvRecorder

    s, r = run.signals, run.roles
    t = np.asarray(s["time"])
    imu = np.column_stack([t, *(np.asarray(s[r[f"measured_{k}"]]) for k in INCREMENTS)])
    deg = 180.0 / math.pi
    truth = np.column_stack([t, *(np.asarray(s[r[f"true_{k}"]]) * f for k, f in
                                  (("latitude", deg), ("longitude", deg), ("height", 1.0), ("vn", 1.0),
                                   ("ve", 1.0), ("vd", 1.0), ("roll", deg), ("pitch", deg), ("heading", deg),
                                   ("distance", 1.0))),
                             np.asarray(s[r["true_stopped"]])])
    for name, columns, data, types in (("imu.csv", ("time_s", *INCREMENTS), imu, None),
                                       ("truth.csv", TRUTH_COLUMNS, truth, ["Real"] * 11 + ["Boolean"])):
        rec = CsvRecorder(out / name, types=dict(zip(columns, types)) if types else None)
        rec.open(list(columns))
        rec.write_block(data)
        rec.close(True)
    return ["imu.csv", "truth.csv"]


def track_geometry(roles: dict):
    """The run's track (:class:`railfmu.models.track.geometry.TrackGeometry`) from the trolley's
    parameters as the SSP binds them; the shipped table when ``track_file`` is the FMU's
    resource."""
    from railfmu.models.track.geometry import DEFAULT_TRACK, TrackGeometry

    params = {k: roles[f"track_{k}"] for k in GEOMETRY if k != "track_file"}
    name = str(roles["track_track_file"])
    table = Path(name) if Path(name).is_absolute() else DEFAULT_TRACK.parent / name
    return TrackGeometry(params, table, DEFAULT_TRACK.parent)


def _has_ins(run: RunData) -> bool:
    return "ins.latitude" in run.estimates


_LAST_SURVEY: list = [None, None]  # (key, SurveyRun) of the last run: metrics, series, figures share it


def _survey(run: RunData):
    """The run's chord accuracy (:class:`survey_accuracy.SurveyRun`), None without the smoother;
    built once per run (the runner hands metrics, series and figures the same signals and
    observer objects in fresh RunData)."""
    from railfmu.experiments.trolley_survey.survey_accuracy import SMOOTHER, SurveyRun

    obs = run.observers.get(SMOOTHER)
    if obs is None:
        return None
    key = (id(run.signals), id(obs))
    if _LAST_SURVEY[0] != key:
        _LAST_SURVEY[:] = [key, SurveyRun(run, position_errors)]
    return _LAST_SURVEY[1]


class TrolleySurvey(Study):
    """The trolley survey: INS errors per IMU grade, the aided smoother's chord accuracy, and
    the standard files."""
    default_variant = "ideal_imu"
    roles = ROLES
    figures_of_signals: dict = {}  # not every recorded signal over 140,000 rows: the figures below
    summary_metrics = (("chord_*_error_mm", "predicted_sigma_*_mm", "filter_seconds", "smoother_seconds")
                       + tuple(metric_name(k, s) for k in ERRORS for s in ("", "_30s", "_60s"))
                       + ("wall_time_s", "timing_s.*", "observers.smoother.wall_time_s"))

    def metrics(self, run: RunData) -> dict:
        out: dict = {}
        sr = _survey(run)
        if sr is not None:
            out.update(sr.metrics())
        if _has_ins(run):
            t, est, true = _arrays(run)
            out.update(error_metrics(t, navigation_errors(est, true), _motion_start(run)))
        return out

    def series(self, run: RunData) -> dict[str, np.ndarray]:
        sr = _survey(run)
        return sr.series() if sr is not None else {}

    def summary_md(self, summary: dict[str, dict], runs: int) -> str:
        """The two Monte Carlo statistics beside their predictions and the paper
        (:func:`survey_accuracy.montecarlo_rows`; the pooled peak RMS is in the summary since
        :meth:`study_tables` ran first), the aiding table, then the statistics of every metric."""
        from railfmu.experiments.trolley_survey.survey_accuracy import aiding_rows, montecarlo_rows

        L = montecarlo_rows(summary)
        values = {v: (st["chord_alignment_max_error_mm"]["rms"], st["chord_level_max_error_mm"]["rms"])
                  for v, st in summary.items() if "chord_alignment_max_error_mm" in st}
        aid = aiding_rows(values, f"RMS over {runs} runs of the max |chord error| per run")
        per_run = {v: {k: x for k, x in st.items() if isinstance(x, dict)} for v, st in summary.items()}
        return "\n".join([*L, "", *aid, "", super().summary_md(per_run, runs)]).strip()

    def study_tables(self, table: dict, series: dict) -> str:
        """Per variant the pooled peak RMS over runs of the chord errors
        (:func:`survey_accuracy.pooled_peak_rms`: into its ``summary``, plain numbers beside the
        statistics over runs; a refusal to pool runs of different chord points goes there as
        ``chord_peak_rms_refused`` and into table.md) and the repeatability (Table 1)."""
        from railfmu.experiments.trolley_survey.survey_accuracy import (
            pooled_peak_rms,
            repeatability,
            repeatability_rows,
        )

        L = []
        for v, runs in series.items():
            try:
                table[v]["summary"].update(pooled_peak_rms(runs))
            except ValueError as exc:
                table[v]["summary"]["chord_peak_rms_refused"] = str(exc)
                L += [f"`{v}`: no peak RMS: {exc}.", ""]
            rows = repeatability(runs)
            if rows:
                table[v]["repeatability"] = rows  # into table.json too
                L += repeatability_rows(v, rows)
        return "\n".join(L).strip()

    def study_figures(self, table: dict, series: dict, out: Path) -> list[str]:
        """``max_error_histograms.png`` (Fig. 12) and, per variant with chords, the first chord's
        estimates over the runs (``repeatability_<variant>.png``, Fig. 15)."""
        from railfmu.experiments.trolley_survey.survey_accuracy import (
            histogram_figure,
            repeatability_figure,
        )

        files = [f for f in [histogram_figure(out, table)] if f]
        for v, runs in series.items():
            first = next(iter(table[v]["runs"].values()), {})
            truth = None
            try:
                from railfmu.models.track.geometry import chord_irregularity
                track = track_geometry(first.get("roles", {}))
                s = np.arange(0.0, 25.0 + 1e-9, 0.5)
                truth = (s, *chord_irregularity(track.rail_positions, track.design_positions, s, 0.0))
            except (KeyError, UserError, ValueError, OSError):  # the figure shows the errors alone
                truth = None
            f = repeatability_figure(out, v, runs, truth)
            if f:
                files.append(f)
        return files

    def files(self, run: RunData, out: Path) -> list[str]:
        return write_standard_files(run, out)

    def figures(self, run: RunData, out: Path) -> list[str]:
        """``track.png`` (plan, profile, irregularities), ``speed.png`` (speed and stops),
        ``ins_errors.png`` (position N/E/D, velocity, attitude over time) with the INS; with
        the smoother ``chord_irregularity.png`` (Figs. 12/14), ``trajectory_3d.png`` (Fig. 14c),
        ``smoother_errors.png``, and for ``paper_montecarlo`` the sensitivity curves (Figs. 8-11)."""
        files = self._track_figures(run, out)
        if _has_ins(run):
            t, est, true = _arrays(run)
            files.append(ins_error_figure(out, "Free-inertial INS errors (INS minus truth)", t, est, true))
        sr = _survey(run)
        if sr is not None:
            from railfmu.experiments.engine.plots import figure

            from railfmu.experiments.trolley_survey.survey_accuracy import (
                irregularity_figure,
                sensitivity_figures,
                trajectory_figure,
            )

            files.append(figure(out, "smoother_errors.png", "Smoothed position error and its predicted sigma",
                                sr.t, "time [s]",
                                [[(f"error {c}", 1e3 * sr.error[:, j], "mm"),
                                  (f"+σ {c}", 1e3 * sr.sigma[:, j], "mm", {"ls": "--", "lw": 0.7}),
                                  (f"-σ {c}", -1e3 * sr.sigma[:, j], "mm", {"ls": "--", "lw": 0.7})]
                                 for j, c in enumerate("NED")]))
            files.append(trajectory_figure(out, sr))
            if sr.grid is not None:
                try:
                    track = track_geometry(run.roles)
                    files.append(irregularity_figure(out, sr, track, f"{run.base['variant']}: 30 m chord "
                                                     "irregularity, estimated and true"))
                except (UserError, ValueError, OSError):
                    pass  # a track table the twin cannot read: no truth to draw
            if run.base.get("variant") == "paper_montecarlo":
                files += sensitivity_figures(out)
        return files

    def _track_figures(self, run: RunData, out: Path) -> list[str]:
        from railfmu.experiments.engine.plots import _pyplot, figure

        s, r = run.signals, run.roles
        ts = np.asarray(s["time"])
        files = []
        plt = _pyplot()
        fig, ax = plt.subplots(3, 1, figsize=(9.0, 9.0))
        north, east, down = (np.asarray(s[r[f"true_{k}"]]) for k in ("north", "east", "down"))
        dist = np.asarray(s[r["true_distance"]])
        ax[0].plot(east, north, lw=1.0)
        ax[0].set_aspect("equal", adjustable="datalim")
        ax[0].set(xlabel="east [m]", ylabel="north [m]", title="Track: plan (from the start point, frame n0)")
        ax[1].plot(dist, -down, lw=1.0)
        ax[1].set(xlabel="distance along the track [m]", ylabel="height above the start [m]", title="Profile")
        try:
            track = track_geometry(r)
            grid = np.linspace(0.0, track.length, 3001)
            yz = np.array([track.offsets(float(x))[::3] for x in grid])
            ax[2].plot(grid, 1e3 * yz[:, 0], lw=0.8, label="alignment (right +)")
            ax[2].plot(grid, 1e3 * yz[:, 1], lw=0.8, label="level (down +)")
            ax[2].legend(fontsize=8)
        except (UserError, ValueError, OSError) as exc:  # a table the twin cannot read: the figure says so
            ax[2].text(0.5, 0.5, f"irregularities not available: {exc}", ha="center", transform=ax[2].transAxes)
        ax[2].set(xlabel="distance along the track [m]", ylabel="[mm]", title="Irregularities")
        for a in ax:
            a.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / "track.png", dpi=110)
        plt.close(fig)
        files.append("track.png")
        files.append(figure(out, "speed.png", "Trolley speed and stops", ts, "time [s]",
                            [[("speed along the track", np.asarray(s[r["true_speed_along"]]), "m/s")],
                             [("stopped", np.asarray(s[r["true_stopped"]]), "0/1")],
                             [("distance", dist, "m")]]))
        return files

    def report_md(self, metrics: dict) -> str:
        L = []
        if "chord_alignment_max_error_mm" in metrics:
            m = metrics
            L += ["## Aided survey: 30 m chord irregularity errors of the smoothed trajectory", "",
                  f"{m['chords_surveyed']} chords, {m['chord_points']} points (0.5 m apart, 5 m offset).", "",
                  "| | alignment [mm] | level [mm] |", "|---|---|---|",
                  f"| max \\|error\\| | {m['chord_alignment_max_error_mm']:.3f} | {m['chord_level_max_error_mm']:.3f} |",
                  f"| rms error | {m['chord_alignment_rms_error_mm']:.3f} | {m['chord_level_rms_error_mm']:.3f} |",
                  f"| predicted RMS over runs of the max (smoother's joint covariance) | "
                  f"{m['predicted_sigma_alignment_mm']:.3f} | {m['predicted_sigma_level_mm']:.3f} |", "",
                  f"Filter {m['filter_seconds']:.3f} s, smoother {m['smoother_seconds']:.3f} s (its INS "
                  f"{m['observers']['smoother'].get('strapdown_seconds', 0.0):.3f} s).", ""]
        elif "filter_seconds" in metrics:
            L += ["## Aided survey", "", "The run surveys no whole 30 m chord: no chord errors.", ""]
        if metric_name("position") not in metrics:
            return "\n".join(L + ["The IMU data and the truth are in imu.csv and truth.csv (the standard form).", "",
                                  observers_md(metrics)])
        L += ["## Free-inertial INS against the trolley's truth", "",
             f"Motion starts at {metrics['motion_start_s']:g} s; 'up to 30 s / 60 s' is the largest error from "
             "the start to that long after the start of motion.", "",
             "| error | whole run | up to 30 s | up to 60 s | final |", "|---|---|---|---|---|"]
        for kind in ERRORS:
            L.append(f"| {kind} [{UNITS[kind].replace('_', '/')}] | {metrics[metric_name(kind)]:.4g} | "
                     f"{metrics[metric_name(kind, '_30s')]:.4g} | {metrics[metric_name(kind, '_60s')]:.4g} | "
                     f"{metrics[f'ins_{kind}_error_final_{UNITS[kind]}']:.4g} |")
        L += ["", "The IMU data and the truth are in imu.csv and truth.csv (the standard form).", "",
              observers_md(metrics)]
        return "\n".join(L)

    def table_md(self, table: dict[str, dict]) -> str:
        """The aiding table (what each aiding buys, per grade), the chord errors of every
        variant with the smoother, and the free-inertial INS errors of those with the INS."""
        from railfmu.experiments.trolley_survey.survey_accuracy import aiding_rows

        L = []
        chords = {v: m for v, m in table.items() if "chord_alignment_max_error_mm" in m}
        if chords:
            L += aiding_rows({v: (m["chord_alignment_max_error_mm"], m["chord_level_max_error_mm"])
                              for v, m in chords.items()}, "max |chord error| of one run")
            L += ["", "| variant | alignment max [mm] | level max [mm] | alignment rms | level rms | predicted "
                  "alignment | predicted level | filter [s] | smoother [s] |", "|---|" + "---|" * 8]
            for v, m in chords.items():
                L.append(f"| {v} | " + " | ".join(f"{m[k]:.3f}" for k in (
                    "chord_alignment_max_error_mm", "chord_level_max_error_mm", "chord_alignment_rms_error_mm",
                    "chord_level_rms_error_mm", "predicted_sigma_alignment_mm", "predicted_sigma_level_mm",
                    "filter_seconds", "smoother_seconds")) + " |")
            L += ["", "Predicted: the RMS over runs of the max |chord error| from the smoother's joint covariance.", ""]
        ins = {v: m for v, m in table.items() if metric_name("position") in m}
        if ins:
            L += ["| variant | position [mm] | at 30 s | at 60 s | velocity [mm/s] | at 30 s | at 60 s | "
                  "attitude [deg] | at 30 s | at 60 s | wall [s] |", "|---|" + "---|" * 10]
            for variant, m in ins.items():
                cells = " | ".join(f"{m[metric_name(k, s)]:.4g}" for k in ERRORS for s in ("", "_30s", "_60s"))
                L.append(f"| {variant} | {cells} | {m['wall_time_s']:.2f} |")
            L += ["", "Free-inertial INS: largest error over the run, and up to 30 s and 60 s after the start of motion."]
        return "\n".join(L).strip()


STUDY = TrolleySurvey(__doc__.strip().splitlines()[0])
