"""Slow obvious NumPy references of the braid-angle kernels (``_kernels/kinematic.py``:
``braid_angles_batch``, ``laid_yarn_angles``): whole-array NumPy, one operation at a time."""

from __future__ import annotations

import numpy as np

from preform.kinematic import smooth_normals
from preform.tolerances import tol


def braid_angle(direction, tangent, normal):
    """Braid angle (rad, magnitude in [0, pi/2]) between directions and the surface projection of
    the centerline tangent (docs/architecture.md §2). All (m, 3); normal unit."""
    d = direction - np.einsum("ij,ij->i", direction, normal)[:, None] * normal
    t = tangent - np.einsum("ij,ij->i", tangent, normal)[:, None] * normal
    dn = np.linalg.norm(d, axis=1)
    tn = np.linalg.norm(t, axis=1)
    c = np.abs(np.einsum("ij,ij->i", d, t)) / np.where(dn * tn > 0, dn * tn, 1.0)
    return np.arccos(np.clip(c, 0.0, 1.0))


def laid_braid_angles(surface, project, centerline, points, face, offsets, mu,
                      curvature_tol=tol.slip_curvature):
    """Braid angle (deg) of the laid yarn at every point, and its slip tendency (bool).

    surface : kinematic.SurfaceArrays of the mandrel; project : CenterlineProjector
    points (m, 3) float64, m, mandrel frame; face (m,) int64; offsets (n_yarns + 1,) int64: yarn
    ``k`` is ``points[offsets[k]:offsets[k + 1]]``; mu : yarn-mandrel friction coefficient.

    The laid direction at a point is the chord between its neighbours along the yarn (one-sided at
    the ends). Slip tendency (docs/theory.md §3): ``|kappa_g| > mu |kappa_n| + curvature_tol``, with
    the curvature vector from a three-point stencil and the normal curvature from the smooth
    normal field.
    """
    m = len(points)
    angles = np.zeros(m)
    slip = np.zeros(m, dtype=bool)
    if m == 0:
        return angles, slip
    prev_i = np.arange(m) - 1
    next_i = np.arange(m) + 1
    starts = offsets[:-1]
    ends = offsets[1:] - 1
    prev_i[starts] = starts
    next_i[ends] = ends
    d = points[next_i] - points[prev_i]
    s = project(points)
    T = centerline.frames_at(s)[1]
    n = smooth_normals(surface, face, points)
    single = np.linalg.norm(d, axis=1) == 0
    angles = np.degrees(braid_angle(np.where(single[:, None], T, d), T, n))
    # curvatures (interior points with both neighbours distinct)
    a = points[prev_i]
    b = points[next_i]
    l1 = np.linalg.norm(points - a, axis=1)
    l2 = np.linalg.norm(b - points, axis=1)
    ok = (l1 > 0) & (l2 > 0)
    if np.any(ok):
        t1 = (points[ok] - a[ok]) / l1[ok, None]
        t2 = (b[ok] - points[ok]) / l2[ok, None]
        tm = t1 + t2
        tm /= np.maximum(np.linalg.norm(tm, axis=1), 1e-300)[:, None]
        kvec = (t2 - t1) / (0.5 * (l1[ok] + l2[ok]))[:, None]
        nn = n[ok]
        kappa_g = np.einsum("ij,ij->i", kvec, np.cross(nn, tm))
        na = smooth_normals(surface, face[prev_i][ok], a[ok])
        nb = smooth_normals(surface, face[next_i][ok], b[ok])
        kappa_n = np.einsum("ij,ij->i", nb - na, tm) / (l1[ok] + l2[ok])
        slip[np.nonzero(ok)[0]] = np.abs(kappa_g) > mu * np.abs(kappa_n) + curvature_tol
    return angles, slip
