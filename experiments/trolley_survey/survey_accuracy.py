r"""The aided survey's accuracy on 30 m chords (Jiang et al. (2017), §§ 5-6): per run, over a
Monte Carlo, and their figures.

Per run (:func:`chord_metrics`), from the offline observer ``smoother``
(:class:`railfmu.estimators.inertial.aided_ins.AidedInsSmoother`) and the trolley's truth:

* the smoothed position error ``e`` (local NED, m; :func:`railfmu.experiments.trolley_survey.position_errors`)
  at the samples of the survey's chord grid (:func:`railfmu.estimators.inertial.chord_accuracy.chord_grid` on the
  trolley's true ``distance``: 0.5 m spacing, consecutive 30 m chords, 5 m offset);
* the chord errors of every surveyed point, exact (:func:`railfmu.estimators.inertial.chord_accuracy.chord_errors`
  with the trolley's true n0 positions), the max ``|error|`` over the run (the survey's
  statistic) and the rms: ``chord_alignment_max_error_mm``, ``chord_level_max_error_mm``,
  ``chord_alignment_rms_error_mm``, ``chord_level_rms_error_mm``;
* the prediction of that statistic from the smoother's joint Gaussian of the errors:
  :data:`PREDICTION_SAMPLES` draws at the grid's epochs (``smoother.error_samples``, seeded by
  the run's seed, 0 without one) through the same exact chord errors, ``sqrt(mean max^2)``
  (:func:`railfmu.estimators.inertial.chord_accuracy.survey_chords` does both):
  ``predicted_sigma_alignment_mm``, ``predicted_sigma_level_mm`` (over a Monte Carlo the mean of
  the per-run predictions sits beside the RMS over runs of the max errors);
* ``filter_seconds``, ``smoother_seconds`` (the observer's own split; its INS integration is
  ``observers.smoother.strapdown_seconds``), ``chords_surveyed``, ``chord_points``.

Over a Monte Carlo (``railfmu study ... --runs N``) two statistics of the same chord errors sit
side by side (:func:`montecarlo_rows`):

* the **RMS of the max**: per run the largest ``|error|`` over the chord points, then the RMS
  over the runs (``chord_*_max_error_mm``'s ``rms``; the survey's figure of merit), beside the mean of the
  per-run predictions ``predicted_sigma_*_mm``;
* the **peak RMS** (:func:`pooled_peak_rms`): at every chord point the RMS over the runs of the
  chord error (the pointwise sigma), then the largest over the points
  (``chord_alignment_peak_rms_error_mm``, ``chord_level_peak_rms_error_mm``; pooled from every
  run's :meth:`SurveyRun.series`, so only over runs that survey the same points), beside the
  mean of the per-run largest pointwise sigma ``predicted_peak_sigma_*_mm``.

Jiang et al. (2017)'s Fig. 12 figures (0.99 / 0.70 mm) are the peak RMS: the paper says its
Monte Carlo "is consistent to the result calculated by the covariance analysis previously",
and that analysis (the largest pointwise sigma, Figs. 8-11) reproduced at the paper's nominal
run gives :data:`NOMINAL_PEAK_SIGMA_MM`
(:func:`railfmu.estimators.inertial.chord_accuracy.nominal_chord_accuracy`;
``tests/test_chord_accuracy.py``), while the RMS of the max of the same errors is clearly
larger (a max over 51 correlated points).

The truth irregularity a figure shows (eq. 1 of the body's true path: the rail's plus the
trolley's wobble) is ``chord_errors`` of the true positions against the design positions at the
same distances: ``[d_s - d_{s+o}](r) - [d_s - d_{s+o}](p_design)``; the estimate is it plus the
chord error.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from railfmu.estimators.inertial.chord_accuracy import (
    DEFAULT_SAMPLES,
    ChordGrid,
    chord_errors,
    survey_chords,
)

SMOOTHER = "smoother"
PREDICTION_SAMPLES = DEFAULT_SAMPLES  # a 500-run Monte Carlo's precision per run (their mean: / sqrt(N))
REPEATABILITY_RUNS = 6  # Jiang et al. (2017), Table 1 and Fig. 15: six runs over the same track
#: Jiang et al. (2017), Fig. 12 (500 runs): the peak RMS over runs of the chord error (module docstring)
PAPER_MAX_ERROR_MM = {"alignment": 0.99, "level": 0.70}
#: the covariance analysis of the paper's nominal constant-speed run, largest pointwise sigma (mm):
#: railfmu.estimators.inertial.chord_accuracy.nominal_chord_accuracy(nominal_run(), **NOMINAL) (tests/test_chord_accuracy.py)
NOMINAL_PEAK_SIGMA_MM = {"alignment": 0.979, "level": 0.695}
CHORD_METRICS = ("chord_alignment_max_error_mm", "chord_level_max_error_mm", "chord_alignment_rms_error_mm",
                 "chord_level_rms_error_mm", "predicted_sigma_alignment_mm", "predicted_sigma_level_mm",
                 "filter_seconds", "smoother_seconds")


class SurveyRun:
    """One run's chord grid, truth, smoothed errors and chord errors (built once per hook)."""

    def __init__(self, run, position_errors):
        s, r = run.signals, run.roles
        self.obs = run.observers[SMOOTHER]
        geodetic = ("latitude", "longitude", "height")
        est = np.column_stack([np.asarray(run.estimates[f"{SMOOTHER}.{k}"]) for k in geodetic])
        # an offline observer's estimates are on its own samples: every stride-th record row
        stride = max(1, -(-np.asarray(s["time"]).size // est.shape[0]))
        rows = slice(0, stride * est.shape[0], stride)
        def truth(k):
            return np.asarray(s[r[f"true_{k}"]])[rows]

        self.t = np.asarray(s["time"])[rows]
        self.error = position_errors(est, np.column_stack([truth(k) for k in geodetic]))
        self.distance = truth("distance")
        self.positions = np.column_stack([truth(k) for k in ("north", "east", "down")])
        self.sigma = np.column_stack([np.asarray(run.estimates[f"{SMOOTHER}.sigma_{k}"]) for k in ("north", "east", "down")])
        self.grid: ChordGrid | None = None
        try:
            survey = survey_chords(self.distance, self.positions, self.error, self.t, self.obs, PREDICTION_SAMPLES,
                                   # a run without --seed still gets the same draws every time
                                   run.base.get("seed") or 0)
        except ValueError:  # a run shorter than one grid spacing
            return
        if survey.grid.n_points:
            self.grid, self.alignment, self.level = survey.grid, survey.alignment, survey.level
            self.prediction, self.chord_metrics = survey.prediction, survey.metrics

    def metrics(self) -> dict:
        out = {"filter_seconds": float(self.obs.filter_seconds), "smoother_seconds": float(self.obs.smoother_seconds)}
        if self.grid is None:
            return {**out, "chords_surveyed": 0, "chord_points": 0}
        return {**self.chord_metrics, **out,
                "prediction_relative_se_alignment": self.prediction.relative_se_alignment,
                "prediction_relative_se_level": self.prediction.relative_se_level,
                "chords_surveyed": int(self.grid.chord_start.size), "chord_points": int(self.grid.n_points)}

    def pointwise_sigma(self) -> tuple[np.ndarray, np.ndarray]:
        """The exact pointwise sigma (mm) of the chord errors, alignment and level at
        ``grid.s``: the smoother's joint covariance of the position errors at the grid's epochs
        through :func:`railfmu.estimators.inertial.chord_accuracy.chord_sigma_from_covariance` (its blocks grow
        as the square of the grid: for tests and short runs; the metrics sample instead)."""
        from railfmu.estimators.inertial.chord_accuracy import chord_sigma_from_covariance
        from railfmu.estimators.inertial.ins_error_model import DR

        g = self.grid
        epochs, inverse = np.unique(self.obs.nearest_epochs(self.t[g.sample]), return_inverse=True)
        n, m = len(self.obs.state_names), epochs.size
        cov = self.obs.joint_covariance(epochs).reshape(m, n, m, n)[:, DR, :, DR][inverse][:, :, inverse]
        sy, sz = chord_sigma_from_covariance(g, self.positions[g.sample], cov.reshape(3 * g.sample.size, -1))
        return 1e3 * sy, 1e3 * sz

    def truth_irregularity(self, track) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 1 of the body's true path at the chord points (alignment, level; m)."""
        g = self.grid.sample
        design = track.design_positions(self.distance[g])
        return chord_errors(self.grid, design, self.positions[g] - design)

    def series(self) -> dict[str, np.ndarray]:
        """What a Monte Carlo member hands back: the chord points' distances and errors (m)."""
        if self.grid is None:
            return {}
        return {"chord_s": self.grid.s.astype(np.float32), "chord_alignment_error": self.alignment.astype(np.float32),
                "chord_level_error": self.level.astype(np.float32)}


# -- per-run figures -------------------------------------------------------------------------------

def irregularity_figure(out: Path, sr: SurveyRun, track, title: str) -> str:
    """``chord_irregularity.png`` (Jiang et al. (2017), Figs. 12/14): estimated and true
    irregularity along the track with the pointwise predicted 1-sigma band, alignment and
    level, and their errors."""
    from railfmu.experiments.engine.plots import _pyplot

    plt = _pyplot()
    ta, tv = sr.truth_irregularity(track)
    gap = np.flatnonzero(np.diff(sr.grid.s) > 1.5 * sr.grid.ds) + 1  # chord ends: no line across

    def split(x):
        return np.insert(np.asarray(x, dtype=float), gap, np.nan)

    s = split(sr.grid.s)
    ta, tv, err_a, err_v = split(ta), split(tv), split(sr.alignment), split(sr.level)
    pa, pv = split(sr.prediction.pointwise_alignment_mm), split(sr.prediction.pointwise_level_mm)
    fig, ax = plt.subplots(4, 1, figsize=(9.0, 10.0), sharex=True)
    for i, (name, true, err, band) in enumerate((("alignment", ta, err_a, pa), ("level", tv, err_v, pv))):
        a = ax[2 * i]
        a.plot(s, 1e3 * true, lw=0.9, label="true")
        a.plot(s, 1e3 * (true + err), lw=0.9, ls="--", label="estimated (smoother)")
        a.fill_between(s, 1e3 * true - band, 1e3 * true + band, alpha=0.25, label="true ± predicted σ")
        a.set_ylabel(f"{name} [mm]")
        a.legend(fontsize=8, loc="upper right")
        b = ax[2 * i + 1]
        b.plot(s, 1e3 * err, lw=0.9, label="error")
        b.fill_between(s, -band, band, alpha=0.25, label="± predicted σ")
        b.set_ylabel(f"{name} error [mm]")
        b.legend(fontsize=8, loc="upper right")
    for a in ax:
        a.grid(alpha=0.3)
    ax[0].set_title(title)
    ax[-1].set_xlabel("distance along the track [m] (chord points s; 30 m chords, 5 m offset)")
    fig.tight_layout()
    fig.savefig(out / "chord_irregularity.png", dpi=110)
    plt.close(fig)
    return "chord_irregularity.png"


def trajectory_figure(out: Path, sr: SurveyRun, length: float = 60.0) -> str:
    """``trajectory_3d.png`` (Fig. 14c): the first ``length`` m, true and smoothed, in n0
    (north, east, up; m), with the smoothed error magnified in a second panel."""
    from railfmu.experiments.engine.plots import _pyplot

    plt = _pyplot()
    keep = sr.distance <= sr.distance[0] + length
    r, e = sr.positions[keep], sr.error[keep]
    fig = plt.figure(figsize=(10.0, 5.0))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax.plot(r[:, 1], r[:, 0], -r[:, 2], lw=1.2, label="true")
    ax.plot(r[:, 1] + e[:, 1], r[:, 0] + e[:, 0], -(r[:, 2] + e[:, 2]), lw=1.0, ls="--", label="smoother")
    ax.set(xlabel="east [m]", ylabel="north [m]", zlabel="up [m]", title=f"First {length:g} m")
    ax.legend(fontsize=8)
    b = fig.add_subplot(1, 2, 2)
    d = sr.distance[keep]
    for j, c in enumerate("NED"):
        b.plot(d, 1e3 * e[:, j], lw=0.9, label=f"error {c}")
    b.set(xlabel="distance [m]", ylabel="smoothed position error [mm]", title="Smoother minus truth")
    b.grid(alpha=0.3)
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "trajectory_3d.png", dpi=110)
    plt.close(fig)
    return "trajectory_3d.png"


#: Jiang et al. (2017), Figs. 8-11: the settings each figure varies (railfmu.estimators.inertial.chord_accuracy.SENSITIVITY_AXES)
SENSITIVITY_FIGURES = {8: ("velocity-update accuracy", ("zupt_sigma",)),
                       9: ("sensor noise", ("gyro_arw_deg_sqrt_h", "accel_noise_ug_sqrt_hz")),
                       10: ("initial attitude errors", ("tilt_sigma", "heading_sigma")),
                       11: ("sensor biases", ("gyro_turn_on_bias_sigma_deg_h", "accel_turn_on_bias_sigma_ug"))}


def sensitivity_figures(out: Path) -> list[str]:
    """``sensitivity_fig8.png`` ... ``fig11.png`` (Jiang et al. (2017), Figs. 8-11): the largest
    pointwise sigma of the 30 m chord errors against one setting at a time, the others at the
    paper's nominal, from :func:`railfmu.estimators.inertial.chord_accuracy.sensitivity_curves` (the covariance
    analysis of the paper's constant-speed run; every other value of its axes, to keep a run's
    figures to seconds)."""
    from railfmu.estimators.inertial.chord_accuracy import SENSITIVITY_AXES, sensitivity_curves
    from railfmu.experiments.engine.plots import _pyplot

    axes = {k: (v[0][::2] if v[0].size > 3 else v[0], *v[1:]) for k, v in SENSITIVITY_AXES.items()}
    curves = sensitivity_curves(axes)
    nominal = curves["nominal"]
    plt = _pyplot()
    files = []
    for number, (what, names) in SENSITIVITY_FIGURES.items():
        names = [n for n in names if n in curves]
        if not names:
            continue
        fig, ax = plt.subplots(1, len(names), figsize=(max(6.8, 5.2 * len(names)), 4.2), squeeze=False)
        for a, name in zip(ax[0], names):
            c = curves[name]
            for key, label, style in (("alignment_mm", "alignment", "-"), ("level_mm", "level", "-"),
                                      ("alignment_mm_position", "alignment, with position updates", "--"),
                                      ("level_mm_position", "level, with position updates", "--")):
                if key in c:
                    a.plot(c["x"], c[key], ls=style, marker="o", ms=3, lw=1.0, label=label)
            a.axhline(nominal["alignment_mm"], color="C0", lw=0.6, ls=":")
            a.axhline(nominal["level_mm"], color="C1", lw=0.6, ls=":")
            a.set_xscale("log")
            a.set(xlabel=f"{name} [{c['unit']}]", ylabel="largest pointwise σ of the chord error [mm]")
            a.grid(alpha=0.3, which="both")
            a.legend(fontsize=7)
        fig.suptitle(f"Jiang et al. (2017), Fig. {number}: {what} (dotted: the paper's nominal)", fontsize=9)
        fig.tight_layout()
        name = f"sensitivity_fig{number}.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


# -- over a Monte Carlo -----------------------------------------------------------------------------

def pooled_peak_rms(series: dict[int, dict[str, np.ndarray]]) -> dict[str, float]:
    """The Monte Carlo's pointwise statistic from the runs' :meth:`SurveyRun.series` (``{seed:
    {"chord_s", "chord_alignment_error", "chord_level_error"}}``, m): at every chord point ``s``
    the RMS over the ``N`` runs, ``sqrt(sum_runs Delta_s^2 / N)`` (mm), and its largest value over
    the points: ``chord_{alignment,level}_peak_rms_error_mm``, with the point's distance
    ``chord_{alignment,level}_peak_rms_s_m`` and ``chord_peak_rms_runs`` = N. Its relative
    standard error at one point is ``1 / sqrt(2 N)`` for Gaussian errors (3.2 % at 500 runs,
    16 % at 20); the max over the points adds a little upward bias.

    Pools only runs that survey the same chord points: a run whose ``chord_s`` differs from the
    first run's (or that has none while another has) is refused with a ``ValueError`` naming
    both. Runs without chords at all give ``{}``."""
    with_chords = {seed: x for seed, x in series.items() if x.get("chord_s") is not None}
    if not with_chords:
        return {}
    seeds = sorted(series)
    first = min(with_chords)
    s0 = np.asarray(with_chords[first]["chord_s"])

    def where(x):
        return f"{x.size} points from {x[0]:g} to {x[-1]:g} m" if x.size else "no chord points"

    for seed in seeds:
        s = series[seed].get("chord_s")
        s = np.zeros(0) if s is None else np.asarray(s)
        if s.shape != s0.shape or not np.array_equal(s, s0):
            raise ValueError(f"cannot pool the chord errors over runs: run {seed} surveys {where(s)}, run {first} "
                             f"{where(s0)}; the pointwise RMS needs the same chord points in every run")
    out: dict[str, float] = {}
    for kind in ("alignment", "level"):
        e = np.stack([np.asarray(series[seed][f"chord_{kind}_error"], dtype=float) for seed in seeds])
        if e.shape[1] != s0.size:
            raise ValueError(f"chord_{kind}_error has {e.shape[1]} values for {s0.size} chord points")
        rms_s = 1e3 * np.sqrt(np.mean(e * e, axis=0))
        k = int(np.argmax(rms_s))
        out[f"chord_{kind}_peak_rms_error_mm"] = float(rms_s[k])
        out[f"chord_{kind}_peak_rms_s_m"] = float(s0[k])
    out["chord_peak_rms_runs"] = len(seeds)
    return out


def montecarlo_rows(summary: dict[str, dict]) -> list[str]:
    """Markdown: per variant and chord component the two statistics of the module docstring,
    each with its prediction and their ratio, and the paper's figure for ``paper_montecarlo``
    (beside the statistic it is: the peak RMS)."""
    rows = []
    for variant, stats in summary.items():
        for kind in ("alignment", "level"):
            mc, pred = stats.get(f"chord_{kind}_max_error_mm"), stats.get(f"predicted_sigma_{kind}_mm")
            if not isinstance(mc, dict) or not isinstance(pred, dict):
                continue
            peak = stats.get(f"chord_{kind}_peak_rms_error_mm")
            peak_pred = stats.get(f"predicted_peak_sigma_{kind}_mm")
            peak_pred = peak_pred["mean"] if isinstance(peak_pred, dict) else None
            cells = [f"{mc['rms']:.3f}", f"{pred['mean']:.3f}", f"{pred['mean'] / mc['rms']:.2f}",
                     "-" if peak is None else f"{peak:.3f}", "-" if peak_pred is None else f"{peak_pred:.3f}",
                     f"{peak_pred / peak:.2f}" if peak and peak_pred is not None else "-",
                     f"{PAPER_MAX_ERROR_MM[kind]:.2f}" if variant.startswith("paper_montecarlo") else "-"]
            rows.append(f"| {variant} | {kind} | " + " | ".join(cells) + " |")
    if not rows:
        return []
    return ["| variant | chord error | RMS of max [mm] | predicted [mm] | predicted / MC | peak RMS [mm] | "
            "predicted peak σ [mm] | predicted / MC | paper (Fig. 12) [mm] |",
            "|---|---|---|---|---|---|---|---|---|", *rows, "",
            "Two statistics of the same 30 m chord errors. **RMS of max**: per run the largest |chord error| "
            "over the chord points, then the RMS over the runs (`chord_*_max_error_mm`, the survey's figure of merit); "
            "predicted: the mean over runs of each run's prediction from the smoother's joint covariance "
            f"({PREDICTION_SAMPLES} draws per run). **Peak RMS**: at each chord point the RMS over the runs of "
            "the chord error (the pointwise σ), then the largest over the points "
            "(`chord_*_peak_rms_error_mm`); predicted: the mean over runs of the largest pointwise σ "
            "(`predicted_peak_sigma_*_mm`, from the same draws). **The paper's Fig. 12 figures (0.99 / "
            "0.70 mm) are the peak RMS**: Jiang et al. (2017) say the Monte Carlo's value \"is consistent to "
            "the result calculated by the covariance analysis previously\", the largest pointwise σ of "
            "Figs. 8-11, and that covariance analysis at the paper's nominal constant-speed run gives "
            f"{NOMINAL_PEAK_SIGMA_MM['alignment']:.3f} / {NOMINAL_PEAK_SIGMA_MM['level']:.3f} mm here "
            "(`railfmu.estimators.inertial.chord_accuracy.nominal_chord_accuracy`); the RMS of the max of the same errors is "
            "1.5-1.7 times larger (1.49 / 1.18 mm there)."]


def aiding_rows(values: dict[str, tuple[float, float]], how: str) -> list[str]:
    """The aiding table: what each aiding buys (rows) per IMU grade (columns), from
    ``values[variant] = (alignment, level)`` in mm; absent variants are '-'."""
    from railfmu.experiments.trolley_survey.variants import AIDINGS

    grades = (("navigation", ""), ("tactical", "_tactical"), ("mems", "_mems"))
    present = [g for g in grades if any(f"{a}{g[1]}" in values for a in AIDINGS)]
    if not present:
        return []
    L = ["| aiding | " + " | ".join(f"{g} grade: alignment / level [mm]" for g, _ in present) + " |",
         "|---|" + "---|" * len(present)]
    for aiding, (what, _) in AIDINGS.items():
        cells = []
        for _, suffix in present:
            v = values.get(f"{aiding}{suffix}")
            cells.append("-" if v is None else f"{v[0]:.3f} / {v[1]:.3f}")
        L.append(f"| {what} (`{aiding}`) | " + " | ".join(cells) + " |")
    return L + ["", f"Chord errors on the 600 m survey, 30 m chords: {how}."]


def repeatability(series: dict[int, dict[str, np.ndarray]]) -> list[dict]:
    """Jiang et al. (2017), Table 1: for each later run j of the first
    :data:`REPEATABILITY_RUNS` the differences of the estimated irregularities from the first
    run's at the same chord points (G1j): max |.|, mean, std (mm), alignment and level. The
    track is the same in every run (its seed is ``irregularity_seed``, not the run's), so the
    difference of two estimates is the difference of their chord errors."""
    seeds = [s for s in sorted(series) if series[s].get("chord_s") is not None][:REPEATABILITY_RUNS]
    out = []
    if len(seeds) < 2:
        return out
    first = series[seeds[0]]
    for j in seeds[1:]:
        other = series[j]
        n = min(first["chord_s"].size, other["chord_s"].size)
        row = {"pair": f"G{seeds[0]}{j}" if j < 10 and seeds[0] < 10 else f"G{seeds[0]},{j}"}
        for kind in ("alignment", "level"):
            d = 1e3 * (other[f"chord_{kind}_error"][:n].astype(float) - first[f"chord_{kind}_error"][:n].astype(float))
            row[kind] = {"max": float(np.abs(d).max()), "mean": float(d.mean()),
                         "std": float(d.std(ddof=1)) if d.size > 1 else 0.0}
        out.append(row)
    return out


def repeatability_rows(variant: str, rows: list[dict]) -> list[str]:
    if not rows:
        return []
    L = [f"Repeatability of `{variant}` (Jiang et al. (2017), Table 1: Gij the difference of runs i and j at the "
         "same chord points, mm)", "",
         "| pair | alignment max | mean | std | level max | mean | std |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        a, v = r["alignment"], r["level"]
        L.append(f"| {r['pair']} | {a['max']:.3f} | {a['mean']:.3f} | {a['std']:.3f} | {v['max']:.3f} | "
                 f"{v['mean']:.3f} | {v['std']:.3f} |")
    return L + [""]


def histogram_figure(out: Path, table: dict) -> str | None:
    """``max_error_histograms.png`` (Fig. 12): per variant the histograms over runs of the max
    chord errors, with their RMS and its mean prediction marked, and the pointwise statistic
    (the peak RMS over runs and the predicted peak sigma, when the summary has them) and the
    paper's figure, which is a peak RMS."""
    from railfmu.experiments.engine.plots import _pyplot

    variants = [v for v, t in table.items()
                if any("chord_alignment_max_error_mm" in m for m in t["runs"].values())]
    if not variants:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(len(variants), 2, figsize=(10.0, 3.2 * len(variants)), squeeze=False)
    for i, v in enumerate(variants):
        runs = [m for m in table[v]["runs"].values() if "chord_alignment_max_error_mm" in m]
        for j, kind in enumerate(("alignment", "level")):
            x = np.array([m[f"chord_{kind}_max_error_mm"] for m in runs])
            pred = float(np.mean([m[f"predicted_sigma_{kind}_mm"] for m in runs]))
            rms = math.sqrt(float(np.mean(x * x)))
            a = ax[i, j]
            a.hist(x, bins=max(5, min(40, x.size // 5)), alpha=0.7)
            a.axvline(rms, color="C1", lw=1.5, label=f"RMS of max {rms:.3f} mm")
            a.axvline(pred, color="C2", lw=1.5, ls="--", label=f"predicted {pred:.3f} mm")
            peak = table[v].get("summary", {}).get(f"chord_{kind}_peak_rms_error_mm")
            if peak is not None:  # the pointwise statistic, on the same mm axis
                a.axvline(peak, color="C3", lw=1.5, label=f"peak RMS (pointwise) {peak:.3f} mm")
                peak_pred = float(np.mean([m[f"predicted_peak_sigma_{kind}_mm"] for m in runs]))
                a.axvline(peak_pred, color="C4", lw=1.5, ls="--", label=f"predicted peak σ {peak_pred:.3f} mm")
            if v.startswith("paper_montecarlo"):
                a.axvline(PAPER_MAX_ERROR_MM[kind], color="k", lw=1.0, ls=":",
                          label=f"paper {PAPER_MAX_ERROR_MM[kind]:.2f} mm (a peak RMS)")
            a.set(xlabel=f"max |{kind} chord error| per run [mm]", ylabel="runs", title=f"{v}: {kind} ({x.size} runs)")
            a.legend(fontsize=8)
            a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "max_error_histograms.png", dpi=110)
    plt.close(fig)
    return "max_error_histograms.png"


def repeatability_figure(out: Path, variant: str, series: dict[int, dict[str, np.ndarray]], truth) -> str | None:
    """``repeatability_<variant>.png`` (Fig. 15): the estimated irregularity of the first
    chord in each run (truth + that run's chord error) over the true one. ``truth``: ``(s,
    alignment, level)`` of the first chord (m) or None (then the errors alone)."""
    from railfmu.experiments.engine.plots import _pyplot

    seeds = [s for s in sorted(series) if series[s].get("chord_s") is not None][:REPEATABILITY_RUNS]
    if len(seeds) < 2:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(2, 1, figsize=(9.0, 6.5), sharex=True)
    s0 = series[seeds[0]]["chord_s"].astype(float)
    first = s0 < s0[0] + 30.0 - 1e-9  # the first chord's points
    for a, kind in zip(ax, ("level", "alignment")):
        base = np.zeros(int(first.sum()))
        if truth is not None:
            ts, ta, tv = truth
            base = np.interp(s0[first], ts, ta if kind == "alignment" else tv)
            a.plot(s0[first], 1e3 * base, color="k", lw=1.5, label="true")
        for seed in seeds:
            e = series[seed][f"chord_{kind}_error"].astype(float)[:first.sum()]
            a.plot(s0[first], 1e3 * (base + e), lw=0.9, marker=".", ms=3, label=f"run {seed}")
        a.set_ylabel(f"{kind} irregularity [mm]" if truth is not None else f"{kind} error [mm]")
        a.grid(alpha=0.3)
        a.legend(fontsize=7, ncol=4)
    ax[0].set_title(f"{variant}: repeatability over {len(seeds)} runs of the same track (Jiang et al. (2017), Fig. 15)")
    ax[-1].set_xlabel("distance along the track [m] (first 30 m chord, 0.5 m spacing)")
    fig.tight_layout()
    name = f"repeatability_{variant}.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return name
