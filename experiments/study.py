"""``railfmu study``: every variant of an experiment, in parallel through Dask.

Each variant is one task (an independent co-simulation in a worker process, since FMUs are
native libraries with their own state); a local cluster by default, or the scheduler at
``--scheduler``. Writes ``table.json`` ({variant: metrics}), ``table.md`` and one sub-folder
per variant.
"""

from __future__ import annotations

import io
import json
import sys
import time
from pathlib import Path

from fmus.errors import UserError

from .runner import _json_default, find_experiment, run_experiment


def _run_variant(name: str, variant: str, out: str, master: str, overrides: dict) -> dict:
    """Worker task: one variant, output captured (workers have no terminal)."""
    log = io.StringIO()
    return run_experiment(name, variant, out, master=master, progress=False, log=log, **overrides)


def run_study(name: str, out: Path | str | None = None, scheduler: str | None = None,
              master: str = "jacobi", workers: int | None = None, log=sys.stderr, **overrides) -> dict:
    from dask.distributed import Client, LocalCluster, as_completed

    from fmus.generate.build import DEFAULT_OUT, build_all

    exp = find_experiment(name)
    if not exp.variants:
        raise UserError(f"experiment {exp.name}: no variants to study")
    out = Path(out or Path("out") / f"{exp.name}_study")
    out.mkdir(parents=True, exist_ok=True)
    build_all(DEFAULT_OUT)  # once, before workers would race to build the same FMUs
    cluster = None
    t0 = time.monotonic()
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise UserError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        else:
            n = workers or min(len(exp.variants), 2)
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=40)
            client = Client(cluster)
        print(f"study {exp.name}: {len(exp.variants)} variants on {client.scheduler.address}", file=log)
        futures = {client.submit(_run_variant, str(exp.path if exp.module is None else exp.name), v,
                                 str(out / v), master, overrides, key=f"{exp.name}-{v}", pure=False): v
                   for v in exp.variants}
        table: dict[str, dict] = {}
        for i, fut in enumerate(as_completed(futures), 1):
            v = futures[fut]
            try:
                table[v] = fut.result()
            except UserError as exc:
                raise UserError(f"variant {v}: {exc}") from None
            print(f"  [{i}/{len(futures)}] {v} done ({time.monotonic() - t0:.1f} s)", file=log)
        client.close()
    finally:
        if cluster is not None:
            cluster.close()
    table = {v: table[v] for v in exp.variants}
    (out / "table.json").write_text(json.dumps(table, indent=2, default=_json_default) + "\n")
    md = [f"# Study {exp.name}", "", exp.description, ""]
    if exp.module is not None and hasattr(exp.module, "table_md"):
        md.append(exp.module.table_md(table))
    else:
        md += ["| variant | wall [s] |", "|---|---|"] + [f"| {v} | {m['wall_time_s']:.2f} |" for v, m in table.items()]
    md += ["", "Each variant's signals, estimates, plots and report are in its sub-folder."]
    (out / "table.md").write_text("\n".join(md) + "\n")
    print(f"wrote {out}/table.json, table.md ({time.monotonic() - t0:.1f} s)", file=log)
    return table
