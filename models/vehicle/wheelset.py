"""Simplified lateral model (SM) of Muñoz et al., §3.3: one wheelset and a suspended frame.

Generalised coordinates (absolute, in a track frame moving along the ideal centre line at V):
wheelset lateral displacement y and yaw psi, suspended-frame lateral displacement y_f (the
frame's yaw is constrained). Input: the lateral alignment xi(s) of the track under the
wheelset (no gauge variation, so both rails are displaced by xi), and its rate.

Equations of motion (eq. 5, M q'' + [Cs + Cc] q' + [Ks + Kc] q = Q_c0), with e = y - xi the
wheelset's displacement relative to the rails:

    m   y''   = -2 f22 (y'/V - psi) - 2 f23 psi'/V - W alpha e / l
                - 2 ky (y - y_f) - 2 cy (y' - y_f')
    I   psi'' = -2 f11 l (l psi'/V + alpha e / r0) + 2 f23 (y'/V - psi) - 2 f33 psi'/V
                - 2 kx ls^2 psi - 2 cx ls^2 psi'
    m_f y_f'' =  2 ky (y - y_f) + 2 cy (y' - y_f')

* Kalker's linear creep (knife-edge contact, conical treads of conicity alpha): longitudinal
  creepage of the left/right wheel -/+(l psi'/V + alpha e/r0), lateral y'/V - psi, spin
  psi'/V (the -/+alpha/r0 spin parts cancel between the wheels). The lateral creepage is
  taken against the stationary rail, so the rail's lateral velocity does not enter it: the
  rate xi' enters only through the first-order hold of xi within a communication step.
* Gravitational stiffness W alpha / l with W = (m + m_f) g the axle load: each wheel carries
  W/2, the wheelset rolls by alpha e / l, and the two normal forces lean by that angle. (The
  paper's eq. 16 prints 2 alpha g (m - m_f) / l for this entry of K_d; with the table's
  masses that is negative, i.e. destabilising, so we take the derivation above.)
* Primary suspension: per side one longitudinal (kx, cx) and one lateral (ky, cy) element at
  lateral distance l_s from the wheelset centre; the paper's Table 1 values are per element.
* Rolling radius: Table 1 lists r0 = 0.85 m, which is the ML95 metro wheel's *diameter*; the
  rolling radius is 0.425 m and that is the default here (it scales the alpha/r0 yaw
  stiffness, entry 2 of K_d in eq. 16).

Sensors of the paper (§4): wheelset lateral acceleration y'', yaw rate psi', frame lateral
acceleration y_f''; all three are outputs, with the states.
"""

from __future__ import annotations

import sympy as sp

from railfmu.models.base import Input, Model, Output, Parameter, State

T1 = "Muñoz et al., Table 1"

PARAMETERS = [
    Parameter("m", "Wheelset mass", "kg", 1109.0, source=T1, positive=True),
    Parameter("I", "Wheelset yaw moment of inertia", "kg.m2", 606.0, source=T1, positive=True),
    Parameter("l", "Half distance between the wheel-rail contact points", "m", 0.75, source=T1, positive=True),
    Parameter("l_s", "Lateral half-spacing of the primary suspension", "m", 0.85, source=T1, positive=True),
    Parameter("alpha", "Equivalent conicity of the wheel treads", "", 0.1, source=T1, min=0.0),
    Parameter("r0", "Rolling radius of the centred wheelset", "m", 0.425,
              source="Muñoz et al., Table 1, list 0.85 m, the ML95 wheel diameter; radius = 0.85/2",
              positive=True),
    Parameter("m_f", "Suspended mass carried by the wheelset (1/4 car body + 1/2 bogie frame)", "kg",
              3781.0, source=T1, positive=True),
    Parameter("f11", "Kalker longitudinal creep coefficient", "N", 5.5e6, source=T1, min=0.0),
    Parameter("f22", "Kalker lateral creep coefficient", "N", 5.0e6, source=T1, min=0.0),
    Parameter("f23", "Kalker lateral/spin creep coefficient", "N.m", 9.3e3, source=T1),
    Parameter("f33", "Kalker spin creep coefficient", "N.m2", 15.0, source=T1, min=0.0),
    Parameter("kx", "Primary longitudinal stiffness, per side", "N/m", 7.95e5, source=T1, min=0.0),
    Parameter("cx", "Primary longitudinal damping, per side", "N.s/m", 1.47e4, source=T1, min=0.0),
    Parameter("ky", "Primary lateral stiffness, per side", "N/m", 4.12e6, source=T1, min=0.0),
    Parameter("cy", "Primary lateral damping, per side", "N.s/m", 1.41e5, source=T1, min=0.0),
    Parameter("V", "Forward speed", "m/s", 20.0, source="Muñoz et al., §5", positive=True),
    Parameter("g", "Gravitational acceleration", "m/s2", 9.81, source="standard gravity (rounded)",
              positive=True),
]


def build() -> Model:
    p = {q.name: q.symbol for q in PARAMETERS}
    m, I, l, ls, alpha, r0, mf = (p[k] for k in ("m", "I", "l", "l_s", "alpha", "r0", "m_f"))
    f11, f22, f23, f33 = (p[k] for k in ("f11", "f22", "f23", "f33"))
    kx, cx, ky, cy, V, g = (p[k] for k in ("kx", "cx", "ky", "cy", "V", "g"))

    xi = Input("xi", "Lateral alignment of the track under the wheelset", "m", 0.0, rate="xi_rate")
    xi_rate = Input("xi_rate", "Time derivative of the lateral alignment under the wheelset", "m/s", 0.0)
    y, psi, yf = (sp.Symbol(n, real=True) for n in ("y", "psi", "y_f"))
    dy, dpsi, dyf = (sp.Symbol(n, real=True) for n in ("dy", "dpsi", "dy_f"))

    e = y - xi.symbol
    lateral_creepage = dy / V - psi
    spin_creepage = dpsi / V
    longitudinal_creepage = l * dpsi / V + alpha * e / r0
    susp_y = 2 * ky * (y - yf) + 2 * cy * (dy - dyf)
    F_y = -2 * f22 * lateral_creepage - 2 * f23 * spin_creepage - (m + mf) * g * alpha / l * e - susp_y
    M_z = (-2 * f11 * l * longitudinal_creepage + 2 * f23 * lateral_creepage - 2 * f33 * spin_creepage
           - 2 * kx * ls**2 * psi - 2 * cx * ls**2 * dpsi)
    ddy, ddpsi, ddyf = F_y / m, M_z / I, susp_y / mf

    states = [
        State("y", "Wheelset lateral displacement", "m", 0.0, der=dy),
        State("psi", "Wheelset yaw angle", "rad", 0.0, der=dpsi),
        State("y_f", "Suspended-frame lateral displacement", "m", 0.0, der=dyf),
        State("dy", "Wheelset lateral velocity", "m/s", 0.0, der=ddy),
        State("dpsi", "Wheelset yaw rate (axle-box gyro)", "rad/s", 0.0, der=ddpsi),
        State("dy_f", "Suspended-frame lateral velocity", "m/s", 0.0, der=ddyf),
    ]
    outputs = [
        Output("ddy", "Wheelset lateral acceleration (axle-box accelerometer)", "m/s2", expr=ddy),
        Output("ddpsi", "Wheelset yaw acceleration", "rad/s2", expr=ddpsi),
        Output("ddy_f", "Suspended-frame lateral acceleration (frame accelerometer)", "m/s2", expr=ddyf),
    ]
    return Model(
        identifier="WheelsetLateral",
        description="Wheelset + suspended frame lateral model (the SM of Muñoz et al., §3.3): linear Kalker "
                    "creep, conical treads, primary suspension; input: track lateral alignment",
        parameters=list(PARAMETERS),
        inputs=[xi, xi_rate],
        states=states,
        outputs=outputs,
        integrator_step=1e-4,
        documentation=__doc__,
    )


WHEELSET = build()
