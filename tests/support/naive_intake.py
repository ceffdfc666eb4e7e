"""Slow, obvious NumPy references of the mesh intake and check kernels (``_kernels.mesh``,
``_kernels.edges``, ``_kernels.sections``) that ``geometry.repair``, ``geometry.mandrel``,
``geometry.centerline`` and ``checks`` call. Each returns what its kernel writes, bit for bit (the
winding numbers to round-off: NumPy's arctan2 is not libm's); the tests compare the two on the
same meshes. Sorts and SciPy's connected components where the kernels use hash tables and
union-find passes.
"""

from __future__ import annotations

import numpy as np


def vertex_bounds(V, F):
    """Least and greatest coordinates (3,), (3,) of the rows of V (n, 3) that F (m, 3) uses, or of
    all rows when F has none (``_kernels.mesh.vertex_bounds``; +-inf for no rows)."""
    P = V if len(F) == 0 else V[F.reshape(-1)]
    return P.min(axis=0, initial=np.inf), P.max(axis=0, initial=-np.inf)


def weld_exact(V):
    """Distinct rows of V (n, 3) float64 in order of first appearance, 0.0 and -0.0 one value
    (``_kernels.mesh.weld_exact``): (first (k,) index in V of each distinct row's first
    appearance, ascending; inverse (n,) each row's distinct row). A stable lexicographic sort."""
    W = V + 0.0                                    # -0.0 -> 0.0
    order = np.lexsort((W[:, 2], W[:, 1], W[:, 0]))
    s = W[order]
    new = np.empty(len(V), dtype=bool)
    new[:1] = True
    np.any(s[1:] != s[:-1], axis=1, out=new[1:])
    group = np.cumsum(new) - 1                     # sorted rank of each sorted row
    first_sorted = order[new]                      # stable: each group's lowest index
    rank = np.empty(len(first_sorted), dtype=np.int64)
    by_appearance = np.argsort(first_sorted, kind="stable")
    rank[by_appearance] = np.arange(len(first_sorted))
    inverse = np.empty(len(V), dtype=np.int64)
    inverse[order] = rank[group]
    return first_sorted[by_appearance], inverse


def merge_clusters(inverse, pairs, n_exact):
    """Vertex clusters (``_kernels.edges.merge_clusters``): connected components of the near
    ``pairs`` (k, 2) on the ``n_exact`` exact-distinct vertices, ``inverse`` (n,) each input
    vertex's one. Returns (survivors (c,) the lowest input vertex of each cluster, ascending;
    new_index (n,) each input vertex's survivor's rank)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_exact, n_exact))
    _, cluster = connected_components(graph, directed=False)
    cluster = cluster[inverse]
    n_clusters = int(cluster.max()) + 1
    keeper = np.full(n_clusters, len(inverse), dtype=np.int64)
    np.minimum.at(keeper, cluster, np.arange(len(inverse)))
    rank = np.empty(n_clusters, dtype=np.int64)
    rank[np.argsort(keeper)] = np.arange(n_clusters)
    return np.sort(keeper), rank[cluster]


def degenerate_faces(V, F, radius):
    """(collapsed, caps, longest) (m,) of faces F on V (``_kernels.mesh.degenerate_faces``):
    a repeated vertex; not collapsed and twice the area at most ``radius`` times the longest
    side; the index of the longest side (the first of equal ones)."""
    collapsed = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    p = V[F]
    side = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
    length = np.linalg.norm(side, axis=2)
    area2 = np.linalg.norm(np.cross(side[:, 0], side[:, 1]), axis=1)
    caps = ~collapsed & (area2 <= radius * length.max(axis=1))
    return collapsed, caps, length.argmax(axis=1)


def first_of_each_face(F):
    """keep (m,) bool: the first face of F (m, 3) with its set of vertices, either winding
    (``_kernels.edges.first_of_each_face``; ``np.unique(np.sort(F, axis=1), axis=0,
    return_index=True)``)."""
    keep = np.zeros(len(F), dtype=bool)
    keep[np.unique(np.sort(F, axis=1), axis=0, return_index=True)[1]] = True
    return keep


def edge_keys(F, n_vertices):
    """Undirected edge key per face side: (m, 3) int64, side k runs F[:, k] -> F[:, k + 1]."""
    a, b = F, np.roll(F, -1, axis=1)
    return np.minimum(a, b) * np.int64(n_vertices) + np.maximum(a, b)


def edge_table(F, n_vertices):
    """Undirected edges of F (m, 3) (``_kernels.edges.edge_table``): (key (ne,) the edge keys
    ``min * n_vertices + max`` ascending, count (ne,) half-edges per edge, side_edge (3 m,) each
    half-edge's edge, order (3 m,) the half-edges grouped by edge, ascending within one)."""
    key = edge_keys(F, n_vertices).reshape(-1)
    uniq, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    return uniq, count, inverse, np.argsort(inverse, kind="stable")


def orient_bodies(F, pairs):
    """Consistent winding of each body (``_kernels.edges.orient_bodies``): connected components
    of the orientation double cover (node f: face f as given, f + m: reversed) across the
    two-face edges ``pairs`` (k, 2) of half-edge ids. Returns (flipped (m,) bool, component (m,)
    bodies in order of their lowest face, the first face whose two nodes are connected (a
    one-sided body) or -1)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = len(F)
    h1, h2 = pairs[:, 0], pairs[:, 1]
    same_direction = F.reshape(-1)[h1] == F.reshape(-1)[h2]
    f1, f2 = h1 // 3, h2 // 3
    g1 = np.where(same_direction, f2 + m, f2)
    g2 = np.where(same_direction, f2, f2 + m)
    rows = np.concatenate([f1, f1 + m])
    cols = np.concatenate([g1, g2])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * m, 2 * m))
    _, label = connected_components(graph, directed=False)
    given, reversed_ = label[:m], label[m:]
    bad = np.nonzero(given == reversed_)[0]
    body_label = np.minimum(given, reversed_)
    _, component = np.unique(body_label, return_inverse=True)
    return given != body_label, component.reshape(-1), int(bad[0]) if len(bad) else -1


def face_cross_normals(V, F):
    """``c = (p1 - p0) x (p2 - p0)`` (m, 3) and the unit normals ``c / |c|`` (c where |c| = 0)
    of faces F (``_kernels.mesh.face_cross_normals``)."""
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area2 = np.linalg.norm(cross, axis=1)
    return cross, cross / np.where(area2 > 0, area2, 1.0)[:, None]


# ------------------------------------------------------ self-intersection test by edge rays
def edge_ray_geometry(V, e):
    """The rays of ``repair.self_intersections`` (``_kernels.mesh.edge_ray_geometry``): for the
    edges (p, q) of e (k, 2) of nonzero length L, their start a = V[p], unit direction u, L, the
    hair eps = 1e-6 L and the origin a + eps u. Returns (keep (k,) bool, a, u, length, eps,
    origin) of the kept edges."""
    a = V[e[:, 0]]
    d = V[e[:, 1]] - a
    length = np.linalg.norm(d, axis=1)
    keep = length > 0
    a, d, length = a[keep], d[keep], length[keep]
    u = d / length[:, None]
    eps = 1e-6 * length
    return keep, a, u, length, eps, a + u * eps[:, None]


def _dot3(x, y):
    """Row dot products of (k, 3) arrays summed as the kernels do, ``(x0 y0 + x1 y1) + x2 y2``."""
    return (x[:, 0] * y[:, 0] + x[:, 1] * y[:, 1]) + x[:, 2] * y[:, 2]


def edge_ray_batch(live, origin, a, u, length, eps, scene_origin, scene_scale):
    """The embree rays of the edges ``live`` (``_kernels.mesh.edge_ray_batch``): the edges with
    some of their length left, ``length - 2 eps - (origin - a).u > 0``, and their origins,
    directions and far distances in the scene's frame as float32. Returns (rays, origin32,
    dirs32, far32)."""
    left = length[live] - 2.0 * eps[live] - _dot3(origin[live] - a[live], u[live])
    go = left > 0
    rays = live[go]
    origin32 = ((origin[rays] - scene_origin) * scene_scale).astype(np.float32)
    return rays, origin32, u[rays].astype(np.float32), (left[go] * scene_scale).astype(np.float32)


def edge_ray_hits(live, prim, V, F, FN, e, origin, a, u, length, eps, base, offset, last, bad):
    """One embree pass of the edge rays ``live`` with hit triangles ``prim`` (-1 for none), as
    ``_kernels.mesh.edge_ray_hits`` does it: updates origin, offset, last and bad in place and
    returns the rays still going, in the order of ``live``."""
    hit = prim >= 0
    r, p = live[hit], prim[hit]
    dup = last[r] == p
    rd = r[dup]
    offset[rd] *= 2.0
    origin[rd] += u[rd] * offset[rd, None]
    rn, pn = r[~dup], p[~dup]
    last[rn] = pn
    un, on, fn = u[rn], origin[rn], FN[pn]
    den = _dot3(un, fn)
    ok = np.abs(den) > 1e-5
    x = un * (_dot3(V[F[pn, 0]] - on, fn) / np.where(ok, den, 1.0))[:, None] + on
    t = _dot3(x - a[rn], un)
    own = np.any((F[pn] == e[rn, 0:1]) | (F[pn] == e[rn, 1:2]), axis=1)
    pierce = ok & (t < length[rn] - 2.0 * eps[rn]) & ~own
    bad[rn[pierce]] = True
    go = ok & ~pierce
    origin[rn[go]] = x[go] + un[go] * base
    offset[rn[go]] = base
    keep = dup.copy()
    keep[~dup] = go
    return r[keep]


def winding_numbers(V, F, P):
    """The generalised winding number of the closed surface (V, F) at each point of P (k, 3)
    (``_kernels.mesh.winding_numbers``): Van Oosterom and Strackee's solid angles over 4 pi, the
    kernel's terms summed in face order (``np.cumsum``, a running sum). Equal to the kernel's to
    round-off, not bit for bit: NumPy's arctan2 is not libm's (measured 4e-17 on case A)."""
    corners = np.ascontiguousarray(V[F].transpose(1, 2, 0))      # (corner, axis, face)
    out = np.empty(len(P))
    for k, p in enumerate(P):
        a, b, c = corners - p[:, None]
        la, lb, lc = (np.sqrt((x * x).sum(axis=0)) for x in (a, b, c))
        det = (a * np.cross(b, c, axis=0)).sum(axis=0)
        den = la * lb * lc + (a * b).sum(axis=0) * lc + (a * c).sum(axis=0) * lb + (b * c).sum(axis=0) * la
        total = np.cumsum(2.0 * np.arctan2(det, den))
        out[k] = (total[-1] if len(total) else 0.0) / (4.0 * np.pi)
    return out


def centroids_and_reach(V, F):
    """Face centroids (m, 3) and each face's largest centroid-to-corner distance (m,)
    (``_kernels.mesh.centroids_and_reach``)."""
    tri = V[F]
    centroids = tri.mean(axis=1)
    return centroids, np.sqrt(((tri - centroids[:, None]) ** 2).sum(axis=2).max(axis=1))


def chain_loops(ids, n_nodes):
    """Closed loops of the segment graph ``ids`` (n, 2) (``_kernels.sections.chain_loops``, the
    same walk with dictionaries): (loop_nodes, loop_offsets (n_loops + 1,), src (n_nodes,) the
    index 2 k + end of the segment end whose coordinates a node keeps, its last appearance)."""
    adjacency: dict[int, list[int]] = {}
    for a, b in ids.tolist():
        if a != b:
            adjacency.setdefault(a, []).append(b)
            adjacency.setdefault(b, []).append(a)
    real = np.repeat(ids[:, 0] != ids[:, 1], 2)
    src = np.full(n_nodes, -1, dtype=np.int64)
    np.maximum.at(src, ids.reshape(-1)[real], np.arange(2 * len(ids))[real])
    nodes, offsets = [], [0]
    seen = set()
    for start in adjacency:
        if start in seen:
            continue
        walk = [start]
        seen.add(start)
        prev, cur = -1, start
        closed = False
        while True:
            nxt = [q for q in adjacency[cur] if q != prev]
            if not nxt:
                break
            q = nxt[0]
            if q == start:
                closed = True
                break
            if q in seen:
                break
            seen.add(q)
            walk.append(q)
            prev, cur = cur, q
        if closed and len(walk) >= 3:
            nodes += walk
            offsets.append(len(nodes))
    return np.array(nodes, dtype=np.int64), np.array(offsets, dtype=np.int64), src


# ------------------------------------------------------------------- a mandrel's own arrays
def face_neighbors(F):
    """(m, 3) the face across edge k (corners k, k + 1) of each face of F, -1 if none or when the
    directed edge is used twice (``_kernels.edges.directed_neighbors`` on ``edge_table``): a
    stable sort of the directed edge keys searched for each twin key."""
    a = F.reshape(-1)
    b = np.roll(F, -1, axis=1).reshape(-1)
    nv = int(F.max()) + 1
    key = a * nv + b
    twin = b * nv + a
    order = np.argsort(key, kind="stable")
    sorted_keys = key[order]
    pos = np.minimum(np.searchsorted(sorted_keys, twin), len(sorted_keys) - 1)
    found = sorted_keys[pos] == twin
    dup = np.zeros(len(key), dtype=bool)
    same = sorted_keys[1:] == sorted_keys[:-1]
    dup[order[1:][same]] = True
    dup[order[:-1][same]] = True
    out = np.where(found, order[pos] // 3, -1)
    out[dup] = -1
    return out.reshape(-1, 3)


def corner_cosines(V, F):
    """(m, 3) cosine of the interior angle at every corner (``_kernels.mesh.corner_cosines``):
    ``u.w / max(|u| |w|, 1e-300)``, u and w the sides from corner k to corners k + 1, k + 2."""
    p = V[F]
    out = np.empty((len(F), 3))
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        w = p[:, (k + 2) % 3] - p[:, k]
        out[:, k] = np.einsum("ij,ij->i", u, w) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1),
                                                             1e-300)
    return out


def corners_by_vertex(F, n_vertices):
    """The corners around each vertex (``_kernels.mesh.corners_by_vertex``): (vert_ptr (n + 1,),
    vert_faces, vert_corner (3 m,)), CSR by vertex, faces ascending (a stable argsort)."""
    flat = F.reshape(-1)
    order = np.argsort(flat, kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n_vertices))])
    return ptr, order // 3, order % 3


def corner_normals(T, FN, angles, vert_ptr, vert_faces, vert_corner, cos_crease):
    """Crease-split, angle-weighted unit normals (m, 3, 3) at every corner
    (``_kernels.mesh.corner_normals``): corner (f, k) sums ``angle * FN[g]`` over the faces g
    around its vertex with ``FN[g].FN[f] >= cos_crease``, in the CSR order (``np.bincount``
    adds its weights in order, as the kernel's running sums do); FN[f] where the sum is zero."""
    corner_vertex = T.reshape(-1)
    degree = vert_ptr[corner_vertex + 1] - vert_ptr[corner_vertex]
    corner = np.repeat(np.arange(len(corner_vertex)), degree)
    first = np.cumsum(degree) - degree
    p = np.repeat(vert_ptr[corner_vertex], degree) + np.arange(len(corner)) - np.repeat(first, degree)
    g, f = vert_faces[p], corner // 3
    c = (FN[g, 0] * FN[f, 0] + FN[g, 1] * FN[f, 1]) + FN[g, 2] * FN[f, 2]
    keep = c >= cos_crease
    corner, g, p = corner[keep], g[keep], p[keep]
    w = angles[g, vert_corner[p]]
    s = [np.bincount(corner, weights=w * FN[g, i], minlength=len(corner_vertex)) for i in range(3)]
    norm = np.sqrt((s[0] * s[0] + s[1] * s[1]) + s[2] * s[2])
    summed = np.stack(s, axis=1) / np.where(norm > 0.0, norm, 1.0)[:, None]
    out = np.where((norm > 0.0)[:, None], summed, FN[np.arange(len(corner_vertex)) // 3])
    return out.reshape(-1, 3, 3)
