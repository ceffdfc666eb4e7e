"""Slow, obvious NumPy twins of the force-density kernels (``preform._kernels.relax``).

Chains are walked yarn by yarn from the fell point to the top point (``ZoneState.chain``), forces
are summed segment by segment, the Laplacian is a dense matrix, the material problem of a yarn is
solved by a dense Newton iteration on its residual written from the energy of
``interaction/frontal.py`` (``W = k (l - q)^2 / (2 q)``, spool payout, smoothed friction).
"""

from __future__ import annotations

import numpy as np

from preform.interaction.settings import DEFAULT

# the model's constants (the twins use the defaults, as the tests pass them to the kernels)
COMPRESSION = DEFAULT.energy.compression
TOP_SMOOTHING2 = DEFAULT.energy.top_smoothing2


def yarn_point(st, c, side, h):
    o = st.over[c] if side == 0 else -st.over[c]
    return st.pos[c] + o * h * st.normal[c]


def chains(st):
    n = st.n_yarns // 2
    return [(0 if k < n else 1, list(st.chain(k))) for k in range(st.n_yarns)]


def segments(st, fell, top, h, eps2):
    """Per yarn k: (side, chain, points fell..top, lengths below each crossing, top length)."""
    out = []
    for k, (side, chain) in enumerate(chains(st)):
        pts = np.array([fell[k]] + [yarn_point(st, c, side, h) for c in chain] + [top[k]])
        d = np.diff(pts, axis=0)
        l = np.sqrt(np.sum(d * d, axis=1) + eps2)
        if chain:
            l[-1] = np.sqrt(d[-1] @ d[-1] + eps2 + TOP_SMOOTHING2)
        out.append((side, chain, pts, l[:-1], l[-1] if chain else 0.0))
    return out


def tension(l, q, EA):
    return EA * (l - q) / q * (1.0 if l >= q else COMPRESSION)


def yarn_residual(s, s0, l, s_old, g, f_top, EA, eps_f, kappa0):
    """dE/ds of one yarn's material problem (crossings lowest first)."""
    q = np.diff(np.concatenate([[s0], s]))
    ka = np.where(l >= q, EA, COMPRESSION * EA)
    wq = 0.5 * ka * (1.0 - (l / q) ** 2)
    x = s - s_old
    r = wq + g * x / np.sqrt(x * x + eps_f ** 2) + kappa0 * x
    r[:-1] -= wq[1:]
    r[-1] += f_top + f_top ** 2 / (2 * EA)
    return r


def material(st, fell, top, s, s_old, g, f_top, EA, eps_f, kappa0, h, eps2, iters=60):
    """Material coordinates (m, 2) solving every yarn's friction law at the positions of st, by
    dense Newton (finite-difference Jacobian) from s; and the segment tensions (m, 2)."""
    s = np.array(s, dtype=float)
    ten = np.zeros_like(s)
    for k, (side, chain, pts, l, _) in enumerate(segments(st, fell, top, h, eps2)):
        if not chain:
            continue
        x = s[chain, side].copy()
        args = (st.material_fell[k], l, s_old[chain, side], g[chain, side], f_top[k], EA, eps_f, kappa0)
        for _ in range(iters):
            r = yarn_residual(x, *args)
            J = np.empty((len(x), len(x)))
            for j in range(len(x)):
                e = np.zeros(len(x))
                e[j] = 1e-9
                J[:, j] = (yarn_residual(x + e, *args) - yarn_residual(x - e, *args)) / 2e-9
            dx = np.linalg.solve(J, -r)
            x += dx
            if np.abs(dx).max() < 1e-13:
                break
        s[chain, side] = x
        q = np.diff(np.concatenate([[st.material_fell[k]], x]))
        ten[chain, side] = [tension(a, b, EA) for a, b in zip(l, q)]
    return s, ten


def net_forces(st, fell, top, ten, f_top, h, eps2, l_jam, k_jam):
    """Net force (m, 3) of the yarns on every crossing: tension times unit vector towards the
    other end of each segment, less the jamming push of segments between two crossings."""
    F = np.zeros((st.m, 3))
    for k, (side, chain, pts, l, lt) in enumerate(segments(st, fell, top, h, eps2)):
        for i, c in enumerate(chain):
            u = (pts[i] - pts[i + 1]) / l[i]          # from c towards the point below
            f = ten[c, side]
            if i > 0 and l[i] < l_jam:
                f -= k_jam * (l_jam - l[i])
            F[c] += f * u
            if i > 0:
                F[chain[i - 1]] -= f * u
        if chain:
            F[chain[-1]] += f_top[k] * (pts[-1] - pts[-2]) / lt
    return F


def laplacian(st, w_below, w_top, active):
    """Dense weighted Laplacian of the crossing lattice; wall rows (active) Dirichlet."""
    m = st.m
    L = np.zeros((m, m))
    for c in range(m):
        for side in range(2):
            lo = st.low[c, side]
            L[c, c] += w_below[c, side]
            if lo >= 0:
                L[lo, lo] += w_below[c, side]
                L[c, lo] -= w_below[c, side]
                L[lo, c] -= w_below[c, side]
    for k in range(st.n_yarns):
        if st.highest[k] >= 0:
            L[st.highest[k], st.highest[k]] += w_top[k]
    diag = np.diag(L).copy()
    for c in np.nonzero(active)[0]:
        L[c, :] = 0.0
        L[:, c] = 0.0
        L[c, c] = 1.0
    return L, diag


def block_stiffness(st, fell, top, ten, f_top, h, eps2, l_jam, k_jam, floor, reg, plane, active):
    """Dense block preconditioner (3m x 3m): per segment ``max(f - f_jam, floor) / l (I - d d^T)
    + k_jam d d^T + reg max(f, floor) / l I`` on the diagonal blocks of both ends and minus it
    on their coupling (fell and top segments: the crossing's diagonal only); rows and columns of
    a crossing on the wall projected onto its plane, plus n n^T on its diagonal."""
    m = st.m
    K = np.zeros((3 * m, 3 * m))
    I3 = np.eye(3)
    for k, (side, chain, pts, l, lt) in enumerate(segments(st, fell, top, h, eps2)):
        for i, c in enumerate(chain):
            d = (pts[i + 1] - pts[i]) / l[i]
            f = ten[c, side]
            fj = k_jam * (l_jam - l[i]) if (i > 0 and l[i] < l_jam) else 0.0
            B = (max(f - fj, floor) / l[i] * (I3 - np.outer(d, d))
                 + (k_jam if fj > 0 else 0.0) * np.outer(d, d) + reg * max(f, floor) / l[i] * I3)
            K[3 * c:3 * c + 3, 3 * c:3 * c + 3] += B
            if i > 0:
                b = chain[i - 1]
                K[3 * b:3 * b + 3, 3 * b:3 * b + 3] += B
                K[3 * c:3 * c + 3, 3 * b:3 * b + 3] -= B
                K[3 * b:3 * b + 3, 3 * c:3 * c + 3] -= B
        if chain:
            c = chain[-1]
            d = (pts[-1] - pts[-2]) / lt
            w = max(f_top[k], floor) / lt
            K[3 * c:3 * c + 3, 3 * c:3 * c + 3] += w * ((1 + reg) * I3 - np.outer(d, d))
    P = np.eye(3 * m)
    N = np.zeros((3 * m, 3 * m))
    for c in np.nonzero(active)[0]:
        n = plane[c, 3:]
        P[3 * c:3 * c + 3, 3 * c:3 * c + 3] -= np.outer(n, n)
        N[3 * c:3 * c + 3, 3 * c:3 * c + 3] = np.outer(n, n)
    return P @ K @ P + N, P


class Anderson:
    """Type-II Anderson mixing written out with NumPy (the twin of ``preconditioners.Anderson``):
    x+ = G(x) - (dX + dR) gamma, gamma the regularised least-squares fit of r by dR over the
    last ``depth`` differences."""

    def __init__(self, depth):
        self.depth = depth
        self.xs, self.rs = [], []

    def __call__(self, x, gx):
        r = gx - x
        self.xs.append(x.copy())
        self.rs.append(r.copy())
        if len(self.xs) == 1:
            return gx
        dX = np.diff(np.array(self.xs[-self.depth - 1:]), axis=0).T
        dR = np.diff(np.array(self.rs[-self.depth - 1:]), axis=0).T
        G = dR.T @ dR
        gamma = np.linalg.solve(G + (1e-12 * np.trace(G) + 1e-300) * np.eye(G.shape[0]),
                                dR.T @ r)
        return gx - (dX + dR) @ gamma


def pattern_keys(low, perm):
    """The keys ``column * m + row`` of the lower block pattern of a matrix with the lattice's
    pattern (each crossing coupled to its neighbours below, ``low`` (m, 2), -1 for none) in the
    order ``perm``, unsorted, diagonal first; and (pc, plo, link): each crossing's position, its
    neighbours' positions (-1 for none) and which neighbours exist."""
    m = low.shape[0]
    pinv = np.empty(m, dtype=np.int64)
    pinv[perm] = np.arange(m)
    link = low >= 0
    pc = np.broadcast_to(pinv[:, None], low.shape)
    plo = np.where(link, pinv[np.maximum(low, 0)], -1)
    rows = np.concatenate([pinv, np.minimum(pc, plo)[link]])
    cols = np.concatenate([pinv, np.maximum(pc, plo)[link]])
    return cols * m + rows, pc, plo, link


def block_fill(low, perm):
    """Blocks of the factor L below the diagonal of a matrix with the lattice's pattern in the
    order perm (``ldl_symbolic`` on the unique keys of ``pattern_keys``)."""
    from preform._kernels import ldl as LDL

    m = low.shape[0]
    uniq = np.unique(pattern_keys(low, perm)[0])
    Ap = np.zeros(m + 1, dtype=np.int64)
    np.add.at(Ap, uniq // m + 1, 1)
    Lnz, etree = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    return LDL.ldl_symbolic(m, np.cumsum(Ap), (uniq % m).astype(np.int64),
                           np.empty(m, dtype=np.int64), Lnz, etree)
