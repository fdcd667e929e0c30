r"""Trolley: a survey trolley pushed along a 3-D track (Jiang et al. 2017) and its ideal IMU.

The track is :mod:`railfmu.models.track.geometry` (design alignment on WGS-84 in the start point's
frame n0, ERRI B176 alignment and level irregularities, optional wobble); this FMU moves a
rigid body along it and outputs, every communication step, the **ideal IMU increments** and
the true navigation state. The C is hand-written (``fmus/native/models/Trolley.c`` with
``TrackGeometry.h`` and ``Earth.h``); :class:`TrolleyTwin` is its Python twin.

Speed profile
-------------
At rest for ``static_duration`` (the INS alignment), then stop-and-go: stops at
``s = stop_spacing, 2 stop_spacing, ...`` and at the track's end, each for
``stop_duration``; after the last stop the trolley stays there. Each run between stops
accelerates to ``speed`` (m/s), cruises and brakes with the smooth ramp ::

    a(tau) = (2 v / T) sin^2(pi tau / T),   T = 2 v / acceleration,   0 <= tau <= T

(peak ``acceleration``; jerk finite, the specific force continuous), braking the mirror
image; a run shorter than ``2 v^2 / acceleration`` peaks at ``sqrt(D acceleration / 2)``.
``s(t)`` and its derivatives are closed forms. Defaults: 600 m with stops every 60 m at
1 m/s (Jiang et al. (2017), §5), 0.5 m/s2 peak, 5 s stops, 10 s initial rest: 700 s.

Body and kinematics
-------------------
The body point is the rail centre line point plus the wobble, ``r(s) = p_rail(s) + w_y Y +
w_z D`` (lateral along the horizontal normal Y, vertical along the n0 vertical D, as the
irregularities); the body axes are x along the true rail tangent ``q = dp_rail/ds`` (heading
``psi = atan2(q_E, q_N)``, pitch ``theta = atan2(-q_D, |q_NE|)`` in n0) and rolled by the
cant, ``phi = asin(c / 1.5 m)``: ``C_b^n0 = R3(psi) R2(theta) R1(phi)``, built from the
direction cosines of ``q`` (no trigonometry per node). The wobble moves the
body off the rail without turning it, so the body velocity has lateral and vertical
components: the non-holonomic constraint is broken on purpose (default amplitude 0).

With ``s(t)`` from the speed profile, in the Earth-fixed frame n0 (``Omega`` = Earth rate
in n0, ``r' = dr/ds``)::

    v = r' s_dot,        a = r'' s_dot^2 + r' s_ddot
    omega_ib^b = E(phi, theta) (phi', theta', psi') s_dot + C_n0^b Omega     (n0 is Earth-fixed)
    f^b        = C_n0^b (a + 2 Omega x v - g^n0)

``E`` the ZYX Euler-rate matrix and ``g`` normal gravity (``railfmu.models.earth``: Somigliana,
gravitation plus centrifugal) at the body point: ``g^n = gamma(L, h) (0, 0, 1)`` in the local
NED. At a quadrature node ``g`` is evaluated from the step's end point by first-order
expansion in the node's displacement ``d`` (millimetres; second-order terms are
``|d|^2 / R`` ~ 1e-12 m): ``g^n ~= (gamma + gamma_L dL + gamma_h dh) (-d_N / (R_N + h),
-d_E / (R_E + h), 1)``, ``d`` from the Hermite-corrected trapezoid of ``r'`` (error
``|ds|^5 r^(5) / 720``).

Increments
----------
``dtheta = int omega_ib^b dt`` and ``dv = int f^b dt`` over the interval from the previous
communication point to this one, by 3-point Gauss-Legendre quadrature on panels of at most
10 ms (error ``5e-7 h^7 max|f^(6)|``: 1e-20 m/s for the 2 m shortest irregularity
wavelength at 1 m/s; 4e-13 m/s for a 2 mm wobble at 0.5 m and 2 m/s, 25 rad/s), split at every instant where the integrand is not smooth: the speed profile's phase
ends, and the times the trolley passes the alignment's element ends (where the curvature
rate, the cant rate or the vertical curvature jump, or with ``bloss`` transitions their
derivatives) and the rows of a measured irregularity
table (found once, by bisection of the closed-form ``s(t)``). The interval is the one the importer
actually stepped: the FMU remembers the previous communication point (``interval_start``)
and integrates up to the current one, so ``t = n h`` and ``t += h`` masters both get
increments that tile their own time grid; the truth is a function of the time alone.
``dtheta``, ``dv`` are integrals, not rotation vectors: an INS applies its own coning and
sculling corrections. At the initialisation point they are 0.

Outputs (at the communication point ``t``)
------------------------------------------
``latitude, longitude`` (rad), ``height`` (m) of the body point; ``north, east, down`` its
n0 position from the design start point (the n0 origin; at ``t = 0`` the trolley sits the
irregularity offset, millimetres, away from it); ``vn, ve, vd`` velocity in the local NED;
``roll, pitch, heading`` (rad) of ``C_b^n`` in the local NED (``heading`` in
``(-pi, pi]``); ``distance`` = ``s`` (design arc length, m); ``speed_along`` = ``s_dot``;
``stopped`` true in the rest phases (a phase end within 1 % of the step counts as reached,
as ``railfmu.models.base.STEP_TOLERANCE``); ``path_length`` the length of the true rail path
travelled (m, the same quadrature) and ``odometer = (1 + odometer_scale_ppm 1e-6)
path_length``. ``interval_start`` and ``path_start`` are the memory of the previous
communication point (outputs, so a saved FMU state keeps them).
"""

from __future__ import annotations

import bisect
import math
from pathlib import Path
from typing import Mapping

from railfmu.models.base import Model, Output, Parameter
from railfmu.models.base import STEP_TOLERANCE
from railfmu.models import earth
from railfmu.models.track import geometry as track_geometry
from railfmu.models.track.geometry import (
    DEFAULT_IRREGULARITY,
    DEFAULT_PLACEMENT,
    DEFAULT_TRACK,
    Alignment,
    TrackGeometry,
    ecef_to_lla,
)

PAPER = "Jiang et al. (2017)"
REST, ACCELERATE, CRUISE, BRAKE = 0, 1, 2, 3
MAX_STOPS = 1e6  # stops of the speed profile; the C has the same limit
#: longest quadrature panel (s) and the 3-point Gauss-Legendre rule on [-1, 1] (nodes in the
#: order the C visits them)
MAX_PANEL = 0.01
GL3 = ((-0.7745966692414834, 0.5555555555555556), (0.0, 0.8888888888888888),
       (0.7745966692414834, 0.5555555555555556))


def _ramp(tau: float, v: float, T: float):
    """Accelerating ramp: distance, speed, acceleration at tau in [0, T]."""
    x = math.pi * tau / T
    sx = math.sin(x)
    s = v * (0.5 * tau * tau / T - T * sx * sx / (2.0 * math.pi * math.pi))
    sd = v * (tau / T - math.sin(2.0 * x) / (2.0 * math.pi))
    sdd = 2.0 * v / T * sx * sx
    return s, sd, sdd


class SpeedProfile:
    """Stop-and-go distance ``s(t)``: phases ``(t0, kind, s0, v, T)`` (see the module doc)."""

    def __init__(self, length: float, speed: float, acceleration: float, stop_spacing: float,
                 stop_duration: float, static_duration: float):
        self.t0, self.kind, self.s0, self.v, self.T = [0.0], [REST], [0.0], [0.0], [0.0]
        t, s = static_duration, 0.0
        self.stops = []
        if length / stop_spacing > MAX_STOPS:  # 5e-324 m: s + D == s, a loop without end
            from railfmu.models.errors import UserError

            raise UserError(f"Trolley: parameter stop_spacing = {stop_spacing:g} m gives more than {MAX_STOPS:g} "
                            f"stops on the {length:g} m track")
        while s < length:
            D = min(stop_spacing, length - s)
            if length - (s + D) < 1e-9 * length:
                D = length - s
            v = min(speed, math.sqrt(0.5 * D * acceleration))
            T = 2.0 * v / acceleration
            cruise = D / v - T
            self._add(t, ACCELERATE, s, v, T)
            t += T
            if cruise > 0:
                self._add(t, CRUISE, s + 0.5 * v * T, v, cruise)
                t += cruise
            self._add(t, BRAKE, s + D, v, T)  # s0 = the stop's distance
            t += T
            s += D
            self.stops.append(s)
            self._add(t, REST, s, 0.0, stop_duration)
            t += stop_duration
        self.end_time = t

    def _add(self, t0, kind, s0, v, T):
        self.t0.append(t0), self.kind.append(kind), self.s0.append(s0), self.v.append(v), self.T.append(T)

    def phase(self, t: float) -> int:
        return max(bisect.bisect_right(self.t0, t) - 1, 0)

    def __call__(self, t: float):
        """s, s_dot, s_ddot at t."""
        k = self.phase(t)
        kind, s0, v, T = self.kind[k], self.s0[k], self.v[k], self.T[k]
        tau = t - self.t0[k]
        if kind == REST:
            return s0, 0.0, 0.0
        if kind == CRUISE:
            return s0 + v * tau, v, 0.0
        if kind == ACCELERATE:
            if tau > T:
                tau = T
            ds, sd, sdd = _ramp(tau, v, T)
            return s0 + ds, sd, sdd
        tau = T - tau if tau < T else 0.0
        ds, sd, sdd = _ramp(tau, v, T)
        return s0 - ds, sd, -sdd

    def stopped(self, t: float, tol: float) -> bool:
        k = self.phase(t)
        if self.kind[k] == REST:
            return True
        if k + 1 < len(self.t0) and self.kind[k + 1] == REST and self.t0[k + 1] - t <= tol:
            return True
        return self.kind[k - 1] == REST and t - self.t0[k] <= tol

    def time_at(self, s: float) -> float | None:
        """The time the trolley passes ``s`` while moving (None at a stop's distance)."""
        for k in range(1, len(self.t0)):
            kind, s0, v, T = self.kind[k], self.s0[k], self.v[k], self.T[k]
            if kind == REST:
                if s == s0:
                    return None
                continue
            if kind == CRUISE:
                if s0 < s < s0 + v * T:
                    return self.t0[k] + (s - s0) / v
                continue
            half = 0.5 * v * T
            if kind == ACCELERATE and s0 < s < s0 + half:
                lo, hi = 0.0, T
                for _ in range(100):  # bisection to the last bit: init only
                    mid = 0.5 * (lo + hi)
                    if s0 + _ramp(mid, v, T)[0] < s:
                        lo = mid
                    else:
                        hi = mid
                return self.t0[k] + 0.5 * (lo + hi)
            if kind == BRAKE and s0 - half < s < s0:
                lo, hi = 0.0, T
                for _ in range(100):
                    mid = 0.5 * (lo + hi)
                    if s0 - _ramp(T - mid, v, T)[0] < s:
                        lo = mid
                    else:
                        hi = mid
                return self.t0[k] + 0.5 * (lo + hi)
        return None


def _rot_zyx(g):
    """C_b^n0 = R3(psi) R2(theta) R1(phi), row-major, from the point's cosines and sines."""
    cp, sp_, ct, st, cf, sf = g.cpsi, g.spsi, g.cth, g.sth, g.cphi, g.sphi
    return [[cp * ct, cp * st * sf - sp_ * cf, cp * st * cf + sp_ * sf],
            [sp_ * ct, sp_ * st * sf + cp * cf, sp_ * st * cf - cp * sf],
            [-st, ct * sf, ct * cf]]


def _mt(C, v):
    return [C[0][i] * v[0] + C[1][i] * v[1] + C[2][i] * v[2] for i in range(3)]


def _m(C, v):
    return [C[i][0] * v[0] + C[i][1] * v[1] + C[i][2] * v[2] for i in range(3)]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


class TrolleyTwin:
    """Python twin of the Trolley FMU: :meth:`outputs` at the end of an interval."""

    def __init__(self, params: Mapping | None = None, track_file: str | Path | None = None,
                 base_dir: str | Path | None = None):
        """``track_file`` defaults to the shipped table; a relative ``irregularity_file`` is
        read from ``base_dir`` (the FMU reads it from its resources/)."""
        self.p = {**TROLLEY.default_parameters(), **(params or {})}
        p = self.p
        check_trolley_parameters(p)
        self.track = TrackGeometry({k: p[k] for k in (*DEFAULT_PLACEMENT, *DEFAULT_IRREGULARITY)},
                                   Alignment.read(track_file or DEFAULT_TRACK), base_dir)
        self.profile = SpeedProfile(self.track.length, p["speed"], p["acceleration"], p["stop_spacing"],
                                    p["stop_duration"], p["static_duration"])
        splits = set(self.profile.t0[1:])
        for b in self.track.kinks:
            t = self.profile.time_at(b)
            if t is not None:
                splits.add(t)
        self.splits = sorted(splits)
        self.interval_start, self.interval_end = 0.0, 0.0
        self.path_start, self.path_length = 0.0, 0.0

    # -- one node --
    def _node(self, t, end, C_n_n0):
        """omega_ib^b, f^b and d(path)/dt at time t; ``end`` the end point's (s, r1, r2,
        gamma, gamma_L, gamma_h, R_N + h, R_E + h)."""
        s, sd, sdd = self.profile(t)
        g = self.track.point(s)
        om = self.track.omega_n0
        v = [g.r1[i] * sd for i in range(3)]
        a = [g.r2[i] * sd * sd + g.r1[i] * sdd for i in range(3)]
        se, r1e, r2e, gam, gam_l, gam_h, rn, re = end
        D = se - s
        d = [-(0.5 * D * (g.r1[i] + r1e[i]) + D * D / 12.0 * (g.r2[i] - r2e[i])) for i in range(3)]
        dn = _m(C_n_n0, d)  # C_n0^n d: in the end point's NED
        gn = gam + gam_l * dn[0] / rn - gam_h * dn[2]
        g_ned = [-gn * dn[0] / rn, -gn * dn[1] / re, gn]
        g_n0 = _mt(C_n_n0, g_ned)
        cor = _cross(om, v)
        f_n0 = [a[i] + 2.0 * cor[i] - g_n0[i] for i in range(3)]
        C = _rot_zyx(g)
        f_b = _mt(C, f_n0)
        sf, cf, st, ct = g.sphi, g.cphi, g.sth, g.cth
        dphi, dth, dpsi = g.dphi * sd, g.dtheta * sd, g.dpsi * sd
        w_e = _mt(C, om)
        w_b = [dphi - dpsi * st + w_e[0], dth * cf + dpsi * ct * sf + w_e[1],
               -dth * sf + dpsi * ct * cf + w_e[2]]
        path = math.sqrt(g.q[0] ** 2 + g.q[1] ** 2 + g.q[2] ** 2) * sd
        return w_b, f_b, path

    def end_state(self, t: float):
        """The truth at t: dict of outputs (no increments) and what the nodes need."""
        tr = self.track
        s, sd, _ = self.profile(t)
        g = tr.point(s, position=True)
        re_ = [tr.r0e[i] + tr.C_e_n0[0][i] * g.r[0] + tr.C_e_n0[1][i] * g.r[1] + tr.C_e_n0[2][i] * g.r[2]
               for i in range(3)]
        lat, lon, h = ecef_to_lla(*re_)
        C_e_n = earth.ecef_to_ned_matrix(lat, lon).tolist()
        # C_n0^n = C_e^n C_n0^e = C_e^n (C_e^n0)^T
        C_n_n0 = [[sum(C_e_n[i][k] * tr.C_e_n0[j][k] for k in range(3)) for j in range(3)] for i in range(3)]
        v_n = _m(C_n_n0, [g.r1[i] * sd for i in range(3)])
        Cb0 = _rot_zyx(g)
        Cbn = [[sum(C_n_n0[i][k] * Cb0[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
        sl, cl = math.sin(lat), math.cos(lat)
        x = 1.0 - earth.E2 * sl * sl
        RE = earth.A / math.sqrt(x)
        RN = RE * (1.0 - earth.E2) / x
        k = earth.K_SOMIGLIANA
        g0 = earth.GE * (1.0 + k * sl * sl) / math.sqrt(x)
        fh = 1.0 - 2.0 * h / earth.A
        # d gamma / d L of Somigliana's formula (the gravity's change over a step's nodes)
        g0_l = earth.GE * sl * cl * (2.0 * k * x + (1.0 + k * sl * sl) * earth.E2) / (x * math.sqrt(x))
        out = {"latitude": lat, "longitude": lon, "height": h,
               "north": g.r[0], "east": g.r[1], "down": g.r[2],
               "vn": v_n[0], "ve": v_n[1], "vd": v_n[2],
               "roll": math.atan2(Cbn[2][1], Cbn[2][2]),
               "pitch": math.asin(max(-1.0, min(1.0, -Cbn[2][0]))),
               "heading": math.atan2(Cbn[1][0], Cbn[0][0]),
               "distance": s, "speed_along": sd}
        end = (s, g.r1, g.r2, g0 * fh, g0_l * fh, -2.0 * g0 / earth.A, RN + h, RE + h)
        return out, end, C_n_n0

    def increments(self, ta: float, tb: float, end, C_n_n0):
        dth, dv, path = [0.0] * 3, [0.0] * 3, 0.0
        i = bisect.bisect_right(self.splits, ta)
        cuts = [ta]
        while i < len(self.splits) and self.splits[i] < tb:
            cuts.append(self.splits[i])
            i += 1
        cuts.append(tb)
        for a, b in zip(cuts[:-1], cuts[1:]):
            n = max(1, math.ceil((b - a) / MAX_PANEL - 1e-9))
            hp = (b - a) / n
            for j in range(n):
                m = a + (j + 0.5) * hp
                for x, w in GL3:
                    wb, fb, pr = self._node(m + 0.5 * hp * x, end, C_n_n0)
                    wq = 0.5 * hp * w
                    for k in range(3):
                        dth[k] += wq * wb[k]
                        dv[k] += wq * fb[k]
                    path += wq * pr
        return dth, dv, path

    def outputs_over(self, ta: float, tb: float, h: float = 0.0) -> dict:
        """The outputs at ``tb`` with the increments over ``[ta, tb]`` (``path_length`` is the
        path travelled over it), without touching the memory."""
        out, end, C = self.end_state(tb)
        if tb > ta:
            dth, dv, path = self.increments(ta, tb, end, C)
        else:
            dth, dv, path = [0.0] * 3, [0.0] * 3, 0.0
        out.update({"dtheta_x": dth[0], "dtheta_y": dth[1], "dtheta_z": dth[2],
                    "dv_x": dv[0], "dv_y": dv[1], "dv_z": dv[2],
                    "stopped": self.profile.stopped(tb, STEP_TOLERANCE * h), "path_length": path,
                    "odometer": (1.0 + 1e-6 * self.p["odometer_scale_ppm"]) * path,
                    "interval_start": ta, "path_start": 0.0})
        return out

    def outputs(self, t: float, h: float = 0.0) -> dict:
        """The FMU's outputs at communication point ``t`` reached by a step ``h`` (0:
        initialisation). Calls must follow the importer's points in order (repeating one
        recomputes it)."""
        if t != self.interval_end:
            self.interval_start, self.interval_end = self.interval_end, t
            self.path_start = self.path_length
        out = self.outputs_over(self.interval_start, t, h)
        self.path_length = self.path_start + out["path_length"]
        out.update({"path_length": self.path_length,
                    "odometer": (1.0 + 1e-6 * self.p["odometer_scale_ppm"]) * self.path_length,
                    "path_start": self.path_start})
        return out

    def start(self, t0: float = 0.0) -> dict:
        """Initialisation at t0 (the FMU's start time)."""
        self.interval_start = self.interval_end = t0
        self.path_start = self.path_length = 0.0
        return self.outputs(t0, 0.0)


def check_trolley_parameters(p: Mapping) -> None:
    from railfmu.models.errors import UserError

    def need(ok, name, rule):
        if not ok:
            raise UserError(f"Trolley: parameter {name} = {p[name]} {rule}")
    need(p["speed"] > 0 and p["speed"] < 50, "speed", "must be in (0, 50) m/s")
    need(p["acceleration"] > 0 and math.isfinite(p["acceleration"]), "acceleration", "must be > 0 m/s2")
    need(p["stop_spacing"] > 0 and math.isfinite(p["stop_spacing"]), "stop_spacing", "must be > 0 m")
    need(p["stop_duration"] >= 0 and math.isfinite(p["stop_duration"]), "stop_duration", "must be >= 0 s")
    need(p["static_duration"] >= 0 and math.isfinite(p["static_duration"]), "static_duration", "must be >= 0 s")
    need(abs(p["odometer_scale_ppm"]) < 1e5, "odometer_scale_ppm", "must be below 1e5 in size")


def build() -> Model:
    deg = math.degrees
    parameters = [
        Parameter("track_file", "Track element table CSV (models/track/geometry.py): an absolute path or "
                  "relative to resources/ (shipped: trolley_track.csv, 600 m, two curves, grades; "
                  "trolley_straight_30m.csv, 30 m straight)",
                  start="trolley_track.csv", type="String", source="models/track/geometry.py"),
        Parameter("start_latitude", f"Latitude of the design start point, the n0 origin "
                  f"({deg(DEFAULT_PLACEMENT['start_latitude']):g} deg)", "rad",
                  DEFAULT_PLACEMENT["start_latitude"], source=f"choice: near Wuhan ({PAPER})"),
        Parameter("start_longitude", f"Longitude of the design start point "
                  f"({deg(DEFAULT_PLACEMENT['start_longitude']):g} deg)", "rad",
                  DEFAULT_PLACEMENT["start_longitude"], source=f"choice: near Wuhan ({PAPER})"),
        Parameter("start_height", "Ellipsoidal height of the design start point", "m",
                  DEFAULT_PLACEMENT["start_height"], source="choice"),
        Parameter("azimuth", "Heading of the first element, clockwise from north (45 deg)", "rad",
                  DEFAULT_PLACEMENT["azimuth"], source=f"{PAPER}, §5: N45°E"),
        Parameter("irregularity_level", "ERRI B176 spectrum of alignment and level: 0 none, 1 low, 2 high",
                  start=1, type="Integer", source="ERRI B176 (models/track/irregularity.py)"),
        Parameter("irregularity_scale", "Factor on the irregularity amplitudes", "", 1.0, source="choice"),
        Parameter("irregularity_lines", "Sinusoids per irregularity channel (log-spaced wavelengths)",
                  start=32, type="Integer", source="choice: a few µs per step"),
        Parameter("lambda_min", "Shortest irregularity wavelength", "m", 2.0,
                  source="choice: below the 5 m chord offset"),
        Parameter("lambda_max", "Longest irregularity wavelength", "m", 120.0,
                  source="choice: four 30 m chords"),
        Parameter("irregularity_seed", "Seed of the SplitMix64 phases", start=1, type="Integer",
                  source="experiment (.ssv)"),
        Parameter("harmonic_lateral_amplitude", "Harmonic alignment A sin(2 pi s / lambda)", "m", 0.0,
                  source="choice"),
        Parameter("harmonic_vertical_amplitude", "Harmonic level A sin(2 pi s / lambda)", "m", 0.0,
                  source="choice"),
        Parameter("harmonic_wavelength", "Wavelength of the harmonic irregularity", "m", 20.0,
                  source="choice"),
        Parameter("irregularity_file", "Measured alignment/level table added to the spectrum: CSV "
                  "s,alignment,vertical_left,vertical_right (m; as TrackIrregularity's profile_file), "
                  "covering the track; absolute or relative to resources/; none when empty",
                  start="", type="String", source="models/track/geometry.py"),
        Parameter("wobble_lateral", "Lateral wobble of the body off the rail (wheel-rail play)", "m", 0.0,
                  source="choice: 0 keeps the non-holonomic constraint exact"),
        Parameter("wobble_vertical", "Vertical wobble of the body off the rail", "m", 0.0, source="choice"),
        Parameter("wobble_wavelength", "Wavelength of the wobble", "m", 2.0, source="choice"),
        Parameter("speed", "Cruise speed", "m/s", 1.0, source=f"{PAPER}, §5 (walking speed)"),
        Parameter("acceleration", "Peak acceleration and deceleration of the smooth ramps", "m/s2", 0.5,
                  source="choice (pushed by hand)"),
        Parameter("stop_spacing", "Distance between stops", "m", 60.0, source=f"{PAPER}, §5 (ZUPT every 60 m)"),
        Parameter("stop_duration", "Duration of each stop", "s", 5.0, source="choice"),
        Parameter("static_duration", "Initial rest (INS alignment)", "s", 10.0, source="choice"),
        Parameter("odometer_scale_ppm", "Odometer scale-factor error", "", 0.0, source="choice"),
    ]
    outputs = [
        *[Output(f"dtheta_{a}", f"Angle increment about body {a}: integral of omega_ib^b over the last step",
                 "rad") for a in "xyz"],
        *[Output(f"dv_{a}", f"Velocity increment along body {a}: integral of the specific force f^b",
                 "m/s") for a in "xyz"],
        Output("latitude", "Latitude of the body point", "rad"),
        Output("longitude", "Longitude of the body point", "rad"),
        Output("height", "Ellipsoidal height of the body point", "m"),
        Output("north", "North of the body point from the design start, frame n0", "m"),
        Output("east", "East of the body point from the design start, frame n0", "m"),
        Output("down", "Down of the body point from the design start, frame n0", "m"),
        Output("vn", "Velocity north (local NED)", "m/s"),
        Output("ve", "Velocity east (local NED)", "m/s"),
        Output("vd", "Velocity down (local NED)", "m/s"),
        Output("roll", "Roll of the body in the local NED", "rad"),
        Output("pitch", "Pitch of the body in the local NED", "rad"),
        Output("heading", "Heading of the body in the local NED, (-pi, pi]", "rad"),
        Output("distance", "Distance along the design track (3-D arc length)", "m"),
        Output("speed_along", "Speed along the design track, d distance / dt", "m/s"),
        Output("stopped", "True while the trolley rests (initial rest and the stops)", type="Boolean"),
        Output("path_length", "Length of the true rail path travelled", "m"),
        Output("odometer", "Odometer: (1 + odometer_scale_ppm 1e-6) path_length", "m"),
        Output("interval_start", "Previous communication point: the increments cover interval_start..t "
               "(memory)", "s"),
        Output("path_start", "path_length at interval_start (memory)", "m"),
    ]
    return Model(
        identifier="Trolley",
        description="Survey trolley pushed along a 3-D track on WGS-84 (Jiang et al. 2017): stop-and-go "
                    "speed profile, rigid body on the rail with cant and optional wobble; ideal IMU "
                    "increments by exact quadrature and the true navigation state",
        parameters=parameters, outputs=outputs,
        default_experiment=(0.0, 700.0, 0.005),
        c_sources=["Earth.h", "TrackGeometry.h", "Trolley.c"],
        resources={"trolley_track.csv": DEFAULT_TRACK,
                   # Jiang et al. (2017), §5's simulation: 30 m straight (experiments/trolley_survey paper_montecarlo)
                   "trolley_straight_30m.csv": DEFAULT_TRACK.parent / "trolley_straight_30m.csv"},
        documentation=__doc__ + "\n\n" + track_geometry.__doc__,
    )


TROLLEY = build()
