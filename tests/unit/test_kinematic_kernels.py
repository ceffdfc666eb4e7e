"""The fell-point walk kernel against its NumPy twin and against cylinder geometry."""

from __future__ import annotations

import numpy as np
import pytest

from preform._kernels import kinematic as K
from support import naive_kinematic as naive


def tube_arrays(r=0.075, length=0.4, n_around=64, n_along=40):
    """Open tube along +z with analytic radial corner normals (independent of preform.geometry)."""
    th = 2 * np.pi * np.arange(n_around) / n_around
    z = np.linspace(0, length, n_along + 1)
    V = np.array([[r * np.cos(a), r * np.sin(a), zz] for zz in z for a in th])
    T = []
    for j in range(n_along):
        for i in range(n_around):
            a, b = j * n_around + i, j * n_around + (i + 1) % n_around
            c, d = a + n_around, b + n_around
            T += [[a, b, d], [a, d, c]]
    T = np.array(T, dtype=np.int64)
    p = V[T]
    FN = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    FN /= np.linalg.norm(FN, axis=1)[:, None]
    radial = V.copy()
    radial[:, 2] = 0
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    CN = radial[T]
    edges = {}
    for f, tri in enumerate(T):
        for k in range(3):
            edges[(tri[k], tri[(k + 1) % 3])] = (f, k)
    NB = -np.ones((len(T), 3), dtype=np.int64)
    for (a, b), (f, k) in edges.items():
        if (b, a) in edges:
            NB[f, k] = edges[(b, a)][0]
    return V, T, FN, CN, NB


def point_on_tube(V, T, f):
    return V[T[f]].mean(axis=0)


def test_face_normals_outward():
    V, T, FN, CN, NB = tube_arrays()
    centroid = V[T].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", FN, centroid * [1, 1, 0]) > 0)


@pytest.mark.parametrize("seed", range(12))
def test_walk_matches_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    V, T, FN, CN, NB = tube_arrays()
    f = int(rng.integers(len(T) // 3, 2 * len(T) // 3))
    x = point_on_tube(V, T, f)
    phi = np.arctan2(x[1], x[0]) + rng.uniform(0.9, 1.6)   # supply point well past tangency
    R = rng.uniform(0.15, 0.5)
    G_end = np.array([R * np.cos(phi), R * np.sin(phi), x[2] + rng.uniform(0.05, 0.3)])
    G_mid = G_end + rng.normal(scale=0.002, size=3)
    got = K.walk_to_tangency(V, T, FN, CN, NB, *x, f, *G_mid, *G_end, 0.002, 1.0)
    ref = naive.walk(V, T, FN, CN, NB, x, f, G_mid, G_end, 0.002, 1.0)
    assert got[4] == ref[2]
    assert got[3] == ref[1]
    # both cut the last sub-step at the root of g: bisection (1e-13) vs brentq (1e-14)
    np.testing.assert_allclose(got[:3], ref[0], atol=1e-10)
    assert got[5] == pytest.approx(ref[3], abs=1e-10)


def test_walk_ends_tangent_with_the_cylinder_lag():
    """On a cylinder the tangent free yarn leaves the fell point acos(r/R) behind its supply point."""
    r, R = 0.075, 0.3
    V, T, FN, CN, NB = tube_arrays(r=r, n_around=256, n_along=40)
    f = len(T) // 2
    x = point_on_tube(V, T, f)
    phi = np.arctan2(x[1], x[0]) + 1.5
    G = np.array([R * np.cos(phi), R * np.sin(phi), x[2] + 0.2])
    xe, ye, ze, fe, status, walked = K.walk_to_tangency(V, T, FN, CN, NB, *x, f, *G, *G, 1e-3, 1.0)
    assert status == K.WALK_TANGENT
    assert abs(K.tangency_gap(V, T, CN, fe, xe, ye, ze, *G)) < 1e-9
    lag = phi - np.arctan2(ye, xe)
    # facets: the smooth normal is radial, the point sits on a chord (sagitta ~ r (pi/256)^2 / 2)
    assert lag == pytest.approx(np.arccos(r / R), abs=2e-3)


def test_liftoff_when_yarn_is_not_cutting_in():
    V, T, FN, CN, NB = tube_arrays()
    f = len(T) // 2
    x = point_on_tube(V, T, f)
    G = x * [4, 4, 1] + [0, 0, 0.2]   # straight outwards: g > 0
    out = K.walk_to_tangency(V, T, FN, CN, NB, *x, f, *G, *G, 1e-3, 1.0)
    assert out[4] == K.WALK_LIFTOFF and out[5] == 0.0


def test_concave_surface_is_reported():
    """Inside of the tube (normals flipped, seen from inside): g falls as the walk goes on."""
    V, T, FN, CN, NB = tube_arrays()
    T2 = T[:, ::-1].copy()
    FN2 = -FN
    CN2 = -CN[:, ::-1]
    edges = {}
    for f, tri in enumerate(T2):
        for k in range(3):
            edges[(tri[k], tri[(k + 1) % 3])] = (f, k)
    NB2 = -np.ones_like(NB)
    for (a, b), (f, k) in edges.items():
        if (b, a) in edges:
            NB2[f, k] = edges[(b, a)][0]
    f = len(T2) // 2
    x = point_on_tube(V, T2, f)
    a = np.arctan2(x[1], x[0])
    # a supply point inside the tube, behind the local tangent plane (g < 0), off to one side
    G = 0.07 * np.array([np.cos(a + 0.3), np.sin(a + 0.3), 0]) * 1.5 + [0, 0, x[2] + 0.1]
    assert K.tangency_gap(V, T2, CN2, f, *x, *G) < 0
    out = K.walk_to_tangency(V, T2, FN2, CN2, NB2, *x, f, *G, *G, 1e-3, 1.0)
    assert out[4] == K.WALK_CONCAVE


def test_smooth_normal_is_radial_on_the_tube():
    V, T, FN, CN, NB = tube_arrays(n_around=16)
    rng = np.random.default_rng(1)
    faces = rng.integers(0, len(T), 50)
    b = rng.dirichlet([1, 1, 1], 50)
    pts = np.einsum("ij,ijk->ik", b, V[T[faces]])
    out = np.empty((50, 3))
    K.smooth_normals_batch(V, T, CN, faces.astype(np.int64), pts, out)
    for i in range(50):
        np.testing.assert_allclose(out[i], naive.normal(V, T, CN, faces[i], pts[i]), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-12)
