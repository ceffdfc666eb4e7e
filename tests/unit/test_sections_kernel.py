"""Section chaining (``geometry.centerline.chain_segments`` on ``_kernels.sections.chain_loops``)
against the slow Python walk of ``support.naive_intake.chain_loops`` (dictionaries of neighbours),
on shuffled and awkward segment soups and a mesh section: the same loops, nodes and kept ends."""

from __future__ import annotations

import numpy as np
import pytest

from preform._kernels.sections import chain_loops
from preform.geometry.centerline import _row_ids, chain_segments
from support import naive_intake


def reference_chain(segments, rel_tol=1e-9):
    """``chain_segments`` with the Python walk: the nodes as ``chain_segments`` welds them, the
    loops from ``naive_intake.chain_loops``; also (ids, node count) for the kernel's own call."""
    segments = np.asarray(segments, dtype=float)
    scale = float(np.ptp(segments.reshape(-1, 3), axis=0).max()) or 1.0
    keys = np.round(segments.reshape(-1, 3) / (rel_tol * 1e3 * scale)).astype(np.int64)
    ids = np.ascontiguousarray(_row_ids(keys).reshape(-1, 2), dtype=np.int64)
    nodes, offsets, src = naive_intake.chain_loops(ids, int(ids.max()) + 1)
    ends = segments.reshape(-1, 3)
    loops = [ends[src[np.append(nodes[a:b], nodes[a])]] for a, b in zip(offsets[:-1], offsets[1:])]
    return loops, (ids, int(ids.max()) + 1)


def assert_same_walk(ids, n_nodes):
    """The kernel's (nodes, offsets, src) are the Python walk's, array for array."""
    for got, ref in zip(chain_loops(ids, n_nodes), naive_intake.chain_loops(ids, n_nodes)):
        np.testing.assert_array_equal(got, ref)


def _polygon(n, r, z, phase=0.0):
    a = phase + 2 * np.pi * np.arange(n) / n
    return np.stack([r * np.cos(a), r * np.sin(a), np.full(n, z)], axis=1)


def _segments(points, closed=True):
    nxt = np.roll(points, -1, axis=0)
    seg = np.stack([points, nxt], axis=1)
    return seg if closed else seg[:-1]


def _soup(rng):
    parts = [_segments(_polygon(40, 0.05, 0.0)),                     # a loop
             _segments(_polygon(7, 0.01, 0.0, 0.3) + [0.2, 0, 0]),    # a second, small loop
             _segments(_polygon(9, 0.02, 0.0) + [0.5, 0, 0], closed=False)]   # an open chain
    eight = np.vstack([_polygon(6, 0.01, 0.0) + [0, 0.3, 0], _polygon(6, 0.01, 0.0, np.pi) + [0.02, 0.3, 0]])
    parts.append(_segments(eight[:6]))                               # a figure eight: two loops
    parts.append(_segments(eight[6:]))                               # sharing one node
    seg = np.vstack(parts)
    seg = np.vstack([seg, seg[:1, :1].repeat(2, axis=1)])            # a segment of zero length
    seg = np.vstack([seg, seg[3:4]])                                 # a duplicated segment
    seg = seg[rng.permutation(len(seg))]
    flip = rng.random(len(seg)) < 0.5
    seg[flip] = seg[flip, ::-1]
    return seg + rng.normal(scale=1e-14, size=seg.shape)             # welded ends differ by a hair


@pytest.mark.parametrize("seed", range(6))
def test_chain_segments_matches_the_python_reference(seed):
    seg = _soup(np.random.default_rng(seed))
    ref, walk = reference_chain(seg)
    assert_same_walk(*walk)
    got = chain_segments(seg)
    assert len(got) == len(ref) >= 2                                  # the figure eight gives 0-2
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a, b)                          # the same points, same order
        assert np.array_equal(a[0], a[-1])


def test_chain_segments_on_a_mesh_section():
    import trimesh
    from trimesh.intersections import mesh_plane

    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    seg = mesh_plane(mesh, plane_normal=[0.2, 0.1, 1.0], plane_origin=[0, 0, 0.03])
    (loop,) = chain_segments(np.asarray(seg))
    (ref,), walk = reference_chain(seg)
    assert_same_walk(*walk)
    np.testing.assert_array_equal(loop, ref)
    assert len(loop) == len(seg) + 1
    assert chain_segments(np.zeros((0, 2, 3))) == []


def test_faces_near_plane_window_is_the_full_scan():
    from preform.geometry.centerline import _faces_near_plane, _slab_index
    from preform.geometry import shapes
    import trimesh

    V, F = shapes.cylinder(0.04, 1.6, n_around=64, n_along=200)      # 25 k faces: the window is used
    mesh = trimesh.Trimesh(V, np.asarray(F), process=False)
    bent = trimesh.Trimesh(V + np.stack([0.3 * V[:, 2] ** 2, 0 * V[:, 2], 0 * V[:, 2]], axis=1),
                           np.asarray(F), process=False)
    rng = np.random.default_rng(3)
    windowed = 0
    for m in (mesh, bent):
        centroids, reach = _slab_index(m)
        for _ in range(60):
            n = rng.normal(size=3) * [0.6, 0.6, 1.0]
            n /= np.linalg.norm(n)
            level = rng.uniform(-0.1, 1.7) * n[2] + rng.normal(scale=0.05)
            full = np.nonzero(np.abs(centroids @ n - level) <= reach * (1.0 + 1e-9))[0]
            got = _faces_near_plane(m, n, level)
            np.testing.assert_array_equal(got, full)
            windowed += np.abs(n).max() >= 0.5 and len(full) > 0
    assert windowed > 40                                  # the window path was taken and found faces
