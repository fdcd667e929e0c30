r"""Longitudinal train dynamics: the train motion model of Cunillera et al. (2022), eqs. 1-2.

Equations (SI; ``u`` the command input clipped to [-1, 1], ``v+ = max(v, 0)``)::

    ds/dt = v+
    dv/dt = f_t - f_b - r(v) - g(s)                       v > 0            (eq. 1)
    dv/dt = max(f_t - f_b - r0 - g(s), 0)                 v <= 0 (at rest: brakes and r0 hold it)
    r(v)  = r0 + r1 v + r2 v^2                            (eq. 2, Davis; mass-specific, N/kg)
    F_t   = max(u, 0) min(F_max, P_max / v+)              traction envelope (N)
    f_t   = F_t / (gamma m),  m = m_tare + l m_load        mass-specific tractive effort (N/kg)
    f_b   = max(-u, 0) b_max                              mass-specific brake effort (N/kg)
    g(s)  = g0 (i(s) / 1000 + w_c(s)) / gamma             line term (N/kg): gradient i in per
                                                          mille, curve w_c (Röckl, optional)

The command is a signed fraction of the available effort: ``u = 1`` full traction, ``u = -1``
the maximum deceleration ``b_max``, 0 coasting. ``r0, r1, r2`` are inputs, so another
component (a StepSource, a SignalTable) can make them drift or step during a run; their
start values are the vehicle's Davis coefficients below divided by ``gamma m`` (the paper's
mass-specific form, f = F / (gamma m)). The load factor ``l`` is an input too (start 1:
``m_load`` as the parameter says), held over a run, so that a component (a SensorNoise channel
drawing it uniformly per run) can give each run its own load; the train does not read it during
a step other than through ``m``. ``i(s)`` and the speed limit come from the line
profile (``models/track/line_profile.py``: the CSV and its look-up). An RK4 step that brakes
through ``v = 0`` ends slightly below it; the FMU then sets ``v = 0`` at the communication
point (the train does not roll back on its brakes).

Inputs for a process model (a sigma-point filter propagating its state through this FMU,
``fmus/cosim/process_model.py``; both false by default, and then nothing changes)::

    set_state       true at the start of fmi2DoStep: (s, v) := (s_set, v_set), then integrate
    use_effort_set  true: the applied mass-specific effort f_t - f_b is effort_set (N/kg),
                    held over the step, instead of the command through the envelope

They are inputs, not writes to the states (FMI 2.0 lets an importer set a state only
before initialisation ends). The C is hand-written
(``fmus/native/models/TrainLongitudinal.c``, for the profile look-up); :class:`Train` is its
Python twin.

Vehicle (a six-car double-deck EMU like the VIRM-VI of Cunillera et al. (2022) §4.1)
--------------------------------------------------------------------------------------
==================== =========== ===========================================================
parameter            default     source
==================== =========== ===========================================================
tare_mass            297 t       Stadler KISS six-car double-deck EMU, TTOBench vehicle data
                                 (BSD licence): VIRM-VI masses are not published
load_mass            15.96 t     35 % load (Cunillera et al. (2022) §4.2) of 570 seats at 80
                                 kg: seats and kg per passenger are this project's assumption
rotating_mass_factor 1.06        Cunillera et al. (2022) §4.2 (manufacturer's value)
max_power            2388 kW     VIRM-VI published traction power
max_traction_force   226 kN      P_max / (38 km/h): the transition speed Cunillera et al.
                                 (2022) §4.4 gives from the manufacturer's values (the KISS
                                 has 400 kN at 6000 kW)
max_deceleration     1.0 m/s2    service brake: this project's assumption (the paper gives no
                                 value; its drivers use at most 59 % of it, §4.2)
Davis r0, r1, r2     5.672 kN,   Stadler KISS, TTOBench: 5.672 kN + 0.02545 kN/(km/h) v +
                     ...         0.00121 kN/(km/h)^2 v^2, divided by gamma m (inputs' starts)
==================== =========== ===========================================================
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from railfmu.models.base import Input, Model, Output, Parameter, State
from railfmu.models.track.line_profile import DEFAULT_LINE, G0, LineProfile

TTOBENCH = "Stadler KISS double-deck EMU, TTOBench vehicle data (BSD licence)"
PAPER = "Cunillera et al. (2022)"

TARE_MASS = 297e3  # kg
SEATS, PASSENGER_MASS, LOAD_FRACTION = 570, 80.0, 0.35
LOAD_MASS = LOAD_FRACTION * SEATS * PASSENGER_MASS  # kg
GAMMA = 1.06
MAX_POWER = 2388e3  # W
TRANSITION_SPEED = 38 / 3.6  # m/s
MAX_TRACTION_FORCE = round(MAX_POWER / TRANSITION_SPEED, -3)  # N: 226 kN
MAX_DECELERATION = 1.0  # m/s2
DAVIS_KN = (5.672, 0.02545, 0.00121)  # kN, kN/(km/h), kN/(km/h)^2


def davis_specific(m_eff: float = GAMMA * (TARE_MASS + LOAD_MASS)) -> tuple[float, float, float]:
    """(r0, r1, r2) in N/kg, N/(kg m/s), N/(kg (m/s)^2) from the KISS Davis coefficients."""
    a, b, c = DAVIS_KN
    return 1e3 * a / m_eff, 1e3 * b * 3.6 / m_eff, 1e3 * c * 3.6**2 / m_eff


R0, R1, R2 = davis_specific()


def build() -> Model:
    parameters = [
        Parameter("tare_mass", "Empty train mass m_tare", "kg", TARE_MASS, source=TTOBENCH, positive=True),
        Parameter("load_mass", "Passenger load m_load (35 % of 570 seats x 80 kg)", "kg", LOAD_MASS,
                  source=f"{PAPER} §4.2: 35 % load; seats and 80 kg: assumption", min=0.0),
        Parameter("rotating_mass_factor", "Rotating mass factor gamma", "", GAMMA,
                  source=f"{PAPER} §4.2", positive=True),
        Parameter("max_traction_force", "Maximum tractive force F_max (low speeds)", "N",
                  MAX_TRACTION_FORCE, source=f"P_max / 38 km/h, the transition speed of {PAPER} §4.4",
                  positive=True),
        Parameter("max_power", "Maximum traction power P_max", "W", MAX_POWER,
                  source="VIRM-VI published traction power", positive=True),
        Parameter("max_deceleration", "Brake effort at command -1, b_max (mass-specific)", "m/s2",
                  MAX_DECELERATION, source="service brake: assumption", positive=True),
        Parameter("line_file", "Line profile CSV position_m,gradient_permille,speed_limit_kmh: an "
                  "absolute path or relative to resources/ (line.csv is shipped)", start="line.csv",
                  type="String", source="models/track/line_profile.py"),
    ]
    inputs = [
        Input("command", "Traction/brake command: +1 full traction, 0 coast, -1 maximum brake",
              "", 0.0, min=-1.0, max=1.0),
        Input("load_factor", "Load carried as a fraction of load_mass (1: load_mass; held over a run)",
              "", 1.0, min=0.0, source="choice: 1 keeps the parameter's load"),
        Input("r0", "Davis constant term (mass-specific)", "N/kg", R0, source=TTOBENCH),
        Input("r1", "Davis linear term (mass-specific)", "N.s/(m.kg)", R1, source=TTOBENCH),
        Input("r2", "Davis quadratic term (mass-specific)", "N.s2/(m2.kg)", R2, source=TTOBENCH),
        Input("s_set", "Position the state takes at the start of a step where set_state is true", "m", 0.0),
        Input("v_set", "Speed the state takes at the start of a step where set_state is true", "m/s", 0.0),
        Input("set_state", "True: (s, v) := (s_set, v_set) at the start of each step (a process "
              "model's sigma point)", start=False, type="Boolean"),
        Input("effort_set", "Applied mass-specific effort f_t - f_b where use_effort_set is true",
              "N/kg", 0.0),
        Input("use_effort_set", "True: the applied effort is effort_set, not the command through the "
              "traction envelope and brake", start=False, type="Boolean"),
    ]
    states = [State("s", "Position along the line", "m", 0.0),
              State("v", "Speed", "m/s", 0.0)]
    # feedthrough: the effort reads the command, or effort_set where use_effort_set, and the
    # traction's share of it the mass (load_factor); the line
    # outputs read the position (a state) only; s_set, v_set, set_state act in fmi2DoStep
    effort = ("command", "effort_set", "use_effort_set", "load_factor")
    davis = ("r0", "r1", "r2")
    outputs = [
        Output("acceleration", "dv/dt at the communication point (eq. 1)", "m/s2", depends_on=effort + davis),
        Output("effort", "Applied effort F_t - F_b (traction positive, brake negative)", "N", depends_on=effort),
        Output("effort_specific", "Mass-specific applied effort f_t - f_b", "N/kg", depends_on=effort),
        Output("power", "Applied power (F_t - F_b) v", "W", depends_on=effort),
        Output("resistance_specific", "Running resistance r(v) (eq. 2)", "N/kg", depends_on=davis),
        Output("gradient", "Line gradient at s (positive uphill)", "", depends_on=()),
        Output("gradient_specific", "Line term g(s) = g0 (i / 1000 + w_c) / gamma: gradient and curve", "N/kg", depends_on=()),
        Output("speed_limit", "Line speed limit at s", "m/s", depends_on=()),
        Output("mass", "Train mass m = m_tare + load_factor m_load (the run's load)", "kg",
               depends_on=("load_factor",)),
    ]
    return Model(
        identifier="TrainLongitudinal",
        description="Longitudinal train motion (Cunillera et al. 2022, eqs. 1-2): Davis resistance "
                    "with r0, r1, r2 as inputs, traction envelope, brake, gradient from a line profile",
        parameters=parameters, inputs=inputs, states=states, outputs=outputs,
        integrator_step=0.05,
        default_experiment=(0.0, 1500.0, 1.0),
        c_sources=["LineProfile.h", "TrainLongitudinal.c"],
        c_constants={"MODEL_STEP_BEGIN": 1},  # set_state acts at the start of fmi2DoStep
        resources={"line.csv": DEFAULT_LINE},
        documentation=__doc__,
    )


TRAIN_LONGITUDINAL = build()


# ---- Python twin of TrainLongitudinal.c ------------------------------------------------------
class Train:
    """The FMU's equations and its RK4 (the runtime's: n = ceil(h / integrator_step) equal
    sub-steps), step by step. ``params`` override the model's defaults; ``line_file`` may be a
    path or a :class:`LineProfile`."""

    def __init__(self, params: Mapping[str, float] | None = None, line: LineProfile | Path | str | None = None):
        self.p = {**TRAIN_LONGITUDINAL.default_parameters(), "integrator_step": 0.05, **(params or {})}
        self.line = line if isinstance(line, LineProfile) else LineProfile.read(line or DEFAULT_LINE)
        self.u = {"command": 0.0, "load_factor": 1.0, "r0": R0, "r1": R1, "r2": R2, "s_set": 0.0, "v_set": 0.0,
                  "set_state": False, "effort_set": 0.0, "use_effort_set": False}
        self.s, self.v, self.t = 0.0, 0.0, 0.0

    @property
    def m_eff(self) -> float:
        p = self.p
        return p["rotating_mass_factor"] * self.mass

    @property
    def mass(self) -> float:
        return self.p["tare_mass"] + self.u["load_factor"] * self.p["load_mass"]

    def efforts(self, v: float) -> tuple[float, float]:
        p = self.p
        u = min(max(self.u["command"], -1.0), 1.0)
        vp = v if v > 0 else 0.0
        avail = p["max_traction_force"]
        if vp * avail > p["max_power"]:
            avail = p["max_power"] / vp
        return (u * avail if u > 0 else 0.0), (-u * p["max_deceleration"] if u < 0 else 0.0)

    def grade(self, s: float) -> float:
        k = self.line.row(s)
        return G0 * (float(self.line.gradient[k]) / 1000.0 + float(self.line.curve[k])) / self.p["rotating_mass_factor"]

    def applied(self, v: float) -> float:
        """f_t - f_b (N/kg): ``effort_set`` where ``use_effort_set``, else through the envelope."""
        if self.u["use_effort_set"]:
            return self.u["effort_set"]
        Ft, fb = self.efforts(v)
        return Ft / self.m_eff - fb

    def accel(self, s: float, v: float) -> float:
        e, g, u = self.applied(v), self.grade(s), self.u
        if v > 0:
            return e - (u["r0"] + u["r1"] * v + u["r2"] * v * v) - g
        r = e - u["r0"] - g
        return r if r > 0 else 0.0

    def _f(self, x):
        return [x[1] if x[1] > 0 else 0.0, self.accel(x[0], x[1])]

    def step(self, h: float) -> None:
        q = h / self.p["integrator_step"] - 1e-9
        n = max(int(np.ceil(q)) if q > 0 else 0, 1)
        dt = h / n
        if not self.u["load_factor"] >= 0:
            raise ValueError(f"input load_factor = {self.u['load_factor']:g} must be >= 0")
        if self.u["set_state"]:
            self.s, self.v = float(self.u["s_set"]), float(self.u["v_set"])
        x = [self.s, self.v]
        for _ in range(n):
            k1 = self._f(x)
            k2 = self._f([x[j] + 0.5 * dt * k1[j] for j in range(2)])
            k3 = self._f([x[j] + 0.5 * dt * k2[j] for j in range(2)])
            k4 = self._f([x[j] + dt * k3[j] for j in range(2)])
            x = [x[j] + dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]) for j in range(2)]
        self.s, self.v = x
        if self.v < 0:
            self.v = 0.0
        self.t += h

    def outputs(self) -> dict[str, float]:
        v, m = self.v, self.m_eff
        Ft, fb = self.efforts(v)
        effort, specific = Ft - fb * m, Ft / m - fb
        u = self.u
        if u["use_effort_set"]:
            effort, specific = u["effort_set"] * m, u["effort_set"]
        return {"s": self.s, "v": v, "acceleration": self.accel(self.s, v), "effort": effort,
                "effort_specific": specific, "power": effort * v,
                "resistance_specific": u["r0"] + u["r1"] * v + u["r2"] * v * v,
                "gradient": self.line.gradient_at(self.s), "gradient_specific": self.grade(self.s),
                "speed_limit": self.line.limit_at(self.s), "mass": self.mass}
