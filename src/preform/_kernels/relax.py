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
def _jam_push(l, l_jam, k_jam, lo):
    """N, the jamming push ``k_jam (l_jam - l)`` of a segment between two crossings (``lo >= 0``)
    shorter than the width ``l_jam``; 0 otherwise (docs/jamming.md)."""
    gap = l_jam - l
    return k_jam * gap if (gap > 0.0 and lo >= 0) else 0.0


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
def _chain_residual(nc, chain, side, k, s0, l_below, s_old, g, f_top, F_top, EA, compression,
                    eps_f, kappa0, tension, work):
    """At the material work[:nc, 5] of one yarn: the residual dE/ds into work[:, 0], the
    tridiagonal Hessian (diagonal work[:, 1], coupling of i and i-1 work[:, 2]) and the segment
    tensions into tension. Returns (largest relative residual |dE/ds| / (|f_below| +
    |f_above|), squared 2-norm of the residual)."""
    prev = s0
    for i in range(nc):
        c = chain[i]
        q = work[i, 5] - prev
        l = l_below[c, side]
        ka = _ka(l, q, EA, compression)
        lq = l / q
        wq = 0.5 * ka * (1.0 - lq * lq)         # dW/dq
        wqq = ka * lq * lq / q
        x = work[i, 5] - s_old[c, side]
        r = math.sqrt(x * x + eps_f * eps_f)
        gg = g[c, side]
        work[i, 0] = wq + gg * x / r + kappa0 * x
        work[i, 1] = wqq + gg * eps_f * eps_f / (r * r * r) + kappa0
        work[i, 2] = -wqq
        if i > 0:
            work[i - 1, 0] -= wq
            work[i - 1, 1] += wqq
        tension[c, side] = ka * (lq - 1.0)
        prev = work[i, 5]
    work[nc - 1, 0] += F_top
    res = 0.0
    norm = 0.0
    for i in range(nc):
        fa = tension[chain[i + 1], side] if i + 1 < nc else f_top[k]
        ri = work[i, 0]
        norm += ri * ri
        e = abs(ri) / max(abs(tension[chain[i], side]) + abs(fa), 1e-300)
        if e > res:
            res = e
    return res, norm


@njit(cache=True)
def material_sweep(n_yarns, lowest, up, yarn, l_below, s, s_fell, s_old, g, f_top, EA,
                   compression, eps_f, kappa0, tol, max_newton, tension, chain, work, stats,
                   l_prev=None):
    """Per yarn, the material coordinates s of its crossings that make ``dE/ds = 0`` for the
    lengths l_below held (the friction law along the yarn, a convex chain problem): Newton on the
    tridiagonal system (Thomas algorithm), O(crossings of the yarn) per Newton step. A full
    step is taken where it lowers the residual's 2-norm; otherwise backtracking on the yarn's
    energy along the same direction (the energy is strictly convex in the material, so both
    reach its one minimum). In place on s; tension (m, 2) receives the segment tensions. chain
    (m,) int64 and work (m, 6) are scratch; stats (2,) int64 counts Newton steps and energy
    evaluations (added to). l_prev (m, 2) or None: the lengths s was solved for; given, Newton
    starts from the material with every segment's strain of s at the new lengths. Returns the
    largest relative residual |dE/ds| / (|f_below| + |f_above|) left."""
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
        if l_prev is None:
            for i in range(nc):
                work[i, 5] = s[chain[i], side]
        else:
            # start from the material that keeps every segment's strain (its tension) at the
            # new lengths: q <- q l / l_prev (a slipping yarn's material follows its lengths)
            prev = s0
            acc = s0
            for i in range(nc):
                c = chain[i]
                q = s[c, side] - prev
                prev = s[c, side]
                acc += q * l_below[c, side] / l_prev[c, side]
                work[i, 5] = acc
        res, norm = _chain_residual(nc, chain, side, k, s0, l_below, s_old, g, f_top, F_top, EA,
                                    compression, eps_f, kappa0, tension, work)
        steps = 0
        while res >= tol and steps < max_newton:
            steps += 1
            stats[0] += 1
            # Thomas algorithm: (diag, sub = work[i, 2] couples i and i-1, symmetric); the
            # direction into work[:, 4]
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
            slope = 0.0
            for i in range(nc):
                slope += work[i, 0] * work[i, 4]
            # the full step (the previous material kept in work[:, 3])
            feasible = True
            prev = s0
            for i in range(nc):
                work[i, 3] = work[i, 5]
                work[i, 5] += work[i, 4]
                if work[i, 5] - prev <= 0.0:
                    feasible = False
                prev = work[i, 5]
            if feasible:
                res1, norm1 = _chain_residual(nc, chain, side, k, s0, l_below, s_old, g, f_top,
                                              F_top, EA, compression, eps_f, kappa0, tension,
                                              work)
                if norm1 < norm:
                    res, norm = res1, norm1
                    continue
            # backtracking on the yarn energy from the previous material, measured from its top
            # material s_ref so that the payout F_top s (s runs to metres) does not swamp it
            for i in range(nc):
                work[i, 5] = work[i, 3]
            s_ref = work[nc - 1, 5]
            E0 = _yarn_energy(nc, chain, side, s_ref, s0, l_below, s_old, g, F_top, EA,
                              compression, eps_f, kappa0, work[:, 5])
            stats[1] += 1
            t = 1.0
            # a decrease below the energy's round-off cannot be judged by it: the feasible step
            # closest to the full one, which the residual then judges
            judged = -slope > 1e-12 * abs(E0)
            for _ in range(60):
                for i in range(nc):
                    work[i, 3] = work[i, 5] + t * work[i, 4]
                E1 = _yarn_energy(nc, chain, side, s_ref, s0, l_below, s_old, g, F_top, EA,
                                  compression, eps_f, kappa0, work[:, 3])
                stats[1] += 1
                if E1 < np.inf and (not judged or E1 <= E0 + 1e-4 * t * slope + 1e-13 * abs(E0)):
                    break
                t *= 0.5
            if E1 < np.inf:
                for i in range(nc):
                    work[i, 5] = work[i, 3]
            res, norm = _chain_residual(nc, chain, side, k, s0, l_below, s_old, g, f_top, F_top,
                                        EA, compression, eps_f, kappa0, tension, work)
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
            fj = _jam_push(l, l_jam, k_jam, lo)
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
def block_jacobi(lat, law, prob, seg, tension, reg, cap, force, plane, active, H, lmin, delta):
    """One block-Jacobi correction of the positions with each crossing's own 3 x 3 stiffness:
    delta_c = H_c^-1 force_c, H_c = sum over its segments of (f - f_jam) / l (I - d d^T) (floored
    at floor / l) + k_jam d d^T (jamming) + reg sum f / l I; at a crossing on the wall (active)
    the move stays in its tangent plane (the normal row and column replaced by the identity in
    the plane's frame). A move longer than cap times the crossing's shortest segment is
    shortened to that (the local model holds for moves small against the segments). H (m, 3, 3)
    and lmin (m,) are scratch; delta (m, 3) receives the moves."""
    m, n_yarns, low, highest = lat.m, lat.n_yarns, lat.low, lat.highest
    d_below, l_below, d_top, l_top = seg.d_below, seg.l_below, seg.d_top, seg.l_top
    f_top, l_jam, k_jam, floor = prob.f_top, law.l_jam, law.k_jam, law.floor
    for c in range(m):
        lmin[c] = np.inf
        for i in range(3):
            for j in range(3):
                H[c, i, j] = 0.0
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            l = l_below[c, side]
            fj = _jam_push(l, l_jam, k_jam, lo)
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


# -- the block preconditioner: each crossing's 3 x 3 stiffness, coupled along the lattice -------

@njit(cache=True)
def _segment_block(dx, dy, dz, w_perp, w_axial, w_iso, B):
    """B (3, 3) = w_perp (I - d d^T) + w_axial d d^T + w_iso I for the unit vector d."""
    B[0, 0] = w_perp * (1.0 - dx * dx) + w_axial * dx * dx + w_iso
    B[1, 1] = w_perp * (1.0 - dy * dy) + w_axial * dy * dy + w_iso
    B[2, 2] = w_perp * (1.0 - dz * dz) + w_axial * dz * dz + w_iso
    B[0, 1] = B[1, 0] = (w_axial - w_perp) * dx * dy
    B[0, 2] = B[2, 0] = (w_axial - w_perp) * dx * dz
    B[1, 2] = B[2, 1] = (w_axial - w_perp) * dy * dz


@njit(cache=True)
def _project_block(B, pa, na, pb, nb, out, scale):
    """out = scale P_a B P_b with P = I - n n^T where p (a flag) says the crossing rests on the
    wall, P = I otherwise."""
    for i in range(3):
        for j in range(3):
            out[i, j] = B[i, j]
    if pa:
        # out <- (I - na na^T) out
        for j in range(3):
            t = na[0] * out[0, j] + na[1] * out[1, j] + na[2] * out[2, j]
            for i in range(3):
                out[i, j] -= na[i] * t
    if pb:
        for i in range(3):
            t = out[i, 0] * nb[0] + out[i, 1] * nb[1] + out[i, 2] * nb[2]
            for j in range(3):
                out[i, j] -= t * nb[j]
    for i in range(3):
        for j in range(3):
            out[i, j] *= scale


@njit(cache=True)
def block_values(lat, law, prob, seg, tension, reg, plane, active, slots, vals, Dg):
    """Blocks of the lattice's geometric stiffness K (3m x 3m, 3 x 3 blocks per pair of
    crossings) into vals (nslots, 3, 3), the upper triangle of a fixed pattern in an elimination
    order: per segment ``B = w (I - d d^T) + k_j d d^T + reg max(f, floor) / l I`` with ``w =
    max(f - f_jam, floor) / l`` (the stiffness of a taut string across itself, none along it;
    jamming's along it; a small isotropic share keeps K definite), added to the diagonal blocks of
    both ends and subtracted from their coupling (top and fell segments: the crossing's diagonal
    only). A crossing resting on the wall (active) moves in its tangent plane: its rows and
    columns are projected, ``P K P + n n^T``. Slots: slot_diag (m,), slot_below (m, 2) the slot of
    the pair (c, low[c, side]) (-1 none), below_first (m, 2) True where that slot holds the
    block (low, c) (low first in the order), else (c, low). Dg (m, 3, 3) is scratch."""
    m, n_yarns, low, highest = lat.m, lat.n_yarns, lat.low, lat.highest
    d_below, l_below, d_top, l_top = seg.d_below, seg.l_below, seg.d_top, seg.l_top
    f_top, l_jam, k_jam, floor = prob.f_top, law.l_jam, law.k_jam, law.floor
    slot_diag, slot_below, below_first = slots.diag, slots.below, slots.below_first
    n = n_yarns // 2
    B = np.empty((3, 3))
    T = np.empty((3, 3))
    for i in range(vals.shape[0]):
        for a in range(3):
            for b in range(3):
                vals[i, a, b] = 0.0
    for c in range(m):
        for a in range(3):
            for b in range(3):
                Dg[c, a, b] = 0.0
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            l = l_below[c, side]
            f = tension[c, side]
            fj = _jam_push(l, l_jam, k_jam, lo)
            kj = k_jam if fj > 0.0 else 0.0
            _segment_block(d_below[c, side, 0] / l, d_below[c, side, 1] / l,
                           d_below[c, side, 2] / l, max(f - fj, floor) / l, kj,
                           reg * max(f, floor) / l, B)
            for a in range(3):
                for b in range(3):
                    Dg[c, a, b] += B[a, b]
            if lo >= 0:
                for a in range(3):
                    for b in range(3):
                        Dg[lo, a, b] += B[a, b]
                slot = slot_below[c, side]
                if below_first[c, side]:
                    _project_block(B, active[lo], plane[lo, 3:], active[c], plane[c, 3:], T, -1.0)
                else:
                    _project_block(B, active[c], plane[c, 3:], active[lo], plane[lo, 3:], T, -1.0)
                for a in range(3):
                    for b in range(3):
                        vals[slot, a, b] += T[a, b]
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        l = l_top[k]
        w = max(f_top[k], floor) / l
        _segment_block(d_top[k, 0] / l, d_top[k, 1] / l, d_top[k, 2] / l, w, 0.0, reg * w, B)
        for a in range(3):
            for b in range(3):
                Dg[c, a, b] += B[a, b]
    for c in range(m):
        for a in range(3):
            for b in range(3):
                B[a, b] = Dg[c, a, b]
        _project_block(B, active[c], plane[c, 3:], active[c], plane[c, 3:], T, 1.0)
        slot = slot_diag[c]
        for a in range(3):
            for b in range(3):
                vals[slot, a, b] += T[a, b]
        if active[c]:
            for a in range(3):
                for b in range(3):
                    vals[slot, a, b] += plane[c, 3 + a] * plane[c, 3 + b]


@njit(cache=True)
def block_pattern(m, low, perm, Ap, Ai, slot_diag, slot_below, below_first):
    """The pattern of the block preconditioners in the order perm (perm[i]: the crossing at
    position i): the upper triangle, CSC of blocks, of one block per crossing and one per pair
    (c, low[c, side]) (a pair given twice shares its block). Ap (m + 1,) the column starts,
    Ai (3m,) the rows, sorted within each column (the first Ap[m] used); slot_diag (m,) the
    slot of c's diagonal block, slot_below (m, 2) the slot of the pair (c, low[c, side]) (-1
    none), below_first (m, 2) True where low[c, side] comes first in the order (the slot holds
    the block (low, c)). Returns the number of slots."""
    pinv = np.empty(m, dtype=np.int64)
    for i in range(m):
        pinv[perm[i]] = i
    count = np.zeros(m + 1, dtype=np.int64)
    for c in range(m):
        count[pinv[c] + 1] += 1
        for side in range(2):
            lo = low[c, side]
            if lo >= 0:
                count[max(pinv[c], pinv[lo]) + 1] += 1
    for j in range(m):
        count[j + 1] += count[j]
    rows = np.empty(count[m], dtype=np.int64)
    owner = np.empty(count[m], dtype=np.int64)     # -1 - c: c's diagonal; 2 c + side: a pair
    fill = count[:m].copy()
    for c in range(m):
        pc = pinv[c]
        rows[fill[pc]] = pc
        owner[fill[pc]] = -1 - c
        fill[pc] += 1
        for side in range(2):
            lo = low[c, side]
            slot_below[c, side] = -1
            below_first[c, side] = False
            if lo >= 0:
                pl = pinv[lo]
                j = max(pc, pl)
                rows[fill[j]] = min(pc, pl)
                owner[fill[j]] = 2 * c + side
                fill[j] += 1
                below_first[c, side] = pl < pc
    nslots = 0
    Ap[0] = 0
    for j in range(m):
        a, b = count[j], count[j + 1]
        # insertion sort of the column's few entries by row
        for i in range(a + 1, b):
            r, o = rows[i], owner[i]
            k = i - 1
            while k >= a and rows[k] > r:
                rows[k + 1] = rows[k]
                owner[k + 1] = owner[k]
                k -= 1
            rows[k + 1] = r
            owner[k + 1] = o
        for i in range(a, b):
            if i == a or rows[i] != rows[i - 1]:
                Ai[nslots] = rows[i]
                nslots += 1
            o = owner[i]
            if o < 0:
                slot_diag[-1 - o] = nslots - 1
            else:
                slot_below[o // 2, o % 2] = nslots - 1
        Ap[j + 1] = nslots
    return nslots


@njit(cache=True)
def ldl_symbolic(n, Ap, Ai, work, Lnz, etree):
    """Elimination tree etree (n,) and column counts Lnz (n,) of the block LDL^T of a symmetric
    matrix given by the pattern of its upper triangle (CSC: Ap (n+1,), Ai, rows <= column; one
    entry per 3 x 3 block), QDLDL's ``QDLDL_etree`` (Davis 2005, section 4.1). work (n,) is
    scratch. Returns the number of blocks of L below the diagonal, -1 if an entry lies below
    the diagonal."""
    for i in range(n):
        work[i] = 0
        Lnz[i] = 0
        etree[i] = -1
    for j in range(n):
        work[j] = j
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            if i > j:
                return -1
            while work[i] != j:
                if etree[i] == -1:
                    etree[i] = j
                Lnz[i] += 1
                work[i] = j
                i = etree[i]
    total = 0
    for i in range(n):
        total += Lnz[i]
    return total


@njit(cache=True)
def _inverse3(A, out):
    """out = A^-1 of a symmetric 3 x 3 block; False if A is not positive definite (a leading
    minor or the determinant not positive)."""
    a00, a01, a02 = A[0, 0], A[0, 1], A[0, 2]
    a11, a12, a22 = A[1, 1], A[1, 2], A[2, 2]
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if not (a00 > 0.0 and a00 * a11 - a01 * a01 > 0.0 and det > 0.0):
        return False
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[0, 1] = out[1, 0] = c01 * inv
    out[0, 2] = out[2, 0] = c02 * inv
    out[1, 1] = (a00 * a22 - a02 * a02) * inv
    out[1, 2] = out[2, 1] = (a01 * a02 - a00 * a12) * inv
    out[2, 2] = (a00 * a11 - a01 * a01) * inv
    return True


@njit(cache=True, inline="always")
def _reach(i, k, etree, marker, elim, y_idx, nnz_y):
    """Append to y_idx[nnz_y:] the rows of row k's pattern reached from i up the elimination tree
    (unmarked rows below k, marked on the way), in topological order (QDLDL's ``QDLDL_factor``);
    returns the new count."""
    marker[i] = True
    elim[0] = i
    ne = 1
    j = etree[i]
    while j != -1 and j < k:
        if marker[j]:
            break
        marker[j] = True
        elim[ne] = j
        ne += 1
        j = etree[j]
    while ne:
        ne -= 1
        y_idx[nnz_y] = elim[ne]
        nnz_y += 1
    return nnz_y


@njit(cache=True, fastmath=True)
def ldl_numeric(n, Ap, Ai, Ax, Lp, Li, Lx, Dinv, etree, Lnz, marker, y_idx, elim, next_space,
                y, D):
    """Block LDL^T factorisation A = L D L^T of a symmetric positive definite matrix of 3 x 3
    blocks: QDLDL's up-looking ``QDLDL_factor`` with every scalar a block (for each row k of L,
    its pattern from the elimination tree, then a sparse triangular solve: y_j -= L_ji y_i,
    L_ki = y_i^T D_i^-1, D_k -= L_ki y_i). A: upper triangle, CSC of blocks (Ap, Ai, Ax (nnz,
    3, 3), Ax[p] the block (Ai[p], column)); out: Lp (n+1,), Li, Lx (nnz_L, 3, 3) the strictly
    lower blocks by column, Dinv (n, 3, 3) the inverses of the diagonal blocks of D. etree, Lnz
    from ``ldl_symbolic``; marker (n,) bool, y_idx, elim, next_space (n,) int64, y (n, 3, 3),
    D (3, 3) scratch. Returns False if a pivot block is not positive definite."""
    T = np.empty((3, 3))
    Lp[0] = 0
    for i in range(n):
        marker[i] = False
        for a in range(3):
            for b in range(3):
                y[i, a, b] = 0.0
        Lp[i + 1] = Lp[i] + Lnz[i]
        next_space[i] = Lp[i]
    for k in range(n):
        nnz_y = 0
        for a in range(3):
            for b in range(3):
                D[a, b] = 0.0
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            if i == k:
                for a in range(3):
                    for b in range(3):
                        D[a, b] = Ax[p, a, b]
                continue
            for a in range(3):
                for b in range(3):
                    y[i, a, b] = Ax[p, a, b]
            if not marker[i]:
                nnz_y = _reach(i, k, etree, marker, elim, y_idx, nnz_y)
        for t in range(nnz_y - 1, -1, -1):
            ci = y_idx[t]
            end = next_space[ci]
            y00, y01, y02 = y[ci, 0, 0], y[ci, 0, 1], y[ci, 0, 2]
            y10, y11, y12 = y[ci, 1, 0], y[ci, 1, 1], y[ci, 1, 2]
            y20, y21, y22 = y[ci, 2, 0], y[ci, 2, 1], y[ci, 2, 2]
            for q in range(Lp[ci], end):
                r = Li[q]
                # y_r -= L_{r, ci} y_ci
                for a in range(3):
                    l0, l1, l2 = Lx[q, a, 0], Lx[q, a, 1], Lx[q, a, 2]
                    y[r, a, 0] -= l0 * y00 + l1 * y10 + l2 * y20
                    y[r, a, 1] -= l0 * y01 + l1 * y11 + l2 * y21
                    y[r, a, 2] -= l0 * y02 + l1 * y12 + l2 * y22
            Li[end] = k
            # L_{k, ci} = y_ci^T Dinv_ci ; D_k -= L_{k, ci} y_ci
            for a in range(3):
                for b in range(3):
                    Lx[end, a, b] = (y[ci, 0, a] * Dinv[ci, 0, b] + y[ci, 1, a] * Dinv[ci, 1, b]
                                     + y[ci, 2, a] * Dinv[ci, 2, b])
            for a in range(3):
                l0, l1, l2 = Lx[end, a, 0], Lx[end, a, 1], Lx[end, a, 2]
                D[a, 0] -= l0 * y00 + l1 * y10 + l2 * y20
                D[a, 1] -= l0 * y01 + l1 * y11 + l2 * y21
                D[a, 2] -= l0 * y02 + l1 * y12 + l2 * y22
            next_space[ci] = end + 1
            for a in range(3):
                for b in range(3):
                    y[ci, a, b] = 0.0
            marker[ci] = False
        # symmetrise the pivot against round-off before inverting it
        for a in range(3):
            for b in range(a + 1, 3):
                D[a, b] = D[b, a] = 0.5 * (D[a, b] + D[b, a])
        if not _inverse3(D, T):
            return False
        for a in range(3):
            for b in range(3):
                Dinv[k, a, b] = T[a, b]
    return True


@njit(cache=True, fastmath=True)
def ldl_solve(n, Lp, Li, Lx, Dinv, perm, rhs, out, x):
    """out (n, 3) = A^-1 rhs (n, 3) for the factor of ``ldl_numeric``, A in the order perm
    (perm[i]: the crossing at position i): L z = P rhs, then D^-1 in the same pass, then L^T
    y = D^-1 z, each row written back to out as it is final; x (n, 3) is scratch."""
    for i in range(n):
        for a in range(3):
            x[i, a] = rhs[perm[i], a]
    for i in range(n):
        # x_i is final here: L's column i updates the rows below, then D_i^-1 scales x_i (the
        # forward solve and the diagonal in one pass)
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        for q in range(Lp[i], Lp[i + 1]):
            r = Li[q]
            for a in range(3):
                x[r, a] -= Lx[q, a, 0] * x0 + Lx[q, a, 1] * x1 + Lx[q, a, 2] * x2
        for a in range(3):
            x[i, a] = Dinv[i, a, 0] * x0 + Dinv[i, a, 1] * x1 + Dinv[i, a, 2] * x2
    for i in range(n - 1, -1, -1):
        for q in range(Lp[i], Lp[i + 1]):
            r = Li[q]
            for a in range(3):
                x[i, a] -= Lx[q, 0, a] * x[r, 0] + Lx[q, 1, a] * x[r, 1] + Lx[q, 2, a] * x[r, 2]
        c = perm[i]
        for a in range(3):
            out[c, a] = x[i, a]


@njit(cache=True)
def _neighbour_ranks(c, low, up, owner, sid, rank, n):
    """(lowest, highest) rank among the lattice neighbours (``low``/``up``) of crossing c that
    belong to the set ``sid`` (``owner``); (n, -1) if none."""
    mn = n
    mx = -1
    for s in range(2):
        for q in range(2):
            nb = low[c, s] if q == 0 else up[c, s]
            if nb >= 0 and owner[nb] == sid:
                r = rank[nb]
                if r < mn:
                    mn = r
                if r > mx:
                    mx = r
    return mn, mx


@njit(cache=True)
def _best_cut(a, b, order, low, up, owner, sid, rank, lo_r, hi_r, cnt1, cnt2, lo_t, hi_t):
    """The smallest vertex separator of the set ``sid`` (sorted in order[a:b]) among the cuts
    at ranks t in [lo_t, hi_t] (first part: ranks < t): variant 0, the first part's crossings
    with a neighbour at rank >= t; variant 1, the second part's with one at rank < t. A
    crossing at rank i with neighbours at ranks mn..mx is in variant 0's separator for t in
    (i, mx] and in variant 1's for t in (mn, i], so both counts for every t come from one
    pass and a running sum (cnt1, cnt2 (n + 2,) scratch). rank, lo_r, hi_r (m,) receive each
    crossing's rank and its neighbours' lowest and highest. Returns (size, t, variant); ties go
    to the cut nearest the middle."""
    n = b - a
    for i in range(a, b):
        rank[order[i]] = i - a
    for t in range(n + 2):
        cnt1[t] = 0
        cnt2[t] = 0
    for i in range(n):
        c = order[a + i]
        mn, mx = _neighbour_ranks(c, low, up, owner, sid, rank, n)
        lo_r[c] = mn
        hi_r[c] = mx
        if mx > i:
            cnt1[i + 1] += 1
            cnt1[mx + 1] -= 1
        if mn < i:
            cnt2[mn + 1] += 1
            cnt2[i + 1] -= 1
    best = n + 1
    bt = n // 2
    bv = 0
    s1 = 0
    s2 = 0
    for t in range(hi_t + 1):
        s1 += cnt1[t]
        s2 += cnt2[t]
        if t < lo_t:
            continue
        for var in range(2):
            size = s1 if var == 0 else s2
            if size < best or (size == best and abs(2 * t - n) < abs(2 * bt - n)):
                best = size
                bt = t
                bv = var
    return best, bt, bv


@njit(cache=True)
def _partition(a, b, order, side, n_l, n_r, buf):
    """Stable partition of order[a:b] into the first part's crossings off the separator (side
    0, n_l of them), the second part's (2, n_r), then the separator's (1)."""
    k0, k2, k1 = 0, n_l, n_l + n_r
    for i in range(a, b):
        c = order[i]
        g = side[c]
        if g == 0:
            buf[k0] = c
            k0 += 1
        elif g == 2:
            buf[k2] = c
            k2 += 1
        else:
            buf[k1] = c
            k1 += 1
    for i in range(b - a):
        order[a + i] = buf[i]


@njit(cache=True)
def band_dissection(m, low, up, u, v, leaf, window, perm):
    """Fill-reducing order of a lattice of crossings on a band around an axis, by geometric
    nested dissection (George 1973): a set of crossings, sorted by u (the angle around the
    axis) and by v (the height along it), is cut at the rank t in each sort, within ``window``
    of the set's size from its middle, that gives the smallest vertex separator, the crossings
    of one part with a lattice neighbour (``low``/``up``, (m, 2)) in the other, either part's
    (``_best_cut``); the order is the first part's, the second's, then the separator's, each
    part dissected in turn. Sets up to ``leaf`` crossings keep their order. On the whole band
    a cut in u makes two arcs at two seams, whose crossings are the first separator. The
    crossings are sorted by u and by v once and every cut partitions both sorts stably, so
    each set's crossings stay sorted: O(m) a level, O(m log m) in all. perm (m,) receives the
    order (perm[i]: the crossing at position i)."""
    owner = np.zeros(m, dtype=np.int64)
    side = np.zeros(m, dtype=np.int8)
    buf = np.empty(m, dtype=np.int64)
    rank = np.empty((2, m), dtype=np.int64)
    lo_r = np.empty((2, m), dtype=np.int64)
    hi_r = np.empty((2, m), dtype=np.int64)
    cnt1 = np.empty(m + 2, dtype=np.int64)
    cnt2 = np.empty(m + 2, dtype=np.int64)
    by_u = np.argsort(u)
    by_v = np.argsort(v)
    stack = np.empty((2 * m + 2, 3), dtype=np.int64)
    stack[0, 0] = 0
    stack[0, 1] = m
    stack[0, 2] = 0
    top = 1
    next_id = 1
    while top:
        top -= 1
        a, b, sid = stack[top, 0], stack[top, 1], stack[top, 2]
        n = b - a
        if n <= leaf:
            continue
        lo_t = max(1, int(math.ceil((0.5 - window) * n)))
        hi_t = min(n - 1, int(math.floor((0.5 + window) * n)))
        if hi_t < lo_t:
            lo_t = hi_t = n // 2
        s_v, t_v, var_v = _best_cut(a, b, by_v, low, up, owner, sid, rank[0], lo_r[0],
                                    hi_r[0], cnt1, cnt2, lo_t, hi_t)
        s_u, t_u, var_u = _best_cut(a, b, by_u, low, up, owner, sid, rank[1], lo_r[1],
                                    hi_r[1], cnt1, cnt2, lo_t, hi_t)
        if s_v <= s_u:
            d, t, var, n_s = 0, t_v, var_v, s_v
        else:
            d, t, var, n_s = 1, t_u, var_u, s_u
        id_l, id_r = next_id, next_id + 1
        next_id += 2
        for i in range(a, b):
            c = by_u[i]
            if rank[d, c] < t:
                side[c] = 1 if (var == 0 and hi_r[d, c] >= t) else 0
            else:
                side[c] = 1 if (var == 1 and lo_r[d, c] < t) else 2
            owner[c] = id_l if side[c] == 0 else (id_r if side[c] == 2 else -1)
        n_l = t - n_s if var == 0 else t
        _partition(a, b, by_u, side, n_l, n - n_l - n_s, buf)
        _partition(a, b, by_v, side, n_l, n - n_l - n_s, buf)
        stack[top, 0] = a
        stack[top, 1] = a + n_l
        stack[top, 2] = id_l
        stack[top + 1, 0] = a + n_l
        stack[top + 1, 1] = b - n_s
        stack[top + 1, 2] = id_r
        top += 2
    for i in range(m):
        perm[i] = by_u[i]


@njit(cache=True)
def tangent_part(m, force, plane, active, out):
    """out (m, 3) = force, less its normal part at the crossings resting on the wall (active):
    the right-hand side of the block update, whose resting crossings move in their planes."""
    for c in range(m):
        fx, fy, fz = force[c, 0], force[c, 1], force[c, 2]
        if active[c]:
            fn = fx * plane[c, 3] + fy * plane[c, 4] + fz * plane[c, 5]
            fx -= fn * plane[c, 3]
            fy -= fn * plane[c, 4]
            fz -= fn * plane[c, 5]
        out[c, 0] = fx
        out[c, 1] = fy
        out[c, 2] = fz


@njit(cache=True)
def cap_moves(m, low, l_below, cap, lmin, delta):
    """Scale the update delta (m, 3) down, all of it, so that no crossing moves further than
    cap times its shortest segment between crossings or to the fell point (lmin (m,) scratch);
    returns the factor (1: none)."""
    for c in range(m):
        lmin[c] = np.inf
    for c in range(m):
        for side in range(2):
            l = l_below[c, side]
            lmin[c] = min(lmin[c], l)
            lo = low[c, side]
            if lo >= 0:
                lmin[lo] = min(lmin[lo], l)
    scale = 1.0
    for c in range(m):
        size = math.sqrt(delta[c, 0] ** 2 + delta[c, 1] ** 2 + delta[c, 2] ** 2)
        if size * scale > cap * lmin[c]:
            scale = cap * lmin[c] / size
    if scale < 1.0:
        for c in range(m):
            for i in range(3):
                delta[c, i] *= scale
    return scale


@njit(cache=True)
def anderson_gram(n, x, gx, x_prev, r_prev, DX, DR, G, k, j, have_prev, b):
    """One pass of Anderson mixing (``interaction/relax._Anderson``) over x, gx (n,), r = gx - x:
    with a previous iterate (have_prev) the new differences x - x_prev, r - r_prev into column j
    of DX, DR (n, depth) and row and column j of the Gram matrix G (depth, depth) over the k
    columns held (j among them); b (depth,) receives DR[:, :k]^T r; x_prev, r_prev become x, r."""
    col = np.zeros(max(k, 1))
    for i in range(k):
        b[i] = 0.0
    for e in range(n):
        r = gx[e] - x[e]
        if have_prev:
            DX[e, j] = x[e] - x_prev[e]
            dr = r - r_prev[e]
            DR[e, j] = dr
            for i in range(k):
                col[i] += DR[e, i] * dr
        for i in range(k):
            b[i] += DR[e, i] * r
        x_prev[e] = x[e]
        r_prev[e] = r
    if have_prev:
        for i in range(k):
            G[j, i] = col[i]
            G[i, j] = col[i]


@njit(cache=True)
def anderson_combine(n, gx, DX, DR, gamma, k, out):
    """out (n,) = gx - (DX[:, :k] + DR[:, :k]) gamma."""
    for e in range(n):
        v = gx[e]
        for i in range(k):
            v -= gamma[i] * (DX[e, i] + DR[e, i])
        out[e] = v


@njit(cache=True)
def sweep(lat, law, prob, pos, s, seg, tension, chain, work, stats, l_prev, predict, keep, tol,
          max_newton):
    """One material sweep at the positions pos in one call: the segments
    (``segment_vectors``), then every yarn's material and tensions (``material_sweep``,
    started from the strains of the lengths l_prev where ``predict``); with ``keep`` the new
    lengths go into l_prev for the next sweep's start. Returns the sweep's largest relative
    material residual. ``lat``, ``law``, ``prob``, ``seg``: ``_kernels.zone``'s Lattice, Law,
    Problem and Segments (written)."""
    m, n_yarns, yarn, low, up = lat.m, lat.n_yarns, lat.yarn, lat.low, lat.up
    lowest, highest, normal, over = lat.lowest, lat.highest, lat.normal, lat.over
    fell, top, s_fell, s_old = prob.fell, prob.top, prob.s_fell, prob.s_old
    g, f_top = prob.g, prob.f_top
    h, eps2, eps2_top = law.h, law.eps2, law.eps2_top
    EA, compression, eps_f, kappa0 = law.EA, law.compression, law.eps_f, law.kappa0
    d_below, l_below, d_top, l_top = seg.d_below, seg.l_below, seg.d_top, seg.l_top
    segment_vectors(m, n_yarns, yarn, pos, normal, over, low, highest, fell, top, h, eps2,
                    eps2_top, d_below, l_below, d_top, l_top)
    if predict:
        worst = material_sweep(n_yarns, lowest, up, yarn, l_below, s, s_fell, s_old, g, f_top,
                               EA, compression, eps_f, kappa0, tol, max_newton, tension, chain,
                               work, stats, l_prev)
    else:
        worst = material_sweep(n_yarns, lowest, up, yarn, l_below, s, s_fell, s_old, g, f_top,
                               EA, compression, eps_f, kappa0, tol, max_newton, tension, chain,
                               work, stats, None)
    if keep:
        for c in range(m):
            l_prev[c, 0] = l_below[c, 0]
            l_prev[c, 1] = l_below[c, 1]
    return worst


@njit(cache=True)
def forces_residual(lat, law, prob, seg, tension, plane, active, release, out):
    """``forces`` then ``wall_residual`` in one call, into ``out`` (``_kernels.zone.Forces``;
    its ``res`` the imbalance per crossing); returns the largest relative imbalance (0 without
    crossings)."""
    forces(lat.m, lat.n_yarns, lat.yarn, lat.low, lat.highest, seg.d_below, seg.l_below,
           seg.d_top, seg.l_top, tension, prob.f_top, law.l_jam, law.k_jam, law.floor, out.force,
           out.w_below, out.w_top, out.total, out.W)
    return wall_residual(lat.m, out.force, out.total, plane, active, out.W, release, out.res)


@njit(cache=True)
def block_step(m, force, plane, active, low, l_below, cap, Lp, Li, Lx, Dinv, perm, rhs, x,
               lmin, delta):
    """The block update in one call: delta = K^-1 P force (``tangent_part``, ``ldl_solve``;
    rhs, x (m, 3) scratch), scaled down to ``cap`` times each crossing's shortest segment
    (``cap_moves``, lmin (m,) scratch). Returns the scale."""
    tangent_part(m, force, plane, active, rhs)
    ldl_solve(m, Lp, Li, Lx, Dinv, perm, rhs, delta, x)
    return cap_moves(m, low, l_below, cap, lmin, delta)


@njit(cache=True)
def anderson_step(n, x, gx, x_prev, r_prev, DX, DR, G, k, j, have_prev, b, M, gamma, out):
    """One Anderson mixing step (``interaction/relax._Anderson``) in one call: the pass of
    ``anderson_gram`` (k: the differences held after this one, j its column), then gamma =
    (G_k + reg I)^-1 b_k with reg = 1e-12 trace(G_k) + 1e-300 by Gaussian elimination with
    partial pivoting (M (depth, depth), gamma (depth,) scratch), then out = gx - (DX + DR)
    gamma (``anderson_combine``). Returns 1 (out holds the mix), 0 (no difference held yet:
    gx is the mix) or -1 (a zero pivot: the caller clears the history; gx is the mix)."""
    anderson_gram(n, x, gx, x_prev, r_prev, DX, DR, G, k, j, have_prev, b)
    if k == 0:
        return 0
    tr = 0.0
    for i in range(k):
        tr += G[i, i]
    reg = 1e-12 * tr + 1e-300
    for i in range(k):
        for c in range(k):
            M[i, c] = G[i, c]
        M[i, i] += reg
        gamma[i] = b[i]
    for col in range(k):
        piv = col
        big = abs(M[col, col])
        for i in range(col + 1, k):
            if abs(M[i, col]) > big:
                big = abs(M[i, col])
                piv = i
        if big == 0.0:
            return -1
        if piv != col:
            for c in range(k):
                M[col, c], M[piv, c] = M[piv, c], M[col, c]
            gamma[col], gamma[piv] = gamma[piv], gamma[col]
        for i in range(col + 1, k):
            f = M[i, col] / M[col, col]
            if f != 0.0:
                for c in range(col, k):
                    M[i, c] -= f * M[col, c]
                gamma[i] -= f * gamma[col]
    for i in range(k - 1, -1, -1):
        v = gamma[i]
        for c in range(i + 1, k):
            v -= M[i, c] * gamma[c]
        gamma[i] = v / M[i, i]
    anderson_combine(n, gx, DX, DR, gamma, k, out)
    return 1


@njit(cache=True)
def _plane_distance(x, y, z, plane, c):
    """Signed distance (m) of the point (x, y, z) in front of crossing c's tangent plane (as
    ``wall_distance``)."""
    return ((x - plane[c, 0]) * plane[c, 3] + (y - plane[c, 1]) * plane[c, 4]
            + (z - plane[c, 2]) * plane[c, 5])


@njit(cache=True)
def block_wall(m, low, up, w_below, force, pos, delta, W, plane, active, release, wall_force,
               moved, new):
    """The wall's active set after a block update delta (m, 3), which moved the resting
    crossings (active) in their planes: each resting crossing's own balance (``wall_update``
    with the diagonal W, from the update with the resting crossings held) decides: one whose
    point lies within ``release`` (m) of its plane keeps the block move, one further in front
    takes the local move and leaves. Then new (m, 3) = pos + delta; a free crossing more than
    ``release`` behind its plane is projected onto it and joins, a resting one more than
    ``release`` in front leaves (active updated in place). wall_force (m,) the wall's push
    (``wall_update``); moved (m, 3) scratch. Returns True if the set changed."""
    for c in range(m):
        for i in range(3):
            moved[c, i] = delta[c, i]
            if active[c]:
                delta[c, i] = 0.0
    wall_update(m, low, up, w_below, force, pos, delta, W, plane, active, release, wall_force)
    for c in range(m):
        if active[c]:
            d = _plane_distance(pos[c, 0] + delta[c, 0], pos[c, 1] + delta[c, 1],
                                pos[c, 2] + delta[c, 2], plane, c)
            if d <= release:
                for i in range(3):
                    delta[c, i] = moved[c, i]
    changed = False
    for c in range(m):
        for i in range(3):
            new[c, i] = pos[c, i] + delta[c, i]
        d = _plane_distance(new[c, 0], new[c, 1], new[c, 2], plane, c)
        if not active[c] and d < -release:
            for i in range(3):
                new[c, i] -= d * plane[c, 3 + i]
            active[c] = True
            changed = True
        elif active[c] and d > release:
            active[c] = False
            changed = True
    return changed


@njit(cache=True)
def wall_project(m, pos, plane, active, release):
    """Project onto its tangent plane every crossing behind it that rests on the wall (active)
    and every free one more than ``release`` (m) behind (a combination of iterates on the
    planes stays on them; Anderson's weights may be negative); the free ones join the active
    set (in place). Returns True if one joined."""
    joined = False
    for c in range(m):
        d = _plane_distance(pos[c, 0], pos[c, 1], pos[c, 2], plane, c)
        if (d < 0.0 and active[c]) or d < -release:
            for i in range(3):
                pos[c, i] -= d * plane[c, 3 + i]
            if not active[c]:
                active[c] = True
                joined = True
    return joined


@njit(cache=True)
def jam_changed(m, low, l_below, l_jam, factored, new_only, jammed):
    """jammed (m, 2) = the segments between two crossings shorter than l_jam (where the
    jamming stiffness enters the block preconditioner); returns whether that set differs from
    ``factored`` (the set at the last factorisation), or with ``new_only`` whether a segment
    jammed that was not."""
    changed = False
    for c in range(m):
        for side in range(2):
            j = l_below[c, side] < l_jam and low[c, side] >= 0
            jammed[c, side] = j
            f = factored[c, side]
            if j != f and (j or not new_only):
                changed = True
    return changed


@njit(cache=True)
def same_flags(m, a, b):
    """True if the flags a, b (m,) are equal."""
    for c in range(m):
        if a[c] != b[c]:
            return False
    return True


# -- the full preconditioner: positions and materials, 5 unknowns a crossing --------------------

@njit(cache=True)
def _projected(A, pa, na, pb, nb, out):
    """out (4, 4) = the segment block A (4, 4: a yarn point's 3 coordinates and the material)
    with its position rows projected by P_a and columns by P_b (``_project_block``; P = I off
    the wall)."""
    for i in range(4):
        for j in range(4):
            out[i, j] = A[i, j]
    if pa:
        for j in range(4):
            t = na[0] * out[0, j] + na[1] * out[1, j] + na[2] * out[2, j]
            for i in range(3):
                out[i, j] -= na[i] * t
    if pb:
        for i in range(4):
            t = out[i, 0] * nb[0] + out[i, 1] * nb[1] + out[i, 2] * nb[2]
            for j in range(3):
                out[i, j] -= t * nb[j]


@njit(cache=True)
def full_values(lat, law, prob, seg, tension, s, reg, plane, active, slots, vals, Dg):
    """Blocks of the Hessian of the zone's energy in the positions and materials together, 5 x 5
    per pair of crossings (unknowns of a crossing: its position, then its material on the warp
    and on the weft), into vals (nslots, 5, 5) at the slots of ``block_values``' pattern (the
    same pairs (c, low[c, side]) couple positions and materials). Per segment (c, side), in its
    length l and material length q with ``W = k (l - q)^2 / (2 q)``: ``W_ll = k / q`` (plus
    jamming's k_jam), ``W_lq = -k l / q^2``, ``W_qq = k l^2 / q^3``; the yarn points see
    ``W_ll u u^T + w (I - u u^T) + reg max(f, floor) / l I`` with the geometric ``w = max(f -
    f_jam, floor) / l`` as in ``block_values``, the coupling to the material ``W_lq u``, added
    to both ends' diagonal blocks and subtracted from their coupling (the fell point and
    ``s_fell`` are fixed). The friction term ``g sqrt(x^2 + eps_f^2) + kappa0 x^2 / 2`` adds
    ``g eps_f^2 / r^3 + kappa0`` to its material's diagonal; the top segment adds its geometric
    block (its tension f_top is held: no axial term). A crossing resting on the wall (active)
    moves in its tangent plane: its position rows and columns projected, ``P H P + n n^T``.
    Dg (m, 5, 5) is scratch. ``lat``, ``law``, ``prob``, ``seg``, ``slots``: ``_kernels.zone``'s
    Lattice, Law, Problem, Segments and BlockSlots."""
    m, n_yarns, yarn, low, highest = lat.m, lat.n_yarns, lat.yarn, lat.low, lat.highest
    d_below, l_below, d_top, l_top = seg.d_below, seg.l_below, seg.d_top, seg.l_top
    s_fell, s_old, g, f_top = prob.s_fell, prob.s_old, prob.g, prob.f_top
    EA, compression, eps_f, kappa0 = law.EA, law.compression, law.eps_f, law.kappa0
    l_jam, k_jam, floor = law.l_jam, law.k_jam, law.floor
    slot_diag, slot_below, below_first = slots.diag, slots.below, slots.below_first
    A = np.empty((4, 4))
    T = np.empty((4, 4))
    B = np.empty((3, 3))
    for i in range(vals.shape[0]):
        for a in range(5):
            for b in range(5):
                vals[i, a, b] = 0.0
    for c in range(m):
        for a in range(5):
            for b in range(5):
                Dg[c, a, b] = 0.0
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            l = l_below[c, side]
            f = tension[c, side]
            below = s[lo, side] if lo >= 0 else s_fell[yarn[c, side]]
            q = s[c, side] - below
            ka = EA if l >= q else compression * EA
            fj = _jam_push(l, l_jam, k_jam, lo)
            kj = k_jam if fj > 0.0 else 0.0
            u0, u1, u2 = d_below[c, side, 0] / l, d_below[c, side, 1] / l, d_below[c, side, 2] / l
            _segment_block(u0, u1, u2, max(f - fj, floor) / l, ka / q + kj,
                           reg * max(f, floor) / l, B)
            for a in range(3):
                for b in range(3):
                    A[a, b] = B[a, b]
            c_lq = -ka * l / (q * q)
            A[0, 3] = A[3, 0] = c_lq * u0
            A[1, 3] = A[3, 1] = c_lq * u1
            A[2, 3] = A[3, 2] = c_lq * u2
            A[3, 3] = ka * l * l / (q * q * q)
            ms = 3 + side
            _projected(A, active[c], plane[c, 3:], active[c], plane[c, 3:], T)
            _add_local(Dg[c], T, ms, ms, 1.0)
            if lo >= 0:
                _projected(A, active[lo], plane[lo, 3:], active[lo], plane[lo, 3:], T)
                _add_local(Dg[lo], T, ms, ms, 1.0)
                slot = slot_below[c, side]
                if below_first[c, side]:
                    _projected(A, active[lo], plane[lo, 3:], active[c], plane[c, 3:], T)
                else:
                    _projected(A, active[c], plane[c, 3:], active[lo], plane[lo, 3:], T)
                _add_local(vals[slot], T, ms, ms, -1.0)
            x = s[c, side] - s_old[c, side]
            r = math.sqrt(x * x + eps_f * eps_f)
            Dg[c, ms, ms] += g[c, side] * eps_f * eps_f / (r * r * r) + kappa0
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        l = l_top[k]
        w = max(f_top[k], floor) / l
        _segment_block(d_top[k, 0] / l, d_top[k, 1] / l, d_top[k, 2] / l, w, 0.0, reg * w, B)
        for a in range(3):
            for b in range(3):
                A[a, b] = B[a, b]
            A[a, 3] = A[3, a] = 0.0
        A[3, 3] = 0.0
        _projected(A, active[c], plane[c, 3:], active[c], plane[c, 3:], T)
        _add_local(Dg[c], T, 3, 3, 1.0)
    for c in range(m):
        slot = slot_diag[c]
        for a in range(5):
            for b in range(5):
                vals[slot, a, b] += Dg[c, a, b]
        if active[c]:
            for a in range(3):
                for b in range(3):
                    vals[slot, a, b] += plane[c, 3 + a] * plane[c, 3 + b]


@njit(cache=True)
def _add_local(out, T, ra, rb, scale):
    """out (5, 5) += scale T (4, 4), T's index 3 (the material) at ra in the rows and rb in the
    columns of out, 0-2 (the position) at 0-2."""
    for i in range(4):
        oi = i if i < 3 else ra
        for j in range(4):
            oj = j if j < 3 else rb
            out[oi, oj] += scale * T[i, j]


@njit(cache=True)
def _inverse_spd(A, nb, out, L):
    """out = A^-1 of a symmetric nb x nb block by its Cholesky factor (L (nb, nb) scratch);
    False if A is not positive definite."""
    for j in range(nb):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        L[j, j] = d
        for i in range(j + 1, nb):
            v = A[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / d
    # out = L^-T L^-1, column by column of the identity
    for col in range(nb):
        for i in range(nb):
            v = 1.0 if i == col else 0.0
            for k in range(i):
                v -= L[i, k] * out[k, col]
            out[i, col] = v / L[i, i]
        for i in range(nb - 1, -1, -1):
            v = out[i, col]
            for k in range(i + 1, nb):
                v -= L[k, i] * out[k, col]
            out[i, col] = v / L[i, i]
    return True


#: the block size of the full preconditioner (positions and the two materials)
_NB5 = 5


@njit(cache=True, fastmath=True)
def ldl_numeric5(n, Ap, Ai, Ax, Lp, Li, Lx, Dinv, etree, Lnz, marker, y_idx, elim, next_space,
                  y, D):
    """``ldl_numeric`` for 5 x 5 blocks (the ``"full"`` preconditioner): the same up-looking
    block LDL^T, the block products as loops of a fixed length (the compiler unrolls them),
    the pivots inverted by their Cholesky factors. Returns False if a pivot block is not
    positive definite."""
    nb = _NB5
    T = np.empty((nb, nb))
    Lc = np.empty((nb, nb))
    Lp[0] = 0
    for i in range(n):
        marker[i] = False
        for a in range(nb):
            for b in range(nb):
                y[i, a, b] = 0.0
        Lp[i + 1] = Lp[i] + Lnz[i]
        next_space[i] = Lp[i]
    for k in range(n):
        nnz_y = 0
        for a in range(nb):
            for b in range(nb):
                D[a, b] = 0.0
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            if i == k:
                for a in range(nb):
                    for b in range(nb):
                        D[a, b] = Ax[p, a, b]
                continue
            for a in range(nb):
                for b in range(nb):
                    y[i, a, b] = Ax[p, a, b]
            if not marker[i]:
                nnz_y = _reach(i, k, etree, marker, elim, y_idx, nnz_y)
        for t in range(nnz_y - 1, -1, -1):
            ci = y_idx[t]
            end = next_space[ci]
            # y_ci in locals (written out as in ``ldl_numeric``: kept in registers)
            y00, y01, y02 = y[ci, 0, 0], y[ci, 0, 1], y[ci, 0, 2]
            y03, y04 = y[ci, 0, 3], y[ci, 0, 4]
            y10, y11, y12 = y[ci, 1, 0], y[ci, 1, 1], y[ci, 1, 2]
            y13, y14 = y[ci, 1, 3], y[ci, 1, 4]
            y20, y21, y22 = y[ci, 2, 0], y[ci, 2, 1], y[ci, 2, 2]
            y23, y24 = y[ci, 2, 3], y[ci, 2, 4]
            y30, y31, y32 = y[ci, 3, 0], y[ci, 3, 1], y[ci, 3, 2]
            y33, y34 = y[ci, 3, 3], y[ci, 3, 4]
            y40, y41, y42 = y[ci, 4, 0], y[ci, 4, 1], y[ci, 4, 2]
            y43, y44 = y[ci, 4, 3], y[ci, 4, 4]
            for q in range(Lp[ci], end):
                r = Li[q]
                # y_r -= L_{r, ci} y_ci
                for a in range(5):
                    l0, l1, l2 = Lx[q, a, 0], Lx[q, a, 1], Lx[q, a, 2]
                    l3, l4 = Lx[q, a, 3], Lx[q, a, 4]
                    y[r, a, 0] -= l0 * y00 + l1 * y10 + l2 * y20 + l3 * y30 + l4 * y40
                    y[r, a, 1] -= l0 * y01 + l1 * y11 + l2 * y21 + l3 * y31 + l4 * y41
                    y[r, a, 2] -= l0 * y02 + l1 * y12 + l2 * y22 + l3 * y32 + l4 * y42
                    y[r, a, 3] -= l0 * y03 + l1 * y13 + l2 * y23 + l3 * y33 + l4 * y43
                    y[r, a, 4] -= l0 * y04 + l1 * y14 + l2 * y24 + l3 * y34 + l4 * y44
            Li[end] = k
            # L_{k, ci} = y_ci^T Dinv_ci ; D_k -= L_{k, ci} y_ci
            for a in range(5):
                for b in range(5):
                    Lx[end, a, b] = (y[ci, 0, a] * Dinv[ci, 0, b] + y[ci, 1, a] * Dinv[ci, 1, b]
                                     + y[ci, 2, a] * Dinv[ci, 2, b] + y[ci, 3, a] * Dinv[ci, 3, b]
                                     + y[ci, 4, a] * Dinv[ci, 4, b])
            for a in range(5):
                l0, l1, l2 = Lx[end, a, 0], Lx[end, a, 1], Lx[end, a, 2]
                l3, l4 = Lx[end, a, 3], Lx[end, a, 4]
                D[a, 0] -= l0 * y00 + l1 * y10 + l2 * y20 + l3 * y30 + l4 * y40
                D[a, 1] -= l0 * y01 + l1 * y11 + l2 * y21 + l3 * y31 + l4 * y41
                D[a, 2] -= l0 * y02 + l1 * y12 + l2 * y22 + l3 * y32 + l4 * y42
                D[a, 3] -= l0 * y03 + l1 * y13 + l2 * y23 + l3 * y33 + l4 * y43
                D[a, 4] -= l0 * y04 + l1 * y14 + l2 * y24 + l3 * y34 + l4 * y44
            next_space[ci] = end + 1
            for a in range(nb):
                for b in range(nb):
                    y[ci, a, b] = 0.0
            marker[ci] = False
        for a in range(nb):
            for b in range(a + 1, nb):
                D[a, b] = D[b, a] = 0.5 * (D[a, b] + D[b, a])
        if not _inverse_spd(D, nb, T, Lc):
            return False
        for a in range(nb):
            for b in range(nb):
                Dinv[k, a, b] = T[a, b]
    return True


@njit(cache=True, fastmath=True)
def ldl_solve5(n, Lp, Li, Lx, Dinv, perm, rhs, out, x):
    """``ldl_solve`` for 5 x 5 blocks: out (n, 5) = A^-1 rhs (n, 5); x (n, 5) scratch."""
    nb = _NB5
    tmp = np.empty(nb)
    for i in range(n):
        for a in range(nb):
            x[i, a] = rhs[perm[i], a]
    for i in range(n):
        for q in range(Lp[i], Lp[i + 1]):
            r = Li[q]
            for a in range(nb):
                v = 0.0
                for b in range(nb):
                    v += Lx[q, a, b] * x[i, b]
                x[r, a] -= v
    for i in range(n):
        for a in range(nb):
            tmp[a] = x[i, a]
        for a in range(nb):
            v = 0.0
            for b in range(nb):
                v += Dinv[i, a, b] * tmp[b]
            x[i, a] = v
    for i in range(n - 1, -1, -1):
        for q in range(Lp[i], Lp[i + 1]):
            r = Li[q]
            for a in range(nb):
                v = 0.0
                for b in range(nb):
                    v += Lx[q, b, a] * x[r, b]
                x[i, a] -= v
    for i in range(n):
        for a in range(nb):
            out[perm[i], a] = x[i, a]


@njit(cache=True)
def reduced_energy(lat, law, prob, seg, s, s_ref):
    """The step energy E (``_kernels.frontal.energy``) of the lengths ``l_below`` (m, 2),
    ``l_top`` (2n,) (``segment_vectors``) and materials ``s`` (m, 2), without its wall term (the
    relaxation keeps crossings outside their planes exactly): per segment the stretch ``k (l -
    q)^2 / (2 q)`` and, between two crossings shorter than the width, the jamming ``k_jam (l_jam
    - l)^2 / 2``; per crossing and yarn the friction ``g (sqrt(x^2 + eps_f^2) - eps_f) + kappa0
    x^2 / 2`` of its slide x = s - s_old; per yarn the held top tension's ``f_top l_top +
    F_top (s_top - s_ref)`` with ``F_top = f_top + f_top^2 / (2 EA)`` (the payout, measured from
    the top material ``s_ref`` (2n,) so that its metres do not swamp the round-off). With the
    materials swept for the lengths (``material_sweep``) it is the reduced energy of the
    positions alone, whose negative gradient is ``forces``' net force. inf where a material
    length is not positive. The lengths are ``seg``'s."""
    m, n_yarns, yarn, low, highest = lat.m, lat.n_yarns, lat.yarn, lat.low, lat.highest
    l_below, l_top = seg.l_below, seg.l_top
    s_fell, s_old, g, f_top = prob.s_fell, prob.s_old, prob.g, prob.f_top
    EA, compression, eps_f, kappa0 = law.EA, law.compression, law.eps_f, law.kappa0
    l_jam, k_jam = law.l_jam, law.k_jam
    n = n_yarns // 2
    E = 0.0
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            below = s[lo, side] if lo >= 0 else s_fell[yarn[c, side]]
            q = s[c, side] - below
            if q <= 0.0:
                return np.inf
            l = l_below[c, side]
            E += 0.5 * _ka(l, q, EA, compression) * (l - q) * (l - q) / q
            if lo >= 0 and l < l_jam:
                E += 0.5 * k_jam * (l_jam - l) * (l_jam - l)
            x = s[c, side] - s_old[c, side]
            E += g[c, side] * (math.sqrt(x * x + eps_f * eps_f) - eps_f) + 0.5 * kappa0 * x * x
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        side = 0 if k < n else 1
        F_top = f_top[k] + f_top[k] * f_top[k] / (2.0 * EA)
        E += f_top[k] * l_top[k] + F_top * (s[c, side] - s_ref[k])
    return E
