"""``Mandrel.closest_points`` (KD-tree of face centroids plus exact point-triangle projection in
numba) against trimesh's general ``closest_point`` on the shipped case A mandrel and a bent tube:
points on and off the surface (inside and outside, near vertices and edges, far away)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from preform.geometry import load_mandrel, shapes
from preform.geometry.mandrel import Mandrel

ROOT = Path(__file__).resolve().parents[2]


def _mandrels():
    yield load_mandrel(ROOT / "mandrels" / "case_a.stl")
    v, f = shapes.cylinder(0.05, 0.3, n_around=24)
    yield load_mandrel_from(v, f)


def load_mandrel_from(v, f):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "c.stl"
        trimesh.Trimesh(v, f, process=False).export(path)
        return load_mandrel(path)


@pytest.mark.parametrize("which", [0, 1])
def test_closest_points_match_trimesh(which):
    mandrel = list(_mandrels())[which]
    assert isinstance(mandrel, Mandrel)
    rng = np.random.default_rng(which)
    V, F = mandrel.vertices, mandrel.faces
    # points at random faces' interiors, edges and vertices, pushed off along random directions
    # by 0 to a few facet sizes, plus far points
    f = rng.integers(len(F), size=600)
    w = rng.dirichlet([1, 1, 1], size=600)
    w[:100, 2] = 0.0
    w[:100] /= w[:100].sum(axis=1)[:, None]          # on edges
    w[100:150] = np.eye(3)[rng.integers(3, size=50)]  # on vertices
    base = np.einsum("ij,ijk->ik", w, V[F[f]])
    size = float(np.median(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1)))
    off = rng.normal(size=(600, 3)) * rng.choice([0.0, 1e-4, 0.3 * size, 3 * size], size=600)[:, None]
    pts = np.vstack([base + off, rng.normal(scale=mandrel.diagonal, size=(20, 3))])
    got, face = mandrel.closest_points(pts)
    scale = mandrel.diagonal
    d = np.linalg.norm(got - pts, axis=1)
    # the point lies on the face it names (barycentric coordinates >= 0, on its plane: 1e-9 and
    # 1e-12 of the mandrel, round-off)
    tri = V[F[face]]
    A = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=2)
    bary = np.array([np.linalg.lstsq(A[i], got[i] - tri[i, 0], rcond=None)[0] for i in range(len(pts))])
    assert bary.min() > -1e-9 and (1.0 - bary.sum(axis=1)).min() > -1e-9
    # as close as trimesh's per-triangle projection onto that face, and never further: trimesh
    # rounds a point near an edge onto it (measured 1.4e-7 m off the true point, 1.2e-10 m
    # further from the query point on case A)
    dp = np.linalg.norm(trimesh.triangles.closest_point(tri, pts) - pts, axis=1)
    assert np.all(d <= dp + 1e-12 * scale) and np.all(d >= dp - 1e-9 * scale)
    # never further than trimesh's general query (which can miss the closest face: measured
    # 3.2e-5 m further at one of these points on case A, whose point lies inside its triangle)
    _, dist, _ = trimesh.proximity.closest_point(mandrel.mesh, pts)
    assert np.all(d <= dist + 1e-12 * scale)
    # the closest face over all faces, by brute force with trimesh's per-triangle projection, on
    # a sample of the points (every face x 60 points)
    every = V[F]
    for i in rng.choice(len(pts), size=60, replace=False):
        q = trimesh.triangles.closest_point(every, np.repeat(pts[i:i + 1], len(F), axis=0))
        best = np.linalg.norm(q - pts[i], axis=1).min()
        assert best - 1e-9 * scale <= d[i] <= best + 1e-12 * scale
