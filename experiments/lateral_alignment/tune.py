"""Tune the alignment filter and fit the smoother's design model on a *training* track, not
the one the study is scored on.

    python -m railfmu.experiments.lateral_alignment.tune [--out .../tuned.json] [--max-evaluations 600]

The study scores on track seed 39 (``parameters/track.ssv``: its band content is the closest
of seeds 1-60 to the one Table 2 of Muñoz et al. implies). The identification
(``identify.py``) and this tuning use track seed 1 (``psd_scale`` 0.773 for 1.4 mm over
3-200 m) and another sensor noise seed, so the reported numbers are out of sample.

1. Runs the experiment's own system (``SystemStructure.ssd``, variant ``standard``: vertical
   irregularities, sensor noise) on the container master on the training track.
2. **Filter** (online): the fixed-gain filter with the paper's identified SM, for every pair of
   ``Q_XI`` x ``SIGMA_VIRTUAL``, scored as the study does (railfmu.estimators.track.metrics.alignment_errors
   after the 20 m run-in); the pair with the smallest mean J_rel over the four bands (whole,
   D1, D2, D3) is the ``alignment`` observer's.

   Why these two: ``q_xi`` sets how fast the filter lets the alignment move, ``sigma_virtual``
   how hard the zero reading pins the common mode (the paper's eq. 17). The spectrum-based defaults
   of railfmu.estimators.track.alignment pin at 305 m and shrink the estimate by 7 % at every wavelength;
   the tuned pair pins at ~0.1 rad/s (~1 km) and lets the sensors carry the 70-200 m band.
3. **Smoother** (offline): with the tuned pair, the SM's equivalent parameters kx, cx, ky, cy,
   m_f, f11, f22 are fitted (Nelder-Mead in log space from the identified values, three
   restarts with shrinking simplices: the cost is rough) to the
   smallest mean J_rel of the RTS smoother over the four bands; they are the ``smoother``
   observer's. Why: the paper's identification fits y and psi, which the kinematic mode
   (1-2 Hz) dominates; the 3-7 Hz response of the 3-DOF SM then differs from the CM's (gain
   1.2-1.5, phase 17-28 deg on the axle-box accelerometer), and the smoother, which leans on
   the model across time, loses to the filter in D1 (0.26 against 0.19; any look-ahead, even
   25 ms, makes D1 worse). Fitted this way the values are equivalent parameters of a
   3-DOF model standing in for a 23-DOF vehicle, not physical ones: the fit (tuned.json)
   takes f11 to 25 x Kalker's and kx to 3 % of the identified value, i.e. a wheelset that
   yaws almost as it rolls (no longitudinal slip) with little yaw stiffness to the frame.
   The cost is rough (other starts end at other such models, all with a stiff creep
   coefficient). The online filter keeps the paper's identified SM: with the smoother's model
   its D1 doubles. The smoother's model is fitted to the nominal vehicle: with the CM's creep
   halved (``kalker_minus50``) it is no better than the filter.
4. Writes the grid, the fit and the choices to ``tuned.json``; the SSD's settings are copied
   from it.
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from railfmu.estimators.track.alignment import AlignmentKalmanFilter
from railfmu.estimators.track.metrics import alignment_errors
from railfmu.experiments.engine.runner import find_experiment, load_system
from railfmu.fmus.cosim.masters import run

from railfmu.experiments.lateral_alignment import BANDS, SENSOR_ROLES, START_UP_S, STUDY

HERE = Path(__file__).resolve().parent
TRAINING_TRACK = {"seed": 1, "psd_scale": 0.773}  # identify.py's track (1.4 mm over 3-200 m)
TRAINING_NOISE_SEED = 101  # the study's sensors use 100
SMOOTHER_FREE = ("kx", "cx", "ky", "cy", "m_f", "f11", "f22")
Q_XI = (1e-4, 2e-4, 4e-4, 8e-4, 1.6e-3)  # m^2/s
SIGMA_VIRTUAL = (2.0, 4.0, 8.0, 16.0)  # m
XI = AlignmentKalmanFilter.outputs.index("xi")


def mean_j_rel(j: dict) -> float:
    """The tuning criterion: mean J_rel over the four bands."""
    return float(np.mean([j[b] for b in BANDS]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE / "tuned.json")
    ap.add_argument("--max-evaluations", type=int, default=600,
                    help="smoother fit: Nelder-Mead evaluations over three restarts")
    args = ap.parse_args(argv)

    system = load_system(find_experiment("lateral_alignment"), "standard",
                         sets={"track": TRAINING_TRACK, "sensors": {"seed": TRAINING_NOISE_SEED}})
    res = run(system, "container", progress=False)
    col = {c: res.data[:, k] for k, c in enumerate(res.columns)}
    roles = STUDY.bind(system)  # the signals the SSD feeds the filter and scores it against
    t, truth = col["time"], col[roles["alignment"]]
    Z = np.column_stack([col[roles[c]] for c in SENSOR_ROLES])
    settings = dict(next(o.settings for o in system.observers if o.name == "alignment"))
    dt, V = system.step_size, float(settings["V"])

    grid = []
    for q, sv in itertools.product(Q_XI, SIGMA_VIRTUAL):
        kf = AlignmentKalmanFilter(dt, **{**settings, "q_xi": q, "sigma_virtual": sv})
        j = alignment_errors(kf.run(t, Z)[:, XI], truth, V, dt, skip_s=START_UP_S)["J_rel"]
        grid.append({"q_xi": q, "sigma_virtual": sv, "J_rel": j, "mean_J_rel": mean_j_rel(j)})
        print(f"q_xi {q:8.2g} m^2/s  sigma_virtual {sv:5.1f} m  J_rel " + " ".join(f"{j[b]:.3f}" for b in BANDS)
              + f"  mean {grid[-1]['mean_J_rel']:.3f}")
    best = min(grid, key=lambda g: g["mean_J_rel"])
    print(f"filter: q_xi = {best['q_xi']:g} m^2/s, sigma_virtual = {best['sigma_virtual']:g} m "
          f"(mean J_rel {best['mean_J_rel']:.3f})")

    # the smoother's equivalent SM, with the filter's pair
    start = {**settings, "q_xi": best["q_xi"], "sigma_virtual": best["sigma_virtual"]}
    x0 = {k: AlignmentKalmanFilter(dt, **start).params[k] for k in SMOOTHER_FREE}  # the SSD's, else defaults

    def smoother_scores(theta):
        p = {k: x0[k] * float(np.exp(v)) for k, v in zip(SMOOTHER_FREE, theta)}
        kf = AlignmentKalmanFilter(dt, **{**start, **p})
        return alignment_errors(kf.smooth(t, Z)[:, XI], truth, V, dt, skip_s=START_UP_S)["J_rel"], p

    def cost(theta):
        try:
            j, _ = smoother_scores(theta)
        except ValueError:  # a parameter set the filter cannot be built for (e.g. not detectable)
            return 10.0
        return mean_j_rel(j)

    n = len(SMOOTHER_FREE)
    j0, _ = smoother_scores(np.zeros(n))
    theta, nfev, message = np.zeros(n), 0, ""
    for step in (0.5, 0.3, 0.15):  # restarts with a fresh, smaller simplex: the cost is rough
        simplex = np.vstack([theta, theta + step * np.eye(n)])
        fit = minimize(cost, theta, method="Nelder-Mead",
                       options={"maxfev": args.max_evaluations // 3, "initial_simplex": simplex,
                                "xatol": 0.01, "fatol": 1e-4})
        theta, nfev, message = fit.x, nfev + fit.nfev, fit.message
        print(f"  restart (simplex {step}): mean smoother J_rel {fit.fun:.4f} after {nfev} evaluations")
    j1, p1 = smoother_scores(theta)
    print("smoother J_rel before " + " ".join(f"{j0[b]:.3f}" for b in BANDS)
          + ", after " + " ".join(f"{j1[b]:.3f}" for b in BANDS) + f" ({nfev} evaluations)")
    print("smoother SM: " + ", ".join(f"{k} {x0[k]:.4g} -> {p1[k]:.4g}" for k in SMOOTHER_FREE))

    out = {"filter": {"q_xi": best["q_xi"], "sigma_virtual": best["sigma_virtual"],
                      "criterion": "smallest mean filter J_rel over whole, D1, D2, D3 on the training track",
                      "grid": grid},
           "smoother": {"parameters": p1, "initial": x0, "J_rel_before": j0, "J_rel_after": j1,
                        "criterion": "smallest mean smoother J_rel over whole, D1, D2, D3 on the training track "
                                     "(Nelder-Mead in log space)",
                        "evaluations": int(nfev), "message": str(message)},
           "training_track": TRAINING_TRACK, "training_noise_seed": TRAINING_NOISE_SEED, "variant": "standard",
           "other_settings": {k: v for k, v in settings.items() if k not in ("q_xi", "sigma_virtual")}}
    args.out.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
