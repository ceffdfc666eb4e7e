"""The centerline: arc length, rotation-minimising frames, CSV, auto trace, sections.

References: hand-computed arc lengths, the helix's closed-form torsion (a rotation-minimising frame
turns against the Frenet frame at the rate -tau), dense brute-force sampling for ``project``, the
shipped CSVs for ``auto_centerline`` and the regular polygon's perimeter for the sections.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from preform.errors import MandrelError
from preform.geometry import (auto_centerline, centerline_from_points, load_mandrel, mandrel_from_arrays,
                              read_centerline_csv, section_perimeters, shapes)
from preform.io.centerline_csv import write_centerline_csv

MANDRELS = Path(__file__).resolve().parents[2] / "mandrels"
SHIPPED = ["case_a", "case_b", "bent_tube", "cone", "waist", "bulge"]


@pytest.fixture(scope="module")
def bent_path():
    return shapes.bent_tube_path()          # 0.4 m along +z, 90 deg bend of radius 0.35 m, 0.4 m along +x


def _orthonormal(cl, atol=1e-12):
    T, N, B = cl.tangents, cl.normals, cl.binormals
    for u in (T, N, B):
        assert np.allclose(np.linalg.norm(u, axis=1), 1.0, atol=atol)
    assert np.allclose(np.einsum("ij,ij->i", T, N), 0.0, atol=atol)
    assert np.allclose(B, np.cross(T, N), atol=atol)
    assert np.allclose(np.linalg.det(np.stack([T, N, B], axis=2)), 1.0, atol=atol)


# ------------------------------------------------------------------ arc length and frames

def test_arc_length_by_hand():
    # 3-4-5 then straight up 12: s = 0, 5, 17; the repeated point is dropped
    cl = centerline_from_points([[0, 0, 0], [3, 4, 0], [3, 4, 0], [3, 4, 12]])
    assert len(cl.points) == 3
    assert np.allclose(cl.s, [0.0, 5.0, 17.0], rtol=0, atol=1e-15)
    assert cl.length == 17.0
    assert np.allclose(cl.tangents[0], [0.6, 0.8, 0.0]) and np.allclose(cl.tangents[-1], [0, 0, 1])


def test_arc_length_of_the_bent_path(bent_path):
    cl = centerline_from_points(bent_path)
    # two straights plus 48 chords of the quarter circle: 2 R sin(theta / 2) each
    chords = 48 * 2 * 0.35 * np.sin(np.pi / 2 / 48 / 2)
    assert cl.length == pytest.approx(0.8 + chords, rel=1e-12)
    assert cl.length == pytest.approx(0.8 + np.pi / 2 * 0.35, rel=1e-4)   # chord deficit (pi/96)^2 / 24


def test_too_few_points():
    with pytest.raises(MandrelError, match="two distinct points"):
        centerline_from_points([[0, 0, 0], [0, 0, 0]])


def _helix(n, a=0.1, c=0.03, turns=2):
    t = np.linspace(0.0, 2 * np.pi * turns, n + 1)
    return t, np.column_stack([a * np.cos(t), a * np.sin(t), c * t])


def _rmf_error_on_helix(n, a=0.1, c=0.03):
    """Max angle (rad) between the RMF normal and its closed form on a helix.

    Frenet frame of (a cos t, a sin t, c t): N_F = (-cos t, -sin t, 0),
    B_F = (c sin t, -c cos t, a) / sqrt(a^2 + c^2), torsion tau = c / (a^2 + c^2). A rotation-
    minimising normal at angle theta from N_F in the (N_F, B_F) plane obeys d theta / ds = -tau."""
    t, points = _helix(n, a, c)
    cl = centerline_from_points(points, roll_reference=[-1.0, 0.0, 0.0])
    _orthonormal(cl)
    NF = np.column_stack([-np.cos(t), -np.sin(t), np.zeros_like(t)])
    BF = np.column_stack([c * np.sin(t), -c * np.cos(t), np.full_like(t, a)]) / np.hypot(a, c)
    theta = np.arctan2(np.einsum("ij,ij->i", cl.normals, BF), np.einsum("ij,ij->i", cl.normals, NF))
    expected = theta[0] - c / (a * a + c * c) * cl.s
    return np.abs(np.angle(np.exp(1j * (theta - expected)))).max()


def test_frames_are_rotation_minimising_on_a_helix():
    # over 2 turns the frame turns 3.6 rad against Frenet; the polyline's chord tangents make the
    # error second order in the spacing: 1.8e-4 rad with 400 points
    e400, e800 = _rmf_error_on_helix(400), _rmf_error_on_helix(800)
    assert e400 < 1e-3
    assert np.log2(e400 / e800) == pytest.approx(2.0, abs=0.2)


@pytest.mark.parametrize("roll, in_plane", [([1.0, 0.0, 0.0], True), ([0.0, 1.0, 0.0], False), (None, True)])
def test_no_twist_on_a_planar_bend(bent_path, roll, in_plane):
    """The bend lies in the x-z plane: a normal starting in it stays in it, one starting along y stays
    along y (a rotation-minimising frame only turns about the binormal of a plane curve)."""
    cl = centerline_from_points(bent_path, roll_reference=roll)
    _orthonormal(cl)
    ny = cl.normals[:, 1]
    if in_plane:
        assert np.max(np.abs(ny)) < 1e-12
        # and it turns with the tangent: +x at the tip, -z after the bend
        assert np.allclose(cl.normals[0], [1, 0, 0], atol=1e-12)
        assert np.allclose(cl.normals[-1], [0, 0, -1], atol=1e-12)
    else:
        assert np.allclose(ny, 1.0, atol=1e-12)


def test_roll_reference_sets_the_first_normal():
    cl = centerline_from_points([[0, 0, 0], [0, 0, 1.0]], roll_reference=[1.0, 1.0, 0.3])
    assert np.allclose(cl.normals[0], [2**-0.5, 2**-0.5, 0.0], atol=1e-12)   # projected normal to T
    assert np.allclose(cl.normals[-1], cl.normals[0], atol=1e-12)
    tilted = np.array([[0.1, 0.2, 0.3], [0.1 + 1 / 3, 0.2 + 2 / 3, 0.3 + 2 / 3]])
    cl = centerline_from_points(tilted, roll_reference=[0.0, 0.0, 1.0])
    T = cl.tangents[0]
    expected = np.array([0.0, 0.0, 1.0]) - T[2] * T
    assert np.allclose(cl.normals[0], expected / np.linalg.norm(expected), atol=1e-12)
    # a reference along the tangent falls back to the world axis least aligned with it (x here)
    cl = centerline_from_points([[0, 0, 0], [0, 0, 1.0]], roll_reference=[0.0, 0.0, 2.0])
    assert np.allclose(cl.normals[0], [1.0, 0.0, 0.0], atol=1e-12)


def test_frames_at_extrapolate_straight_beyond_the_ends(bent_path):
    cl = centerline_from_points(bent_path, roll_reference=[0.0, 1.0, 0.0])
    d = np.array([0.05, 0.3])
    p, T, N, B = cl.frames_at(np.concatenate([-d, cl.length + d]))
    assert np.allclose(p[:2], cl.points[0] - d[:, None] * cl.tangents[0], atol=1e-15)
    assert np.allclose(p[:2], [[0, 0, -0.05], [0, 0, -0.3]], atol=1e-15)
    assert np.allclose(p[2:], cl.points[-1] + d[:, None] * cl.tangents[-1], atol=1e-15)
    assert np.allclose(p[2:], [[0.8, 0, 0.75], [1.05, 0, 0.75]], atol=1e-12)
    for k, end in ((0, 0), (1, 0), (2, -1), (3, -1)):
        assert np.allclose(T[k], cl.tangents[end]) and np.allclose(N[k], cl.normals[end])
        assert np.allclose(B[k], cl.binormals[end])


def test_frames_at_interpolates_on_the_polyline(bent_path):
    cl = centerline_from_points(bent_path)
    p, T, N, B = cl.frames_at(cl.s)
    assert np.allclose(p, cl.points, atol=1e-15) and np.allclose(N, cl.normals, atol=1e-12)
    s = np.linspace(0.0, cl.length, 777)
    p, T, N, B = cl.frames_at(s)
    s_back, d = cl.project(p)
    assert np.allclose(d, 0.0, atol=1e-12) and np.allclose(s_back, s, atol=1e-12)
    assert np.allclose(np.einsum("ij,ij->i", T, N), 0.0, atol=1e-12)


def test_project_against_brute_force(bent_path):
    cl = centerline_from_points(bent_path)
    rng = np.random.default_rng(4)
    on = cl.frames_at(rng.uniform(0.0, cl.length, 300))[0]
    points = on + rng.normal(scale=0.03, size=on.shape)        # well within the bend radius 0.35 m
    s, d = cl.project(points)
    # brute force: every segment sampled at spacing <= h; the nearest sample is at most h/2 farther
    # than the true closest point, and (for points this close to a smooth bend) at an arc length
    # within a few h of it
    h = 1e-4
    samples, sample_s = [], []
    for a, b, sa, sb in zip(cl.points[:-1], cl.points[1:], cl.s[:-1], cl.s[1:]):
        u = np.linspace(0.0, 1.0, int(np.ceil((sb - sa) / h)) + 1)
        samples.append(a + u[:, None] * (b - a))
        sample_s.append(sa + u * (sb - sa))
    samples, sample_s = np.vstack(samples), np.concatenate(sample_s)
    for k, q in enumerate(points):
        dist = np.linalg.norm(samples - q, axis=1)
        j = np.argmin(dist)
        assert d[k] <= dist[j] + 1e-12
        assert d[k] >= dist[j] - h / 2
        assert abs(s[k] - sample_s[j]) < 5 * h


# ------------------------------------------------------------------ CSV

def test_read_csv_with_and_without_header(tmp_path, bent_path):
    body = "\n".join(",".join(repr(float(v)) for v in row) for row in bent_path)
    (tmp_path / "h.csv").write_text("x,y,z\n" + body + "\n")
    (tmp_path / "n.csv").write_text(body)
    (tmp_path / "c.csv").write_text("# tip first\n\n" + body.replace(",", "; ") + "\n\n")
    ref = centerline_from_points(bent_path)
    for name in ("h.csv", "n.csv", "c.csv"):
        cl = read_centerline_csv(tmp_path / name)
        assert np.array_equal(cl.points, ref.points)
        assert np.allclose(cl.s, ref.s, rtol=0, atol=1e-15)


def test_read_csv_in_mm(tmp_path, bent_path):
    rows = (",".join(repr(float(v * 1e3)) for v in row) for row in bent_path)
    (tmp_path / "mm.csv").write_text("x,y,z\n" + "\n".join(rows))
    cl = read_centerline_csv(tmp_path / "mm.csv", unit="mm")
    assert np.allclose(cl.points, bent_path, rtol=0, atol=1e-15)
    assert cl.length == pytest.approx(centerline_from_points(bent_path).length, rel=1e-14)


@pytest.mark.parametrize("text, line", [
    ("x,y,z\n0,0,0\n0,0,abc\n0,0,1\n", 3),
    ("0,0,0\n0,0,0.5\n0,0\n0,0,1\n", 3),
    ("0,0,0\nx,y,z\n0,0,1\n", 2),           # a header after data is a bad row
])
def test_read_csv_bad_row_names_file_and_line(tmp_path, text, line):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(MandrelError) as err:
        read_centerline_csv(path)
    assert str(path) in str(err.value) and f"line {line}" in str(err.value)


def test_read_csv_missing_or_too_short(tmp_path):
    with pytest.raises(MandrelError, match="not found"):
        read_centerline_csv(tmp_path / "none.csv")
    (tmp_path / "one.csv").write_text("x,y,z\n0,0,0\n")
    with pytest.raises(MandrelError, match="at least two points"):
        read_centerline_csv(tmp_path / "one.csv")


def test_read_csv_header_after_a_comment(tmp_path):
    path = tmp_path / "commented.csv"
    path.write_text("# exported by CAD\n\nx,y,z\n0,0,0\n0,0,1\n")
    assert read_centerline_csv(path).length == 1.0


def test_read_csv_header_picks_the_named_columns(tmp_path):
    path = tmp_path / "s_first.csv"
    path.write_text("s,x,y,z\n0,0,0,0\n2,0,0,2\n")
    cl = read_centerline_csv(path)
    assert np.allclose(cl.points, [[0, 0, 0], [0, 0, 2]]) and cl.length == 2.0


def test_read_csv_second_header_is_a_bad_row(tmp_path):
    path = tmp_path / "twice.csv"
    path.write_text("x,y,z\n0,0,0\nx,y,z\n0,0,1\n")
    with pytest.raises(MandrelError, match="line 3"):
        read_centerline_csv(path)


def test_write_csv_round_trip(tmp_path, bent_path):
    cl = centerline_from_points(bent_path)
    out = write_centerline_csv(cl, tmp_path / "out.csv")
    assert out == tmp_path / "out.csv"
    assert out.read_text().splitlines()[0] == "x,y,z,s,perimeter"
    back = read_centerline_csv(out)
    # 9 significant digits: coordinates below 1 m come back within 5e-10 m
    assert np.allclose(back.points, cl.points, rtol=0, atol=1e-9)
    assert np.allclose(back.s, cl.s, rtol=0, atol=1e-8)
    assert not list(tmp_path.glob(".*.tmp"))                  # the atomic write left nothing behind


def test_write_csv_in_mm_with_perimeter(tmp_path, bent_path):
    cl = centerline_from_points(bent_path, perimeter=np.linspace(0.2, 0.3, len(bent_path)))
    out = write_centerline_csv(cl, tmp_path / "mm.csv", unit="mm")
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    # 9 significant digits of values up to 1350 mm: half a unit of the 9th digit, relative 5e-9
    assert np.allclose(table[:, :3] * 1e-3, cl.points, rtol=5e-9, atol=1e-15)
    assert np.allclose(table[:, 3] * 1e-3, cl.s, rtol=5e-9, atol=1e-15)
    assert np.allclose(table[:, 4] * 1e-3, cl.perimeter, rtol=5e-9)
    back = read_centerline_csv(out, unit="mm")
    assert np.allclose(back.points, cl.points, rtol=5e-9, atol=1e-15)


# ------------------------------------------------------------------ auto centerline

@pytest.fixture(scope="module")
def shipped():
    return {name: load_mandrel(MANDRELS / f"{name}.stl") for name in SHIPPED}


@pytest.mark.parametrize("name", SHIPPED)
def test_auto_centerline_follows_the_shipped_csv(shipped, name):
    mandrel = shipped[name]
    ref = read_centerline_csv(MANDRELS / f"{name}_centerline.csv")
    auto = auto_centerline(mandrel)
    s, d = ref.project(auto.points)
    assert d.max() < 1e-3
    # the trace runs tip first from the origin end to the far end, covering the whole reference
    assert np.linalg.norm(auto.points[0]) < 1e-3
    assert np.linalg.norm(auto.points[-1] - ref.points[-1]) < 1e-3
    assert s[0] < 1e-3 and s[-1] > ref.length - 1e-3
    assert np.all(np.diff(s) > 0)
    assert auto.length == pytest.approx(ref.length, abs=2e-3)
    assert auto.perimeter is not None and np.all(auto.perimeter > 0)


def test_auto_centerline_tip_is_the_end_nearer_the_origin(shipped):
    """The same cylinder moved so that its far end is at the origin: the trace starts there."""
    m = shipped["cone"]
    flipped = mandrel_from_arrays(m.vertices * [1.0, 1.0, -1.0] + [0.0, 0.0, 1.0], m.faces[:, ::-1])
    auto = auto_centerline(flipped, n_sections=40)
    assert np.allclose(auto.points[0], [0.0, 0.0, 0.0], atol=1e-3)      # the wide end, now at z = 0
    assert np.allclose(auto.points[-1], [0.0, 0.0, 1.0], atol=1e-3)
    assert auto.perimeter[1] > auto.perimeter[-2]


# ------------------------------------------------------------------ sections

def test_cylinder_section_is_the_polygon_perimeter():
    n, r = 128, 0.05
    m = mandrel_from_arrays(*shapes.cylinder(r, 0.2, n_around=n, n_along=4))
    cl = centerline_from_points([[0, 0, 0], [0, 0, 0.2]])
    s = [0.001, 0.03, 0.05, 0.1, 0.123, 0.199]                # 0.05 and 0.1 cut through the vertex rings
    # regular n-gon of circumradius r: n sides of chord length 2 r sin(pi / n). Cuts through the
    # triangulated side quads add collinear points only, so the loop is this polygon to rounding
    polygon = 2 * n * r * np.sin(np.pi / n)
    assert np.allclose(section_perimeters(m, cl, s), polygon, rtol=1e-12)


def test_case_b_perimeter_equal_at_both_ends(shipped):
    m = shipped["case_b"]
    cl = read_centerline_csv(MANDRELS / "case_b_centerline.csv")
    square, circle = section_perimeters(m, cl, [0.05, 1.45])
    # rounded square and circle of the same perimeter by construction; each is sampled by a 128-gon,
    # which shortens them by different small amounts (measured 0.03 % and 0.01 %)
    assert square == pytest.approx(circle, rel=0.02)
    exact = shapes.rounded_square_perimeter(0.09, 0.015)
    assert square == pytest.approx(exact, rel=0.02) and circle == pytest.approx(exact, rel=0.02)


@pytest.mark.parametrize("sections", [16, 24, 100, 128, 200, 256])
@pytest.mark.parametrize("encoding", ["stl", "stl_ascii"])
@pytest.mark.parametrize("scale", [1.0, 1000.0])
def test_auto_centerline_on_trimesh_capped_cylinders(tmp_path, sections, encoding, scale):
    # trimesh's capped cylinders: long side slivers, so no side face centroid is near the tip (a
    # tip direction from the sign of a dot product of two perpendicular vectors would refuse 7 of
    # these 12, "no cross-section near the tip"); scale 1000 is an STL in mm read as m, which
    # must reach the unit check (preflight) instead of failing here
    import trimesh

    m = trimesh.creation.cylinder(radius=0.04, height=1.6, sections=sections)
    m.apply_translation([0.0, 0.0, 0.8])
    m.apply_scale(scale)
    path = tmp_path / "cyl.stl"
    m.export(path, file_type=encoding)
    cl = auto_centerline(load_mandrel(path))
    # on the axis, tip (z = 0) first, the full length, to the STL's float32 rounding (6e-8 relative)
    # and ASCII's 6 significant digits (1e-6 relative)
    assert np.hypot(cl.points[:, 0], cl.points[:, 1]).max() < 1.6e-6 * scale
    assert cl.points[0, 2] == pytest.approx(0.0, abs=1.6e-6 * scale)
    assert cl.length == pytest.approx(1.6 * scale, rel=1e-6)


def test_auto_centerline_does_not_depend_on_the_triangulation():
    # the same cylinder as slivers, as a well-shaped sweep and with its faces split 4-way
    import trimesh

    from preform.geometry import shapes

    m = trimesh.creation.cylinder(radius=0.04, height=1.6, sections=128)
    m.apply_translation([0.0, 0.0, 0.8])
    meshes = [(m.vertices, m.faces), shapes.cylinder(0.04, 1.6, n_around=128),
              trimesh.remesh.subdivide(*shapes.cylinder(0.04, 1.6, n_around=128))]
    lines = [auto_centerline(mandrel_from_arrays(V, F)) for V, F in meshes]
    s = np.linspace(0.0, 1.6, 50)
    ref = lines[0].frames_at(s)[0]
    for cl in lines[1:]:
        assert cl.length == pytest.approx(1.6, rel=1e-9)
        assert np.abs(cl.frames_at(s)[0] - ref).max() < 1e-6


def test_frame_at_is_frames_at_for_one_value(bent_path):
    # the scalar fast path against the vectorised one, inside, at the points and beyond both ends
    cl = centerline_from_points(bent_path)
    rng = np.random.default_rng(5)
    for s in np.concatenate([rng.uniform(-0.2, cl.length + 0.2, 500), cl.s]):
        for one, many in zip(cl.frame_at(s), cl.frames_at([s])):
            assert np.allclose(one, many[0], rtol=0, atol=1e-14)
