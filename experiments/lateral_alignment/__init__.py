"""Lateral track alignment from in-service inertial sensors (Muñoz et al.): Kalman filter and RTS smoother on the wheelset model, validated on the complete vehicle model.

The system is ``SystemStructure.ssd``: ERRI B176 lateral and vertical irregularities (400 m
at 20 m/s) drive the complete vehicle model (VehicleLateral, 23 DOF); a SensorNoise FMU adds
the paper's sensor noise to the leading wheelset's lateral acceleration and yaw rate and its
bogie frame's lateral acceleration; the alignment Kalman filter (railfmu.estimators.track.alignment, the
paper's eqs. 9-17 on the simplified model with the identified primary suspension) estimates
the alignment online, and the RTS smoother (an offline observer, run on the record after the
run) offline. Variants: the conditions of the paper's Tables 2-4.

Training and test track: the SM is identified (identify.py), the filter's q_xi and
sigma_virtual are tuned and the smoother's own equivalent SM is fitted (tune.py; the observer
``smoother`` in the SSD) on track seed 1; the study is scored on track seed 39, whose
band content is the closest to what the paper's Table 2 implies (parameters/track.ssv). The
irregularities ramp in over the first 20 m (the track's run_in_length), and the scores start
after it.

Monte Carlo over held-out tracks (``railfmu study lateral_alignment --runs N --seed 1000``):
each member is a new track and noise draw (the run's seed reaches both) and runs 2020 m
(:meth:`LateralAlignment.monte_carlo_stop_time`: the run-in plus 10 of D3's 200 m). Why: on
400 m the D3 band holds ~3.5 spectral lines, the band's rms of the truth ranges 0.5-1.5 mm
over tracks and the sensor-noise error in D3 0.05-0.18 mm over noise draws on one track, so a
run's D3 J_rel (their ratio) scatters (p95 0.19 over seeds 1000-1049) around a filter whose
D3 error is the same on every track (noise-free 0.086: the causal filter's flat 0.945 gain).
On 2020 m: p95 0.145. A single run keeps the paper's 400 m.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.study_protocol import (
    RunData,
    Study,
    measurement,
    observers_md,
    output,
    parameter,
    truth,
)
from railfmu.models.errors import UserError

HERE = Path(__file__).resolve().parent
DEFAULT_VARIANT = "standard"
BANDS = ("whole", "D1", "D2", "D3")
START_UP_S = 1.0  # s: the track's 20 m run-in (parameters/track.ssv); errors are scored after it
# Monte Carlo members score this many of the longest EN 13848 wavelength (D3's 200 m) after the
# run-in: 400 m holds ~3.5 spectral lines of D3 (width (1/70 - 1/200) 1/m x 380 m), so a run's D3
# J_rel is a ratio of two few-line estimates and scatters with the track and the noise draw
MONTE_CARLO_WAVELENGTHS = 10

# Muñoz et al., Tables 2-4: J (mm) / J_rel per band (whole, D1, D2, D3); Table 4's case 2 only
# as its text gives it (whole range), case 3 not printed in the text we have
MUNOZ_TABLE = {
    "standard": [(0.36, 0.25), (0.21, 0.48), (0.22, 0.26), (0.18, 0.15)],
    "no_noise": [(0.34, 0.24), (0.21, 0.48), (0.21, 0.26), (0.13, 0.12)],
    "no_vertical": [(0.34, 0.24), (0.17, 0.40), (0.21, 0.26), (0.18, 0.16)],
    "conicity_minus10": [(0.38, 0.27), (0.22, 0.51), (0.23, 0.29), (0.18, 0.16)],
    "kalker_minus50": [(0.39, 0.27), (0.22, 0.51), (0.23, 0.29), (0.18, 0.16)],
    "all_conditions": [(0.47, 0.32), (0.30, 0.68), (0.27, 0.32), (0.21, 0.18)],
    "resonance_case1": [(0.36, 0.25), (0.21, 0.48), (0.22, 0.26), (0.18, 0.15)],
    "resonance_case2": [(0.21, 0.29), None, None, None],
    "resonance_case3": [None, None, None, None],
}
SENSOR_ROLES = ("ddy", "dpsi", "ddy_f")  # the filter's measurements: the noisy sensor channels the SSD feeds it (tune.py)
ROLES = {  # where the SSD holds what the study reads
    "ddy": measurement("alignment", "ddy"), "dpsi": measurement("alignment", "dpsi"),
    "ddy_f": measurement("alignment", "ddy_f"),
    "alignment": truth("alignment", "xi"),  # the real alignment under the leading wheelset
    "wheelset_y": truth("alignment", "y"),
    "position": output("track", "position"),
    "speed": parameter("track", "V"),
    "run_in_length": parameter("track", "run_in_length"),
}

PLOTS = {  # Muñoz et al., Fig. 4: the three sensor signals (roles or signal names)
    "sensors.png": ("Sensor signals (Muñoz et al., Fig. 4)",
                    [["axle-box lateral acc.", ("ddy", "axle-box lateral acc. (noisy)"),
                      ("vehicle.ddy_w1", "noise-free")],
                     ["wheelset yaw rate", ("dpsi", "wheelset yaw rate (noisy)"), ("vehicle.dpsi_w1", "noise-free")],
                     ["bogie-frame lateral acc.", ("ddy_f", "bogie-frame lateral acc. (noisy)"),
                      ("vehicle.ddy_b1", "noise-free")]]),
}


def _beside(name: str) -> dict:
    f = HERE / name
    return json.loads(f.read_text()) if f.is_file() else {}


def identified() -> dict:
    """The identification of the SM's primary suspension against the CM (identify.py)."""
    return _beside("identified.json")


def tuned() -> dict:
    """The filter's tuning and the smoother's fitted SM, on the training track (tune.py)."""
    return _beside("tuned.json")


def _cell(j, r) -> str:
    return "-" if j is None else f"{j:.2f} / {r:.2f}"


def _ours(m: dict, key_j="J_mm", key_r="J_rel") -> list[str]:
    return [_cell(m[key_j][b], m[key_r][b]) for b in BANDS]


def first_lateral_mode() -> tuple[float, float, str]:
    """railfmu.models.vehicle.vehicle_lateral.first_lateral_mode of the model's own parameters, cached beside
    the FMUs and keyed by the model sources: it derives the complete vehicle model (sympy,
    seconds), for one sentence of every report."""
    from railfmu.fmus.generate.build import default_out, sources_key

    cache, key = default_out() / ".first_lateral_mode.json", sources_key()
    try:
        cached = json.loads(cache.read_text())
        if cached["key"] == key:
            return tuple(cached["mode"])
    except (OSError, ValueError, KeyError):
        pass
    from railfmu.models.vehicle.vehicle_lateral import first_lateral_mode as derived

    mode = derived()
    cache.parent.mkdir(parents=True, exist_ok=True)
    part = cache.with_name(f"{cache.name}.{os.getpid()}.part")  # study workers write it at once
    part.write_text(json.dumps({"key": key, "mode": list(mode)}) + "\n")
    part.replace(cache)
    return mode


def _fit_md(fit: dict) -> list[str]:
    """identify.py's fit record as a table: the cost and each channel's NRMSE before and after."""
    if not fit:
        return []
    before, after = fit.get("before", {}), fit.get("after", {})
    channels = list(after.get("nrmse", {}))
    L = ["", f"Fit of the SM to the CM (y and psi of the leading wheelset, lateral irregularity only): "
         f"{fit.get('chosen', ', '.join(fit.get('free', [])) + ' fitted')}; cost {fit.get('cost', '')}; "
         f"{fit.get('n_evaluations', '?')} evaluations.", "",
         "| | cost | J_ls (eq. 8) | " + " | ".join(f"NRMSE {c}" for c in channels) + " |",
         "|---|---|---|" + "---|" * len(channels)]
    for label, r in (("Muñoz et al., Table 1 (initial)", before), ("identified", after)):
        L.append(f"| {label} | {r.get('cost', float('nan')):.4f} | {r.get('J_ls_eq8', float('nan')):.4g} | "
                 + " | ".join(f"{r.get('nrmse', {}).get(c, float('nan')):.3f}" for c in channels) + " |")
    return L


class LateralAlignment(Study):
    """Muñoz et al.: the alignment filter and smoother on the complete vehicle model."""
    default_variant = DEFAULT_VARIANT
    roles = ROLES
    figures_of_signals = PLOTS
    x_axis = "position"
    summary_metrics = ("J_mm.*", "J_rel.*", "J_mm_smoothed.*", "J_rel_smoothed.*", "estimator_seconds")
    figures_from_run = True  # the band-passed curves need no score: drawn while the run is scored
    figure_imports = ("scipy.signal", "railfmu.estimators.track.metrics")

    def monte_carlo_stop_time(self, system) -> float:
        """Record length (s) of a Monte Carlo member: the run-in plus
        :data:`MONTE_CARLO_WAVELENGTHS` of D3's longest wavelength at the run's speed,
        ``T = (L_run_in + N lambda_max) / V`` (m, m, m/s; 101 s = 2020 m at 20 m/s), never
        shorter than the SSD's. A single run keeps the paper's 400 m (Table 2)."""
        from railfmu.estimators.track.metrics import BANDS as LIMITS

        roles = self.bind(system)
        length = float(roles["run_in_length"]) + MONTE_CARLO_WAVELENGTHS * LIMITS["D3"][1]
        return max(length / float(roles["speed"]), float(system.stop_time))

    def metrics(self, run: RunData) -> dict:
        """J_mm / J_rel per band for the filter (online estimate) and the smoother (the offline
        observer ``smoother``, run by the bank after the run), the observability rank, and the
        estimators' wall time on the recorded 20 s."""
        signals, estimates, base, roles = run.signals, run.estimates, run.base, run.roles
        from railfmu.estimators.track.metrics import alignment_errors

        dt = base["step_size_s"]
        V = float(roles["speed"])
        truth = np.asarray(signals[roles["alignment"]])
        online = np.asarray(estimates["alignment.xi"])
        kf = base["observers"]["alignment"]  # the online filter's diagnostics, timed by the bank
        smoother = base["observers"]["smoother"]  # the offline observer's diagnostics
        try:
            f = alignment_errors(online, truth, V, dt, skip_s=START_UP_S)
            s = alignment_errors(np.asarray(estimates["smoother.xi"]), truth, V, dt, skip_s=START_UP_S)
            whole_run = alignment_errors(online, truth, V, dt)
        except ValueError as exc:  # a run too short to score: the user's --stop-time
            raise UserError(f"lateral_alignment: cannot score a run of {base['simulated_seconds']:g} s ({exc}); "
                            f"J is scored after the {START_UP_S:g} s run-in: give a longer --stop-time") from None
        return {
            "J_mm": f["J_mm"], "J_rel": f["J_rel"],
            "J_mm_smoothed": s["J_mm"], "J_rel_smoothed": s["J_rel"],
            "J_mm_including_start_up": whole_run["J_mm"], "J_rel_including_start_up": whole_run["J_rel"],
            "scored_from_s": START_UP_S,
            "observability_rank": int(kf["observability_rank"]),
            "observability_rank_smoother_model": int(smoother["observability_rank"]),
            "estimator_seconds": kf["wall_time_s"], "smoother_seconds": smoother["wall_time_s"],
            "alignment_rms_3_200_mm": float(f["J_mm"]["whole"] / f["J_rel"]["whole"]),
        }

    def figures(self, run: RunData, out: Path) -> list[str]:
        """Figs. 5, 6 and 8 of Muñoz et al.: estimate and smoothed estimate over the real alignment along
        the track, per EN 13848 band, with the wheelset's lateral displacement."""
        signals, estimates, metrics, roles = run.signals, run.estimates, run.base, run.roles
        from railfmu.estimators.track.metrics import bandpass
        from railfmu.experiments.engine.plots import figure, x_axis

        dt = metrics["step_size_s"]
        V = float(roles["speed"])
        s, s_label = x_axis(signals, roles["position"])
        truth = np.asarray(signals[roles["alignment"]])
        est = np.asarray(estimates["alignment.xi"])
        smoothed = np.asarray(estimates["smoother.xi"])  # the offline observer's (estimates_smoother.csv)

        mm = 1e3
        real, kf, rts = {"color": "k", "lw": 1.2}, {"color": "C1", "lw": 0.9}, {"color": "C0", "lw": 0.9}
        title = f"Alignment estimate, {metrics['variant']} (Muñoz et al., Figs. 5 and 8)"
        files = [figure(out, "alignment.png", title, s, s_label,
                        [[("real alignment xi", mm * truth, "mm", real), ("Kalman filter", mm * est, "mm", kf),
                          ("RTS smoother", mm * smoothed, "mm", rts),
                          ("wheelset y (CM)", mm * np.asarray(signals[roles["wheelset_y"]]), "mm",
                           {"color": "C2", "lw": 0.7, "alpha": 0.7})]],
                        width=11, quantities=["lateral alignment"])]
        files.append(figure(out, "alignment_bands.png",
                            "Alignment per EN 13848 band: D1 3-25 m, D2 25-70 m, D3 70-200 m (Muñoz et al., Fig. 6)",
                            s, s_label,
                            [[(f"real, {band}", mm * bandpass(truth, V, dt, band), "mm", real),
                              (f"filter, {band}", mm * bandpass(est, V, dt, band), "mm", kf),
                              (f"smoother, {band}", mm * bandpass(smoothed, V, dt, band), "mm", rts)]
                             for band in ("D1", "D2", "D3")], width=11,
                            quantities=[f"alignment, {band}" for band in ("D1", "D2", "D3")]))
        return files

    def report_md(self, metrics: dict) -> str:
        L = ["## Alignment estimate: J (mm) / J_rel, band-passed per EN 13848 (Muñoz et al., eq. 32)", "",
             f"Estimate and real alignment are band-passed to each EN 13848 range (zero-phase Butterworth) "
             f"before J and J_rel are taken; scored after the first {metrics['scored_from_s']:g} s (the track's "
             "run-in, where the irregularities ramp in from zero). The observers' tables further down are of "
             "the raw estimate (not band-passed): larger, and not comparable with the paper's.", "",
             "| | whole 3-200 m | D1 3-25 m | D2 25-70 m | D3 70-200 m |", "|---|---|---|---|---|",
             "| Kalman filter | " + " | ".join(_ours(metrics)) + " |",
             "| RTS smoother (its own equivalent SM) | "
             + " | ".join(_ours(metrics, "J_mm_smoothed", "J_rel_smoothed")) + " |",
             "| filter incl. start-up | " + " | ".join(_ours(metrics, "J_mm_including_start_up",
                                                             "J_rel_including_start_up")) + " |"]
        paper = MUNOZ_TABLE.get(metrics["variant"])
        if paper:
            L.append("| Muñoz et al. | " + " | ".join("-" if c is None else _cell(*c) for c in paper) + " |")
        f1, zeta, what = first_lateral_mode()
        L += ["", f"Observability rank {metrics['observability_rank']} (of 7). Filter: "
              f"{metrics['estimator_seconds']:.3f} s wall for {metrics['simulated_seconds']:g} s of data "
              f"(Muñoz et al.: 5.7 s in Matlab); smoother {metrics['smoother_seconds']:.3f} s. Alignment rms over "
              f"3-200 m: {metrics['alignment_rms_3_200_mm']:.2f} mm.", "",
              f"CM first lateral mode at 20 m/s: f1 = {f1:.3f} Hz (damping ratio {zeta:.2f}; {what}), "
              f"resonance wavelength V/f1 = {20.0 / f1:.2f} m (Muñoz et al.: 1.277 Hz, 15.66 m)."]
        ident = identified()
        if ident:
            L += ["", "## Identification of the SM's primary suspension against the CM (Muñoz et al., §3.4)", "",
                  "| | kx [N/m] | cx [N s/m] | ky [N/m] | cy [N s/m] |", "|---|---|---|---|---|",
                  "| Muñoz et al., Table 1 (initial) | "
                  + " | ".join(f"{ident['initial'][k]:.4g}" for k in ("kx", "cx", "ky", "cy")) + " |",
                  "| identified | " + " | ".join(f"{ident[k]:.4g}" for k in ("kx", "cx", "ky", "cy")) + " |"]
            L += _fit_md(ident.get("fit", {}))
        tune = tuned()
        if tune:
            f, sm = tune["filter"], tune["smoother"]
            L += ["", "## Filter tuning and the smoother's model, on the training track (tune.py)", "",
                  f"Track seed {tune['training_track']['seed']}, sensor noise seed {tune['training_noise_seed']} "
                  f"(this run: track seed {metrics['parameters']['track'].get('seed')}, noise seed "
                  f"{metrics['parameters']['sensors'].get('seed')}), variant {tune['variant']}. Filter: q_xi = "
                  f"{f['q_xi']:g} m^2/s, sigma_virtual = {f['sigma_virtual']:g} m ({f['criterion']}).", "",
                  "| q_xi [m^2/s] | sigma_virtual [m] | whole | D1 | D2 | D3 | mean |", "|---|---|---|---|---|---|---|"]
            L += [f"| {g['q_xi']:g} | {g['sigma_virtual']:g} | " + " | ".join(f"{g['J_rel'][b]:.3f}" for b in BANDS)
                  + f" | {g['mean_J_rel']:.3f} |" for g in f["grid"]]
            keys = list(sm["parameters"])
            L += ["", f"Smoother: the SM's equivalent parameters fitted to its accuracy ({sm['criterion']}; "
                  f"{sm['evaluations']} evaluations). Training J_rel (whole, D1, D2, D3) before "
                  + ", ".join(f"{sm['J_rel_before'][b]:.3f}" for b in BANDS) + "; after "
                  + ", ".join(f"{sm['J_rel_after'][b]:.3f}" for b in BANDS) + ".", "",
                  "| | " + " | ".join(keys) + " |", "|---|" + "---|" * len(keys),
                  "| filter's SM (identified) | " + " | ".join(f"{sm['initial'][k]:.4g}" for k in keys) + " |",
                  "| smoother's SM (fitted) | " + " | ".join(f"{sm['parameters'][k]:.4g}" for k in keys) + " |"]
        raw = observers_md(metrics)
        return "\n".join(L + (["", raw] if raw else []))

    def table_md(self, table: dict[str, dict]) -> str:
        """The layout of Tables 2-4 of Muñoz et al.: per condition, ours (filter and smoother) beside the paper's."""
        L = ["| condition | estimate | whole 3-200 m | D1 3-25 m | D2 25-70 m | D3 70-200 m |",
             "|---|---|---|---|---|---|"]
        for variant, m in table.items():
            L.append(f"| {variant} | filter | " + " | ".join(_ours(m)) + " |")
            L.append(f"| {variant} | smoother | " + " | ".join(_ours(m, "J_mm_smoothed", "J_rel_smoothed")) + " |")
            paper = MUNOZ_TABLE.get(variant)
            if paper:
                L.append(f"| {variant} | Muñoz et al. | " + " | ".join("-" if c is None else _cell(*c) for c in paper)
                         + " |")
        L += ["", "J in mm / J_rel, band-passed per EN 13848, scored after the track's 1 s (20 m) run-in. "
              "Filter wall time per 20 s run: "
              + ", ".join(f"{v} {m['estimator_seconds']:.2f} s" for v, m in table.items()) + "."]
        return "\n".join(L)


STUDY = LateralAlignment(__doc__.strip().splitlines()[0])
