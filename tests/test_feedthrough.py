"""The ModelStructure of every FMU is what the FMU does (FMI 2.0 direct feedthrough).

For each built FMU, at one or more operating points: after initialisation (and a few
communication steps where a model needs them), set every input, save the FMU state, then
perturb one input at a time (restoring the state before each) and read all outputs without
fmi2DoStep. An output that changes depends directly on the input. Compared both ways with
``<ModelStructure><Outputs>``: a declared dependency that no operating point shows is as
wrong as an undeclared one (a Gauss-Seidel master reports a false algebraic loop for it).

Tolerance: a Real output changed when |y' - y| > 1e-9 max(|y|, |y'|); Integer and Boolean
outputs exactly. Without fmi2DoStep nothing is integrated: an output that does not read an
input is bit-identical after that input changes (the hand-written C), except where a symbol
cancels in the definition (x - x once expanded) but the generated C, summing its common
subexpressions in its own order, leaves rounding noise (measured on VehicleLateral: 3e-16 and
5e-14 relative). A real dependency moves an output by the order of the perturbation: +37 %
and -130 % of max(|u|, 1) (a Boolean is toggled, an Integer moved by 1). A dependency that
exists only in some region (a clipped command, a speed above zero, the reach tolerance of a
track step, the flange contact) gets an operating point in that region below.

In initialisation mode the same perturbations (outputs computed from the start values)
must show no dependency the Outputs declare not; for generated models the InitialUnknowns
list (time, parameters, state starts, inputs the expression reads) is compared both ways too.
Hand-written models omit it (FMI 2.0: then an initial unknown depends on all knowns).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from railfmu.models import all_models

H = 0.01  # s, communication step of the pre-steps
FACTORS = (0.37, -1.3)


def _ops_track(md):
    """distance_input: every output reads distance and speed; near the step (each wheelset in
    turn just short of it, within STEP_TOLERANCE |v| h) the speed moves the step's reach."""
    base = {"params": {"distance_input": True, "step_lateral": 1e-3, "step_vertical": 2e-3,
                       "step_position": 100.0}, "inputs": {"distance": 50.0, "speed": 20.0}, "steps": 1}
    ops = [base]
    for x in (0.0, 2.5, 19.0, 21.5):  # axle_position_1..4
        ops.append({**base, "inputs": {"distance": 100.0 + x - 1e-3, "speed": 20.0}})
    return ops


def _ops_train(md):
    """v > 0 (r1, r2 act), a command inside the clip; effort_set acts with use_effort_set."""
    start = {"s": 100.0, "v": 10.0}
    return [{"params": start, "inputs": {"command": 0.5}},
            {"params": start, "inputs": {"command": 0.5, "use_effort_set": True, "effort_set": 0.2}},
            {"params": start, "inputs": {"command": -0.5}}]


def _ops_driver(md):
    """Accelerating below a lower limit (the limit shapes the command); braking to the stop at
    the line's end (s moves the command); reaching the cruise target (the limit decides
    whether to hold) or cruising by cycles (the limit moves the target); standing still after braking (stop_time: v only, as STOPPED follows
    BRAKE_STOP alone). "end-x": x m before the line's end (stop_position); "cruise": the
    style's cruise target."""
    brake = {"s": "end-300", "v": 25.0, "speed_limit": 40.0}
    return [{"inputs": {"s": 10.0, "v": 5.0, "speed_limit": 10.0}},
            {"inputs": brake},
            {"inputs": {"s": 10.0, "v": 5.0}, "steps": 1,
             "after": {"s": 10.0, "v": "cruise", "speed_limit": "cruise"}},
            # cruising by cycles (if the style draws them): the limit moves the target
            {"inputs": {"s": 10.0, "v": "cruise", "speed_limit": "cruise"}, "steps": 2,
             "after": {"v": "cruise"}},
            # two steps: mode_before is BRAKE_STOP; then v just above 0 (-130 % of it: stopped)
            {"inputs": brake, "steps": 2, "after": {"s": "end-1", "v": 0.5}}]


def _ops_imu(md):
    """Misalignments couple the three axes of a triad."""
    mis = {v.name: 1000.0 for v in md.modelVariables
           if v.causality == "parameter" and "misalignment_" in v.name and "sigma" not in v.name}
    return [{"params": mis, "inputs": {v.name: 1e-3 * (k + 1) for k, v in enumerate(_inputs(md))},
             "steps": 1}]


def _ops_recording(md):
    """Disabled, each output is its exact_* input (the recording itself reads none)."""
    return [{"params": {"enabled": False}}]


SPECIAL = {"TrackIrregularity": _ops_track, "TrainLongitudinal": _ops_train, "Driver": _ops_driver,
           "ImuErrors": _ops_imu, "TrackRecording": _ops_recording}


def _inputs(md):
    return [v for v in md.modelVariables if v.causality == "input"]


def _outputs(md):
    return [v for v in md.modelVariables if v.causality == "output"]


def _default_ops(md):
    """States away from 0 (an input such as a stiffness multiplies them), inputs at distinct
    non-zero values."""
    states = [v for v in md.modelVariables if v.causality == "output" and v.initial == "exact"]
    params = {v.name: 0.01 * (1 + k / 7) for k, v in enumerate(states)}
    inputs = {v.name: (0.02 * (1 + k / 5) if v.type == "Real" else v.start)
              for k, v in enumerate(_inputs(md)) if v.type == "Real"}
    return [{"params": params, "inputs": inputs, "steps": 1}]


class Probe:
    def __init__(self, fmu: Path, tmp: Path):
        self.md = read_model_description(fmu)
        self.dir = extract(fmu, unzipdir=tmp / fmu.stem)
        self.vars = {v.name: v for v in self.md.modelVariables}

    def new(self):
        s = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                      modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="probe")
        s.instantiate()
        return s

    def set(self, s, values: dict):
        for name, x in values.items():
            v = self.vars[name]
            if v.type == "Real":
                s.setReal([v.valueReference], [float(x)])
            elif v.type == "Integer":
                s.setInteger([v.valueReference], [int(x)])
            elif v.type == "Boolean":
                s.setBoolean([v.valueReference], [bool(x)])

    def get(self, s) -> dict:
        out = {}
        for v in _outputs(self.md):
            fn = {"Real": s.getReal, "Integer": s.getInteger, "Boolean": s.getBoolean}[v.type]
            out[v.name] = fn([v.valueReference])[0]
        return out

    def perturbed(self, name: str, x):
        v = self.vars[name]
        if v.type == "Boolean":
            return [not x]
        if v.type == "Integer":
            return [x + 1, x - 1]
        scale = max(abs(x), 1.0)
        return [x + f * scale for f in FACTORS]


def _start(v):
    if v.type == "Boolean":
        return str(v.start).lower() in ("true", "1")
    return int(v.start or 0) if v.type == "Integer" else float(v.start or 0.0)


RTOL = 1e-9  # of the output's magnitude (module docstring)


def _changed(a: dict, b: dict) -> set[str]:
    def moved(x, y) -> bool:
        if isinstance(x, float):
            if x != x or y != y:  # NaN
                return (x != x) != (y != y)
            return abs(y - x) > RTOL * max(abs(x), abs(y))
        return x != y
    return {k for k in a if moved(a[k], b[k])}


def _resolve(values: dict, outputs: dict) -> dict:
    def one(x):
        if isinstance(x, str) and x.startswith("end-"):
            return outputs["stop_position"] - float(x[4:])
        return outputs["cruise_target"] if x == "cruise" else x
    return {k: one(x) for k, x in values.items()}


def measure(probe: Probe, op: dict, init_mode: bool = False) -> dict[str, set[str]]:
    """Output -> the inputs it changed with at this operating point."""
    md = probe.md
    ins = _inputs(md)
    found = {v.name: set() for v in _outputs(md)}
    s = probe.new()
    stepping = False
    try:
        s.setupExperiment(startTime=0.0)
        probe.set(s, op.get("params", {}))
        s.enterInitializationMode()
        values = {v.name: _start(v) for v in ins}
        if init_mode:
            probe.set(s, values)
            base = probe.get(s)
            for u in ins:
                for x in probe.perturbed(u.name, values[u.name]):
                    probe.set(s, {u.name: x})
                    for o in _changed(base, probe.get(s)):
                        found[o].add(u.name)
                    probe.set(s, {u.name: values[u.name]})
            return found
        s.exitInitializationMode()
        stepping = True
        stop = probe.get(s)
        values.update(_resolve(op.get("inputs", {}), stop))
        probe.set(s, values)
        t = 0.0
        for _ in range(op.get("steps", 0)):
            s.doStep(currentCommunicationPoint=t, communicationStepSize=H)
            t += H
        values.update(_resolve(op.get("after", {}), stop))
        probe.set(s, values)  # after the steps: tau = 0, the hold restarts here
        state = s.getFMUstate()
        base = probe.get(s)
        for u in ins:
            for x in probe.perturbed(u.name, values[u.name]):
                s.setFMUstate(state)
                probe.set(s, {u.name: x})
                for o in _changed(base, probe.get(s)):
                    found[o].add(u.name)
        s.freeFMUstate(state)
        return found
    finally:
        if stepping:
            s.terminate()
        s.freeInstance()


def declared(md) -> dict[str, set[str]]:
    return {u.variable.name: ({d.name for d in u.dependencies} if u.dependencies is not None
                              else {v.name for v in _inputs(md)}) for u in md.outputs}


MODELS = [m.identifier for m in all_models()]


@pytest.mark.parametrize("identifier", MODELS)
def test_outputs_declare_their_true_feedthrough(fmu_dir, tmp_path, identifier):
    probe = Probe(Path(fmu_dir) / f"{identifier}.fmu", tmp_path)
    ops = SPECIAL.get(identifier, _default_ops)(probe.md)
    seen = {o.name: set() for o in _outputs(probe.md)}
    for op in ops:
        for o, ins in measure(probe, op).items():
            seen[o] |= ins
    decl = declared(probe.md)
    assert set(decl) == set(seen), "every output is in ModelStructure/Outputs"
    missing = {o: sorted(seen[o] - decl[o]) for o in seen if seen[o] - decl[o]}
    extra = {o: sorted(decl[o] - seen[o]) for o in seen if decl[o] - seen[o]}
    assert not missing, f"{identifier}: undeclared direct feedthrough {missing}"
    assert not extra, f"{identifier}: declared dependencies the FMU does not have {extra}"


@pytest.mark.parametrize("identifier", MODELS)
def test_initialization_mode_has_no_undeclared_feedthrough(fmu_dir, tmp_path, identifier):
    probe = Probe(Path(fmu_dir) / f"{identifier}.fmu", tmp_path)
    params = SPECIAL.get(identifier, _default_ops)(probe.md)[0].get("params", {})
    seen = measure(probe, {"params": params}, init_mode=True)
    decl = declared(probe.md)
    missing = {o: sorted(seen[o] - decl[o]) for o in seen if seen[o] - decl[o]}
    assert not missing, f"{identifier}: undeclared feedthrough in initialisation mode {missing}"


# -- InitialUnknowns (generated models; hand-written ones omit the list: "all knowns") ------

GENERATED = [m.identifier for m in all_models() if m.generated]
INIT_START_TIMES = (0.0, 2.0)  # s: before and after StepSource's default step at 1 s


def _knowns(md):
    """What initialisation knows (FMI 2.0): time, parameters, the start values of the states
    (outputs with initial="exact") and the inputs."""
    params = [v for v in md.modelVariables if v.causality == "parameter" and v.type != "String"]
    states = [v for v in md.modelVariables if v.causality == "output" and v.initial == "exact"]
    return params + states + _inputs(md)


def _initial_outputs(probe: Probe, start_time: float, values: dict) -> dict | None:
    """The calculated outputs in initialisation mode with ``values`` set (None: refused, e.g.
    a parameter out of its range)."""
    from fmpy.fmi1 import FMICallException

    md = probe.md
    before = {k: x for k, x in values.items() if probe.vars[k].causality != "input"}
    inputs = {k: x for k, x in values.items() if probe.vars[k].causality == "input"}
    names = {u.variable.name for u in md.initialUnknowns}
    s = probe.new()
    try:
        s.setupExperiment(startTime=start_time)
        probe.set(s, before)
        s.enterInitializationMode()
        probe.set(s, inputs)
        return {k: x for k, x in probe.get(s).items() if k in names}
    except FMICallException:
        return None
    finally:
        s.freeInstance()


# values on top of the default operating point that reach a switch: the flange contact
# (|y_w - xi| beyond the flangeway clearance, with the contact on)
INIT_EXTRA = {"VehicleLateral": [{"flange_contact": 1, **{f"y_w{j}": 0.2 for j in range(1, 5)}}]}


@pytest.mark.parametrize("identifier", GENERATED)
def test_initial_unknowns_declare_what_initialisation_reads(fmu_dir, tmp_path, identifier):
    probe = Probe(Path(fmu_dir) / f"{identifier}.fmu", tmp_path)
    md = probe.md
    op = _default_ops(md)[0]
    default = {v.name: _start(v) for v in _knowns(md)}
    default.update(op["params"])
    default.update(op["inputs"])
    seen = {u.variable.name: set() for u in md.initialUnknowns}
    for extra in [{}, *INIT_EXTRA.get(identifier, [])]:
        values = {**default, **extra}
        for t0 in INIT_START_TIMES:
            base = _initial_outputs(probe, t0, values)
            assert base is not None
            trials = [(t0 + f * max(abs(t0), 1.0), {}) for f in FACTORS]  # the start time
            trials += [(t0, {k: x}) for k, x0 in values.items() for x in probe.perturbed(k, x0)]
            for t, change in trials:
                out = _initial_outputs(probe, t, {**values, **change})
                for o in _changed(base, out) if out is not None else ():
                    seen[o].add(next(iter(change), "time"))
    decl = {u.variable.name: {d.name for d in u.dependencies} for u in md.initialUnknowns}
    assert all(u.dependencies is not None for u in md.initialUnknowns), "generated: declared"
    missing = {o: sorted(seen[o] - decl[o]) for o in seen if seen[o] - decl[o]}
    extra = {o: sorted(decl[o] - seen[o]) for o in seen if decl[o] - seen[o]}
    assert not missing, f"{identifier}: undeclared initial dependencies {missing}"
    assert not extra, f"{identifier}: declared initial dependencies initialisation does not read {extra}"
