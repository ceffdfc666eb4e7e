"""Slow, obvious NumPy twins of the kinematic kernels (``preform._kernels.kinematic``).

Written from the definitions with vector operations and ``np.linalg``, not from the kernel code.
"""

from __future__ import annotations

import math

import numpy as np

TANGENT, CONCAVE, BUDGET, DEGENERATE, BOUNDARY, LIFTOFF = 0, 1, 2, 3, 4, -1


def bary(V, T, f, x):
    p = V[T[f]]
    A = np.stack([p[1] - p[0], p[2] - p[0]], axis=1)
    b12, *_ = np.linalg.lstsq(A, x - p[0], rcond=None)
    return np.array([1 - b12.sum(), b12[0], b12[1]])


def normal(V, T, CN, f, x):
    n = bary(V, T, f, x) @ CN[f]
    return n / np.linalg.norm(n)


def gap(V, T, CN, f, x, G):
    return float((G - x) @ normal(V, T, CN, f, x))


def direction(FN, f, x, G):
    d = G - x
    d = d - (d @ FN[f]) * FN[f]
    return d / np.linalg.norm(d)


def exit_along(V, T, f, x, d):
    """Smallest t >= 0 with x + t d on an edge of face f (by sampling the barycentrics linearly)."""
    b0 = bary(V, T, f, x)
    b1 = bary(V, T, f, x + d)  # barycentrics are affine in position
    rate = b1 - b0
    best, edge = np.inf, -1
    for i in range(3):
        if rate[i] < -1e-14:
            t = max(b0[i] / -rate[i], 0.0)
            if t < best:
                best, edge = t, (i + 1) % 3
    return best, edge


def walk(V, T, FN, CN, NB, x, f, G_mid, G_end, h_max, max_len):
    x = np.array(x, dtype=float)
    g_prev = gap(V, T, CN, f, x, G_end)
    if g_prev >= 0:
        return x, f, LIFTOFF, 0.0
    walked = 0.0
    for _ in range(100000):
        if walked >= max_len:
            return x, f, BUDGET, walked
        d = direction(FN, f, x, G_mid)
        t_exit, edge = exit_along(V, T, f, x, d)
        h = min(h_max, t_exit, max_len - walked)
        d = direction(FN, f, x + 0.5 * h * d, G_mid)
        t_exit, edge = exit_along(V, T, f, x, d)
        h = min(h_max, t_exit, max_len - walked)
        x1 = x + h * d
        g1 = gap(V, T, CN, f, x1, G_end)
        if g1 >= 0:
            from scipy.optimize import brentq

            tau = brentq(lambda t: gap(V, T, CN, f, x + t * d, G_end), 0.0, h, xtol=1e-14)
            return x + tau * d, f, TANGENT, walked + tau
        if g1 < g_prev - 1e-12 * (1 + abs(g_prev)) and h > 0:
            return x1, f, CONCAVE, walked + h
        walked += h
        x, g_prev = x1, g1
        if h >= t_exit and edge >= 0:
            if NB[f, edge] < 0:
                return x, f, BOUNDARY, walked
            f = NB[f, edge]
    return x, f, BUDGET, walked


def project_to_polyline(points, P, S):
    """Closest polyline point to each point, from the definition with whole-array NumPy: every
    segment for every point, u clipped to [0, 1], the first of the nearest (np.argmin).
    Returns (s (m,), distance (m,))."""
    a = P[:-1]
    e = P[1:] - a
    L2 = np.einsum("ij,ij->i", e, e)
    u = np.einsum("mjk,jk->mj", points[:, None, :] - a[None], e) / np.where(L2 > 0, L2, 1.0)
    u = np.where(L2 > 0, np.clip(u, 0.0, 1.0), 0.0)
    q = a[None] + u[..., None] * e[None]
    d = np.linalg.norm(q - points[:, None, :], axis=2)
    j = np.argmin(d, axis=1)
    rows = np.arange(len(points))
    return S[j] + u[rows, j] * (S[j + 1] - S[j]), d[rows, j]


def project_to_polyline_loops(points, P, S):
    """The same, one segment after another in plain Python floats, the operations in the order
    of the kernel's segment test: the brute force the kernel's pruned search must equal bit for
    bit. Returns (s (m,), distance (m,))."""
    out_s = np.empty(len(points))
    out_d = np.empty(len(points))
    P = P.tolist()
    S = S.tolist()
    for i, (px, py, pz) in enumerate(points.tolist()):
        best, best_s = float("inf"), 0.0
        for j in range(len(P) - 1):
            ax, ay, az = P[j]
            ex, ey, ez = P[j + 1][0] - ax, P[j + 1][1] - ay, P[j + 1][2] - az
            L2 = ex * ex + ey * ey + ez * ez
            u = 0.0
            if L2 > 0.0:
                u = min(max(((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / L2, 0.0), 1.0)
            dx, dy, dz = ax + u * ex - px, ay + u * ey - py, az + u * ez - pz
            d2 = dx * dx + dy * dy + dz * dz
            if d2 < best:
                best, best_s = d2, S[j] + u * (S[j + 1] - S[j])
        out_s[i] = best_s
        out_d[i] = math.sqrt(best)
    return out_s, out_d


def project_sampled(points, Q, Sq):
    """Arc length on the resampled centerline Q (n, 3), arc lengths Sq (n,), in whole-array
    NumPy: the nearest sample by a KD-tree, then the nearer of its two resampled segments (the
    first on a tie), u clipped to [0, 1]."""
    from scipy.spatial import cKDTree

    _, i = cKDTree(Q).query(points)
    n = len(Sq)
    best_s = Sq[i].copy()
    best_d = np.full(len(points), np.inf)
    for lo in (np.maximum(i - 1, 0), i):
        hi = np.minimum(lo + 1, n - 1)
        a = Q[lo]
        ab = Q[hi] - a
        L2 = np.einsum("ij,ij->i", ab, ab)
        u = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        d = np.linalg.norm(a + u[:, None] * ab - points, axis=1)
        better = d < best_d
        best_d[better] = d[better]
        best_s[better] = (Sq[lo] + u * (Sq[hi] - Sq[lo]))[better]
    return best_s
