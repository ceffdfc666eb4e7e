"""The clipping and pooling kernels against slow, obvious NumPy references."""

from __future__ import annotations

import numpy as np
import pytest

from preform.analysis import fields as F
from preform._kernels import fields as K
from support.naive_geometry import point_triangle_distance
from support.field_standins import cylinder, helices


def naive_face_lengths(points, offsets, group, vertices, faces, pieces=400):
    """Cut each segment into `pieces` equal bits and give each bit to the face nearest its middle
    (point-to-triangle distance by brute force). Error per segment: at most the bits that straddle
    an edge, 1/pieces of the segment per edge crossed."""
    tri = vertices[faces]
    out = np.zeros((len(faces), 2))
    for k in range(len(offsets) - 1):
        P = points[offsets[k]:offsets[k + 1]]
        t = (np.arange(pieces) + 0.5) / pieces
        for a, b in zip(P[:-1], P[1:]):
            mids = a + t[:, None] * (b - a)
            nearest = np.argmin(point_triangle_distance(mids, tri), axis=1)
            np.add.at(out[:, group[k]], nearest, np.linalg.norm(b - a) / pieces)
    return out


def test_clip_matches_sampled_reference_and_conserves_length():
    mandrel = cylinder(sections=10, height=0.1)
    V, Fc, _ = F.refine_to_edge_length(mandrel.vertices, mandrel.faces, 0.03)
    normals, _, centroids = F.face_geometry(V, Fc)
    yarns = helices(np.radians(35.0), 2, z1=0.1, dz=5e-3)
    length, moment, unmapped = F.clip_yarns(yarns, V, Fc, normals, centroids)
    total = sum(np.linalg.norm(np.diff(yarns.yarn(k), axis=0), axis=1).sum() for k in range(yarns.n_yarns))
    assert length.sum() == pytest.approx(total, rel=1e-12) and unmapped == 0.0
    # the moment's trace is the length (unit directions)
    assert np.allclose(np.trace(moment, axis1=2, axis2=3), length, atol=1e-14)
    ref = naive_face_lengths(yarns.points, yarns.offsets, yarns.group, V, Fc)
    # 1 mm: bits of 1/400 of a 5 mm segment straddling edges, plus the wedge-vs-nearest-face
    # difference for points that sit off the facets by the chord error (< 0.5 mm here)
    assert np.abs(length - ref).max() < 1e-3
    assert np.abs(length - ref).sum() < 0.01 * total


def test_walk_off_an_open_mesh_counts_as_unmapped():
    mandrel = cylinder(sections=10, height=0.1)
    yarns = helices(np.radians(35.0), 2, z0=0.0, z1=0.15, dz=5e-3)  # a third runs past the top
    normals, _, centroids = F.face_geometry(mandrel.vertices, mandrel.faces)
    keep = np.abs(normals[:, 2]) < 0.5  # drop the caps: an open tube
    Fo = mandrel.faces[keep]
    length, _, unmapped = F.clip_yarns(yarns, mandrel.vertices, Fo, normals[keep], centroids[keep])
    total = sum(np.linalg.norm(np.diff(yarns.yarn(k), axis=0), axis=1).sum() for k in range(yarns.n_yarns))
    assert length.sum() + unmapped == pytest.approx(total, rel=1e-12)
    assert unmapped == pytest.approx(total / 3, rel=0.05)


def test_pool_sums_matches_dense_reference():
    rng = np.random.default_rng(3)
    centroids = rng.uniform(0, 0.1, (300, 3))
    normals = rng.normal(size=(300, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    radius = rng.uniform(0.01, 0.03, 300)
    values = rng.normal(size=(300, 4))
    d = np.linalg.norm(centroids[:, None] - centroids[None], axis=2)
    w = np.clip(1 - (d / radius[:, None]) ** 2, 0, None) ** 2
    w[normals @ normals.T < 0.5] = 0.0
    np.fill_diagonal(w, 1.0)
    got = K.pool_sums(centroids, centroids, normals, radius, values, 0.5)
    assert np.allclose(got, w @ values, rtol=1e-12, atol=1e-12)
    # values sitting elsewhere than the window centres: distances from c_f to s_g
    sources = centroids + rng.uniform(-0.01, 0.01, (300, 3))
    d = np.linalg.norm(sources[None] - centroids[:, None], axis=2)
    w = np.clip(1 - (d / radius[:, None]) ** 2, 0, None) ** 2
    w[normals @ normals.T < 0.5] = 0.0
    np.fill_diagonal(w, 1.0)
    got = K.pool_sums(centroids, sources, normals, radius, values, 0.5)
    assert np.allclose(got, w @ values, rtol=1e-12, atol=1e-12)


def test_edge_planes_are_shared_between_neighbours():
    mandrel = cylinder(sections=8)
    normals, _, _ = F.face_geometry(mandrel.vertices, mandrel.faces)
    m, off, nb = F.edge_planes(mandrel.vertices, mandrel.faces, normals)
    assert (nb >= 0).all()  # closed mesh
    for f in range(len(nb)):
        for j in range(3):
            g = nb[f, j]
            jg = int(np.flatnonzero(nb[g] == f)[0])
            assert np.array_equal(m[f, j], -m[g, jg]) and off[f, j] == -off[g, jg]
