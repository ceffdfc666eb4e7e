"""``mandrel_info`` and the parts of the geometry API it leans on: the auto centerline on meshes
that are hard for it (uneven meshing, a bent tube posed anywhere), the CSV writer's argument order,
and the resolution and profiles of the generators the shipped mandrels come from.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from preform.geometry import (auto_centerline, centerline_from_points, format_mandrel_info, mandrel_from_arrays,
                              mandrel_info, read_centerline_csv, shapes)
from preform.io.centerline_csv import write_centerline_csv


def _write_stl(path, V, F, scale=1.0):
    trimesh.Trimesh(V * scale, F, process=False).export(path)
    return path


@pytest.fixture(scope="module")
def cone_stl(tmp_path_factory):
    V, F = shapes.cone(0.04, 0.08, 0.5, n_around=64)
    return _write_stl(tmp_path_factory.mktemp("cone") / "cone_mm.stl", V, F, scale=1000.0)


def test_mandrel_info_is_a_plain_dict_with_the_measures(cone_stl):
    info = mandrel_info(cone_stl, unit="mm")
    d = dict(info)
    json.dumps(d)                                           # plain values only
    for key in ("watertight", "consistently_oriented", "n_faces", "bounds", "centerline_length",
                "perimeter_min", "perimeter_max"):
        assert key in d
    assert d["watertight"] and d["consistently_oriented"]
    assert info["n_faces"] == len(info.mandrel.faces)
    assert np.allclose(d["bounds"], [[-0.08, -0.08, 0.0], [0.08, 0.08, 0.5]], atol=1e-6)
    assert d["centerline_length"] == pytest.approx(0.5, abs=1e-4)
    # sections of a 64-gon cone: perimeter 2 n r sin(pi / n) at the section's circumradius r; the
    # inner sections run from about the tip radius to about the back radius (a trace step from
    # each end: h = 0.5 m / 200, r' = 0.08, so within 2 h r' of the ends' radii)
    poly = 2 * 64 * np.sin(np.pi / 64)
    assert poly * 0.04 <= d["perimeter_min"] <= poly * (0.04 + 2 * 0.0025 * 0.08) + 1e-9
    assert poly * (0.08 - 2 * 0.0025 * 0.08) - 1e-9 <= d["perimeter_max"] <= poly * 0.08 + 1e-9
    assert d["perimeter_min_at"] < 0.01 and d["perimeter_max_at"] > 0.49
    text = format_mandrel_info(info)
    assert "watertight" in text and "cone_mm.stl" in text and 'stl_unit = "mm"; lengths below in m' in text
    assert f"min {d['perimeter_min']:.5f} m" in text and " mm" not in text    # one unit system
    assert info.warnings == ()


def test_mandrel_info_with_a_centerline_csv(cone_stl, tmp_path):
    csv = tmp_path / "cl.csv"
    csv.write_text("x,y,z\n0,0,0\n0,0,250\n0,0,500\n")            # mm, like the STL
    info = mandrel_info(cone_stl, unit="mm", centerline=csv)
    assert info["centerline"] == str(csv)
    assert info["centerline_length"] == pytest.approx(0.5)
    # the middle point's section: circumradius 0.06 m, polygon factor as above; the STL's float32
    # coordinates (in mm) are good to 2**-24 relative
    assert info.centerline.perimeter[1] == pytest.approx(2 * 64 * np.sin(np.pi / 64) * 0.06, rel=1e-6)


def test_write_centerline_csv_takes_path_first(tmp_path):
    cl = centerline_from_points([[0, 0, 0], [0, 0, 0.5], [0.1, 0, 1.0]])
    a = write_centerline_csv(tmp_path / "a.csv", cl)
    b = write_centerline_csv(cl, tmp_path / "b.csv")               # the older order still works
    assert a.read_text() == b.read_text()
    assert np.allclose(read_centerline_csv(a).points, cl.points, atol=1e-9)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv"]      # no temporaries


def test_auto_centerline_is_not_fooled_by_uneven_meshing():
    """A short fat cylinder (length 0.35, radius 0.1) with almost all its rings bunched in the
    middle: its vertices spread more across than along, so a vertex PCA would take a diameter for
    the axis. The area-weighted PCA of the surface finds the axis."""
    length, r = 0.35, 0.1
    rings = np.concatenate([[0.0], np.linspace(0.17, 0.18, 60), [length]])
    V, F = shapes.sweep(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]]), lambda s: shapes.circle(r, 48), 48, rings)
    # the trap is real: the vertices spread most across the axis (and so do the face centroids,
    # counted per face: that version of the trace crossed the diameter)
    assert np.argmax(np.var(V, axis=0)) != 2
    cl = auto_centerline(mandrel_from_arrays(V, F), n_sections=50)
    assert np.allclose(cl.points[:, :2], 0.0, atol=1e-9)
    assert cl.points[0, 2] == pytest.approx(0.0, abs=1e-9) and cl.length == pytest.approx(length, abs=1e-9)


@pytest.mark.parametrize("r_back", [0.08, 0.15])
def test_auto_centerline_stays_on_the_axis_of_a_cone(r_back):
    """Slopes 0.08 and 0.22 over 0.5 m. A tangent taken from consecutive centroids alone made the
    trace of the first cone wander off the axis and stop at a third of its length (the tilt of a
    cut grows by r r' / h per step); the chord over the section's size keeps it on the axis."""
    V, F = shapes.cone(0.04, r_back, 0.5, n_around=64)
    cl = auto_centerline(mandrel_from_arrays(V, F))
    assert np.abs(cl.points[:, :2]).max() < 1e-9                 # centroids of regular polygons
    assert cl.length == pytest.approx(0.5, abs=1e-9)


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_auto_centerline_follows_a_bent_tube_posed_anywhere():
    """The bent tube rotated and moved (tip still the end nearer the origin): the trace follows
    the moved generating path. 2 mm: a few trace steps' chord error; measured ~0.1 mm."""
    path = shapes.bent_tube_path()
    V, F = shapes.bent_tube(n_around=48)
    Rm = _rotation([0.3, -1.0, 0.5], 1.1)
    t = np.array([0.05, -0.02, 0.03])
    m = mandrel_from_arrays(V @ Rm.T + t, F)
    ref = centerline_from_points(path @ Rm.T + t)
    cl = auto_centerline(m, n_sections=150)
    s, d = ref.project(cl.points)
    assert d.max() < 2e-3
    assert np.linalg.norm(cl.points[0] - t) < 2e-3 and np.linalg.norm(cl.points[-1] - ref.points[-1]) < 2e-3
    assert cl.length == pytest.approx(ref.length, abs=2e-3)
    # round the bend the section is the rounded square (perimeter unchanged by the sweep)
    per = shapes.rounded_square_perimeter(0.06, 0.012)
    poly_deficit = 0.01                                     # 48 points on arcs and flats: < 1 % short
    assert np.all(np.abs(cl.perimeter[1:-1] / per - 1) < poly_deficit)


# ------------------------------------------------------------------ generators

def test_sweep_without_caps_is_an_outward_open_tube():
    V, F = shapes.sweep(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3]]), lambda s: shapes.circle(0.05, 16), 16,
                        np.linspace(0, 0.3, 4), caps=False)
    mesh = trimesh.Trimesh(V, F, process=False)
    assert not mesh.is_watertight and mesh.is_winding_consistent
    assert len(F) == 2 * 16 * 3 and len(V) == 16 * 4
    centroids = V[F].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", mesh.face_normals, centroids * [1, 1, 0]) > 0)


@pytest.mark.parametrize("make, perimeter", [
    (lambda n: shapes.cylinder(0.05, 0.4, n_around=n), 2 * np.pi * 0.05),
    (lambda n: shapes.case_b(n_around=n, length=0.4, blend=(0.1, 0.3)), shapes.rounded_square_perimeter(0.09, 0.015)),
    (lambda n: shapes.waist(n_around=n, length=0.4, centre=0.2), 2 * np.pi * 0.075),
], ids=["cylinder", "case_b", "waist"])
def test_axial_resolution_follows_n_around(make, perimeter):
    """Doubling the sections halves the ring spacing too: the edges keep their aspect ratio."""
    spacing = {}
    for n in (64, 128, 256):
        V, _ = make(n)
        z = np.unique(np.round(V[:, 2], 12))
        spacing[n] = np.diff(z).max()
    assert spacing[128] == pytest.approx(spacing[64] / 2, rel=0.1)
    assert spacing[256] == pytest.approx(spacing[128] / 2, rel=0.1)
    # ring spacing / around edge: the documented aspect (4 default, 1 for the waist), +- rounding up
    aspect = spacing[128] / (perimeter / 128)
    assert 0.9 <= aspect <= 4.1


def test_waist_is_concave_enough_to_bridge():
    """Normal curvature along a yarn at braid angle alpha on a surface of revolution:
    kappa_n = cos^2(alpha) (-r'') + sin^2(alpha) / r; the yarn lifts off (bridges) where it is
    negative, r'' > tan^2(alpha) / r. At the waist's bottom that holds up to 60 deg."""
    h = 1e-4
    s0 = 0.5
    r = shapes.waist_radius(s0)
    r2 = (shapes.waist_radius(s0 + h) - 2 * r + shapes.waist_radius(s0 - h)) / h**2
    assert r == pytest.approx(0.045)
    for alpha in np.radians([45.0, 55.0, 59.0]):
        assert r2 > np.tan(alpha) ** 2 / r
    # and the shipped-resolution mesh has it: rings of 5 mm sample the 30 mm Gaussian
    V, _ = shapes.waist(n_around=128, n_along=240)
    rho = np.hypot(V[:, 0], V[:, 1])
    assert rho[rho > 0.01].min() == pytest.approx(0.045, abs=1e-6)        # the side, not the cap centres


def test_bulge_is_steep_enough_to_catch():
    """The flank of the bulge rises faster than 60 deg (|r'| > tan 60): a free yarn leaving the
    tip side at a shallow angle meets it."""
    s = np.linspace(0.3, 0.6, 30001)
    r = shapes.bulge_radius(s)
    slope = np.gradient(r, s)
    assert r.max() == pytest.approx(0.09, abs=1e-6)
    assert np.abs(slope).max() > np.tan(np.radians(60.0))
    # closed form of the steepest flank: height sqrt(2/e) / width
    assert np.abs(slope).max() == pytest.approx(0.04 * np.sqrt(2 / np.e) / 0.015, rel=1e-4)
