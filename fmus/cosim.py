"""A fixed-step Jacobi master on FMPy's FMU2Slave, with a recorder that writes as it goes.

Jacobi: at every communication point all connected outputs are read, copied to the inputs,
then every FMU steps. This is the coupling FMPy's container FMU and libcosim's fixed-step
algorithm use, so their trajectories can be compared sample by sample.
"""

from __future__ import annotations

import csv
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from .errors import UserError
from .slave import Slave


@dataclass
class Connection:
    src: str  # component
    src_var: str
    dst: str
    dst_var: str


@dataclass
class Component:
    name: str
    fmu: Path
    parameters: dict[str, float | int | bool | str] = field(default_factory=dict)


def simulate(components: list[Component], connections: list[Connection], stop_time: float,
             step_size: float, out_csv: Path | None = None, record: list[tuple[str, str]] | None = None,
             start_time: float = 0.0, progress: bool = True) -> dict[str, list[float]]:
    """Run the system with the Jacobi scheme; returns the recorded signals by ``comp.var``
    (and writes them to ``out_csv`` row by row, so an interrupted run leaves a readable file)."""
    n_steps = round((stop_time - start_time) / step_size)
    if n_steps < 1 or not math.isclose(start_time + n_steps * step_size, stop_time, rel_tol=1e-9, abs_tol=1e-12):
        raise UserError(f"step size {step_size} s does not divide the interval [{start_time}, {stop_time}] s")
    loaded: dict[str, Slave] = {}
    writer_file = None
    try:
        for c in components:
            s = loaded[c.name] = Slave(c.fmu, c.name)
            s.enter_initialization(start_time, stop_time)
            for name, value in c.parameters.items():
                s.set(name, value)
        for c in connections:
            for comp in (c.src, c.dst):
                if comp not in loaded:
                    raise UserError(f"connection {c.src}.{c.src_var} -> {c.dst}.{c.dst_var}: "
                                    f"unknown component {comp!r}")
        links = [(loaded[c.src].var(c.src_var).valueReference, loaded[c.src],
                  loaded[c.dst].var(c.dst_var).valueReference, loaded[c.dst]) for c in connections]
        record = record or [(n, v.name) for n, f in loaded.items() for v in f.md.modelVariables
                            if v.causality == "output"]
        rec = [(f"{c}.{v}", loaded[c], loaded[c].var(v).valueReference) for c, v in record]
        for f in loaded.values():
            f.exit_initialization()

        columns = ["time", *[name for name, _, _ in rec]]
        data: dict[str, list[float]] = {k: [] for k in columns}
        if out_csv is not None:
            out_csv.parent.mkdir(parents=True, exist_ok=True)
            writer_file = open(out_csv, "w", newline="")
            writer = csv.writer(writer_file)
            writer.writerow(columns)

        def sample(t: float) -> None:
            row = [t] + [f.fmu.getReal([vr])[0] for _, f, vr in rec]
            for k, v in zip(columns, row):
                if not math.isfinite(v):
                    raise UserError(f"{k} = {v} at t = {t:.6g} s: a non-finite value left an FMU")
                data[k].append(v)
            if writer_file is not None:
                writer.writerow([repr(v) for v in row])

        t0 = time.monotonic()
        last_report = t0
        for k in range(n_steps + 1):
            t = start_time + k * step_size
            for vr_src, src, vr_dst, dst in links:  # Jacobi: all outputs first, then all steps
                dst.fmu.setReal([vr_dst], src.fmu.getReal([vr_src]))
            sample(t)
            if k == n_steps:
                break
            for f in loaded.values():
                f.do_step(t, step_size)
            now = time.monotonic()
            if progress and now - last_report > 1.0:
                print(f"\r  t = {t:8.3f} / {stop_time:g} s ({100 * k / n_steps:5.1f} %)", end="", file=sys.stderr)
                last_report = now
        if progress and time.monotonic() - t0 > 1.0:
            print(f"\r  t = {stop_time:8.3f} / {stop_time:g} s (100.0 %)", file=sys.stderr)
        return data
    finally:
        if writer_file is not None:
            writer_file.close()
        for f in loaded.values():
            f.close()
