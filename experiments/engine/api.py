"""The public functions of :mod:`railfmu` (re-exported there lazily); the CLI calls them.

Every user error (unknown experiment, variant or parameter, bad value) raises
:class:`railfmu.models.errors.UserError` with a one-line message.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TextIO

# small matrices every step: BLAS threads only fight over them (see cli.py); before numpy loads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from railfmu.models.errors import UserError  # noqa: E402

from railfmu.experiments.engine.parameters import Parameter, list_parameters  # noqa: E402
from railfmu.experiments.engine.result import Run  # noqa: E402
from railfmu.experiments.engine.runner import execute, find_experiment, load_system  # noqa: E402
from railfmu.experiments.engine.studies import experiment_names, register_study  # noqa: E402

__all__ = ["Parameter", "Run", "export", "list_experiments", "parameters", "read_ssp", "register_study", "run",
           "study"]

ExperimentRef = str | os.PathLike  # a name of `railfmu list`, or the path of an .ssp, .ssd or folder


def _sets(parameters: Mapping[str, Any] | None) -> dict[str, dict[str, Any]]:
    """``{"component.param": value}`` -> ``{component: {param: value}}`` (as ``--set``)."""
    out: dict[str, dict[str, Any]] = {}
    for key, value in (parameters or {}).items():
        comp, dot, param = str(key).partition(".")
        if not dot or not comp or not param:
            raise UserError(f"parameter {key!r}: expected 'COMPONENT.PARAM' (see railfmu.parameters())")
        out.setdefault(comp, {})[param] = str(value) if isinstance(value, os.PathLike) else value
    return out


def run(experiment: ExperimentRef, variant: str | None = None, *, parameters: Mapping[str, Any] | None = None,
        seed: int | None = None, master: str | None = None, stop_time: float | None = None,
        step_size: float | None = None, out: str | os.PathLike | None = None, progress: bool = False,
        log: TextIO | None = None, verbose: bool = False, fmi_version: int = 2,
        record_format: str = "csv", sampling: str = "after-transfer") -> Run:
    """Run one experiment and return its signals, estimates and metrics in memory.

    Parameters
    ----------
    experiment : str or path-like
        A name from :func:`list_experiments` (e.g. ``"track_wheelset"``), or the path of an
        ``.ssp`` archive, an ``.ssd`` file or a folder holding ``SystemStructure.ssd``.
    variant : str, optional
        A variant of the experiment (``variants/NAME.ssv``); default: the study's default
        variant, else the SSD as it is.
    parameters : mapping, optional
        ``{"component.parameter": value}`` overrides, as ``railfmu run --set``
        (also ``"observer.setting"`` and ``"experiment.stopTime"``); see :func:`parameters`.
    seed : int, optional
        Seed of every random source (track profile, sensor noise).
    master : str, optional
        ``"jacobi"``, ``"gauss-seidel"`` or ``"container"``; default: the one the SSD names
        (``rf:FixedStep master=``), else jacobi.
    stop_time, step_size : float, optional
        Override the stop time and the communication step [s].
    out : str or path-like, optional
        Also write the files of ``railfmu run --out`` into this folder (signals.csv and
        estimates.csv as the run goes; the rest as :meth:`Run.save`).
    progress : bool
        Show a progress line on stderr.
    log : file, optional
        Where the ``running ...`` / ``wrote ...`` lines and warnings go (default: none;
        warnings then go through :mod:`warnings`).
    verbose : bool
        More detail in ``log``: the study, components, observers, timing.
    fmi_version : int
        2 (default) or 3: run railfmu's FMUs as their FMI 2.0 or FMI 3.0 builds (the same
        model code; the results are equal). An SSP's own packed FMUs run as they are.
    record_format : str
        ``"csv"`` (default), ``"parquet"`` or ``"mat"``: the format of the signals and
        estimates written into ``out`` (:func:`read_signals` reads any of them back).
    sampling : str
        ``"after-transfer"`` (default): each row is read after every connection is copied;
        ``"before-transfer"`` (Jacobi master only): right after the step, before any input is
        set, as libcosim reads; for FMUs that sample their inputs when their outputs are read
        (a direct-feedthrough output then shows the previous step's inputs).

    Returns
    -------
    Run
        ``r.signals["wheelset.y"]``, ``r.estimates["alignment"]["xi"]``, ``r.metrics``,
        ``r.system``, ``r.save(folder)``, ``r.report()``, ``r.to_pandas()``.

    Raises
    ------
    railfmu.models.errors.UserError
        A one-line message for anything the caller can fix.

    Examples
    --------
    >>> import railfmu
    >>> r = railfmu.run("track_wheelset", seed=1, stop_time=2.0)   # doctest: +SKIP
    >>> r.metrics["observers"]["alignment"]["xi"]["rms_error"]     # doctest: +SKIP
    """
    if out is not None:  # the figures' worker imports matplotlib while the run sets up and steps
        from railfmu.experiments.engine.figure_worker import start

        start()
    r = execute(experiment, variant, out, master, _sets(parameters), seed, stop_time, step_size,
                progress=progress, log=log, verbose=verbose, fmi_version=fmi_version,
                record_format=record_format, sampling=sampling, figures=out is not None)
    if out is not None:
        r.save(out, log=log)
    return r


def study(experiment: ExperimentRef, variants: list[str] | None = None, *, runs: int = 1, seed: int | None = None,
          parameters: Mapping[str, Any] | None = None, master: str | None = None, stop_time: float | None = None,
          step_size: float | None = None, out: str | os.PathLike | None = None, scheduler: str | None = None,
          workers: int | None = None, keep_runs: bool = False, resume: bool = False,
          log: TextIO | None = None) -> dict:
    """Run variants x seeds of an experiment in parallel (Dask) and return the study table.

    Parameters
    ----------
    experiment : str or path-like
        As for :func:`run`.
    variants : list of str, optional
        The variants to run (default: all).
    runs : int
        Monte Carlo: ``runs`` runs per variant with seeds ``seed, seed + 1, ...`` (default
        first seed 1).
    seed, parameters, master, stop_time, step_size
        As for :func:`run`.
    out : str or path-like, optional
        Folder of table.json, table.md and the runs' sub-folders (default ``out/EXP_study``).
    scheduler : str, optional
        Address of a running Dask scheduler (default: a local cluster of ``workers``).
    workers : int, optional
        Local cluster size (default: min(runs in all, 2)).
    keep_runs : bool
        With ``runs > 1``: keep each run's files.
    resume : bool
        Keep the runs a previous study into ``out`` with the same settings finished (each is
        saved as it finishes, in ``out/runs``) and run only the missing ones.
    log : file, optional
        Where the progress lines go (default: none).

    Returns
    -------
    dict
        table.json: ``{variant: metrics}``, or with ``runs > 1``
        ``{variant: {"runs": {seed: metrics}, "summary": {metric: statistics}}}``.
    """
    from railfmu.experiments.engine.study import run_study

    return run_study(str(experiment), out, scheduler=scheduler, master=master, workers=workers,
                     variants=variants, runs=runs, keep_runs=keep_runs, seed=seed,
                     resume=resume, log=log if log is not None else io.StringIO(), sets=_sets(parameters),
                     stop_time=stop_time, step_size=step_size)


def read_ssp(experiment: ExperimentRef, variant: str | None = None, *, parameters: Mapping[str, Any] | None = None,
             seed: int | None = None, stop_time: float | None = None, step_size: float | None = None,
             fmi_version: int = 2):
    """The resolved system of an experiment or SSP, its FMUs built, without running it.

    Parameters
    ----------
    experiment, variant, parameters, seed, stop_time, step_size, fmi_version
        As for :func:`run`.

    Returns
    -------
    railfmu.fmus.cosim.system.System
        Components with their final parameters, connections, times, recorder, observers
        and ``study`` (the study the SSD names).
    """
    exp = find_experiment(experiment)
    return load_system(exp, variant or exp.default_variant, _sets(parameters), seed, stop_time, step_size,
                       fmi_version)


def export(experiment: ExperimentRef, path: str | os.PathLike, variant: str | None = None, *,
           parameters: Mapping[str, Any] | None = None, seed: int | None = None, stop_time: float | None = None,
           step_size: float | None = None, fmi_version: int = 2, ssp_version: str = "1.0") -> Path:
    """Write one variant as a self-contained ``.ssp`` (SSD, final parameters, FMUs).

    The archive names the experiment's study, so ``railfmu.run(path)`` gets its metrics and
    figures; FMPy, libcosim and OMSimulator run it too.

    Parameters
    ----------
    experiment, variant, parameters, seed, stop_time, step_size
        As for :func:`run`.
    fmi_version : int
        2 (default) or 3: pack the FMI 2.0 or the FMI 3.0 builds of the FMUs.
    ssp_version : str
        "1.0" (default) or "2.0" (or 1, 2): write the SSD as SSP 1.0 or SSP 2.0.
    path : str or path-like
        The archive to write; must end in ``.ssp``.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    return export_system(experiment, path, variant, parameters=parameters, seed=seed, stop_time=stop_time,
                         step_size=step_size, fmi_version=fmi_version, ssp_version=ssp_version)[0]


def export_system(experiment: ExperimentRef, path: str | os.PathLike, variant: str | None = None,
                  ssp_version: str = "1.0", **options) -> tuple[Path, Any]:
    """:func:`export`, returning the archive's path and the system written (for the CLI's line)."""
    from railfmu.fmus.ssp import write_ssp
    from railfmu.fmus.ssp.writer import SSP_VERSIONS

    out = Path(path)
    if out.suffix != ".ssp":
        raise UserError(f"-o {out}: the archive name must end in .ssp")
    if out.is_dir():
        raise UserError(f"-o {out}: a folder of that name exists; give a file name")
    version = {"1": "1.0", "2": "2.0"}.get(str(ssp_version), str(ssp_version))
    if version not in SSP_VERSIONS:  # before building and reading anything
        raise UserError(f"--ssp {ssp_version}: railfmu writes SSP 1.0 and 2.0 (1.0 or 2.0)")
    system = read_ssp(experiment, variant, **options)
    return write_ssp(system, out, version), system


def parameters(experiment: ExperimentRef, variant: str | None = None) -> list[Parameter]:
    """What ``parameters`` of :func:`run` (``--set``) can change, with units and defaults.

    Parameters
    ----------
    experiment, variant
        As for :func:`run`.

    Returns
    -------
    list of Parameter
        Each FMU parameter (``component.parameter``: type, unit, the FMU's default, the
        value the variant runs with, description) and each observer setting.
    """
    return list_parameters(str(experiment), variant)


def list_experiments() -> dict[str, dict[str, Any]]:
    """The shipped experiments, as ``railfmu list`` shows them.

    Returns
    -------
    dict
        ``{name: {"description": str, "variants": [str, ...], "default_variant": str or None}}``.
    """
    out = {}
    for name in experiment_names():
        exp = find_experiment(name)
        out[name] = {"description": exp.description, "variants": exp.variants,
                     "default_variant": exp.default_variant}
    return out


def read_signals(path: str | os.PathLike) -> dict[str, "np.ndarray"]:
    """A run's record — ``signals.csv|.parquet|.mat``, ``estimates.*``, or what a killed run
    left (``signals.parquet.spool``: its complete rows) — as ``{column: array}``, bit for bit
    the values the run held. ValueError (one line) for a file it cannot read."""
    from railfmu.experiments.engine.records import read_signals as read

    return read(path)
