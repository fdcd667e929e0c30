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

and, for an estimator that outputs its acceleration and effort, the driving regimes and
features (:func:`regime_scores`), read by the recogniser the estimator names
(:func:`regime_recognisers`: ``improved`` the hidden Markov model over the run, the
paper's UKFs the paper's rules), with its name as ``regime_recogniser``;
and ``truth``: the run's true r0-r2 at the end, the driver's style (cruise target, brake
rate per ATB-EG step, cycles), the run time, top speed, and from the driver's regime the
shares of traction, cruising, coasting and braking in the run time and the final coast and
brake durations (the quantities of the paper's Figs. 3 and 7).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railfmu.experiments.engine.study_protocol import RunData, Study, observers_md
from railfmu.experiments.train_resistance.scores import (
    finite_or_none,
    hold_offline,
    format_or_dash,
    DEFAULT_VARIANT,
    estimators_of,
    KMH,
    mass_effective,
    PAPER,
    PLOTS,
    regime_recognisers,
    regime_scores,
    REGIMES,
    resistance_rel_error,
    ROLES,
    term_shares,
)
from railfmu.models.errors import UserError

class TrainResistance(Study):
    """Cunillera et al. (2022) on simulated runs: every estimator's resistance, the truth, the
    paper's figures per run and over a Monte Carlo."""
    default_variant = DEFAULT_VARIANT
    roles = ROLES
    figures_of_signals = PLOTS
    summary_metrics = ("*.speed_rmse_kmh", "*.position_rmse_m", "*.resistance_rel_error", "*.r?_rel_error",
                       "*.seconds", "*_share_max", "*regime_accuracy", "*max_power_rel_error", "*max_effort_rel_error",
                       "*cruise_speed_error_kmh", "*brake_rate_error*", "*.features.max_power_w",
                       "*.features.cruise_speed_kmh", "*.features.final_*", "truth.cruise_target_kmh",
                       "truth.final_coast_min", "truth.final_brake_s", "truth.share_*", "wall_time_s")

    # ---- per run -----------------------------------------------------------------------------
    def bind(self, system) -> dict:
        """The roles, and the check that every observer of the GNSS samples at its period (a
        ``--set gnss.sample_period`` alone would leave the observers at the old one)."""
        roles = super().bind(system)
        roles["regime_recognisers"] = regime_recognisers(system)
        period = float(roles["gnss_period"])
        if system.stop_time - system.start_time < period:  # the fix at the start is the initial state
            raise UserError(f"{system.source or system.name}: the run ({system.stop_time - system.start_time:g} s) "
                            f"ends before its first GNSS fix after the start (every {period:g} s): nothing to "
                            f"estimate or score; give a stop time of at least {period:g} s")
        for o in system.observers:
            own = o.period if o.period is not None else system.step_size
            if any(s.startswith("gnss.") for s in o.measurements.values()) and abs(own - period) > 1e-9 * period:
                raise UserError(f"{system.source or system.name}: Observer {o.name!r} samples every {own:g} s but "
                                f"the GNSS fixes come every {period:g} s: set {o.name}.samplePeriod={period:g} too")
        return roles

    def metrics(self, run: RunData) -> dict:
        sig, est, roles = run.signals, hold_offline(run.estimates), run.roles
        t = np.asarray(est["time"])
        n = len(t)
        fixes_all = np.flatnonzero(np.asarray(sig[roles["fix"]])[:n] != 0)
        fixes = fixes_all[1:]  # the first is the initial state
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
            if f"{name}.acceleration" in est and f"{name}.effort" in est and len(fixes_all) >= 2:
                out[name].update(regime_scores(run, name, fixes_all)[0])
            obs = run.observers.get(name) if run.observers else None
            if getattr(obs, "prior_cov", None) is not None:  # the run's posterior and prior, for the fleet
                out[name]["theta_cov"] = np.asarray(obs.theta_cov, float).tolist()
                out[name]["theta_prior"] = np.asarray(obs.theta0, float).tolist()
                out[name]["theta_prior_cov"] = np.asarray(obs.prior_cov, float).tolist()
        out["truth"] = self._truth(run, r_true)
        return out

    @staticmethod
    def _truth(run: RunData, r_true: np.ndarray) -> dict:
        """The run's true resistance, the driver's style and, by the paper's definitions on the
        driver's exact steps (:func:`railfmu.estimators.train.driving_regimes.reference_features`), the shares
        of the regimes in the running time (standstill left out), the final coast and brake
        durations and the applied brake rate per ATB-EG step."""
        from railfmu.estimators.train.driving_regimes import reference_features, true_regimes

        sig, roles = run.signals, run.roles
        t, v, f = (np.asarray(sig[k]) for k in ("time", roles["v"], roles["effort"]))
        regime = true_regimes(t, v, f)
        dt = np.r_[np.diff(t), 0.0]
        running = float(dt[regime != 0].sum())
        ref = reference_features(t, v, f, mass_effective(run))
        vc = float(sig[roles["cruise_target"]][0])
        return {
            **{f"r{i}": float(r_true[i]) for i in range(3)},
            "mass_kg": float(np.asarray(sig[roles["mass"]])[0]),  # the run's load (a variant may draw it)
            "run_time_s": float(t[-1] - t[0]), "running_time_s": running, "max_power_w": float(roles["max_power"]),
            "top_speed_kmh": float(np.max(v) / KMH),
            "cruise_target_kmh": vc / KMH, "cruise_above_140": float(vc / KMH > 140.0),
            "cycles": float(sig[roles["cycles"]][0]), "traction_fraction": float(sig[roles["traction_fraction"]][0]),
            **{f"brake_rate_{k}": float(sig[roles[f"brake_rate_{k}"]][0]) for k in range(1, 6)},
            **{f"applied_brake_rate_{k}": finite_or_none(ref["brake_rates"][k - 1]) for k in range(1, 6)},
            "final_coast_min": finite_or_none(ref["final_coast_duration"] / 60.0),
            "final_brake_s": finite_or_none(ref["final_brake_duration"]),
            **{f"share_{REGIMES[c]}": float(dt[regime == c].sum() / running) for c in (1, 2, 3, 4)},
        }

    def series(self, run: RunData) -> dict[str, np.ndarray]:
        """What a Monte Carlo member brings back for the study's figures (float32): at its GNSS
        fixes the position and GNSS speed (Fig. 2); per estimator the traction power samples
        of the initial acceleration (mid speed in km/h, power in W; Fig. 9) and the braking
        samples (mid speed, deceleration, ATB-EG step; Fig. 8) of its recognised regimes."""
        sig, est, roles = run.signals, hold_offline(run.estimates), run.roles
        n = len(est["time"])
        fixes = np.flatnonzero(np.asarray(sig[roles["fix"]])[:n] != 0)
        out = {"position": sig[roles["gnss_position"]][fixes], "speed_kmh": sig[roles["gnss_speed"]][fixes] / KMH}
        m_eff = mass_effective(run)
        for name in estimators_of(est):
            if f"{name}.acceleration" not in est or len(fixes) < 2:
                continue
            feats = regime_scores(run, name, fixes)[1]
            p, b = feats["power_samples"], feats["brake_samples"]
            out[f"{name}.power_speed_kmh"] = p["speed"][p["initial"]] / KMH
            out[f"{name}.power_w"] = p["power"][p["initial"]] * m_eff
            out[f"{name}.brake_speed_kmh"] = b["speed"] / KMH
            out[f"{name}.brake_deceleration"] = b["deceleration"]
            out[f"{name}.brake_step"] = b["step"]
        return {k: np.asarray(v, dtype=np.float32) for k, v in out.items()}

    def figures(self, run: RunData, out: Path) -> list[str]:
        from railfmu.experiments.train_resistance import figures

        hold_offline(run.estimates)
        return figures.run_figures(run, out)

    def report_md(self, metrics: dict) -> str:
        names = [k for k, v in metrics.items() if isinstance(v, dict) and "resistance_rel_error" in v]
        L = ["## Running resistance at the end of the run", "",
             "| estimator | speed rmse [km/h] | position rmse [m] | resistance rel. error (40-140 km/h) | "
             "r0 rel. | r1 rel. | r2 rel. | wall [s] |", "|---|---|---|---|---|---|---|---|"]
        L += [f"| {n} | {_row(metrics[n])} |" for n in names]
        tr = metrics["truth"]
        L += ["", f"True at the end: r0 = {tr['r0']:.5g} N/kg, r1 = {tr['r1']:.4g} N/(kg m/s), "
              f"r2 = {tr['r2']:.4g} N/(kg (m/s)^2).", ""]
        scored = [n for n in names if "regime_accuracy" in metrics[n]]
        if scored:
            L += ["## Driving regimes and features (§3.2-3.3)", "",
                  "| estimator | recogniser | regime accuracy | max. power rel. error | max. effort rel. error | "
                  "cruise speed error [km/h] | brake rate error per ATB-EG step [m/s2] |", "|---|---|---|---|---|---|---|"]
            L += [f"| {n} | {metrics[n].get('regime_recogniser', 'paper')} | {format_or_dash(metrics[n]['regime_accuracy'], '.3f')} | "
                  f"{format_or_dash(metrics[n]['max_power_rel_error'], '.4f')} | "
                  f"{format_or_dash(metrics[n]['max_effort_rel_error'], '.4f')} | {format_or_dash(metrics[n]['cruise_speed_error_kmh'], '.2f')} | "
                  f"{', '.join(format_or_dash(e, '+.3f') for e in metrics[n]['brake_rate_error'])} |" for n in scored]
            L.append("")
        head = " | ".join(f"{n} (recognised)" for n in scored)
        L += ["## The run beside the paper's Fig. 3 run", "",
              f"| | truth | {head + ' | ' if head else ''}Cunillera et al. (2022) |",
              "|---|---|" + "---|" * len(scored) + "---|"]
        for regime, share in PAPER["shares"].items():
            rec = "".join(f"{100 * metrics[n]['regime_share'][regime]:.1f} | " for n in scored)
            L.append(f"| {regime} [% of the running time] | {100 * tr[f'share_{regime}']:.1f} | {rec}{100 * share:.1f} |")
        feats = [metrics[n]["features"] for n in scored]
        L += [f"| cruise speed [km/h] | {tr['cruise_target_kmh']:.1f} (target) | "
              + "".join(f"{format_or_dash(f['cruise_speed_kmh'], '.1f')} | " for f in feats) + "- |",
              f"| final coast [min] | {format_or_dash(tr['final_coast_min'], '.2f')} | "
              + "".join(f"{format_or_dash(f['final_coast_min'], '.2f')} | " for f in feats) + "2.5-10 over its 67 runs (Fig. 7) |",
              f"| final brake [s] | {format_or_dash(tr['final_brake_s'], '.0f')} | "
              + "".join(f"{format_or_dash(f['final_brake_s'], '.0f')} | " for f in feats) + "- |"]
        for term, what in (("linear", "r1 v"), ("quadratic", "r2 v^2")):
            L.append(f"| largest share of {what} in r(v) [%] | - | "
                     + "".join(f"{100 * metrics[n][f'{term}_share_max']:.0f} | " for n in scored)
                     + f"{100 * PAPER[f'{term}_share_max']:.0f} (Fig. 5) |")
        L += ["", "Truth: the paper's regime definitions on the driver's exact 1 s steps "
              "(railfmu.estimators.train.driving_regimes.reference_features); the cruise speed is the driver's target.",
              "", observers_md(metrics)]
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
             "| variant | quantity | truth | " + "estimators (recognised regimes and features) | "
             "Cunillera et al. (2022) |", "|---|---|---|---|---|"]
        for variant, s in summary.items():
            def stat(key, k="p50", scale=1.0, fmt=".3g"):
                return format(s[key][k] * scale, fmt) if key in s else "-"

            def cv(key):
                return f"{s[key]['std'] / s[key]['mean']:.2f}" if key in s and s[key]["mean"] else "-"

            names = sorted({k.split(".")[0] for k in s if k.endswith(".r0_final")})

            def each(fn):
                return "; ".join(f"{n}: {fn(n)}" for n in names) or "-"
            rows = [
                ("final r0, min-max [N/kg]", f"median {stat('truth.r0', fmt='.5f')}",
                 each(lambda n: _pct(s, f"{n}.r0_final")), PAPER["r0_bounds"]),
                ("largest share of r1 v in r(v), median", "-", each(lambda n: stat(f"{n}.linear_share_max", scale=100,
                                                                                   fmt=".0f") + " %"),
                 f"{100 * PAPER['linear_share_max']:.0f} % (Fig. 5)"),
                ("largest share of r2 v^2 in r(v), median", "-",
                 each(lambda n: stat(f"{n}.quadratic_share_max", scale=100, fmt=".0f") + " %"),
                 f"{100 * PAPER['quadratic_share_max']:.0f} % (Fig. 5)"),
                ("runs cruising above 140 km/h", f"{stat('truth.cruise_above_140', 'mean', 100, '.0f')} %",
                 each(lambda n: stat(f"{n}.features.cruise_above_140", "mean", 100, ".0f") + " %"),
                 f"{100 * PAPER['above_140']:.0f} %"),
                ("final coast [min], min-max",
                 f"{stat('truth.final_coast_min', 'min', fmt='.1f')}-{stat('truth.final_coast_min', 'max', fmt='.1f')}",
                 each(lambda n: f"{stat(f'{n}.features.final_coast_min', 'min', fmt='.1f')}-"
                                f"{stat(f'{n}.features.final_coast_min', 'max', fmt='.1f')}"),
                 f"{PAPER['coast_min'][0]}-{PAPER['coast_min'][1]}"),
                ("CV of the final brake time", cv("truth.final_brake_s"),
                 each(lambda n: cv(f"{n}.features.final_brake_s")), f"{PAPER['brake_cv']:.2f}"),
                ("CV of the final coast time", cv("truth.final_coast_min"),
                 each(lambda n: cv(f"{n}.features.final_coast_min")), f"{PAPER['coast_cv']:.2f}"),
            ]
            for regime, share in PAPER["shares"].items():
                rows.append((f"{regime} share of the running time, median",
                             f"{stat(f'truth.share_{regime}', scale=100, fmt='.1f')} %",
                             each(lambda n: stat(f"{n}.regime_share.{regime}", scale=100, fmt=".1f") + " %"),
                             f"{100 * share:.1f} % (its Fig. 3 run)"))
            L += [f"| {variant} | {q} | {t} | {e} | {p} |" for q, t, e, p in rows]
        L += ["", "The paper's resistance is that of a VIRM-VI; ours is the published KISS Davis law (the "
              "estimators start from it), so compare spreads, not values. Truth: the driver's style and the "
              "paper's regime definitions on its exact 1 s steps."]
        return "\n".join(L)

    def study_tables(self, table: dict, series: dict) -> str:
        """Fleet calibration (:func:`railfmu.experiments.train_resistance.fleet.fleet_table`) of every
        variant whose runs carry a posterior covariance: each variant's runs taken as the runs of
        one unit, in seed order; added to the table as ``fleet``."""
        from railfmu.experiments.train_resistance.fleet import fleet_md, fleet_table

        L = []
        for variant, t in table.items():
            for name, f in fleet_table(t["runs"]).items():
                t.setdefault("fleet", {})[name] = f
                L.append(fleet_md(variant, name, f))
        return "\n".join(L)

    def study_figures(self, table: dict, series: dict, out: Path) -> list[str]:
        from railfmu.experiments.train_resistance import figures

        return figures.study_figures(table, series, out)


def _pct(s: dict, key: str) -> str:
    if key not in s:
        return "-"
    return f"{s[key]['min']:.5f}-{s[key]['max']:.5f} (p50 {s[key]['p50']:.5f}, p95 {s[key]['p95']:.5f})"


def _row(e: dict) -> str:
    return (f"{e['speed_rmse_kmh']:.3f} | {e['position_rmse_m']:.2f} | {e['resistance_rel_error']:.4f} | "
            f"{e['r0_rel_error']:+.4f} | {e['r1_rel_error']:+.4f} | {e['r2_rel_error']:+.4f} | {e['seconds']:.3f}")


STUDY = TrainResistance(__doc__.strip().splitlines()[0])
