"""Whether the container master can be trusted with a system, proven before the run.

FMPy's container FMU loads every FMU into one native process; a third-party FMU it cannot
drive (libcosim's crane demo, an OpenModelica ``Add``) takes that process down with a
segfault or a panic, where the Python masters get a clean error or run it. So a system with an
FMU railfmu did not build gets a short trial run of the container in a child process first
(a few steps, no sinks); if the child dies or fails, :func:`container_refusal` says why and
the caller runs the Jacobi master instead. railfmu's own FMUs are tested with the container
and skip the trial.

Only systems with an FMI 3.0 component reach FMPy's container now. An FMI 2.0 system runs in
the container master's own C loop (:mod:`railfmu.fmus.cosim.native_loop`), which calls the
FMUs as the Jacobi master does and, like that master, needs no trial: the crane demo runs
there.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import signal

from railfmu.fmus.cosim.system import System

TRIAL_STEPS = 10  # enough to pass initialisation and a few doStep calls
TRIAL_TIMEOUT_S = 120.0


def built_by_railfmu(md) -> bool:
    from railfmu.fmus.generate import GENERATOR

    return (md.generationTool or "").split(" ")[0] == GENERATOR


def container_refusal(system: System, run_container) -> str | None:
    """None if the container master may run ``system``; else one line saying why not.
    ``run_container(system, sinks, progress)``: the container master, tried in the child."""
    if all(built_by_railfmu(c.md) for c in system.components):
        return None
    n = max(1, min(TRIAL_STEPS, round((system.stop_time - system.start_time) / system.step_size)))
    trial = dataclasses.replace(system, stop_time=system.start_time + n * system.step_size, observers=[])
    ctx = multiprocessing.get_context("fork")  # the parent has loaded no FMU yet
    reader, writer = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_trial, args=(run_container, trial, writer), daemon=True)
    child.start()
    writer.close()
    child.join(TRIAL_TIMEOUT_S)
    if child.is_alive():
        child.kill()
        child.join()
        return f"a {n}-step trial run of the container did not finish in {TRIAL_TIMEOUT_S:g} s"
    try:
        message = reader.recv() if reader.poll() else None
    except (EOFError, OSError):  # the child died before it could say why
        message = None
    if child.exitcode == 0:
        return None
    if child.exitcode is not None and child.exitcode < 0:
        try:
            name = signal.Signals(-child.exitcode).name
        except ValueError:
            name = f"signal {-child.exitcode}"
        return f"a {n}-step trial run of the container crashed ({name})"
    return f"a {n}-step trial run of the container failed: {message or f'exit code {child.exitcode}'}"


def _trial(run_container, system: System, writer) -> None:
    import faulthandler

    faulthandler.disable()  # a crash is the finding, said by the parent in one line
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # what the FMUs print on their way down stays out of the user's terminal
    os.dup2(devnull, 2)
    code = 0
    try:
        run_container(system, [], False)
    except BaseException as exc:  # noqa: BLE001 - everything is a reason not to trust the container
        writer.send(" ".join(str(exc).split()) or type(exc).__name__)
        code = 3
    writer.close()
    os._exit(code)  # no atexit handlers of the parent's (they would remove its unpacked FMUs)
