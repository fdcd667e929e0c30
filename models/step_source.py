"""Step signal source: a fault or excitation that is a component of the system.

    y(t) = initial_value   for t <  step_time
    y(t) = final_value     for t >= step_time

Semantics in co-simulation: the FMU has no states; ``y`` is evaluated at the communication
points (and in initialisation mode, at the start time). The step therefore appears at the
first communication point ``t_n >= step_time`` and a connected input sees the new value for
the whole step that starts there (zero-order hold). When ``step_time`` lies on the step grid
the switch happens exactly at ``step_time``; because importers compute grid times in floating
point (0.99 + 0.01 may be 0.9999999999999999), the comparison allows 1e-9 relative, the same
tolerance the runtime uses to match ``currentCommunicationPoint`` with its own time::

    t >= step_time - 1e-9 max(1, |step_time|)

``y`` has no unit (the unit attribute is omitted): the source is generic and connects to any
real input, e.g. the secondary stiffness ``k1`` (N/m) of the CoachVertical FMU (seed 004 §4:
k1 falls from 430e3 to 215e3 N/m at t = 20 s), a speed or an irregularity. The values carry
the unit of whatever the output drives; say it in the .ssv that sets them.
"""

from __future__ import annotations

import sympy as sp

from .base import Model, Output, Parameter

TIME_TOLERANCE = 1e-9  # relative, as the runtime's time_close()

PARAMETERS = [
    Parameter("initial_value", "Output before the step (in the unit of the connected input)", "", 0.0,
              source="experiment (.ssv)"),
    Parameter("final_value", "Output from step_time on (in the unit of the connected input)", "", 1.0,
              source="experiment (.ssv)"),
    Parameter("step_time", "Time of the step", "s", 1.0, source="experiment (.ssv)"),
]


def build() -> Model:
    t = sp.Symbol("t", real=True)  # simulation time (Model._args puts it first; C: r[0])
    y0, y1, ts = (q.symbol for q in PARAMETERS)
    after = t >= ts - TIME_TOLERANCE * sp.Max(1, sp.Abs(ts))
    y = Output("y", "initial_value before step_time, final_value from step_time on", "",
               expr=sp.Piecewise((y1, after), (y0, True)))
    return Model(
        identifier="StepSource",
        description="Step signal: initial_value before step_time, final_value from then on "
                    "(a fault or excitation as a component of the system)",
        parameters=list(PARAMETERS),
        outputs=[y],
        documentation=__doc__,
    )


STEP_SOURCE = build()
