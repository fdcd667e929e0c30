"""Secondary vertical suspension stiffness k1 (Onat et al. 2016) from a measured coach run and a recording car's rail heights by position.

``SystemStructure.ssd``: a SignalTable FMU plays ``coach.csv`` (the seven inertial channels);
the TrackIrregularity FMU in its measured-profile mode gives the rail heights and rates under
both bogies from ``geometry.csv`` (``position_m, vertical_left_m, vertical_right_m``) at
position ``s_start + V t - axle_position_i``; the observers ``paper_wls``
(:class:`railfmu.estimators.suspension.stiffness.SuspensionWLS`) and ``improved``
(:class:`railfmu.estimators.suspension.stiffness.SuspensionJoint`) estimate k1 over time. No
truth is read. Shipped: a simulated ``suspension_fault --variant step_fault --seed 1`` run
(``record.py``; ``resources/README.md``).

Outputs: ``k1.csv`` (``time_s``, ``paper_wls_k1_N_m``, ``improved_k1_N_m``), ``k1_estimates.png``
(both over time, the alarm level and the detection times), ``rails.png`` (the rail heights
under the bogies along the track). Metrics per estimator: ``k1_final_N_m`` (the mean over the last
:data:`FINAL_SPAN` s), ``k1_baseline_N_m`` (the median over :data:`BASELINE` s), and
``detection_time_s``: the first time the estimate stays below ``(1 - ALARM_DROP)`` times the
baseline for :data:`HOLD` s, at the end of that hold (None: no alarm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railfmu.experiments.engine.study_protocol import RunData, Study, observers_md

ESTIMATORS = ("paper_wls", "improved")
#: s: the estimators start from k1 = 330 kN/m and converge within ~10 s (suspension_fault)
BASELINE = (10.0, 15.0)
ALARM_DROP = 0.25  # a drop of 25 % of the baseline: half the paper's 50 % fault
HOLD = 1.0  # s the estimate must stay below the alarm level
FINAL_SPAN = 10.0  # s


def detection_time(t: np.ndarray, k1: np.ndarray, baseline: float, drop: float = ALARM_DROP,
                   hold: float = HOLD) -> float | None:
    """The end of the first ``hold`` s (s) over which ``k1`` (N/m) stays below ``(1 - drop)
    baseline``; None when it never does."""
    below = np.isfinite(k1) & (k1 < (1.0 - drop) * baseline)
    d = np.diff(np.concatenate([[0], below.astype(np.int8), [0]]))
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        end = np.searchsorted(t, t[a] + hold - 1e-9)
        if end < b:
            return float(t[end])
    return None


def k1_metrics(t: np.ndarray, k1: np.ndarray) -> dict:
    """The metrics of the module docstring for one estimate (N/m at ``t``, s)."""
    base = (t >= BASELINE[0]) & (t <= BASELINE[1])
    baseline = float(np.nanmedian(k1[base])) if base.any() else float("nan")
    final = t >= t[-1] - FINAL_SPAN
    return {"k1_baseline_N_m": baseline, "k1_final_N_m": float(np.nanmean(k1[final])),
            "detection_time_s": detection_time(t, k1, baseline) if np.isfinite(baseline) else None}


def _estimates(run: RunData) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    t = np.asarray(run.estimates["time"])
    return t, {n: np.asarray(run.estimates[f"{n}.k1"])[:t.size] for n in ESTIMATORS if f"{n}.k1" in run.estimates}


class SuspensionReplay(Study):
    """k1 of both estimators on a replayed run, and when each sees the fault."""
    default_variant = "recorded"
    figures_of_signals: dict = {}
    summary_metrics = ("*.k1_final_N_m", "*.detection_time_s", "wall_time_s")

    def metrics(self, run: RunData) -> dict:
        t, k = _estimates(run)
        return {n: k1_metrics(t, k1) for n, k1 in k.items()}

    def files(self, run: RunData, out: Path) -> list[str]:
        t, k = _estimates(run)
        data = np.column_stack([t, *k.values()])
        np.savetxt(out / "k1.csv", data, delimiter=",", fmt="%.10g", comments="",
                   header=",".join(["time_s", *(f"{n}_k1_N_m" for n in k)]))
        return ["k1.csv"]

    def figures(self, run: RunData, out: Path) -> list[str]:
        from railfmu.experiments.engine.plots import figure

        t, k = _estimates(run)
        curves, marks = [], []
        for (n, k1), c in zip(k.items(), ("C1", "C0")):
            m = k1_metrics(t, k1)
            curves.append((f"{n} estimate", k1 / 1e3, "kN/m", {"color": c, "lw": 1.0}))
            curves.append((f"{n} alarm level", np.full(t.size, (1 - ALARM_DROP) * m["k1_baseline_N_m"] / 1e3),
                           "kN/m", {"color": c, "lw": 0.6, "ls": ":"}))
            if m["detection_time_s"] is not None:
                marks.append(f"{n} {m['detection_time_s']:.2f} s")
        title = "k1 on the replayed run (Fig. 3 of Onat et al. (2016))" + (
            f"; detected: {', '.join(marks)}" if marks else "; no detection")
        files = [figure(out, "k1_estimates.png", title, t, "time [s]", [curves],
                        quantities=["secondary suspension stiffness k1"])]
        s = run.signals
        files.append(figure(out, "rails.png", "Rail heights under the bogies (from the geometry file by position)",
                            np.asarray(s["track.position"]), "distance along the track [m] (bogie 1)",
                            [[(f"{side} rail", 1e3 * np.asarray(s[f"track.vertical_{side}_{i}"]), "mm")
                              for side in ("left", "right")] for i in (1, 2)],
                            quantities=[f"rail height, bogie {i}" for i in (1, 2)]))
        return files

    def report_md(self, metrics: dict) -> str:
        L = ["## k1 on the replayed run", "",
             f"Baseline: the median over {BASELINE[0]:g}-{BASELINE[1]:g} s; alarm: {ALARM_DROP:.0%} below it for "
             f"{HOLD:g} s.", "", "| estimator | baseline [kN/m] | final [kN/m] | detection time [s] |",
             "|---|---|---|---|"]
        for n in ESTIMATORS:
            m = metrics.get(n)
            if m:
                d = "-" if m["detection_time_s"] is None else f"{m['detection_time_s']:.2f}"
                L.append(f"| {n} | {m['k1_baseline_N_m'] / 1e3:.1f} | {m['k1_final_N_m'] / 1e3:.1f} | {d} |")
        return "\n".join(L + ["", observers_md(metrics)])


STUDY = SuspensionReplay(__doc__.strip().splitlines()[0])
