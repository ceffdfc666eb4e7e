"""Numba kernels of the force-density relaxation of a convergence-zone step
(``preform/interaction/relax.py`` says what is solved and why; docs/theory.md §4).

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
``preform/interaction/settings.py`` (``EnergySettings``, ``FrontalSettings``). The slow twins are in ``tests/support/naive_relax.py``.

Here: the segments, the yarns' material sweep, the forces and residual, the wall's active set,
the friction bounds, the reduced energy and Anderson mixing. The preconditioners' matrices are
in ``_kernels/stiffness.py``, their block LDL^T and orders in ``_kernels/ldl.py``.
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
    current geometry and tensions into g (m, 2) (docs/theory.md §4), and Psi / (f_int + f_ext),
    Psi = |f_int - f_ext| cos(delta/2) - mu (f_int + f_ext) sin(delta/2), into psi (m, 2); mu
    (m,): each crossing's coefficient (``interaction.contact.crossing_friction``).
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
            g[c, side] = mu[c] * (fi + fe) * sh / max(ch, 1e-300)
            psi[c, side] = (abs(fi - fe) * ch - mu[c] * (fi + fe) * sh) / max(fi + fe, 1e-300)


# -- the block preconditioner: each crossing's 3 x 3 stiffness, coupled along the lattice -------

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
    """One pass of Anderson mixing (``interaction/preconditioners.Anderson``) over x, gx (n,),
    r = gx - x: with a previous iterate (have_prev) the new differences x - x_prev, r - r_prev into column j
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
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, s_fell, s_old, g, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor = law
    d_below, l_below, d_top, l_top = seg
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
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor = law
    fell, top, s_fell, s_old, g, f_top = prob
    d_below, l_below, d_top, l_top = seg
    force, w_below, w_top, total, W, res = out
    forces(m, n_yarns, yarn, low, highest, d_below, l_below, d_top, l_top, tension, f_top,
           l_jam, k_jam, floor, force, w_below, w_top, total, W)
    return wall_residual(m, force, total, plane, active, W, release, res)


@njit(cache=True)
def anderson_step(n, x, gx, x_prev, r_prev, DX, DR, G, k, j, have_prev, b, M, gamma, out):
    """One Anderson mixing step (``interaction/preconditioners.Anderson``) in one call: the pass of
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
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, s_fell, s_old, g, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor = law
    d_below, l_below, d_top, l_top = seg
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
