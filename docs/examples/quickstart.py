"""Quickstart: run an experiment from Python and read a signal, an estimate and a metric.

The track irregularity FMU drives the wheelset model; an alignment Kalman filter estimates
the track's alignment from the wheelset's sensors. ``python quickstart.py [FOLDER]`` also
writes the files of ``railfmu run --out FOLDER`` and a figure ``quickstart.png`` there.
"""

import sys
from pathlib import Path

import numpy as np

import railfmu

r = railfmu.run("track_wheelset", seed=1, stop_time=5.0)  # 5 s of the default variant (psd)

t = r.signals["time"]
y = r.signals["wheelset.y"]                     # wheelset lateral displacement [m]
xi_hat = r.estimates["alignment"]["xi"]         # the filter's estimate of the alignment [m]
xi = r.signals[r.metrics["roles"]["alignment"]]  # its truth: the track's alignment under the wheelset
score = r.metrics["observers"]["alignment"]["xi"]

print(f"{len(t)} samples, t = {t[0]:g}..{t[-1]:g} s; wheelset y rms {1e3 * np.sqrt(np.mean(y**2)):.3f} mm")
print(f"alignment estimate: rms error {1e3 * score['rms_error']:.3f} mm of {1e3 * score['rms_truth']:.3f} mm rms "
      f"(after t = {score['from_time_s']:g} s)")

if len(sys.argv) > 1:
    out = Path(sys.argv[1])
    print("wrote", ", ".join(r.save(out)))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3))
    ax.plot(t, 1e3 * xi, label="alignment (truth)")
    ax.plot(r.estimates["alignment"]["time"], 1e3 * xi_hat, label="Kalman filter estimate", lw=0.8)
    ax.set(xlabel="time [s]", ylabel="[mm]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "quickstart.png", dpi=100)
