"""A seeded fuzz of the FMI 2 call sequence (fmus/native/runtime/fmi2_runtime.c) on every FMU:
calls in random order and state (setup, initialisation, steps, reset, terminate, FMU states),
set/get of every variable type with NaN, infinities, huge and tiny numbers, integers at the
ends of a C int, booleans other than 0/1, long, missing and hostile file names, value
references out of range, zero, negative, non-finite and huge step sizes, steps at the wrong
time. The contract: no crash, never fmi2Fatal, every fmi2Error logged with a reason, and the
instance still usable afterwards (a reset and a fresh initialisation step).

RAILFMU_FUZZ_SEED, RAILFMU_FUZZ_CASES (sequences per FMU: CASES // 4, 40 calls each); `make
sanitize` runs it against FMUs built with ASan + UBSan, where any out-of-bounds access or
undefined behaviour aborts the run.
"""

from __future__ import annotations

import math
import os
import random
from pathlib import Path

import pytest
from fmpy.fmi1 import FMICallException

from railfmu.fmus.cosim.slave import FMUError, Slave, Status
from railfmu.models import all_models

MODELS = [m.identifier for m in all_models()]
SEED = int(os.environ.get("RAILFMU_FUZZ_SEED", "0"))
CASES = int(os.environ.get("RAILFMU_FUZZ_CASES", "60"))
CALLS = 40
HOSTILE = Path(__file__).parent / "data" / "hostile"
INT_MAX, INT_MIN = 2**31 - 1, -(2**31)
REALS = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1e308, -1e308, 5e-324, 1e-300, -1.0, 1.0, 1e6]
INTEGERS = [0, 1, -1, 2, 7, INT_MAX, INT_MIN]
BOOLEANS = [0, 1, 2, -1]
STRINGS = ["", "x" * 100_000, "/no/such/file.csv", "relative.csv", "é", str(HOSTILE),
           *(str(p) for p in sorted(HOSTILE.glob("*/bad_*.csv"))[:12]),
           *(str(p) for p in sorted(HOSTILE.glob("*/clean.csv")))]
# steps: none so long that a valid one would run for minutes (1e9 internal steps are refused)
STEPS = [0.0, -0.0, -1e-3, math.nan, math.inf, -math.inf, 1e300, 5e-324, 1e-3, 0.01, 0.1]
BAD_VRS = [10**6, 2**32 - 1]


class Sequence:
    def __init__(self, s: Slave, rng: random.Random):
        self.s, self.f, self.rng = s, s.fmu, rng
        self.vars = {t: [v for v in s.md.modelVariables if v.type == t] for t in ("Real", "Integer", "Boolean",
                                                                                  "String")}
        self.t = 0.0
        self.states = []
        self.blobs = []

    def vrs(self, kind):
        vs = self.vars[kind]
        chosen = [v.valueReference for v in self.rng.sample(vs, min(len(vs), self.rng.randint(1, 3)))]
        if self.rng.random() < 0.1:
            chosen.append(self.rng.choice(BAD_VRS))
        return chosen

    def value(self, kind, v=None):
        r = self.rng
        if kind == "Real":
            return r.choice(REALS + ([float(v.start)] if v is not None and v.start is not None else []))
        if kind == "Integer":
            return r.choice(INTEGERS)
        if kind == "Boolean":
            return r.choice(BOOLEANS)
        return r.choice(STRINGS)

    def one(self):
        r, f = self.rng, self.f
        op = r.choice(["setup", "enter", "exit", "step", "step", "step", "set", "set", "set", "get", "get",
                       "state", "serialize", "reset", "terminate", "derivatives", "status"])
        if op == "setup":
            f.setupExperiment(tolerance=r.choice([None, 1e-6, -1.0, math.nan]), startTime=r.choice([0.0, -1.0, 1e300]),
                              stopTime=r.choice([None, 1.0, 0.0, -1.0, math.inf, math.nan]))
        elif op == "enter":
            f.enterInitializationMode()
        elif op == "exit":
            f.exitInitializationMode()
        elif op == "step":
            h = r.choice(STEPS)
            t = self.t if r.random() < 0.8 else r.choice([self.t + 1.0, -1.0, math.nan])
            f.doStep(t, h)
            self.t = t + h
        elif op in ("set", "get"):
            kind = r.choice([k for k, vs in self.vars.items() if vs])
            vrs = self.vrs(kind)
            if op == "get":
                getattr(f, f"get{kind}")(vrs)
            else:
                by_vr = {v.valueReference: v for v in self.vars[kind]}
                getattr(f, f"set{kind}")(vrs, [self.value(kind, by_vr.get(vr)) for vr in vrs])
        elif op == "state":
            action = r.choice(["get", "set", "free"]) if self.states else "get"
            if action == "get":
                self.states.append(f.getFMUstate())
            elif action == "set":
                f.setFMUstate(r.choice(self.states))
            else:
                f.freeFMUstate(self.states.pop(r.randrange(len(self.states))))
        elif op == "serialize":
            if self.states and r.random() < 0.5:
                self.blobs.append(bytes(f.serializeFMUstate(r.choice(self.states))))
            elif self.blobs:
                blob = bytearray(r.choice(self.blobs))
                if r.random() < 0.5 and blob:
                    blob[r.randrange(len(blob))] ^= 1 << r.randrange(8)
                self.states.append(f.deSerializeFMUstate(bytes(blob)))
        elif op == "reset":
            f.reset()
            self.t = 0.0
        elif op == "terminate":
            f.terminate()
        elif op == "derivatives":
            reals = self.vars["Real"]
            vr = [r.choice(reals).valueReference, *([r.choice(BAD_VRS)] if r.random() < 0.2 else [])]
            order = [r.choice([1, 0, -1, 2, INT_MAX])] * len(vr)
            if r.random() < 0.5:
                f.getRealOutputDerivatives(vr, order)
            else:
                f.setRealInputDerivatives(vr, order, [r.choice(REALS)] * len(vr))
        else:
            getattr(f, r.choice(["getRealStatus", "getIntegerStatus", "getBooleanStatus", "getStringStatus",
                                 "getStatus"]))(r.choice([0, 1, 2, 3, 4, -1, 99]))


@pytest.mark.parametrize("ident", MODELS)
def test_random_call_sequences_never_crash_and_every_error_has_a_reason(fmu_dir, ident):
    sequences = max(1, CASES // 4)
    statuses = {}
    for case in range(sequences):
        rng = random.Random(f"{SEED} {ident} {case}")
        with Slave(fmu_dir / f"{ident}.fmu", ident, logging_on=rng.random() < 0.5) as s:
            seq = Sequence(s, rng)
            for _ in range(CALLS):
                n = len(s.messages)
                try:
                    seq.one()
                    status = "OK or Warning"
                except FMICallException as exc:
                    status = Status.name_of(exc.status)
                    assert exc.status != Status.FATAL, s.messages[n:]
                    if exc.status == Status.ERROR:
                        assert any(st == "Error" for st, _, _ in s.messages[n:]), \
                            f"{exc}: fmi2Error without a logged reason"
                except (ValueError, OverflowError, TypeError):
                    status = "refused by fmpy"  # e.g. fmpy's own conversion of an argument
                statuses[status] = statuses.get(status, 0) + 1
            # whatever happened, the instance can start over
            for st in seq.states:
                s.fmu.freeFMUstate(st)
            s.fmu.reset()
            n = len(s.messages)
            s.fmu.setupExperiment(startTime=0.0)
            s.fmu.enterInitializationMode()
            s.fmu.exitInitializationMode()
            s.fmu.doStep(0.0, 1e-3)
            assert not [m for st, _, m in s.messages[n:] if st in ("Error", "Fatal")]
    assert statuses.get("fmi2Error", 0) > 0 and statuses.get("OK or Warning", 0) > 0, statuses


def test_a_trolley_step_too_long_to_integrate_is_refused(fmu_dir):
    """Found by this fuzz under UBSan: a 1e300 s step overflowed the Trolley's panel count (a
    double cast to an integer); it is now an error naming the limit, not garbage increments."""
    with Slave(fmu_dir / "Trolley.fmu", "trolley") as s:
        s.initialize(0.0)
        with pytest.raises(FMICallException):
            s.fmu.doStep(0.0, 1e300)
        assert any("longer than 1e+07 s" in m for st, _, m in s.messages if st == "Error"), s.messages


SWEEP = {"Real": [math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, -1.0], "Integer": [INT_MAX, INT_MIN, -1],
         "Boolean": [2, -1], "String": ["", "x" * 100_000, "/no/such/file.csv", str(HOSTILE / "signal" / "bad_nul_byte.csv")]}


@pytest.mark.parametrize("ident", MODELS)
def test_every_parameter_and_input_with_every_hostile_value(fmu_dir, ident):
    """Each settable variable in turn, with each value of SWEEP for its type, set before the
    end of initialisation: the set, the end of initialisation and a first step each succeed or
    fail with a logged reason (a refused parameter names itself), and every variable can then
    be read; a reset then starts over cleanly."""
    with Slave(fmu_dir / f"{ident}.fmu", ident) as s:
        f = s.fmu
        by_type = {t: [v.valueReference for v in s.md.modelVariables if v.type == t] for t in SWEEP}
        settable = [v for v in s.md.modelVariables if v.causality in ("parameter", "input")]
        for v in settable:
            for value in SWEEP[v.type]:
                f.reset()
                n = len(s.messages)
                f.setupExperiment(startTime=0.0)
                f.enterInitializationMode()
                try:
                    getattr(f, f"set{v.type}")([v.valueReference], [value])
                    f.exitInitializationMode()
                    f.doStep(0.0, 1e-3)
                except FMICallException as exc:
                    assert exc.status == Status.ERROR, (v.name, value, s.messages[n:])
                    errors = [m for st, _, m in s.messages[n:] if st == "Error"]
                    assert errors, f"{v.name} = {value!r}: {exc} without a logged reason"
                for t, vrs in by_type.items():
                    if vrs:
                        try:
                            getattr(f, f"get{t}")(vrs)
                        except FMICallException:
                            assert [m for st, _, m in s.messages[n:] if st == "Error"]
        f.reset()
        n = len(s.messages)
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        f.exitInitializationMode()
        f.doStep(0.0, 1e-3)
        assert not [m for st, _, m in s.messages[n:] if st in ("Error", "Fatal")]


def test_a_trolley_stop_spacing_too_small_to_end_is_refused(fmu_dir):
    """Found by the sweep above: stop_spacing = 5e-324 m never advanced the speed profile (s + D
    == s), and initialisation never returned."""
    from railfmu.models.errors import UserError
    from railfmu.models.inertial.trolley import SpeedProfile

    with Slave(fmu_dir / "Trolley.fmu", "trolley") as s:
        with pytest.raises(FMUError, match="stop_spacing = 4.94066e-324 m gives more than 1e.06 stops"):
            s.initialize(0.0, None, {"stop_spacing": 5e-324})
    with pytest.raises(UserError, match="stop_spacing = 4.94066e-324 m gives more than 1e"):
        SpeedProfile(600.0, 1.0, 0.5, 5e-324, 1.0, 1.0)
