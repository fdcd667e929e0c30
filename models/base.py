"""One definition per model: its variables (with units, descriptions, sources) and equations.

A :class:`Model` is the single source for

* its FMU: ``railfmu.fmus.generate.codegen`` turns the variables into ``modelDescription.xml`` and the
  equations into C (sympy ``ccode``);
* Python: :meth:`Model.rhs` and :meth:`Model.outputs` lambdify the same expressions, so a
  test can solve the definition with scipy and compare it with the compiled FMU, and an
  estimator can take its design matrices from :meth:`Model.linearize`.

Models whose code cannot be written as closed-form expressions (the track generator) set
``c_sources`` to hand-written C; their variables are still declared here, and a test proves
the C equals the Python implementation.

Types (FMI 2.0): Real everywhere; Integer and Boolean parameters, inputs and outputs
(discrete: they change only at communication points); String parameters (a file name, a
column name), which no expression may use. In expressions an Integer or Boolean is a number
(true = 1); an Integer output is its expression rounded to the nearest integer (C ``lround``),
a Boolean output is true where its expression is non-zero (a relation such as ``v < 0.01``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import sympy as sp

from railfmu.models.cache import cache_root, write_atomic
from railfmu.models.design import check_parameters

#: The communication step ``h`` (s) of the step that ended at the current time ``t`` (0 in
#: initialisation mode), for output expressions that switch at given times; C: the runtime's
#: ``m->stepSize``.
STEP_SIZE = sp.Symbol("h", real=True)
#: A boundary (a sample or switching instant) that lies less than this fraction of ``h``
#: after a communication point counts as reached there: masters compute their time as
#: ``n h`` or accumulate ``t += h``, apart by a fraction of ``h`` that grows as ``n^2`` and
#: stays below this over millions of steps. The runtime's ``STEP_TOLERANCE`` (model.h), the
#: same value.
STEP_TOLERANCE = 1e-2


TYPES = frozenset({"Real", "Integer", "Boolean", "String"})


def _as_type(type_: str, v) -> float | int | bool:
    """A value computed as a number, as the FMU delivers it (see the module docstring)."""
    if type_ == "Integer":
        v = float(v)
        return int(np.copysign(np.floor(abs(v) + 0.5), v))  # C lround: halves away from 0
    if type_ == "Boolean":
        return bool(v != 0)
    return float(v)


@dataclass
class Variable:
    """An FMU variable. ``unit`` is an FMI unit name ('' = dimensionless); ``source`` says where
    a parameter's value comes from (a reference study's table, benchmark vehicle, standard)."""

    name: str
    description: str
    unit: str = ""  # Real only: FMI 2.0 gives Integer, Boolean and String no unit
    start: float | int | bool | str | None = 0.0
    type: str = "Real"  # Real | Integer | Boolean | String
    source: str = ""
    min: float | None = None
    max: float | None = None
    positive: bool = False  # must be > 0 (a mass, a stiffness): checked when initialisation ends

    @property
    def symbol(self) -> sp.Symbol:
        return sp.Symbol(self.name, real=True)


@dataclass
class Parameter(Variable):
    """A parameter the importer may set before initialisation (``tunable``: also during the run).
    ``min``/``max`` are checked when initialisation ends: a violation is an fmi2Error with a
    logged message naming the parameter."""

    tunable: bool = False


@dataclass
class Input(Variable):
    """A continuous input. With ``rate`` naming another input that carries its time
    derivative, the FMU extrapolates the input linearly over a communication step
    (first-order hold) instead of holding it."""

    rate: str | None = None


@dataclass
class State(Variable):
    """A continuous state; also an output (initial='exact'), so its start value is the initial
    condition the importer may set. ``der`` is the time derivative as a sympy expression."""

    der: sp.Expr | None = None


@dataclass
class Output(Variable):
    """An output computed from states, inputs and parameters (``expr``), or by hand-written C.
    ``depends_on``: the inputs the value read right after they are set depends on (direct
    feedthrough, FMI 2 ModelStructure). Derived from ``expr`` (its free symbols) for generated
    models; hand-written models with inputs must state it for every output (() = none)."""

    expr: sp.Expr | None = None
    start: float | int | bool | str | None = None
    depends_on: Sequence[str] | None = None


@dataclass
class Model:
    identifier: str  # FMI modelIdentifier: a C identifier, also the .fmu file name
    description: str
    parameters: list[Parameter] = field(default_factory=list)
    inputs: list[Input] = field(default_factory=list)
    states: list[State] = field(default_factory=list)
    outputs: list[Output] = field(default_factory=list)
    integrator_step: float = 1e-4  # s, default of the internal RK4 step parameter
    # (start s, stop s, communication step s) for importers' defaults: the run of Muñoz et al.,
    # 20 s (400 m at 20 m/s) at 1 kHz
    default_experiment: tuple[float, float, float] = (0.0, 20.0, 1e-3)
    # the simulation ends at the first communication point where this holds (a sympy relation
    # of t, states, inputs, parameters): fmi2DoStep returns fmi2Discard, fmi2Terminated is true
    terminate_when: sp.Expr | None = None
    c_sources: list[Path] = field(default_factory=list)  # hand-written C, if not generated
    c_constants: dict[str, int] = field(default_factory=dict)  # #defines in model_config.h
    resources: dict[str, Path] = field(default_factory=dict)  # name in resources/ -> file
    documentation: str = ""  # the model's equations, for the FMU's documentation/

    # -- structure ---------------------------------------------------------------------------
    def __post_init__(self) -> None:
        names = [v.name for v in self.variables]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"model {self.identifier}: duplicate variable names {sorted(dup)}")
        known = {v.name for v in self.inputs}
        for u in self.inputs:
            if u.rate is not None and u.rate not in known:
                raise ValueError(f"model {self.identifier}: input {u.name} has unknown rate {u.rate}")
            if u.rate is not None and (u.type, self.variable(u.rate).type) != ("Real", "Real"):
                raise ValueError(f"model {self.identifier}: input {u.name}: a rate needs two Real inputs")
        self._check_types()
        self._check_dependencies()

    def _check_dependencies(self) -> None:
        """Every output's direct feedthrough is known (declared or derivable) and names inputs."""
        inputs = {u.name for u in self.inputs}
        for o in self.outputs:
            where = f"model {self.identifier}: output {o.name}"
            if o.depends_on is None:
                if o.expr is None and inputs:
                    raise ValueError(f"{where}: hand-written with inputs: declare depends_on")
                continue
            unknown = set(o.depends_on) - inputs
            if unknown:
                raise ValueError(f"{where}: depends_on names no input: {sorted(unknown)}")
            if o.expr is not None and set(o.depends_on) != set(self.feedthrough(o)):
                raise ValueError(f"{where}: depends_on {sorted(o.depends_on)} differs from its "
                                 f"expression's inputs {sorted(self.feedthrough(o))}")

    def feedthrough(self, o: "Output") -> list[str]:
        """The inputs output ``o`` depends on directly, in input order. From the expression's
        free symbols: right after inputs are set the first-order hold has not started (tau = 0),
        so a rate input counts only where the expression itself uses it."""
        if o.depends_on is not None and o.expr is None:
            return [u.name for u in self.inputs if u.name in set(o.depends_on)]
        if o.expr is None:
            return []
        free = self.reads(o.expr)
        return [u.name for u in self.inputs if u.name in free]

    def reads(self, expr: sp.Expr) -> set[str]:
        """Names of the symbols ``expr``'s value depends on: those in a condition (a switch) and
        those with a derivative not identically 0 (a free symbol may cancel, as x - x)."""
        cache = self.__dict__.setdefault("_reads", {})  # the build asks twice (GUID, description)
        e = sp.sympify(expr)
        if e not in cache:
            switches = set().union(*[r.free_symbols for r in e.atoms(sp.core.relational.Relational)])
            cache[e] = {s.name for s in e.free_symbols if s in switches or sp.diff(e, s) != 0}
        return cache[e]

    def _check_types(self) -> None:
        """What FMI 2.0 and the generator allow: see the module docstring."""
        allowed = {Parameter: TYPES, Input: TYPES - {"String"}, State: {"Real"},
                   Output: TYPES - {"String"}}
        for v in self.variables:
            where = f"model {self.identifier}: {type(v).__name__.lower()} {v.name}"
            if v.type not in allowed[type(v)]:
                raise ValueError(f"{where}: type {v.type} is not allowed (allowed: {sorted(allowed[type(v)])})")
            if v.type != "Real" and v.unit:
                raise ValueError(f"{where}: an {v.type} has no unit in FMI 2.0 (say it in the description)")
        strings = {p.symbol for p in self.parameters if p.type == "String"}
        exprs = [s.der for s in self.states] + [o.expr for o in self.outputs] + [self.terminate_when]
        for e in exprs:
            used = strings & set(sp.sympify(e).free_symbols) if e is not None else set()
            if used:
                raise ValueError(f"model {self.identifier}: String parameter {sorted(map(str, used))[0]} "
                                 "used in an expression")

    @property
    def variables(self) -> list[Variable]:
        return [*self.parameters, *self.inputs, *self.states, *self.outputs]

    @property
    def generated(self) -> bool:
        """True when the model's C code is generated from its expressions."""
        return not self.c_sources

    def variable(self, name: str) -> Variable:
        for v in self.variables:
            if v.name == name:
                return v
        raise KeyError(f"model {self.identifier} has no variable {name!r}")

    def default_parameters(self) -> dict[str, float]:
        return {p.name: p.start for p in self.parameters}

    def check_parameters(self, params: Mapping[str, float]) -> None:
        """The same range checks the FMU applies when initialisation ends."""
        check_parameters(self.identifier, self.parameters, params)

    # -- numerics (generated models) -------------------------------------------------------
    def _substitute_held_inputs(self, expr: sp.Expr, tau: sp.Symbol) -> sp.Expr:
        """u -> u + u_rate * tau for inputs with a rate (first-order hold over a step)."""
        subs = {u.symbol: u.symbol + self.variable(u.rate).symbol * tau for u in self.inputs if u.rate}
        return expr.subs(subs)

    def derivative_exprs(self, hold_tau: sp.Symbol | None = None) -> list[sp.Expr]:
        exprs = [s.der for s in self.states]
        if hold_tau is not None:
            exprs = [self._substitute_held_inputs(e, hold_tau) for e in exprs]
        return exprs

    def _args(self) -> list[sp.Symbol]:
        return [sp.Symbol("t", real=True), STEP_SIZE, *[s.symbol for s in self.states],
                *[u.symbol for u in self.inputs], *[p.symbol for p in self.parameters]]

    def _lambdify(self, key: str, exprs: Sequence[sp.Expr]) -> Callable:
        cache = self.__dict__.setdefault("_compiled", {})
        if key not in cache:  # lambdify is slow; the expressions never change
            cache[key] = sp.lambdify(self._args(), list(exprs), modules="numpy", cse=True)
        return cache[key]

    def _call(self, fn: Callable, t: float, x, u: Mapping[str, float] | None, p: Mapping[str, float] | None,
              h: float = 0.0):
        p = {**self.default_parameters(), **(p or {})}
        u = {**{v.name: v.start for v in self.inputs}, **(u or {})}
        return fn(t, h, *x, *[u[v.name] for v in self.inputs], *[p[v.name] for v in self.parameters])

    def rhs(self, p: Mapping[str, float] | None = None, u: Callable[[float], Mapping[str, float]] | None = None):
        """Return f(t, x) for scipy.integrate.solve_ivp; ``u(t)`` gives the inputs by name."""
        fn = self._lambdify("rhs", self.derivative_exprs())

        def f(t, x):
            return np.asarray(self._call(fn, t, x, u(t) if u else None, p), dtype=float)

        return f

    def outputs_at(self, t: float, x, u: Mapping[str, float] | None = None,
                   p: Mapping[str, float] | None = None, h: float = 0.0) -> dict[str, float]:
        """All outputs (states included) at one instant, reached by a communication step
        ``h`` (s; 0: initialisation mode), which only expressions with :data:`STEP_SIZE` use."""
        fn = self._lambdify("outputs", [o.expr for o in self.outputs])
        vals = self._call(fn, t, x, u, p, h)
        out = {s.name: float(xi) for s, xi in zip(self.states, x)}
        out.update({o.name: _as_type(o.type, v) for o, v in zip(self.outputs, vals)})
        return out

    def terminates(self, t: float, x, u: Mapping[str, float] | None = None,
                   p: Mapping[str, float] | None = None) -> bool:
        """Whether ``terminate_when`` holds at one instant (False without one)."""
        if self.terminate_when is None:
            return False
        fn = self._lambdify("terminate", [self.terminate_when])
        return bool(self._call(fn, t, x, u, p)[0])

    def linearize(self, p: Mapping[str, float] | None = None, u0: Mapping[str, float] | None = None):
        """(A, B, C, D) of dx = A x + B du, y = C x + D du about x = 0 and the inputs at their
        start values (overridden by ``u0``; an input such as a stiffness is an operating
        point, not a small signal), with the given parameters; B and D columns follow
        ``self.inputs``, C and D rows ``self.outputs``."""
        pv = {**self.default_parameters(), **(p or {})}
        uv = {**{v.name: v.start for v in self.inputs}, **(u0 or {})}
        # an estimator built per run (a Monte Carlo member) gets the same matrices without the cost of
        # substitution; evaluated by sympy as before, so the numbers are bit for bit the same
        key = (tuple(sorted(pv.items())), tuple(sorted(uv.items())))
        memo = self.__dict__.setdefault("_compiled", {}).setdefault("linearized", {})
        if key not in memo:
            memo[key] = self._linearized_on_disk(key)
        return tuple(m.copy() for m in memo[key])

    def _jacobians(self):
        cache = self.__dict__.setdefault("_compiled", {})
        if "jacobians" not in cache:  # derived once per process
            x = [s.symbol for s in self.states]
            u = [v.symbol for v in self.inputs]
            f = sp.Matrix(self.derivative_exprs())
            g = sp.Matrix([o.expr for o in self.outputs])
            cache["jacobians"] = (f.jacobian(x), f.jacobian(u), g.jacobian(x), g.jacobian(u))
        return cache["jacobians"]

    def _substituted(self, jacobians, pv, uv):
        subs = {q.symbol: pv[q.name] for q in self.parameters if q.type != "String"}
        zero = {**{s.symbol: 0 for s in self.states}, **{v.symbol: uv[v.name] for v in self.inputs}}
        return tuple(np.array(m.subs(subs).subs(zero), dtype=float) for m in jacobians)

    def _linearized_on_disk(self, key) -> tuple:
        """(A, B, C, D) for ``key`` from the per-user cache, else substituted and stored; a new process (each
        ``railfmu run``) then skips the Jacobians' derivation and substitution (~0.5 s for the
        wheelset). Keyed by the equations' text and the values, so a changed model or
        parameter is a new entry; the arrays are saved as float64, bit for bit."""
        import hashlib

        text = repr((self.identifier, [str(e) for e in self.derivative_exprs()], [str(o.expr) for o in self.outputs],
                     [s.name for s in self.states], [v.name for v in self.inputs], key))
        path = cache_root() / "linearized" / f"{hashlib.sha256(text.encode()).hexdigest()[:32]}.npz"
        try:
            with np.load(path) as z:
                return tuple(z[n] for n in "ABCD")
        except (OSError, KeyError, ValueError):
            pass
        mats = self._substituted(self._jacobians(), dict(key[0]), dict(key[1]))
        write_atomic(path, lambda f: np.savez(f, **dict(zip("ABCD", mats))))  # a read-only cache: derived every time
        return mats
