"""Interstation runs of the Driver, TrainLongitudinal and GnssReceiver twins (``models/``), for
the tests of the driving-regime recognition and the feature extraction (Cunillera et al.
(2022) §3.2-3.3); the experiments run the FMUs.

The twins are coupled as the Jacobi master couples the FMUs (``tests/test_driver.py``): at
``t_k`` the driver decides on the train's outputs of ``t_(k-1)`` and its command is held over
``[t_k, t_k + h]``; so the driver's ``regime[k]`` is the regime of that step.

:func:`sample` turns a run into what a regime recogniser sees every GNSS period ``T``: per
fix ``j`` the speed, the acceleration and the applied effort *of the interval*
``(t_(j-1), t_j]`` — the effort an estimator uses to predict from one fix to the next.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from railfmu.models.train.driver import DriverTwin
from railfmu.models.train.gnss import Gnss
from railfmu.models.track.line_profile import DEFAULT_LINE, LineProfile
from railfmu.models.train.longitudinal import Train

_LINE = LineProfile.read(DEFAULT_LINE)


@dataclass
class TwinRun:
    """A run on the driver's grid ``time`` (step ``h``). ``effort[k]`` is the mean applied
    mass-specific effort f_t - f_b (N/kg) over ``[t_k, t_k + h]`` (trapezoid of the held
    command's effort at both ends), ``regime[k]`` the driver's regime of that step, ``drag[k]``
    = r(v) + g(s) at ``t_k`` (N/kg), ``s``, ``v`` the train's states at ``t_k``."""

    time: np.ndarray
    s: np.ndarray
    v: np.ndarray
    effort: np.ndarray
    drag: np.ndarray
    regime: np.ndarray
    style: dict
    train: dict = field(default_factory=dict)  # m_eff (kg), max_power (W), max_traction_force (N)

    @property
    def h(self) -> float:
        return float(self.time[1] - self.time[0])


def simulate(seed: int, h: float = 1.0, stop_time: float = 3000.0, dwell: float = 30.0) -> TwinRun:
    """The run of the driver drawn from ``seed``, on to ``dwell`` s after the stop (the FMU
    ends there; a GNSS fix after the stop shows the final brake)."""
    train, driver = Train(line=_LINE), DriverTwin({"seed": seed}, line=_LINE)
    prev, t, end = train.outputs(), 0.0, stop_time
    rows = []
    while t <= end:
        out = train.outputs()
        d = driver.outputs(t, prev["s"], prev["v"], prev["speed_limit"])
        train.u["command"] = d["command"]
        f0 = _applied(train, out["v"])
        drag = out["resistance_specific"] + out["gradient_specific"]
        if driver.terminated and end == stop_time:
            end = min(t + dwell, stop_time)
        train.step(h)
        f1 = _applied(train, train.v)
        rows.append((t, out["s"], out["v"], 0.5 * (f0 + f1), drag, d["regime"]))
        prev, t = out, t + h
    a = np.array(rows)
    p = train.p
    return TwinRun(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], a[:, 5].astype(int), dict(driver.style),
                   {"m_eff": train.m_eff, "max_power": p["max_power"],
                    "max_traction_force": p["max_traction_force"]})


def _applied(train: Train, v: float) -> float:
    """f_t - f_b (N/kg) at speed v with the train's held command."""
    Ft, fb = train.efforts(v)
    return Ft / train.m_eff - fb


def sample(run: TwinRun, period: float = 10.0, gnss: dict | None = None) -> dict:
    """Every ``period`` s (a whole number of driver steps), per fix ``j`` the interval
    ``(t_(j-1), t_j]`` (fix 0: zero acceleration and effort, the train at rest):

    * exact (``gnss=None``): ``speed`` v(t_j); ``acceleration`` (v_j - v_(j-1)) / T;
      ``effort`` the mean applied effort over the interval;
    * measured (``gnss`` the GnssReceiver's parameters, e.g. ``{"seed": 3}``): the receiver's
      speed (rounded to 1 km/h) and position (4 m noise); ``acceleration`` the finite
      difference of the measured speeds; ``effort`` = acceleration + r(v_mid) + g(s_j) with the
      true Davis coefficients (what an estimator that has converged would compute).
    """
    n = round(period / run.h)
    idx = np.arange(0, len(run.time), n)
    t, v = run.time[idx], run.v[idx]
    out = {"time": t, "true_speed": v, "position": run.s[idx]}
    if gnss is None:
        acc = np.r_[0.0, np.diff(v) / period]
        eff = np.r_[0.0, [run.effort[i - n:i].mean() for i in idx[1:]]]
        out.update(speed=v, acceleration=acc, effort=eff)
        return out
    rx = Gnss(gnss)
    fixes = [rx.outputs(float(tj), 0.0 if j == 0 else period, float(run.s[i]), float(run.v[i]))
             for j, (tj, i) in enumerate(zip(t, idx))]
    vm = np.array([f["speed"] for f in fixes])
    sm = np.array([f["position"] for f in fixes])
    acc = np.r_[0.0, np.diff(vm) / period]
    train = Train(line=_LINE)
    u = train.u
    vmid = np.r_[vm[0], 0.5 * (vm[1:] + vm[:-1])]
    r = np.where(vmid > 0, u["r0"] + u["r1"] * vmid + u["r2"] * vmid**2, 0.0)
    g = np.array([train.grade(x) for x in sm])
    eff = np.r_[0.0, (acc + r + g)[1:]]
    out.update(speed=vm, position=sm, acceleration=acc, effort=eff)
    return out
