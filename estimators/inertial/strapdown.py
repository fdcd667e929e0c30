r"""Strapdown inertial navigation from IMU increments, in NED on WGS-84.

Input per IMU interval ``k`` (from ``t_{k-1}`` to ``t_k = t_{k-1} + h``): the increments
``a_k = int omega_ib^b dt`` (rad) and ``u_k = int f^b dt`` (m/s) in the body frame
(forward-right-down). State: latitude ``L``, longitude ``lambda`` (rad), height ``h_e`` (m),
velocity ``v^n`` (NED, m/s), attitude ``C_b^n`` (held as a unit quaternion). The Earth is
:mod:`railfmu.models.earth`.

Mechanisation: Savage (1998, J. Guid. Control Dyn. 21(1) pp. 19-28 and 21(2) pp. 208-221),
single-speed form at the IMU rate, the coning and sculling terms from the previous interval's
increments (exact for angular rate and specific force linear in time)::

    phi_k   = a_k + (a_{k-1} x a_k) / 12                                  coning
    dv_k^b  = u_k + (1/2 - |a_k|^2 / 24) a_k x u_k + a_k x (a_k x u_k) / 6    rotation
                  + (a_{k-1} x u_k + u_{k-1} x a_k) / 12                  sculling
    (mid-interval values, subscript m: latitude extrapolated from the last two, velocity and
     height predicted with this interval's increments)
    omega_in^n = omega_ie^n(L_m) + omega_en^n(L_m, h_m, v_m)              Earth + transport rate
    zeta_k  = omega_in^n h                                                n-frame rotation
    dv_sf^n = (I - [zeta_k x] / 2 + [zeta_k x]^2 / 6) C_b^n(k-1) dv_k^b   specific force in n(k)
    v_k     = v_{k-1} + dv_sf^n + (g^n(L_m, h_m) - (2 omega_ie^n + omega_en^n) x v_m) h
                                                            normal gravity, Coriolis
    h_k     = h_{k-1} - (v_D,k-1 + v_D,k) h / 2                           trapezoidal
    L_k     = L_{k-1} + (v_N,k-1 + v_N,k) h / (2 (R_N(L_m) + h_m))
    lambda_k = lambda_{k-1} + (v_E,k-1 + v_E,k) h / (2 (R_E(L_m) + h_m) cos L_m)
    C_b^n(k) = exp(-[zeta_k x]) C_b^n(k-1) exp([phi_k x])                 attitude

The rotation terms are the series of ``int_0^h exp([omega t x]) dt`` (Savage keeps the first):
the second-order one is needed, not a refinement: a body rocking in roll at 5e-4 rad/s in
gravity rectifies ``|a|^2 g h / 6`` into the vertical velocity, 8e-9 m/s in 300 s at 100 Hz
without it. Likewise for the n-frame's rotation ``zeta_k`` (Earth rate, 3.6e-7 rad per 5 ms
step) against the 0.05 m/s gravity increment. The cross term of the two rotations
(``zeta x C (a x u) / 12``, < 1e-15 m/s per step on a trolley) is left out.

Floating point: latitude and longitude (about 0.5 rad) move by about 1e-9 rad per 5 ms step,
where one rounding is 7e-10 m; they and the height are Kahan-compensated sums, so 140,000
steps add up to nanometres, not to a systematic 0.1 mm. The gravity and specific-force
velocity increments (0.05 m/s each, opposite) are added together before they meet the
velocity. The quaternion too is a compensated sum, the previous one plus its change (each
part of the small rotations' quaternions to full precision); its norm, 1 to rounding, is
divided out where C_b^n is formed. On exact increments, at rest and on python-ins's curved
stop-and-go run (700 s at 200 Hz), the position stays at the truth to well below a micrometre
and far closer than python-ins's own integrator (the bounds asserted in
``tests/test_strapdown.py``).

Cost: the arithmetic is one numba kernel (``_step``, compiled with ``cache=True`` and without
fastmath, so the compensated sums round exactly as the plain-float loop they replaced: equal
bit for bit on this file's tests and on the 700 s runs). ``integrate`` loops in the kernel and
writes an (n, 10) array; ``update`` calls the same kernel for one sample. ``integrate`` is
much faster per sample than the plain-float loop and than the observer's per-sample
``step``; a fresh process pays for the JIT once, compiling without numba's on-disk cache and
far less loading it with. The costs are measured by ``benchmarks/strapdown.py``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from railfmu.estimators.inertial.attitude import (
    quat_from_rph,
    quat_increment_from_rotvec,
    rph_from_quat,
)
from railfmu.estimators.core.compiled import cache_note
from railfmu.models import earth

_A, _E2, _RATE = earth.A, earth.E2, earth.RATE
_GE, _K = earth.GE, earth.K_SOMIGLIANA

#: column order of :meth:`Strapdown.integrate`'s result and of :meth:`Strapdown.navigation`
NAV = ("latitude", "longitude", "height", "vn", "ve", "vd", "roll", "pitch", "heading")

# the state array: navigation and quaternion first (the rows :func:`_integrate` writes), then the
# mid-interval latitude memory, the Kahan compensations, the previous interval's increments
_LAT, _LON, _H, _VN, _VE, _VD, _Q0, _Q1, _Q2, _Q3, _LAT_PREV = range(11)
_C_LAT, _C_LON, _C_H, _C_Q0, _C_Q1, _C_Q2, _C_Q3 = range(11, 18)
_PA, _PU = 18, 21            # dtheta_x..z, dv_x..z of the previous interval
_N_STATE = 24
_ROW = 10                    # lat, lon, h, vn, ve, vd, q0..q3

# the same function compiled (no fastmath: a contracted multiply-add or a reassociated sum would
# change the roundings the compensated sums are built on)
_quat_increment = numba.njit(cache=True)(quat_increment_from_rotvec)


@numba.njit(cache=True)
def _step(x, h, ax, ay, az, ux, uy, uz):
    """One IMU interval of the mechanisation on the state array ``x`` (module docstring), in place."""
    bx, by, bz = x[_PA], x[_PA + 1], x[_PA + 2]
    wx, wy, wz = x[_PU], x[_PU + 1], x[_PU + 2]
    # body frame: coning (phi), rotation and sculling (dv^b)
    px = ax + (by * az - bz * ay) / 12.0
    py = ay + (bz * ax - bx * az) / 12.0
    pz = az + (bx * ay - by * ax) / 12.0
    cx = ay * uz - az * uy
    cy = az * ux - ax * uz
    cz = ax * uy - ay * ux
    r = 0.5 - (ax * ax + ay * ay + az * az) / 24.0
    dx = ux + r * cx + (ay * cz - az * cy) / 6.0 + (by * uz - bz * uy + wy * az - wz * ay) / 12.0
    dy = uy + r * cy + (az * cx - ax * cz) / 6.0 + (bz * ux - bx * uz + wz * ax - wx * az) / 12.0
    dz = uz + r * cz + (ax * cy - ay * cx) / 6.0 + (bx * uy - by * ux + wx * ay - wy * ax) / 12.0
    x[_PA], x[_PA + 1], x[_PA + 2] = ax, ay, az
    x[_PU], x[_PU + 1], x[_PU + 2] = ux, uy, uz
    # C_b^n(k-1) dv^b
    q0, q1, q2, q3 = x[_Q0], x[_Q1], x[_Q2], x[_Q3]
    c11 = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    c22 = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    c33 = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    c12 = 2.0 * (q1 * q2 - q0 * q3)
    c21 = 2.0 * (q1 * q2 + q0 * q3)
    c13 = 2.0 * (q1 * q3 + q0 * q2)
    c31 = 2.0 * (q1 * q3 - q0 * q2)
    c23 = 2.0 * (q2 * q3 - q0 * q1)
    c32 = 2.0 * (q2 * q3 + q0 * q1)
    k = 1.0 / (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)  # 1 to rounding: C_b^n of a unit q
    fn = (c11 * dx + c12 * dy + c13 * dz) * k
    fe = (c21 * dx + c22 * dy + c23 * dz) * k
    fd = (c31 * dx + c32 * dy + c33 * dz) * k
    # Earth at mid-interval: latitude extrapolated (second order), radii, Earth rate, gravity
    lat, vn, ve, vd, hh = x[_LAT], x[_VN], x[_VE], x[_VD], x[_H]
    lm = 1.5 * lat - 0.5 * x[_LAT_PREV]
    s = math.sin(lm)
    c = math.cos(lm)
    tl = s / c
    e = 1.0 - _E2 * s * s
    sx = math.sqrt(e)
    re = _A / sx
    rn = re * (1.0 - _E2) / e
    wn = _RATE * c
    wd = -_RATE * s
    g0 = _GE * (1.0 + _K * s * s) / sx
    # predictor for the mid-interval velocity and height (Coriolis, transport rate, gravity)
    rr = 1.0 / (re + hh)
    rt = 1.0 / (rn + hh)
    tn = 2.0 * wn + ve * rr
    te = -vn * rt
    td = 2.0 * wd - ve * tl * rr
    g = g0 * (1.0 - 2.0 * (hh - 0.5 * vd * h) / _A)
    vnm = vn + 0.5 * (fn - (te * vd - td * ve) * h)
    vem = ve + 0.5 * (fe - (td * vn - tn * vd) * h)
    vdm = vd + 0.5 * (fd + (g - (tn * ve - te * vn)) * h)
    hm = hh - 0.5 * vdm * h
    rr = 1.0 / (re + hm)
    rt = 1.0 / (rn + hm)
    rho_n = vem * rr
    rho_e = -vnm * rt
    rho_d = -rho_n * tl
    g = g0 * (1.0 - 2.0 * hm / _A)
    # n-frame rotation over the interval, and the specific force rotated into n(k)
    zn = (wn + rho_n) * h
    ze = rho_e * h
    zd = (wd + rho_d) * h
    cx = ze * fd - zd * fe
    cy = zd * fn - zn * fd
    cz = zn * fe - ze * fn
    fn, fe, fd = (fn - 0.5 * cx + (ze * cz - zd * cy) / 6.0, fe - 0.5 * cy + (zd * cx - zn * cz) / 6.0,
                  fd - 0.5 * cz + (zn * cy - ze * cx) / 6.0)
    tn = 2.0 * wn + rho_n
    te = rho_e
    td = 2.0 * wd + rho_d
    vn1 = vn + (fn - (te * vdm - td * vem) * h)
    ve1 = ve + (fe - (td * vnm - tn * vdm) * h)
    vd1 = vd + (fd + (g - (tn * vem - te * vnm)) * h)
    x[_VN], x[_VE], x[_VD] = vn1, ve1, vd1
    # position: trapezoidal, Kahan-compensated
    dh = -0.5 * (vd + vd1) * h
    hm = hh + 0.5 * dh
    y = dh - x[_C_H]
    t = hh + y
    x[_C_H] = (t - hh) - y
    x[_H] = t
    y = 0.5 * (vn + vn1) * h / (rn + hm) - x[_C_LAT]
    t = lat + y
    x[_C_LAT] = (t - lat) - y
    x[_LAT_PREV] = lat
    x[_LAT] = t
    lon = x[_LON]
    y = 0.5 * (ve + ve1) * h / ((re + hm) * c) - x[_C_LON]
    t = lon + y
    x[_C_LON] = (t - lon) - y
    x[_LON] = t
    # attitude: q(k) = conj(q(zeta)) q(k-1) q(phi), as q(k-1) + (the change), compensated;
    # q(phi) - 1 and conj(q(zeta)) - 1, each part to full precision
    a0, a1, a2, a3 = _quat_increment(px, py, pz)
    d0 = q0 * a0 - q1 * a1 - q2 * a2 - q3 * a3
    d1 = q0 * a1 + q1 * a0 + q2 * a3 - q3 * a2
    d2 = q0 * a2 - q1 * a3 + q2 * a0 + q3 * a1
    d3 = q0 * a3 + q1 * a2 - q2 * a1 + q3 * a0
    r0, r1, r2, r3 = q0 + d0, q1 + d1, q2 + d2, q3 + d3
    n0, n1, n2, n3 = _quat_increment(zn, ze, zd)
    y = d0 + n0 * r0 + n1 * r1 + n2 * r2 + n3 * r3 - x[_C_Q0]
    t = q0 + y
    x[_C_Q0] = (t - q0) - y
    x[_Q0] = t
    y = d1 + n0 * r1 - n1 * r0 - n2 * r3 + n3 * r2 - x[_C_Q1]
    t = q1 + y
    x[_C_Q1] = (t - q1) - y
    x[_Q1] = t
    y = d2 + n0 * r2 + n1 * r3 - n2 * r0 - n3 * r1 - x[_C_Q2]
    t = q2 + y
    x[_C_Q2] = (t - q2) - y
    x[_Q2] = t
    y = d3 + n0 * r3 - n1 * r2 + n2 * r1 - n3 * r0 - x[_C_Q3]
    t = q3 + y
    x[_C_Q3] = (t - q3) - y
    x[_Q3] = t


@numba.njit(cache=True)
def _integrate(x, h, inc, out):
    """:func:`_step` over the rows of ``inc`` (n, 6); row k of ``out`` (n, 10) gets the state's
    navigation and quaternion after interval k."""
    for k in range(inc.shape[0]):
        _step(x, h, inc[k, 0], inc[k, 1], inc[k, 2], inc[k, 3], inc[k, 4], inc[k, 5])
        for j in range(_ROW):
            out[k, j] = x[j]


@numba.njit(cache=True)
def _navigate(x, h, inc, out):
    """:func:`_step` over the rows of ``inc`` (n, 6); row k of ``out`` (n, 9) gets the
    navigation after interval k exactly as :meth:`Strapdown.navigation` gives it (the same
    roll, pitch and heading arithmetic, libm's atan2)."""
    for k in range(inc.shape[0]):
        _step(x, h, inc[k, 0], inc[k, 1], inc[k, 2], inc[k, 3], inc[k, 4], inc[k, 5])
        for j in range(6):
            out[k, j] = x[j]
        q0, q1, q2, q3 = x[_Q0], x[_Q1], x[_Q2], x[_Q3]
        c31 = 2.0 * (q1 * q3 - q0 * q2)
        c32 = 2.0 * (q2 * q3 + q0 * q1)
        c33 = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
        c21 = 2.0 * (q1 * q2 + q0 * q3)
        c11 = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
        out[k, 6] = math.atan2(c32, c33)
        out[k, 7] = math.atan2(-c31, math.sqrt(c32 * c32 + c33 * c33))
        out[k, 8] = math.atan2(c21, c11)


def _state_property(i: int, doc: str, settable: bool = False) -> property:
    def get(self) -> float:
        return float(self._x[i])

    def set_(self, value: float) -> None:
        self._x[i] = value
    return property(get, set_ if settable else None, doc=doc)


class Strapdown:
    """The strapdown mechanisation (module docstring) as a state machine.

    ``Strapdown(lat, lon, height, v_ned, q, dt)``: initial latitude, longitude (rad), height
    (m), NED velocity (m/s), attitude quaternion ``q`` of C_b^n (scalar first; see
    :meth:`from_rph`) at the start time, and the IMU interval ``dt`` (s). :meth:`prime` gives
    the increments of the interval before the start (for coning and sculling; zero if not
    given), :meth:`update` integrates one interval, :meth:`integrate` many; both run the one
    compiled kernel on the state array. The state is read through ``lat, lon, h`` (rad, rad,
    m), ``vn, ve, vd`` (m/s), ``q0..q3``, and changed through :meth:`set_state`; ``lat_prev``
    (the latitude one interval earlier, for the mid-interval extrapolation) can be set.
    """

    __slots__ = ("dt", "_x")

    lat = _state_property(_LAT, "latitude, rad")
    lon = _state_property(_LON, "longitude, rad")
    h = _state_property(_H, "height above the ellipsoid, m")
    vn = _state_property(_VN, "north velocity, m/s")
    ve = _state_property(_VE, "east velocity, m/s")
    vd = _state_property(_VD, "down velocity, m/s")
    q0 = _state_property(_Q0, "quaternion of C_b^n, scalar part")
    q1 = _state_property(_Q1, "quaternion of C_b^n, x")
    q2 = _state_property(_Q2, "quaternion of C_b^n, y")
    q3 = _state_property(_Q3, "quaternion of C_b^n, z")
    lat_prev = _state_property(_LAT_PREV, "latitude one IMU interval earlier, rad", settable=True)

    def __init__(self, lat: float, lon: float, height: float, v_ned, q, dt: float) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"Strapdown: dt must be a positive number of seconds, not {dt!r}")
        cache_note("strapdown", _step, _navigate)
        self.dt = float(dt)
        x = self._x = np.zeros(_N_STATE)
        x[_LAT], x[_LON], x[_H] = float(lat), float(lon), float(height)
        x[_VN:_VD + 1] = [float(v) for v in v_ned]
        # the latitude one step earlier, for the first mid-interval extrapolation
        x[_LAT_PREV] = x[_LAT] - x[_VN] * self.dt / earth.principal_radii(x[_LAT], x[_H])[0]
        q = np.asarray(q, dtype=float)
        x[_Q0:_Q3 + 1] = q / np.linalg.norm(q)

    @classmethod
    def from_rph(cls, lat: float, lon: float, height: float, v_ned, rph, dt: float) -> "Strapdown":
        """Initial attitude from roll, pitch, heading (rad)."""
        return cls(lat, lon, height, v_ned, quat_from_rph(*rph), dt)

    def prime(self, dtheta, dv) -> None:
        """The increments of the interval that ends at the start time (coning, sculling)."""
        self._x[_PA:_PA + 3] = [float(v) for v in dtheta]
        self._x[_PU:_PU + 3] = [float(v) for v in dv]

    def update(self, ax: float, ay: float, az: float, ux: float, uy: float, uz: float) -> None:
        """One IMU interval: increments ``(ax, ay, az)`` (rad) and ``(ux, uy, uz)`` (m/s)."""
        _step(self._x, self.dt, float(ax), float(ay), float(az), float(ux), float(uy), float(uz))

    def set_state(self, lat: float | None = None, lon: float | None = None, height: float | None = None,
                  v_ned=None, q=None) -> None:
        """Replace parts of the state (an aided filter's error feedback): latitude, longitude
        (rad), height (m), NED velocity (m/s), attitude quaternion of C_b^n (scalar first,
        normalised here). Each part set drops its compensation term (the rounding carried in
        it belonged to the old value); the mid-interval latitude extrapolation moves with a
        corrected latitude so the feedback does not masquerade as a velocity."""
        x = self._x
        if lat is not None:
            x[_LAT_PREV] += float(lat) - x[_LAT]
            x[_LAT], x[_C_LAT] = float(lat), 0.0
        if lon is not None:
            x[_LON], x[_C_LON] = float(lon), 0.0
        if height is not None:
            x[_H], x[_C_H] = float(height), 0.0
        if v_ned is not None:
            x[_VN:_VD + 1] = [float(v) for v in v_ned]
        if q is not None:
            q = np.asarray(q, dtype=float)
            x[_Q0:_Q3 + 1] = q / np.linalg.norm(q)
            x[_C_Q0:_C_Q3 + 1] = 0.0

    def rph(self) -> tuple[float, float, float]:
        """(roll, pitch, heading) (rad) of the current attitude; heading in (-pi, pi]."""
        q0, q1, q2, q3 = self._x[_Q0:_Q3 + 1].tolist()
        c31 = 2.0 * (q1 * q3 - q0 * q2)
        c32 = 2.0 * (q2 * q3 + q0 * q1)
        c33 = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
        c21 = 2.0 * (q1 * q2 + q0 * q3)
        c11 = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
        return (math.atan2(c32, c33), math.atan2(-c31, math.sqrt(c32 * c32 + c33 * c33)),
                math.atan2(c21, c11))

    def navigation(self) -> tuple[float, ...]:
        """The current ``(latitude, longitude, height, vn, ve, vd, roll, pitch, heading)``
        (rad, rad, m, m/s x 3, rad x 3), in the order of :data:`NAV`."""
        return (*self._x[_LAT:_VD + 1].tolist(), *self.rph())

    def quaternion(self) -> np.ndarray:
        return self._x[_Q0:_Q3 + 1].copy()

    def navigate(self, increments, out: np.ndarray | None = None) -> np.ndarray:
        """All rows of ``increments`` ``(n, 6)``, one interval each, in one compiled call ->
        ``(n, 9)`` (``out`` if given): row k is what :meth:`navigation` returns after
        :meth:`update` with row k, bit for bit."""
        inc = np.ascontiguousarray(increments, dtype=np.float64)
        if inc.ndim != 2 or inc.shape[1] != 6:
            raise ValueError(f"Strapdown.navigate: increments of shape {inc.shape}, expected (n, 6)")
        if out is None or not out.flags.c_contiguous:
            res = np.empty((inc.shape[0], len(NAV)))
            _navigate(self._x, self.dt, inc, res)
            if out is None:
                return res
            out[:] = res
            return out
        _navigate(self._x, self.dt, inc, out)
        return out

    def integrate(self, increments) -> np.ndarray:
        """All rows of ``increments`` ``(n, 6)`` (``dtheta_x..z`` rad, ``dv_x..z`` m/s), one
        interval each -> the navigation after each, ``(n, 9)`` in the order of :data:`NAV`.
        Attitude as roll/pitch/heading; :meth:`quaternion` gives the last one exactly."""
        inc = np.ascontiguousarray(increments, dtype=np.float64)
        if inc.ndim != 2 or inc.shape[1] != 6:
            raise ValueError(f"Strapdown.integrate: increments of shape {inc.shape}, expected (n, 6)")
        out = np.empty((inc.shape[0], _ROW))
        _integrate(self._x, self.dt, inc, out)
        out[:, 6:9] = rph_from_quat(out[:, 6:10])
        return out[:, :9]
