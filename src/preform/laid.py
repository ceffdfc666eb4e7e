"""The laid yarn's braid angle, curvature and slip tendency, and arc length along the centerline
(docs/architecture.md §2, docs/theory.md §3): post-processing of deposited yarn for the history
and the yarn paths.

``braid_angle`` is the angle between a yarn direction and the surface projection of the centerline
tangent; ``laid_braid_angles`` evaluates it along every deposited yarn and flags the points where
the laid yarn would slip on the mandrel, ``|kappa_g| > mu kappa_n``.
"""

from __future__ import annotations

import numpy as np
from ._kernels import kinematic as K
from ._kernels.mesh import project_sampled, sample_tree
from .tolerances import tol


class CenterlineProjector:
    """Arc length (m) of points near a centerline, through a dense resampling.

    The nearest sample (exact, a box tree over the samples), then its two resampled segments
    projected exactly, so the result is the polyline's closest point up to ties between branches
    (kernel ``_kernels.mesh.project_sampled``).
    """

    def __init__(self, centerline, spacing=tol.projector_spacing):
        L = centerline.length
        n = max(int(np.ceil(L / spacing)) + 1, 2)
        self.s = np.linspace(0.0, L, n)
        self.points = np.ascontiguousarray(centerline.frames_at(self.s)[0])
        self._tree = sample_tree(self.points)

    def __call__(self, points):
        """points (m, 3) float64, m, mandrel frame -> (m,) float64 arc length, m."""
        points = np.ascontiguousarray(np.atleast_2d(points), dtype=np.float64)
        out = np.empty(len(points))
        project_sampled(points, self.points, self.s, *self._tree, out)
        return out


def mandrel_friction(config):
    """Yarn-mandrel friction coefficient for the slip tendency: the config has no coefficient of
    its own for yarn on the mandrel, so it is the yarn-yarn one, ``[yarn] friction``; mixed
    yarns: (n_yarns,), every yarn's type's own ``friction``."""
    if getattr(config, "is_mixed", False):
        return np.array([t.friction for t in config.types])[config.carrier_types()]
    return config.yarn.friction


def braid_angle(direction, tangent, normal):
    """Braid angle (rad, magnitude in [0, pi/2]) between directions and the surface projection of
    the centerline tangent (docs/architecture.md §2). All (m, 3); normal unit."""
    d = direction - np.einsum("ij,ij->i", direction, normal)[:, None] * normal
    t = tangent - np.einsum("ij,ij->i", tangent, normal)[:, None] * normal
    dn = np.linalg.norm(d, axis=1)
    tn = np.linalg.norm(t, axis=1)
    c = np.abs(np.einsum("ij,ij->i", d, t)) / np.where(dn * tn > 0, dn * tn, 1.0)
    return np.arccos(np.clip(c, 0.0, 1.0))


def _c(a, dtype=np.float64):
    return np.ascontiguousarray(a, dtype=dtype)


def braid_angles_at(surface, centerline, points, faces, s, directions):
    """Braid angle (rad) of directions (m, 3) at points (m, 3) on faces (m,) with centerline arc
    lengths s (m,): ``braid_angle`` with the centerline tangent at s (``Centerline.frames_at``)
    and the smooth normal, in one kernel pass (``_kernels.kinematic.braid_angles_batch``)."""
    c = np.empty(len(points))
    K.braid_cosines_batch(surface.V, surface.T, surface.CN, _c(centerline.s), _c(centerline.tangents),
                          _c(points).reshape(-1, 3), _c(faces, np.int64), _c(s),
                          _c(directions).reshape(-1, 3), c)
    return np.arccos(np.clip(c, 0.0, 1.0))


def laid_braid_angles(surface, project, centerline, points, face, offsets, mu,
                      curvature_tol=tol.slip_curvature, s=None):
    """Braid angle (deg) of the laid yarn at every point, and its slip tendency (bool).

    surface : kinematic.SurfaceArrays of the mandrel; project : CenterlineProjector
    points (m, 3) float64, m, mandrel frame; face (m,) int64; offsets (n_yarns + 1,) int64: yarn
    ``k`` is ``points[offsets[k]:offsets[k + 1]]``; mu : yarn-mandrel friction coefficient, one
    or (n_yarns,) one per yarn;
    s : the points' arc lengths when already known (else ``project(points)``).

    The laid direction at a point is the chord between its neighbours along the yarn (one-sided at
    the ends). Slip tendency (docs/theory.md §3): ``|kappa_g| > mu |kappa_n| + curvature_tol``, with
    the curvature vector from a three-point stencil and the normal curvature from the smooth
    normal field (kernel ``_kernels.kinematic.laid_yarn_angles``).
    """
    m = len(points)
    slip = np.zeros(m, dtype=bool)
    if m == 0:
        return np.zeros(m), slip
    prev_i = np.arange(m) - 1
    next_i = np.arange(m) + 1
    starts = offsets[:-1]
    ends = offsets[1:] - 1
    prev_i[starts] = starts
    next_i[ends] = ends
    s = project(points) if s is None else s
    c = np.empty(m)
    per_point = (np.full(m, float(mu)) if np.ndim(mu) == 0 else
                 np.repeat(np.asarray(mu, dtype=float), np.diff(offsets)))
    K.laid_yarn_angles(surface.V, surface.T, surface.CN, _c(centerline.s), _c(centerline.tangents),
                       _c(points), _c(face, np.int64), _c(s), prev_i, next_i, per_point,
                       float(curvature_tol), c, slip)
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0))), slip
