"""Numba kernel of the section tracer (``geometry.centerline.chain_segments``): plain arrays only.

A plane cuts a mesh into segments whose end points, once welded, are graph nodes; the closed loops
are walked from node to node. The walk is the one of the Python reference in
``tests/support/naive_intake.py`` (``chain_loops``), step for step (node order, neighbour order, which
coordinates a node keeps), so the loops are the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def chain_loops(ids, n_nodes):
    """Closed loops of the segment graph ``ids`` (n, 2) int64 (node ids 0 .. n_nodes - 1).

    Segments with both ends on one node are skipped. Nodes are visited in the order they first
    appear (segment by segment, first end first); each node's neighbours in segment order. A walk
    from an unseen node goes to the first neighbour that is not the node it came from, and ends
    closed when it returns to its start, open at a dead end or a node already seen. Returns
    (loop_nodes (m,), loop_offsets (n_loops + 1,), src (n_nodes,) the index 2 k + end of the
    segment end whose coordinates a node keeps: its last appearance).
    """
    n = ids.shape[0]
    degree = np.zeros(n_nodes, dtype=np.int64)
    src = np.full(n_nodes, -1, dtype=np.int64)
    order = np.empty(n_nodes, dtype=np.int64)
    first = np.zeros(n_nodes, dtype=np.bool_)
    n_order = 0
    for k in range(n):
        a = ids[k, 0]
        b = ids[k, 1]
        if a == b:
            continue
        degree[a] += 1
        degree[b] += 1
        src[a] = 2 * k
        src[b] = 2 * k + 1
        if not first[a]:
            first[a] = True
            order[n_order] = a
            n_order += 1
        if not first[b]:
            first[b] = True
            order[n_order] = b
            n_order += 1
    start_at = np.zeros(n_nodes + 1, dtype=np.int64)
    for v in range(n_nodes):
        start_at[v + 1] = start_at[v] + degree[v]
    fill = start_at[:-1].copy()
    nbr = np.empty(start_at[n_nodes], dtype=np.int64)
    for k in range(n):
        a = ids[k, 0]
        b = ids[k, 1]
        if a == b:
            continue
        nbr[fill[a]] = b
        fill[a] += 1
        nbr[fill[b]] = a
        fill[b] += 1
    seen = np.zeros(n_nodes, dtype=np.bool_)
    loop_nodes = np.empty(n_nodes, dtype=np.int64)
    loop_offsets = np.zeros(n_nodes + 1, dtype=np.int64)
    walk = np.empty(n_nodes, dtype=np.int64)
    n_nodes_out = 0
    n_loops = 0
    for j in range(n_order):
        start = order[j]
        if seen[start]:
            continue
        length = 1
        walk[0] = start
        seen[start] = True
        prev = -1
        cur = start
        closed = False
        while True:
            q = -1
            for e in range(start_at[cur], start_at[cur + 1]):
                if nbr[e] != prev:
                    q = nbr[e]
                    break
            if q < 0:
                break
            if q == start:
                closed = True
                break
            if seen[q]:
                break
            seen[q] = True
            walk[length] = q
            length += 1
            prev = cur
            cur = q
        if closed and length >= 3:
            for i in range(length):
                loop_nodes[n_nodes_out + i] = walk[i]
            n_nodes_out += length
            n_loops += 1
            loop_offsets[n_loops] = n_nodes_out
    return loop_nodes[:n_nodes_out], loop_offsets[:n_loops + 1], src
