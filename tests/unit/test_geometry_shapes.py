"""The mesh generators (``preform.geometry.shapes``): closed, outward, and the right size.

Volumes are compared with the polygonal solids the generators build exactly, and with the smooth
solids within the polygon's area deficit.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from preform.geometry import centerline_from_points, mandrel_from_arrays, shapes

GENERATORS = {
    "cylinder": lambda: shapes.cylinder(0.05, 0.3, n_around=24, n_along=5),
    "cone": lambda: shapes.cone(0.02, 0.05, 0.3, n_around=24, n_along=5),
    "waist": lambda: shapes.waist(n_around=24, n_along=40),
    "bulge": lambda: shapes.bulge(n_around=24, n_along=40),
    "case_b": lambda: shapes.case_b(n_around=32, spacing=0.1),
    "bent_tube": lambda: shapes.bent_tube(n_around=24, spacing=0.05),
    "revolution": lambda: shapes.revolution(lambda s: 0.03 + 0.01 * np.sin(10 * s), 0.5, n_around=20),
    "sweep_reversed": lambda: shapes.sweep(shapes.bent_tube_path(), lambda s: shapes.circle(0.02, 12)[::-1],
                                           12, np.linspace(0.0, 1.2, 30)),
}


def _signed_volume(V, F):
    """Divergence theorem: sum over faces of v0 . (v1 - v0) x (v2 - v0) / 6."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->", a, np.cross(b - a, c - a))) / 6.0


def _polygon_area(r, n):
    """Regular n-gon of circumradius r: n triangles of area r^2 sin(2 pi / n) / 2."""
    return 0.5 * n * r * r * np.sin(2 * np.pi / n)


@pytest.mark.parametrize("name", GENERATORS)
def test_generator_is_closed_and_outward(name):
    V, F = GENERATORS[name]()
    assert V.dtype == np.float64 and F.dtype == np.int64
    assert V.shape[1] == 3 and F.shape[1] == 3
    assert np.array_equal(np.unique(F), np.arange(len(V)))          # no unreferenced vertices
    mesh = trimesh.Trimesh(V, F, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert _signed_volume(V, F) > 0
    assert mesh.volume == pytest.approx(_signed_volume(V, F), rel=1e-12)
    # a sphere-like surface: Euler characteristic V - E + F = 2 (E = 3F / 2 when closed)
    assert len(V) - 3 * len(F) // 2 + len(F) == 2
    m = mandrel_from_arrays(V, F)                       # the package's own checks agree
    assert np.all(m.neighbors >= 0)


@pytest.mark.parametrize("name", ["cylinder", "cone", "waist", "bulge", "case_b"])
def test_straight_generators_run_from_the_origin_along_z(name):
    V, _ = GENERATORS[name]()
    assert V[:, 2].min() == pytest.approx(0.0, abs=1e-15)
    tip = V[np.abs(V[:, 2]) < 1e-12]
    assert np.allclose(tip[:, :2].mean(axis=0), 0.0, atol=1e-12)     # the tip cap is centred on the axis


def test_bent_tube_turns_towards_plus_x():
    V, _ = GENERATORS["bent_tube"]()
    # 0.4 m up z, a bend of radius 0.35 m to (0.35, 0, 0.75), 0.4 m along +x: the end cap is centred
    # at (0.75, 0, 0.75). The section is 60 mm wide, so z reaches 0.75 + 0.03 and x dips to -0.03
    assert V[:, 0].max() == pytest.approx(0.75, abs=1e-12)
    assert V[:, 2].max() == pytest.approx(0.75 + 0.03, abs=1e-12)
    assert V[:, 2].min() == pytest.approx(0.0, abs=1e-12) and V[:, 0].min() == pytest.approx(-0.03, abs=1e-12)


@pytest.mark.parametrize("n", [12, 24, 128])
def test_cylinder_volume(n):
    r, length = 0.05, 0.3
    V, F = shapes.cylinder(r, length, n_around=n, n_along=3)
    # a prism on the inscribed regular n-gon: exact to rounding
    assert _signed_volume(V, F) == pytest.approx(_polygon_area(r, n) * length, rel=1e-12)
    # the smooth cylinder is larger by the polygon's area deficit:
    # sin(x)/x with x = 2 pi / n is 1 - x^2/6 + ...
    deficit = 1 - np.sin(2 * np.pi / n) / (2 * np.pi / n)
    assert _signed_volume(V, F) == pytest.approx(np.pi * r * r * length * (1 - deficit), rel=1e-12)
    assert deficit < (2 * np.pi / n) ** 2 / 6


@pytest.mark.parametrize("n", [12, 24, 128])
def test_cone_volume(n):
    r0, r1, length = 0.02, 0.05, 0.3
    V, F = shapes.cone(r0, r1, length, n_around=n, n_along=4)
    # the side quads are planar trapezoids, so the mesh is exactly the frustum of similar n-gons:
    # V = L / 3 (A0 + A1 + sqrt(A0 A1)) with A the polygon areas
    a0, a1 = _polygon_area(r0, n), _polygon_area(r1, n)
    assert _signed_volume(V, F) == pytest.approx(length / 3 * (a0 + a1 + np.sqrt(a0 * a1)), rel=1e-12)
    smooth = np.pi * length / 3 * (r0 * r0 + r0 * r1 + r1 * r1)
    deficit = 1 - np.sin(2 * np.pi / n) / (2 * np.pi / n)          # same area ratio at every section
    assert _signed_volume(V, F) == pytest.approx(smooth * (1 - deficit), rel=1e-12)


def test_revolution_rings_follow_the_radius():
    def radius(s):
        return 0.04 + 0.02 * s

    V, F = shapes.revolution(radius, 1.0, n_around=16, n_along=10)
    ring = V[:-2]                                      # the two cap centres come last
    assert np.allclose(np.hypot(ring[:, 0], ring[:, 1]), radius(ring[:, 2]), atol=1e-15)
    assert np.allclose(V[-2:], [[0, 0, 0], [0, 0, 1.0]], atol=1e-15)


def test_circle_and_rounded_square_sections():
    c = shapes.circle(0.03, 16)
    assert np.allclose(np.hypot(c[:, 0], c[:, 1]), 0.03) and np.allclose(c[0], [0.03, 0.0])
    side, rc, n = 0.09, 0.015, 400
    sq = shapes.rounded_square(side, rc, n)
    # on the boundary: inside the square, and in the corners at distance rc from the corner centre
    assert np.all(np.abs(sq) <= side / 2 + 1e-15)
    corner = np.all(np.abs(sq) > side / 2 - rc, axis=1)
    centre = np.sign(sq[corner]) * (side / 2 - rc)
    assert np.allclose(np.linalg.norm(sq[corner] - centre, axis=1), rc, atol=1e-12)
    # uniform in arc length, counter-clockwise, starting mid right side
    assert np.allclose(sq[0], [side / 2, 0.0], atol=1e-15)
    edges = np.linalg.norm(np.diff(np.vstack([sq, sq[:1]]), axis=0), axis=1)
    exact = shapes.rounded_square_perimeter(side, rc)
    assert exact == pytest.approx(4 * (side - 2 * rc) + 2 * np.pi * rc)
    # chords of arc length h on the corner arcs fall short by h - 2 rc sin(h / (2 rc)) ~ h^3 / (24 rc^2)
    # each, (h / rc)^2 / 24 of the arcs' length; the straight sides are exact
    h = exact / n
    deficit = exact - edges.sum()
    assert 0 < deficit <= 2 * np.pi * rc * (h / rc) ** 2 / 24 * (1 + 1e-3)
    assert deficit >= 0.9 * 2 * np.pi * rc * (h / rc) ** 2 / 24
    assert np.max(edges) == pytest.approx(exact / n, rel=1e-12)
    area = 0.5 * np.sum(sq[:, 0] * np.roll(sq[:, 1], -1) - np.roll(sq[:, 0], -1) * sq[:, 1])
    assert area == pytest.approx(side * side - (4 - np.pi) * rc * rc, rel=1e-4)


def test_case_b_ends_have_equal_perimeter():
    V, F = shapes.case_b(n_around=64, spacing=0.5)
    rings = V[:-2].reshape(-1, 64, 3)

    def perimeter(ring):
        return np.linalg.norm(np.diff(np.vstack([ring, ring[:1]]), axis=0), axis=1).sum()

    first, last = perimeter(rings[0]), perimeter(rings[-1])
    # the square end and the circle end both sample curves of the same length with 64 points
    assert first == pytest.approx(last, rel=2e-3)
    assert np.allclose(np.hypot(rings[-1][:, 0], rings[-1][:, 1]),
                       shapes.rounded_square_perimeter(0.09, 0.015) / (2 * np.pi), atol=1e-12)


def test_bent_tube_sections_are_normal_to_the_path():
    V, F = shapes.bent_tube(n_around=24, spacing=0.05)
    cl = centerline_from_points(shapes.bent_tube_path())
    rings = V[:-2].reshape(-1, 24, 3)
    centres = rings.mean(axis=1)
    s, d = cl.project(centres)
    assert d.max() < 1e-12                          # each ring is centred on the path
    _, T, _, _ = cl.frames_at(s)
    along = np.einsum("rkj,rj->rk", rings - centres[:, None, :], T)
    assert np.abs(along).max() < 1e-12              # and lies in the plane normal to it


def _aspect(V, F):
    """Longest edge over the height on it, per face."""
    e = V[F] - np.roll(V[F], -1, axis=1)
    longest = np.linalg.norm(e, axis=2).max(axis=1)
    double_area = np.linalg.norm(np.cross(e[:, 0], -e[:, 2]), axis=1)
    return longest ** 2 / double_area


@pytest.mark.parametrize("name", shapes.FAMILY)
def test_family_parts_closed_and_both_triangulations_one_solid(name):
    """Every part of the family is closed and outward in both triangulations; the sliver one
    bounds the same solid (its rings are a subset on straight, constant pieces, where the even
    rings add nothing but points on the same planes; on arcs and section changes it keeps
    rings at the same arc spacing, so the volumes agree to the chord error of the coarser
    rings) and has CAD-like slivers (aspect ratios in the tens at 24 points around, above 100 at 48)."""
    out = {}
    for tri in ("even", "sliver"):
        V, F, path = shapes.family_part(name, n_around=24, triangulation=tri)
        mesh = trimesh.Trimesh(V, F, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert _signed_volume(V, F) > 0
        assert np.all(mandrel_from_arrays(V, F).neighbors >= 0)
        out[tri] = V, F, path
    (Ve, Fe, pe), (Vs, Fs, ps) = out["even"], out["sliver"]
    assert np.array_equal(pe, ps)
    # the even rings are every 2 around-edges, the sliver arcs every 2 around-edges too
    # (part_rings' default): only straight constant pieces lose rings, exactly
    assert _signed_volume(Vs, Fs) == pytest.approx(_signed_volume(Ve, Fe), rel=2e-3)
    assert _aspect(Ve, Fe).max() < 15.0
    # the longest straight constant piece (0.15-0.4 m) over the around edge (6.5-8 mm at 24)
    assert _aspect(Vs, Fs).max() > 30.0


def test_family_part_scale_is_millimetres():
    V, F, path = shapes.family_part("s_tube", n_around=24)
    Vm, Fm, pm = shapes.family_part("s_tube", n_around=24, scale=1000.0)
    assert np.array_equal(F, Fm)
    assert np.allclose(Vm, 1000.0 * V) and np.allclose(pm, 1000.0 * path)


def test_bend_path_arcs_and_s_bend():
    """An arc of radius R and angle a is R a long and turns the tangent by a; an S-bend's two
    opposite arcs leave it along +z again, displaced sideways by 2 R (1 - cos a) + line sin a."""
    R, a, line = 0.3, np.radians(35.0), 0.08
    pts, ends = shapes.bend_path([("line", 0.1), ("arc", R, 35.0), ("line", line),
                                  ("arc", R, -35.0), ("line", 0.2)], arc_step_deg=0.5)
    assert ends == pytest.approx([0, 0.1, 0.1 + R * a, 0.1 + R * a + line,
                                  0.1 + 2 * R * a + line, 0.3 + 2 * R * a + line])
    d = pts[-1] - pts[-2]
    assert d / np.linalg.norm(d) == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert pts[-1, 0] == pytest.approx(2 * R * (1 - np.cos(a)) + line * np.sin(a), rel=1e-12)
    cl = centerline_from_points(pts)
    # the polyline's chords are shorter than the arcs by a (1 - sinc) of 0.5 deg steps
    assert cl.length == pytest.approx(ends[-1], rel=1e-5)


def test_rounded_rectangle_perimeter_and_start():
    pts = shapes.rounded_rectangle(0.06, 0.04, 0.01, 400)
    closed = np.vstack([pts, pts[:1]])
    assert np.linalg.norm(np.diff(closed, axis=0), axis=1).sum() == pytest.approx(
        shapes.rounded_rectangle_perimeter(0.06, 0.04, 0.01), rel=1e-4)
    assert pts[0] == pytest.approx([0.03, 0.0])
    assert np.all(np.abs(pts[:, 0]) <= 0.03 + 1e-15) and np.all(np.abs(pts[:, 1]) <= 0.02 + 1e-15)
    with pytest.raises(ValueError, match="corner radius"):
        shapes.rounded_rectangle(0.06, 0.04, 0.03, 16)
