"""Write the measured table this experiment replays: a run of ``track_wheelset`` as an axle-box
logger would record it.

    python -m railfmu.experiments.alignment_replay.record [SECONDS]

runs ``railfmu run track_wheelset --stop-time SECONDS`` (default 3 s of the ``psd`` variant:
ERRI B176 low-level alignment at 20 m/s, 1 kHz) and keeps ``time,ddy,dpsi,ddy_f,alignment``
of its ``signals.csv`` in ``resources/axlebox_run.csv``. The cells are copied as text:
``signals.csv`` holds ``repr`` floats, which read back to the same doubles, so the replay
feeds the observer exactly the samples the simulated run fed it.
"""

from __future__ import annotations

import csv
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
TABLE = HERE / "resources" / "axlebox_run.csv"
# measured-table column -> the track_wheelset signal it records (units: m/s2, rad/s, m/s2, m)
COLUMNS = {"ddy": "wheelset.ddy", "dpsi": "wheelset.dpsi", "ddy_f": "wheelset.ddy_f",
           "alignment": "track.alignment_1"}


def table_from_signals(signals_csv: Path, out: Path) -> Path:
    """The measured table (``time`` and :data:`COLUMNS`) from a run's ``signals.csv``, cell text
    unchanged (full precision)."""
    with open(signals_csv, newline="") as f:
        rows = csv.reader(f)
        header = next(rows)
        keep = [header.index("time")] + [header.index(s) for s in COLUMNS.values()]
        lines = [",".join(["time", *COLUMNS])] + [",".join(r[j] for j in keep) for r in rows if r]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    return out


def record(seconds: float = 3.0, out: Path = TABLE) -> Path:
    """Run track_wheelset for ``seconds`` and write its measured table to ``out``."""
    from railfmu.experiments.engine.runner import run_experiment

    with tempfile.TemporaryDirectory() as tmp:
        run_experiment("track_wheelset", out=tmp, stop_time=seconds, progress=False)
        return table_from_signals(Path(tmp) / "signals.csv", out)


if __name__ == "__main__":
    path = record(float(sys.argv[1]) if len(sys.argv) > 1 else 3.0)
    print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB)")
