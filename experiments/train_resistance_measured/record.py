"""Write the example measured run this experiment replays: one simulated run of
``train_resistance`` as an operator's GNSS log would hold it.

    python -m railfmu.experiments.train_resistance_measured.record [SEED] [--from RUN] [--to FILE]

runs ``railfmu run train_resistance`` (variant ``standard``, default seed 1), or takes the
output folder ``RUN`` of a run you made, and keeps, at each GNSS fix (every 10 s),
``time_s``, the measured ``position_m`` (4 m noise, written to 0.1 m) and ``speed_kmh`` (the
receiver's, rounded to 1 km/h) in ``FILE`` (default ``resources/example_run.csv``).
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
TABLE = HERE / "resources" / "example_run.csv"
HEADER = ("time_s", "position_m", "speed_kmh")


def table_from_signals(signals_csv: Path, out: Path) -> Path:
    """``time_s,position_m,speed_kmh`` at the rows of ``signals.csv`` where ``gnss.valid`` is 1."""
    lines = [",".join(HEADER)]
    with open(signals_csv, newline="") as f:
        for row in csv.DictReader(f):
            if row["gnss.valid"] == "1":
                kmh = round(float(row["gnss.speed"]) * 3.6)
                lines.append(f"{float(row['time']):g},{float(row['gnss.position']):.1f},{kmh:d}")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    return out


def record(seed: int = 1, out: Path = TABLE) -> Path:
    from railfmu.experiments.engine.runner import run_experiment

    with tempfile.TemporaryDirectory() as tmp:
        run_experiment("train_resistance", "standard", out=tmp, seed=seed, progress=False)
        return table_from_signals(Path(tmp) / "signals.csv", out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=int, default=1)
    ap.add_argument("--from", dest="run", type=Path, default=None, help="a train_resistance output folder")
    ap.add_argument("--to", type=Path, default=TABLE)
    args = ap.parse_args(argv)
    print(table_from_signals(args.run / "signals.csv", args.to) if args.run is not None else record(args.seed, args.to))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
