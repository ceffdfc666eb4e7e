"""Plane sections of a triangle mesh from its arrays: the cut segments (``plane_segments``) and
the mesh's faces indexed for the cuts (``SectionIndex``; the index itself is built by
``centerline._slab_index`` and ``_axis_order``). No trimesh: the everyday run cuts sections
(reference perimeters, the auto centerline) without loading it."""

from __future__ import annotations

import numpy as np


class SectionIndex:
    """A triangle mesh's faces indexed for plane sections (``_section_loops``): vertices (nv, 3),
    faces (nf, 3) and ``metadata``, where ``_slab_index`` and ``_axis_order`` keep the centroids,
    reaches and per-axis orders they build on first use."""

    def __init__(self, vertices, faces):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.metadata = {}


#: ``plane_segments``: a corner within this distance (m) of the plane lies on it (trimesh's
#: ``tol.merge``, so that sections agree with trimesh's ``mesh_plane`` segment for segment)
ON_PLANE = 1e-8
#: ``plane_segments``: a direction shorter than this is no direction (trimesh's ``tol.zero``)
ZERO = 1e-13


def _unit_rows(v):
    """Rows of ``v`` (n, 3) scaled to unit length; rows not longer than ``ZERO`` left as they are."""
    norm = np.sqrt(np.dot(v * v, [1.0, 1.0, 1.0]))
    valid = norm > ZERO
    norm[valid] **= -1
    return v * norm.reshape((-1, 1))


def _plane_lines(origin, unit_normal, start, end):
    """Intersections (m, 3) of the lines through ``start`` -> ``end`` (n, 3) with the plane, and
    which lines meet it (n,) bool (not parallel to it): ``p = a + t d``, d the unit direction,
    ``t = n . (o - a) / n . d``."""
    direction = _unit_rows(end - start)
    t = np.dot(unit_normal, (origin - start).T)
    b = np.dot(unit_normal, direction.T)
    valid = np.abs(b) > ZERO
    d = np.divide(t[valid], b[valid])
    return start[valid] + np.reshape(d, (-1, 1)) * direction[valid], valid


def plane_segments(corners, dots, normal, origin):
    """The segments (m, 2, 3) where a plane cuts triangles, or None where the cut is ill-posed.

    corners (3 nf, 3): triangle f's corners at rows 3f, 3f + 1, 3f + 2; dots (3 nf,): their signed
    distances from the plane; normal (3,), origin (3,): the plane. A corner within ``ON_PLANE`` of
    the plane lies on it (sign 0). With the corners' signs sorted, a triangle is cut

    - with one corner on one side and two on the other (signs -1 -1 1 or -1 1 1): the segment
      joins the lines from the lone corner to the other two where they meet the plane;
    - through a corner on the plane, the other two on either side (-1 0 1): from that corner to
      where the opposite side meets the plane;
    - along a side on the plane with the third corner above it (0 0 1): that side. A side with
      the third corner below is left to the triangle above, so that a side is taken once and a
      facet lying in the plane gives no segments.

    Segments come in that order (all of the first case, then the second, then the third), the
    way trimesh's ``mesh_plane`` orders them, and equal to its segments bit for bit (the same
    arithmetic, ``tests/unit/test_plane_segments.py``), without importing trimesh on the everyday run.
    """
    signs = np.zeros(len(dots), dtype=np.int8)
    signs[dots < -ON_PLANE] = -1
    signs[dots > ON_PLANE] = 1
    signs = signs.reshape(-1, 3)
    faces = np.arange(len(dots), dtype=np.int64).reshape(-1, 3)
    ordered = np.sort(signs, axis=1)
    coded = np.zeros(len(ordered), dtype=np.int8) + 14
    for i in range(3):
        coded += ordered[:, i] << 3 - i
    basic = (coded == 4) | (coded == 12)
    one_vertex = coded == 8
    one_edge = coded == 16
    unit_normal = normal / np.sqrt(np.dot(normal, normal))

    s, f = signs[basic], faces[basic]
    lone = np.zeros_like(s, dtype=bool)
    for value in (-1, 1):
        test = s == value
        once = test.sum(axis=1) == 1
        lone[once] = test[once]
    edges = np.column_stack((f[lone], f[np.roll(lone, 1, axis=1)],
                             f[lone], f[np.roll(lone, 2, axis=1)])).reshape((-1, 2))
    cut, valid = _plane_lines(origin, unit_normal, corners[edges[:, 0]], corners[edges[:, 1]])
    if not valid.all():
        return None                  # a side with corners on either side parallel to the plane
    parts = [cut.reshape((-1, 2, 3))]

    s, f = signs[one_vertex], faces[one_vertex]
    on, through = f[s == 0], f[s != 0].reshape((-1, 2))
    cut, valid = _plane_lines(origin, unit_normal, corners[through[:, 0]], corners[through[:, 1]])
    parts.append(np.column_stack((corners[on[valid]], cut)).reshape((-1, 2, 3)))

    s, f = signs[one_edge], faces[one_edge]
    parts.append(corners[f[s == 0].reshape((-1, 2))])
    return np.vstack(parts)
