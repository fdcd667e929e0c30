r"""Complete vehicle model (CM) of Muñoz et al. (§3.2, §5): one car body, two bogie frames, four
wheelsets on straight track with irregularities; weakly coupled vertical/lateral dynamics.

The paper validates its simplified model (SM, :mod:`railfmu.models.vehicle.wheelset`) against a complete
multibody model of the ML95 metro car (its ref. [15], Muñoz et al., MSSP 115 (2019)): track-
relative coordinates, small angles, linear suspensions, knife-edge contact with equivalent
conicity and Kalker's linear creep, flange contact as an option. This module is that CM,
derived once with sympy and generated into the ``VehicleLateral`` FMU.

Coordinates (23 DOF, 46 states)
-------------------------------
Absolute small displacements of each body's centre of gravity in a frame moving along the
ideal track centre line at ``V``: ``x`` forward, ``y`` to the left, ``z`` up; rotations
right-handed about them (roll ``phi`` about x: left side up; pitch ``theta`` about y: front
end down; yaw ``psi`` about z: front to the left). A body point at ``r = (x, y, z)`` from the
centre of gravity moves by ``u + rot x r``::

    u_x = theta z - psi y,    u_y = Y + psi x - phi z,    u_z = Z + phi y - theta x

    car body  c      y_c, z_c, phi_c, theta_c, psi_c                    5
    bogie     b1, b2 y_bi, z_bi, phi_bi, theta_bi, psi_bi               10
    wheelset  w1..w4 y_wj, psi_wj                                       8

Bogie 1 leads (``x = +a_b``); wheelsets 1, 2 in bogie 1 at ``+a_w``, ``-a_w`` from its
centre, 3, 4 in bogie 2. Lateral DOF: lateral, yaw and roll of car body and bogies and
lateral and yaw of the wheelsets (17, as the 17-DOF model of the paper's ref. [12]); vertical DOF:
bounce and pitch of car body and bogies (6), so the wheel loads follow the vertical
irregularities. The wheelsets' vertical position and roll are *kinematic*, imposed by the
rails (knife-edge contact, no wheel-rail separation)::

    z_wj = (zl_j + zr_j) / 2,        phi_wj = (zl_j - zr_j) / (2 l)

with ``zl_j``/``zr_j`` the vertical irregularity of the left/right rail under wheelset j.
The conicity-induced roll ``alpha e / l`` of the wheelset enters only the gravitational
stiffness below (as in the SM), not the primary suspension deflections.

Equations (Lagrange with linear elements)
-----------------------------------------
With coordinates at the centres of gravity and principal axes, the kinetic energy is
diagonal, so ``M`` is the constant diagonal of masses and inertias and no matrix is
inverted: ``q_k'' = Q_k / M_kk``. Each suspension element is a linear spring ``k`` and a
viscous damper ``c`` acting on the relative displacement ``d`` of its two attachment points
along its direction (``d`` is linear in q and in the rail inputs); with ``V_e = k d^2 / 2``
and ``D_e = c d'^2 / 2`` its generalised force is ::

    Q_k += F_e dd/dq_k,    F_e = -k d - c d'

(``d'`` uses the rail rates, the inputs' ``*_rate``). Gravity and the static preloads cancel
at the equilibrium on perfect track (motions about it, as :mod:`railfmu.models.vehicle.coach_vertical`).
Neglected: wheelset spin gyroscopic terms, the geometric stiffness of preloaded springs, the
inertia of the wheelset in the wheel loads.

Suspension (per element; ``s = +1`` left, ``-1`` right)
------------------------------------------------------
* primary, per axle box (wheelset j, side s) at ``(±a_w, s l_s)`` and axle height ``r0``:
  longitudinal ``kx_p, cx_p``, lateral ``ky_p, cy_p``, vertical ``kz_p, cz_p``. The wheelset
  point moves by ``(-s l_s psi_wj, y_wj, z_wj + s l_s phi_wj)``.
* secondary, per side of each bogie at ``(±a_b, s b_s)`` and height ``h_s``: air spring
  ``kx_s, ky_s, kz_s`` with vertical damper ``cz_s``, lateral damper ``cy_s``; a yaw damper
  (longitudinal) ``c_yd`` at ``(±a_b, s b_yd, h_s)``; an anti-roll bar ``k_ar`` on
  ``phi_c - phi_bi``. The heights of the lateral elements couple lateral motion and roll.

Wheel-rail contact (wheelset j, wheel s; e_j = y_wj - xi_j)
----------------------------------------------------------
Wheel loads: the static share ``Q0 = (m_c + 2 m_b + 4 m_w) g / 8`` plus the dynamic force of
the primary vertical element above that wheel (wheelset inertia neglected)::

    Q_js = Q0 - kz_p d_js - cz_p d_js'      d_js: bogie point minus wheelset point (z)

Kalker's linear creep (the paper's ref. [13]) with load-dependent coefficients: the Hertzian
contact-ellipse semi-axes grow as ``Q^(1/3)``, so ``f11, f22 ~ G ab ~ Q^(2/3)``,
``f23 ~ G (ab)^(3/2) ~ Q`` and ``f33 ~ G (ab)^2 ~ Q^(4/3)`` (Kalker 1967; Garg & Dukkipati,
*Dynamics of Railway Vehicle Systems*, 1984, §5.5; the ellipse shape a/b stays fixed
because the curvatures do)::

    f_ik,js = f_ik0 (Q_js / Q0)^n_ik        n = 2/3, 2/3, 1, 4/3  for f11, f22, f23, f33

``f_ik0`` are the values of Muñoz et al., Table 1, which Kalker's theory gave at the static
wheel load of the SM, ``(m + m_f) g / 2`` = 23.99 kN; the CM's ``Q0`` equals it exactly (the suspended
mass per wheelset, 3781 kg, is ``m_c/4 + m_b/2``). Creepages as in the SM::

    nu_x,js = -s (l psi_wj' / V + alpha e_j / r0),  nu_y,j = y_wj' / V - psi_wj,  nu_sp,j = psi_wj' / V
    F_x,js = -f11 nu_x,   F_y,js = -f22 nu_y - f23 nu_sp,   M_z,js = f23 nu_y - f33 nu_sp

Normal forces (gravitational stiffness): they turn with the wheelset's roll, ``alpha e / l``
from the cones plus the rails' cross-level ``phi_wj``; on the cones they push each wheel
towards the track centre by ``alpha Q``, which cancels only when the loads are equal::

    F_N,j = -(Q_jL + Q_jR) (alpha e_j / l + phi_wj) + alpha (Q_jR - Q_jL)

At rest on perfect track this is the SM's ``-W alpha e / l``. Flange contact (switch
``flange_contact``, off by default; Cooperrider's bogie model, ASME J. Eng. Ind. 94 (1972)
as used by True & Kaas-Petersen): a stiff spring outside the flangeway clearance ``delta``::

    F_fl,j = -k_fl (e_j - delta)  if e_j > delta,   -k_fl (e_j + delta)  if e_j < -delta,   else 0

Wheelset j: ``m_w y_wj'' = sum_s F_y,js + F_N,j + F_fl,j + primary lateral``,
``I_w psi_wj'' = sum_s (-s l F_x,js + M_z,js) + primary yaw``.

Rolling radius
--------------
Muñoz et al., Table 1, list ``r0 = 0.85 m``, the ML95 wheel's *diameter*; the rolling radius is
0.425 m (as in the SM). It sets the longitudinal creepage ``alpha e / r0`` (entry 2 of
``K_d``, the paper's eq. 16) and the axle-box height.

Sensors (Muñoz et al., §4) and other outputs
--------------------------------------------
``ddy_w1`` axle-box lateral acceleration of wheelset 1, ``dpsi_w1`` its yaw rate (a state),
``ddy_b1`` lateral acceleration of bogie frame 1 at the accelerometer, placed at
``(sensor_x, 0, sensor_z)`` from the frame's centre of gravity (default: above wheelset 1 at
axle height; the paper does not give the position, its SM frame sits above the wheelset).
Also ``ddy_c``, the wheel loads ``Q_jL, Q_jR`` and the total lateral contact force ``F_yj``
on each wheelset (creep + normal + flange).

Modes
-----
:func:`lateral_modes` returns the damped modes of the linearisation (:func:`state_matrix`,
central differences of the model's own right-hand side; ``Model.linearize`` gives the same
A symbolically but takes minutes). Defaults at V = 20 m/s (damped Hz, damping ratio):
car body yaw 0.62 (0.71), lower sway 0.66 (0.32), bounce 1.07 (0.14), upper sway / roll
1.23 (0.22), pitch 1.29 (0.19); wheelset kinematic modes, coupled with the car-body roll,
1.51-1.64 (0.08-0.27), below Klingel's 1.78 Hz for a free wheelset because the primary yaw
stiffness ties the wheelsets to the bogie frames; bogie bounce 7.2, pitch 8.2, roll 9.5.
:func:`first_lateral_mode` (lowest lateral mode with damping ratio < 0.25) gives
f1 = 1.23 Hz, a 16.3 m wavelength at 20 m/s (Muñoz et al., §5.5: 1.277 Hz, 15.66 m). The linear
critical speed with these parameters lies between 45 and 50 m/s (hunting of the wheelsets).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import sympy as sp

from railfmu.models.base import Input, Model, Output, Parameter, State

T1 = "Muñoz et al., Table 1"
MB = "Manchester benchmark vehicle 1 (Iwnicki, VSD 30 (1998) 295-313)"
# The metro car is the Manchester benchmark coach scaled in mass so that the suspended mass
# per wheelset m_c/4 + m_b/2 is the m_f = 3781 kg of Muñoz et al., Table 1 (the benchmark's is
# 32000/4 + 2615/2 = 9307.5 kg); stiffnesses and damping scale alike, so the suspension
# frequencies of the benchmark are kept.
S_M = 3781.0 / 9307.5
SCALED = f"{MB} x s_m = 3781/9307.5 = {S_M:.4f}"


def _scaled(value: float) -> float:
    return float(f"{value * S_M:.4g}")


PARAMETERS = [
    # wheelsets: Muñoz et al., Table 1
    Parameter("m_w", "Wheelset mass", "kg", 1109.0, source=T1, positive=True),
    Parameter("I_w", "Wheelset yaw moment of inertia", "kg.m2", 606.0, source=T1, positive=True),
    Parameter("l", "Half distance between the wheel-rail contact points", "m", 0.75, source=T1, positive=True),
    Parameter("r0", "Rolling radius of the centred wheelset", "m", 0.425,
              source="Muñoz et al., Table 1, list 0.85 m, the ML95 wheel diameter; radius = 0.85/2", positive=True),
    Parameter("alpha", "Equivalent conicity of the wheel treads", "", 0.1, source=T1, min=0.0),
    Parameter("f11", "Kalker longitudinal creep coefficient per wheel at the static load Q0", "N", 5.5e6,
              source=T1, min=0.0),
    Parameter("f22", "Kalker lateral creep coefficient per wheel at Q0", "N", 5.0e6, source=T1, min=0.0),
    Parameter("f23", "Kalker lateral/spin creep coefficient per wheel at Q0", "N.m", 9.3e3, source=T1),
    Parameter("f33", "Kalker spin creep coefficient per wheel at Q0", "N.m2", 15.0, source=T1, min=0.0),
    # car body and bogie frames
    Parameter("m_c", "Car-body mass", "kg", _scaled(32000.0),
              source=f"{SCALED}; with m_b: m_c/4 + m_b/2 = 3781 kg (Muñoz et al., Table 1, m_f)", positive=True),
    Parameter("Ix_c", "Car-body roll moment of inertia", "kg.m2", _scaled(56.8e3), source=SCALED, positive=True),
    Parameter("Iy_c", "Car-body pitch moment of inertia", "kg.m2", _scaled(1970e3), source=SCALED, positive=True),
    Parameter("Iz_c", "Car-body yaw moment of inertia", "kg.m2", _scaled(1970e3), source=SCALED, positive=True),
    Parameter("m_b", "Bogie-frame mass (each)", "kg", _scaled(2615.0), source=SCALED, positive=True),
    Parameter("Ix_b", "Bogie-frame roll moment of inertia", "kg.m2", _scaled(1722.0), source=SCALED, positive=True),
    Parameter("Iy_b", "Bogie-frame pitch moment of inertia", "kg.m2", _scaled(1476.0), source=SCALED, positive=True),
    Parameter("Iz_b", "Bogie-frame yaw moment of inertia", "kg.m2", _scaled(3067.0), source=SCALED, positive=True),
    # geometry
    Parameter("a_b", "Longitudinal semi-distance of the bogie pivots", "m", 9.5,
              source="ERRI B176 / Manchester coach (Onat et al. 2016, Table 1, a1); matches TrackIrregularity's "
                     "axle_position defaults (19 m between the bogies)", positive=True),
    Parameter("a_w", "Semi-wheelbase of the bogies", "m", 1.25,
              source="matches TrackIrregularity's axle_position defaults (2.5 m wheelbase; Manchester 2.56 m)",
              positive=True),
    Parameter("l_s", "Lateral semi-spacing of the primary suspension (axle boxes)", "m", 0.85, source=T1,
              positive=True),
    Parameter("b_s", "Lateral semi-spacing of the secondary suspension (air springs, lateral dampers)", "m", 1.0,
              source=f"{MB} (Onat et al. 2016, Table 1, c1)", positive=True),
    Parameter("b_yd", "Lateral semi-spacing of the yaw dampers", "m", 1.3,
              source="assumed: yaw dampers outboard of the air springs (typical bogie layout)", positive=True),
    Parameter("h_c", "Car-body centre of gravity above rail level", "m", 1.6,
              source="assumed: typical metro car (low floor ~1.1 m, roof ~3.6 m)", positive=True),
    Parameter("h_b", "Bogie-frame centre of gravity above rail level", "m", 0.55,
              source="assumed: typical bogie frame with 0.85 m wheels", positive=True),
    Parameter("h_s", "Height of the secondary elements (air spring, dampers) above rail level", "m", 0.9,
              source="assumed: air springs on the frame side beams", positive=True),
    # primary suspension, per axle box
    Parameter("kx_p", "Primary longitudinal stiffness, per axle box", "N/m", 7.95e5,
              source=f"{T1} kx (per side of the wheelset): a soft-yaw rubber-sprung metro bogie; "
                     f"the benchmark coach's 31.4 MN/m is a stiff main-line value", min=0.0),
    Parameter("cx_p", "Primary longitudinal damping, per axle box", "N.s/m", 1.47e4, source=f"{T1} cx", min=0.0),
    Parameter("ky_p", "Primary lateral stiffness, per axle box", "N/m", 4.12e6,
              source=f"{T1} ky (the benchmark's is 3.884 MN/m per axle box)", min=0.0),
    Parameter("cy_p", "Primary lateral damping, per axle box", "N.s/m", 1.41e5, source=f"{T1} cy", min=0.0),
    Parameter("kz_p", "Primary vertical stiffness, per axle box", "N/m", _scaled(1220e3),
              source=f"{SCALED} (1220 kN/m per axle box)", min=0.0),
    Parameter("cz_p", "Primary vertical damping, per axle box", "N.s/m", _scaled(4e3),
              source=f"{SCALED} (4 kN s/m per axle box)", min=0.0),
    # secondary suspension, per side of each bogie
    Parameter("kx_s", "Secondary longitudinal stiffness (air spring), per side", "N/m", _scaled(160e3),
              source=f"{SCALED} (160 kN/m)", min=0.0),
    Parameter("ky_s", "Secondary lateral stiffness (air spring), per side", "N/m", _scaled(160e3),
              source=f"{SCALED} (160 kN/m)", min=0.0),
    Parameter("kz_s", "Secondary vertical stiffness (air spring), per side", "N/m", _scaled(430e3),
              source=f"{SCALED} (430 kN/m; Onat et al. 2016, Table 1, k1)", min=0.0),
    Parameter("cy_s", "Secondary lateral damping, per side", "N.s/m", _scaled(32e3),
              source=f"{SCALED} (32 kN s/m)", min=0.0),
    Parameter("cz_s", "Secondary vertical damping, per side", "N.s/m", _scaled(20e3),
              source=f"{SCALED} (20 kN s/m; Onat et al. 2016, Table 1, b1)", min=0.0),
    Parameter("c_yd", "Yaw damper (longitudinal) damping, per side", "N.s/m", _scaled(500e3),
              source="assumed 500 kN s/m, a passenger-coach yaw damper, x s_m", min=0.0),
    Parameter("k_ar", "Anti-roll bar torsional stiffness, per bogie (car body vs bogie roll)", "N.m/rad",
              _scaled(2.5e6), source="assumed 2.5 MN m/rad (coach anti-roll bar) x s_m", min=0.0),
    # contact options and running conditions
    Parameter("flange_contact", "Flange contact: 0 off, 1 on", "", 0, type="Integer", min=0, max=1,
              source="Muñoz et al., §3.2: flange contact can be simulated; off in their runs"),
    Parameter("k_fl", "Flange contact lateral stiffness (rail + contact)", "N/m", 1.823e7,
              source="Cooperrider's bogie model (True & Kaas-Petersen): k0 = 1.823e7 N/m", min=0.0),
    Parameter("delta_fl", "Flangeway clearance (lateral play before flange contact)", "m", 0.0091,
              source="Cooperrider's bogie model (True & Kaas-Petersen): delta = 9.1 mm", positive=True),
    Parameter("sensor_x", "Longitudinal position of the bogie-1 accelerometer from the frame's centre", "m",
              1.25, source="assumed: above wheelset 1 (a_w), where the SM's frame is"),
    Parameter("sensor_z", "Height of the bogie-1 accelerometer above the frame's centre of gravity", "m",
              -0.125, source="assumed: at axle height (r0 - h_b)"),
    Parameter("V", "Forward speed", "m/s", 20.0, source="Muñoz et al., §5", positive=True),
    Parameter("g", "Gravitational acceleration", "m/s2", 9.81, source="standard gravity (rounded)", positive=True),
]

BODIES = ("c", "b1", "b2")
BODY_DOF = ("y", "z", "phi", "theta", "psi")
WHEELSETS = (1, 2, 3, 4)
COORDS = [f"{d}_{b}" for b in BODIES for d in BODY_DOF] + [f"{d}_w{j}" for j in WHEELSETS for d in ("y", "psi")]
SIDES = (("L", 1), ("R", -1))
_UNIT = {"y": "m", "z": "m", "phi": "rad", "theta": "rad", "psi": "rad"}
_WHAT = {"y": "lateral displacement", "z": "bounce (up)", "phi": "roll (left side up)",
         "theta": "pitch (front end down)", "psi": "yaw (front to the left)"}
_BODY_NAME = {"c": "Car-body", "b1": "Bogie-frame 1 (leading)", "b2": "Bogie-frame 2",
              "w1": "Wheelset 1 (leading)", "w2": "Wheelset 2", "w3": "Wheelset 3", "w4": "Wheelset 4"}


class cbrt(sp.Function):  # named after the C function it prints as
    """Real cube root that stays one function call: sympy's own ``x**(1/3)`` merges with
    powers of the same base (``c**2`` -> ``x**(2/3)``), which C evaluates with pow()."""

    nargs = 1

    @classmethod
    def eval(cls, x):
        if x.is_Number:
            return sp.Float(np.cbrt(float(x)))

    def fdiff(self, argindex=1):
        return 1 / (3 * cbrt(self.args[0]) ** 2)

    def _ccode(self, printer):
        return f"cbrt({printer._print(self.args[0])})"

    def _numpycode(self, printer):
        return f"{printer._module_format('numpy.cbrt')}({printer._print(self.args[0])})"


def _sym(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def _inputs() -> list[Input]:
    out = []
    for j in WHEELSETS:
        out += [Input(f"alignment_{j}", f"Lateral alignment of the track under wheelset {j} (left positive)", "m",
                      0.0, rate=f"alignment_rate_{j}"),
                Input(f"vertical_left_{j}", f"Vertical irregularity of the left rail under wheelset {j} (up)",
                      "m", 0.0, rate=f"vertical_left_rate_{j}"),
                Input(f"vertical_right_{j}", f"Vertical irregularity of the right rail under wheelset {j} (up)",
                      "m", 0.0, rate=f"vertical_right_rate_{j}")]
    for j in WHEELSETS:
        out += [Input(f"alignment_rate_{j}", f"Time derivative of alignment_{j}", "m/s", 0.0),
                Input(f"vertical_left_rate_{j}", f"Time derivative of vertical_left_{j}", "m/s", 0.0),
                Input(f"vertical_right_rate_{j}", f"Time derivative of vertical_right_{j}", "m/s", 0.0)]
    return out


def build() -> Model:
    p = {q.name: q.symbol for q in PARAMETERS}
    inputs = _inputs()
    u = {v.name: v.symbol for v in inputs}
    rate_of = {v.symbol: u[v.rate] for v in inputs if v.rate}
    q = {n: _sym(n) for n in COORDS}
    dq = {n: _sym("d" + n) for n in COORDS}

    def rate(expr):
        """d/dt of an expression linear in the coordinates and the rail inputs."""
        return (sum(sp.diff(expr, q[n]) * dq[n] for n in COORDS)
                + sum(sp.diff(expr, s) * r for s, r in rate_of.items()))

    Q = {n: sp.S.Zero for n in COORDS}

    def element(d, k, c):
        """A spring k and damper c on the deflection d: adds its generalised forces, returns
        the element force F = -k d - c d'."""
        F = -k * d - c * rate(d)
        for n in COORDS:
            a = sp.diff(d, q[n])
            if a != 0:
                Q[n] += F * a
        return F

    def body_point(b, x, y, z):
        """Displacement (u_x, u_y, u_z) of the point (x, y, z) from body b's centre of gravity."""
        Y, Z, phi, th, psi = (q[f"{d}_{b}"] for d in BODY_DOF)
        return th * z - psi * y, Y + psi * x - phi * z, Z + phi * y - th * x

    a_b, a_w, l_s, b_s, b_yd = p["a_b"], p["a_w"], p["l_s"], p["b_s"], p["b_yd"]
    h_c, h_b, h_s, r0, l = p["h_c"], p["h_b"], p["h_s"], p["r0"], p["l"]

    # secondary suspension: car body vs bogie i, per side
    for i, xb in ((1, a_b), (2, -a_b)):
        b = f"b{i}"
        for _, s in SIDES:
            uc = body_point("c", xb, s * b_s, h_s - h_c)
            ub = body_point(b, 0, s * b_s, h_s - h_b)
            element(uc[0] - ub[0], p["kx_s"], 0)
            element(uc[1] - ub[1], p["ky_s"], p["cy_s"])
            element(uc[2] - ub[2], p["kz_s"], p["cz_s"])
            ucy = body_point("c", xb, s * b_yd, h_s - h_c)
            uby = body_point(b, 0, s * b_yd, h_s - h_b)
            element(ucy[0] - uby[0], 0, p["c_yd"])
        element(q["phi_c"] - q[f"phi_{b}"], p["k_ar"], 0)

    # primary suspension and wheel loads
    Q0 = (p["m_c"] + 2 * p["m_b"] + 4 * p["m_w"]) * p["g"] / 8
    loads, phi_w, xi = {}, {}, {}
    for j in WHEELSETS:
        b = "b1" if j <= 2 else "b2"
        xw = a_w if j in (1, 3) else -a_w
        zl, zr = u[f"vertical_left_{j}"], u[f"vertical_right_{j}"]
        z_w, phi_w[j] = (zl + zr) / 2, (zl - zr) / (2 * l)
        xi[j] = u[f"alignment_{j}"]
        y_w, psi_w = q[f"y_w{j}"], q[f"psi_w{j}"]
        for side, s in SIDES:
            ub = body_point(b, xw, s * l_s, r0 - h_b)
            uw = (-s * l_s * psi_w, y_w, z_w + s * l_s * phi_w[j])
            element(ub[0] - uw[0], p["kx_p"], p["cx_p"])
            element(ub[1] - uw[1], p["ky_p"], p["cy_p"])
            loads[j, side] = Q0 + element(ub[2] - uw[2], p["kz_p"], p["cz_p"])

    # wheel-rail contact
    V, alpha = p["V"], p["alpha"]
    contact = {}
    for j in WHEELSETS:
        e = q[f"y_w{j}"] - xi[j]
        nu_y = dq[f"y_w{j}"] / V - q[f"psi_w{j}"]
        nu_sp = dq[f"psi_w{j}"] / V
        F_y, M_z = sp.S.Zero, sp.S.Zero
        for side, s in SIDES:
            r = sp.Max(loads[j, side], 0) / Q0  # load ratio (no tension in the contact)
            c = cbrt(r)
            f11, f22, f23, f33 = p["f11"] * c**2, p["f22"] * c**2, p["f23"] * r, p["f33"] * r * c
            nu_x = -s * (l * dq[f"psi_w{j}"] / V + alpha * e / r0)
            F_y += -f22 * nu_y - f23 * nu_sp
            M_z += -s * l * (-f11 * nu_x) + f23 * nu_y - f33 * nu_sp
        QL, QR = loads[j, "L"], loads[j, "R"]
        F_N = -(QL + QR) * (alpha * e / l + phi_w[j]) + alpha * (QR - QL)
        d = p["delta_fl"]
        F_fl = p["flange_contact"] * sp.Piecewise((-p["k_fl"] * (e - d), e > d), (-p["k_fl"] * (e + d), e < -d),
                                                  (0, True))
        contact[j] = F_y + F_N + F_fl
        Q[f"y_w{j}"] += contact[j]
        Q[f"psi_w{j}"] += M_z

    inertia = {}
    for b, (m, Ix, Iy, Iz) in {"c": ("m_c", "Ix_c", "Iy_c", "Iz_c"), "b1": ("m_b", "Ix_b", "Iy_b", "Iz_b"),
                               "b2": ("m_b", "Ix_b", "Iy_b", "Iz_b")}.items():
        for d, key in zip(BODY_DOF, (m, m, Ix, Iy, Iz)):
            inertia[f"{d}_{b}"] = p[key]
    for j in WHEELSETS:
        inertia[f"y_w{j}"], inertia[f"psi_w{j}"] = p["m_w"], p["I_w"]
    acc = {n: Q[n] / inertia[n] for n in COORDS}

    states = []
    for n in COORDS:
        d, b = n.split("_")
        states.append(State(n, f"{_BODY_NAME[b]} {_WHAT[d]}", _UNIT[d], 0.0, der=dq[n]))
    for n in COORDS:
        d, b = n.split("_")
        desc = f"{_BODY_NAME[b]} {_WHAT[d].split(' (')[0]} {'velocity' if d in ('y', 'z') else 'rate'}"
        if n == "psi_w1":
            desc += " (sensor: axle-box gyro)"
        states.append(State("d" + n, desc, _UNIT[d] + "/s", 0.0, der=acc[n]))
    outputs = [
        Output("ddy_w1", "Wheelset 1 lateral acceleration (sensor: axle-box accelerometer)", "m/s2",
               expr=acc["y_w1"]),
        Output("ddy_b1", "Bogie-frame 1 lateral acceleration at (sensor_x, 0, sensor_z) (sensor: frame "
               "accelerometer)", "m/s2",
               expr=acc["y_b1"] + p["sensor_x"] * acc["psi_b1"] - p["sensor_z"] * acc["phi_b1"]),
        Output("ddy_c", "Car-body lateral acceleration at its centre of gravity", "m/s2", expr=acc["y_c"]),
    ]
    for j in WHEELSETS:
        outputs += [Output(f"Q_{j}{side}", f"Vertical wheel load, wheelset {j}, {'left' if s > 0 else 'right'} "
                           f"wheel", "N", expr=loads[j, side]) for side, s in SIDES]
    outputs += [Output(f"F_y{j}", f"Total lateral contact force on wheelset {j} (creep + normal + flange)", "N",
                       expr=contact[j]) for j in WHEELSETS]
    return Model(
        identifier="VehicleLateral",
        description="Complete vehicle model (the CM of Muñoz et al.): car body, 2 bogie frames, 4 wheelsets; lateral, "
                    "yaw, roll and bounce/pitch, primary and secondary suspension, Kalker creep with "
                    "load-dependent coefficients, optional flange contact; inputs: rail irregularities "
                    "under each wheelset",
        parameters=list(PARAMETERS),
        inputs=inputs,
        states=states,
        outputs=outputs,
        integrator_step=1e-4,
        documentation=__doc__,
    )


VEHICLE_LATERAL = build()
N_DOF = len(COORDS)


# -- linear analysis ---------------------------------------------------------------------------
def state_matrix(params: Mapping[str, float] | None = None, eps: float = 1e-7) -> np.ndarray:
    """A = df/dx about rest on perfect track, by central differences of the model's own
    right-hand side (the equations are linear in the states apart from the load-dependent
    creep coefficients, whose effect is second order at rest; eps in m or rad)."""
    f = VEHICLE_LATERAL.rhs(dict(params or {}))
    n = 2 * N_DOF
    A = np.empty((n, n))
    for k in range(n):
        dx = np.zeros(n)
        dx[k] = eps
        A[:, k] = (f(0.0, dx) - f(0.0, -dx)) / (2 * eps)
    return A


def _energy_shares(v: np.ndarray) -> dict[tuple[str, str], float]:
    """Shares of a mode shape (complex amplitudes of the 23 coordinates) by (body group, motion),
    weighted by the inertias (kinetic energy of the mode)."""
    pv = VEHICLE_LATERAL.default_parameters()
    shares: dict[tuple[str, str], float] = {}
    for n, a in zip(COORDS, v):
        d, b = n.split("_")
        if b.startswith("w"):
            w, group = (pv["m_w"] if d == "y" else pv["I_w"]), "wheelsets"
        else:
            key = {"y": "m", "z": "m", "phi": "Ix", "theta": "Iy", "psi": "Iz"}[d]
            w, group = pv[f"{key}_{'c' if b == 'c' else 'b'}"], ("car body" if b == "c" else "bogies")
        shares[group, d] = shares.get((group, d), 0.0) + w * abs(a) ** 2
    total = sum(shares.values())
    return {k: e / total for k, e in shares.items()}


def _modes(params: Mapping[str, float] | None = None) -> list[tuple[float, float, str, float, float]]:
    """(frequency, damping ratio, description, lateral share, wheelset share) of each pair."""
    lam, vec = np.linalg.eig(state_matrix(params))
    out = []
    for k in np.flatnonzero((lam.imag > 0) & (-lam.real < 0.99 * np.abs(lam))):  # not (nearly) real pairs
        sh = _energy_shares(vec[:N_DOF, k])
        top = sorted(sh.items(), key=lambda kv: -kv[1])[:2]
        desc = ", ".join(f"{g} {d} {e:.0%}" for (g, d), e in top)
        lateral = sum(e for (g, d), e in sh.items() if d in ("y", "phi", "psi"))
        wheelsets = sum(e for (g, d), e in sh.items() if g == "wheelsets")
        out.append((float(lam[k].imag / (2 * math.pi)), float(-lam[k].real / abs(lam[k])), desc, lateral,
                    wheelsets))
    return sorted(out)


def lateral_modes(params: Mapping[str, float] | None = None) -> list[tuple[float, float, str]]:
    """Oscillatory modes of the linearised vehicle (vertical ones included), sorted by
    frequency: (damped frequency |Im lambda| / 2 pi in Hz, damping ratio -Re lambda / |lambda|,
    description: the two largest kinetic-energy shares by body and motion). ``params`` may
    change any parameter, e.g. ``V``."""
    return [m[:3] for m in _modes(params)]


def first_lateral_mode(params: Mapping[str, float] | None = None,
                       max_damping: float = 0.25) -> tuple[float, float, str]:
    """f1 of Muñoz et al., §5.5 (its resonance wavelength is V / f1): the lowest-frequency lightly
    damped (damping ratio below ``max_damping``) mode whose energy is mostly lateral, yaw or
    roll."""
    return next(m[:3] for m in _modes(params) if m[3] > 0.5 and m[1] < max_damping)


def kinematic_mode(params: Mapping[str, float] | None = None) -> tuple[float, float, str]:
    """The wheelsets' kinematic mode: the oscillatory mode with the largest energy share in
    wheelset motion (lateral + yaw)."""
    return max(_modes(params), key=lambda m: m[4])[:3]
