"""Chords of a replayed survey (Jiang et al. (2017), eq. 1 and Fig. 14): the 30 m / 5 m chord
alignment and level of the smoothed trajectory along the distance, each with its predicted
sigma, and with reference positions the chord differences and their RMS.

Positions are local NED (m) about the smoothed start (``ned_difference``: over a 600 m survey
the flat-Earth form bends a 30 m chord's 5 m offset by 0.01 mm, the same for estimate and
reference). Distance (m): the odometer column when imu.csv has one (``imu.column_7``), else
the smoothed path length. Chord values: :func:`railfmu.estimators.inertial.chord_accuracy.chord_offsets`
(alignment horizontal, level vertical; m): the track's irregularity plus its design's own chord
offsets (a curve's versine). Prediction: :func:`~railfmu.estimators.inertial.chord_accuracy.survey_chords`
on the smoother's joint error distribution (RMS of the max, and the pointwise sigma).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railfmu.estimators.inertial.chord_accuracy import ChordGrid, chord_errors, chord_grid, chord_offsets, survey_chords
from railfmu.estimators.inertial.ins_error_model import ned_difference

PREDICTION_SAMPLES = 500


def local_ned(lat, lon, h, origin) -> np.ndarray:
    """(n, 3) NED (m) of geodetic rows (rad, rad, m) about ``origin`` (lat, lon, h)."""
    return ned_difference(lat, lon, h, *origin)


def path_length(positions: np.ndarray) -> np.ndarray:
    """Cumulative 3-D path length (m) of (n, 3) positions, from 0."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])


@dataclass
class ReplayChords:
    """``grid`` and at its chord points ``s`` (m): ``alignment``, ``level`` (m, the smoothed
    trajectory's), ``sigma_alignment``, ``sigma_level`` (m, pointwise predicted), ``metrics``;
    with a reference ``reference_alignment``, ``reference_level`` and the differences
    ``diff_alignment``, ``diff_level`` (m, estimate minus reference), else None."""
    grid: ChordGrid
    alignment: np.ndarray
    level: np.ndarray
    sigma_alignment: np.ndarray
    sigma_level: np.ndarray
    metrics: dict
    reference_alignment: np.ndarray | None = None
    reference_level: np.ndarray | None = None
    diff_alignment: np.ndarray | None = None
    diff_level: np.ndarray | None = None


def replay_chords(t, distance, est, smoother, ref=None, seed: int = 0) -> ReplayChords:
    """Chords of a record: ``t`` (s), ``distance`` (m), ``est`` (n, 3) smoothed NED (m),
    ``smoother`` (``error_samples``), ``ref`` (n, 3) reference NED (m) at the same samples or
    None. ValueError when the record covers no grid point."""
    grid = chord_grid(distance)
    g = grid.sample
    base = ref if ref is not None else est
    survey = survey_chords(distance, base, (est - ref) if ref is not None else np.zeros_like(est), t, smoother,
                           PREDICTION_SAMPLES, seed)
    p = survey.prediction
    a, v = chord_offsets(grid, est[g])
    m = {k: x for k, x in survey.metrics.items() if k.startswith("predicted")}
    m.update(chords_surveyed=int(grid.chord_start.size), chord_points=int(grid.n_points))
    out = ReplayChords(grid, a, v, p.pointwise_alignment_mm / 1e3, p.pointwise_level_mm / 1e3, m)
    if ref is not None:
        out.reference_alignment, out.reference_level = chord_offsets(grid, ref[g])
        out.diff_alignment, out.diff_level = chord_errors(grid, ref[g], est[g] - ref[g])
        m.update({k: x for k, x in survey.metrics.items() if not k.startswith("predicted")})
    return out


def write_csv(path, c: ReplayChords) -> None:
    """``chords.csv``: per chord point s_m, chord_start_m, alignment_mm, level_mm,
    sigma_alignment_mm, sigma_level_mm [, reference_alignment_mm, reference_level_mm,
    alignment_difference_mm, level_difference_mm]."""
    start = np.repeat(c.grid.chord_start, c.grid.n_points // max(1, c.grid.chord_start.size))
    cols = {"s_m": c.grid.s, "chord_start_m": start, "alignment_mm": 1e3 * c.alignment, "level_mm": 1e3 * c.level,
            "sigma_alignment_mm": 1e3 * c.sigma_alignment, "sigma_level_mm": 1e3 * c.sigma_level}
    if c.diff_alignment is not None:
        cols.update(reference_alignment_mm=1e3 * c.reference_alignment, reference_level_mm=1e3 * c.reference_level,
                    alignment_difference_mm=1e3 * c.diff_alignment, level_difference_mm=1e3 * c.diff_level)
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for row in np.column_stack(list(cols.values())):
            f.write(",".join(f"{x:.6g}" for x in row) + "\n")


def figure(out, c: ReplayChords, title: str) -> str:
    """``chords.png``: alignment and level along the distance with the ± predicted sigma band
    (and the reference's), with a reference their differences and RMS (Fig. 14)."""
    from railfmu.experiments.engine.plots import _pyplot, legend_outside, save

    plt = _pyplot()
    gap = np.flatnonzero(np.diff(c.grid.s) > 1.5 * c.grid.ds) + 1

    def split(x):
        return np.insert(1e3 * np.asarray(x, dtype=float), gap, np.nan)

    s = np.insert(np.asarray(c.grid.s, dtype=float), gap, np.nan)
    has_ref = c.diff_alignment is not None
    fig, ax = plt.subplots(4 if has_ref else 2, 1, figsize=(9.0, 10.0 if has_ref else 5.5), sharex=True)
    for i, (name, val, sig, rv, dv) in enumerate((("alignment", c.alignment, c.sigma_alignment,
                                                   c.reference_alignment, c.diff_alignment),
                                                  ("level", c.level, c.sigma_level, c.reference_level, c.diff_level))):
        a = ax[2 * i] if has_ref else ax[i]
        y, band = split(val), split(sig)
        a.plot(s, y, lw=0.9, label="smoother")
        a.fill_between(s, y - band, y + band, alpha=0.3, label="± predicted σ")
        if has_ref:
            a.plot(s, split(rv), lw=0.8, ls="--", label="reference")
            b = ax[2 * i + 1]
            d = split(dv)
            rms = float(np.sqrt(np.nanmean(d * d)))
            b.plot(s, d, lw=0.9, label=f"smoother − reference (RMS {rms:.3f} mm)")
            b.fill_between(s, -band, band, alpha=0.3, label="± predicted σ")
            b.set_ylabel(f"{name} difference [mm]")
            legend_outside(b)
            b.grid(alpha=0.3)
        a.set_ylabel(f"{name} [mm]")
        legend_outside(a)
        a.grid(alpha=0.3)
    ax[0].set_title(title)
    ax[-1].set_xlabel("distance along the track [m] (chord points s; 30 m chords, 5 m offset, 0.5 m spacing)")
    fig.tight_layout()
    save(fig, out / "chords.png")
    plt.close(fig)
    return "chords.png"
