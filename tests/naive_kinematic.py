"""Slow, obvious NumPy twins of the kinematic kernels (``preform._kernels.kinematic``).

Written from the definitions with vector operations and ``np.linalg``, not from the kernel code.
"""

from __future__ import annotations

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
