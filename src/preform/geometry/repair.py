"""Mesh intake for real-world CAD STLs (issue 5): repair what can be repaired, refuse the rest.

``repair_mesh`` merges duplicate vertices, drops degenerate and duplicated faces, makes the winding
consistent and outward, and fills small holes; it refuses, naming the file and what to do, meshes
that cannot be a mandrel: large holes (an open surface), several disjoint bodies (unless
``body="largest"``), non-manifold edges. Every change is said in ``RepairReport.messages``, which
the run log and ``summary.json`` repeat.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import MandrelError
from ..tolerances import tol

#: holes whose boundary loop spans less than this fraction of the bounding-box diagonal are filled
SMALL_HOLE = 0.05


@dataclass(frozen=True)
class RepairReport:
    messages: tuple = field(default=())

    @property
    def changed(self) -> bool:
        return bool(self.messages)


def _diag(vertices):
    return float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0


def _merge(vertices, faces, rel_tol):
    q = np.round((vertices - vertices.min(axis=0)) / (rel_tol * _diag(vertices))).astype(np.int64)
    _, first, inverse = np.unique(q, axis=0, return_index=True, return_inverse=True)
    return vertices[first], inverse.reshape(-1)[faces]


def _drop_bad_faces(vertices, faces):
    p = vertices[faces]
    area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    degenerate = ~distinct | (area2 <= 1e-12 * _diag(vertices) ** 2)
    faces = faces[~degenerate]
    _, keep = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    keep = np.sort(keep)
    return faces[keep], int(degenerate.sum()), len(faces) - len(keep)


def _edges(faces):
    """Undirected edge ids per face side (nf, 3), and the (a, b) of each id."""
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    undirected = np.sort(directed, axis=1)
    uniq, inverse, counts = np.unique(undirected, axis=0, return_inverse=True, return_counts=True)
    return inverse.reshape(-1, 3), uniq, counts


def _orient(faces, edge_ids, counts):
    """Flip faces so that every manifold edge is used in opposite directions; returns (faces, flips)."""
    nf = len(faces)
    sides = edge_ids.reshape(-1)
    order = np.argsort(sides, kind="stable")
    sorted_sides = sides[order]
    starts = np.searchsorted(sorted_sides, np.arange(len(counts)))
    flipped = np.zeros(nf, dtype=bool)
    seen = np.zeros(nf, dtype=bool)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2)   # (nf, 3, 2)
    for root in range(nf):
        if seen[root]:
            continue
        seen[root] = True
        queue = deque([root])
        while queue:
            f = queue.popleft()
            for k in range(3):
                e = edge_ids[f, k]
                if counts[e] != 2:
                    continue
                a = order[starts[e]]
                b = order[starts[e] + 1]
                g_side = b if a // 3 == f else a
                g = g_side // 3
                if seen[g]:
                    continue
                seen[g] = True
                da = directed[f, k] if not flipped[f] else directed[f, k][::-1]
                db = directed[g, g_side % 3]
                if da[0] == db[0] and da[1] == db[1]:
                    flipped[g] = True
                queue.append(g)
    out = faces.copy()
    out[flipped] = out[flipped][:, ::-1]
    return out, int(flipped.sum())


def _components(nf, edge_ids, counts):
    sides = edge_ids.reshape(-1)
    order = np.argsort(sides, kind="stable")
    sorted_sides = sides[order]
    pair = (counts[sorted_sides] == 2)
    first = np.nonzero(pair & np.r_[True, sorted_sides[1:] != sorted_sides[:-1]])[0]
    a = order[first] // 3
    b = order[first + 1] // 3
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(nf, nf))
    return connected_components(graph, directed=False)


def _boundary_loops(faces, edge_ids, counts):
    """Loops of boundary edges, each a list of vertex ids directed as in their faces (None for an
    open chain). Vertices where two holes touch are walked through once per loop."""
    nxt: dict[int, list] = {}
    for f, k in zip(*np.nonzero(counts[edge_ids] == 1)):
        nxt.setdefault(int(faces[f, k]), []).append(int(faces[f, (k + 1) % 3]))
    loops = []
    while nxt:
        start = next(iter(nxt))
        loop = [start]
        cur = start
        while True:
            outs = nxt.get(cur)
            if not outs:
                loops.append(None)
                break
            q = outs.pop()
            if not outs:
                del nxt[cur]
            if q == start:
                loops.extend(_simple_loops(loop))
                break
            loop.append(q)
            cur = q
    return loops


def _simple_loops(loop):
    """Split a closed walk that passes a vertex twice (two holes touching) into simple loops."""
    out = []
    stack = []
    where = {}
    for v in loop:
        if v in where:
            i = where[v]
            out.append(stack[i:])
            for u in stack[i + 1:]:
                del where[u]
            stack = stack[:i + 1]
        else:
            where[v] = len(stack)
            stack.append(v)
    out.append(stack)
    return [c for c in out if len(c) >= 3]


def _signed_volume(vertices, faces):
    p = vertices[faces]
    return float(np.einsum("ij,ij->", p[:, 0], np.cross(p[:, 1], p[:, 2]))) / 6.0


def repair_mesh(vertices, faces, *, source="mandrel", body=None):
    """Repair a triangle soup into a closed, outward mandrel mesh (see module docstring).

    vertices (n, 3) float64 m, faces (m, 3) int. body: None (one body required) or "largest".
    Returns (vertices, faces, RepairReport); inputs are not modified.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    msgs = []
    n_v = len(V)
    V, F = _merge(V, F, tol.merge_vertices)
    if len(V) < n_v and n_v != 3 * len(F):
        # an STL is a triangle soup by format (3 vertices per triangle): merging it is no repair
        msgs.append(f"merged {n_v - len(V):,} duplicate vertices")
    F, n_degenerate, n_duplicate = _drop_bad_faces(V, F)
    if n_degenerate:
        msgs.append(f"dropped {n_degenerate} degenerate faces")
    if n_duplicate:
        msgs.append(f"dropped {n_duplicate} duplicated faces")
    if len(F) == 0:
        raise MandrelError(f"{source}: no usable triangles")
    edge_ids, edges, counts = _edges(F)
    if np.any(counts > 2):
        e = edges[np.argmax(counts)]
        raise MandrelError(
            f"{source}: {int(np.sum(counts > 2))} non-manifold edges (more than two triangles on one edge, "
            f"e.g. near ({', '.join(f'{x:.4g}' for x in V[e[0]])}) m): inside and outside are ambiguous. Export the mandrel "
            "as one closed solid")
    n_comp, labels = _components(len(F), edge_ids, counts)
    if n_comp > 1:
        sizes = np.bincount(labels)
        if body != "largest":
            listing = ", ".join(str(s) for s in sorted(sizes, reverse=True)[:5])
            raise MandrelError(
                f"{source}: {n_comp} disjoint bodies ({listing} triangles): a mandrel is one body. Remove the "
                'others in your CAD tool, or load with body="largest" to keep the largest')
        keep = labels == np.argmax(sizes)
        F = F[keep]
        used = np.unique(F)
        remap = np.full(len(V), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        V, F = V[used], remap[F]
        msgs.append(f"kept the largest of {n_comp} bodies ({int(keep.sum())} triangles)")
        edge_ids, edges, counts = _edges(F)
    F, n_flipped = _orient(F, edge_ids, counts)
    if n_flipped and n_flipped < len(F):
        msgs.append(f"flipped {n_flipped} faces to a consistent winding")
    if np.any(counts == 1):
        F, V, filled, msg = _fill_holes(V, F, edge_ids, counts, source)
        msgs.append(msg)
    if _signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
        msgs.append("turned the normals outwards (the triangles were wound inwards)")
    _refuse_self_intersections(V, F, source)
    return V, F, RepairReport(tuple(msgs))


def self_intersections(vertices, faces):
    """Edges that pierce a triangle they do not belong to: (k,) edge index pairs (a, b).

    Every pair of crossing (non-coplanar) triangles has such an edge. One batched ray query with
    trimesh (embree when installed): each edge, shortened by a hair at both ends, is cast against
    the mesh.
    """
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    e = np.unique(np.sort(mesh.edges, axis=1), axis=0)
    a, b = vertices[e[:, 0]], vertices[e[:, 1]]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    ok = length > 0
    e, a, d, length = e[ok], a[ok], d[ok], length[ok]
    u = d / length[:, None]
    eps = 1e-6 * length
    loc, ray, tri = mesh.ray.intersects_location(a + u * eps[:, None], u, multiple_hits=True)
    if len(ray) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    t = np.einsum("ij,ij->i", loc - a[ray], u[ray])
    inside = t < length[ray] - 2 * eps[ray]
    own = np.any(faces[tri] == e[ray, 0:1], axis=1) | np.any(faces[tri] == e[ray, 1:2], axis=1)
    bad = inside & ~own
    return e[np.unique(ray[bad])]


def _refuse_self_intersections(V, F, source):
    bad = self_intersections(V, F)
    if len(bad):
        p = V[bad[0, 0]]
        raise MandrelError(
            f"{source}: the surface intersects itself ({len(bad)} edges pierce other triangles, e.g. near "
            f"({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m), so inside and outside are ambiguous. Export the "
            "mandrel as one clean solid (a boolean union of its parts)")


def _fill_holes(V, F, edge_ids, counts, source):
    loops = _boundary_loops(F, edge_ids, counts)
    diag = _diag(V)
    spans = []
    for loop in loops:
        if loop is None or len(loop) < 3:
            spans.append(np.inf)
        else:
            p = V[loop]
            spans.append(float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))))
    spans = np.array(spans)
    if np.any(spans > SMALL_HOLE * diag):
        big = spans[np.isfinite(spans)]
        largest = f"{1e3 * big.max():.1f} mm across" if len(big) else "not a closed loop"
        raise MandrelError(
            f"{source} is an open surface: {len(loops)} boundary loop(s), the largest {largest} "
            f"(holes up to {SMALL_HOLE:.0%} of the mandrel's size, {1e3 * SMALL_HOLE * diag:.1f} mm, are filled). "
            "A mandrel must be closed: cap it in your CAD tool")
    new_V = [V]
    new_F = [F]
    n = len(V)
    for loop in loops:
        centre = V[loop].mean(axis=0)
        new_V.append(centre[None])
        ring = np.array(loop)
        # boundary edges run a -> b in their faces: the fill uses b -> a
        new_F.append(np.stack([np.roll(ring, -1), ring, np.full(len(ring), n)], axis=1))
        n += 1
    msg = f"filled {len(loops)} small hole(s) (largest {1e3 * spans.max():.1f} mm across)"
    return np.vstack(new_F), np.vstack(new_V), len(loops), msg
