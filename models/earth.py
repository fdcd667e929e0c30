r"""The Earth of the trolley survey (Jiang et al. 2017): WGS-84 ellipsoid, Earth rate and
normal gravity, in the navigation frame NED. Angles in radians, lengths in metres.

One definition for everything that navigates: the ``Trolley`` FMU's C (``Earth.h`` mirrors
these formulas and constants and is tested against them), its Python twin and the strapdown
INS of ``estimators/``. The constants and the gravity model are those of the ``python-ins``
package (P. D. Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., 2013, §2.4 and §2.4.7), so that its integrator can cross-check our IMU data
to the micrometre: over a 10-minute free-inertial run a 1e-10 g difference in gravity alone
moves the height by 0.2 mm.

Equations (``L`` latitude, ``h`` height above the ellipsoid)::

    R_E = a / sqrt(1 - e^2 sin^2 L)                  transverse (prime vertical) radius
    R_N = a (1 - e^2) / (1 - e^2 sin^2 L)^(3/2)      meridian radius
    omega_ie^n = Omega (cos L, 0, -sin L)            Earth rate in NED
    omega_en^n = (v_E / (R_E + h), -v_N / (R_N + h), -v_E tan L / (R_E + h))   transport rate
    gamma(L, h) = g_e (1 + k sin^2 L) / sqrt(1 - e^2 sin^2 L) (1 - 2 h / a)
                  k = sqrt(1 - e^2) g_p / g_e - 1    Somigliana, linear free-air correction
    g^n = (0, 0, gamma)                              normal gravity (gravitation + centrifugal)
"""

from __future__ import annotations

import numpy as np

#: Earth rotation rate Omega (rad/s); WGS-84 gives 7.2921151467e-5, python-ins 7.292115e-5
RATE = 7.292115e-5
#: WGS-84 semi-major axis a (m)
A = 6378137.0
#: WGS-84 first eccentricity squared e^2
E2 = 6.6943799901413e-3
#: normal gravity at the equator g_e and at the poles g_p (m/s2), WGS-84
GE = 9.7803253359
GP = 9.8321849378
#: Somigliana's constant k
K_SOMIGLIANA = (1.0 - E2) ** 0.5 * GP / GE - 1.0


def principal_radii(lat, h=0.0):
    """``(R_N + h, R_E + h)`` (m): meridian and transverse radii of curvature plus the height."""
    s2 = np.sin(lat) ** 2
    x = 1.0 - E2 * s2
    re = A / np.sqrt(x)
    return re * (1.0 - E2) / x + h, re + h


def gravity(lat, h=0.0):
    """Normal gravity magnitude gamma(L, h) (m/s2), down in NED."""
    s2 = np.sin(lat) ** 2
    return GE * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2) * (1.0 - 2.0 * np.asarray(h) / A)


def earth_rate_n(lat) -> np.ndarray:
    """omega_ie^n (rad/s), shape ``(..., 3)``."""
    lat = np.asarray(lat, dtype=float)
    return np.stack([RATE * np.cos(lat), np.zeros_like(lat), -RATE * np.sin(lat)], axis=-1)


def transport_rate_n(lat, h, v_n) -> np.ndarray:
    """omega_en^n (rad/s) of a velocity ``v_n`` (NED, m/s), shape ``(..., 3)``."""
    rn, re = principal_radii(lat, h)
    v_n = np.asarray(v_n, dtype=float)
    vn, ve = v_n[..., 0], v_n[..., 1]
    return np.stack([ve / re, -vn / rn, -ve * np.tan(lat) / re], axis=-1)


def lla_to_ecef(lat, lon, h) -> np.ndarray:
    """Geodetic (rad, rad, m) -> ECEF (m), shape ``(..., 3)``."""
    s, c = np.sin(lat), np.cos(lat)
    re = A / np.sqrt(1.0 - E2 * s * s)
    return np.stack([(re + h) * c * np.cos(lon), (re + h) * c * np.sin(lon), (re * (1.0 - E2) + h) * s], axis=-1)


def ecef_to_ned_matrix(lat, lon) -> np.ndarray:
    """C_e^n: rotates an ECEF vector into the NED frame at (lat, lon)."""
    sL, cL, sl, cl = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    return np.array([[-sL * cl, -sL * sl, cL], [-sl, cl, 0.0], [-cL * cl, -cL * sl, -sL]])


def ned_from_origin(lat, lon, h, lat0: float, lon0: float, h0: float) -> np.ndarray:
    """North, east, down (m) of points from an origin, in the origin's local-level frame
    (the frame n0 in which Jiang et al. (2017) compute their chords)."""
    d = lla_to_ecef(lat, lon, h) - lla_to_ecef(lat0, lon0, h0)
    return d @ ecef_to_ned_matrix(lat0, lon0).T
