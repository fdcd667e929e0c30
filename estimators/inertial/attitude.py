r"""Attitude of a body (forward-right-down) in the navigation frame NED: direction cosine
matrix, quaternion, rotation vector and Euler roll-pitch-heading; static coarse alignment.

Conventions (those of ``python-ins`` and of Groves 2013, §2.2)::

    C_b^n = R_z(heading) R_y(pitch) R_x(roll)        body -> NED, a column of C_b^n is a body
                                                     axis resolved in NED
    q = (q0, q1, q2, q3), scalar first, C_b^n(q)     the same rotation as a unit quaternion
    exp([phi x]) = I + sin|phi|/|phi| [phi x] + (1 - cos|phi|)/|phi|^2 [phi x]^2
                                                     rotation vector phi -> DCM (Rodrigues)

Vectorised conversions use ``scipy.spatial.transform.Rotation`` (intrinsic ``"ZYX"`` Euler
angles are exactly heading-pitch-roll). The strapdown loop does not: a ``Rotation`` object
costs microseconds to build, more than a whole mechanisation step in plain floats, so
:mod:`railfmu.estimators.inertial.strapdown` has its own scalar quaternion arithmetic and uses the
small-angle series of :func:`quat_from_rotvec` (``1 - cos`` of a 1e-6 rad increment would
lose half its digits).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from railfmu.models import earth


def dcm_from_rph(roll, pitch, heading) -> np.ndarray:
    """C_b^n from roll, pitch, heading (rad); shape ``(3, 3)`` or ``(n, 3, 3)``."""
    return Rotation.from_euler("ZYX", np.stack([heading, pitch, roll], axis=-1)).as_matrix()


def rph_from_dcm(C) -> np.ndarray:
    """(roll, pitch, heading) (rad) of C_b^n; heading in (-pi, pi]. Shape ``(3,)`` or ``(n, 3)``."""
    return Rotation.from_matrix(C).as_euler("ZYX")[..., ::-1]


def quat_from_rph(roll, pitch, heading) -> np.ndarray:
    """Unit quaternion (scalar first) of C_b^n from roll, pitch, heading (rad)."""
    return Rotation.from_euler("ZYX", np.stack([heading, pitch, roll], axis=-1)).as_quat(scalar_first=True)


def rph_from_quat(q) -> np.ndarray:
    """(roll, pitch, heading) (rad) of a quaternion (scalar first) of C_b^n."""
    return Rotation.from_quat(q, scalar_first=True).as_euler("ZYX")[..., ::-1]


def dcm_from_rotvec(phi) -> np.ndarray:
    """exp([phi x]) (rotation vector phi, rad); shape ``(3, 3)`` or ``(n, 3, 3)``."""
    return Rotation.from_rotvec(phi).as_matrix()


def quat_from_rotvec(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """Quaternion (cos(a/2), sin(a/2)/a * phi) of the rotation vector phi = (x, y, z), a = |phi|,
    in plain floats. Below a = 1e-2 rad by its Taylor series, exact to a relative 1e-17 there
    (the next terms are a^6/46080 and a^6/645120)."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-4:
        c = 1.0 - a2 / 8.0 + a2 * a2 / 384.0
        s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    else:
        a = math.sqrt(a2)
        c = math.cos(0.5 * a)
        s = math.sin(0.5 * a) / a
    return c, s * x, s * y, s * z


def quat_increment_from_rotvec(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """:func:`quat_from_rotvec` minus the identity quaternion, ``(cos(a/2) - 1, ...)``, each part
    to full relative precision: a small rotation added to an attitude as a compensated sum."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-4:
        c = -a2 / 8.0 + a2 * a2 / 384.0
        s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    else:
        a = math.sqrt(a2)
        c = -2.0 * math.sin(0.25 * a) ** 2
        s = math.sin(0.5 * a) / a
    return c, s * x, s * y, s * z


def perturb(C, error_n) -> np.ndarray:
    """The attitude C_b^n rotated by a small error: exp([e x]) C_b^n, ``e = (e_N, e_E, e_D)``
    (rad) a rotation vector in NED. ``e_N``, ``e_E`` are the tilt errors, ``e_D`` the heading
    error (the computed heading is the true one plus ``e_D``). The usual error angle of INS
    error models (Groves §14.2, C~ = (I - [psi x]) C) is ``psi = -e``."""
    return dcm_from_rotvec(np.asarray(error_n, dtype=float)) @ np.asarray(C, dtype=float)


def coarse_alignment(f_b, w_b) -> np.ndarray:
    r"""C_b^n from the mean specific force ``f_b`` (m/s2) and the mean angular rate ``w_b``
    (rad/s) of a body at rest (analytic coarse alignment, Groves §5.6.2; Titterton & Weston
    §10.3): at rest ``f^b = C_n^b (0, 0, -g)`` and ``w^b = C_n^b Omega (cos L, 0, -sin L)``, so
    the NED axes in the body frame are::

        d = -f / |f|,   e = (d x w) / |d x w|,   n = e x d,    C_b^n = [n e d]^T

    The heading error of the result is the east component of the gyro error over the Earth's
    horizontal rate, ``delta_psi ~= eps_E / (Omega cos L)`` (see :func:`coarse_heading_sigma`);
    the tilt error is the horizontal accelerometer error over g.
    """
    f_b = np.asarray(f_b, dtype=float)
    w_b = np.asarray(w_b, dtype=float)
    d = -f_b / np.linalg.norm(f_b)
    e = np.cross(d, w_b)
    norm = np.linalg.norm(e)
    if not (norm > 0.0):
        raise ValueError("coarse_alignment: the angular rate is parallel to gravity (at a pole) or zero; "
                         "heading cannot be found")
    e /= norm
    n = np.cross(e, d)
    return np.array([n, e, d])


def coarse_heading_sigma(gyro_sigma: float, lat: float) -> float:
    """Heading accuracy (rad) of a static coarse alignment: ``eps / (Omega cos L)``, with
    ``eps`` (rad/s) the error of the mean east gyro rate over the alignment (a bias, or an
    angle random walk N (rad/sqrt(s)) averaged over T seconds: ``eps = N / sqrt(T)``) and L
    the latitude (rad). E.g. 0.01 deg/h at 30.5 deg N: 7.7e-4 rad (0.044 deg)."""
    return gyro_sigma / (earth.RATE * math.cos(lat))
