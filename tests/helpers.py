"""Data from the real FMUs for estimator tests: the track -> wheelset system through the
Jacobi master (railfmu.fmus.cosim.masters), as `railfmu run track_wheelset` couples it."""

from pathlib import Path

import numpy as np

from railfmu.fmus.cosim.masters import run
from railfmu.experiments.engine.recorder import CsvRecorder
from railfmu.fmus.cosim.system import Component, Connection, System

SENSORS = ("ddy", "dpsi", "ddy_f")


def track_wheelset_signals(fmu_dir: Path, track_params: dict, stop_time: float, out_csv: Path | None = None,
                           step_size: float = 1e-3):
    """Returns (t, Z, xi_true): Z the columns wheelset.ddy, dpsi, ddy_f; xi_true the alignment
    under the leading wheelset. Writes signals.csv to ``out_csv`` if given."""
    system = System(
        "track_wheelset",
        [Component("track", fmu_dir / "TrackIrregularity.fmu", dict(track_params)),
         Component("wheelset", fmu_dir / "WheelsetLateral.fmu")],
        [Connection("track", "alignment_1", "wheelset", "xi"),
         Connection("track", "alignment_rate_1", "wheelset", "xi_rate")],
        stop_time=stop_time, step_size=step_size,
        record=["track.alignment_1", *(f"wheelset.{s}" for s in SENSORS)])
    res = run(system, "jacobi", sinks=[CsvRecorder(out_csv)] if out_csv else [], progress=False)
    col = {c: res.data[:, j] for j, c in enumerate(res.columns)}
    Z = np.column_stack([col[f"wheelset.{s}"] for s in SENSORS])
    return col["time"], Z, col["track.alignment_1"]
