"""Slow, obvious geometry references shared by the tests."""

from __future__ import annotations

import numpy as np


def point_triangle_distance(p, tri):
    """(n, nf) distance from points p (n, 3) to triangles tri (nf, 3, 3): nearest of the plane
    projection (if inside) and the three edges."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = p[:, None, :] - a[None]
    h = np.einsum("pfi,fi->pf", d, n)
    q = p[:, None, :] - h[..., None] * n[None]
    inside = np.ones(h.shape, bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("pfi,fi->pf", np.cross(v - u, q - u[None]), n) >= 0
    best = np.where(inside, np.abs(h), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        s = np.clip(np.einsum("pfi,fi->pf", p[:, None] - u[None], e) / np.einsum("fi,fi->f", e, e), 0, 1)
        best = np.minimum(best, np.linalg.norm(p[:, None] - (u[None] + s[..., None] * e[None]), axis=2))
    return best
