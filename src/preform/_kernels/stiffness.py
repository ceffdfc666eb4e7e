"""Numba kernels of the relaxation's preconditioners (``preform/interaction/relax.py``): the values
of the scalar force-density Laplacian, the block-Jacobi corrections, the lattice's geometric
stiffness in 3 x 3 blocks (``"block"``) and the Hessian in the positions and materials in 5 x 5
blocks (``"full"``), and the block update. Layout and equations as in ``_kernels/relax.py``; the
slow twins are in ``tests/support/naive_relax.py`` and ``tests/validation/test_relax_ring.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .ldl import ldl_solve3
from .relax import _jam_push, cap_moves, tangent_part


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
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, s_fell, s_old, g, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor = law
    d_below, l_below, d_top, l_top = seg
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
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, s_fell, s_old, g, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor = law
    d_below, l_below, d_top, l_top = seg
    slot_diag, slot_below, below_first = slots
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
def block_step(m, force, plane, active, low, l_below, cap, Lp, Li, Lx, Dinv, perm, rhs, x,
               lmin, delta):
    """The block update in one call: delta = K^-1 P force (``tangent_part``, ``ldl_solve3``;
    rhs, x (m, 3) scratch), scaled down to ``cap`` times each crossing's shortest segment
    (``cap_moves``, lmin (m,) scratch). Returns the scale."""
    tangent_part(m, force, plane, active, rhs)
    ldl_solve3(m, Lp, Li, Lx, Dinv, perm, rhs, delta, x)
    return cap_moves(m, low, l_below, cap, lmin, delta)


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
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, s_fell, s_old, g, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor = law
    d_below, l_below, d_top, l_top = seg
    slot_diag, slot_below, below_first = slots
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
