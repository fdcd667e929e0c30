"""The figures of Cunillera et al. (2022) for one run (Figs. 3, 5, 6) and over a Monte Carlo
study (Figs. 2, 4, 7, 8, 9), with the ground truth the paper did not have.

Only the runner (a run that writes files) and the study client import this module: a Monte
Carlo member does not load matplotlib.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railfmu.experiments.engine.plots import _pyplot
from railfmu.models.train.longitudinal import R0, R1, R2

from railfmu.experiments.train_resistance.scores import ATB_EG, KMH, REGIME_COLOURS, REGIMES, estimators_of, mass_effective

COLOURS = ("C3", "C2", "C1", "C5")  # per estimator, in SSD order
PUBLISHED = (R0, R1, R2)  # the estimators' default start: the 35 %-load mass-specific KISS values


def _save(fig, out: Path, fname: str) -> str:
    fig.tight_layout()
    fig.savefig(out / fname, dpi=110)
    _pyplot().close(fig)
    return fname


def _fixes(run) -> np.ndarray:
    n = len(run.estimates["time"])
    return np.flatnonzero(np.asarray(run.signals[run.roles["fix"]])[:n] != 0)


def run_figures(run, out: Path) -> list[str]:
    sig, est, roles = run.signals, run.estimates, run.roles
    plt = _pyplot()
    t, fx = np.asarray(sig["time"]), _fixes(run)
    names = estimators_of(est)
    files = []

    # Fig. 3: speed, acceleration, effort, r0-r2 with the truth
    m_eff = mass_effective(run)
    v_env = np.linspace(0.1, max(np.max(sig[roles["v"]]), 1.0), 200)
    f_max = np.minimum(float(roles["max_traction_force"]), float(roles["max_power"]) / v_env) / m_eff
    fig, ax = plt.subplots(6, 1, figsize=(9, 14), sharex=True)
    ax[0].plot(t[fx], sig[roles["gnss_speed"]][fx] / KMH, "b.", ms=3, label="GNSS speed")
    ax[0].plot(t, sig[roles["v"]] / KMH, "k-", lw=0.8, label="true speed")
    for name, c in zip(names, COLOURS):
        ax[0].plot(t[fx], est[f"{name}.v"][fx] / KMH, "-", color=c, lw=1, label=f"{name}")
        if f"{name}.acceleration" in est:
            ax[1].plot(t[fx], est[f"{name}.acceleration"][fx], ".", color=c, ms=3, label=name)
            ax[2].plot(t[fx], est[f"{name}.effort"][fx], ".", color=c, ms=3, label=name)
    ax[0].set_ylabel("speed [km/h]")
    ax[1].plot(t, sig[roles["acceleration"]], "k-", lw=0.6, label="true")
    ax[1].axhline(-float(roles["max_deceleration"]), color="k", ls="--", lw=0.8, label="-b_max")
    ax[1].set_ylabel("acceleration [m/s2]")
    ax[2].plot(t, sig[roles["effort"]], "k-", lw=0.6, label="true f_t - f_b")
    ax[2].plot(t, np.interp(sig[roles["v"]], v_env, f_max), "k--", lw=0.8, label="max. tractive effort at v")
    ax[2].set_ylabel("effort [N/kg]")
    for k, unit in enumerate(("N/kg", "N/(kg m/s)", "N/(kg (m/s)^2)")):
        a = ax[3 + k]
        a.plot(t, sig[roles[f"r{k}"]], "b--", lw=1, label="true")
        for name, c in zip(names, COLOURS):
            a.plot(t[fx], est[f"{name}.r{k}"][fx], "-", color=c, lw=1, label=name)
        a.set_ylabel(f"r{k} [{unit}]")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7, loc="upper right")
    ax[0].set_title("Estimates on one run (Fig. 3 of Cunillera et al. (2022)), with the truth")
    ax[-1].set_xlabel("time [s]")
    files.append(_save(fig, out, "fig3_run.png"))

    # Fig. 5: stacked resistance terms of the first estimator along the run, line term beside
    if names:
        name = names[0]
        v = np.maximum(est[f"{name}.v"][fx], 0.0)
        terms = [est[f"{name}.r0"][fx], est[f"{name}.r1"][fx] * v, est[f"{name}.r2"][fx] * v * v]
        fig, ax = plt.subplots(figsize=(9, 4))
        ax.stackplot(t[fx], *terms, labels=["r0", "r1 v", "r2 v^2"], colors=["navy", "plum", "lightblue"])
        ax.plot(t, sig[roles["line_term"]], color="m", lw=1, label="line term g(s)")
        ax.set_ylabel("[N/kg]")
        ax.set_xlabel("time [s]")
        ax.legend(fontsize=8, loc="upper left")
        ax.grid(alpha=0.3)
        ax.set_title(f"Running resistance terms ({name}) and the line term (Fig. 5 of Cunillera et al. (2022))")
        files.append(_save(fig, out, "fig5_resistance_terms.png"))

    # Fig. 6: regimes along the run: the truth on the driver's steps, each estimator's recognised ones at its fixes
    from railfmu.estimators.train.driving_regimes import true_regimes

    from railfmu.experiments.train_resistance.scores import regime_scores

    panels = [("truth (the paper's definitions on the driver's 1 s steps)", t,
               true_regimes(t, sig[roles["v"]], sig[roles["effort"]]), sig[roles["v"]] / KMH)]
    for name in names:
        if f"{name}.acceleration" in est and len(fx) >= 2:
            panels.append((f"{name}: recognised at the GNSS fixes", t[fx],
                           np.asarray(regime_scores(run, name, fx)[1]["regimes"]), est[f"{name}.v"][fx] / KMH))
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 2.8 * len(panels)), sharex=True, squeeze=False)
    for ax, (title, tt, regime, v) in zip(axes[:, 0], panels):
        for code, label in REGIMES.items():
            sel = regime == code
            if sel.any():
                ax.scatter(tt[sel], v[sel], s=4, color=REGIME_COLOURS[code], label=label)
        ax.set_ylabel("speed [km/h]")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7, markerscale=3, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle("Driving regimes along the run (Fig. 6 of Cunillera et al. (2022))", fontsize=10)
    files.append(_save(fig, out, "fig6_regimes.png"))
    return files


def study_figures(table: dict, series: dict, out: Path) -> list[str]:
    """Figs. 2, 4, 7, 8 and 9 per variant over its members (file names carry the variant)."""
    plt = _pyplot()
    files = []
    for variant, t in table.items():
        runs, ser = t["runs"], series.get(variant, {})
        seeds = sorted(runs)
        names = sorted({k[:-len(".r0_final")] for m in runs.values() for k in _flat_names(m)
                        if k.endswith(".r0_final")})

        # Fig. 2: every speed profile
        fig, ax = plt.subplots(figsize=(9, 4))
        for s in seeds:
            if "position" in ser.get(s, {}):
                ax.plot(ser[s]["position"] / 1e3, ser[s]["speed_kmh"], lw=0.6, alpha=0.7)
        ax.set_xlabel("position [km]")
        ax.set_ylabel("GNSS speed [km/h]")
        ax.grid(alpha=0.3)
        ax.set_title(f"{variant}: the {len(seeds)} speed profiles (Fig. 2 of Cunillera et al. (2022))")
        files.append(_save(fig, out, f"fig2_speed_profiles_{variant}.png"))

        # Fig. 4: final r0, r1, r2 per estimator, the true values beside
        fig, ax = plt.subplots(1, 3, figsize=(12, 3.6))
        for k in range(3):
            true = np.array([runs[s]["truth"][f"r{k}"] for s in seeds])
            est = {name: np.array([runs[s][name][f"r{k}_final"] for s in seeds if name in runs[s]]) for name in names}
            bins = np.linspace(min(true.min(), *(e.min() for e in est.values())),
                               max(true.max(), *(e.max() for e in est.values())), 25)
            ax[k].hist(true, bins=bins, histtype="step", color="k", lw=1.2, label="true (per run)")
            for (name, vals), c in zip(est.items(), COLOURS):
                ax[k].hist(vals, bins=bins, alpha=0.5, color=c, label=name)
            ax[k].axvline(PUBLISHED[k], color="k", ls="--", lw=0.8, label="published (the estimators' start)")
            ax[k].set_xlabel(f"r{k} at the end of the run")
            ax[k].ticklabel_format(axis="x", style="sci", scilimits=(-3, 3))
            ax[k].legend(fontsize=7)
        fig.suptitle(f"{variant}: final resistance coefficients (Fig. 4 of Cunillera et al. (2022))", fontsize=9)
        files.append(_save(fig, out, f"fig4_resistance_{variant}.png"))

        # Fig. 7: cruise speed, final coast and brake durations: recognised per estimator, and the truth
        fig, ax = plt.subplots(1, 3, figsize=(12, 3.6))
        for a, key, truth_key, label in zip(ax, ("cruise_speed_kmh", "final_coast_min", "final_brake_s"),
                                            ("cruise_target_kmh", "final_coast_min", "final_brake_s"),
                                            ("cruise speed [km/h]", "final coast [min]", "final brake [s]")):
            true = _values([runs[s]["truth"].get(truth_key) for s in seeds])
            groups = {name: _values([runs[s].get(name, {}).get("features", {}).get(key) for s in seeds])
                      for name in names}
            every = np.concatenate([true, *groups.values()]) if len(true) else true
            bins = np.linspace(every.min(), every.max(), 15) if every.size and np.ptp(every) > 0 else 10
            a.hist(true, bins=bins, histtype="step", color="k", lw=1.2, label="truth")
            for (name, vals), c in zip(groups.items(), COLOURS):
                if vals.size:
                    a.hist(vals, bins=bins, alpha=0.5, color=c, label=f"{name} (recognised)")
            a.set_xlabel(label)
            a.legend(fontsize=7)
        fig.suptitle(f"{variant}: driving style (Fig. 7 of Cunillera et al. (2022)); truth: the driver's cruise "
                     "target, the durations on its exact steps", fontsize=9)
        files.append(_save(fig, out, f"fig7_driving_style_{variant}.png"))

        # Fig. 8: brake rates per ATB-EG step: each estimator's braking fixes, their mean and std, the
        # driver's style rates
        fig, ax = plt.subplots(figsize=(8, 3.6))
        style = np.array([[runs[s]["truth"][f"brake_rate_{k}"] for k in range(1, 6)] for s in seeds])
        ax.plot(np.arange(5) + 0.3, style.mean(axis=0), "kx", ms=8, label="driver's style rate (mean)")
        for name, c in zip(names, COLOURS):
            d = [ser.get(s, {}) for s in seeds]
            step = np.concatenate([x.get(f"{name}.brake_step", []) for x in d]).astype(int)
            dec = np.concatenate([x.get(f"{name}.brake_deceleration", []) for x in d])
            if not step.size:
                continue
            ax.plot(step - 1 + np.random.default_rng(0).uniform(-0.2, 0.2, step.size), dec, ".", color="b", ms=2,
                    alpha=0.5, label=f"{name}: braking fixes")
            means = [dec[step == k].mean() if (step == k).any() else np.nan for k in range(1, 6)]
            stds = [dec[step == k].std() if (step == k).any() else np.nan for k in range(1, 6)]
            ax.errorbar(range(5), means, yerr=stds, fmt="s", color=c, capsize=4, label=f"{name}: mean and std")
        ax.set_xticks(range(5), [f"{b} km/h" for b in ATB_EG])
        ax.set_ylabel("deceleration [m/s2]")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        ax.set_title(f"{variant}: brake rates per ATB-EG step (Fig. 8 of Cunillera et al. (2022))", fontsize=9)
        files.append(_save(fig, out, f"fig8_brake_rates_{variant}.png"))

        # Fig. 9: traction power vs speed in the initial acceleration, recognised per estimator
        fig, ax = plt.subplots(figsize=(8, 4))
        for name, c in zip(names, COLOURS):
            first = True
            for s in seeds:
                d = ser.get(s, {})
                if f"{name}.power_w" in d:
                    ax.plot(d[f"{name}.power_speed_kmh"], d[f"{name}.power_w"] / 1e3, ".", color=c, ms=2,
                            label=name if first else None)
                    first = False
        ax.axhline(runs[seeds[0]]["truth"]["max_power_w"] / 1e3, color="0.5", ls="--", label="maximum power")
        ax.set_xlabel("speed [km/h]")
        ax.set_ylabel("traction power [kW]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        ax.set_title(f"{variant}: traction power in the initial acceleration (Fig. 9 of Cunillera et al. (2022))",
                     fontsize=9)
        files.append(_save(fig, out, f"fig9_traction_power_{variant}.png"))
    return files


def _values(xs) -> np.ndarray:
    return np.array([x for x in xs if x is not None and np.isfinite(x)], dtype=float)


def _flat_names(m: dict, prefix: str = "") -> list[str]:
    out = []
    for k, v in m.items():
        if isinstance(v, dict):
            out += _flat_names(v, f"{prefix}{k}.")
        else:
            out.append(f"{prefix}{k}")
    return out
