"""One FMU run on its own, as ``fmpy simulate`` runs it: ``railfmu run X.fmu``.

The system has one component (named after the FMU's model identifier) and no connection; its
inputs keep their start values, ``--set <modelIdentifier>.<parameter>=<value>`` sets a
parameter. The time grid is FMPy's: start and stop from the FMU's DefaultExperiment (0 and
start + 1 s without one), and the communication step its CoSimulation fixedInternalStepSize,
else the DefaultExperiment stepSize (doubled until the run has at most 1000 steps), else
FMPy's ``auto_interval`` (500 to 1000 steps); ``--stop-time`` and ``--step-size`` override.
"""

from __future__ import annotations

from pathlib import Path

from railfmu.models.errors import UserError
from railfmu.fmus.cosim.system import Component, System, check_system, read_model
from railfmu.fmus.ssp.params import from_cli, why_not_settable


def system_of_fmu(path, overrides: dict | None = None, start_time: float | None = None,
                  stop_time: float | None = None, step_size: float | None = None) -> System:
    """The :class:`System` of one FMU; ``overrides``: ``{modelIdentifier: {parameter: value}}``."""
    from fmpy.util import auto_interval

    path = Path(path)
    fmu, md = read_model(path, str(path))
    name = md.coSimulation.modelIdentifier
    comp = Component(name, fmu, model=md)
    for cname, values in (overrides or {}).items():
        if cname != name:
            raise UserError(f"--set {cname}.{next(iter(values), '?')}: no component {cname!r}; "
                            f"the FMU's component is {name!r}")
        for param, value in values.items():
            where = f"--set {cname}.{param}"
            var = comp.variable(param, where)
            why = why_not_settable(var)
            if why:
                raise UserError(f"{where}: {path.name} variable {param!r} {why}; it cannot be set")
            comp.parameters[param] = from_cli(value, var, where)
    de = md.defaultExperiment
    start = float(start_time if start_time is not None else
                  (de.startTime if de is not None and de.startTime is not None else 0.0))
    stop_from = "--stop-time" if stop_time is not None else "the FMU's DefaultExperiment"
    if stop_time is None:
        if de is not None and de.stopTime is not None:
            stop_time = de.stopTime
        else:
            stop_time, stop_from = start + 1.0, "FMPy's default (start + 1 s)"
    stop = float(stop_time)
    if step_size is not None:
        step, step_from = float(step_size), "--step-size"
    else:
        given = md.coSimulation.fixedInternalStepSize or (de.stepSize if de is not None else None)
        if given is not None:
            step, step_from = float(given), "the FMU's DefaultExperiment stepSize"
            while (stop - start) / step > 1000:  # as fmpy simulate
                step *= 2
            if step != float(given):
                step_from += f" {float(given):g} s, doubled to at most 1000 steps as fmpy simulate does"
        else:
            step, step_from = float(auto_interval(stop - start)), "FMPy's output interval for the run's length"
    system = System(name=name, components=[comp], connections=[], start_time=start, stop_time=stop,
                    step_size=step, source=path, description=md.description or "",
                    step_size_from=step_from, stop_time_from=stop_from)
    try:
        check_system(system)
    except UserError as exc:
        raise UserError(f"{path}: {exc}") from None
    return system
