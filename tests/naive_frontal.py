"""Slow, obvious NumPy twins of the frontal kernels (``preform._kernels.frontal``).

Chains are walked yarn by yarn from the fell point to the top point (not over the crossing
arrays in creation order as the kernels do), segments are vectors, the energy is written term by
term from the docstring of ``preform/interaction/frontal.py`` and the friction cone from DESIGN.md
§3.3 (``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``).
"""

from __future__ import annotations

import numpy as np

from preform._kernels.frontal import COMPRESSION   # a constant of the model, not code


def yarn_point(st, c, side, h):
    s = st.over[c] if side == 0 else -st.over[c]
    return st.pos[c] + s * h * st.normal[c]


def chains(st):
    """Per yarn: (side, [crossings lowest first])."""
    n = st.n_yarns // 2
    return [(0 if k < n else 1, list(st.chain(k))) for k in range(st.n_yarns)]


def polyline(st, k, side, chain, fell, top, h):
    return np.array([fell[k]] + [yarn_point(st, c, side, h) for c in chain] + [top[k]])


def energy(st, fell, top, f_top, g, s_old, EA, eps_f, kappa0, h, eps2, eps2_top, l_jam=0.0,
           k_jam=0.0):
    """The step energy (no wall) by yarns: stretched segments, jamming of segments between two
    crossings shorter than l_jam, spool payout (top segment length smoothed by eps2 + eps2_top),
    friction."""
    E = 0.0
    for k, (side, chain) in enumerate(chains(st)):
        if not chain:
            continue
        pts = polyline(st, k, side, chain, fell, top, h)
        s = [st.s_fell[k]] + [st.s[c, side] for c in chain]
        for i in range(len(chain)):
            d = pts[i + 1] - pts[i]
            l = np.sqrt(d @ d + eps2)
            q = s[i + 1] - s[i]
            if q <= 0:
                return np.inf
            E += 0.5 * EA * (l - q) ** 2 / q * (1.0 if l >= q else COMPRESSION)
            if i >= 1 and l < l_jam:      # pts[0] is the fell point
                E += 0.5 * k_jam * (l_jam - l) ** 2
        d = pts[-1] - pts[-2]
        f = f_top[k]
        E += (f + f * f / (2 * EA)) * s[-1] + f * np.sqrt(d @ d + eps2 + eps2_top)
    x = st.s[: st.m] - s_old
    E += np.sum(g * (np.sqrt(x * x + eps_f ** 2) - eps_f) + 0.5 * kappa0 * x * x)
    return E


def tensions(st, fell, EA, h, eps2):
    """Tension below every crossing (m, 2), walking every yarn from its fell point up."""
    out = np.zeros((st.m, 2))
    for k, (side, chain) in enumerate(chains(st)):
        prev, s_prev = fell[k], st.s_fell[k]
        for c in chain:
            p = yarn_point(st, c, side, h)
            l = np.sqrt(np.sum((p - prev) ** 2) + eps2)
            q = st.s[c, side] - s_prev
            out[c, side] = EA * (l - q) / q * (1.0 if l >= q else COMPRESSION)
            prev, s_prev = p, st.s[c, side]
    return out


def bounds(st, fell, top, tension, f_top, h, mu):
    """Friction bound mu (f_int + f_ext) tan(delta/2) per crossing and yarn (m, 2)."""
    out = np.zeros((st.m, 2))
    for k, (side, chain) in enumerate(chains(st)):
        pts = polyline(st, k, side, chain, fell, top, h)
        ten = [tension[c, side] for c in chain] + [f_top[k]]
        for i, c in enumerate(chain):
            lo, p, hi = pts[i], pts[i + 1], pts[i + 2]
            u_int = (lo - p) / np.linalg.norm(lo - p)
            u_ext = (hi - p) / np.linalg.norm(hi - p)
            delta = np.pi - np.arccos(np.clip(u_int @ u_ext, -1, 1))
            out[c, side] = mu * (ten[i] + ten[i + 1]) * np.tan(delta / 2)
    return out
