"""``railfmu study``: variants x seeds of an experiment as Dask tasks, and their table.

Each run is one task (an independent co-simulation in a worker process, since FMUs are native
libraries with their own state); a local cluster by default, or the scheduler at
``--scheduler``. One run per variant (``--runs 1``, the default) writes ``table.json``
(``{variant: metrics}``), the study's ``table.md`` and one sub-folder per variant.

``--runs N`` is the Monte Carlo: each variant runs with seeds S, S+1, ..., S+N-1 (``--seed S``,
default 1), every seeded component (track profile, sensor noise) taking the run's seed.
Each member runs the study's :meth:`Study.monte_carlo_stop_time` when it names one and
``--stop-time`` is not given (a per-run statistic needs a record long enough for it).
``table.json`` is then ``{variant: {"runs": {seed: metrics}, "summary": {metric: statistics}}}``
over every numeric metric (nested keys joined with dots) and ``table.md`` shows the summary.
The study's ``study_tables`` runs before its ``summary_md`` and may add to a variant's summary
what only the members' series together give (e.g. a statistic pooled over runs at each point
of a grid), as plain values beside the statistics.
Members write no files (no CSVs, plots or reports; ``--keep-runs`` keeps them, one
sub-folder per variant and seed) and pay no per-run fixed cost a worker has already paid:
imports stay loaded in the worker, the FMUs' up-to-date check derives no model.
"""

from __future__ import annotations

import io
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from railfmu.estimators.track.metrics import rms
from railfmu.models.errors import UserError

from railfmu.experiments.engine.runner import _json_default, find_experiment, load_system, run_experiment

DEFAULT_FIRST_SEED = 1
# the run's inputs, echoed in its metrics: not summarised
INPUT_KEYS = {"parameters", "observer_settings", "roles", "seed", "start_time_s", "stop_time_s", "step_size_s",
              "simulated_seconds"}


def flatten(metrics: dict, prefix: str = "") -> dict[str, float]:
    """Every numeric leaf of nested ``metrics`` as ``{"a.b.c": value}`` (booleans, strings and
    None are not numbers here; non-finite numbers are left out)."""
    flat: dict[str, float] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, f"{name}."))
        elif isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_)):
            if math.isfinite(value):
                flat[name] = float(value)
    return flat


def statistics(values) -> dict[str, float]:
    """mean; sample standard deviation (N - 1; 0 for one value); rms = sqrt(mean(x^2)); min;
    p50 and p95 (linear interpolation between order statistics, numpy's default); max."""
    x = np.asarray(values, dtype=float)
    return {"mean": float(x.mean()), "std": float(x.std(ddof=1)) if x.size > 1 else 0.0,
            "rms": rms(x), "min": float(x.min()),
            "p50": float(np.percentile(x, 50)), "p95": float(np.percentile(x, 95)), "max": float(x.max())}


def summarise(runs: dict) -> dict[str, dict[str, float]]:
    """``{metric: statistics}`` over the runs (``{seed: metrics}``) of every numeric metric that
    is not an input of the run (:data:`INPUT_KEYS`); a metric counts the runs that have it."""
    flat = [flatten({k: v for k, v in m.items() if k not in INPUT_KEYS}) for m in runs.values()]
    keys = list(dict.fromkeys(k for f in flat for k in f))
    return {k: statistics([f[k] for f in flat if k in f]) for k in keys}


def _run_member(name: str, variant: str, out: str | None, master: str | None, overrides: dict,
                series: bool = False) -> dict:
    """Worker task: one run, output captured (workers have no terminal); ``out`` None writes
    nothing; ``series``: the metrics carry the study's per-run arrays (Monte Carlo figures)."""
    log = io.StringIO()
    return run_experiment(name, variant, out, master=master, progress=False, log=log,
                          write_files=out is not None, series=series, **overrides)


def _eta(elapsed: float, done: int, total: int) -> str:
    left = elapsed / done * (total - done)
    return f"~{left:.0f} s left" if done < total else "done"


def run_study(name: str, out: Path | str | None = None, scheduler: str | None = None,
              master: str | None = None, workers: int | None = None, variants: list[str] | None = None,
              runs: int = 1, keep_runs: bool = False, seed: int | None = None, log=sys.stderr,
              **overrides) -> dict:
    """Run the study; writes table.json and table.md into ``out`` and returns the table.
    ``master`` None: each run takes the experiment's preferred master (its SSD's
    ``<rf:FixedStep master=...>``), else jacobi."""
    from dask.distributed import Client, LocalCluster, as_completed

    from railfmu.fmus.generate.build import build_all, default_out

    exp = find_experiment(name)
    if not exp.variants:
        raise UserError(f"experiment {exp.name}: no variants to study")
    unknown = [v for v in variants or [] if v not in exp.variants]
    if unknown:
        raise UserError(f"experiment {exp.name}: unknown variant {unknown[0]!r}; known: {', '.join(exp.variants)}")
    if runs < 1:
        raise UserError(f"--runs {runs}: must be at least 1")
    selected = list(dict.fromkeys(variants)) if variants else exp.variants
    monte_carlo = runs > 1
    first = seed if seed is not None else DEFAULT_FIRST_SEED
    seeds = [first + i for i in range(runs)] if monte_carlo else [seed]
    out = Path(out or Path("out") / f"{exp.name}_study")
    out.mkdir(parents=True, exist_ok=True)
    build_all(default_out())  # once, before workers would race to build the same FMUs

    def member_out(v: str, s: int | None) -> str | None:
        if not monte_carlo:
            return str(out / v)
        return str(out / v / f"seed_{s}") if keep_runs else None

    member_overrides = {v: {**overrides} for v in selected}
    if monte_carlo and overrides.get("stop_time") is None:  # the study's record length for a statistic
        for v in selected:
            system = load_system(exp, v, overrides.get("sets"), None, None, overrides.get("step_size"))
            stop = exp.study.monte_carlo_stop_time(system)
            if stop is not None:
                member_overrides[v]["stop_time"] = float(stop)
                print(f"study {exp.name}: variant {v}: each run {stop:g} s (the study's Monte Carlo record "
                      "length; --stop-time overrides it)", file=log)

    cluster = None
    t0 = time.monotonic()
    total = len(selected) * len(seeds)
    target = exp.name if exp.packaged else str(exp.path)
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise UserError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        else:
            cluster = LocalCluster(n_workers=workers or min(total, 2), threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=40)
            client = Client(cluster)
        what = f"{len(selected)} variants x {runs} seeds ({seeds[0]}..{seeds[-1]})" if monte_carlo \
            else f"{len(selected)} variants"
        print(f"study {exp.name}: {what} on {client.scheduler.address}", file=log)
        futures = {client.submit(_run_member, target, v, member_out(v, s), master, {**member_overrides[v], "seed": s},
                                 monte_carlo, key=f"{exp.name}-{v}-{s}", pure=False): (v, s)
                   for v in selected for s in seeds}
        results: dict[tuple[str, int | None], dict] = {}
        for i, fut in enumerate(as_completed(futures), 1):
            v, s = futures[fut]
            try:
                results[v, s] = fut.result()
            except UserError as exc:
                raise UserError(f"variant {v}{f' seed {s}' if monte_carlo else ''}: {exc}") from None
            elapsed = time.monotonic() - t0
            print(f"  [{i}/{total}] {v}{f' seed {s}' if monte_carlo else ''} done ({elapsed:.1f} s, "
                  f"{_eta(elapsed, i, total)})", file=log)
        client.close()
    finally:
        if cluster is not None:
            cluster.close()
    md = [f"# Study {exp.name}", "", exp.description, ""]
    if monte_carlo:
        table, series = {}, {}
        for v in selected:
            series[v] = {s: results[v, s].pop("series", {}) for s in seeds}
            member_runs = {s: results[v, s] for s in seeds}
            table[v] = {"runs": member_runs, "summary": summarise(member_runs)}
        extra = exp.study.study_tables(table, series)  # first: it may add values pooled over runs to a summary
        md.append(exp.study.summary_md({v: t["summary"] for v, t in table.items()}, runs))
        md += ["", extra] if extra else []
        plots = exp.study.study_figures(table, series, out)
        md += ["", *[f"![{p}]({p})" for p in plots], ""] if plots else []
        md += ["", "Each run's files are in <variant>/seed_<seed>/." if keep_runs else
               "Members wrote no files (--keep-runs keeps each run's signals, plots and report)."]
    else:
        table = {v: results[v, seeds[0]] for v in selected}
        md += [exp.study.table_md(table), "",
               "Each variant's signals, estimates, plots and report are in its sub-folder."]
    (out / "table.json").write_text(json.dumps(table, indent=2, default=_json_default) + "\n")
    (out / "table.md").write_text("\n".join(md) + "\n")
    print(f"wrote {out}/table.json, table.md ({time.monotonic() - t0:.1f} s)", file=log)
    return table
