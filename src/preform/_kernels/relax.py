"""Numba kernels of the force-density relaxation of a convergence-zone step
(``preform/interaction/relax.py`` says what is solved and why; DESIGN.md §3.3).

Plain arrays only. Layout as in ``preform/interaction/zone_state.py``: crossings ``c < m`` with
``yarn (m, 2)`` (warp, weft index), ``low``/``up (m, 2)`` (neighbour crossing below / above on each
yarn, -1 at the fell / top end), ``over (m,)`` (+1: the warp is outside), contact normals
``normal (m, 3)``, contact points ``pos (m, 3)`` and material coordinates ``s (m, 2)`` (the
state's ``material``); per yarn ``lowest``/``highest (2n,)``, ``s_fell (2n,)`` (``material_fell``), ``fell``/``top (2n, 3)``. The yarn point of side
``side`` at ``c`` is ``C + o h N`` with ``o = over[c]`` for the warp and ``-over[c]`` for the weft
(paper eq. 16). Segment ``(c, side)`` runs from the yarn point below (crossing ``low[c, side]`` or the
fell point) up to ``c``'s; each yarn also has its top segment, highest crossing to top point.

The equations are those of ``_kernels/frontal.assemble`` (the Newton reference): per segment the
tension ``f = k (l - q) / q`` (``k = EA``, ``compression EA`` when slack), ``l = sqrt(|d|^2 +
eps2)`` (top: ``+ eps2_top``), material ``q = s_c - s_below``; jamming push ``k_jam (l_jam -
l)`` between two crossings closer than ``l_jam``; smoothed friction ``g sqrt(x^2 + eps_f^2) + kappa0
x^2 / 2`` in the slide ``x = s - s_old``. The constants arrive as arguments from
``preform/interaction/settings.py`` (``EnergySettings``, ``FrontalSettings``). The slow twins are in ``tests/naive_relax.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit



@njit(cache=True)
def _offset(over, c, side, h):
    return over[c] * h if side == 0 else -over[c] * h


@njit(cache=True)
def segment_vectors(m, n_yarns, yarn, pos, normal, over, low, highest, fell, top, h, eps2, eps2_top,
                    d_below, l_below, d_top, l_top):
    """Vectors (upper yarn point less lower) and smoothed lengths of every segment: below every
    crossing on both yarns into d_below (m, 2, 3), l_below (m, 2); top segments (top point less
    the highest yarn point) into d_top (2n, 3), l_top (2n,) (l = 0 for a yarn without crossings)."""
    n = n_yarns // 2
    for c in range(m):
        for side in range(2):
            o = _offset(over, c, side, h)
            lo = low[c, side]
            dd = 0.0
            for i in range(3):
                p = pos[c, i] + o * normal[c, i]
                if lo >= 0:
                    b = pos[lo, i] + _offset(over, lo, side, h) * normal[lo, i]
                else:
                    b = fell[yarn[c, side], i]
                d_below[c, side, i] = p - b
                dd += (p - b) * (p - b)
            l_below[c, side] = math.sqrt(dd + eps2)
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            l_top[k] = 0.0
            for i in range(3):
                d_top[k, i] = 0.0
            continue
        side = 0 if k < n else 1
        o = _offset(over, c, side, h)
        dd = 0.0
        for i in range(3):
            v = top[k, i] - (pos[c, i] + o * normal[c, i])
            d_top[k, i] = v
            dd += v * v
        l_top[k] = math.sqrt(dd + eps2 + eps2_top)


@njit(cache=True)
def _ka(l, q, EA, compression):
    return EA if l >= q else compression * EA


@njit(cache=True)
def _yarn_energy(nc, chain, side, s_ref, s0, l_below, s_old, g, F_top, EA, compression, eps_f,
                 kappa0, trial):
    """Energy of one yarn's material problem at the trial coordinates (inf if a q <= 0); the
    spool's payout measured from s_ref (the top material of the current iterate), so that the
    terms Newton changes are not lost in the round-off of F_top s (s runs to metres)."""
    E = 0.0
    prev = s0
    for i in range(nc):
        c = chain[i]
        q = trial[i] - prev
        if q <= 0.0:
            return np.inf
        l = l_below[c, side]
        E += 0.5 * _ka(l, q, EA, compression) * (l - q) * (l - q) / q
        x = trial[i] - s_old[c, side]
        E += g[c, side] * (math.sqrt(x * x + eps_f * eps_f) - eps_f) + 0.5 * kappa0 * x * x
        prev = trial[i]
    return E + F_top * (trial[nc - 1] - s_ref)


@njit(cache=True)
def material_sweep(n_yarns, lowest, up, yarn, l_below, s, s_fell, s_old, g, f_top, EA,
                   compression, eps_f, kappa0, tol, max_newton, tension, chain, work, stats):
    """Per yarn, the material coordinates s of its crossings that make ``dE/ds = 0`` for the
    lengths l_below held (the friction law along the yarn, a convex chain problem): Newton on the
    tridiagonal system with backtracking on the yarn's energy, O(crossings of the yarn) per
    Newton step. In place on s; tension (m, 2) receives the segment tensions. chain (m,) int64
    and work (m, 6) are scratch; stats (2,) int64 counts Newton steps and energy evaluations
    (added to). Returns the largest relative residual |dE/ds| / (|f_below| + |f_above|) left."""
    n = n_yarns // 2
    worst = 0.0
    for k in range(n_yarns):
        c = lowest[k]
        if c < 0:
            continue
        side = 0 if k < n else 1
        nc = 0
        while c >= 0:
            chain[nc] = c
            nc += 1
            c = up[c, side]
        F_top = f_top[k] + f_top[k] * f_top[k] / (2.0 * EA)
        s0 = s_fell[k]
        for i in range(nc):
            work[i, 5] = s[chain[i], side]
        E_known = False
        E_cur = 0.0
        E1 = 0.0
        s_ref = 0.0
        for it in range(max_newton + 1):
            # residual r (work[:, 0]), diagonal (1), sub-diagonal coupling to i-1 (2)
            res = 0.0
            prev = s0
            wq_prev = 0.0
            for i in range(nc):
                c = chain[i]
                q = work[i, 5] - prev
                l = l_below[c, side]
                ka = _ka(l, q, EA, compression)
                wq = 0.5 * ka * (1.0 - (l / q) ** 2)         # dW/dq
                wqq = ka * l * l / (q * q * q)
                x = work[i, 5] - s_old[c, side]
                r = math.sqrt(x * x + eps_f * eps_f)
                gg = g[c, side]
                work[i, 0] = wq + gg * x / r + kappa0 * x
                work[i, 1] = wqq + gg * eps_f * eps_f / (r * r * r) + kappa0
                work[i, 2] = -wqq
                if i > 0:
                    work[i - 1, 0] -= wq
                    work[i - 1, 1] += wqq
                tension[c, side] = ka * (l - q) / q
                prev = work[i, 5]
            work[nc - 1, 0] += F_top
            for i in range(nc):
                fa = tension[chain[i + 1], side] if i + 1 < nc else f_top[k]
                e = abs(work[i, 0]) / max(abs(tension[chain[i], side]) + abs(fa), 1e-300)
                if e > res:
                    res = e
            if res < tol or it == max_newton:
                break
            stats[0] += 1
            # Thomas algorithm: (diag, sub = work[i, 2] couples i and i-1, symmetric)
            for i in range(nc):
                work[i, 3] = work[i, 1]
                work[i, 4] = -work[i, 0]
            for i in range(1, nc):
                w = work[i, 2] / work[i - 1, 3]
                work[i, 3] -= w * work[i, 2]
                work[i, 4] -= w * work[i - 1, 4]
            work[nc - 1, 4] /= work[nc - 1, 3]
            for i in range(nc - 2, -1, -1):
                work[i, 4] = (work[i, 4] - work[i + 1, 2] * work[i + 1, 4]) / work[i, 3]
            # backtracking on the yarn energy (trial in work[:, 3])
            if s_ref != work[nc - 1, 5] or not E_known:
                s_ref = work[nc - 1, 5]
                E0 = _yarn_energy(nc, chain, side, s_ref, s0, l_below, s_old, g, F_top, EA,
                                  compression, eps_f, kappa0, work[:, 5])
                stats[1] += 1
            else:
                E0 = E_cur
            slope = 0.0
            for i in range(nc):
                slope += work[i, 0] * work[i, 4]
            t = 1.0
            # a decrease below the energy's round-off cannot be judged by it: the full step,
            # which the residual then judges (as frontal._newton_step does)
            halvings = 60 if -slope > 1e-12 * abs(E0) else 0
            for i in range(nc):
                work[i, 3] = work[i, 5] + work[i, 4]
            for _ in range(halvings):
                for i in range(nc):
                    work[i, 3] = work[i, 5] + t * work[i, 4]
                E1 = _yarn_energy(nc, chain, side, s_ref, s0, l_below, s_old, g, F_top, EA,
                                  compression, eps_f, kappa0, work[:, 3])
                stats[1] += 1
                if E1 <= E0 + 1e-4 * t * slope + 1e-13 * abs(E0):
                    break
                t *= 0.5
            # the accepted trial's energy starts the next step's line search (measured from
            # the same s_ref, which the next step then keeps)
            E_known = halvings > 0
            E_cur = E1 + F_top * (s_ref - work[nc - 1, 3]) if E_known else 0.0
            s_ref = work[nc - 1, 3]
            for i in range(nc):
                work[i, 5] = work[i, 3]
        for i in range(nc):
            s[chain[i], side] = work[i, 5]
        if res > worst:
            worst = res
    return worst


@njit(cache=True)
def forces(m, n_yarns, yarn, low, highest, d_below, l_below, d_top, l_top, tension, f_top,
           l_jam, k_jam, floor, force, w_below, w_top, total, W):
    """Net yarn force (N) on every crossing into force (m, 3): tension times unit vector of each
    of its segments towards the segment's other end, less the jamming push; the preconditioner's
    force densities (N/m) of the segments into w_below (m, 2), w_top (2n,): ``max(f - f_jam,
    floor) / l + k_jam`` (jamming active), which is the force density ``(f - f_jam) / l`` itself
    wherever that exceeds floor / l and no jam acts; total (m,) the sum of the four tensions at
    each crossing (the scale of its balance); W (m,) the sum of its segments' densities."""
    for c in range(m):
        total[c] = 0.0
        W[c] = 0.0
        for i in range(3):
            force[c, i] = 0.0
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            l = l_below[c, side]
            f = tension[c, side]
            gap = l_jam - l
            fj = k_jam * gap if (gap > 0.0 and lo >= 0) else 0.0
            kj = k_jam if fj > 0.0 else 0.0
            a = (f - fj) / l
            for i in range(3):
                force[c, i] -= a * d_below[c, side, i]
                if lo >= 0:
                    force[lo, i] += a * d_below[c, side, i]
            w = max(f - fj, floor) / l + kj
            w_below[c, side] = w
            total[c] += abs(f)
            W[c] += w
            if lo >= 0:
                total[lo] += abs(f)
                W[lo] += w
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            w_top[k] = 0.0
            continue
        a = f_top[k] / l_top[k]
        for i in range(3):
            force[c, i] += a * d_top[k, i]
        w_top[k] = max(f_top[k], floor) / l_top[k]
        total[c] += abs(f_top[k])
        W[c] += w_top[k]


@njit(cache=True)
def wall_residual(m, force, total, plane, active, W, release, out):
    """Relative imbalance per crossing into out (m,): |force| / total at a free crossing; at one
    resting on the wall (active) the tangential part and a pull away from the wall (the wall
    cannot pull) beyond release W (the pull that would move it off by ``release`` m, W its
    stiffness), the wall taking the rest. Returns the largest."""
    worst = 0.0
    for c in range(m):
        fx, fy, fz = force[c, 0], force[c, 1], force[c, 2]
        if active[c]:
            fn = fx * plane[c, 3] + fy * plane[c, 4] + fz * plane[c, 5]
            fx -= fn * plane[c, 3]
            fy -= fn * plane[c, 4]
            fz -= fn * plane[c, 5]
            e = math.sqrt(fx * fx + fy * fy + fz * fz) + max(fn - release * W[c], 0.0)
        else:
            e = math.sqrt(fx * fx + fy * fy + fz * fz)
        e /= max(total[c], 1e-300)
        out[c] = e
        if e > worst:
            worst = e
    return worst


@njit(cache=True)
def laplacian_values(m, n_yarns, low, highest, w_below, w_top, active, slot_diag, slot_below,
                     nslots, vals, diag):
    """Values of the scalar weighted Laplacian of the crossing lattice, sum_j w_cj on the
    diagonal and -w_cj off it, into vals (nslots,) at the slots of its fixed pattern
    (slot_diag (m,), slot_below (m, 2): the upper-triangle entry of (c, low[c, side]), -1
    without one). A crossing resting on the wall (active) is a Dirichlet row (1 on the
    diagonal, its couplings dropped from both rows and columns); its own diagonal sum goes into
    diag (m,) for its local update."""
    n = n_yarns // 2
    for i in range(nslots):
        vals[i] = 0.0
    for c in range(m):
        diag[c] = 0.0
    for c in range(m):
        for side in range(2):
            w = w_below[c, side]
            lo = low[c, side]
            diag[c] += w
            if lo >= 0:
                diag[lo] += w
                if not active[c] and not active[lo]:
                    vals[slot_below[c, side]] -= w
    for k in range(n_yarns):
        c = highest[k]
        if c >= 0:
            diag[c] += w_top[k]
    for c in range(m):
        vals[slot_diag[c]] += 1.0 if active[c] else diag[c]


@njit(cache=True)
def wall_update(m, low, up, w_below, force, pos, delta, diag, plane, active, release,
                wall_force):
    """Local update of the crossings resting on the wall after the free crossings moved by delta
    (m, 3) (the wall ones have delta 0 on entry): each goes to where its own balance puts it for
    the force densities held, ``C + (force + sum_j w_cj delta_j) / sum_j w_cj``, projected onto
    its tangent plane unless that point lies more than ``release`` (m) in front of it; wall_force
    (m,) the wall's push (N; negative: the yarns pull it away); delta receives the wall crossings'
    moves."""
    for c in range(m):
        wall_force[c] = 0.0
        if not active[c]:
            continue
        fx, fy, fz = force[c, 0], force[c, 1], force[c, 2]
        for side in range(2):
            lo = low[c, side]
            if lo >= 0 and not active[lo]:
                w = w_below[c, side]
                fx += w * delta[lo, 0]
                fy += w * delta[lo, 1]
                fz += w * delta[lo, 2]
            u = up[c, side]
            if u >= 0 and not active[u]:
                w = w_below[u, side]
                fx += w * delta[u, 0]
                fy += w * delta[u, 1]
                fz += w * delta[u, 2]
        W = diag[c]
        x = pos[c, 0] + fx / W
        y = pos[c, 1] + fy / W
        z = pos[c, 2] + fz / W
        dist = ((x - plane[c, 0]) * plane[c, 3] + (y - plane[c, 1]) * plane[c, 4]
                + (z - plane[c, 2]) * plane[c, 5])
        wall_force[c] = -dist * W
        if dist < release:
            x -= dist * plane[c, 3]
            y -= dist * plane[c, 4]
            z -= dist * plane[c, 5]
        delta[c, 0] = x - pos[c, 0]
        delta[c, 1] = y - pos[c, 1]
        delta[c, 2] = z - pos[c, 2]


@njit(cache=True)
def wall_distance(m, pos, plane, out):
    """Signed distance (m) of every crossing in front of its tangent plane into out (m,)."""
    for c in range(m):
        out[c] = ((pos[c, 0] - plane[c, 0]) * plane[c, 3] + (pos[c, 1] - plane[c, 1]) * plane[c, 4]
                  + (pos[c, 2] - plane[c, 2]) * plane[c, 5])


@njit(cache=True)
def friction_bounds(m, n_yarns, yarn, up, d_below, l_below, d_top, tension, f_top, mu, g, psi):
    """Friction bound g = mu (f_int + f_ext) tan(delta/2) (N) of every crossing and yarn for the
    current geometry and tensions into g (m, 2) (DESIGN.md §3.3), and Psi / (f_int + f_ext),
    Psi = |f_int - f_ext| cos(delta/2) - mu (f_int + f_ext) sin(delta/2), into psi (m, 2).
    ``delta`` from the yarn points (the top segment to the unsmoothed top point); a segment
    without length counts as straight."""
    for c in range(m):
        for side in range(2):
            u = up[c, side]
            fi = tension[c, side]
            if u >= 0:
                fe = tension[u, side]
                bx, by, bz = d_below[u, side, 0], d_below[u, side, 1], d_below[u, side, 2]
            else:
                k = yarn[c, side]
                fe = f_top[k]
                bx, by, bz = d_top[k, 0], d_top[k, 1], d_top[k, 2]
            ax, ay, az = -d_below[c, side, 0], -d_below[c, side, 1], -d_below[c, side, 2]
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            if la < 1e-12 or lb < 1e-12:
                d = -1.0
            else:
                d = min(1.0, max(-1.0, (ax * bx + ay * by + az * bz) / (la * lb)))
            ch = math.sqrt(max(0.5 * (1.0 - d), 0.0))
            sh = math.sqrt(max(0.5 * (1.0 + d), 0.0))
            g[c, side] = mu * (fi + fe) * sh / max(ch, 1e-300)
            psi[c, side] = (abs(fi - fe) * ch - mu * (fi + fe) * sh) / max(fi + fe, 1e-300)


@njit(cache=True)
def _add_block(H, c, w_perp, w_axial, dx, dy, dz):
    """H[c] += w_perp (I - d d^T) + w_axial d d^T for the unit vector d."""
    d = (dx, dy, dz)
    for i in range(3):
        for j in range(3):
            e = d[i] * d[j]
            H[c, i, j] += w_perp * ((1.0 if i == j else 0.0) - e) + w_axial * e


@njit(cache=True)
def block_jacobi(m, n_yarns, low, highest, d_below, l_below, d_top, l_top, tension, f_top,
                 l_jam, k_jam, floor, reg, cap, force, plane, active, H, lmin, delta):
    """One block-Jacobi correction of the positions with each crossing's own 3 x 3 stiffness:
    delta_c = H_c^-1 force_c, H_c = sum over its segments of (f - f_jam) / l (I - d d^T) (floored
    at floor / l) + k_jam d d^T (jamming) + reg sum f / l I; at a crossing on the wall (active)
    the move stays in its tangent plane (the normal row and column replaced by the identity in
    the plane's frame). A move longer than cap times the crossing's shortest segment is
    shortened to that (the local model holds for moves small against the segments). H (m, 3, 3)
    and lmin (m,) are scratch; delta (m, 3) receives the moves."""
    for c in range(m):
        lmin[c] = np.inf
        for i in range(3):
            for j in range(3):
                H[c, i, j] = 0.0
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            l = l_below[c, side]
            gap = l_jam - l
            fj = k_jam * gap if (gap > 0.0 and lo >= 0) else 0.0
            kj = k_jam if fj > 0.0 else 0.0
            wp = max(tension[c, side] - fj, floor) / l
            lmin[c] = min(lmin[c], l)
            if lo >= 0:
                lmin[lo] = min(lmin[lo], l)
            dx = d_below[c, side, 0] / l
            dy = d_below[c, side, 1] / l
            dz = d_below[c, side, 2] / l
            _add_block(H, c, wp, kj, dx, dy, dz)
            wr = reg * max(tension[c, side], floor) / l
            for i in range(3):
                H[c, i, i] += wr
            if lo >= 0:
                _add_block(H, lo, wp, kj, dx, dy, dz)
                for i in range(3):
                    H[lo, i, i] += wr
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        l = l_top[k]
        wp = max(f_top[k], floor) / l
        _add_block(H, c, wp, 0.0, d_top[k, 0] / l, d_top[k, 1] / l, d_top[k, 2] / l)
        for i in range(3):
            H[c, i, i] += reg * wp
    b = np.empty(3)
    for c in range(m):
        for i in range(3):
            b[i] = force[c, i]
        if active[c]:
            # P H P + n n^T with P = I - n n^T, right-hand side P force: the move in the plane
            n0, n1, n2 = plane[c, 3], plane[c, 4], plane[c, 5]
            nv = (n0, n1, n2)
            fn = b[0] * n0 + b[1] * n1 + b[2] * n2
            for i in range(3):
                b[i] -= fn * nv[i]
            Hn = np.empty(3)
            for i in range(3):
                Hn[i] = H[c, i, 0] * n0 + H[c, i, 1] * n1 + H[c, i, 2] * n2
            nHn = Hn[0] * n0 + Hn[1] * n1 + Hn[2] * n2
            for i in range(3):
                for j in range(3):
                    H[c, i, j] += -Hn[i] * nv[j] - nv[i] * Hn[j] + nHn * nv[i] * nv[j] \
                        + nv[i] * nv[j]
        # 3 x 3 solve by Cramer's rule (H symmetric positive definite)
        a00, a01, a02 = H[c, 0, 0], H[c, 0, 1], H[c, 0, 2]
        a11, a12, a22 = H[c, 1, 1], H[c, 1, 2], H[c, 2, 2]
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        det = a00 * c00 + a01 * c01 + a02 * c02
        if not det > 0.0:
            for i in range(3):
                delta[c, i] = 0.0
            continue
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        delta[c, 0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det
        delta[c, 1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) / det
        delta[c, 2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det
        size = math.sqrt(delta[c, 0] ** 2 + delta[c, 1] ** 2 + delta[c, 2] ** 2)
        if size > cap * lmin[c]:
            for i in range(3):
                delta[c, i] *= cap * lmin[c] / size
