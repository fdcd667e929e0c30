"""The train study's scores, apart from its protocol (so the figures can use them without
importing the protocol): the resistance error over the speed grid, the driving regimes and
features of each estimator, the resistance terms' shares, the last coast and brake of a run."""

from __future__ import annotations

import numpy as np

from railfmu.experiments.engine.study_protocol import RunData, output, parameter, truth
from railfmu.models.errors import UserError

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
    "tare_mass": parameter("train", "tare_mass"), "mass": output("train", "mass"),
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


def hold_offline(estimates: dict) -> dict:
    """``estimates`` with every column shorter than the online rows (an offline observer's,
    on its own sample rows: every ``stride``-th row from the first) held to each online row
    (zero-order hold; the observer's rows are the online rows ``0, stride, 2 stride, ...``), in
    place, so that the study scores online and offline estimators alike."""
    n = len(estimates["time"])
    for c, x in list(estimates.items()):
        m = len(x)
        if c == "time" or m >= n or m < 2:
            continue
        stride = -(-n // m)
        if (m - 1) * stride < n <= m * stride:
            estimates[c] = np.asarray(x)[np.arange(n) // stride]
    return estimates


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


def mass_effective(run: RunData) -> float:
    """gamma m, kg: the train's mass as the run has it (its ``mass`` output: tare plus the
    run's load, which a variant may draw per run). Scoring only: no observer is told it."""
    return float(run.roles["gamma"]) * float(np.asarray(run.signals[run.roles["mass"]])[0])


def regime_recognisers(system) -> dict[str, str]:
    """Per observer the regime recogniser it is scored with (:data:`railfmu.estimators.train.recognisers.RECOGNISERS`):
    its SSD setting ``regime_recogniser``, else its class attribute of that name, else the
    paper's rules (``"paper"``): each estimator is scored as its author means it to be read."""
    from railfmu.estimators.train.recognisers import RECOGNISERS
    from railfmu.experiments.engine import registry

    where = str(system.source or system.name)
    out = {}
    for o in system.observers:
        name = o.settings.get("regime_recogniser")
        if name is None:
            try:  # quiet: the observer bank warns of a deprecated path and refuses an unknown one
                name = getattr(registry.load(o.cls, where, warn=False), "regime_recogniser", "paper")
            except UserError:
                name = "paper"
        if name not in RECOGNISERS:
            raise UserError(f"{where}: Observer {o.name!r}: regime_recogniser {name!r} is not one of "
                            f"{', '.join(RECOGNISERS)}")
        out[o.name] = str(name)
    return out


def regime_scores(run: RunData, name: str, fixes: np.ndarray) -> tuple[dict, dict]:
    """One estimator's driving regimes and features (Cunillera et al. (2022) §3.2-3.3, by
    :func:`railfmu.estimators.train.recognisers.score` with the estimator's recogniser,
    :func:`regime_recognisers`) at the GNSS fix rows ``fixes``: the study's
    ``regime_accuracy``, ``max_power_rel_error``, ``max_effort_rel_error``,
    ``cruise_speed_error_kmh``, ``brake_rate_error`` (five, per ATB-EG step, None where the
    run has no braking fix there; also as ``brake_rate_error_step`` by step for the study's
    summary), the recognised regimes' ``regime_share`` of the running time and the
    ``features``; and the features' dict with its samples (the figures')."""
    from railfmu.estimators.train.driving_regimes import REGIME_NAMES
    from railfmu.estimators.train.recognisers import score

    sig, est, roles = run.signals, run.estimates, run.roles
    t = np.asarray(est["time"])[fixes]
    style = {k: float(sig[roles[k]][0]) for k in ("cruise_target", "traction_fraction",
                                                  *(f"brake_rate_{j}" for j in range(1, 6)))}
    train = {k: float(roles[k]) for k in ("max_power", "max_traction_force", "tare_mass")}
    train["load_mass"] = float(np.asarray(sig[roles["mass"]])[0]) - train["tare_mass"]  # the run's load
    train["rotating_mass_factor"] = float(roles["gamma"])
    recogniser = roles.get("regime_recognisers", {}).get(name, "paper")
    m, feats = score(t, np.asarray(est[f"{name}.v"])[fixes], np.asarray(est[f"{name}.acceleration"])[fixes],
                     np.asarray(est[f"{name}.effort"])[fixes], sig["time"], sig[roles["v"]], sig[roles["effort"]],
                     style, train, recogniser)
    m = {k: finite_or_none(x) if isinstance(x, float) else x for k, x in m.items()}
    rec = np.asarray(feats["regimes"])
    dt = np.r_[0.0, np.diff(t)]  # a fix stands for the interval before it
    running = float(dt[rec != 0].sum()) or 1.0
    return {**m, "regime_recogniser": recogniser,
            "brake_rate_error_step": {str(k + 1): e for k, e in enumerate(m["brake_rate_error"]) if e is not None},
            "regime_share": {REGIME_NAMES[c]: float(dt[rec == c].sum() / running) for c in (1, 2, 3, 4)},
            "features": {"max_power_w": finite_or_none(feats["max_power"]), "max_effort_n": finite_or_none(feats["max_effort"]),
                         "cruise_speed_kmh": finite_or_none(feats["cruise_speed"] / KMH),
                         "cruise_above_140": float(feats["cruise_speed"] / KMH > 140.0),
                         "final_coast_min": finite_or_none(feats["final_coast_duration"] / 60.0),
                         "final_brake_s": finite_or_none(feats["final_brake_duration"]),
                         "brake_rates": [finite_or_none(x) for x in feats["brake_rates"]]}}, feats


def finite_or_none(x) -> float | None:
    """None where a feature is undefined (NaN), as JSON has no NaN."""
    return float(x) if x is not None and np.isfinite(x) else None


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


def format_or_dash(x, fmt: str) -> str:
    """``x`` in ``fmt``, or "-" where it is undefined (None)."""
    return "-" if x is None else format(x, fmt)
