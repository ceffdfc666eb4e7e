"""The closest-point searches on a polyline against their NumPy references (``naive_kinematic``):
``_kernels.mesh.project_to_polyline`` (``Centerline.project``) and ``project_sampled``
(``laid.CenterlineProjector``)."""

from __future__ import annotations

import numpy as np
import pytest

from preform._kernels.mesh import project_to_polyline, sample_tree
from preform.laid import CenterlineProjector
from preform.geometry.centerline import centerline_from_points
from support import naive_kinematic as naive


def arc_lengths(P):
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])


def kernel(points, P):
    S = arc_lengths(P)
    out_s = np.empty(len(points))
    out_d = np.empty(len(points))
    project_to_polyline(np.ascontiguousarray(points), np.ascontiguousarray(P), S, out_s, out_d)
    return out_s, out_d


def polylines():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 1, 201)
    yield "bent tube", np.stack([0.6 * np.sin(2 * t), 0.1 * t, 0.6 * (1 - np.cos(2 * t))], axis=1)
    yield "helix", np.stack([0.2 * np.cos(12 * t), 0.2 * np.sin(12 * t), t], axis=1)
    yield "random walk", np.cumsum(rng.normal(scale=0.05, size=(120, 3)), axis=0)
    yield "one segment", np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 3.0]])
    yield "U turn", np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    P = np.stack([np.cos(3 * t), np.sin(3 * t), 0 * t], axis=1)
    yield "with repeated vertices", np.repeat(P, 2, axis=0)


@pytest.mark.parametrize("name,P", list(polylines()), ids=[n for n, _ in polylines()])
def test_equals_brute_force_bit_for_bit(name, P):
    rng = np.random.default_rng(len(P))
    lo, hi = P.min(axis=0) - 0.3, P.max(axis=0) + 0.3
    points = np.concatenate([
        rng.uniform(lo, hi, size=(1500, 3)),                     # anywhere around it
        P[rng.integers(0, len(P), 200)] + rng.normal(scale=0.01, size=(200, 3)),  # near it
        P[rng.integers(0, len(P), 50)],                          # on its vertices
        rng.uniform(lo, hi, size=(1, 3)) * 1e3,                  # far away
    ])
    if name == "U turn":   # equidistant from the two legs: ties between far-apart segments
        points = np.concatenate([points, np.stack([rng.uniform(0, 1, 300), np.full(300, 0.5),
                                                   rng.normal(size=300)], axis=1)])
    s, d = kernel(points, P)
    s_ref, d_ref = naive.project_to_polyline_loops(points, P, arc_lengths(P))
    np.testing.assert_array_equal(s, s_ref)
    np.testing.assert_array_equal(d, d_ref)
    # and the definition in whole-array NumPy (other summation order: rounding only, 1e-12 m)
    s_np, d_np = naive.project_to_polyline(points, P, arc_lengths(P))
    np.testing.assert_allclose(d, d_np, rtol=0, atol=1e-12 * max(1.0, np.abs(points).max()))
    ok = np.abs(d - d_np) < 1e-13        # where the nearest distance is unique the s agrees
    np.testing.assert_allclose(s[ok], s_np[ok], rtol=0, atol=1e-9)


def test_tie_takes_the_lower_segment():
    P = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    s, d = kernel(np.array([[0.5, 0.5, 0.0]]), P)   # 0.5 from all three segments
    assert s[0] == 0.5 and d[0] == 0.5


@pytest.mark.parametrize("name,P", list(polylines()), ids=[n for n, _ in polylines()])
def test_sampled_projector_equals_numpy_bit_for_bit(name, P):
    """CenterlineProjector's kernel (box tree, then the two resampled segments) gives the arc
    lengths of the whole-array NumPy projector (KD-tree) to the last bit; a spacing of a
    thousandth of the length, as 0.5 mm on case A's 3 m."""
    rng = np.random.default_rng(len(P) + 1)
    cl = centerline_from_points(P)
    proj = CenterlineProjector(cl, spacing=cl.length / 1000)
    lo, hi = P.min(axis=0) - 0.3, P.max(axis=0) + 0.3
    points = np.concatenate([
        rng.uniform(lo, hi, size=(3000, 3)),
        P[rng.integers(0, len(P), 300)] + rng.normal(scale=0.02, size=(300, 3)),
        proj.points[rng.integers(0, len(proj.points), 50)],            # on samples
        rng.uniform(lo, hi, size=(1, 3)) * 1e3,
    ])
    np.testing.assert_array_equal(proj(points), naive.project_sampled(points, proj.points, proj.s))


def test_sample_tree_boxes_hold_their_samples():
    t = np.linspace(0, 1, 1001)
    Q = np.stack([np.cos(3 * t), np.sin(3 * t), t], axis=1)
    lo, hi, left, box = sample_tree(Q)
    used = np.nonzero(lo >= 0)[0]
    leaves = used[left[used] < 0]
    # the leaves cover every sample once
    np.testing.assert_array_equal(np.sort(np.concatenate([np.arange(lo[k], hi[k]) for k in leaves])),
                                  np.arange(len(Q)))
    for k in used:
        q = Q[lo[k]:hi[k]]
        np.testing.assert_array_equal(box[k, :3], q.min(axis=0))
        np.testing.assert_array_equal(box[k, 3:], q.max(axis=0))
