"""3-D track geometry (models/track/geometry.py): positions against closed forms (circle,
clothoid by Fresnel integrals, parabolic vertical curve, Bloss transitions and cubic-blended
vertical curves against adaptive quadrature), continuity of curvature and cant (and of their
rates, so of the roll, pitch and yaw rates, where the transitions are bloss),
the analytic derivatives against the positions, the chord irregularity of Jiang et al. (2017)
eq. 1 for a pure sinusoid, and one-line errors for bad element tables."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import fresnel

from railfmu.models.errors import UserError
from railfmu.models import earth
from railfmu.models.track.geometry import (
    DEFAULT_TRACK,
    Alignment,
    TrackGeometry,
    chord_irregularity_along,
    ecef_to_lla,
    irregularity_lines,
    vector_distance,
)

HEADER7 = "kind,start_m,end_m,radius_m,cant_mm,gradient_permille,transition\n"

HEADER = "kind,start_m,end_m,radius_m,cant_mm,gradient_permille\n"
FLAT = {"irregularity_level": 0}


def table(tmp_path, rows: str, name="t.csv"):
    p = tmp_path / name
    p.write_text(HEADER + rows)
    return p


def _t7(tmp_path, rows: str, name="t7.csv"):
    """A table with the transition column."""
    p = tmp_path / name
    p.write_text(HEADER7 + rows)
    return p


@pytest.fixture
def spiral(tmp_path):
    """straight 50 m, clothoid 60 m into R 300 m right (70 mm cant), curve 90 m; level."""
    return TrackGeometry({**FLAT, "azimuth": 0.3}, table(tmp_path, (
        "straight,0,50,,,\nclothoid,50,110,,,\ncurve_right,110,200,300,70,\ngrade,0,200,,,0\n")))


def test_clothoid_and_circle_against_fresnel_and_closed_form(spiral):
    R, L, chi0 = 300.0, 60.0, 0.3
    a = math.sqrt(math.pi * R * L)  # chi(u) = u^2 / (2 R L) = pi/2 (u / a)^2

    def local(u):  # clothoid in its own frame: along chi0, right of it
        S, C = fresnel(u / a)
        return a * C, a * S

    def to_ned(x, y, origin):
        return np.array([origin[0] + x * math.cos(chi0) - y * math.sin(chi0),
                         origin[1] + x * math.sin(chi0) + y * math.cos(chi0), 0.0])

    start = np.array([50 * math.cos(chi0), 50 * math.sin(chi0), 0.0])
    for u in (0.0, 7.3, 30.0, 59.99, 60.0):
        x, y = local(u)
        assert np.abs(spiral.design_position(50.0 + u) - to_ned(x, y, start)).max() < 1e-11
    # the circle continues from the clothoid's end with its heading and radius R
    x, y = local(L)
    p1 = to_ned(x, y, start)
    chi1 = chi0 + L / (2 * R)
    centre = p1 + R * np.array([-math.sin(chi1), math.cos(chi1), 0.0])
    for u in (0.0, 12.5, 45.0, 90.0):
        chi = chi1 + u / R
        expected = centre + R * np.array([math.sin(chi), -math.cos(chi), 0.0])
        assert np.abs(np.array(spiral.design_position(110.0 + u)) - expected).max() < 1e-10
        assert spiral.angles(110.0 + u)[0] == pytest.approx(chi, abs=1e-15)


def test_parabolic_vertical_curve_against_closed_form(tmp_path):
    # gradient g linear in s from 0 to 12 per mille over [100, 250] m: dz/ds = g / sqrt(1 + g^2)
    tr = TrackGeometry({**FLAT, "azimuth": 0.0}, table(tmp_path, (
        "straight,0,400,,,\ngrade,0,100,,,0\nvertical_curve,100,250,,,\ngrade,250,400,,,12\n")))
    dg = 0.012 / 150.0
    for s in (100.0, 180.0, 250.0, 300.0):
        u = min(s, 250.0) - 100.0
        g = dg * u
        north = 100.0 + math.asinh(g) / dg + (s - 250.0 if s > 250 else 0.0) / math.sqrt(1 + 0.012**2)
        up = (g * g / (math.sqrt(1 + g * g) + 1) / dg
              + (s - 250.0 if s > 250 else 0.0) * 0.012 / math.sqrt(1 + 0.012**2))
        p = tr.design_position(s)
        assert p[0] == pytest.approx(north, abs=1e-11) and p[2] == pytest.approx(-up, abs=1e-12)
    assert tr.point(180.0).theta == pytest.approx(math.atan(dg * 80.0), abs=1e-15)


def test_bloss_transition_against_closed_forms(tmp_path):
    """straight 50 m, Bloss transition 60 m into R 300 m right with 70 mm cant, curve 90 m.
    With x = u / L: curvature x^2 (3 - 2 x) / R, its rate 6 x (1 - x) / (L R) (zero at both
    ends, 1.5 / (L R) at mid-length), heading chi0 + (u^3 / L^2 - u^4 / (2 L^3)) / R, at the
    end L / (2 R) as the clothoid's; cant likewise. Positions against adaptive quadrature of
    the closed-form heading (scipy), independent of the Gauss-Legendre pieces."""
    R, L, chi0, c1 = 300.0, 60.0, 0.3, 0.07
    tr = TrackGeometry({**FLAT, "azimuth": chi0}, _t7(tmp_path, (
        "straight,0,50,,,,\nclothoid,50,110,,,,bloss\ncurve_right,110,200,300,70,,\ngrade,0,200,,,0,\n")))
    assert tr.al.hshape == [0, 1, 0]

    def chi(u):
        return chi0 + (u**3 / L**2 - u**4 / (2 * L**3)) / R

    start = np.array([50 * math.cos(chi0), 50 * math.sin(chi0), 0.0])
    for u in (0.0, 7.3, 30.0, 59.99, 60.0):
        x = u / L
        a = tr.angles(50.0 + u)
        assert a[0] == pytest.approx(chi(u), abs=1e-15)
        assert a[1] == pytest.approx(x * x * (3 - 2 * x) / R, abs=1e-17)
        assert a[2] == pytest.approx(6 * x * (1 - x) / (L * R), abs=1e-18)
        assert a[5] == pytest.approx(c1 * x * x * (3 - 2 * x), abs=1e-17)
        assert a[6] == pytest.approx(c1 * 6 * x * (1 - x) / L, abs=1e-18)
        n = quad(lambda v: math.cos(chi(v)), 0.0, u, epsabs=1e-12, epsrel=0.0)[0] if u else 0.0
        e = quad(lambda v: math.sin(chi(v)), 0.0, u, epsabs=1e-12, epsrel=0.0)[0] if u else 0.0
        assert np.abs(tr.design_position(50.0 + u) - (start + [n, e, 0.0])).max() < 1e-11
    # the end: heading L / (2 R) as for the clothoid; rates zero at both ends, the peak 1.5 times
    assert tr.angles(110.0)[0] == pytest.approx(chi0 + L / (2 * R), abs=1e-15)
    for s in (50.0, 110.0 - 1e-12):
        a = tr.angles(s)
        assert abs(a[2]) < 1e-16 and abs(a[6]) < 1e-15
    assert tr.angles(80.0)[2] == pytest.approx(1.5 / (L * R), rel=1e-14)
    # the circle continues from the transition's end with its heading and radius R
    p1 = np.array(tr.design_position(110.0))
    chi1 = chi0 + L / (2 * R)
    centre = p1 + R * np.array([-math.sin(chi1), math.cos(chi1), 0.0])
    for u in (12.5, 90.0):
        c = chi1 + u / R
        assert np.abs(np.array(tr.design_position(110.0 + u)) - centre
                      - R * np.array([math.sin(c), -math.cos(c), 0.0])).max() < 1e-10


def test_bloss_vertical_curve_against_quadrature(tmp_path):
    """The gradient blended by 3 x^2 - 2 x^3 from 0 to 12 per mille over [100, 250] m: the
    vertical curvature 6 x (1 - x) 0.012 / 150 is zero at both ends (pitch rate continuous);
    down = -int g / sqrt(1 + g^2) ds, north = int 1 / sqrt(1 + g^2) ds by adaptive quadrature."""
    tr = TrackGeometry({**FLAT, "azimuth": 0.0}, _t7(tmp_path, (
        "straight,0,400,,,,\ngrade,0,100,,,0,\nvertical_curve,100,250,,,,bloss\ngrade,250,400,,,12,\n")))

    def g(s):
        x = min(max((s - 100.0) / 150.0, 0.0), 1.0)
        return 0.012 * x * x * (3 - 2 * x)

    for s in (100.0, 141.0, 175.0, 250.0, 300.0):
        # north - s: the integrand 1 / sqrt(1 + g^2) - 1 is small, so its absolute tolerance is tight
        pts = [250.0] if s > 250 else None
        north = s + (quad(lambda v: -g(v) ** 2 / (1 + math.sqrt(1 + g(v) ** 2)) / math.sqrt(1 + g(v) ** 2),
                          100.0, s, epsabs=1e-15, epsrel=0.0, points=pts)[0] if s > 100 else 0.0)
        up = quad(lambda v: g(v) / math.sqrt(1 + g(v) ** 2), 100.0, s, epsabs=1e-13, epsrel=0.0,
                  points=pts)[0] if s > 100 else 0.0
        p = tr.design_position(s)
        assert p[0] == pytest.approx(north, abs=1e-11) and p[2] == pytest.approx(-up, abs=1e-12)
        assert tr.angles(s)[3] == pytest.approx(g(s), abs=1e-17)
    assert abs(tr.angles(100.0)[4]) < 1e-18 and abs(tr.angles(250.0 - 1e-12)[4]) < 1e-15
    assert tr.angles(175.0)[4] == pytest.approx(1.5 * 0.012 / 150.0, rel=1e-14)
    assert tr.point(175.0).dtheta == pytest.approx(1.5 * 0.012 / 150.0 / (1 + 0.006**2), rel=1e-12)


def test_rates_are_continuous_at_every_element_end():
    """The shipped track (all bloss) with its irregularities: curvature rate, cant rate,
    vertical curvature and so the yaw, pitch and roll rates per metre (dpsi, dtheta, dphi of
    Point) join at every element end; the same table with linear transitions has jumps there
    (a check that would catch the shape not being applied)."""
    tr = TrackGeometry()
    linear_table = DEFAULT_TRACK.read_text().replace(",bloss", ",linear")
    assert tr.al.hshape == [0, 1, 0, 1, 0, 1, 0, 1, 0] and tr.al.vshape == [0, 1, 0, 1, 0]
    worst, jumps = 0.0, []
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "linear.csv"
        f.write_text(linear_table)
        lin = TrackGeometry(alignment=f)
        for b in tr.al.breakpoints:
            for geo, acc in ((tr, None), (lin, jumps)):
                lo, hi = geo.point(b - 1e-9), geo.point(b + 1e-9)
                a_lo, a_hi = geo.angles(b - 1e-9), geo.angles(b + 1e-9)
                d = max(abs(hi.dpsi - lo.dpsi), abs(hi.dtheta - lo.dtheta), abs(hi.dphi - lo.dphi),
                        abs(a_hi[2] - a_lo[2]), abs(a_hi[4] - a_lo[4]), abs(a_hi[6] - a_lo[6]))
                if acc is None:
                    worst = max(worst, d)
                else:
                    acc.append(d)
    assert worst < 1e-11, worst
    assert min(jumps) > 1e-5  # cant ramps 0.06 / (1.5 40), vertical curves 4e-3 / 60 ...


def test_curvature_cant_and_heading_are_continuous():
    tr = TrackGeometry(FLAT)
    for b in tr.al.breakpoints:
        lo, hi = tr.angles(b - 1e-9), tr.angles(b + 1e-9)
        chi, k, _, g, _, c, _ = zip(lo, hi)
        assert abs(chi[1] - chi[0]) < 1e-11 and abs(k[1] - k[0]) < 1e-11
        assert abs(g[1] - g[0]) < 1e-12 and abs(c[1] - c[0]) < 1e-11
        assert np.abs(np.diff(tr.design_positions([b - 1e-9, b + 1e-9]), axis=0)).max() < 3e-9
    # the shipped table: R 400 m right with 100 mm cant, R 600 m left with 60 mm
    assert tr.angles(180.0)[1] == pytest.approx(1 / 400) and tr.angles(180.0)[5] == pytest.approx(0.1)
    assert tr.angles(450.0)[1] == pytest.approx(-1 / 600) and tr.angles(450.0)[5] == pytest.approx(-0.06)
    assert tr.point(180.0).phi == pytest.approx(math.asin(0.1 / 1.5))  # right side down in a right curve
    assert tr.angles(100.0)[1] == pytest.approx(0.5 / 400) and tr.angles(100.0)[5] == pytest.approx(0.05)


@pytest.mark.parametrize("s", [35.0, 97.3, 181.0, 205.5, 420.0, 555.0])
def test_analytic_derivatives_match_the_positions(s):
    """r', r'' and the attitude rates of Point against central differences of the positions
    (irregularities and wobble on): an independent check of every derivative formula."""
    tr = TrackGeometry({"wobble_lateral": 2e-3, "wobble_vertical": 1e-3, "harmonic_lateral_amplitude": 1e-3,
                        "harmonic_vertical_amplitude": 5e-4, "harmonic_wavelength": 7.0})
    d = 1e-3
    pt = tr.point(s, position=True)
    r = [np.array(tr.point(s + k * d, position=True).r) for k in (-2, -1, 1, 2)]
    r1 = (8 * (r[2] - r[1]) - (r[3] - r[0])) / (12 * d)
    r2 = (-(r[3] + r[0]) + 16 * (r[2] + r[1]) - 30 * np.array(pt.r)) / (12 * d * d)
    assert np.abs(r1 - pt.r1).max() < 1e-9
    assert np.abs(r2 - pt.r2).max() < 2e-6
    assert np.linalg.norm(pt.r1) == pytest.approx(1.0, abs=1e-4)
    e = [tr.point(s + k * d) for k in (-2, -1, 1, 2)]
    for name in ("psi", "theta", "phi"):
        v = [getattr(x, name) for x in e]
        num = (8 * (v[2] - v[1]) - (v[3] - v[0])) / (12 * d)
        assert num == pytest.approx(getattr(pt, "d" + name), abs=1e-9)
    # the body x axis follows the rail tangent q, not the wobbling body path
    q = np.array(pt.q) / np.linalg.norm(pt.q)
    assert math.atan2(q[1], q[0]) == pt.psi and math.isclose(math.asin(-q[2]), pt.theta, abs_tol=1e-15)


def test_chord_irregularity_of_a_pure_sinusoid(tmp_path):
    """Straight, level track at N45E with y = A sin(2 pi s / lambda) (right) and
    z = B sin(...) (down): eq. 1 against its closed form on the chord [c, c + 30]. With
    dy = y(c + 30) - y(c), dz likewise, hor = sqrt(30^2 + dy^2), l = sqrt(hor^2 + dz^2), a
    point x has the vector distance ``d_y = ((y(x) - y(c)) 30 - (x - c) dy) / hor`` and
    ``d_z = ((z(x) - z(c)) hor - a_h dz) / l``, ``a_h = ((x - c) 30 + (y(x) - y(c)) dy) / hor``
    its distance along the chord's horizontal direction; the design's is 0."""
    A, B, lam = 2e-3, 1.5e-3, 13.0
    tr = TrackGeometry({**FLAT, "harmonic_lateral_amplitude": A, "harmonic_vertical_amplitude": B,
                        "harmonic_wavelength": lam},
                       table(tmp_path, "straight,0,120,,,\ngrade,0,120,,,0\n"))
    y = lambda s: A * np.sin(2 * np.pi * s / lam)  # noqa: E731
    z = lambda s: B * np.sin(2 * np.pi * s / lam)  # noqa: E731

    def closed(s, c):
        dy, dz = y(c + 30) - y(c), z(c + 30) - z(c)
        hor = math.hypot(30.0, dy)
        lc = math.hypot(hor, dz)

        def d(x):
            ah = ((x - c) * 30.0 + (y(x) - y(c)) * dy) / hor
            return ((y(x) - y(c)) * 30.0 - (x - c) * dy) / hor, ((z(x) - z(c)) * hor - ah * dz) / lc
        (a0, v0), (a5, v5) = d(s), d(s + 5.0)
        return a0 - a5, v0 - v5

    for c in (0.0, 30.0, 60.0):
        s = c + np.linspace(0, 25, 11)
        ali, lev = tr.true_chord_irregularity(s, c)
        ali_c, lev_c = closed(s, c)
        assert np.abs(ali - ali_c).max() < 1e-13 and np.abs(lev - lev_c).max() < 1e-13
        assert np.abs(ali).max() > 1e-3 and np.abs(lev).max() > 1e-3
    s, a, v = chord_irregularity_along(tr, ds=1.0)
    assert s.size == 4 * 26 and np.all(np.isfinite(a))
    # the design alone has no irregularity, also on curves and vertical curves
    tr0 = TrackGeometry(FLAT)
    _, a0, v0 = chord_irregularity_along(tr0, ds=2.5)
    assert np.abs(a0).max() < 1e-12 and np.abs(v0).max() < 1e-12


def test_vector_distance_of_points_on_a_tilted_chord():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([21.0, 12.0, 2.5])
    pts = a + np.outer([0.0, 0.3, 1.0], b - a)
    y, z = vector_distance(pts, a, b)
    assert np.abs(y).max() < 1e-14 and np.abs(z).max() < 1e-14
    # 1 mm to the right of the chord in the horizontal plane, 1 mm below
    hor = (b - a)[:2] / np.linalg.norm((b - a)[:2])
    y, z = vector_distance(a + 0.5 * (b - a) + 1e-3 * np.array([-hor[1], hor[0], 0.0]), a, b)
    assert y[0] == pytest.approx(1e-3, rel=1e-12)


def test_irregularity_lines_follow_the_spectrum():
    from railfmu.models.track.irregularity import psd_alignment, psd_vertical
    p = {"irregularity_level": 1, "irregularity_scale": 1.0, "irregularity_lines": 32, "lambda_min": 2.0,
         "lambda_max": 120.0, "irregularity_seed": 1}
    ln = irregularity_lines(p)
    W = 2 * np.pi / 120.0 * 60.0 ** (np.arange(33) / 32)
    assert np.allclose(ln.omega, np.sqrt(W[1:] * W[:-1]), rtol=1e-15)
    assert np.allclose(ln.amp_y**2 / 2, psd_alignment(ln.omega, 1) * np.diff(W), rtol=1e-14)
    assert np.allclose(ln.amp_z**2 / 2, psd_vertical(ln.omega, 1) * np.diff(W), rtol=1e-14)
    assert np.all((ln.phase_y >= 0) & (ln.phase_y < 2 * np.pi)) and ln.phase_y[0] != ln.phase_z[0]
    tr = TrackGeometry()
    s = 123.4
    y = sum(a * math.sin(w * s + f) for a, w, f in zip(ln.amp_y, ln.omega, ln.phase_y))
    assert tr.offsets(s)[0] == pytest.approx(y, abs=1e-17)
    assert irregularity_lines({**p, "irregularity_level": 0}).omega.size == 0


def test_ecef_to_lla_inverts_lla_to_ecef():
    for lat, lon, h in ((0.53, 2.0, 25.0), (-1.2, -0.3, 3000.0), (1.0, 3.1, -50.0)):
        r = earth.lla_to_ecef(lat, lon, h)
        lat2, lon2, h2 = ecef_to_lla(*r)
        assert abs(lat2 - lat) < 2e-16 * 4 and abs(lon2 - lon) < 1e-15 and abs(h2 - h) < 2e-9


def test_positions_map_exactly_to_geodetic():
    """n0 is the start point's NED: earth.ned_from_origin of the geodetic positions gives the
    n0 positions back."""
    tr = TrackGeometry()
    p = tr.rail_positions([0.0, 150.0, 600.0])
    lla = tr.to_geodetic(p)
    back = earth.ned_from_origin(lla[:, 0], lla[:, 1], lla[:, 2], tr.p["start_latitude"],
                                 tr.p["start_longitude"], tr.p["start_height"])
    assert np.abs(back - p).max() < 1e-8
    assert tr.length == 600.0 and np.linalg.norm(p[2]) > 500


@pytest.mark.parametrize("rows, message", [
    ("straight,0,50,,,\nstraight,40,100,,,\ngrade,0,100,,,0\n", r"line 3, column 2 \(start_m\): 40 must equal 50"),
    ("straight,0,50,,,\nstraight,50,45,,,\ngrade,0,45,,,0\n", r"line 3, column 3 \(end_m\): 45 is not greater"),
    ("straight,0,50,,,\ncurve_left,50,100,-300,,\ngrade,0,100,,,0\n",
     r"line 3, column 4 \(radius_m\): a curve_left needs a radius > 0"),
    ("straight,0,50,,,\ncurve_left,50,100,300,250,\ngrade,0,100,,,0\n", r"line 3, column 5 \(cant_mm\)"),
    ("clothoid,0,50,,,\ncurve_left,50,100,300,,\ngrade,0,100,,,0\n", r"line 2, column 1 \(kind\): a clothoid needs"),
    ("straight,0,100,,,\nvertical_curve,0,100,,,\n", r"line 3, column 1 \(kind\): a vertical_curve needs a grade"),
    ("straight,0,100,,,\ngrade,0,90,,,0\n", r"horizontal elements end at 100 m, the vertical ones at 90 m"),
    ("spiral,0,100,,,\ngrade,0,100,,,0\n", r"line 2, column 1 \(kind\): 'spiral' is not one of"),
    ("straight,0,1x0,,,\ngrade,0,100,,,0\n", r"line 2, column 3 \(end_m\): '1x0' is not a finite number"),
    ("straight,0,100,,,\ngrade,0,100,,,\n", r"line 3, column 6 \(gradient_permille\)"),
    ("straight,0,100,,\n", r"line 2: 5 fields, expected 6"),
    ("straight,0,100,,,,\ngrade,0,100,,,0\n", r"line 2: 7 fields, expected 6"),
])
def test_bad_tables_are_one_line_user_errors(tmp_path, rows, message):
    p = table(tmp_path, rows)
    with pytest.raises(UserError, match=message) as e:
        Alignment.read(p)
    assert "\n" not in str(e.value) and str(p) in str(e.value)


@pytest.mark.parametrize("rows, message", [
    ("straight,0,50,,,,\nclothoid,50,90,,,,cubic\ncurve_left,90,100,300,,,\ngrade,0,100,,,0,\n",
     r"line 3, column 7 \(transition\): 'cubic' is not one of linear, bloss"),
    ("straight,0,100,,,,bloss\ngrade,0,100,,,0,\n",
     r"line 2, column 7 \(transition\): only clothoid and vertical_curve rows take a transition shape, "
     "not a straight"),
    ("straight,0,100,,,\ngrade,0,100,,,0,\n", r"line 2: 6 fields, expected 7"),
])
def test_bad_transitions_are_one_line_user_errors(tmp_path, rows, message):
    p = _t7(tmp_path, rows)
    with pytest.raises(UserError, match=message) as e:
        Alignment.read(p)
    assert "\n" not in str(e.value) and str(p) in str(e.value)


def test_transition_column_is_optional_and_blank_is_linear(tmp_path):
    """A six-column table (before the column existed) and blank or 'linear' cells give the
    same, linear, geometry."""
    p6 = table(tmp_path, "straight,0,50,,,\nclothoid,50,90,,,\ncurve_left,90,100,300,40,\n"
                         "grade,0,30,,,0\nvertical_curve,30,70,,,\ngrade,70,100,,,5\n", name="six.csv")
    p7 = _t7(tmp_path, "straight,0,50,,,,\nclothoid,50,90,,,,linear\ncurve_left,90,100,300,40,,\n"
                       "grade,0,30,,,0,\nvertical_curve,30,70,,,,\ngrade,70,100,,,5,\n")
    a6, a7 = Alignment.read(p6), Alignment.read(p7)
    assert a6 == a7 and a6.hshape == [0, 0, 0] and a6.vshape == [0, 0, 0]
    t6, t7 = TrackGeometry(FLAT, a6), TrackGeometry(FLAT, a7)
    assert t6.design_position(99.0) == t7.design_position(99.0)
    assert t6.angles(60.0)[1] == pytest.approx(-0.25 / 300, rel=1e-14)  # linear: 10 of 40 m (bloss: 0.156)


def test_missing_table_and_bad_header(tmp_path):
    with pytest.raises(UserError, match="cannot open"):
        Alignment.read(tmp_path / "none.csv")
    p = tmp_path / "h.csv"
    p.write_text("kind,start,end\n")
    with pytest.raises(UserError, match="line 1: header must be"):
        Alignment.read(p)
    assert Alignment.read(DEFAULT_TRACK).length == 600.0


def test_measured_table_hermite_and_coverage(tmp_path):
    """The measured table (TrackIrregularity's profile format): Catmull-Rom slopes are exact
    for a quadratic, so inside the table the Hermite reproduces y = a + b s + c s^2 with its
    derivatives 2 c exactly; level = (left + right) / 2; the rows are quadrature kinks."""
    s = np.arange(-2.0, 603.0, 0.5)
    y = 1e-3 + 2e-6 * s - 3e-9 * s**2
    f = tmp_path / "m.csv"
    f.write_text("s,alignment,vertical_left,vertical_right\n" +
                 "".join(f"{a!r},{b!r},{b + 1e-3!r},{b - 3e-4!r}\n" for a, b in zip(s.tolist(), y.tolist())))
    tr = TrackGeometry({**FLAT, "irregularity_file": str(f)})
    for x in (0.0, 13.37, 300.25, 599.9):
        o = tr.offsets(x)
        ye, d1, d2 = 1e-3 + 2e-6 * x - 3e-9 * x * x, 2e-6 - 6e-9 * x, -6e-9
        assert o[0] == pytest.approx(ye, abs=1e-17) and o[1] == pytest.approx(d1, abs=1e-16)
        assert o[2] == pytest.approx(d2, abs=1e-16)
        assert o[3] == pytest.approx(ye + 3.5e-4, abs=1e-17) and o[5] == pytest.approx(d2, abs=1e-16)
    assert len(tr.kinks) == len(set(tr.al.breakpoints) | {x for x in s if 0 < x < 600})
    short = tmp_path / "short.csv"
    short.write_text("s,alignment,vertical_left,vertical_right\n0,0,0,0\n100,0,0,0\n")
    with pytest.raises(UserError, match=r"short.csv: covers s = 0..100 m, the track needs 0..600 m"):
        TrackGeometry({"irregularity_file": str(short)})
    bad = tmp_path / "bad.csv"
    bad.write_text("s,alignment,vertical_left,vertical_right\n0,0,0,0\n0,0,0,0\n")
    with pytest.raises(UserError, match="irregularity_file"):
        TrackGeometry({"irregularity_file": str(bad)})
