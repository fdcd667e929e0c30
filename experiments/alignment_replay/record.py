"""Write the measured table this experiment replays: a run of ``track_wheelset`` as an axle-box
logger would record it.

    python -m railfmu.experiments.alignment_replay.record [SECONDS] [--from RUN] [--to FILE]

runs ``railfmu run track_wheelset --stop-time SECONDS`` (default 3 s of the ``psd`` variant:
ERRI B176 low-level alignment at 20 m/s, 1 kHz), or takes the output folder ``RUN`` of a run
you made, and keeps ``time,ddy,dpsi,ddy_f,alignment`` of its ``signals.csv`` in ``FILE``
(default ``resources/axlebox_run.csv``). The cells are copied as text:
``signals.csv`` holds ``repr`` floats, which read back to the same doubles, so the replay
feeds the observer exactly the samples the simulated run fed it.
"""

from __future__ import annotations

import argparse
import csv
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seconds", nargs="?", type=float, default=3.0)
    ap.add_argument("--from", dest="run", type=Path, default=None, help="a track_wheelset output folder")
    ap.add_argument("--to", type=Path, default=TABLE)
    args = ap.parse_args(argv)
    path = (table_from_signals(args.run / "signals.csv", args.to) if args.run is not None
            else record(args.seconds, args.to))
    print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
