"""Trolley survey (Jiang et al. 2017), free-inertial: a pushed trolley's IMU through an IMU grade into a strapdown INS.

The system is ``SystemStructure.ssd``: the ``Trolley`` FMU is pushed along 600 m of curved,
graded track with ERRI B176 alignment and level irregularities, stopping every 60 m, and
gives the ideal IMU increments over each 5 ms step (200 Hz) and its true navigation state;
the ``ImuErrors`` FMU adds the errors of one IMU grade; the observer ``ins``
(:class:`estimators.ins_observer.StrapdownINS`) integrates the measured increments from the
trolley's state at the first sample (its settings are bound to the trolley's outputs) and is
scored against the trolley's state. Variants swap the grade: ``ideal_imu`` (the numerical
floor: the data and the INS are exact to < 0.01 mm and 1e-6 rad), ``navigation_grade`` (the
paper's IMU), ``tactical_grade``, ``mems_grade``.

Every run writes, besides ``signals.csv``, the two standard files (documented here, read by
:func:`estimators.ins_observer.read_imu_csv` and by the ``trolley_imu_replay`` experiment):

* ``imu.csv``: ``time_s, dtheta_x, dtheta_y, dtheta_z`` (rad), ``dv_x, dv_y, dv_z`` (m/s):
  the *measured* increments (the ImuErrors outputs), body forward-right-down, each over the
  interval that ends at ``time_s``; the first row (the initial time) carries zeros;
* ``truth.csv``: ``time_s, lat_deg, lon_deg, height_m`` (WGS-84 ellipsoidal), ``vn, ve, vd``
  (m/s), ``roll_deg, pitch_deg, heading_deg`` (body to local NED, ZYX), ``distance_m`` (along
  the design track), ``stopped`` (0/1).

Floats are written with ``repr`` (they read back to the same double).

Metrics (``metrics.json``), the INS against the trolley over the run: ``ins_position_error_max_mm``
(the largest 3-D position error), ``ins_velocity_error_max_mm_s`` (the largest 3-D velocity
error), ``ins_attitude_error_max_deg`` (the largest rotation angle between the INS's and the
true attitude), each also as the largest up to 30 s and 60 s after the start of motion
(``..._30s``, ``..._60s``: the first free-inertial spans between stops), plus
``motion_start_s`` and the final errors ``ins_position_error_final_mm`` etc.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from experiments.study_protocol import RunData, Study, observers_md, output, parameter
from fmus.errors import UserError

NAV = ("latitude", "longitude", "height", "vn", "ve", "vd", "roll", "pitch", "heading")
INCREMENTS = ("dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")
TRUTH_COLUMNS = ("time_s", "lat_deg", "lon_deg", "height_m", "vn", "ve", "vd", "roll_deg", "pitch_deg",
                 "heading_deg", "distance_m", "stopped")
AFTER_MOTION = (30.0, 60.0)  # s after the start of motion (Jiang et al. (2017): free-inertial spans)
ERRORS = ("position", "velocity", "attitude")
UNITS = {"position": "mm", "velocity": "mm_s", "attitude": "deg"}

# the trolley's track parameters the irregularity figure needs (models/track_geometry.py)
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


def navigation_errors(est: np.ndarray, true: np.ndarray) -> dict[str, np.ndarray]:
    """INS minus truth, rows of :data:`NAV` (rad, m, m/s): ``position`` (n, 3) NED in m (the
    latitude and longitude differences times the local radii plus height), ``velocity``
    (n, 3) NED in m/s, ``attitude`` (n, 3) in rad: the NED rotation vector ``e`` with
    ``C_est = exp([e x]) C_true`` (``estimators.attitude.perturb``'s convention)."""
    from scipy.spatial.transform import Rotation

    from estimators.attitude import dcm_from_rph
    from models import earth

    rn, re = earth.principal_radii(true[:, 0], true[:, 2])
    position = np.stack([(est[:, 0] - true[:, 0]) * rn, (est[:, 1] - true[:, 1]) * re * np.cos(true[:, 0]),
                         -(est[:, 2] - true[:, 2])], axis=1)
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
    from experiments.plots import figure

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
    from fmus.cosim.recorder import CsvRecorder

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
    """The run's track (:class:`models.track_geometry.TrackGeometry`) from the trolley's
    parameters as the SSP binds them; the shipped table when ``track_file`` is the FMU's
    resource."""
    from models.track_geometry import DEFAULT_TRACK, TrackGeometry

    params = {k: roles[f"track_{k}"] for k in GEOMETRY if k != "track_file"}
    name = str(roles["track_track_file"])
    table = Path(name) if Path(name).is_absolute() else DEFAULT_TRACK.parent / name
    return TrackGeometry(params, table, DEFAULT_TRACK.parent)


class TrolleySurvey(Study):
    """The free-inertial trolley survey: INS errors per IMU grade, and the standard files."""
    default_variant = "ideal_imu"
    roles = ROLES
    figures_of_signals: dict = {}  # not every recorded signal over 140,000 rows: the figures below
    summary_metrics = tuple(metric_name(k, s) for k in ERRORS for s in ("", "_30s", "_60s")) + ("wall_time_s",)

    def metrics(self, run: RunData) -> dict:
        t, est, true = _arrays(run)
        return error_metrics(t, navigation_errors(est, true), _motion_start(run))

    def files(self, run: RunData, out: Path) -> list[str]:
        return write_standard_files(run, out)

    def figures(self, run: RunData, out: Path) -> list[str]:
        """``track.png`` (plan, profile, irregularities), ``speed.png`` (speed and stops),
        ``ins_errors.png`` (position N/E/D, velocity, attitude over time)."""
        from experiments.plots import _pyplot, figure

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
        t, est, true = _arrays(run)
        files.append(ins_error_figure(out, "Free-inertial INS errors (INS minus truth)", t, est, true))
        return files

    def report_md(self, metrics: dict) -> str:
        L = ["## Free-inertial INS against the trolley's truth", "",
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
        L = ["| variant | position [mm] | at 30 s | at 60 s | velocity [mm/s] | at 30 s | at 60 s | "
             "attitude [deg] | at 30 s | at 60 s | wall [s] |", "|---|" + "---|" * 10]
        for variant, m in table.items():
            cells = " | ".join(f"{m[metric_name(k, s)]:.4g}" for k in ERRORS for s in ("", "_30s", "_60s"))
            L.append(f"| {variant} | {cells} | {m['wall_time_s']:.2f} |")
        return "\n".join(L + ["", "Largest error over the run, and up to 30 s and 60 s after the start of motion."])


STUDY = TrolleySurvey(__doc__.strip().splitlines()[0])
