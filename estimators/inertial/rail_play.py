r"""The wheel-rail play of a vehicle on a rail as a shaping filter in the distance travelled:
nuisance states that let a non-holonomic constraint know that the body's offset from the rail
is bounded.

A body that rides a rail (a survey trolley, a bogie frame) moves off the rail centre line by
the play between wheel and rail: millimetres, sideways (``y``, along the body's y axis) and
up and down (``z``, body z), as a function of where it is on the rail, the distance ``s``
(m). Its velocity across the rail is then ``v^b_y = dy/dt = v_s y'`` (``y' = dy/ds``, ``v_s``
the speed along the rail), likewise ``v^b_z = v_s z'``. Treating ``v^b_{y,z}`` as white
noise (``AidedInsSmoother(play_model="white")``) lets the constraint's integral -- the
lateral and vertical position -- wander as a random walk; modelled as the slope of a bounded
offset, the body's cross-track displacement over any distance is bounded by the play, which
ties the cross-track drift to the gyros' heading and pitch (dead reckoning along the rail).

Each offset is a stationary second-order process in ``s`` (a damped oscillator driven by white
noise; the same for ``z`` with its own sigma)::

    d/ds [y, y'] = F [y, y'] + [0, 1] w,     F = [[0, 1], [-k^2, -2 zeta k]],
    E[w(s) w(s')] = q delta(s - s'),         q = 4 zeta k^3 sigma^2   (1/m)

``k = 2 pi / wavelength`` (rad/m) the natural wavenumber, ``zeta`` the damping (default
``1/sqrt(2)``: a Butterworth spectrum, flat below ``k`` and falling as ``kappa^-4`` above),
``sigma`` (m) the offset's stationary standard deviation. Its spectral density and
stationary covariance (the Lyapunov equation ``F P + P F^T + G q G^T = 0``)::

    S_y(kappa) = q / ((k^2 - kappa^2)^2 + (2 zeta k kappa)^2)   (m^2 / (rad/m))
    P_inf      = diag(sigma^2, k^2 sigma^2)                    (m^2, -)

so ``y'`` has rms ``k sigma`` and ``v^b_y`` rms ``v_s k sigma`` (a sinusoid of amplitude ``a``
and wavelength ``l``: ``sigma = a / sqrt(2)``, the same rms slope ``2 pi a / (sqrt(2) l)``).
``y'``'s spectrum ``kappa^2 S_y`` vanishes at ``kappa = 0``: the cross-track velocity has no
mean over long distances, which is what the white model cannot say.

Discretisation over the distance ``ds`` travelled in one filter epoch, exact: ``Phi =
exp(F ds)`` in closed form (a 2 x 2 matrix exponential; with ``mu = -zeta k ds`` and
``a = k ds sqrt(|1 - zeta^2|)``)::

    Phi = e^mu (c I + S (F ds - mu I)),   c = cos a, S = sin(a) / a    (zeta < 1)
                                          c = cosh a, S = sinh(a) / a  (zeta > 1; 1, 1 at zeta = 1)
    Q_d = P_inf - Phi P_inf Phi^T

(the last from the stationarity of the sampled process: ``P_inf = Phi P_inf Phi^T + Q_d``,
the same matrix as Van Loan's integral ``int_0^ds Phi(u) G q G^T Phi(u)^T du``;
``tests/test_rail_play.py``). ``ds = 0`` (at rest) gives ``Phi = I``, ``Q_d = 0`` exactly:
the play does not change while the vehicle stands. The process is Markov in the distance
travelled, ``|ds|``: a vehicle that reverses meets its play again, which this model forgets
(a survey runs forward).

State order: ``(y, y', z, z')`` (:data:`NAMES`); the measurement rows of the body velocity
across the rail (:meth:`RailPlay.velocity_rows`) are ``v_s`` at ``y'`` and ``z'``.
"""

from __future__ import annotations

import math

import numpy as np

NAMES = ("play_lateral", "play_lateral_slope", "play_vertical", "play_vertical_slope")
#: the default damping: a second-order Butterworth spectrum
BUTTERWORTH = 1.0 / math.sqrt(2.0)


class RailPlay:
    """The play's shaping filter (module docstring): lateral and vertical stationary sigmas
    ``sigma_lateral``, ``sigma_vertical`` (m, >= 0; 0: no play, the states stay zero),
    ``wavelength`` (m, > 0), ``damping`` (-, > 0). ``names``, ``n`` (4)."""

    names = NAMES
    n = len(NAMES)

    def __init__(self, sigma_lateral: float, sigma_vertical: float, wavelength: float,
                 damping: float = BUTTERWORTH) -> None:
        for name, v, positive in (("sigma_lateral", sigma_lateral, False), ("sigma_vertical", sigma_vertical, False),
                                  ("wavelength", wavelength, True), ("damping", damping, True)):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or \
                    not math.isfinite(v) or v < 0 or (positive and v == 0):
                raise ValueError(f"RailPlay: {name} must be a finite number {'> 0' if positive else '>= 0'}, "
                                 f"not {v!r}")
        self.sigma = np.array([float(sigma_lateral), float(sigma_vertical)])
        self.wavelength, self.damping = float(wavelength), float(damping)
        self.wavenumber = 2.0 * math.pi / self.wavelength

    # -- the continuous model (in s) -------------------------------------------------------------
    def system_matrix(self) -> np.ndarray:
        """``F`` of the four states, ``d x / ds = F x + G w`` (1/m)."""
        k, z = self.wavenumber, self.damping
        F = np.zeros((4, 4))
        for i in (0, 2):
            F[i, i + 1] = 1.0
            F[i + 1, i], F[i + 1, i + 1] = -k * k, -2.0 * z * k
        return F

    def noise_density(self) -> np.ndarray:
        """``G q G^T``: the driving noises' densities on the slopes, ``q = 4 zeta k^3 sigma^2``
        (1/m)."""
        k, z = self.wavenumber, self.damping
        Qc = np.zeros((4, 4))
        Qc[1, 1], Qc[3, 3] = 4.0 * z * k**3 * self.sigma**2
        return Qc

    def stationary_covariance(self) -> np.ndarray:
        """``P_inf = diag(sigma_y^2, k^2 sigma_y^2, sigma_z^2, k^2 sigma_z^2)``: the prior of
        the play states."""
        k2 = self.wavenumber**2
        s2 = self.sigma**2
        return np.diag([s2[0], k2 * s2[0], s2[1], k2 * s2[1]])

    # -- sampled over a distance -----------------------------------------------------------------
    def transition(self, ds) -> np.ndarray:
        """``exp(F2 ds)`` of one offset and its slope in closed form (module docstring):
        ``ds`` ``(M,)`` (m; its absolute value) -> ``(M, 2, 2)``."""
        ds = np.abs(np.asarray(ds, dtype=float).reshape(-1))
        k, z = self.wavenumber, self.damping
        a = k * ds * math.sqrt(abs(1.0 - z * z))
        if z < 1.0:
            c, S = np.cos(a), np.sinc(a / math.pi)  # np.sinc(x) = sin(pi x) / (pi x)
        elif z > 1.0:
            safe = np.where(a > 0.0, a, 1.0)
            c, S = np.cosh(a), np.where(a > 0.0, np.sinh(safe) / safe, 1.0)
        else:
            c, S = np.ones_like(a), np.ones_like(a)
        e = np.exp(-z * k * ds)
        zkd = z * k * ds
        Phi = np.empty((ds.size, 2, 2))
        Phi[:, 0, 0] = e * (c + S * zkd)
        Phi[:, 0, 1] = e * S * ds
        Phi[:, 1, 0] = -e * S * k * k * ds
        Phi[:, 1, 1] = e * (c - S * zkd)
        return Phi

    def discretize(self, ds) -> tuple[np.ndarray, np.ndarray]:
        """``(Phi, Q_d)`` ``(M, 4, 4)`` of the four states over the distances ``ds`` ``(M,)``
        (m) travelled in each epoch (module docstring; exact, vectorised)."""
        P2 = self.transition(ds)
        M = P2.shape[0]
        unit = np.diag([1.0, self.wavenumber**2])  # P_inf of a unit-sigma offset
        Q2 = unit - P2 @ unit @ P2.transpose(0, 2, 1)
        Q2 = 0.5 * (Q2 + Q2.transpose(0, 2, 1))
        Phi, Qd = np.zeros((M, 4, 4)), np.zeros((M, 4, 4))
        for i, s in zip((0, 2), self.sigma):
            Phi[:, i:i + 2, i:i + 2] = P2
            Qd[:, i:i + 2, i:i + 2] = (s * s) * Q2
        return Phi, Qd

    # -- measurement rows ------------------------------------------------------------------------
    @staticmethod
    def velocity_rows(speed) -> np.ndarray:
        """``(M, 2, 4)``: the body velocity across the rail (body y, z; m/s) that the play
        states make, ``v^b_{y,z} = v_s (y', z')``, at along-track speeds ``speed`` ``(M,)``
        (m/s)."""
        speed = np.asarray(speed, dtype=float).reshape(-1)
        H = np.zeros((speed.size, 2, 4))
        H[:, 0, 1] = H[:, 1, 3] = speed
        return H
