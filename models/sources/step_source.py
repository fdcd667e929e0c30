"""Step signal source: a fault or excitation that is a component of the system.

    y(t) = initial_value   before step_time
    y(t) = final_value     from step_time on

Semantics in co-simulation: the FMU has no states; ``y`` is evaluated at the communication
points (and in initialisation mode, at the start time). The step therefore appears at the
first communication point that reaches ``step_time``, and a connected input sees the new value
for the whole step that starts there (zero-order hold).

When is ``step_time`` reached? With ``h`` the communication step that ended at ``t`` (s, the
``communicationStepSize`` of fmi2DoStep; 0 in initialisation mode) and ``eps`` =
``railfmu.models.base.STEP_TOLERANCE`` = 0.01::

    y = final_value   if  t >= step_time - eps h

A step time on the master's grid thus switches exactly there, however the master computes
its time: ``n h`` in floating point (0.99 + 0.01 may be 0.9999999999999999) or an
accumulated ``t += h`` (OMSimulator, FMPy's container FMU: off the grid by a fraction of
``h`` that grows as ``n^2``, below ``eps`` over millions of steps). The band is a fraction of the
step, not of ``t``, so it does not widen over a long run; a step time more than ``eps h``
after a communication point (between grid points) appears at the next one. In
initialisation mode (``h = 0``) the comparison is exact: ``y`` is final_value at the start
only when ``step_time <= t0``.

``y`` has no unit (the unit attribute is omitted): the source is generic and connects to any
real input, e.g. the secondary stiffness ``k1`` (N/m) of the CoachVertical FMU (Onat et al.
(2016) sec. 4: k1 falls from 430e3 to 215e3 N/m at t = 20 s), a speed or an irregularity.
The values carry the unit of whatever the output drives; say it in the .ssv that sets them.
"""

from __future__ import annotations

import sympy as sp

from railfmu.models.base import STEP_SIZE, STEP_TOLERANCE, Model, Output, Parameter

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
    after = t >= ts - STEP_TOLERANCE * STEP_SIZE
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
"""The step source FMU: the step happens at the first communication point t >= step_time - 0.01 h."""
