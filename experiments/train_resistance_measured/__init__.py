"""A measured train run (GNSS position and speed) replayed into the running-resistance observers of Cunillera et al. (2022).

``SystemStructure.ssd``: a SignalTable FMU plays the run (``time_s,position_m,speed_kmh``, one
row per GNSS fix; the shipped ``resources/example_run.csv`` is one simulated run of
``train_resistance``, ``record.py`` writes it) into the observers of ``train_resistance``;
the line profile they read is the system parameter ``line.file``::

    railfmu run train_resistance_measured --set replay.file=RUN.csv --set line.file=LINE.csv

No ground truth: ``metrics.json`` holds, per estimator (an object under its name), the final
``r0_final``, ``r1_final``, ``r2_final`` (SI: N/kg, N/(kg m/s), N/(kg (m/s)^2)), the rms of
its speed and position against the measured fixes (``speed_residual_kmh``,
``position_residual_m``: how well the model follows the run, not an error) and ``seconds``;
``features`` (§3.3 on its recognised regimes, mass-specific: the maximum
tractive power and effort, cruise speed, final coast and brake durations, brake rate per
ATB-EG step, regime shares); and the run's ``fixes``, ``run_time_s`` and ``top_speed_kmh``. A run shorter than one GNSS
sample is a one-line error.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.study_protocol import RunData, Study, measurement, parameter
from railfmu.experiments.train_resistance.scores import (
    KMH,
    estimators_of,
    finite_or_none,
    format_or_dash,
    regime_recognisers,
    resistance,
)
from railfmu.models.errors import UserError

REFERENCE = "ukf_paper"
ROLES = {"position": measurement(REFERENCE, "position"), "speed": measurement(REFERENCE, "speed"),
         "file": parameter("replay", "file")}
PLOTS = {"measured.png": ("The replayed run", [[("position", "position along the line")], [("speed", "speed")]])}
#: the Davis coefficients' names on the figure's axes (their units are the estimators')
DAVIS = ("r0, constant resistance", "r1, resistance per speed", "r2, resistance per speed squared")


def features_of(t: np.ndarray, est: dict, name: str, recogniser_name: str = "paper") -> dict:
    """The §3.3 features of one estimator's outputs at the fixes (Cunillera et al. (2022),
    :func:`railfmu.estimators.train.driving_regimes.features` on the regimes its recogniser ``recogniser_name``
    reads, :func:`railfmu.experiments.train_resistance.regime_recognisers`); mass-specific (a
    measured run carries no mass): ``max_power_w_per_kg``, ``max_effort_n_per_kg``, the
    cruise speed, final coast and brake durations, the brake rate per ATB-EG step and the
    recognised regimes' shares of the running time. None where a feature is undefined."""
    from railfmu.estimators.train.driving_regimes import REGIME_NAMES, features
    from railfmu.estimators.train.recognisers import recogniser

    v, a, f = (np.asarray(est[f"{name}.{k}"]) for k in ("v", "acceleration", "effort"))
    regimes = recogniser(recogniser_name)(t, v, a, f)
    feats = features(t, v, a, f, regimes)
    dt = np.r_[0.0, np.diff(t)]
    running = float(dt[regimes != 0].sum()) or 1.0
    return {"max_power_w_per_kg": finite_or_none(feats["max_power_specific"]),
            "max_effort_n_per_kg": finite_or_none(feats["max_effort_specific"]),
            "cruise_speed_kmh": finite_or_none(feats["cruise_speed"] / KMH),
            "final_coast_min": finite_or_none(feats["final_coast_duration"] / 60.0),
            "final_brake_s": finite_or_none(feats["final_brake_duration"]),
            "brake_rates": [finite_or_none(x) for x in feats["brake_rates"]],
            "regime_share": {REGIME_NAMES[c]: float(dt[regimes == c].sum() / running) for c in (1, 2, 3, 4)}}


def table_span(path: str) -> float | None:
    """Last minus first time of a run CSV, or None when it cannot be read as one (the
    SignalTable FMU then names the file, line and column)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
        if not rows or rows[0][0].strip() not in ("time", "time_s") or len(rows) < 2:
            return None if len(rows) != 1 else 0.0
        t = [float(r[0]) for r in rows[1:]]
    except (OSError, ValueError, IndexError):
        return None
    if not all(math.isfinite(x) for x in t) or any(b <= a for a, b in zip(t, t[1:])):
        return None
    return t[-1] - t[0]


class TrainResistanceMeasured(Study):
    """The running-resistance observers on a replayed GNSS log: final estimates, no truth."""
    default_variant = "measured"
    roles = ROLES
    figures_of_signals = PLOTS
    summary_metrics = ("*.r?_final", "*.speed_residual_kmh", "*.seconds", "*.features.*")

    def bind(self, system) -> dict:
        """The roles, and the check that the run outlasts one GNSS sample (the step size)."""
        roles = super().bind(system)
        roles["regime_recognisers"] = regime_recognisers(system)
        spec = next(o for o in system.observers if o.name == REFERENCE)
        roles["gnss_period"] = period = spec.period if spec.period is not None else system.step_size
        span = table_span(str(roles["file"]))
        if span is not None and span < period:
            raise UserError(f"replay.file {roles['file']}: the run lasts {span:g} s, shorter than one GNSS sample "
                            f"({period:g} s, the observers' sample period): nothing to estimate")
        return roles

    def metrics(self, run: RunData) -> dict:
        sig, est, roles = run.signals, run.estimates, run.roles
        period = float(roles["gnss_period"])
        rows = np.arange(0, len(est["time"]), round(period / float(run.base["step_size_s"])))  # the samples
        if len(rows) < 2:
            raise UserError(f"replay.file {roles['file']}: the run ends before its second GNSS sample "
                            f"({period:g} s, the observers' sample period): nothing to estimate")
        t = np.asarray(est["time"])[rows]
        est = {k: np.asarray(x)[rows] for k, x in est.items() if len(x) == len(est["time"])}
        z_s = np.asarray(sig[roles["position"]])[rows]
        z_v = np.asarray(sig[roles["speed"]])[rows] * KMH  # the connector's km/h
        out: dict = {"fixes": len(t), "run_time_s": float(t[-1] - t[0]), "top_speed_kmh": float(np.max(z_v) / KMH)}
        for name in estimators_of(est):
            r_hat = np.array([float(est[f"{name}.r{k}"][-1]) for k in range(3)])
            e_v = (np.asarray(est[f"{name}.v"])[1:] - z_v[1:]) / KMH
            e_s = np.asarray(est[f"{name}.s"])[1:] - z_s[1:]
            out[name] = {**{f"r{k}_final": float(r_hat[k]) for k in range(3)},
                         "resistance_at_100kmh": float(resistance(r_hat, np.array(100 * KMH))),
                         "speed_residual_kmh": float(np.sqrt(np.mean(e_v * e_v))),
                         "position_residual_m": float(np.sqrt(np.mean(e_s * e_s))),
                         "seconds": float(run.base["observers"].get(name, {}).get("wall_time_s", float("nan")))}
            if f"{name}.acceleration" in est and f"{name}.effort" in est:
                out[name]["features"] = features_of(t, est, name, roles["regime_recognisers"].get(name, "paper"))
        return out

    def report_md(self, metrics: dict) -> str:
        names = [k for k, v in metrics.items() if isinstance(v, dict) and "r0_final" in v]
        L = [f"## Final running resistance ({metrics['fixes']} fixes, {metrics['run_time_s']:g} s, "
             f"top speed {metrics['top_speed_kmh']:.0f} km/h)", "",
             "| estimator | r0 [N/kg] | r1 [N/(kg m/s)] | r2 [N/(kg (m/s)^2)] | r(100 km/h) [N/kg] | "
             "speed residual [km/h] | position residual [m] | wall [s] |", "|---|---|---|---|---|---|---|---|"]
        for n in names:
            e = metrics[n]
            L.append(f"| {n} | {e['r0_final']:.6g} | {e['r1_final']:.6g} | {e['r2_final']:.6g} | "
                     f"{e['resistance_at_100kmh']:.5g} | {e['speed_residual_kmh']:.3f} | "
                     f"{e['position_residual_m']:.2f} | {e['seconds']:.3f} |")
        L += ["", "Residuals: the estimate against the measured fix (no ground truth in a measured run).", ""]
        with_features = [n for n in names if "features" in metrics[n]]
        if with_features:
            L += ["## Features (§3.3, on the recognised regimes)", "",
                  "| estimator | max. power [W/kg] | max. effort [N/kg] | cruise speed [km/h] | final coast [min] | "
                  "final brake [s] | brake rate per ATB-EG step [m/s2] | traction / cruising / coasting / braking [%] |",
                  "|---|---|---|---|---|---|---|---|"]
            for n in with_features:
                f = metrics[n]["features"]
                L.append(f"| {n} | {format_or_dash(f['max_power_w_per_kg'], '.2f')} | {format_or_dash(f['max_effort_n_per_kg'], '.3f')} | "
                         f"{format_or_dash(f['cruise_speed_kmh'], '.1f')} | {format_or_dash(f['final_coast_min'], '.2f')} | "
                         f"{format_or_dash(f['final_brake_s'], '.0f')} | {', '.join(format_or_dash(x, '.3f') for x in f['brake_rates'])} | "
                         f"{' / '.join(format(100 * x, '.1f') for x in f['regime_share'].values())} |")
        return "\n".join(L)

    def table_md(self, table: dict[str, dict]) -> str:
        L = ["| variant | estimator | r0 [N/kg] | r1 [N/(kg m/s)] | r2 [N/(kg (m/s)^2)] | speed residual [km/h] |",
             "|---|---|---|---|---|---|"]
        for variant, m in table.items():
            L += [f"| {variant} | {n} | {e['r0_final']:.6g} | {e['r1_final']:.6g} | {e['r2_final']:.6g} | "
                  f"{e['speed_residual_kmh']:.3f} |" for n, e in m.items() if isinstance(e, dict) and "r0_final" in e]
        return "\n".join(L)

    def figures(self, run: RunData, out: Path) -> list[str]:
        from railfmu.experiments.engine.plots import figure

        est = run.estimates
        t = np.asarray(est["time"])
        units = {**{f"r{k}": u for k, u in enumerate(("N/kg", "N.s/(m.kg)", "N.s2/(m2.kg)"))},
                 **{k: u for o in run.observers.values() for k, u in getattr(o, "units", {}).items()}}
        axes = [([(n, est[f"{n}.r{k}"], units[f"r{k}"]) for n in estimators_of(est)], DAVIS[k]) for k in range(3)]
        axes = [a for a in axes if a[0]]
        return [figure(out, "resistance_estimates.png", "Running-resistance estimates on the replayed run",
                       t, "time [s]", [a for a, _ in axes], quantities=[q for _, q in axes])] if axes else []


STUDY = TrainResistanceMeasured(__doc__.strip().splitlines()[0])
