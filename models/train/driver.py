r"""Driver: manual driving of one interstation run, as Cunillera et al. (2022) §4 describes it.

Every communication point the driver reads the train's position ``s``, speed ``v`` and the
line's limit at ``s`` (``speed_limit``, from the TrainLongitudinal FMU), decides its mode from
the mode of the previous point, and commands the train (``command``: +1 full traction, 0
coast, -1 maximum brake ``max_deceleration``; the train's input of the same name). It reads
the line profile itself (``line_file``, as the train) to see the lower limits ahead and the
stopping point, the last row's position ``L``.

Modes (Integer output ``mode``) and the true driving regime (Integer output ``regime``; the
codes of the regime recognition: 0 standstill, 1 traction, 2 cruising, 3 coasting, 4 braking)

==== ================ ======= ================================================================
mode name             regime  command / leaves when
==== ================ ======= ================================================================
0    wait             0       0; the first point: accelerate
1    accelerate       1       f q(v) [clip((v* - v) / 5 km/h, 0, 1) if limit < v_c]: gentle start
                              q = clip(0.3 + 0.7 v / 10 km/h, 0, 1), traction reduced to reach
                              the limit v* = min(v_c, limit) (the 40 km/h at the departure);
                              leaves at v >= v_c - 1 km/h where limit >= v_c
2    hold             2       clip((v* - v) / 1 km/h, 0, 1): cruising by holding the speed
3    cycle traction   1       f until v >= v* + 2 km/h                 (traction/coast cycles)
4    cycle coast      3       0 until v <= v* - 5 km/h
5    coast            3       0, from the coasting point s >= s_c on
6    brake for limit  4       -min(b(v) max(rho_lim, 1), b_max) / b_max while rho_lim >= 0.1
7    brake to stop    4       -min(b(v) max(rho_lim, rho_stop), b_max) / b_max until v = 0
8    stopped          0       -b_5 / b_max (held); the FMU ends the simulation ``dwell_time``
                              after the stop (the train stands at the platform: the final
                              brake is followed by a standstill, as a measured run's last fixes)
==== ================ ======= ================================================================

Braking follows the ATB-EG speed steps (> 130, 130-80, 80-60, 60-40, < 40 km/h) with the
style's rate ``b_k`` in each: the distance to brake from ``v`` to ``v_t`` is
``D(v, v_t) = sum_k (min(v, hi_k)^2 - max(v_t, lo_k)^2)^+ / (2 b_k)``; for each lower limit
ahead (row j, ``v > limit_j + 0.05 m/s``) ``rho_j = D(v, limit_j) / (p_j - s - 2 s v)`` (the
limit is reached 2 s before its start: the driver's and a Jacobi master's delay) and for the
stop ``rho_stop = D(v, 0) / (L - s)``. Braking starts where a rho reaches 1 (any non-braking
mode) and the deceleration ``b(v) rho`` follows the curve, so the train reaches each limit at
its start and stops at ``L`` (``rho_stop = v^2 / (2 b_5 (L - s))`` below 40 km/h: the
kinematic stop). Modes 2-4 go to coast at the coasting point. The cruise style (holding or
cycles) comes back after braking for a limit before the coasting point.

Style, drawn per run from ``seed`` (``u_j``: output ``j + 1`` of SplitMix64(seed), the
top 53 bits as a fraction in [0, 1)): cruise target ``v_c = 120 + 20 u_0`` km/h (the paper's
cruise speeds lie mostly near the 140 km/h line speed, Fig. 7); coasting point
``s_c = L - (5000 + 9000 u_1)`` m (final coasts of 2.5-10 min, Fig. 7); traction fraction
``f = 0.7 + 0.3 u_2``; cycles when ``u_3 < 0.5``; brake rates (m/s2) ``0.30 + 0.15 u_4``,
``0.30 + 0.15 u_5`` (> 130, 130-80 km/h), ``0.40 + 0.15 u_6``, ``0.40 + 0.15 u_7`` (80-60,
60-40) and ``0.45 + 0.25 u_8`` (< 40): lower speed steps brake harder and vary more (Fig. 8;
the ranges are this project's choice, the paper gives no numbers). The drawn style is output
(``cruise_target``, ``coasting_point``, ``traction_fraction``, ``cycles``,
``brake_rate_1..5``) as the ground truth of the feature extraction.

Memory: ``mode``, ``mode_before`` and ``decision_time`` are outputs, so a saved FMU state
keeps them; at a communication point the mode is decided from ``mode_before`` (the mode of
the previous point), so a get after a set at the same point decides again, not twice. The C
is hand-written (``fmus/native/models/Driver.c``); :class:`DriverTwin` is its Python twin.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

from railfmu.models.base import Input, Model, Output, Parameter
from railfmu.models.track.line_profile import DEFAULT_LINE, LineProfile
from railfmu.models.train.longitudinal import MAX_DECELERATION

WAIT, ACCELERATE, HOLD, CYCLE_TRACTION, CYCLE_COAST, COAST, BRAKE_LIMIT, BRAKE_STOP, STOPPED = range(9)
REGIME = (0, 1, 2, 1, 3, 3, 4, 4, 0)
REGIME_NAMES = {0: "standstill", 1: "traction", 2: "cruising", 3: "coasting", 4: "braking"}
KMH = 1.0 / 3.6
ANTICIPATION = 2.0  # s: a limit is reached this long before its start (driver's and master's delay)
# traction/coast cycles between v* - 5 and v* + 2 km/h: phases of 20-30 s at 140 km/h, so that a
# 10 s GNSS interval usually holds one regime (this project's choice; the paper gives no band)
CYCLE_BAND_LOW = 5.0 * KMH
DWELL_TOLERANCE = 1e-6  # s: the dwell has elapsed at this point whatever the master's clock arithmetic
STEP_LOW = (130.0 * KMH, 80.0 * KMH, 60.0 * KMH, 40.0 * KMH, 0.0)
GAMMA = 0x9E3779B97F4A7C15
_M64 = (1 << 64) - 1
PAPER = "Cunillera et al. (2022)"


def _mix64(z: int) -> int:
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _M64
    return z ^ (z >> 31)


def uniform(seed: int, j: int) -> float:
    return float(_mix64((seed + (j + 1) * GAMMA) & _M64) >> 11) * 2.0**-53


def build() -> Model:
    parameters = [
        Parameter("seed", "Seed of the driving style", start=1, type="Integer", source="experiment (.ssv)"),
        Parameter("max_deceleration", "The train's b_max (command -1)", "m/s2", MAX_DECELERATION,
                  source="TrainLongitudinal.max_deceleration", positive=True),
        Parameter("dwell_time", "Time the train stands at the stop before the run ends", "s", 30.0,
                  source="this project's choice (a measured run's fixes go on at the platform)", min=0.0),
        Parameter("line_file", "Line profile CSV (as TrainLongitudinal's): an absolute path or "
                  "relative to resources/ (line.csv is shipped)", start="line.csv", type="String",
                  source="models/track/line_profile.py"),
    ]
    inputs = [Input("s", "Train position", "m", 0.0), Input("v", "Train speed", "m/s", 0.0),
              Input("speed_limit", "Line speed limit at s", "m/s", 40.0 * KMH)]
    # the decision reads (s, v, speed_limit); the style and the memory of earlier points do not
    decided = ("s", "v", "speed_limit")
    outputs = [
        Output("command", "Traction/brake command to the train, -1..1", "", depends_on=decided),
        Output("regime", "True driving regime: 0 standstill, 1 traction, 2 cruising, 3 coasting, "
               "4 braking", type="Integer", depends_on=decided),
        Output("mode", "Driver mode 0-8 (models/train/driver.py)", type="Integer", depends_on=decided),
        Output("mode_before", "Mode at the previous communication point (memory)", type="Integer", depends_on=()),
        Output("decision_time", "Communication point at which mode was decided (memory)", "s", depends_on=()),
        Output("cruise_target", "Style: cruise target v_c", "m/s", depends_on=()),
        Output("coasting_point", "Style: coasting point s_c", "m", depends_on=()),
        Output("traction_fraction", "Style: traction fraction f", "", depends_on=()),
        Output("cycles", "Style: cruising by traction/coast cycles (else holding)", type="Boolean", depends_on=()),
        *[Output(f"brake_rate_{k}", f"Style: brake rate in ATB-EG speed step {k} ({band} km/h)", "m/s2", depends_on=())
          for k, band in enumerate(("> 130", "130-80", "80-60", "60-40", "< 40"), 1)],
        Output("stop_position", "Stopping point L: the line profile's last position", "m", depends_on=()),
        Output("stop_time", "Communication point at which the train stopped (memory; 0 before)", "s",
               depends_on=("v",))  # STOPPED follows BRAKE_STOP alone, where only v decides,
    ]
    return Model(
        identifier="Driver",
        description="Manual train driver (Cunillera et al. 2022, §4): gentle start, limits, cruise "
                    "by holding or cycles, coasting point, ATB-EG step braking to stop; style drawn "
                    "from seed; true regime as an Integer",
        parameters=parameters, inputs=inputs, outputs=outputs,
        default_experiment=(0.0, 1500.0, 1.0),
        c_sources=["LineProfile.h", "Driver.c"],
        resources={"line.csv": DEFAULT_LINE},
        documentation=__doc__,
    )


DRIVER = build()


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else (hi if x > hi else x)


class DriverTwin:
    """Python twin of the Driver FMU: :meth:`outputs` at one communication point."""

    def __init__(self, params: Mapping | None = None, line: LineProfile | Path | str | None = None):
        self.p = {**DRIVER.default_parameters(), **(params or {})}
        self.line = line if isinstance(line, LineProfile) else LineProfile.read(line or DEFAULT_LINE)
        seed = int(self.p["seed"]) & _M64
        u = [uniform(seed, j) for j in range(9)]
        L = float(self.line.position[-1])
        self.style = {
            "cruise_target": (120.0 + 20.0 * u[0]) * KMH,
            "coasting_point": L - (5000.0 + 9000.0 * u[1]),
            "traction_fraction": 0.7 + 0.3 * u[2],
            "cycles": u[3] < 0.5,
            "brake_rate_1": 0.30 + 0.15 * u[4], "brake_rate_2": 0.30 + 0.15 * u[5],
            "brake_rate_3": 0.40 + 0.15 * u[6], "brake_rate_4": 0.40 + 0.15 * u[7],
            "brake_rate_5": 0.45 + 0.25 * u[8],
            "stop_position": L,
        }
        self.rates = [self.style[f"brake_rate_{k}"] for k in range(1, 6)]
        self.mode, self.mode_before, self.decision_time = WAIT, WAIT, 0.0
        self.stop_time = 0.0
        self.terminated = False

    def brake_rate_at(self, v: float) -> float:
        for k in range(4):
            if v > STEP_LOW[k]:
                return self.rates[k]
        return self.rates[4]

    def brake_distance(self, v: float, vt: float) -> float:
        d, hi = 0.0, math.inf
        for k in range(5):
            a = v if v < hi else hi
            b = vt if vt > STEP_LOW[k] else STEP_LOW[k]
            if a > b:
                d += (a * a - b * b) / (2.0 * self.rates[k])
            hi = STEP_LOW[k]
        return d

    def braking_need(self, s: float, v: float) -> tuple[float, float]:
        ln = self.line
        if not v > 0:
            return 0.0, 0.0
        lim = 0.0
        for j in range(len(ln.position) - 1):
            pj, vj = float(ln.position[j]), float(ln.limit[j])
            if pj > s and v > vj + 0.05:
                left = pj - s - ANTICIPATION * v
                rho = self.brake_distance(v, vj) / left if left > 0.01 else 1e6
                if rho > lim:
                    lim = rho
        L = float(ln.position[-1])
        return lim, (self.brake_distance(v, 0.0) / (L - s) if L - s > 0.01 else 1e6)

    def _cruise_mode(self) -> int:
        return CYCLE_COAST if self.style["cycles"] else HOLD

    def decide(self, before: int, s: float, v: float, limit: float) -> int:
        st = self.style
        vc = st["cruise_target"]
        target = vc if vc < limit else limit
        past = s >= st["coasting_point"]
        if before == STOPPED:
            return STOPPED
        if before == BRAKE_STOP:
            return BRAKE_STOP if v > 0 else STOPPED
        rl, rs = self.braking_need(s, v)
        if rs >= 1.0:
            return BRAKE_STOP
        if before == BRAKE_LIMIT:
            if rl >= 0.1:  # until the limit is reached
                return BRAKE_LIMIT
            return COAST if past else self._cruise_mode()
        if rl >= 1.0:
            return BRAKE_LIMIT
        if before == WAIT:
            return ACCELERATE
        if before == ACCELERATE:
            if past:
                return COAST
            if v >= vc - 1.0 * KMH and limit >= vc:
                return CYCLE_TRACTION if st["cycles"] else HOLD
            return ACCELERATE
        if before == HOLD:
            return COAST if past else HOLD
        if before == CYCLE_TRACTION:
            if past:
                return COAST
            return CYCLE_COAST if v >= target + 2.0 * KMH else CYCLE_TRACTION
        if before == CYCLE_COAST:
            if past:
                return COAST
            return CYCLE_TRACTION if v <= target - CYCLE_BAND_LOW else CYCLE_COAST
        return COAST

    def command(self, mode: int, s: float, v: float, limit: float) -> float:
        st = self.style
        vc = st["cruise_target"]
        target = vc if vc < limit else limit
        bmax = self.p["max_deceleration"]
        if mode == ACCELERATE:
            gentle = _clip(0.3 + 0.7 * v / (10.0 * KMH), 0.0, 1.0)
            if limit < vc:  # traction reduced to reach a limit below the cruise target
                gentle *= _clip((target - v) / (5.0 * KMH), 0.0, 1.0)
            return st["traction_fraction"] * gentle
        if mode == HOLD:
            return _clip((target - v) / KMH, 0.0, 1.0)
        if mode == CYCLE_TRACTION:
            return st["traction_fraction"]
        if mode in (BRAKE_LIMIT, BRAKE_STOP):
            rl, rs = self.braking_need(s, v)
            if mode == BRAKE_LIMIT and rl < 1.0:  # at least the step's rate
                rl = 1.0
            if mode == BRAKE_STOP and rl < rs:
                rl = rs
            return -_clip(self.brake_rate_at(v) * rl, 0.0, bmax) / bmax
        if mode == STOPPED:
            return -_clip(self.rates[4], 0.0, bmax) / bmax
        return 0.0

    def outputs(self, t: float, s: float, v: float, limit: float) -> dict:
        if t != self.decision_time:
            self.mode_before, self.decision_time = self.mode, t
        mode = self.decide(self.mode_before, s, v, limit)
        self.mode = mode
        if mode == STOPPED and self.mode_before != STOPPED:
            self.stop_time = t
        self.terminated = mode == STOPPED and t - self.stop_time >= self.p["dwell_time"] - DWELL_TOLERANCE
        return {"command": self.command(mode, s, v, limit), "regime": REGIME[mode], "mode": mode,
                "mode_before": self.mode_before, "stop_time": self.stop_time, **self.style}
