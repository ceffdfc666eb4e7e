"""``centerline.plane_segments`` (the section cut of the everyday run, no trimesh import) against
trimesh's ``mesh_plane`` on the same corners: the same segments in the same order, bit for bit, in
every cut case (a side crossing, a corner on the plane, a side on the plane, a facet in it)."""

from types import SimpleNamespace

import numpy as np
import pytest

from preform.geometry import shapes
from preform.geometry.centerline import _faces_near_plane, _section_loops
from preform.geometry.sections import SectionIndex, plane_segments

trimesh = pytest.importorskip("trimesh")
from trimesh.intersections import mesh_plane  # noqa: E402


def _reference(corners, dots, normal, origin):
    patch = SimpleNamespace(vertices=corners, faces=np.arange(len(corners)).reshape(-1, 3))
    return np.asarray(mesh_plane(patch, plane_normal=normal, plane_origin=origin, cached_dots=dots))


def _meshes():
    V, F = shapes.cylinder(0.04, 1.6, n_around=32, n_along=40)
    yield "cylinder", V, np.asarray(F)
    box = trimesh.creation.box(extents=[0.1, 0.2, 0.3])
    yield "box", box.vertices.view(np.ndarray), box.faces.view(np.ndarray)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    yield "sphere", sphere.vertices.view(np.ndarray), sphere.faces.view(np.ndarray)
    sliver = trimesh.creation.cylinder(radius=0.04, height=1.6, sections=64)
    yield "sliver", sliver.vertices.view(np.ndarray), sliver.faces.view(np.ndarray)


def _planes(V, rng):
    """Random tilted planes, and planes through vertices along the axes (corner and side cases)."""
    for _ in range(20):
        n = rng.normal(size=3)
        yield n / np.linalg.norm(n), V[rng.integers(len(V))] + rng.normal(scale=1e-3, size=3)
    for axis in range(3):
        n = np.zeros(3)
        n[axis] = 1.0
        for v in V[rng.integers(len(V), size=4)]:
            yield n, v                                     # through vertices: on-plane corners


@pytest.mark.parametrize("name,V,F", list(_meshes()), ids=lambda x: x if isinstance(x, str) else "")
def test_plane_segments_equal_trimesh_mesh_plane(name, V, F):
    rng = np.random.default_rng(7)
    cases = np.zeros(3, dtype=int)
    for normal, origin in _planes(V, rng):
        corners = V[F.reshape(-1)]
        dots = corners @ normal - float(origin @ normal)
        got = plane_segments(corners, dots, normal, origin)
        ref = _reference(corners, dots, normal, origin)
        assert got is not None
        np.testing.assert_array_equal(got, ref.reshape(-1, 2, 3))
        on = np.abs(dots.reshape(-1, 3)) <= 1e-8
        cases += [np.any(on.sum(axis=1) == 0), np.any(on.sum(axis=1) == 1), np.any(on.sum(axis=1) == 2)]
    if name in ("cylinder", "box"):
        assert cases.min() > 0                   # planes through corners and along sides were cut


def test_facet_in_the_plane_is_cut_by_the_sides_above_it():
    """A box's facet in the plane: its outline comes once, from the side triangles above the
    plane (0 0 1); at the top facet no side is above it, so there is no segment."""
    box = trimesh.creation.box(extents=[0.1, 0.2, 0.3])
    V, F = box.vertices.view(np.ndarray), box.faces.view(np.ndarray)
    corners = V[F.reshape(-1)]
    normal = np.array([0.0, 0.0, 1.0])
    seg = plane_segments(corners, corners @ normal + 0.15, normal, np.array([0.0, 0.0, -0.15]))
    assert len(seg) == 4                                  # the bottom outline, each side once
    assert np.isclose(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1).sum(), 0.6)
    assert len(plane_segments(corners, corners @ normal - 0.15, normal, np.array([0, 0, 0.15]))) == 0


def test_section_loops_on_an_index_equal_those_on_a_trimesh():
    V, F = shapes.cylinder(0.04, 1.6, n_around=64, n_along=200)
    index = SectionIndex(V, np.asarray(F))
    mesh = trimesh.Trimesh(V, np.asarray(F), process=False)
    for z in (0.013, 0.4, 0.8, 1.2):
        normal = np.array([0.05, -0.02, 1.0])
        normal /= np.linalg.norm(normal)
        origin = np.array([0.0, 0.0, z])
        np.testing.assert_array_equal(_faces_near_plane(index, normal, z * normal[2]),
                                      _faces_near_plane(mesh, normal, z * normal[2]))
        (loop,) = _section_loops(index, origin, normal)
        (ref,) = _section_loops(mesh, origin, normal)
        np.testing.assert_array_equal(loop, ref)
        r = np.linalg.norm(loop[:, :2] - loop[:, :2].mean(axis=0), axis=1)
        assert abs(np.linalg.norm(np.diff(loop, axis=0), axis=1).sum()
                   - 2 * np.pi * 0.04 * np.sin(np.pi / 64) * 64 / np.pi / normal[2]) < 2e-3
        assert r.max() < 0.0405 / normal[2]
