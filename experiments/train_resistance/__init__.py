"""Train running resistance from GNSS with the UKF of Cunillera et al. (2022), on simulated runs with ground truth.

``SystemStructure.ssd``: the Driver (manual driving, style drawn from the run's seed) drives
the TrainLongitudinal FMU (eqs. 1-2) over the 32,103 m line; the GnssReceiver gives position
and speed fixes (10 s, 4 m, 1 km/h) with a valid flag; the run's true Davis coefficients are
the published ones times per-run factors N(1, 0.1^2) (a SensorNoise held over the run). Every
observer of the SSD (``ukf_paper``: the paper's UKF as written) estimates s, v, r0-r2 from the
fixes. Variants: ``standard`` (the paper's 10 s GNSS), ``gnss_1hz``, ``resistance_drift`` (r2
rising +30 % per 1500 s, a headwind), ``heavy_load`` (100 % load; the observers start from the
35 %-load values). ``railfmu study train_resistance --runs 67`` gives the paper's 67-run
statistics (its Figs. 2, 4, 7, 8, 9) with the ground truth beside them.

Metrics (``metrics.json``), per estimator (every observer with outputs s, v, r0, r1, r2),
an object under its name::

    speed_rmse_kmh, position_rmse_m   rms at the GNSS fixes after the first (the initial state)
                                      against the train's true v, s
    resistance_rel_error              rms over v = 40, 41, ..., 140 km/h of (r^(v) - r(v)) / r(v),
                                      r^ from the estimates at the end of the run, r the true
                                      resistance at the end of the run (eq. 2)
    r0_rel_error, r1_rel_error, r2_rel_error   (r^_i - r_i) / r_i at the end, signed
    r0_final, r1_final, r2_final      the final estimates (SI)
    seconds                           the estimator's wall time in the run

and ``truth``: the run's true r0-r2 at the end, the driver's style (cruise target, brake
rate per ATB-EG step, cycles), the run time, top speed, and from the driver's regime the
shares of traction, cruising, coasting and braking in the run time and the final coast and
brake durations (the quantities of the paper's Figs. 3 and 7).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.study_protocol import RunData, Study, observers_md, output, parameter, truth
from fmus.errors import UserError

KMH = 1.0 / 3.6
DEFAULT_VARIANT = "standard"
REFERENCE = "ukf_paper"  # the observer whose truth bindings name the train's s, v, r0-r2
#: the resistance_rel_error speed grid: 40-140 km/h, 1 km/h
SPEED_GRID = np.arange(40.0, 141.0, 1.0) * KMH
REGIMES = {0: "standstill", 1: "traction", 2: "cruising", 3: "coasting", 4: "braking"}
REGIME_COLOURS = {0: "0.6", 1: "k", 2: "C0", 3: "C4", 4: "C3"}  # the paper's Fig. 6: black, blue, purple, red
ATB_EG = ("> 130", "130-80", "80-60", "60-40", "< 40")  # km/h, the driver's brake_rate_1..5
ESTIMATES = ("s", "v", "r0", "r1", "r2")

ROLES = {
    "s": truth(REFERENCE, "s"), "v": truth(REFERENCE, "v"),
    "r0": truth(REFERENCE, "r0"), "r1": truth(REFERENCE, "r1"), "r2": truth(REFERENCE, "r2"),
    "fix": output("gnss", "valid"), "gnss_position": output("gnss", "position"),
    "gnss_speed": output("gnss", "speed"), "gnss_period": parameter("gnss", "sample_period"),
    "regime": output("driver", "regime"), "cruise_target": output("driver", "cruise_target"),
    "cycles": output("driver", "cycles"), "coasting_point": output("driver", "coasting_point"),
    "traction_fraction": output("driver", "traction_fraction"),
    **{f"brake_rate_{k}": output("driver", f"brake_rate_{k}") for k in range(1, 6)},
    "acceleration": output("train", "acceleration"), "effort": output("train", "effort_specific"),
    "power": output("train", "power"), "line_term": output("train", "gradient_specific"),
    "tare_mass": parameter("train", "tare_mass"), "load_mass": parameter("train", "load_mass"),
    "gamma": parameter("train", "rotating_mass_factor"), "max_power": parameter("train", "max_power"),
    "max_traction_force": parameter("train", "max_traction_force"),
    "max_deceleration": parameter("train", "max_deceleration"),
}

PLOTS = {
    "run.png": ("The run: speed, driver's regime, line", [
        [("v", "true speed"), ("gnss_speed", "GNSS speed")],
        [("regime", "driver's regime (0 standstill .. 4 braking)")],
        [("line_term", "line term g(s)")]]),
}

#: what Cunillera et al. (2022) publish for their 67 NS runs (VIRM-VI, Eindhoven - 's-Hertogenbosch)
PAPER = {
    "r0_bounds": "0.0072-0.00738 N/kg besides outliers (Fig. 4; VIRM-VI, manufacturer value near the upper bound)",
    "above_140": 0.12, "coast_min": (2.5, 10.0), "brake_cv": 0.20, "coast_cv": 0.30,
    "shares": {"traction": 0.164, "cruising": 0.17, "coasting": 0.57, "braking": 0.093},
    "linear_share_max": 0.11, "quadratic_share_max": 0.76,
}


def estimators_of(estimates: dict) -> list[str]:
    """Every observer that estimates s, v, r0, r1, r2 (online: one row per recorded row)."""
    names = [c[:-3] for c in estimates if c.endswith(".r0")]
    n = len(estimates["time"])
    return [o for o in names if all(len(estimates.get(f"{o}.{e}", ())) == n for e in ESTIMATES)]


def resistance(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Eq. 2: r0 + r1 v + r2 v^2 (N/kg) for coefficients ``r = (r0, r1, r2)``."""
    return r[0] + r[1] * v + r[2] * v * v


def resistance_rel_error(r_hat: np.ndarray, r_true: np.ndarray, grid: np.ndarray = SPEED_GRID) -> float:
    """rms over ``grid`` (m/s) of (r^(v) - r(v)) / r(v)."""
    e = (resistance(r_hat, grid) - resistance(r_true, grid)) / resistance(r_true, grid)
    return float(np.sqrt(np.mean(e * e)))


def term_shares(est: dict, name: str, rows: np.ndarray) -> dict[str, float]:
    """The largest shares of the linear and quadratic terms in r(v) along the run (Fig. 5 of
    Cunillera et al. (2022): up to 11 % and 76 %), with the estimator's running r0-r2 and v."""
    v = np.maximum(np.asarray(est[f"{name}.v"])[rows], 0.0)
    r0, r1, r2 = (np.asarray(est[f"{name}.r{k}"])[rows] for k in range(3))
    total = r0 + r1 * v + r2 * v * v
    return {"linear_share_max": float(np.max(r1 * v / total)), "quadratic_share_max": float(np.max(r2 * v * v / total))}


def blocks(regime: np.ndarray) -> list[tuple[int, int, int]]:
    """Runs of equal regime as (code, first row, last row)."""
    r = np.asarray(regime).astype(int)
    edges = np.flatnonzero(np.diff(r)) + 1
    starts, ends = np.r_[0, edges], np.r_[edges - 1, len(r) - 1]
    return [(int(r[a]), int(a), int(b)) for a, b in zip(starts, ends)]


def final_coast_and_brake(t: np.ndarray, regime: np.ndarray) -> tuple[float, float]:
    """Durations (s) of the final brake (the last braking block, to the stop) and of the coast
    before it (the coasting rows after the last traction or cruising row and before that
    brake; a brake for a limit inside it does not count), from the driver's regime per row,
    each row standing for the step that follows it."""
    r = np.asarray(regime).astype(int)
    dt = np.r_[np.diff(t), 0.0]
    bl = blocks(r)
    last_brake = next((b for b in reversed(bl) if b[0] == 4), None)
    if last_brake is None:
        return float("nan"), float("nan")
    brake = float(dt[last_brake[1]:last_brake[2] + 1].sum())
    before = r[:last_brake[1]]
    pulling = np.flatnonzero((before == 1) | (before == 2))
    k0 = pulling[-1] + 1 if len(pulling) else 0
    coast = float(dt[k0:last_brake[1]][before[k0:] == 3].sum())
    return coast, brake


class TrainResistance(Study):
    """Cunillera et al. (2022) on simulated runs: every estimator's resistance, the truth, the
    paper's figures per run and over a Monte Carlo."""
    default_variant = DEFAULT_VARIANT
    roles = ROLES
    figures_of_signals = PLOTS
    summary_metrics = ("*.speed_rmse_kmh", "*.position_rmse_m", "*.resistance_rel_error", "*.r?_rel_error",
                       "*.seconds", "*_share_max", "*regime_accuracy", "*max_power_rel_error", "*max_effort_rel_error",
                       "*cruise_speed_error_kmh", "*brake_rate_error*", "truth.cruise_target_kmh",
                       "truth.final_coast_min", "truth.final_brake_s", "truth.share_*", "wall_time_s")

    # ---- per run -----------------------------------------------------------------------------
    def bind(self, system) -> dict:
        """The roles, and the check that every observer of the GNSS samples at its period (a
        ``--set gnss.sample_period`` alone would leave the observers at the old one)."""
        roles = super().bind(system)
        period = float(roles["gnss_period"])
        for o in system.observers:
            own = o.period if o.period is not None else system.step_size
            if any(s.startswith("gnss.") for s in o.measurements.values()) and abs(own - period) > 1e-9 * period:
                raise UserError(f"{system.source or system.name}: Observer {o.name!r} samples every {own:g} s but "
                                f"the GNSS fixes come every {period:g} s: set {o.name}.samplePeriod={period:g} too")
        return roles

    def metrics(self, run: RunData) -> dict:
        sig, est, roles = run.signals, run.estimates, run.roles
        t = np.asarray(est["time"])
        n = len(t)
        fixes = np.flatnonzero(np.asarray(sig[roles["fix"]])[:n] != 0)[1:]  # the first is the initial state
        last = n - 1
        r_true = np.array([float(sig[roles[k]][last]) for k in ("r0", "r1", "r2")])
        out: dict = {}
        for name in estimators_of(est):
            r_hat = np.array([float(est[f"{name}.{k}"][last]) for k in ("r0", "r1", "r2")])
            e_v = (np.asarray(est[f"{name}.v"])[fixes] - np.asarray(sig[roles["v"]])[fixes]) / KMH
            e_s = np.asarray(est[f"{name}.s"])[fixes] - np.asarray(sig[roles["s"]])[fixes]
            out[name] = {
                "speed_rmse_kmh": float(np.sqrt(np.mean(e_v * e_v))),
                "position_rmse_m": float(np.sqrt(np.mean(e_s * e_s))),
                "resistance_rel_error": resistance_rel_error(r_hat, r_true),
                **{f"r{i}_rel_error": float((r_hat[i] - r_true[i]) / r_true[i]) for i in range(3)},
                **{f"r{i}_final": float(r_hat[i]) for i in range(3)},
                **term_shares(est, name, fixes),
                "seconds": float(run.base["observers"].get(name, {}).get("wall_time_s", float("nan"))),
            }
        out["truth"] = self._truth(run, r_true)
        return out

    @staticmethod
    def _truth(run: RunData, r_true: np.ndarray) -> dict:
        sig, roles = run.signals, run.roles
        t = np.asarray(sig["time"])
        regime = np.asarray(sig[roles["regime"]]).astype(int)
        dt = np.r_[np.diff(t), 0.0]
        moving_time = float(t[-1] - t[0])
        coast, brake = final_coast_and_brake(t, regime)
        vc = float(sig[roles["cruise_target"]][0])
        return {
            **{f"r{i}": float(r_true[i]) for i in range(3)},
            "run_time_s": moving_time, "max_power_w": float(roles["max_power"]), "top_speed_kmh": float(np.max(sig[roles["v"]]) / KMH),
            "cruise_target_kmh": vc / KMH, "cruise_above_140": float(vc / KMH > 140.0),
            "cycles": float(sig[roles["cycles"]][0]), "traction_fraction": float(sig[roles["traction_fraction"]][0]),
            **{f"brake_rate_{k}": float(sig[roles[f"brake_rate_{k}"]][0]) for k in range(1, 6)},
            "final_coast_min": coast / 60.0, "final_brake_s": brake,
            **{f"share_{REGIMES[c]}": float(dt[regime == c].sum() / moving_time) for c in (1, 2, 3, 4)},
        }

    def series(self, run: RunData) -> dict[str, np.ndarray]:
        """What a Monte Carlo member brings back for the study's figures, at its GNSS fixes
        (float32): position, the GNSS speed, and per estimator the applied power it computed
        (effort x estimated speed x gamma m, W) in the initial traction (Fig. 9: the driver's
        traction regime before its first non-traction one); the true power there too."""
        sig, est, roles = run.signals, run.estimates, run.roles
        n = len(est["time"])
        fixes = np.flatnonzero(np.asarray(sig[roles["fix"]])[:n] != 0)
        regime = np.asarray(sig[roles["regime"]]).astype(int)
        first_other = next((k for k in range(len(regime)) if regime[k] != 1), len(regime))
        m_eff = float(roles["gamma"]) * (float(roles["tare_mass"]) + float(roles["load_mass"]))
        initial = fixes[fixes < first_other]
        out = {"position": sig[roles["gnss_position"]][fixes], "speed_kmh": sig[roles["gnss_speed"]][fixes] / KMH,
               "traction_speed_kmh": sig[roles["v"]][initial] / KMH, "traction_power_true": sig[roles["power"]][initial]}
        for name in estimators_of(est):
            out[f"{name}.traction_speed_kmh"] = est[f"{name}.v"][initial] / KMH
            out[f"{name}.traction_power"] = m_eff * est[f"{name}.effort"][initial] * est[f"{name}.v"][initial] \
                if f"{name}.effort" in est else np.full(len(initial), np.nan)
        return {k: np.asarray(v, dtype=np.float32) for k, v in out.items()}

    def figures(self, run: RunData, out: Path) -> list[str]:
        from . import figures

        return figures.run_figures(run, out)

    def report_md(self, metrics: dict) -> str:
        names = [k for k, v in metrics.items() if isinstance(v, dict) and "resistance_rel_error" in v]
        L = ["## Running resistance at the end of the run", "",
             "| estimator | speed rmse [km/h] | position rmse [m] | resistance rel. error (40-140 km/h) | "
             "r0 rel. | r1 rel. | r2 rel. | wall [s] |", "|---|---|---|---|---|---|---|---|"]
        L += [f"| {n} | {_row(metrics[n])} |" for n in names]
        tr = metrics["truth"]
        L += ["", f"True at the end: r0 = {tr['r0']:.5g} N/kg, r1 = {tr['r1']:.4g} N/(kg m/s), "
              f"r2 = {tr['r2']:.4g} N/(kg (m/s)^2).", "",
              "## The run (driver's truth) beside the paper's Fig. 3 run", "",
              "| | this run | Cunillera et al. (2022), Fig. 3 |", "|---|---|---|"]
        for regime, share in PAPER["shares"].items():
            L.append(f"| {regime} [% of the run time] | {100 * tr[f'share_{regime}']:.1f} | {100 * share:.1f} |")
        L += [f"| cruise target [km/h] | {tr['cruise_target_kmh']:.1f} | - |",
              f"| final coast [min] | {tr['final_coast_min']:.2f} | 2.5-10 over its 67 runs (Fig. 7) |",
              f"| final brake [s] | {tr['final_brake_s']:.0f} | - |"]
        for n in names:
            L += [f"| largest share of r1 v in r(v), {n} [%] | {100 * metrics[n]['linear_share_max']:.0f} | "
                  f"{100 * PAPER['linear_share_max']:.0f} (Fig. 5) |",
                  f"| largest share of r2 v^2 in r(v), {n} [%] | {100 * metrics[n]['quadratic_share_max']:.0f} | "
                  f"{100 * PAPER['quadratic_share_max']:.0f} (Fig. 5) |"]
        L += ["", observers_md(metrics)]
        return "\n".join(L)

    def table_md(self, table: dict[str, dict]) -> str:
        L = ["| variant | estimator | speed rmse [km/h] | position rmse [m] | resistance rel. error | r0 rel. | "
             "r1 rel. | r2 rel. | wall [s] |", "|---|---|---|---|---|---|---|---|---|"]
        for variant, m in table.items():
            L += [f"| {variant} | {n} | {_row(m[n])} |" for n, v in m.items()
                  if isinstance(v, dict) and "resistance_rel_error" in v]
        return "\n".join(L)

    def summary_md(self, summary: dict[str, dict[str, dict]], runs: int) -> str:
        L = [super().summary_md(summary, runs), "", "## Beside Cunillera et al. (2022) (67 NS runs, VIRM-VI)", "",
             "| variant | quantity | this study (driver's truth / estimates) | Cunillera et al. (2022) |",
             "|---|---|---|---|"]
        for variant, s in summary.items():
            def stat(key, k="p50", scale=1.0, fmt=".3g"):
                return format(s[key][k] * scale, fmt) if key in s else "-"

            def cv(key):
                return f"{s[key]['std'] / s[key]['mean']:.2f}" if key in s and s[key]["mean"] else "-"
            for name in sorted({k.split(".")[0] for k in s if k.endswith(".r0_final")}):
                L.append(f"| {variant} | {name}: final r0, min-max [N/kg] | "
                         f"{_pct(s, f'{name}.r0_final')} (true median {stat('truth.r0', fmt='.5f')}) | "
                         f"{PAPER['r0_bounds']} |")
                for term, what in (("linear", "r1 v"), ("quadratic", "r2 v^2")):
                    L.append(f"| {variant} | {name}: largest share of {what} in r(v), median | "
                             f"{stat(f'{name}.{term}_share_max', scale=100, fmt='.0f')} % | "
                             f"{100 * PAPER[f'{term}_share_max']:.0f} % (Fig. 5) |")
            L += [f"| {variant} | runs cruising above 140 km/h | {stat('truth.cruise_above_140', 'mean', 100, '.0f')} % | "
                  f"{100 * PAPER['above_140']:.0f} % |",
                  f"| {variant} | final coast [min], min-max | {stat('truth.final_coast_min', 'min', fmt='.1f')}-"
                  f"{stat('truth.final_coast_min', 'max', fmt='.1f')} | {PAPER['coast_min'][0]}-{PAPER['coast_min'][1]} |",
                  f"| {variant} | CV of the final brake time | {cv('truth.final_brake_s')} | {PAPER['brake_cv']:.2f} |",
                  f"| {variant} | CV of the final coast time | {cv('truth.final_coast_min')} | {PAPER['coast_cv']:.2f} |"]
            for regime, share in PAPER["shares"].items():
                L.append(f"| {variant} | {regime} share of the run time, median | "
                         f"{stat(f'truth.share_{regime}', scale=100, fmt='.1f')} % | {100 * share:.1f} % (its Fig. 3 run) |")
        L += ["", "The paper's resistance is that of a VIRM-VI; ours is the published KISS Davis law (the "
              "estimators start from it), so compare spreads, not values."]
        return "\n".join(L)

    def study_figures(self, table: dict, series: dict, out: Path) -> list[str]:
        from . import figures

        return figures.study_figures(table, series, out)


def _pct(s: dict, key: str) -> str:
    if key not in s:
        return "-"
    return f"{s[key]['min']:.5f}-{s[key]['max']:.5f} (p50 {s[key]['p50']:.5f}, p95 {s[key]['p95']:.5f})"


def _row(e: dict) -> str:
    return (f"{e['speed_rmse_kmh']:.3f} | {e['position_rmse_m']:.2f} | {e['resistance_rel_error']:.4f} | "
            f"{e['r0_rel_error']:+.4f} | {e['r1_rel_error']:+.4f} | {e['r2_rel_error']:+.4f} | {e['seconds']:.3f}")


STUDY = TrainResistance(__doc__.strip().splitlines()[0])
