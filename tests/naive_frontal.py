"""Slow, obvious NumPy twins of the frontal kernels (``preform._kernels.frontal``).

Chains are walked yarn by yarn from the fell point to the top point (not over the crossing
arrays in creation order as the kernels do), segments are vectors, the friction cone is written
from DESIGN.md §3.3 (``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``).
"""

from __future__ import annotations

import numpy as np


def yarn_point(st, c, side, h):
    s = st.over[c] if side == 0 else -st.over[c]
    return st.pos[c] + s * h * st.normal[c]


def chains(st):
    """Per yarn: (side, [crossings lowest first])."""
    n = st.n_yarns // 2
    return [(0 if k < n else 1, list(st.chain(k))) for k in range(st.n_yarns)]


def polyline(st, k, side, chain, fell, top, h):
    return np.array([fell[k]] + [yarn_point(st, c, side, h) for c in chain] + [top[k]])


def energy_and_gradient(st, fell, top, f_top, h, eps2):
    """E = sum f sqrt(|d|^2 + eps2) and dE/dC (m, 3), segment tensions from st.tension / f_top."""
    g = np.zeros((st.m, 3))
    E = 0.0
    for k, (side, chain) in enumerate(chains(st)):
        if not chain:
            continue
        pts = polyline(st, k, side, chain, fell, top, h)
        ids = [-1] + chain + [-1]
        ten = [st.tension[c, side] for c in chain] + [f_top[k]]
        for i in range(len(pts) - 1):
            d = pts[i + 1] - pts[i]
            l = np.sqrt(d @ d + eps2)
            E += ten[i] * l
            if ids[i + 1] >= 0:
                g[ids[i + 1]] += ten[i] * d / l
            if ids[i] >= 0:
                g[ids[i]] -= ten[i] * d / l
    return E, g


def capstan_tensions(st, fell, top, f_top, h, mu):
    """Tensions below each crossing (m, 2) walking every yarn from its top point down."""
    out = np.zeros((st.m, 2))
    for k, (side, chain) in enumerate(chains(st)):
        pts = polyline(st, k, side, chain, fell, top, h)
        f = f_top[k]
        for i in range(len(chain), 0, -1):
            c = chain[i - 1]
            lo, p, hi = pts[i - 1], pts[i], pts[i + 1]
            u_int = (lo - p) / np.linalg.norm(lo - p)
            u_ext = (hi - p) / np.linalg.norm(hi - p)
            delta = np.pi - np.arccos(np.clip(u_int @ u_ext, -1, 1))
            t = mu * np.tan(delta / 2)
            lo_f, hi_f = f * (1 - t) / (1 + t), (f * (1 + t) / (1 - t) if t < 1 else np.inf)
            s = st.slip[c, side]
            if s > 0:
                f = hi_f
            elif s < 0:
                f = lo_f
            else:
                f = np.clip(st.ratio[c, side] * f, lo_f, hi_f)
            out[c, side] = f
    return out
