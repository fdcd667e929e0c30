"""Vertical 7-DOF coach of Onat et al. (2016), §2: car body bounce, pitch and roll; bounce
and roll of each of the two bogies (ERRI B176 benchmark coach, their Table 1).

Coordinates and signs
---------------------
Vertical displacements are absolute, measured upwards from the static equilibrium on a
perfect track (gravity and the static spring preloads cancel there, so ``g`` does not
appear: motions about equilibrium, the paper's linearisation "around the operating state").
Bogie 1 is the leading bogie, at ``+a1`` ahead of the car-body centre; bogie 2 at ``-a1``.

    z_c      car-body bounce (m, up)            paper: y_1
    theta_c  car-body pitch (rad): positive when the end over bogie 1 rises   paper: phi_z1
    phi_c    car-body roll (rad): positive when the left side rises           paper: phi_x1
    z_b1/2   bogie bounce (m, up)               paper: y_2, y_3
    phi_b1/2 bogie roll (rad, left side up)     paper: phi_x2, phi_x3

(The paper's axes are x along the track, y vertical, z lateral, so its pitch is "around z".)

Suspension (one spring and one damper per side and bogie, Table 1 values per element)
----------------------------------------------------------------------------------
Secondary, between car body and bogie i (s_1 = +1, s_2 = -1), on side j (e_L = +1, e_R = -1)
at lateral distance c1::

    d_s = (z_c + s_i a1 theta_c + e_j c1 phi_c) - (z_bi + e_j c1 phi_bi)
    F_s = -k1 d_s - b1 d_s'                 (upwards on the car body, downwards on the bogie)

Primary, between bogie i and the rail under side j at lateral distance c2, driven by the
vertical irregularity w_ij = z_lI / z_rI (input) and its rate (input)::

    d_p = z_bi + e_j c2 phi_bi - w_ij
    F_p = -k2 d_p - b2 d_p'                 (upwards on the bogie)

The primary damper uses the rail's rate ``dz_l1 .. dz_r2`` (the paper's T_b u' term).

Equations of motion (the paper's eq. 2, M x'' + B x' + K x = T_b u' + T_k u)::

    m1  z_c''      = sum_ij F_s,ij
    Jz1 theta_c''  = a1 sum_j (F_s,1j - F_s,2j)
    Jx1 phi_c''    = c1 sum_i (F_s,iL - F_s,iR)
    m2  z_bi''     = -(F_s,iL + F_s,iR) + F_p,iL + F_p,iR
    Jx2 phi_bi''   = -c1 (F_s,iL - F_s,iR) + c2 (F_p,iL - F_p,iR)

The secondary stiffness ``k1`` is an *input* (its start value is Table 1's 430 kN/m), so a
fault source can change it during a run (the paper's §4: k1 drops to 50 % at t = 20 s); it is
held constant over a communication step.

Sensors (the paper's eq. 6 and §3: "low cost inertial sensors", accelerometers and gyros)
---------------------------------------------------------------------------------------
Accelerometers measure the vertical translations, gyros the rotations (rates), one set on
the car body and one on each bogie, seven signals in the paper's order (:data:`SENSORS`)::

    ddz_c     car-body vertical acceleration at its centre    (accelerometer)   m/s2
    dtheta_c  car-body pitch rate                             (gyro)            rad/s
    dphi_c    car-body roll rate                              (gyro)            rad/s
    ddz_b1    bogie 1 vertical acceleration                   (accelerometer)   m/s2
    dphi_b1   bogie 1 roll rate                               (gyro)            rad/s
    ddz_b2    bogie 2 vertical acceleration                   (accelerometer)   m/s2
    dphi_b2   bogie 2 roll rate                               (gyro)            rad/s

The rates are states (an FMU's states are outputs too); the accelerations are outputs. The
paper's weighted least squares puts 70 % of the weight on the car-body vertical acceleration
and roll rate (ddz_c, dphi_c). Accelerations are inertial, without gravity (the static 1 g
of a real accelerometer is a constant offset removed by the sensor model). Sensor noise is
not added here: the estimator experiment adds it (the paper: R = I, i.e. unit variance in the
units above), so the FMU stays deterministic and its outputs are the true values.

Modes with Table 1 (:func:`natural_frequencies`; undamped / damped Hz, damping ratio)
------------------------------------------------------------------------------------
car body: bounce 1.005 / 0.999 (0.11), pitch 1.219 / 1.209 (0.13), roll 0.755 / 0.752 (0.08);
bogies: bounce in phase 5.64 / 5.42 (0.28), anti-phase 5.64 / 5.40 (0.28); roll in phase
6.95 / 6.57 (0.33), anti-phase 6.97 / 6.60 (0.32). With k1 halved the car-body bounce drops
to 0.755 Hz (damped): sqrt of the bounce stiffness 4 k1 k2 / (k1 + k2), springs in series.

Deviations from the paper and what is left out
----------------------------------------------
* The paper prints its state vector, not its matrices (those are in the appendix of its
  ref. [8], Gerlici & Lack); the equations above are the standard 7-DOF vertical model with
  that state vector and Table 1's parameters.
* Table 1 lists a2 (a second "longitudinal semi spacing", 9.5 m) and V = 20 m/s. Bogies
  have no pitch here, so the primary suspension acts at the bogie centre and neither enters
  the equations: they set the delay 2 a2 / V = 0.95 s between the bogies' inputs, which the
  track FMU provides (its axle positions: bogie pivots 19 m apart). They are not FMU
  parameters of this model (:data:`TRACK_GEOMETRY` keeps them for the experiment).
* In the ERRI B176 benchmark (Iwnicki 1998) the primary vertical stiffness 1220 kN/m and
  damping 4 kN s/m are per axle box (two per side and bogie), and 430 kN/m / 20 kN s/m per
  air spring; the paper's 7-DOF model has one primary element per side and bogie and we keep
  its Table 1 values per element, as the paper does.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from railfmu.models.base import Input, Model, Output, Parameter, State

T1 = "Onat et al. (2016), Table 1 (ERRI B176 benchmark coach)"
K1_NOMINAL = 430e3  # N/m, Onat et al. (2016), Table 1: start value of the k1 input

PARAMETERS = [
    Parameter("m1", "Car-body mass", "kg", 32000.0, source=T1, positive=True),
    Parameter("m2", "Bogie mass (each bogie)", "kg", 2615.0, source=T1, positive=True),
    Parameter("Jz1", "Car-body pitch moment of inertia (in the paper: around its lateral z axis)", "kg.m2",
              1.97e6, source=T1, positive=True),
    Parameter("Jx1", "Car-body roll moment of inertia", "kg.m2", 56800.0, source=T1, positive=True),
    Parameter("Jx2", "Bogie roll moment of inertia (each bogie)", "kg.m2", 1722.0, source=T1,
              positive=True),
    Parameter("k2", "Primary vertical stiffness, per side and bogie", "N/m", 1.22e6, source=T1, min=0.0),
    Parameter("b1", "Secondary vertical damping, per side and bogie", "N.s/m", 20e3, source=T1, min=0.0),
    Parameter("b2", "Primary vertical damping, per side and bogie", "N.s/m", 4e3, source=T1, min=0.0),
    Parameter("c1", "Lateral semi-spacing of the secondary suspension", "m", 1.0, source=T1, positive=True),
    Parameter("c2", "Lateral semi-spacing of the primary suspension", "m", 1.0, source=T1, positive=True),
    Parameter("a1", "Longitudinal semi-spacing of the secondary suspension (bogie pivot to "
              "car-body centre)", "m", 9.5, source=T1, positive=True),
]

# Table 1 entries that set the track input geometry, not the vehicle's equations
TRACK_GEOMETRY = {"a2": 9.5, "V": 20.0}  # m (bogie semi-distance), m/s (speed); Onat et al. (2016), Table 1

# the paper's measurement vector (eq. 6), in its order
SENSORS = ("ddz_c", "dtheta_c", "dphi_c", "ddz_b1", "dphi_b1", "ddz_b2", "dphi_b2")
POSITIONS = ("z_c", "theta_c", "phi_c", "z_b1", "phi_b1", "z_b2", "phi_b2")


def _sym(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def build() -> Model:
    p = {q.name: q.symbol for q in PARAMETERS}
    m1, m2, Jz1, Jx1, Jx2 = (p[k] for k in ("m1", "m2", "Jz1", "Jx1", "Jx2"))
    k2, b1, b2, c1, c2, a1 = (p[k] for k in ("k2", "b1", "b2", "c1", "c2", "a1"))

    inputs = []
    rail = {}  # (bogie, side) -> (height symbol, rate symbol)
    for i in (1, 2):
        for side, word in (("l", "left"), ("r", "right")):
            inputs.append(Input(f"z_{side}{i}", f"Vertical irregularity of the {word} rail under bogie {i} "
                                f"(up positive)", "m", 0.0, rate=f"dz_{side}{i}"))
            rail[i, side] = (_sym(f"z_{side}{i}"), _sym(f"dz_{side}{i}"))
    for i in (1, 2):
        for side, word in (("l", "left"), ("r", "right")):
            inputs.append(Input(f"dz_{side}{i}", f"Time derivative of z_{side}{i}", "m/s", 0.0))
    k1_in = Input("k1", "Secondary vertical stiffness, per side and bogie (an input so that a fault "
                  "source can change it during a run)", "N/m", K1_NOMINAL,
                  source=T1 + ": 430e3 N/m nominal")
    inputs.append(k1_in)
    k1 = k1_in.symbol

    q = {n: _sym(n) for n in POSITIONS}
    dq = {n: _sym("d" + n) for n in POSITIONS}

    def coach(i, e, x):  # car-body vertical displacement (or velocity) over bogie i, side e
        return x["z_c"] + (1 if i == 1 else -1) * a1 * x["theta_c"] + e * c1 * x["phi_c"]

    F_s, F_p = {}, {}
    for i in (1, 2):
        for side, e in (("l", 1), ("r", -1)):
            d_s = coach(i, e, q) - (q[f"z_b{i}"] + e * c1 * q[f"phi_b{i}"])
            v_s = coach(i, e, dq) - (dq[f"z_b{i}"] + e * c1 * dq[f"phi_b{i}"])
            F_s[i, side] = -k1 * d_s - b1 * v_s
            w, dw = rail[i, side]
            d_p = q[f"z_b{i}"] + e * c2 * q[f"phi_b{i}"] - w
            v_p = dq[f"z_b{i}"] + e * c2 * dq[f"phi_b{i}"] - dw
            F_p[i, side] = -k2 * d_p - b2 * v_p

    acc = {
        "z_c": sum(F_s.values()) / m1,
        "theta_c": a1 * (F_s[1, "l"] + F_s[1, "r"] - F_s[2, "l"] - F_s[2, "r"]) / Jz1,
        "phi_c": c1 * (F_s[1, "l"] - F_s[1, "r"] + F_s[2, "l"] - F_s[2, "r"]) / Jx1,
    }
    for i in (1, 2):
        acc[f"z_b{i}"] = (-(F_s[i, "l"] + F_s[i, "r"]) + F_p[i, "l"] + F_p[i, "r"]) / m2
        acc[f"phi_b{i}"] = (-c1 * (F_s[i, "l"] - F_s[i, "r"]) + c2 * (F_p[i, "l"] - F_p[i, "r"])) / Jx2
    acc = {k: sp.expand(v) for k, v in acc.items()}

    what = {"z_c": ("Car-body bounce", "m"), "theta_c": ("Car-body pitch (end over bogie 1 up)", "rad"),
            "phi_c": ("Car-body roll (left side up)", "rad"), "z_b1": ("Bogie 1 bounce", "m"),
            "phi_b1": ("Bogie 1 roll (left side up)", "rad"), "z_b2": ("Bogie 2 bounce", "m"),
            "phi_b2": ("Bogie 2 roll (left side up)", "rad")}
    gyro = {"theta_c": "car-body gyro", "phi_c": "car-body gyro", "phi_b1": "bogie 1 gyro",
            "phi_b2": "bogie 2 gyro"}
    states = [State(n, f"{what[n][0]}, from static equilibrium", what[n][1], 0.0, der=dq[n]) for n in POSITIONS]
    for n in POSITIONS:
        text, unit = what[n]
        body, motion = text.split(" (")[0].rsplit(" ", 1)
        if n in gyro:
            desc = f"{body} {motion} rate (sensor: {gyro[n]})"
        else:
            desc = f"{body} vertical velocity"
        states.append(State("d" + n, desc, unit + "/s", 0.0, der=acc[n]))
    outputs = [
        Output("ddz_c", "Car-body vertical acceleration at its centre (sensor: car-body accelerometer)",
               "m/s2", expr=acc["z_c"]),
        Output("ddz_b1", "Bogie 1 vertical acceleration (sensor: bogie 1 accelerometer)", "m/s2",
               expr=acc["z_b1"]),
        Output("ddz_b2", "Bogie 2 vertical acceleration (sensor: bogie 2 accelerometer)", "m/s2",
               expr=acc["z_b2"]),
    ]
    return Model(
        identifier="CoachVertical",
        description="Vertical 7-DOF ERRI B176 coach (Onat et al. 2016): car-body bounce, pitch, roll; bogie "
                    "bounce and roll; inputs: rail vertical irregularities under both bogies and the "
                    "secondary stiffness k1",
        parameters=list(PARAMETERS),
        inputs=inputs,
        states=states,
        outputs=outputs,
        integrator_step=1e-4,
        documentation=__doc__,
    )


COACH_VERTICAL = build()

MODES = ("coach_bounce", "coach_pitch", "coach_roll", "bogie_bounce_in_phase", "bogie_bounce_anti_phase",
         "bogie_roll_in_phase", "bogie_roll_anti_phase")


def natural_frequencies(params: dict[str, float] | None = None, damped: bool = True) -> dict[str, float]:
    """Frequencies (Hz) of the seven vibration modes from the model's own A matrix.

    ``damped=True``: the damped frequency |Im lambda| / 2 pi (what a free decay shows);
    ``False``: the undamped natural frequency |lambda| / 2 pi. ``params`` may hold any
    parameter and the input ``k1``. Each complex pair is named by its mode shape: the
    body (car body or bogies) with the larger kinetic share, the motion (bounce, pitch,
    roll) with the larger share, and for bogie modes whether the two bogies move in or
    against phase. Raises if a mode is over-damped (a real eigenvalue pair)."""
    params = dict(params or {})
    u0 = {"k1": params.pop("k1")} if "k1" in params else None
    A = COACH_VERTICAL.linearize(params, u0)[0]
    pv = {**COACH_VERTICAL.default_parameters(), **params}
    inertia = np.array([pv["m1"], pv["Jz1"], pv["Jx1"], pv["m2"], pv["Jx2"], pv["m2"], pv["Jx2"]])
    lam, vec = np.linalg.eig(A)
    out: dict[str, float] = {}
    for k in np.flatnonzero(lam.imag > 0):
        v = vec[:7, k]
        e = inertia * np.abs(v) ** 2  # kinetic-energy share of each coordinate
        coach = e[:3].sum() >= e[3:].sum()
        if coach:
            name = ("coach_bounce", "coach_pitch", "coach_roll")[int(np.argmax(e[:3]))]
        else:
            roll = e[4] + e[6] > e[3] + e[5]
            j1, j2 = (4, 6) if roll else (3, 5)
            phase = "in_phase" if (v[j1] * np.conj(v[j2])).real > 0 else "anti_phase"
            name = f"bogie_{'roll' if roll else 'bounce'}_{phase}"
        if name in out:
            raise ValueError(f"two modes classified as {name}: {out[name]} Hz and {lam[k]}")
        out[name] = float((abs(lam[k].imag) if damped else abs(lam[k])) / (2 * np.pi))
    missing = set(MODES) - set(out)
    if missing:
        raise ValueError(f"modes not found (over-damped?): {sorted(missing)}")
    return {n: out[n] for n in MODES}
