"""The braid-angle kernels of laid yarn (``_kernels.kinematic.braid_cosines_batch``,
``laid_yarn_angles`` through ``preform.laid``) against their slow NumPy reference
(``support.naive_analysis``, whole-array NumPy), on a curved mandrel."""

from __future__ import annotations

import numpy as np
import pytest

from support import naive_analysis as naive
from preform import laid
from preform.laid import CenterlineProjector
from preform.geometry import centerline_from_points, mandrel_from_arrays, shapes
from preform.kinematic import SurfaceArrays


@pytest.fixture(scope="module")
def setup():
    V, F = shapes.cone(0.04, 0.08, 0.5, n_around=48, n_along=30)
    mandrel = mandrel_from_arrays(V, F)
    # a bent centerline (its tangents vary, so the blend of vertex tangents matters)
    z = np.linspace(0.0, 0.5, 41)
    cl = centerline_from_points(np.stack([0.01 * np.sin(6 * z), 0.005 * z, z], axis=1))
    return mandrel, SurfaceArrays.from_mandrel(mandrel), cl, CenterlineProjector(cl)


def _yarns(mandrel, rng, n_yarns=7, n_points=60):
    """Helix-like laid yarns on the surface (points on faces, some repeated: zero chords)."""
    pts, faces, offsets = [], [], [0]
    for _ in range(n_yarns):
        z = np.sort(rng.uniform(0.02, 0.48, n_points))
        phi = rng.uniform(0, 2 * np.pi) + np.cumsum(rng.uniform(0, 0.3, n_points))
        r = 0.04 + 0.08 * z                                  # the cone's radius at z
        far = np.stack([2 * r * np.cos(phi), 2 * r * np.sin(phi), z], axis=1)
        axis = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
        hit, p, f, _ = mandrel.intersect_segments(far, axis)
        assert np.all(hit)
        p[5] = p[4]                                         # a repeated point: zero chord on one side
        f[5] = f[4]
        pts.append(p)
        faces.append(f)
        offsets.append(offsets[-1] + n_points)
    pts.append(pts[0][:1])                                  # a one-point yarn: its direction is T
    faces.append(faces[0][:1])
    offsets.append(offsets[-1] + 1)
    return np.vstack(pts), np.concatenate(faces).astype(np.int64), np.array(offsets, dtype=np.int64)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_laid_braid_angles_match_the_numpy_reference(setup, seed):
    mandrel, surface, cl, project = setup
    points, faces, offsets = _yarns(mandrel, np.random.default_rng(seed))
    mu, tol_k = 0.2, 0.5
    ref_angles, ref_slip = naive.laid_braid_angles(surface, project, cl, points, faces, offsets, mu, tol_k)
    angles, slip = laid.laid_braid_angles(surface, project, cl, points, faces, offsets, mu, tol_k)
    # the same operations, but NumPy's einsum sums the three products of a dot in another order
    # (SIMD pairs): the cosines differ by ~1e-16, the angles by ~1e-16 / sin(alpha) rad; the
    # 1e-11 deg bounds it with a margin of 100 above 1 deg; below, the cosines are compared
    keep = ref_angles > 1.0
    assert keep.sum() > 0.9 * len(keep)
    np.testing.assert_allclose(angles[keep], ref_angles[keep], rtol=0, atol=1e-11)
    np.testing.assert_allclose(np.cos(np.radians(angles)), np.cos(np.radians(ref_angles)), rtol=0, atol=1e-15)
    assert angles[-1] == pytest.approx(0.0, abs=1e-5)      # the one-point yarn runs along T
    np.testing.assert_array_equal(slip, ref_slip)
    assert 0 < slip.sum() < len(slip)                      # both outcomes exercised
    assert np.all((angles >= 0) & (angles <= 90))


def test_braid_angles_at_match_the_numpy_reference(setup):
    mandrel, surface, cl, project = setup
    rng = np.random.default_rng(5)
    points, faces, _ = _yarns(mandrel, rng)
    directions = rng.normal(size=points.shape)
    directions[3] = 0.0                                     # no direction: 90 deg, as the reference
    s = project(points)
    T = cl.frames_at(s)[1]
    n = naive.smooth_normals(surface, faces, points)
    ref = naive.braid_angle(directions, T, n)
    got = laid.braid_angles_at(surface, cl, points, faces, s, directions)
    keep = ref > np.radians(1.0)                            # as above: 1e-16 / sin(alpha) rad
    np.testing.assert_allclose(got[keep], ref[keep], rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.cos(got), np.cos(ref), rtol=0, atol=1e-15)
    # beyond the centerline's ends the tangent is the end tangent (frames_at's straight extension)
    s_out = np.where(np.arange(len(s)) % 2 == 0, -0.1, 0.7)
    ref = naive.braid_angle(directions, cl.frames_at(s_out)[1], n)
    got = laid.braid_angles_at(surface, cl, points, faces, s_out, directions)
    np.testing.assert_allclose(np.cos(got), np.cos(ref), rtol=0, atol=1e-15)
