"""The study's fleet calibration: a variant's runs as the runs of one unit (seed order), each
estimator's per-run posteriors pooled and tested for a change
(:mod:`railfmu.estimators.train.fleet`), r(v) against the truth of the last run."""

from __future__ import annotations

import numpy as np

from railfmu.estimators.train.fleet import change_test, resistance_band
from railfmu.experiments.train_resistance.scores import KMH

#: the speeds the pooled r(v) is given at: 40-140 km/h
FLEET_SPEEDS_KMH = np.arange(40.0, 141.0, 10.0)


def fleet_table(runs: dict) -> dict:
    """Per estimator with ``theta_cov`` in its runs' metrics: the pooled r0-r2 (of the runs
    since the last flagged change), their sigmas, r(v) with its sigma and its relative error
    against the last run's true r(v) at 40-140 km/h (max over the grid), and the change test
    (seeds of flagged runs, the first)."""
    seeds = sorted(runs, key=int)
    names = sorted({n for s in seeds for n, m in runs[s].items() if isinstance(m, dict) and "theta_cov" in m})
    out = {}
    for n in names:
        ok = [s for s in seeds if "theta_cov" in runs[s].get(n, {})]
        th = [np.array([runs[s][n][f"r{i}_final"] for i in range(3)]) for s in ok]
        cov = [np.array(runs[s][n]["theta_cov"]) for s in ok]
        first = runs[ok[0]][n]  # the prior each run holds once (F1)
        res = change_test(th, cov, first.get("theta_prior"), first.get("theta_prior_cov"))
        v = FLEET_SPEEDS_KMH * KMH
        r, sd = resistance_band(res["theta"], res["cov"], v)
        tr = runs[ok[-1]]["truth"]
        r_true = tr["r0"] + tr["r1"] * v + tr["r2"] * v * v
        out[n] = {"runs": len(ok), "since_seed": int(ok[res["since_run"]]),
                  **{f"r{i}": float(res["theta"][i]) for i in range(3)},
                  **{f"r{i}_sigma": float(np.sqrt(res["cov"][i, i])) for i in range(3)},
                  "speed_kmh": FLEET_SPEEDS_KMH.tolist(), "r_v": r.tolist(), "r_v_sigma": sd.tolist(),
                  "r_v_rel_error": ((r - r_true) / r_true).tolist(),
                  "r_v_max_abs_rel_error": float(np.max(np.abs((r - r_true) / r_true))),
                  "change_flagged": bool(res["flagged_runs"]),
                  "flagged_seeds": [int(ok[k]) for k in res["flagged_runs"]],
                  "first_flag_seed": int(ok[res["first_flag"]]) if res["first_flag"] is not None else None,
                  "chi2": res["chi2"], "cusum": res["cusum"]}
    return out


def fleet_md(variant: str, name: str, f: dict) -> str:
    """One estimator's fleet calibration as a markdown paragraph."""
    flag = (f"change flagged at seed(s) {', '.join(map(str, f['flagged_seeds']))}" if f["change_flagged"]
            else "no change flagged")
    return (f"Fleet ({variant}, {name}, {f['runs']} runs, pooled since seed {f['since_seed']}): "
            f"r0 = {f['r0']:.5g} +- {f['r0_sigma']:.2g} N/kg, r1 = {f['r1']:.4g} +- {f['r1_sigma']:.2g}, "
            f"r2 = {f['r2']:.4g} +- {f['r2_sigma']:.2g}; r(v) within {100 * f['r_v_max_abs_rel_error']:.2f} % "
            f"of the last run's truth over 40-140 km/h; {flag}.\n")
