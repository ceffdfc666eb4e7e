"""Numba kernels on the edges of a triangle mesh, for the intake of big STLs: the
undirected edge table in the order of ``np.unique`` on the edge keys, the face across every
directed edge, duplicate faces, and the consistent winding of each body. Each one replaces a
NumPy sort of the ``3 m`` half-edges (or a graph-components call) with O(m) passes and gives
the NumPy form's arrays exactly (tests/unit/test_big_mesh_kernels.py)."""

from __future__ import annotations

import numpy as np
from numba import njit

from .mesh import empty_table, hash_slot

#: a vertex with more incident half-edges than this sorts them with a merge sort, not insertion
INSERTION_MAX = 32


@njit(cache=True)
def edge_table(F, n_vertices, side_edge, order):
    """Undirected edges of F (m, 3) int64, vertex ids below ``n_vertices``.

    Half-edge ``h = 3 f + k`` runs from ``F[f, k]`` to ``F[f, (k + 1) % 3]``; its edge key is
    ``min * n_vertices + max``. Edges are numbered in increasing key (the order of
    ``np.unique(keys)``): writes each half-edge's edge id into side_edge (3 m,) and the
    half-edges grouped by edge, increasing within an edge (``np.argsort(side_edge,
    kind="stable")``), into order (3 m,). Returns (key (ne,) int64, count (ne,) int64: half-edges
    per edge). A counting sort of the half-edges by their lower vertex, then a stable sort of each
    vertex's few half-edges by the upper one.
    """
    m = F.shape[0]
    nh = 3 * m
    ptr = np.zeros(n_vertices + 1, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            ptr[min(a, b) + 1] += 1
    for v in range(n_vertices):
        ptr[v + 1] += ptr[v]
    fill = ptr[:-1].copy()
    upper = np.empty(nh, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            lo = min(a, b)
            p = fill[lo]
            order[p] = 3 * f + k
            upper[p] = max(a, b)
            fill[lo] = p + 1
    widest = 0
    for v in range(n_vertices):
        widest = max(widest, ptr[v + 1] - ptr[v])
    scratch_h = np.empty(widest if widest > INSERTION_MAX else 0, dtype=np.int64)
    scratch_u = np.empty_like(scratch_h)
    for v in range(n_vertices):
        s = ptr[v]
        e = ptr[v + 1]
        if e - s > INSERTION_MAX:
            # bottom-up merge sort of order[s:e] by upper[s:e], stable (the left run wins ties);
            # written out here rather than np.argsort(kind="mergesort") and fancy indexing,
            # which compile numba's generic sort and shape-error formatting (about 3 s)
            n = e - s
            width = 1
            while width < n:
                for lo in range(0, n, 2 * width):
                    mid = min(lo + width, n)
                    hi = min(lo + 2 * width, n)
                    i = lo
                    j = mid
                    for t in range(lo, hi):
                        if j >= hi or (i < mid and upper[s + i] <= upper[s + j]):
                            scratch_h[t] = order[s + i]
                            scratch_u[t] = upper[s + i]
                            i += 1
                        else:
                            scratch_h[t] = order[s + j]
                            scratch_u[t] = upper[s + j]
                            j += 1
                for t in range(n):
                    order[s + t] = scratch_h[t]
                    upper[s + t] = scratch_u[t]
                width *= 2
        else:
            for i in range(s + 1, e):
                h = order[i]
                u = upper[i]
                j = i
                while j > s and upper[j - 1] > u:
                    order[j] = order[j - 1]
                    upper[j] = upper[j - 1]
                    j -= 1
                order[j] = h
                upper[j] = u
    key = np.empty(nh, dtype=np.int64)
    count = np.empty(nh, dtype=np.int64)
    ne = 0
    for v in range(n_vertices):
        for p in range(ptr[v], ptr[v + 1]):
            if p == ptr[v] or upper[p] != upper[p - 1]:
                key[ne] = v * n_vertices + upper[p]
                count[ne] = 0
                ne += 1
            side_edge[order[p]] = ne - 1
            count[ne - 1] += 1
    return key[:ne].copy(), count[:ne].copy()


@njit(cache=True)
def directed_neighbors(F, order, count, out):
    """The face across every directed edge (``geometry.mandrel.face_neighbors``): out (3 m,)
    int64, for half-edge h from a to b the face of the lowest half-edge from b to a, or -1 when
    there is none or when another half-edge also runs from a to b. order, count: the half-edges
    grouped by undirected edge and the group sizes (``edge_table``)."""
    p = 0
    for e in range(count.shape[0]):
        c = count[e]
        for i in range(p, p + c):
            h = order[i]
            f = h // 3
            k = h % 3
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            twin = -1
            dup = False
            for j in range(p, p + c):
                g = order[j]
                ga = F[g // 3, g % 3]
                gb = F[g // 3, (g % 3 + 1) % 3]
                if twin < 0 and ga == b and gb == a:
                    twin = g
                if g != h and ga == a and gb == b:
                    dup = True
            out[h] = -1 if (dup or twin < 0) else twin // 3
        p += c


@njit(cache=True)
def first_of_each_face(F, keep):
    """keep (m,) bool: face f is the first (lowest index) of the faces of F (m, 3) with its set of
    three vertices (either winding): the faces ``np.unique(np.sort(F, axis=1), axis=0,
    return_index=True)`` keeps. An open-addressing hash table on the sorted triple."""
    m = F.shape[0]
    table = empty_table(m)
    size = table.shape[0]
    sorted_f = np.empty((m, 3), dtype=np.int64)
    for f in range(m):
        a = F[f, 0]
        b = F[f, 1]
        c = F[f, 2]
        if a > b:
            a, b = b, a
        if b > c:
            b, c = c, b
        if a > b:
            a, b = b, a
        sorted_f[f, 0] = a
        sorted_f[f, 1] = b
        sorted_f[f, 2] = c
        slot = hash_slot(a, b, c, size)
        while True:
            g = table[slot]
            if g < 0:
                table[slot] = f
                keep[f] = True
                break
            if sorted_f[g, 0] == a and sorted_f[g, 1] == b and sorted_f[g, 2] == c:
                keep[f] = False
                break
            slot = (slot + 1) & (size - 1)


@njit(cache=True, inline="always")
def _find(parent, parity, x):
    """Root of x and x's parity relative to it; the path is pointed at the root."""
    r = x
    p = 0
    while parent[r] != r:
        p ^= parity[r]
        r = parent[r]
    y = x
    py = p
    while parent[y] != y:
        nxt = parent[y]
        pn = py ^ parity[y]
        parent[y] = r
        parity[y] = py
        y = nxt
        py = pn
    return r, p


@njit(cache=True)
def orient_bodies(F, pairs, flipped, component):
    """Consistent winding of each body of faces F (m, 3) across its two-face edges ``pairs``
    (k, 2) of half-edge ids (``geometry.repair._orientation``).

    Faces g and h of a pair agree when the edge runs opposite ways in them, so one must be
    flipped relative to the other when it runs the same way: a union-find over the faces with
    the parity of each face relative to its root. Writes flipped (m,) bool (the face differs in
    parity from the lowest face of its body, which is kept as given) and component (m,) int64
    (bodies numbered in order of their lowest face). Returns the lowest face of a body where the
    parities conflict (a non-orientable surface), or -1. These are the arrays of the graph form:
    components of the orientation double cover, numbered in order of their lowest node.
    """
    m = F.shape[0]
    parent = np.arange(m)
    parity = np.zeros(m, dtype=np.int64)
    rank = np.zeros(m, dtype=np.int64)
    bad = np.zeros(m, dtype=np.bool_)
    for i in range(pairs.shape[0]):
        h1 = pairs[i, 0]
        h2 = pairs[i, 1]
        d = 1 if F[h1 // 3, h1 % 3] == F[h2 // 3, h2 % 3] else 0     # same direction: flip one
        ra, pa = _find(parent, parity, h1 // 3)
        rb, pb = _find(parent, parity, h2 // 3)
        if ra == rb:
            if (pa ^ pb) != d:
                bad[ra] = True
            continue
        if rank[ra] < rank[rb]:
            ra, rb = rb, ra
        parent[rb] = ra
        parity[rb] = pa ^ pb ^ d
        bad[ra] = bad[ra] or bad[rb]
        if rank[ra] == rank[rb]:
            rank[ra] += 1
    label = np.full(m, -1, dtype=np.int64)       # per root: body number
    lowest_parity = np.zeros(m, dtype=np.int64)  # per root: parity of the body's lowest face
    n_bodies = 0
    first_bad = -1
    for f in range(m):
        r, p = _find(parent, parity, f)
        if label[r] < 0:
            label[r] = n_bodies
            lowest_parity[r] = p
            n_bodies += 1
            if bad[r] and first_bad < 0:
                first_bad = f
        component[f] = label[r]
        flipped[f] = p != lowest_parity[r]
    return first_bad


@njit(cache=True)
def merge_clusters(inverse, pairs, n_exact, survivors, new_index):
    """Vertex clusters of ``geometry.repair._merge_vertices``: the exact-distinct vertices
    (``inverse`` (n,): each input vertex's one) joined by the near pairs (k, 2) (a union-find,
    the partition of the pairs graph's connected components). The lowest input vertex of each
    cluster survives: their indices, ascending, into the first rows of survivors (n,), and each
    input vertex's survivor's rank into new_index (n,). Returns the number of clusters."""
    parent = np.arange(n_exact)
    for i in range(pairs.shape[0]):
        a = pairs[i, 0]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        b = pairs[i, 1]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            if a < b:
                parent[b] = a
            else:
                parent[a] = b
    rank = np.full(n_exact, -1, dtype=np.int64)       # per root: its cluster's survivor's rank
    n = 0
    for i in range(inverse.shape[0]):
        r = inverse[i]
        while parent[r] != r:
            r = parent[r]
        if rank[r] < 0:
            rank[r] = n
            survivors[n] = i
            n += 1
        new_index[i] = rank[r]
    return n
