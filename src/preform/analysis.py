"""The laid yarn's braid angle, curvature and slip tendency, and arc length along the centerline
(DESIGN.md §2, §3.2): post-processing of deposited yarn for the history and the yarn paths.

``braid_angle`` is the angle between a yarn direction and the surface projection of the centerline
tangent; ``laid_braid_angles`` evaluates it along every deposited yarn and flags the points where
the laid yarn would slip on the mandrel, ``|kappa_g| > mu kappa_n``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .kinematic import smooth_normals
from .tolerances import tol


class CenterlineProjector:
    """Arc length (m) of points near a centerline: KD-tree on a dense resampling.

    Accurate to ``spacing / 2`` in s before refinement; the nearest sample's two segments are then
    projected exactly, so the result is the polyline's closest point up to ties between branches.
    """

    def __init__(self, centerline, spacing=tol.projector_spacing):
        L = centerline.length
        n = max(int(np.ceil(L / spacing)) + 1, 2)
        self.s = np.linspace(0.0, L, n)
        self.points = centerline.frames_at(self.s)[0]
        self.tree = cKDTree(self.points)

    def __call__(self, points):
        """points (m, 3) float64, m, mandrel frame -> (m,) float64 arc length, m."""
        points = np.atleast_2d(points)
        _, i = self.tree.query(points)
        n = len(self.s)
        best_s = self.s[i].copy()
        best_d = np.full(len(points), np.inf)
        for lo in (np.maximum(i - 1, 0), i):
            hi = np.minimum(lo + 1, n - 1)
            a = self.points[lo]
            ab = self.points[hi] - a
            L2 = np.einsum("ij,ij->i", ab, ab)
            u = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
            d = np.linalg.norm(a + u[:, None] * ab - points, axis=1)
            better = d < best_d
            best_d[better] = d[better]
            best_s[better] = (self.s[lo] + u * (self.s[hi] - self.s[lo]))[better]
        return best_s


def mandrel_friction(config) -> float:
    """Yarn-mandrel friction coefficient for the slip tendency: the config has no coefficient of
    its own for yarn on the mandrel, so it is the yarn-yarn one, ``[yarn] friction``."""
    return config.yarn.friction


def braid_angle(direction, tangent, normal):
    """Braid angle (rad, magnitude in [0, pi/2]) between directions and the surface projection of
    the centerline tangent (DESIGN.md §2). All (m, 3); normal unit."""
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
    the ends). Slip tendency (DESIGN.md §3.2): ``|kappa_g| > mu |kappa_n| + curvature_tol``, with
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
