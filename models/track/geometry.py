r"""3-D railway track geometry for the trolley survey (Jiang et al. 2017): a design alignment
on WGS-84, rail irregularities, and the true chord irregularity of their eq. 1.

Design frame and distance
-------------------------
The alignment lives in the start point's local-level frame **n0**: NED at the geodetic
point ``(L0, lambda0, h0)`` (parameters ``start_latitude``, ``start_longitude``,
``start_height``), an Earth-fixed frame. A point ``p`` (m, n0) is at the ECEF position
``r^e = r0^e + C_n0^e p`` exactly (``r0^e`` = ``earth.lla_to_ecef(L0, lambda0, h0)``,
``C_n0^e`` = ``earth.ecef_to_ned_matrix(L0, lambda0).T``). Defaults: 30.5° N, 114.4° E,
25 m (near Wuhan, where Jiang et al. (2017) surveyed), first straight at azimuth N45°E as
the paper's simulated track.

The design centre line is parameterised by its **3-D arc length** ``s`` (m), "the distance
along the track": ``p(s) = int_0^s T(sigma) dsigma`` with the unit tangent ::

    T = (cos th cos chi, cos th sin chi, -sin th)      NED in n0

``chi(s)`` the heading (azimuth from north, clockwise) and ``th(s) = atan g(s)`` the grade
angle, ``g`` the gradient (rise per unit horizontal distance, positive uphill). So the
tangent is a unit vector by construction and ``|dp/ds| = 1``. ``p`` is integrated with
16-point Gauss-Legendre rules over each piece between element ends (exact to round-off:
the integrand is entire and the heading changes by less than 2 rad on a piece).

Element table (CSV, the user's file ``track_file``)
---------------------------------------------------
Header ``kind,start_m,end_m,radius_m,cant_mm,gradient_permille`` and optionally a seventh
column ``transition`` (a table without it is read as all ``linear``); one row per element; the
horizontal rows (``straight``, ``clothoid``, ``curve_left``, ``curve_right``) and the
vertical rows (``grade``, ``vertical_curve``) each tile ``[0, length]`` in order (the first
starts at 0, each starts where the previous one of its layer ended, ``end_m > start_m``),
and both layers end at the same length. Blank cells where a kind needs no value.

==============  =========================================================================
kind            meaning
==============  =========================================================================
straight        curvature 0, cant 0
curve_left/     circular curve, ``radius_m`` > 0 (curvature ``chi' = -1/R`` left, ``+1/R``
curve_right     right), cant ``cant_mm`` in [0, 200) on the outer rail (blank = 0)
clothoid        transition: curvature and cant ramp from the previous element's to the
                next one's (both neighbours must be straights or curves), in the shape
                ``transition`` gives
grade           constant gradient ``gradient_permille`` (per mille, positive uphill, |g| < 100)
vertical_curve  gradient ramps between the neighbouring grades, in the shape ``transition``
                gives
==============  =========================================================================

Transition shapes (column ``transition``, only on ``clothoid`` and ``vertical_curve`` rows;
blank = ``linear``). With ``x = (s - s0) / L`` the relative position in the element of length
``L``, a quantity ``a`` (curvature and cant of a clothoid row, gradient of a vertical curve)
goes from ``a0`` to ``a1`` as ``a = a0 + (a1 - a0) f(x)``:

``linear``  ``f = x``: the clothoid (curvature linear in ``s``, a straight cant ramp) and the
            parabolic vertical curve (vertical radius ``L / |g1 - g0|``). The rates ``a'``
            jump at both ends, so the roll rate (cant) and the pitch rate (gradient) of a
            moving vehicle jump there.
``bloss``   ``f = 3 x^2 - 2 x^3``, Bloss's transition as high-speed lines build it (IFC 4.3
            names it ``BLOSSCURVE``); for a vertical curve the gradient is blended by the
            same cubic. ``a' = (a1 - a0) 6 x (1 - x) / L`` is zero at both ends, so
            curvature, cant and gradient join their neighbours with a continuous rate, and so
            do the roll, pitch and yaw rates (the peak rate, at mid-length, is 1.5 times the
            linear one; what still jumps is ``a''``, an angular acceleration). For a clothoid
            row the heading is ``chi0 + k0 u + (k1 - k0) L (x^3 - x^4 / 2)``, ``u = s - s0``:
            at the end ``(k0 + k1) L / 2`` as for the clothoid (``L / (2 R)`` from a
            straight into a curve of radius ``R``).

Why it matters here: an INS that works from increments (two-sample coning and sculling)
takes the angular rate as smooth over two intervals; across a rate jump ``dw`` it is off by
about ``|dw| h |dv| / 12`` per jump (3.4e-8 m/s at the 100 mm cant ramp ends at 5 ms), and
that integrates (0.0386 mm over the shipped 700 s run at 5 ms with ``linear``; 0.0013 mm
with ``bloss``). Real transitions and a real trolley (finite wheelbase) have continuous
rates; the shipped table uses ``bloss`` throughout.

Curvatures are per metre of 3-D arc (``chi' = kappa``; the plan-view curvature is
``kappa / cos th``, 3e-5 relative apart at 8 per mille). The shipped table
``models/data/trolley_track.csv`` is 600 m: straight, transition, R 400 m right with
100 mm cant, transition, straight, transition, R 600 m left with 60 mm cant, transition,
straight; level, a vertical curve to +8 per mille, another to -4 per mille; every transition
and vertical curve ``bloss``. Problems (non-monotonic distances, gaps, a radius <= 0, an
unknown kind or transition ...) raise
:class:`railfmu.models.errors.UserError` naming the file, line and column.

Cant and body roll
------------------
The signed cant ``c(s)`` (m; positive when the left rail is higher, i.e. in right-hand
curves) gives the roll of the rail plane ``phi = asin(c / b)``, ``b`` = :data:`RAIL_BASE`
= 1.5 m between the rail centres of standard gauge; positive roll is right side down (FRD).

Irregularities
--------------
The true rail centre line is the design one displaced by ``y(s)`` along the horizontal
right normal ``Y = (-sin chi, cos chi, 0)`` (alignment, positive right) and ``z(s)`` along
the vertical ``D = (0, 0, 1)`` of n0 (level, positive down): ``p_rail = p + y Y + z D``.
Why the vertical and not the normal of the tangent in the vertical plane: that normal turns
with the grade angle, whose rate jumps where a linear vertical curve starts, so the offset
line's speed (``1 - z kappa_v`` per unit ``s``) would jump there, by 3e-7 for 2 mm at a
7500 m vertical radius, and the IMU increments would miss that impulse; ``D`` is constant
and ``Y`` turns with the heading, whose rate (the curvature) is continuous through the
transitions. (A
table with a curve straight after a straight, no clothoid, has a curvature jump: there the
rail's speed jumps by ``y dkappa`` and the increments miss it; use transitions.) ``y`` and
``z`` are sums of sinusoids with exact analytic derivatives::

    y(s) = sum_k a_k sin(Omega_k s + phi_k) + A_y sin(2 pi s / lambda_h)
    a_k  = scale sqrt(2 S(Omega_k) dOmega_k)

``S`` the ERRI B176 one-sided spectrum of ``railfmu.models.track.irregularity`` (``psd_alignment`` for ``y``,
``psd_vertical`` for ``z``, level 1 low or 2 high, 0 none), on ``N`` lines
(``irregularity_lines``) with wavelengths log-spaced over ``[lambda_min, lambda_max]``:
line ``k`` sits at the geometric centre of its band ``Omega_k = sqrt(W_k W_{k+1})``,
``W_j = 2 pi / lambda_max (lambda_max / lambda_min)^(j / N)``, ``dOmega_k = W_{k+1} - W_k``;
phases ``2 pi u`` from SplitMix64(``irregularity_seed``): first the N alignment phases,
then the N level phases. Few lines keep the FMU's step cheap; the variance is the Riemann
sum of the spectrum over the band.

A **measured table** (``irregularity_file``, added to the above) has the format of the
``TrackIrregularity`` FMU's ``profile_file`` (``models/track/irregularity.py``): header
``s,alignment,vertical_left,vertical_right`` (m, ``s`` strictly increasing), interpolated by
the same cubic Hermite splines with Catmull-Rom slopes; ``y`` is its alignment and ``z`` the
vertical profile ``(vertical_left + vertical_right) / 2``, signs as ``y`` and ``z`` here
(right, down). It must cover the whole track (no jump where it would end). Its second
derivative jumps at every row, so the Trolley splits its quadrature there too
(:attr:`TrackGeometry.kinks`).

Chord irregularity (Jiang et al. (2017), eqs. 1, 13-15)
-------------------------------------------------------
For a chord from ``a = p(c)`` to ``b = p(c + l_c)`` (n0 frame) the c-frame is n0 turned by
``theta_a`` about z and ``theta_l`` about y (eq. 13), with ``sin theta_a = dE / hor``,
``cos theta_a = dN / hor``, ``sin theta_l = -dD / l``, ``cos theta_l = hor / l`` (eq. 15,
``d = b - a``, ``hor = |(dN, dE)|``, ``l = |d|``); the vector distance of a point ``p``
(eq. 14) has the components ::

    alignment  y_c = -(pN - aN) sin theta_a + (pE - aE) cos theta_a
    level      z_c =  (pN - aN) sin theta_l cos theta_a + (pE - aE) sin theta_l sin theta_a
                      + (pD - aD) cos theta_l

and the irregularity at ``s`` (eq. 1) is ``(d_s - d_{s+5}) - (dbar_s - dbar_{s+5})``, ``d``
of the true (or measured) points against their own chord and ``dbar`` of the design
points against the design chord. :func:`vector_distance`, :func:`chord_irregularity` and
:meth:`TrackGeometry.true_chord_irregularity` (true rail minus design) implement it;
the trolley survey study calls them with estimated positions too.

The same arithmetic is in ``fmus/native/models/TrackGeometry.h`` (the Trolley FMU);
``tests/test_track_geometry.py`` checks closed forms, ``tests/test_trolley.py`` C = Python.
"""

from __future__ import annotations

import bisect
import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from railfmu.models.errors import UserError

from railfmu.models import earth
from railfmu.models.track.irregularity import ProfileTable, SplitMix64, psd_alignment, psd_vertical

HERE = Path(__file__).resolve().parents[1]  # models/
DEFAULT_TRACK = HERE / "data" / "trolley_track.csv"
COLUMNS = ("kind", "start_m", "end_m", "radius_m", "cant_mm", "gradient_permille")
#: the optional seventh column and its values (index = the shape code the C uses too)
TRANSITION = "transition"
SHAPES = ("linear", "bloss")
HORIZONTAL = ("straight", "clothoid", "curve_left", "curve_right")
VERTICAL = ("grade", "vertical_curve")
#: distance between the rail centres of standard gauge (m): cant c gives roll asin(c / b)
RAIL_BASE = 1.5
MAX_CANT_MM = 200.0
MAX_GRADIENT_PERMILLE = 100.0

#: Gauss-Legendre 16-point nodes and weights on [-1, 1] (positive half; the C has the same)
GL16_X = (0.09501250983763744, 0.2816035507792589, 0.45801677765722737, 0.6178762444026438,
          0.755404408355003, 0.8656312023878318, 0.9445750230732326, 0.9894009349916499)
GL16_W = (0.18945061045506864, 0.18260341504492364, 0.16915651939500265, 0.1495959888165767,
          0.12462897125553407, 0.0951585116824926, 0.062253523938647456, 0.027152459411754176)

#: defaults of the placement (also the Trolley FMU's parameter defaults)
DEFAULT_PLACEMENT = {"start_latitude": math.radians(30.5), "start_longitude": math.radians(114.4),
                     "start_height": 25.0, "azimuth": math.radians(45.0)}
#: defaults of the irregularities and the wobble (also the Trolley FMU's)
DEFAULT_IRREGULARITY = {"irregularity_level": 1, "irregularity_scale": 1.0, "irregularity_lines": 32,
                        "lambda_min": 2.0, "lambda_max": 120.0, "irregularity_seed": 1,
                        "harmonic_lateral_amplitude": 0.0, "harmonic_vertical_amplitude": 0.0,
                        "harmonic_wavelength": 20.0, "irregularity_file": "",
                        "wobble_lateral": 0.0, "wobble_vertical": 0.0, "wobble_wavelength": 2.0}


# ---- the element table ---------------------------------------------------------------------

@dataclass
class Alignment:
    """The element table, evaluated: horizontal elements on ``hs[i]..hs[i+1]`` with signed
    curvature ``k0[i]..k1[i]`` (1/m, + right), signed cant ``c0[i]..c1[i]`` (m) and heading
    ``chi[i]`` at their start (relative to the first straight: the azimuth is added by
    :class:`TrackGeometry`); vertical elements on ``vs[j]..vs[j+1]`` with gradient
    ``g0[j]..g1[j]`` (rise/run). ``hshape``/``vshape``: each element's transition shape,
    an index into :data:`SHAPES` (0 linear, 1 bloss; all linear when not given)."""

    hs: list[float]
    k0: list[float]
    k1: list[float]
    c0: list[float]
    c1: list[float]
    vs: list[float]
    g0: list[float]
    g1: list[float]
    hshape: list[int] | None = None
    vshape: list[int] | None = None

    def __post_init__(self):
        self.hshape = list(self.hshape) if self.hshape is not None else [0] * len(self.k0)
        self.vshape = list(self.vshape) if self.vshape is not None else [0] * len(self.g0)

    @property
    def length(self) -> float:
        return self.hs[-1]

    @property
    def breakpoints(self) -> list[float]:
        """Element ends of both layers inside (0, length), sorted, without repeats."""
        return sorted(set(self.hs[1:-1]) | set(self.vs[1:-1]))

    @classmethod
    def read(cls, path: Path | str = DEFAULT_TRACK) -> "Alignment":
        """Read and check a table; a problem is a UserError naming file, line and column."""
        path = Path(path)
        where = f"track_file {path}"
        try:
            with open(path, newline="", encoding="utf-8-sig") as f:
                rows = [(i + 1, r) for i, r in enumerate(csv.reader(f)) if any(c.strip() for c in r)]
        except OSError as e:
            raise UserError(f"{where}: cannot open ({e.strerror})") from None
        head = [c.strip() for c in rows[0][1]] if rows else []
        if head not in (list(COLUMNS), [*COLUMNS, TRANSITION]):
            raise UserError(f"{where}, line 1: header must be {','.join(COLUMNS)} (and optionally "
                            f",{TRANSITION})")
        ncol = len(head)
        hor, ver = [], []  # (line, kind, start, end, radius, cant, gradient, shape)
        for no, r in rows[1:]:
            if len(r) != ncol:
                raise UserError(f"{where}, line {no}: {len(r)} fields, expected {ncol}")
            kind = r[0].strip()
            if kind not in HORIZONTAL + VERTICAL:
                raise UserError(f"{where}, line {no}, column 1 (kind): '{kind}' is not one of "
                                f"{', '.join(HORIZONTAL + VERTICAL)}")
            vals = []
            for j in range(1, len(COLUMNS)):
                c = r[j].strip()
                if c == "":
                    vals.append(None)
                    continue
                try:
                    x = float(c)
                except ValueError:
                    x = math.nan
                if not math.isfinite(x):
                    raise UserError(f"{where}, line {no}, column {j + 1} ({COLUMNS[j]}): '{c}' is not "
                                    "a finite number")
                vals.append(x)
            start, end, radius, cant, grad = vals
            shape = r[6].strip() if ncol > 6 else ""
            if shape and shape not in SHAPES:
                raise UserError(f"{where}, line {no}, column 7 ({TRANSITION}): '{shape}' is not one of "
                                f"{', '.join(SHAPES)}")
            if shape and kind not in ("clothoid", "vertical_curve"):
                raise UserError(f"{where}, line {no}, column 7 ({TRANSITION}): only clothoid and "
                                f"vertical_curve rows take a transition shape, not a {kind}")
            shape = SHAPES.index(shape) if shape else 0
            for j, x in ((2, start), (3, end)):
                if x is None:
                    raise UserError(f"{where}, line {no}, column {j} ({COLUMNS[j - 1]}): missing")
            layer = hor if kind in HORIZONTAL else ver
            if not end > start:
                raise UserError(f"{where}, line {no}, column 3 (end_m): {end:g} is not greater than "
                                f"start_m {start:g} (distances must increase)")
            expected = layer[-1][3] if layer else 0.0
            if abs(start - expected) > 1e-9 * max(1.0, abs(expected)):
                name = "horizontal" if layer is hor else "vertical"
                raise UserError(f"{where}, line {no}, column 2 (start_m): {start:g} must equal "
                                f"{expected:g}, where the previous {name} element ends (no gaps or "
                                "overlaps, distances increasing)")
            start = expected
            if kind.startswith("curve"):
                if radius is None or not radius > 0:
                    raise UserError(f"{where}, line {no}, column 4 (radius_m): a {kind} needs a radius "
                                    f"> 0 m, got {'nothing' if radius is None else f'{radius:g}'}")
                cant = 0.0 if cant is None else cant
                if not 0.0 <= cant < MAX_CANT_MM:
                    raise UserError(f"{where}, line {no}, column 5 (cant_mm): {cant:g} must be in "
                                    f"[0, {MAX_CANT_MM:g}) mm")
            if kind == "grade":
                if grad is None or not abs(grad) < MAX_GRADIENT_PERMILLE:
                    raise UserError(f"{where}, line {no}, column 6 (gradient_permille): a grade needs "
                                    f"a gradient below {MAX_GRADIENT_PERMILLE:g} per mille in size")
            layer.append((no, kind, start, end, radius, cant, grad, shape))
        if not hor or not ver:
            raise UserError(f"{where}: needs horizontal ({', '.join(HORIZONTAL)}) and vertical "
                            f"({', '.join(VERTICAL)}) elements")
        if abs(hor[-1][3] - ver[-1][3]) > 1e-9 * hor[-1][3]:
            raise UserError(f"{where}: the horizontal elements end at {hor[-1][3]:g} m, the vertical "
                            f"ones at {ver[-1][3]:g} m: both must cover the same length")
        # horizontal: curvature and signed cant at each element's ends
        kap, cnt = [], []
        for no, kind, *_rest in hor:
            radius, cant = _rest[2], _rest[3]
            if kind == "straight":
                kap.append(0.0), cnt.append(0.0)
            elif kind == "clothoid":
                kap.append(None), cnt.append(None)
            else:
                sign = 1.0 if kind == "curve_right" else -1.0
                kap.append(sign / radius), cnt.append(sign * cant * 1e-3)
        k0, k1, c0, c1 = [], [], [], []
        for i, (no, kind, *_r) in enumerate(hor):
            if kind == "clothoid":
                if i == 0 or i == len(hor) - 1 or hor[i - 1][1] == "clothoid" or hor[i + 1][1] == "clothoid":
                    raise UserError(f"{where}, line {no}, column 1 (kind): a clothoid needs a straight "
                                    "or curve on both sides")
                k0.append(kap[i - 1]), k1.append(kap[i + 1]), c0.append(cnt[i - 1]), c1.append(cnt[i + 1])
            else:
                k0.append(kap[i]), k1.append(kap[i]), c0.append(cnt[i]), c1.append(cnt[i])
        g0, g1 = [], []
        for j, (no, kind, *_r) in enumerate(ver):
            if kind == "vertical_curve":
                if j == 0 or j == len(ver) - 1 or ver[j - 1][1] != "grade" or ver[j + 1][1] != "grade":
                    raise UserError(f"{where}, line {no}, column 1 (kind): a vertical_curve needs a "
                                    "grade on both sides")
                g0.append(ver[j - 1][6] * 1e-3), g1.append(ver[j + 1][6] * 1e-3)
            else:
                g0.append(_r[4] * 1e-3), g1.append(_r[4] * 1e-3)
        hs = [0.0] + [e[3] for e in hor]
        vs = [0.0] + [e[3] for e in ver]
        vs[-1] = hs[-1]
        return cls(hs, k0, k1, c0, c1, vs, g0, g1, [e[7] for e in hor], [e[7] for e in ver])


# ---- irregularity lines ----------------------------------------------------------------------

@dataclass
class IrregularityLines:
    """Spatial angular frequencies ``omega`` (rad/m), amplitudes (m) and phases (rad) of the
    alignment (``*_y``) and level (``*_z``) sinusoids."""

    omega: np.ndarray
    amp_y: np.ndarray
    amp_z: np.ndarray
    phase_y: np.ndarray
    phase_z: np.ndarray


def irregularity_lines(p: Mapping) -> IrregularityLines:
    """The lines of the documented spectrum for parameters ``p`` (see the module docstring)."""
    n = int(p["irregularity_lines"])
    level = int(p["irregularity_level"])
    if level == 0 or n == 0:
        z = np.zeros(0)
        return IrregularityLines(z, z, z, z, z)
    lo, hi = float(p["lambda_min"]), float(p["lambda_max"])
    W = 2.0 * math.pi / hi * (hi / lo) ** (np.arange(n + 1) / n)
    omega = np.sqrt(W[:-1] * W[1:])
    dW = W[1:] - W[:-1]
    scale = float(p["irregularity_scale"])
    amp_y = scale * np.sqrt(2.0 * psd_alignment(omega, level) * dW)
    amp_z = scale * np.sqrt(2.0 * psd_vertical(omega, level) * dW)
    u = SplitMix64(int(p["irregularity_seed"])).uniforms(2 * n)
    return IrregularityLines(omega, amp_y, amp_z, 2.0 * math.pi * u[:n], 2.0 * math.pi * u[n:])


def check_geometry_parameters(p: Mapping) -> None:
    """UserError naming the first bad parameter (the FMU checks the same)."""
    def need(ok, name, rule):
        if not ok:
            raise UserError(f"parameter {name} = {p[name]} {rule}")
    need(abs(p["start_latitude"]) < math.radians(89.0), "start_latitude", "must be within 89° of the equator (rad)")
    need(math.isfinite(p["start_longitude"]), "start_longitude", "must be finite (rad)")
    need(abs(p["start_height"]) < 1e5, "start_height", "must be within 100 km of the ellipsoid")
    need(math.isfinite(p["azimuth"]), "azimuth", "must be finite (rad)")
    need(p["irregularity_level"] in (0, 1, 2), "irregularity_level", "must be 0, 1 or 2")
    need(p["irregularity_scale"] >= 0, "irregularity_scale", "must be >= 0")
    need(0 <= p["irregularity_lines"] <= 4096, "irregularity_lines", "must be in 0..4096")
    need(p["lambda_min"] > 0, "lambda_min", "must be > 0 m")
    need(p["lambda_max"] > p["lambda_min"], "lambda_max", "must be greater than lambda_min")
    need(p["harmonic_wavelength"] > 0, "harmonic_wavelength", "must be > 0 m")
    need(p["wobble_wavelength"] > 0, "wobble_wavelength", "must be > 0 m")
    need(isinstance(p["irregularity_file"], str), "irregularity_file", "must be a file name (or empty)")
    for name in ("harmonic_lateral_amplitude", "harmonic_vertical_amplitude", "wobble_lateral",
                 "wobble_vertical"):
        need(abs(p[name]) < 0.1, name, "must be below 0.1 m in size")


# ---- small vector helpers (scalar, as the C) ---------------------------------------------------

def _add(*terms):
    """Sum of (factor, 3-vector) pairs."""
    return [sum(f * v[i] for f, v in terms) for i in range(3)]


@dataclass
class Point:
    """The geometry at one distance ``s``: body point ``r`` derivatives w.r.t. ``s`` (``r1``,
    ``r2``; ``r`` itself only when asked), the rail tangent ``q`` (not unit: ``|q|`` is
    d(rail path)/ds), the body's Euler angles in n0 (heading ``psi``, pitch ``theta``, roll
    ``phi``) and their derivatives w.r.t. ``s``."""

    s: float
    r: list | None
    r1: list
    r2: list
    q: list
    psi: float
    theta: float
    phi: float
    dpsi: float
    dtheta: float
    dphi: float
    # the same attitude as cosines and sines, as the C uses them (no trig)
    cpsi: float = 1.0
    spsi: float = 0.0
    cth: float = 1.0
    sth: float = 0.0
    cphi: float = 1.0
    sphi: float = 0.0


class TrackGeometry:
    """Design alignment + irregularities + wobble. ``params`` override
    :data:`DEFAULT_PLACEMENT` and :data:`DEFAULT_IRREGULARITY`; ``alignment`` an
    :class:`Alignment` or a table path (default the shipped table); a relative
    ``irregularity_file`` is read from ``base_dir`` (the FMU: its resources/)."""

    def __init__(self, params: Mapping | None = None, alignment: Alignment | Path | str | None = None,
                 base_dir: Path | str | None = None):
        self.p = {**DEFAULT_PLACEMENT, **DEFAULT_IRREGULARITY, **(params or {})}
        check_geometry_parameters(self.p)
        self.al = alignment if isinstance(alignment, Alignment) else Alignment.read(alignment or DEFAULT_TRACK)
        al = self.al
        self.chi = [float(self.p["azimuth"])]
        for i in range(len(al.k0)):
            L = al.hs[i + 1] - al.hs[i]
            self.chi.append(self.chi[i] + 0.5 * (al.k0[i] + al.k1[i]) * L)
        self.lines = irregularity_lines(self.p)
        self.table = None
        f = self.p["irregularity_file"]
        if f:
            path = Path(f) if Path(f).is_absolute() else Path(base_dir or ".") / f
            try:
                self.table = ProfileTable.from_csv(path)
            except ValueError as e:
                raise UserError(str(e).replace("profile_file", "irregularity_file", 1)) from None
            if self.table.s[0] > 0.0 or self.table.s[-1] < al.length:
                raise UserError(f"irregularity_file {path}: covers s = {self.table.s[0]:g}..{self.table.s[-1]:g} m, "
                                f"the track needs 0..{al.length:g} m")
        self._phase = [(math.cos(a), math.sin(a), math.cos(b), math.sin(b))
                       for a, b in zip(self.lines.phase_y.tolist(), self.lines.phase_z.tolist())]
        # design positions at the pieces' ends
        self.pieces = [0.0] + al.breakpoints + [al.length]
        self.P = [[0.0, 0.0, 0.0]]
        for k in range(len(self.pieces) - 1):
            d = self._integrate_tangent(self.pieces[k], self.pieces[k + 1])
            self.P.append([self.P[k][i] + d[i] for i in range(3)])
        lat0, lon0, h0 = self.p["start_latitude"], self.p["start_longitude"], self.p["start_height"]
        self.r0e = [float(x) for x in earth.lla_to_ecef(lat0, lon0, h0)]
        self.C_e_n0 = earth.ecef_to_ned_matrix(lat0, lon0).tolist()
        self.omega_n0 = [earth.RATE * math.cos(lat0), 0.0, -earth.RATE * math.sin(lat0)]

    @property
    def length(self) -> float:
        return self.al.length

    @property
    def kinks(self) -> list[float]:
        """Where some derivative of the geometry jumps, inside (0, length): the element ends
        and the rows of a measured irregularity table."""
        k = set(self.al.breakpoints)
        if self.table is not None:
            k |= {float(x) for x in self.table.s if 0.0 < x < self.length}
        return sorted(k)

    # -- design angles --
    def angles(self, s: float):
        """chi, chi', chi'', g, g', cant c (m, signed), c' at s (the shapes of the module
        docstring; the C has the same arithmetic)."""
        al = self.al
        i = min(max(bisect.bisect_right(al.hs, s) - 1, 0), len(al.k0) - 1)
        L = al.hs[i + 1] - al.hs[i]
        u = s - al.hs[i]
        if al.hshape[i]:  # bloss: f = x^2 (3 - 2 x), f' = 6 x (1 - x) / L
            x = u / L
            f, f1 = x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x) / L
            Dk, Dc = al.k1[i] - al.k0[i], al.c1[i] - al.c0[i]
            chi = self.chi[i] + u * al.k0[i] + Dk * L * (x * x * x * (1.0 - 0.5 * x))
            chi1, dk = al.k0[i] + Dk * f, Dk * f1
            c, dc = al.c0[i] + Dc * f, Dc * f1
        else:
            dk = (al.k1[i] - al.k0[i]) / L
            chi = self.chi[i] + u * (al.k0[i] + 0.5 * dk * u)
            chi1 = al.k0[i] + dk * u
            dc = (al.c1[i] - al.c0[i]) / L
            c = al.c0[i] + dc * u
        j = min(max(bisect.bisect_right(al.vs, s) - 1, 0), len(al.g0) - 1)
        Lv = al.vs[j + 1] - al.vs[j]
        if al.vshape[j]:
            x = (s - al.vs[j]) / Lv
            Dg = al.g1[j] - al.g0[j]
            g, dg = al.g0[j] + Dg * (x * x * (3.0 - 2.0 * x)), Dg * (6.0 * x * (1.0 - x) / Lv)
        else:
            dg = (al.g1[j] - al.g0[j]) / Lv
            g = al.g0[j] + dg * (s - al.vs[j])
        return chi, chi1, dk, g, dg, c, dc

    def tangent(self, s: float) -> list:
        chi, _, _, g, _, _, _ = self.angles(s)
        ct = 1.0 / math.sqrt(1.0 + g * g)
        return [ct * math.cos(chi), ct * math.sin(chi), -g * ct]

    def _integrate_tangent(self, a: float, b: float) -> list:
        m, h = 0.5 * (a + b), 0.5 * (b - a)
        acc = [0.0, 0.0, 0.0]
        for x, w in zip(GL16_X, GL16_W):
            t1, t2 = self.tangent(m - h * x), self.tangent(m + h * x)
            for i in range(3):
                acc[i] += w * (t1[i] + t2[i])
        return [h * v for v in acc]

    def design_position(self, s: float) -> list:
        """p(s) (m, n0), exact to round-off."""
        k = min(max(bisect.bisect_right(self.pieces, s) - 1, 0), len(self.pieces) - 2)
        d = self._integrate_tangent(self.pieces[k], s)
        return [self.P[k][i] + d[i] for i in range(3)]

    # -- irregularities --
    def offsets(self, s: float):
        """Rail alignment y and level z (m; right, down) and their first and second
        derivatives w.r.t. s: (y, y', y'', z, z', z'')."""
        p, ln = self.p, self.lines
        y = y1 = y2 = z = z1 = z2 = 0.0
        for k in range(ln.omega.size):
            # sin(w s + phi) = sin(w s) cos(phi) + cos(w s) sin(phi): one sincos per line
            w = float(ln.omega[k])
            sn, cs = math.sin(w * s), math.cos(w * s)
            cpy, spy, cpz, spz = self._phase[k]
            sy, cy = sn * cpy + cs * spy, cs * cpy - sn * spy
            sz, cz = sn * cpz + cs * spz, cs * cpz - sn * spz
            ay, az = float(ln.amp_y[k]), float(ln.amp_z[k])
            y += ay * sy
            y1 += ay * w * cy
            y2 -= ay * w * w * sy
            z += az * sz
            z1 += az * w * cz
            z2 -= az * w * w * sz
        Ay, Az = p["harmonic_lateral_amplitude"], p["harmonic_vertical_amplitude"]
        if Ay != 0.0 or Az != 0.0:
            w = 2.0 * math.pi / p["harmonic_wavelength"]
            sn, cs = math.sin(w * s), math.cos(w * s)
            y, y1, y2 = y + Ay * sn, y1 + Ay * w * cs, y2 - Ay * w * w * sn
            z, z1, z2 = z + Az * sn, z1 + Az * w * cs, z2 - Az * w * w * sn
        if self.table is not None:
            ta, tl, tr = _hermite2(self.table, s)
            y, y1, y2 = y + ta[0], y1 + ta[1], y2 + ta[2]
            z, z1, z2 = z + 0.5 * (tl[0] + tr[0]), z1 + 0.5 * (tl[1] + tr[1]), z2 + 0.5 * (tl[2] + tr[2])
        return y, y1, y2, z, z1, z2

    def wobble(self, s: float):
        """Body offsets from the rail centre line (lateral, vertical) and derivatives."""
        p = self.p
        Ay, Az = p["wobble_lateral"], p["wobble_vertical"]
        if Ay == 0.0 and Az == 0.0:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        w = 2.0 * math.pi / p["wobble_wavelength"]
        sn, cs = math.sin(w * s), math.cos(w * s)
        return Ay * sn, Ay * w * cs, -Ay * w * w * sn, Az * sn, Az * w * cs, -Az * w * w * sn

    # -- the point --
    def point(self, s: float, position: bool = False) -> Point:
        """Body point and attitude at ``s`` (see :class:`Point`)."""
        chi, k, dk, g, dg, c, dc = self.angles(s)
        den = 1.0 + g * g
        ct = 1.0 / math.sqrt(den)
        st = g * ct
        th1 = dg / den
        sc, cc = math.sin(chi), math.cos(chi)
        H, Y, D = [cc, sc, 0.0], [-sc, cc, 0.0], [0.0, 0.0, 1.0]
        T = _add((ct, H), (-st, D))
        Z = _add((st, H), (ct, D))  # the normal of T in the vertical plane
        T1 = _add((-th1, Z), (ct * k, Y))
        Y1 = [-k * H[0], -k * H[1], 0.0]
        Y2 = _add((-dk, H), (-k * k, Y))
        # offsets: y along Y (turns with the heading), z along the fixed vertical D
        y, y1, y2, z, z1, z2 = self.offsets(s)
        q = _add((1.0, T), (y1, Y), (y, Y1), (z1, D))
        q1 = _add((1.0, T1), (y2, Y), (2.0 * y1, Y1), (y, Y2), (z2, D))
        wy, wy1, wy2, wz, wz1, wz2 = self.wobble(s)
        r1 = _add((1.0, q), (wy1, Y), (wy, Y1), (wz1, D))
        r2 = _add((1.0, q1), (wy2, Y), (2.0 * wy1, Y1), (wy, Y2), (wz2, D))
        r = None
        if position:
            pd = self.design_position(s)
            r = _add((1.0, pd), (y + wy, Y), (z + wz, D))
        # attitude: x along the rail tangent q, roll by the cant
        hh = q[0] * q[0] + q[1] * q[1]
        h = math.sqrt(hh)
        psi = math.atan2(q[1], q[0])
        theta = math.atan2(-q[2], h)
        dpsi = (q[0] * q1[1] - q[1] * q1[0]) / hh
        dh = (q[0] * q1[0] + q[1] * q1[1]) / h
        dtheta = (-h * q1[2] + q[2] * dh) / (hh + q[2] * q[2])
        sphi = c / RAIL_BASE
        phi = math.asin(sphi)
        cphi = math.sqrt(1.0 - sphi * sphi)
        dphi = dc / (RAIL_BASE * cphi)
        nq = math.sqrt(hh + q[2] * q[2])
        return Point(s, r, r1, r2, q, psi, theta, phi, dpsi, dtheta, dphi,
                     q[0] / h, q[1] / h, h / nq, -q[2] / nq, cphi, sphi)

    # -- vectorised helpers for studies --
    def design_positions(self, s) -> np.ndarray:
        """Design centre line p(s) (m, n0), shape (n, 3)."""
        return np.array([self.design_position(float(x)) for x in np.atleast_1d(s)])

    def rail_positions(self, s) -> np.ndarray:
        """True rail centre line p + y Y + z D (m, n0; no wobble), shape (n, 3)."""
        out = []
        for x in np.atleast_1d(s):
            x = float(x)
            chi = self.angles(x)[0]
            y, _, _, z, _, _ = self.offsets(x)
            pd = self.design_position(x)
            out.append([pd[0] - y * math.sin(chi), pd[1] + y * math.cos(chi), pd[2] + z])
        return np.array(out)

    def to_geodetic(self, p_n0) -> np.ndarray:
        """n0 positions (n, 3) -> latitude, longitude (rad), height (m), shape (n, 3)."""
        p = np.atleast_2d(np.asarray(p_n0, dtype=float))
        r = np.asarray(self.r0e) + p @ np.asarray(self.C_e_n0)
        return np.array([ecef_to_lla(*x) for x in r])

    def true_chord_irregularity(self, s, chord_start: float, chord_length: float = 30.0,
                                offset: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
        """Jiang et al. (2017) eq. 1 for the true rail against the design, at points ``s`` of
        the chord ``[chord_start, chord_start + chord_length]`` (``s + offset`` must lie on it
        too): (alignment, level) in m."""
        return chord_irregularity(self.rail_positions, self.design_positions, s, chord_start,
                                  chord_length, offset)


def _hermite2(table: ProfileTable, s: float):
    """The table's cubic Hermite (Catmull-Rom slopes) at s: (value, d/ds, d2/ds2) of each of
    its three columns; the row interval is the last with s_i <= s (the C's arithmetic)."""
    ts = table.s
    i = min(max(bisect.bisect_right(ts.tolist(), s) - 1, 0), ts.size - 2)
    h = float(ts[i + 1] - ts[i])
    t = (s - float(ts[i])) / h
    t2 = t * t
    out = []
    for c in range(3):
        y0, y1 = float(table.values[c, i]), float(table.values[c, i + 1])
        m0, m1 = float(table.slopes[c, i]), float(table.slopes[c, i + 1])
        v = (2.0 * t2 * t - 3.0 * t2 + 1.0) * y0 + (t2 * t - 2.0 * t2 + t) * h * m0 \
            + (-2.0 * t2 * t + 3.0 * t2) * y1 + (t2 * t - t2) * h * m1
        d = ((6.0 * t2 - 6.0 * t) * y0 + (-6.0 * t2 + 6.0 * t) * y1) / h \
            + (3.0 * t2 - 4.0 * t + 1.0) * m0 + (3.0 * t2 - 2.0 * t) * m1
        d2 = ((12.0 * t - 6.0) * y0 + (6.0 - 12.0 * t) * y1) / (h * h) \
            + ((6.0 * t - 4.0) * m0 + (6.0 * t - 2.0) * m1) / h
        out.append((v, d, d2))
    return out


def ecef_to_lla(x: float, y: float, z: float) -> tuple[float, float, float]:
    """ECEF (m) -> geodetic latitude, longitude (rad), height (m) by fixed-point iteration on
    the latitude (5 iterations: converged to round-off within ~100 km of the ellipsoid and
    away from the poles); the same arithmetic as ``Earth.h``'s ``earth_ecef_to_lla``."""
    pr = math.hypot(x, y)
    lon = math.atan2(y, x)
    lat = math.atan2(z, pr * (1.0 - earth.E2))
    for _ in range(5):
        s = math.sin(lat)
        N = earth.A / math.sqrt(1.0 - earth.E2 * s * s)
        h = pr / math.cos(lat) - N
        lat = math.atan2(z, pr * (1.0 - earth.E2 * N / (N + h)))
    s = math.sin(lat)
    N = earth.A / math.sqrt(1.0 - earth.E2 * s * s)
    return lat, lon, pr / math.cos(lat) - N


# ---- chords (Jiang et al. (2017), eqs. 1, 13-15) --------------------------------------------

def vector_distance(points, a, b) -> tuple[np.ndarray, np.ndarray]:
    """Alignment and level (m) of ``points`` (n, 3; NED in n0) from the chord ``a`` -> ``b``
    (eq. 14 with eq. 15's angles). Stacked chords broadcast: ``a``, ``b`` (..., 3) with
    ``points`` (..., n, 3) give (..., n) (many chords, or many sampled error trajectories,
    in one call)."""
    points, a, b = (np.asarray(x, dtype=float) for x in (points, a, b))
    d = (b - a)[..., None, :]
    hor = np.hypot(d[..., 0], d[..., 1])
    lc = np.sqrt(hor * hor + d[..., 2] * d[..., 2])
    sa, ca = d[..., 1] / hor, d[..., 0] / hor
    sl, cl = -d[..., 2] / lc, hor / lc
    e = np.atleast_2d(points) - a[..., None, :]
    return (-e[..., 0] * sa + e[..., 1] * ca,
            e[..., 0] * sl * ca + e[..., 1] * sl * sa + e[..., 2] * cl)


def chord_irregularity(position: Callable, design: Callable, s, chord_start: float,
                       chord_length: float = 30.0, offset: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1, ``(d_s - d_{s+offset}) - (dbar_s - dbar_{s+offset})``: ``position(s)`` gives the
    true (or measured) points, ``design(s)`` the design points, both (n, 3) in n0, each
    against its own chord ``[chord_start, chord_start + chord_length]``. Returns
    (alignment, level) at ``s`` (m)."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    c0, c1 = chord_start, chord_start + chord_length
    if np.any(s < c0 - 1e-9) or np.any(s + offset > c1 + 1e-9):
        raise ValueError(f"points s and s + {offset:g} must lie on the chord [{c0:g}, {c1:g}] m")
    out = []
    for f in (position, design):
        ends = f(np.array([c0, c1]))
        ya, za = vector_distance(f(s), ends[0], ends[1])
        yb, zb = vector_distance(f(s + offset), ends[0], ends[1])
        out.append((ya - yb, za - zb))
    return out[0][0] - out[1][0], out[0][1] - out[1][1]


def chord_irregularity_along(track: TrackGeometry, ds: float = 0.5, chord_length: float = 30.0,
                             offset: float = 5.0, position: Callable | None = None):
    """Eq. 1 along the whole track on consecutive chords ``[0, l], [l, 2 l], ...``, at
    ``s = c, c + ds, ..., c + l - offset`` on each: (s, alignment, level), m. ``position``
    defaults to the true rail (:meth:`TrackGeometry.rail_positions`)."""
    position = position or track.rail_positions
    S, A, V = [], [], []
    c = 0.0
    while c + chord_length <= track.length + 1e-9:
        s = c + np.arange(0.0, chord_length - offset + 1e-9, ds)
        a, v = chord_irregularity(position, track.design_positions, s, c, chord_length, offset)
        S.append(s), A.append(a), V.append(v)
        c += chord_length
    return np.concatenate(S), np.concatenate(A), np.concatenate(V)
