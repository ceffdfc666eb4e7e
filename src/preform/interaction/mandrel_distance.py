"""Signed distances of crossings to the mandrel, and which crossings need them: the interaction
model's look-ups of the mandrel's faces (``InteractionZone``'s wall and deposit test)."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree



#: a tangent plane no crossing reaches (as ``frontal.Boundary`` without a mandrel): no wall
NO_PLANE = np.array([0.0, 0.0, -1e300, 0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class NearSettings:
    """Which crossings the mandrel's faces are looked up for (``MandrelDistance.near``): only
    those a cheap bound does not prove far from the surface."""

    #: m, every surface point lies within this of a face sample, so the bound ``D >= r - spacing``
    #: (r: distance to the nearest sample) is this tight (case A: 0.82 M samples, 0.5 s to build)
    spacing: float = 5e-3
    #: the most samples: a large mandrel is sampled coarser (about 50 bytes per sample)
    max_samples: int = 2_000_000
    #: m, a crossing that may lie within this of the surface at a step's start gets its tangent
    #: plane; one further off moving this far in the step makes the step solved again with all
    wall_clearance: float = 5e-3
    #: m, how far beyond the clearance the face samples are looked up (``near``): a crossing
    #: further off is looked up again only once it has moved about this far
    reach: float = 2e-2
    #: m, a point counts as near unless proven this much further off than the clearance: the
    #: bound is of the unsigned distance, and a crossing the wall holds lies behind its tangent
    #: plane by the wall's give (Newton's penalty: f / k_wall, about 1 um), inside the surface
    margin: float = 1e-4


NEAR = NearSettings()


class MandrelDistance:
    """Signed distance (m, positive outside) of points to a mandrel, mandrel frame: to the plane
    of the face with the nearest centroid where the point's projection falls inside it, else to
    the closest point over the faces round the nearest vertex and that face's corners, signed
    by its face's outward normal (``_closest``); the tangent planes of the wall are those faces'
    planes. (The face with the nearest centroid is not the closest face where faces are long
    and thin, as CAD exports make them: on a sliver triangulation its plane can lie millimetres
    off the surface under a crossing, which moved the deposit and the wall, docs/decisions.md.)

    ``near`` bounds the true distance to the surface from below by a second KD-tree of face
    samples, so that the faces are looked up only where a crossing may be close (``settings``:
    :class:`NearSettings`)."""

    def __init__(self, mandrel, settings: NearSettings = NEAR):
        faces = np.asarray(mandrel.faces)
        v = np.asarray(mandrel.vertices, dtype=float)
        self.settings = settings
        self._triangles = v[faces]
        self.centroids = self._triangles.mean(axis=1)
        self.normals = np.asarray(mandrel.face_normals, dtype=float)
        self.tree = cKDTree(self.centroids)
        self._V = np.ascontiguousarray(v)
        self._F = np.ascontiguousarray(faces, dtype=np.int64)
        used = np.unique(self._F)
        self.vertex_tree = cKDTree(self._V[used])
        self._vertex_id = used
        # the faces round every vertex (CSR: ``_ring_faces[_ring_ptr[v]:_ring_ptr[v + 1]]``)
        order = np.argsort(self._F.ravel(), kind="stable")
        self._ring_faces = (order // 3).astype(np.int64)
        self._ring_ptr = np.searchsorted(self._F.ravel()[order], np.arange(len(v) + 1)).astype(np.int64)
        self._box = v[np.unique(faces)].min(axis=0), v[np.unique(faces)].max(axis=0)
        self._samples = None

    def __call__(self, points):
        points = np.atleast_2d(points)
        c, f, inside = self._closest(points)
        d = points - c
        side = np.einsum("ij,ij->i", d, self.normals[f])
        # over the face: the distance to its plane; else to the closest point, signed by its face
        return np.where(inside, side, np.where(side < 0.0, -1.0, 1.0) * np.linalg.norm(d, axis=1))

    def _sample_tree(self):
        """(KD-tree of face samples, spacing m): each face on a barycentric grid whose cells'
        edges are at most ``spacing`` long, so every point of a face lies within ``spacing`` of
        a sample (a point of a triangle lies within its longest edge of a corner); built on
        first use."""
        if self._samples is None:
            tri = self._triangles
            longest = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2).max(axis=1)
            spacing = float(self.settings.spacing)
            while True:
                k = np.maximum(np.ceil(longest / spacing), 1).astype(np.int64)
                if int(np.sum((k + 1) * (k + 2) // 2)) <= self.settings.max_samples:
                    break
                spacing *= 1.5
            parts = []
            for kk in np.unique(k):
                i, j = np.meshgrid(np.arange(kk + 1), np.arange(kk + 1), indexing="ij")
                keep = i + j <= kk
                w = np.stack([1.0 - (i[keep] + j[keep]) / kk, i[keep] / kk, j[keep] / kk], axis=1)
                parts.append(np.einsum("sj,fjk->fsk", w, tri[k == kk]).reshape(-1, 3))
            self._samples = cKDTree(np.vstack(parts)), spacing
        return self._samples

    def _closest(self, points):
        """(plane points (k, 3), faces (k,), inside (k,) bool) of points (k, 3), mandrel frame:
        the face under each point and a point of its plane. Where the point's projection on the
        plane of the face with the nearest centroid falls inside that face (``inside``; nearly
        every point near a well-shaped mesh), that face, with its centroid as the plane's point
        (the distance is that to the plane); elsewhere (a point over an edge, or beside a long
        thin face whose centroid lies far off) the closest point over the faces round the
        nearest vertex and round the corners of that face, and its face."""
        from .._kernels.mesh import closest_on_candidates

        points = np.ascontiguousarray(np.atleast_2d(points), dtype=float)
        m = len(points)
        _, f = self.tree.query(points)
        f = np.asarray(f, dtype=np.int64).reshape(m)
        out = self.centroids[f]
        n = self.normals[f]
        q = points - np.einsum("ij,ij->i", points - out, n)[:, None] * n
        tri = self._triangles[f]
        e1, e2, w = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], q - tri[:, 0]
        d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
        w1, w2 = np.einsum("ij,ij->i", w, e1), np.einsum("ij,ij->i", w, e2)
        den = d11 * d22 - d12 * d12
        with np.errstate(divide="ignore", invalid="ignore"):
            b1 = (d22 * w1 - d12 * w2) / den
            b2 = (d11 * w2 - d12 * w1) / den
        tol = -1e-9
        inside = (den > 0.0) & (b1 >= tol) & (b2 >= tol) & (1.0 - b1 - b2 >= tol)
        rest = np.nonzero(~inside)[0]
        if len(rest):
            # candidates: the faces round the nearest vertex and round the corners of the
            # nearest centroid's face (a long thin face under the point has a corner nearer
            # than its centroid)
            _, v = self.vertex_tree.query(points[rest])
            v = self._vertex_id[np.asarray(v, dtype=np.int64).reshape(-1)]
            ring = self._ring_ptr, self._ring_faces
            corners = np.concatenate([v.reshape(-1, 1), self._F[f[rest]]], axis=1)
            counts = ring[0][corners + 1] - ring[0][corners]
            ptr = np.concatenate([[0], np.cumsum(counts.sum(axis=1))]).astype(np.int64)
            starts = np.repeat(ring[0][corners].ravel(), counts.ravel())
            offs = np.arange(int(counts.sum())) - np.repeat(
                np.cumsum(counts.ravel()) - counts.ravel(), counts.ravel())
            cand = np.ascontiguousarray(ring[1][starts + offs])
            r = len(rest)
            c_out, c_face, d2 = np.empty((r, 3)), np.empty(r, dtype=np.int64), np.empty(r)
            closest_on_candidates(np.ascontiguousarray(points[rest]), self._V, self._F, ptr, cand,
                                  c_out, c_face, d2)
            out = out.copy()
            out[rest], f[rest] = c_out, c_face
        return out, f, inside

    def near(self, points, clearance, cache=None):
        """(near (k,) bool, lower (k,) m) for points (k, 3), mandrel frame: ``lower`` bounds the
        distance of each point to the surface from below, and ``near`` is where it is below
        ``clearance`` (plus a margin, below): only those points may lie within ``clearance`` of
        the surface.

        Two bounds: the distance to the mandrel's bounding box, and ``r - spacing`` with r the
        distance to the nearest face sample (the closest surface point lies within ``spacing``
        of one), r looked up within ``clearance + NearSettings.reach`` (beyond: at least that).
        ``cache``, ``(near_lo, near_hi, near_at)`` (``ZoneState``), holds bounds of r at other
        points; r is 1-Lipschitz, so a point is looked up only where those bounds, widened by
        the distance moved, leave it open whether ``r - spacing`` is below the limit, and
        ``near`` is what a look-up of every point would give. The bound is of the unsigned
        distance: a point counts as near unless it is proven ``NearSettings.margin`` further
        off than ``clearance`` (a point inside the surface by less than that, as the wall holds
        crossings, stays near)."""
        points = np.atleast_2d(points)
        tree, spacing = self._sample_tree()
        limit = max(clearance, 0.0) + self.settings.margin
        box = self._box_distance(points)
        if cache is None:
            lo, hi = np.full(len(points), -np.inf), np.full(len(points), np.inf)
        else:
            lo_c, hi_c, at = cache
            moved = np.linalg.norm(points - at, axis=1)
            lo, hi = lo_c - moved, hi_c + moved
        # r - spacing below the limit for sure (hi), above it for sure (lo), else look it up
        idx = np.nonzero((box < limit) & (lo - spacing < limit) & ~(hi - spacing < limit))[0]
        if len(idx):
            beyond = limit + self.settings.reach + spacing
            # a query radius a little wider than beyond: rounding drops no point
            r, _ = tree.query(points[idx], distance_upper_bound=beyond * (1.0 + 1e-9))
            found = np.isfinite(r)
            lo[idx] = np.where(found, r, beyond)
            hi[idx] = np.where(found, r, np.inf)
            if cache is not None:
                lo_c[idx], hi_c[idx], at[idx] = lo[idx], hi[idx], points[idx]
        lower = np.maximum(box, lo - spacing)
        near = (box < limit) & (lo - spacing < limit)
        return near, lower

    def _box_distance(self, points):
        """(k,) m: distance of points (k, 3), mandrel frame, to the mandrel's bounding box, a
        lower bound of their distance to its surface (0 inside the box)."""
        lo, hi = self._box
        return np.linalg.norm(np.maximum(np.maximum(lo - points, points - hi), 0.0), axis=1)

    def clear_of(self, points, distance) -> np.ndarray:
        """(k,) bool: whether each point (k, 3), mandrel frame, lies further than ``distance``
        (k,) m from the surface, proven by the mandrel's bounding box or else by the face
        samples (``near``)."""
        points = np.atleast_2d(points)
        distance = np.asarray(distance, dtype=float)
        out = self._box_distance(points) > distance
        rest = np.nonzero(~out)[0]
        if len(rest):
            tree, spacing = self._sample_tree()
            reach = (float(distance[rest].max()) + spacing) * (1.0 + 1e-9) + 1e-12
            r, _ = tree.query(points[rest], distance_upper_bound=reach)
            out[rest] = r - spacing > distance[rest]
        return out

    def planes(self, points, pose):
        """(n, 6): point and outward unit normal of the closest face's plane, machine frame, for
        points given in the machine frame (pose: the mandrel's)."""
        c, f, _ = self._closest(np.atleast_2d(pose.to_mandrel(points)))
        return self._planes_of(c, f, pose)

    def _planes_of(self, c, f, pose):
        """(n, 6): the planes through the points c (n, 3) of the planes of faces f (n,),
        mandrel frame, with those faces' outward normals, in the machine frame."""
        p0 = np.asarray(pose.to_machine(c), dtype=float)
        n = np.asarray(pose.to_machine(c + self.normals[f]), dtype=float) - p0
        n /= np.linalg.norm(n, axis=1)[:, None]
        return np.hstack([p0, n])

    def near_planes(self, points, pose, clearance, cache=None):
        """(planes (n, 6), lower (n,) m): ``planes`` for the points that may lie within
        ``clearance`` of the surface (``near``), and for the others a plane far behind
        (``NO_PLANE``: no wall); ``lower`` the lower bound of each point's distance to the
        surface (``near``; ``inf`` where the point has its plane)."""
        points = np.atleast_2d(points)
        near, lower = self.near(pose.to_mandrel(points), clearance, cache)
        out = np.tile(NO_PLANE, (len(points), 1))
        idx = np.nonzero(near)[0]
        if len(idx):
            c, f, _ = self._closest(pose.to_mandrel(points[idx]))
            out[idx] = self._planes_of(c, f, pose)
        return out, np.where(near, np.inf, lower)

    def below(self, points, height, cache=None):
        """(k,) bool for points (k, 3), mandrel frame: signed distance (``__call__``) below
        ``height``, looked up only for the points ``near`` does not prove further than
        ``height`` from the surface (those are not below it)."""
        points = np.atleast_2d(points)
        near, _ = self.near(points, height, cache)
        out = np.zeros(len(points), dtype=bool)
        idx = np.nonzero(near)[0]
        if len(idx):
            out[idx] = self(points[idx]) < height
        return out
