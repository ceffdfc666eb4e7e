"""Slow, obvious NumPy twins of the frontal kernels (``preform._kernels.frontal``).

Chains are walked yarn by yarn from the fell point to the top point (not over the crossing
arrays in creation order as the kernels do), segments are vectors, the energy is written term by
term from the docstring of ``preform/interaction/frontal.py`` and the friction cone from docs/theory.md §4
§3.3 (``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``). The model's constants are
arguments (``preform.interaction.settings``).
"""

from __future__ import annotations

import numpy as np


def yarn_point(st, c, side, h):
    o = st.over[c] if side == 0 else -st.over[c]
    return st.pos[c] + o * h * st.normal[c]


def chains(st):
    """Per yarn: (side, [crossings lowest first])."""
    n = st.n_yarns // 2
    return [(0 if k < n else 1, list(st.chain(k))) for k in range(st.n_yarns)]


def polyline(st, k, side, chain, fell, top, h):
    return np.array([fell[k]] + [yarn_point(st, c, side, h) for c in chain] + [top[k]])


def energy(st, fell, top, f_top, bound, centre, EA, compression, eps_f, kappa0, h, eps2, eps2_top,
           l_jam=0.0, k_jam=0.0, plane=None, k_wall=0.0, pos=None, material=None):
    """The step energy by yarns: stretched segments, jamming of segments between two crossings
    shorter than l_jam, spool payout (top segment length smoothed by eps2 + eps2_top), friction,
    and the wall (``plane`` (m, 6): point and outward normal per crossing; none if None). pos,
    material: the iterate (default the state's)."""
    pos = st.pos[: st.m] if pos is None else pos
    material = st.material[: st.m] if material is None else material
    E = 0.0
    for k, (side, chain) in enumerate(chains(st)):
        if not chain:
            continue
        o = np.array([st.over[c] if side == 0 else -st.over[c] for c in chain])
        pts = np.vstack([fell[k], pos[chain] + o[:, None] * h * st.normal[chain], top[k]])
        u = [st.material_fell[k]] + [material[c, side] for c in chain]
        for i in range(len(chain)):
            d = pts[i + 1] - pts[i]
            l = np.sqrt(d @ d + eps2)
            q = u[i + 1] - u[i]
            if q <= 0:
                return np.inf
            E += 0.5 * EA * (l - q) ** 2 / q * (1.0 if l >= q else compression)
            if i >= 1 and l < l_jam:      # pts[0] is the fell point
                E += 0.5 * k_jam * (l_jam - l) ** 2
        d = pts[-1] - pts[-2]
        f = f_top[k]
        E += (f + f * f / (2 * EA)) * u[-1] + f * np.sqrt(d @ d + eps2 + eps2_top)
    x = material - centre
    E += np.sum(bound * (np.sqrt(x * x + eps_f ** 2) - eps_f) + 0.5 * kappa0 * x * x)
    if plane is not None:
        dist = np.einsum("ij,ij->i", pos - plane[:, :3], plane[:, 3:])
        E += 0.5 * k_wall * np.sum(np.minimum(dist, 0.0) ** 2)
    return E


def tensions(st, fell, EA, compression, h, eps2):
    """Tension below every crossing (m, 2), walking every yarn from its fell point up."""
    out = np.zeros((st.m, 2))
    for k, (side, chain) in enumerate(chains(st)):
        prev, u_prev = fell[k], st.material_fell[k]
        for c in chain:
            p = yarn_point(st, c, side, h)
            l = np.sqrt(np.sum((p - prev) ** 2) + eps2)
            q = st.material[c, side] - u_prev
            out[c, side] = EA * (l - q) / q * (1.0 if l >= q else compression)
            prev, u_prev = p, st.material[c, side]
    return out


def bounds(st, fell, top, tension, f_top, h, mu):
    """Friction bound mu (f_int + f_ext) tan(delta/2) per crossing and yarn (m, 2); mu: one
    coefficient, or (m,) one per crossing."""
    out = np.zeros((st.m, 2))
    mu = np.broadcast_to(np.asarray(mu, dtype=float), (st.m,))
    for k, (side, chain) in enumerate(chains(st)):
        pts = polyline(st, k, side, chain, fell, top, h)
        ten = [tension[c, side] for c in chain] + [f_top[k]]
        for i, c in enumerate(chain):
            lo, p, hi = pts[i], pts[i + 1], pts[i + 2]
            u_int = (lo - p) / np.linalg.norm(lo - p)
            u_ext = (hi - p) / np.linalg.norm(hi - p)
            delta = np.pi - np.arccos(np.clip(u_int @ u_ext, -1, 1))
            out[c, side] = mu[c] * (ten[i] + ten[i + 1]) * np.tan(delta / 2)
    return out
