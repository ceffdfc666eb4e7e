"""Slow NumPy reference of ``geometry.repair.self_intersections``: the edge rays with whole-array
bookkeeping (trimesh's plane intersection, its embree wrapper), on the mesh centred first."""

from __future__ import annotations

import numpy as np

from preform.geometry.repair import RAY_ADVANCE, _edge_keys, _unique


def self_intersections(vertices, faces):
    """Edges that pierce a triangle they do not belong to: (k, 2) int64 vertex-index pairs.

    vertices : (n, 3) float64, m; faces : (m, 3) int64. Every pair of crossing, non-coplanar
    triangles has such an edge. Each edge, shortened by a hair at both ends, is cast along itself
    (embree when installed, which works in float32: the mesh is centred first) and every
    triangle it meets before its end is collected: the hit is recomputed in float64 on the
    triangle's plane and the ray restarted just past it (trimesh's multiple-hit scheme), with the
    ray's far limit set to what is left of the edge, so no ray travels on through the mandrel.
    Coplanar overlaps are not found.
    """
    import trimesh
    from trimesh.intersections import planes_lines

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    centred = vertices - (vertices.max(axis=0) + vertices.min(axis=0)) / 2
    mesh = trimesh.Trimesh(centred, faces, process=False)
    n = np.int64(len(vertices))
    key = _unique(_edge_keys(faces, n))
    e = np.stack([key // n, key % n], axis=1)
    a = centred[e[:, 0]]
    d = centred[e[:, 1]] - a
    length = np.linalg.norm(d, axis=1)
    ok = length > 0
    e, a, d, length = e[ok], a[ok], d[ok], length[ok]
    u = d / length[:, None]
    eps = 1e-6 * length
    intersector = mesh.ray
    scene = getattr(intersector, "_scene", None)
    if scene is None or not hasattr(scene, "scene"):        # no embree: trimesh's own rays
        loc, ray, tri = intersector.intersects_location(a + u * eps[:, None], u, multiple_hits=True)
        t = np.einsum("ij,ij->i", loc - a[ray], u[ray])
        inside = t < length[ray] - 2 * eps[ray]
        own = np.any(faces[tri] == e[ray, 0:1], axis=1) | np.any(faces[tri] == e[ray, 1:2], axis=1)
        return e[_unique(ray[inside & ~own])]
    base = max(1e-8, RAY_ADVANCE * float(np.linalg.norm(np.ptp(centred, axis=0))))
    plane_origins = centred[faces[:, 0]]
    plane_normals = mesh.face_normals
    origin = a + u * eps[:, None]
    offset = np.full(len(e), base)
    last = np.full(len(e), -1, dtype=np.int64)
    live = np.arange(len(e))
    bad = []
    for _ in range(100):
        if len(live) == 0:
            break
        left = length[live] - 2 * eps[live] - np.einsum("ij,ij->i", origin[live] - a[live], u[live])
        go = left > 0
        live, left = live[go], left[go]
        if len(live) == 0:
            break
        prim = scene.run(origin[live], u[live], dists=(left * scene.scale).astype(np.float32))
        hit = prim >= 0
        rays, tris = live[hit], prim[hit].astype(np.int64)
        dupe = last[rays] == tris
        last[rays] = tris
        fresh, ftri = rays[~dupe], tris[~dupe]
        at, valid = planes_lines(plane_origins=plane_origins[ftri], plane_normals=plane_normals[ftri],
                                 line_origins=origin[fresh], line_directions=u[fresh])
        fresh, ftri = fresh[valid], ftri[valid]
        t = np.einsum("ij,ij->i", at - a[fresh], u[fresh])
        own = np.any(faces[ftri] == e[fresh, 0:1], axis=1) | np.any(faces[ftri] == e[fresh, 1:2], axis=1)
        pierce = (t < length[fresh] - 2 * eps[fresh]) & ~own
        bad.append(fresh[pierce])
        origin[fresh] = at + u[fresh] * base
        offset[fresh] = base
        dup_rays = rays[dupe]
        offset[dup_rays] *= 2.0
        origin[dup_rays] += u[dup_rays] * offset[dup_rays, None]
        live = np.concatenate([fresh[~pierce], dup_rays])
    bad = _unique(np.concatenate(bad)) if bad else np.zeros(0, dtype=np.int64)
    return e[bad]
