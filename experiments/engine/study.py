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
Each finished run's metrics (and series) go at once, atomically, to ``runs/<variant>/<seed>.json``
beside the settings they were run with (``runs/study.json``): ``--resume`` after a kill or a
crash runs only the runs missing there, and the table is built from those files either way,
so a resumed table equals an uninterrupted one. Without ``--resume`` a study starts afresh.
A ``--scheduler`` lost midway ends the study with one line (the runs kept, and ``--resume``).
Members write no files (no CSVs, plots or reports; ``--keep-runs`` keeps them, one
sub-folder per variant and seed) and pay no per-run fixed cost a worker has already paid:
imports stay loaded in the worker, the FMUs' up-to-date check derives no model.
"""

from __future__ import annotations

import io
import json
import math
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from railfmu.estimators.track.metrics import rms
from railfmu.models.errors import UserError

from railfmu.experiments.engine.files import check_seed, check_times, ensure_folder, write_atomic
from railfmu.experiments.engine.runner import _json_default, find_experiment, load_system, run_experiment

DEFAULT_FIRST_SEED = 1
MAX_RUNS = 1_000_000  # seeds and futures are held in memory: 10**12 runs would be killed by the OOM killer
MAX_WORKERS = 1024  # worker processes of a local cluster
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
    try:
        return run_experiment(name, variant, out, master=master, progress=False, log=log,
                              write_files=out is not None, series=series, **overrides)
    except UserError as exc:  # a value, not raised: Dask would log the worker's traceback
        return _MemberError(str(exc))


class _MemberError(str):
    """A member's one-line user error, handed back from the worker."""


RUNS_DIR = "runs"


def _canonical(result: dict) -> tuple[str, dict, dict]:
    """A member's result as stored (JSON text) and as the table sees it (metrics; series as
    arrays): a resumed study reads the same text back, so both paths build the same table."""
    text = json.dumps(result, indent=1, default=_json_default) + "\n"
    return (text, *_from_text(text))


def _from_text(text: str) -> tuple[dict, dict]:
    metrics = json.loads(text)
    series = {k: None if v is None else np.asarray(v) for k, v in metrics.pop("series", {}).items()}
    return metrics, series


def _run_file(runs_dir: Path, variant: str, seed: int | None) -> Path:
    return runs_dir / variant / f"{'default' if seed is None else seed}.json"


def _stored_runs(runs_dir: Path, settings: dict, resume: bool, keys) -> dict:
    """The runs already finished in ``runs_dir`` with these settings (``resume``), else none
    (and the folder emptied, so no stale run is ever mixed into a table)."""
    manifest = runs_dir / "study.json"
    if not resume:
        shutil.rmtree(runs_dir, ignore_errors=True)
    elif manifest.is_file():
        try:
            before = json.loads(manifest.read_text())
        except (OSError, ValueError):
            before = None
        if before != settings:
            changed = [k for k in settings if not isinstance(before, dict) or before.get(k) != settings[k]]
            raise UserError(f"--resume: {runs_dir} holds runs made with other settings "
                            f"({', '.join(changed) or 'unreadable'}); give another --out, or drop --resume "
                            "to start afresh")
    runs_dir.mkdir(parents=True, exist_ok=True)
    write_atomic(manifest, json.dumps(settings, indent=1, sort_keys=True) + "\n")
    found = {}
    for key in keys:
        path = _run_file(runs_dir, *key)
        try:
            found[key] = _from_text(path.read_text())
        except (OSError, ValueError):  # missing (never half-written: write_atomic)
            continue
    return found


def _user_files(sets: dict) -> dict[str, str]:
    """Make every file a ``--set`` names (``X.file``, ``X.*_file``) that exists relative to the
    current directory absolute before the tasks leave (a worker's directory is not the user's);
    ``resources/...`` stays the SSP's. Anything else is left as given for the SSP reader, the one
    place that decides what a file name means (an FMU's own table, or a one-line error the first
    member returns). Returns ``{name: absolute path}``."""
    out = {}
    for comp, params in sets.items():
        for param, value in list(params.items()):
            if not (param == "file" or param.endswith("_file")) or not isinstance(value, str) or not value \
                    or value.startswith("resources/"):
                continue
            path = Path(value).expanduser()
            path = path if path.is_absolute() else Path.cwd() / path
            if path.is_file():
                params[param] = out[f"{comp}.{param}"] = str(path.resolve())
    return out


def _workers_see(client, scheduler: str, files: dict[str, str]) -> None:
    """A remote scheduler's workers read the files where the user named them: each must see
    the path (a shared file system); a one-line error names the first that does not."""
    import os

    for name, path in files.items():
        seen = client.run(os.path.isfile, path)
        blind = [w for w, ok in seen.items() if not ok]
        if blind:
            raise UserError(f"--scheduler {scheduler}: worker {blind[0]} cannot see {name}={path}; the workers must "
                            "see the files a study names at the same path (a shared file system)")


def _eta(elapsed: float, done: int, total: int) -> str:
    left = elapsed / done * (total - done)
    return f"~{left:.0f} s left" if done < total else "done"


def _scheduler_lost(client, scheduler: str, runs_dir: Path, done: int, total: int) -> UserError:
    """The one line for a scheduler that went away mid-study: the runs received so far are
    already in runs_dir; --resume runs the others (on any scheduler, or a local cluster)."""
    import logging

    logging.getLogger("distributed.client").setLevel(logging.CRITICAL)  # its reconnect's traceback
    client.close(timeout=2)
    return UserError(f"--scheduler {scheduler}: lost the scheduler after {done} of {total} runs; the "
                     f"finished ones are kept in {runs_dir}: rerun with --resume (a running --scheduler, "
                     "or none for a local cluster) to run the others")


def run_study(name: str, out: Path | str | None = None, scheduler: str | None = None,
              master: str | None = None, workers: int | None = None, variants: list[str] | None = None,
              runs: int = 1, keep_runs: bool = False, seed: int | None = None, log=sys.stderr,
              resume: bool = False, **overrides) -> dict:
    """Run the study; writes table.json and table.md into ``out`` and returns the table.
    ``master`` None: each run takes the experiment's preferred master (its SSD's
    ``<rf:FixedStep master=...>``), else jacobi. ``resume``: keep the runs a previous study
    into ``out`` with the same settings finished (``out/runs``) and run only the others."""
    from concurrent.futures import CancelledError

    from dask.distributed import Client, LocalCluster, as_completed
    from distributed.comm.core import CommClosedError

    from railfmu.fmus.generate.build import build_all, default_out, sources_key

    exp = find_experiment(name)
    if not exp.variants:
        raise UserError(f"experiment {exp.name}: no variants to study")
    unknown = [v for v in variants or [] if v not in exp.variants]
    if unknown:
        raise UserError(f"experiment {exp.name}: unknown variant {unknown[0]!r}; known: {', '.join(exp.variants)}")
    if not 1 <= runs <= MAX_RUNS:
        raise UserError(f"--runs {runs}: must be from 1 to {MAX_RUNS:,}")
    selected = list(dict.fromkeys(variants)) if variants else exp.variants
    monte_carlo = runs > 1
    first = seed if seed is not None else DEFAULT_FIRST_SEED
    seeds = [first + i for i in range(runs)] if monte_carlo else [seed]
    if workers is not None and not 1 <= workers <= MAX_WORKERS:
        raise UserError(f"--workers {workers}: must be from 1 to {MAX_WORKERS}")
    check_seed(first)
    check_times(overrides.get("stop_time"), overrides.get("step_size"))
    check_seed(first + runs - 1, f"--seed {first} with --runs {runs}: the last seed")
    files = _user_files(overrides.get("sets") or {})  # relative to this folder, not the workers'
    out = Path(out or Path("out") / f"{exp.name}_study")
    ensure_folder(out)
    build_all(default_out())  # once, before workers would race to build the same FMUs
    settings = json.loads(json.dumps({
        "experiment": exp.name, "master": master, "monte_carlo": monte_carlo, "keep_runs": keep_runs,
        "overrides": overrides, "fmu_sources": sources_key()[:16]}, default=str))
    runs_dir = out / RUNS_DIR
    wanted = [(v, s) for v in selected for s in seeds]
    stored = _stored_runs(runs_dir, settings, resume, wanted)
    if resume and log is not None:
        print(f"study {exp.name}: {len(stored)} of {len(wanted)} runs already in {runs_dir}, "
              f"{len(wanted) - len(stored)} to run", file=log)

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
    total = len(wanted)
    target = exp.name if exp.packaged else str(exp.path)
    results: dict[tuple[str, int | None], tuple[dict, dict]] = dict(stored)
    todo = [k for k in wanted if k not in stored]
    try:
        if todo and scheduler:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise UserError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
            _workers_see(client, scheduler, files)
        elif todo:
            cluster = LocalCluster(n_workers=min(workers or 2, len(todo)), threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=40)
            client = Client(cluster)
        if todo:
            what = f"{len(selected)} variants x {runs} seeds ({seeds[0]}..{seeds[-1]})" if monte_carlo \
                else f"{len(selected)} variants"
            print(f"study {exp.name}: {what} on {client.scheduler.address}", file=log)
            futures = {client.submit(_run_member, target, v, member_out(v, s), master, {**member_overrides[v], "seed": s},
                                     monte_carlo, key=f"{exp.name}-{v}-{s}", pure=False): (v, s)
                       for v, s in todo}
            for i, fut in enumerate(as_completed(futures), len(stored) + 1):
                v, s = futures[fut]
                try:
                    result = fut.result()
                except (CancelledError, CommClosedError):
                    if not scheduler or client.status == "running":
                        raise
                    raise _scheduler_lost(client, scheduler, runs_dir, i - 1, total) from None
                if isinstance(result, _MemberError):
                    raise UserError(f"variant {v}{f' seed {s}' if monte_carlo else ''}: {result}")
                text, *results[v, s] = _canonical(result)
                path = _run_file(runs_dir, v, s)
                path.parent.mkdir(parents=True, exist_ok=True)
                write_atomic(path, text)  # as it finishes: a killed study keeps it
                elapsed = time.monotonic() - t0
                print(f"  [{i}/{total}] {v}{f' seed {s}' if monte_carlo else ''} done ({elapsed:.1f} s, "
                      f"{_eta(elapsed, i - len(stored), total - len(stored))})", file=log)
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
    md = [f"# Study {exp.name}", "", exp.description, ""]
    if monte_carlo:
        table, series = {}, {}
        for v in selected:
            series[v] = {s: results[v, s][1] for s in seeds}
            member_runs = {s: results[v, s][0] for s in seeds}
            table[v] = {"runs": member_runs, "summary": summarise(member_runs)}
        extra = exp.study.study_tables(table, series)  # first: it may add values pooled over runs to a summary
        md.append(exp.study.summary_md({v: t["summary"] for v, t in table.items()}, runs))
        md += ["", extra] if extra else []
        plots = exp.study.study_figures(table, series, out)
        md += ["", *[f"![{p}]({p})" for p in plots], ""] if plots else []
        md += ["", "Each run's files are in <variant>/seed_<seed>/." if keep_runs else
               "Members wrote no files (--keep-runs keeps each run's signals, plots and report)."]
    else:
        table = {v: results[v, seeds[0]][0] for v in selected}
        md += [exp.study.table_md(table), "",
               "Each variant's signals, estimates, plots and report are in its sub-folder."]
    write_atomic(out / "table.json", json.dumps(table, indent=2, default=_json_default) + "\n")
    write_atomic(out / "table.md", "\n".join(md) + "\n")
    print(f"wrote {out}/table.json, table.md ({time.monotonic() - t0:.1f} s)", file=log)
    return table
