r"""``ukf_fmu``: the running-resistance UKF of Cunillera et al. (2022) with a vehicle FMU as its
process model.

:class:`FmuPaperUKF` is :class:`railfmu.estimators.train.running_resistance.PaperUKF` (state
``(s, v, r0, r1, r2)``, effort from the measured acceleration, Merwe points α = 1e-3, κ = −2,
Table 1, Q = 0) whose prediction ``Y_i = f(X_i, u, t, dt)`` is one step of the
``TrainLongitudinal`` FMU per sigma point (:class:`railfmu.fmus.cosim.process_model.FmuProcessModel`:
FMU state saved at ``t``, restored for each point)::

    s_set, v_set, r0, r1, r2 := X_i       set_state = true: the step starts from (s_set, v_set)
    effort_set := u                       use_effort_set = true: f_t - f_b = u over the step
    fmi2DoStep(t, dt)                     eq. 1 by the FMU's RK4 (sub-steps of integrator_step)
    Y_i = (s, v, r0, r1, r2)              the Davis coefficients are constant (Q = 0)

It is what lets a user estimate with their own vehicle FMU: any FMU with these inputs and
outputs can be named. ``estimators/`` does not import ``fmus/``: the experiment layer builds
the process model and hands it in.

In an SSD (``org.railfmu.observers``) the observer names the system component whose FMU and
parameters (its line profile, masses, integrator step) the process model uses::

    <rf:Observer name="ukf_fmu" class="resistance_ukf_fmu"
                 sampling="event" samplePeriod="10">
      <rf:Measurement name="position" connector="gnss.position" valid="gnss.valid"/>
      <rf:Measurement name="speed" connector="gnss.speed" valid="gnss.valid"/>
      <rf:Setting name="process_component" value="train"/>
    </rf:Observer>

The observer's ``line_file`` and ``rotating_mass_factor`` (its line term ``g(s)`` for the
effort) default to the component's, so filter and FMU use the same line.

The paper's effort (setting ``effort="paper"``, the default) inverts eq. 1 with eq. 4's
constant acceleration: ``u = a_obs + r(v^) + g(s^)``. Under the FMU's eq. 1 the held ``u``
does not reproduce the measured speed change (``r(v)`` grows while the train accelerates),
and with Q = 0 the filter, sure of its state, does not correct it: on the driven 32 km run
(seed 1) speed rms 0.81 km/h and position rms 79 m, against 0.28 km/h and 4.7 m with eq. 4.
``effort="process"`` takes instead the effort whose prediction of the centre sigma point by
the FMU reproduces the measured speed change (one secant step from the paper's effort: two
more FMU steps per fix): 0.28 km/h and 4.9 m, as eq. 4.
"""

from __future__ import annotations

from typing import Any, ClassVar

from railfmu.estimators.train.running_resistance import PaperUKF
from railfmu.fmus.cosim.process_model import FmuProcessModel
from railfmu.fmus.cosim.system import Component
from railfmu.models.errors import UserError

#: TrainLongitudinal's process-model variables for the rows (s, v, r0, r1, r2) of PaperUKF:
#: (input, output); output None: held over the step
TRAIN_COLUMNS = (("s_set", "s"), ("v_set", "v"), ("r0", None), ("r1", None), ("r2", None))


class FmuPaperUKF(PaperUKF):
    """:class:`PaperUKF` with ``process`` an :class:`FmuProcessModel` of the component named by
    the setting ``process_component`` (module docstring). Diagnostics beside PaperUKF's: the
    process model's ``process_steps``, ``process_sigma_points``, ``process_seconds`` and
    ``process_us_per_call`` (µs per process call: one filter prediction, all sigma points)."""

    process_columns: ClassVar[tuple[tuple[str, str | None], ...]] = TRAIN_COLUMNS
    process_known: ClassVar[tuple[str, ...]] = ("effort_set",)
    process_fixed: ClassVar[dict[str, bool]] = {"set_state": True, "use_effort_set": True}

    def __init__(self, dt: float, process: FmuProcessModel | None = None, effort: str = "paper",
                 **settings: Any) -> None:
        if not isinstance(process, FmuProcessModel):
            raise ValueError("needs the setting process_component naming the system component whose FMU is "
                             "its process model")
        if effort not in ("paper", "process"):
            raise ValueError(f"effort must be 'paper' or 'process', not {effort!r}")
        self.effort_rule = effort
        if "line_file" not in settings:
            settings["line_file"] = str(process.resource(str(process.value("line_file"))))
        settings.setdefault("rotating_mass_factor", float(process.value("rotating_mass_factor")))
        super().__init__(dt, process=process, **settings)

    def _effort(self, v_meas: float, t: float) -> float:
        """The paper's effort, or (``effort="process"``) the one whose FMU prediction of the
        centre point ends at the measured speed change (module docstring)."""
        u0 = super()._effort(v_meas, t)
        if self.effort_rule == "paper" or self._v_meas is None or t <= self._t_meas or not self._pending:
            return u0
        x = (self.x * self.D)[None, :]
        target = x[0, 1] + (v_meas - self._v_meas)

        def miss(u: float) -> float:
            X = x
            for j in range(self._pending):
                X = self.process(X, u, self._t_post + j * self.dt, self.dt)
            return float(X[0, 1]) - target

        u1 = u0 + 1e-3  # N/kg; v(t + dt) is affine in u while the train moves (slope dt)
        m0, m1 = miss(u0), miss(u1)
        return u0 if m1 == m0 else u1 - m1 * (u1 - u0) / (m1 - m0)  # at rest the held train: u0

    def finish(self) -> dict:
        p = self.process
        return {**super().finish(), "process_steps": p.steps, "process_sigma_points": p.points,
                "process_seconds": p.seconds,
                "process_us_per_call": 1e6 * p.seconds / p.steps if p.steps else None}

    def close(self) -> None:
        """Free the process model's FMU instance (a later run creates it again)."""
        self.process.close()


def process_model(cls: type, component: Component, label: str, name: str = "") -> FmuProcessModel:
    """The process model of observer class ``cls`` (its ``process_columns``, ``process_known``,
    ``process_fixed``) on one extra instance of ``component``'s FMU with its parameters;
    ``label`` (the SSD and observer) begins every error message, ``name`` names the instance."""
    columns = getattr(cls, "process_columns", None)
    if columns is None:
        raise UserError(f"{label}: {cls.__name__} takes no FMU process model (setting process_component)")
    try:
        return FmuProcessModel(component.fmu, columns, getattr(cls, "process_known", ()),
                               getattr(cls, "process_fixed", {}), component.parameters,
                               name=f"{name or cls.__name__} process model", md=component.md)
    except UserError as exc:
        raise UserError(f"{label}: process_component {component.name!r}: {exc}") from None
