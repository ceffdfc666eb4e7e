"""Mesh kernels of the intake (``_kernels.mesh``) against their NumPy references
(``support.naive_intake``), bit for bit: corner angles' cosines, the corners around each vertex,
face centroids and reach."""

from __future__ import annotations

import numpy as np
import trimesh

from preform._kernels.mesh import centroids_and_reach, corner_cosines, corners_by_vertex
from support import naive_intake


def meshes():
    rng = np.random.default_rng(2)
    yield trimesh.creation.cylinder(radius=0.04, height=1.6, sections=64)
    s = trimesh.creation.icosphere(subdivisions=3)
    yield trimesh.Trimesh(s.vertices + rng.normal(scale=0.01, size=s.vertices.shape), s.faces, process=False)
    V = rng.normal(size=(50, 3))
    yield trimesh.Trimesh(np.vstack([V, [[9.0, 9.0, 9.0]]]), rng.integers(0, 50, size=(200, 3)), process=False)


def test_corner_cosines_equal_numpy():
    for m in meshes():
        V, F = np.asarray(m.vertices, dtype=float), np.asarray(m.faces, dtype=np.int64)
        got = np.empty((len(F), 3))
        corner_cosines(V, F, got)
        np.testing.assert_array_equal(got, naive_intake.corner_cosines(V, F))


def test_corners_by_vertex_equal_stable_argsort():
    for m in meshes():
        V, F = np.asarray(m.vertices, dtype=float), np.asarray(m.faces, dtype=np.int64)
        ptr = np.empty(len(V) + 1, dtype=np.int64)
        faces = np.empty(3 * len(F), dtype=np.int64)
        corner = np.empty(3 * len(F), dtype=np.int64)
        corners_by_vertex(F, len(V), ptr, faces, corner)
        ref_ptr, ref_faces, ref_corner = naive_intake.corners_by_vertex(F, len(V))
        np.testing.assert_array_equal(ptr, ref_ptr)
        np.testing.assert_array_equal(faces, ref_faces)
        np.testing.assert_array_equal(corner, ref_corner)


def test_centroids_and_reach_equal_numpy():
    for m in meshes():
        V, F = np.asarray(m.vertices, dtype=float), np.asarray(m.faces, dtype=np.int64)
        c = np.empty((len(F), 3))
        r = np.empty(len(F))
        centroids_and_reach(V, F, c, r)
        ref_c, ref_r = naive_intake.centroids_and_reach(V, F)
        np.testing.assert_array_equal(c, ref_c)
        np.testing.assert_array_equal(r, ref_r)


def test_any_side_longer_is_the_subdivision_test():
    from preform._kernels.mesh import any_side_longer

    for m in meshes():
        V, F = np.asarray(m.vertices, dtype=float), np.asarray(m.faces, dtype=np.int64)
        tri = V[F]
        sides = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
        for h in (0.5 * sides.max(), sides.max(), np.nextafter(sides.max(), 0), 2 * sides.max()):
            assert any_side_longer(V, F, h) == bool((sides > h).any())
