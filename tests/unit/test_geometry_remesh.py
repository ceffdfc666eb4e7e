"""The remesher's helpers (geometry/remesh.py): pre-cut, feature edges, locating faces."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from preform.analysis.fields import face_geometry
from preform.geometry import shapes
from preform.geometry.remesh import feature_edges, isotropic_remesh, locate_faces, subdivide_long_edges


@pytest.mark.parametrize("h", [0.05, 0.013, 0.004])
def test_subdivide_long_edges_is_conforming_and_keeps_the_surface(h):
    m = trimesh.creation.cylinder(radius=0.04, height=0.5, sections=24)   # slivers and cap fans
    V0, F0 = np.asarray(m.vertices), np.asarray(m.faces)
    V, F, src = subdivide_long_edges(V0, F0, h)
    tri = V[F]
    # new edges: pieces of input edges (<= h) or strip rungs, which join points about the same
    # fraction along a face's two long sides: at most its shortest edge plus one piece
    tri0 = V0[F0]
    shortest = np.linalg.norm(tri0 - np.roll(tri0, 1, axis=1), axis=2).min(axis=1).max()
    assert np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max() <= shortest + h * (1 + 1e-12)
    out = trimesh.Trimesh(V, F, process=False)
    assert out.is_watertight and out.is_winding_consistent       # no hanging nodes
    n0, a0, _ = face_geometry(V0, F0)
    n1, a1, _ = face_geometry(V, F)
    # each piece lies in its source face: same normal, and the pieces' areas add up to it
    assert np.allclose(np.bincount(src, a1, len(F0)), a0, rtol=1e-9)
    assert (np.einsum("ij,ij->i", n1, n0[src]) > 1 - 1e-9).all()
    assert np.array_equal(V[:len(V0)], V0)


def test_subdivide_leaves_short_edged_meshes_alone():
    V, F = shapes.cylinder(0.04, 0.2, n_around=32)
    V1, F1, src = subdivide_long_edges(V, F, 1.0)
    assert np.array_equal(F1, F) and np.array_equal(src, np.arange(len(F)))


def test_feature_edges_are_the_cap_rims():
    V, F = shapes.cylinder(0.04, 0.2, n_around=32, n_along=10)
    sharp = feature_edges(V, F, 45.0)
    assert len(sharp) == 2 * 32
    z = V[sharp][:, :, 2]
    assert np.all((np.abs(z) < 1e-12) | (np.abs(z - 0.2) < 1e-12))


def test_locate_faces_finds_the_face_under_each_point():
    V, F = shapes.cylinder(0.04, 0.2, n_around=32, n_along=20)
    normals, _, centroids = face_geometry(V, F)
    rng = np.random.default_rng(1)
    w = rng.dirichlet([1, 1, 1], len(F))
    points = np.einsum("fk,fki->fi", w, V[F])
    assert np.array_equal(locate_faces(V, F, points, normals, 0.005), np.arange(len(F)))


def test_isotropic_remesh_of_a_coarse_box_keeps_its_corners():
    box = trimesh.creation.box(extents=(0.2, 0.1, 0.05))           # 12 faces, sharp edges
    U, G = isotropic_remesh(np.asarray(box.vertices), np.asarray(box.faces), 0.01)
    out = trimesh.Trimesh(U, G, process=False)
    assert out.is_watertight and out.volume == pytest.approx(box.volume, rel=1e-6)
    for corner in box.vertices:
        assert np.linalg.norm(U - corner, axis=1).min() < 1e-9


def test_the_remesher_import_warns_the_user_of_nothing():
    """gpytoolbox imports deprecated scipy / numpy names; those DeprecationWarnings reached the
    user as ``warning:`` lines of ``preform run``. A fresh process turning them into errors
    remeshes without one."""
    import subprocess
    import sys

    code = ("import trimesh\n"
            "from preform.geometry.remesh import isotropic_remesh\n"
            "m = trimesh.creation.icosphere(2)\n"
            "print(len(isotropic_remesh(m.vertices, m.faces, 0.3)[1]))\n")
    out = subprocess.run([sys.executable, "-W", "error::DeprecationWarning", "-c", code],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.split()[-1]) > 100
