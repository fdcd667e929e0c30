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


def installed_estimators(site: Path, dist: str = "stub_estimators", **estimators: str) -> Path:
    """A distribution that registers ``estimators`` (name -> ``"module:Class"``) in the entry-point
    group railfmu.estimators, as a third party's installed package would: ``site/<dist>-0.1.dist-info``
    with METADATA and entry_points.txt. Put ``site`` on sys.path (or PYTHONPATH) to install it."""
    info = site / f"{dist}-0.1.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[railfmu.estimators]\n" + "".join(f"{k} = {v}\n" for k, v in estimators.items()))
    return site
