"""Python reference of the section chaining kernel (``_kernels.sections.chain_loops``): the
former ``geometry.centerline.chain_segments``, dictionaries and lists."""

from __future__ import annotations

import numpy as np


def chain_segments(segments, rel_tol=1e-9):
    """Join segments (n, 2, 3) that share end points into closed loops; open chains are dropped."""
    if len(segments) == 0:
        return []
    scale = float(np.ptp(segments.reshape(-1, 3), axis=0).max()) or 1.0
    keys = np.round(segments.reshape(-1, 3) / (rel_tol * 1e3 * scale)).astype(np.int64)
    _, ids = np.unique(keys, axis=0, return_inverse=True)
    ids = ids.reshape(-1, 2)
    points = {}
    adjacency: dict[int, list] = {}
    for k, (a, b) in enumerate(ids):
        if a == b:
            continue
        points[a] = segments[k, 0]
        points[b] = segments[k, 1]
        adjacency.setdefault(a, []).append(b)
        adjacency.setdefault(b, []).append(a)
    loops = []
    seen = set()
    for start in adjacency:
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        prev, cur = None, start
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
            loop.append(q)
            prev, cur = cur, q
        if closed and len(loop) >= 3:
            pts = np.array([points[q] for q in loop + [start]])
            loops.append(pts)
    return loops
