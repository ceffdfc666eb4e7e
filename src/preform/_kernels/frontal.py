"""Numba kernels of the frontal solver of the interaction model (paper §2.4; DESIGN.md §3.3).

Arrays and scalars only; the layout of the crossing arrays is documented in
``preform/interaction/zone_state.py`` (creation order, ``low``/``up`` links, ``over``, ``normal``);
the reading of the paper implemented here is in ``preform/interaction/frontal.py``. The slow NumPy
twins live in ``tests/naive_frontal.py``.

Geometry. The centerline point of yarn ``side`` (0 warp, 1 weft) at crossing ``c`` is
``P = C + s h N`` with ``s = over[c]`` for the warp and ``-over[c]`` for the weft, ``h`` half the
yarn thickness and ``N = normal[c]`` the contact normal held fixed during a solve (paper eq. 16, one
normal per crossing). Segments: below every crossing on both yarns (to the lower crossing's yarn
point or the fell point) with tension ``tension[c, side]``, and the top segment of every yarn (its
highest crossing to its top point: ring point or spool point) with tension ``f_top[k]``.

Two kernels carry the physics:

* ``capstan_sweep`` (force sweep, supply side -> fell points, newest crossing first): the tension
  below a crossing from the tension above it and the yarn's deflection ``delta`` there, by the
  discrete Capstan bound of DESIGN.md §3.3 (slipping: on the bound on the side of ``slide``) or
  the stored stick ratio clipped into the cone (sticking);
* ``assemble`` (position step): with the tensions fixed, the crossings in force balance are the
  stationary point of ``E(C) = sum_segments f |P_a - P_b|``, a convex function of the positions;
  its gradient at a crossing is minus the sum of the four yarn forces on it, so ``grad = 0`` is pair
  balance (paper eqs. 3-4). ``assemble`` returns ``E``, the gradient and the Hessian as COO
  triplets (3x3 blocks ``f / l (I - d d^T / l^2)``). The length is smoothed,
  ``l = sqrt(|d|^2 + eps2)``, so a crossing just created at the supply point (upper segment of
  length 0) keeps a regular, positive definite Hessian; ``eps2`` is tiny (see ``frontal.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import contact as CK


@njit(cache=True)
def yarn_point(pos, normal, over, c, side, h, out):
    """Centerline point (m) of yarn ``side`` at crossing ``c`` into out (3,)."""
    s = over[c] * h if side == 0 else -over[c] * h
    out[0] = pos[c, 0] + s * normal[c, 0]
    out[1] = pos[c, 1] + s * normal[c, 1]
    out[2] = pos[c, 2] + s * normal[c, 2]


@njit(cache=True)
def _end_point(pos, normal, over, nb, side, k, ends, h, out):
    """Yarn point at neighbour crossing nb, or ends[k] (fell or top point) when nb < 0."""
    if nb >= 0:
        yarn_point(pos, normal, over, nb, side, h, out)
    else:
        out[0] = ends[k, 0]
        out[1] = ends[k, 1]
        out[2] = ends[k, 2]


@njit(cache=True)
def radial_normals(m, pos, normal):
    """normal[c] = outward radial unit vector of pos[c] (away from the machine axis), c < m."""
    for c in range(m):
        r = math.sqrt(pos[c, 0] ** 2 + pos[c, 1] ** 2)
        if r < 1e-300:
            normal[c, 0] = 1.0
            normal[c, 1] = 0.0
        else:
            normal[c, 0] = pos[c, 0] / r
            normal[c, 1] = pos[c, 1] / r
        normal[c, 2] = 0.0


@njit(cache=True)
def deflection_dot(p, a, b):
    """u_int . u_ext (= -cos delta) of a yarn at p with lower point a and upper point b (3,);
    -1 (straight) where a segment has no length."""
    ax = a[0] - p[0]
    ay = a[1] - p[1]
    az = a[2] - p[2]
    bx = b[0] - p[0]
    by = b[1] - p[1]
    bz = b[2] - p[2]
    la = math.sqrt(ax * ax + ay * ay + az * az)
    lb = math.sqrt(bx * bx + by * by + bz * bz)
    if la < 1e-12 or lb < 1e-12:
        return -1.0
    d = (ax * bx + ay * by + az * bz) / (la * lb)
    return min(1.0, max(-1.0, d))


@njit(cache=True)
def cone(f_ext, d, mu):
    """(lowest, highest) internal tension (N) the friction cone allows for external tension f_ext
    and u_int . u_ext = d (DESIGN.md §3.3, discrete Capstan); highest = inf when self-locking."""
    lo = CK.slip_tension(f_ext, d, mu, -1)
    hi = CK.slip_tension(f_ext, d, mu, 1)
    if lo < 0.0:
        lo = 0.0
    if hi < 0.0:
        hi = np.inf
    return lo, hi


@njit(cache=True)
def capstan_sweep(m, yarn, pos, normal, over, low, up, fell, top, f_top, h, mu, slide, ratio,
                  tension):
    """Tensions below every crossing (N) into tension (m, 2), newest crossing first.

    slide (m, 2) int8: +1 / -1 slipping (internal tension above / below the external one, on the
    bound), 0 sticking: internal = ratio (m, 2) * external, clipped into the cone.
    """
    p = np.empty(3)
    a = np.empty(3)
    b = np.empty(3)
    for c in range(m - 1, -1, -1):
        for side in range(2):
            k = yarn[c, side]
            u = up[c, side]
            fe = tension[u, side] if u >= 0 else f_top[k]
            if mu == 0.0:
                tension[c, side] = fe
                continue
            yarn_point(pos, normal, over, c, side, h, p)
            _end_point(pos, normal, over, low[c, side], side, k, fell, h, a)
            _end_point(pos, normal, over, u, side, k, top, h, b)
            d = deflection_dot(p, a, b)
            lo, hi = cone(fe, d, mu)
            s = slide[c, side]
            if s > 0:
                f = hi if hi < np.inf else fe
            elif s < 0:
                f = lo
            else:
                f = min(hi, max(lo, ratio[c, side] * fe))
            tension[c, side] = f


@njit(cache=True)
def _segment(E, grad, rows, cols, vals, nnz, ia, ib, pa, pb, f, eps2):
    """Add f * l(pa - pb) to E, its gradient and Hessian blocks (ia, ib: crossing or -1 fixed)."""
    dx = pa[0] - pb[0]
    dy = pa[1] - pb[1]
    dz = pa[2] - pb[2]
    l2 = dx * dx + dy * dy + dz * dz + eps2
    l = math.sqrt(l2)
    E += f * l
    gx = f * dx / l
    gy = f * dy / l
    gz = f * dz / l
    if ia >= 0:
        grad[ia, 0] += gx
        grad[ia, 1] += gy
        grad[ia, 2] += gz
    if ib >= 0:
        grad[ib, 0] -= gx
        grad[ib, 1] -= gy
        grad[ib, 2] -= gz
    w = f / l
    d0 = dx / l
    d1 = dy / l
    d2 = dz / l
    for i in range(3):
        di = d0 if i == 0 else (d1 if i == 1 else d2)
        for j in range(3):
            dj = d0 if j == 0 else (d1 if j == 1 else d2)
            kij = w * ((1.0 if i == j else 0.0) - di * dj)
            if ia >= 0:
                rows[nnz] = 3 * ia + i
                cols[nnz] = 3 * ia + j
                vals[nnz] = kij
                nnz += 1
            if ib >= 0:
                rows[nnz] = 3 * ib + i
                cols[nnz] = 3 * ib + j
                vals[nnz] = kij
                nnz += 1
            if ia >= 0 and ib >= 0:
                rows[nnz] = 3 * ia + i
                cols[nnz] = 3 * ib + j
                vals[nnz] = -kij
                nnz += 1
                rows[nnz] = 3 * ib + i
                cols[nnz] = 3 * ia + j
                vals[nnz] = -kij
                nnz += 1
    return E, nnz


@njit(cache=True)
def assemble(m, n_yarns, yarn, pos, normal, over, low, highest, fell, top, f_top, tension, h,
             eps2, plane, k_wall, grad, rows, cols, vals):
    """Energy E (N m), gradient grad (m, 3) (N) and Hessian triplets (N/m) of the network with the
    tensions fixed (module docstring). rows, cols, vals need 36 (2 m + n_yarns) entries.
    plane (m, 6): point and outward unit normal of the mandrel's tangent plane near each crossing
    (machine frame); a crossing behind it is pushed out by the convex penalty k_wall s^2 / 2
    (s < 0 its signed distance, k_wall N/m). rows, cols, vals need one more block per crossing.
    Returns (E, nnz)."""
    n = n_yarns // 2
    pa = np.empty(3)
    pb = np.empty(3)
    E = 0.0
    nnz = 0
    for c in range(m):
        grad[c, 0] = 0.0
        grad[c, 1] = 0.0
        grad[c, 2] = 0.0
    for c in range(m):
        for side in range(2):
            k = yarn[c, side]
            yarn_point(pos, normal, over, c, side, h, pa)
            lo = low[c, side]
            _end_point(pos, normal, over, lo, side, k, fell, h, pb)
            E, nnz = _segment(E, grad, rows, cols, vals, nnz, c, lo, pa, pb, tension[c, side], eps2)
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        side = 0 if k < n else 1
        yarn_point(pos, normal, over, c, side, h, pa)
        pb[0] = top[k, 0]
        pb[1] = top[k, 1]
        pb[2] = top[k, 2]
        E, nnz = _segment(E, grad, rows, cols, vals, nnz, c, -1, pa, pb, f_top[k], eps2)
    for c in range(m):
        sd = _wall_distance(pos, plane, c)
        if sd < 0.0:
            E += 0.5 * k_wall * sd * sd
            for i in range(3):
                grad[c, i] += k_wall * sd * plane[c, 3 + i]
                for j in range(3):
                    rows[nnz] = 3 * c + i
                    cols[nnz] = 3 * c + j
                    vals[nnz] = k_wall * plane[c, 3 + i] * plane[c, 3 + j]
                    nnz += 1
    return E, nnz


@njit(cache=True)
def _wall_distance(pos, plane, c):
    return ((pos[c, 0] - plane[c, 0]) * plane[c, 3] + (pos[c, 1] - plane[c, 1]) * plane[c, 4]
            + (pos[c, 2] - plane[c, 2]) * plane[c, 5])


@njit(cache=True)
def energy(m, n_yarns, yarn, pos, normal, over, low, highest, fell, top, f_top, tension, h, eps2,
           plane, k_wall):
    """E = sum f l over the segments (N m), as in ``assemble``, without derivatives."""
    n = n_yarns // 2
    pa = np.empty(3)
    pb = np.empty(3)
    E = 0.0
    for c in range(m):
        for side in range(2):
            yarn_point(pos, normal, over, c, side, h, pa)
            _end_point(pos, normal, over, low[c, side], side, yarn[c, side], fell, h, pb)
            E += tension[c, side] * math.sqrt((pa[0] - pb[0]) ** 2 + (pa[1] - pb[1]) ** 2
                                              + (pa[2] - pb[2]) ** 2 + eps2)
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        yarn_point(pos, normal, over, c, 0 if k < n else 1, h, pa)
        E += f_top[k] * math.sqrt((pa[0] - top[k, 0]) ** 2 + (pa[1] - top[k, 1]) ** 2
                                  + (pa[2] - top[k, 2]) ** 2 + eps2)
    for c in range(m):
        sd = _wall_distance(pos, plane, c)
        if sd < 0.0:
            E += 0.5 * k_wall * sd * sd
    return E


@njit(cache=True)
def balance_error(m, yarn, up, grad, tension, f_top):
    """Largest relative force imbalance over the crossings: |grad_c| / (sum of the 4 tensions)."""
    worst = 0.0
    for c in range(m):
        s = tension[c, 0] + tension[c, 1]
        for side in range(2):
            u = up[c, side]
            s += tension[u, side] if u >= 0 else f_top[yarn[c, side]]
        g = math.sqrt(grad[c, 0] ** 2 + grad[c, 1] ** 2 + grad[c, 2] ** 2)
        e = g / max(s, 1e-300)
        if e > worst:
            worst = e
    return worst


@njit(cache=True)
def below_lengths(m, yarn, pos, normal, over, low, fell, h, out):
    """Yarn length (m) from the fell point up to every crossing, per side, into out (m, 2);
    oldest crossing first (the lower neighbour is done before)."""
    p = np.empty(3)
    q = np.empty(3)
    for c in range(m):
        for side in range(2):
            lo = low[c, side]
            yarn_point(pos, normal, over, c, side, h, p)
            _end_point(pos, normal, over, lo, side, yarn[c, side], fell, h, q)
            d = math.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2)
            out[c, side] = d + (out[lo, side] if lo >= 0 else 0.0)


@njit(cache=True)
def top_tensions(n_yarns, highest, pos, normal, over, fell, top, spool, h, f_spool, mu_r,
                 has_ring, f_top):
    """Tension (N) of every yarn's top segment into f_top (2n,): the spool tension, or behind a
    guide ring the Capstan law f = f_spool exp(mu_r eta) (paper eq. 9), eta the yarn's deflection
    at the ring point (the yarn is drawn from the spool towards the mandrel)."""
    n = n_yarns // 2
    p = np.empty(3)
    for k in range(n_yarns):
        if not has_ring:
            f_top[k] = f_spool
            continue
        c = highest[k]
        _end_point(pos, normal, over, c, 0 if k < n else 1, k, fell, h, p)
        ax = p[0] - top[k, 0]
        ay = p[1] - top[k, 1]
        az = p[2] - top[k, 2]
        bx = spool[k, 0] - top[k, 0]
        by = spool[k, 1] - top[k, 1]
        bz = spool[k, 2] - top[k, 2]
        na = math.sqrt(ax * ax + ay * ay + az * az)
        nb = math.sqrt(bx * bx + by * by + bz * bz)
        cb = (ax * bx + ay * by + az * bz) / max(na * nb, 1e-300)
        eta = math.pi - math.acos(min(1.0, max(-1.0, cb)))
        f_top[k] = f_spool * math.exp(mu_r * eta)


@njit(cache=True)
def _block_jacobi(n, indptr, indices, data, binv):
    """Inverses of the 3x3 diagonal blocks of a CSR matrix (3n x 3n) into binv (n, 3, 3)."""
    a = np.empty((3, 3))
    for b in range(n):
        for i in range(3):
            for j in range(3):
                a[i, j] = 0.0
            r = 3 * b + i
            for p in range(indptr[r], indptr[r + 1]):
                col = indices[p]
                if col // 3 == b:
                    a[i, col - 3 * b] += data[p]
        c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
        c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
        c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
        det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
        if abs(det) < 1e-300:
            det = 1e-300
        binv[b, 0, 0] = c00 / det
        binv[b, 1, 0] = c01 / det
        binv[b, 2, 0] = c02 / det
        binv[b, 0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) / det
        binv[b, 1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) / det
        binv[b, 2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) / det
        binv[b, 0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) / det
        binv[b, 1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) / det
        binv[b, 2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) / det


@njit(cache=True)
def _matvec(indptr, indices, data, x, out):
    for r in range(len(indptr) - 1):
        s = 0.0
        for p in range(indptr[r], indptr[r + 1]):
            s += data[p] * x[indices[p]]
        out[r] = s


@njit(cache=True)
def _precondition(binv, r, z):
    for b in range(binv.shape[0]):
        for i in range(3):
            z[3 * b + i] = (binv[b, i, 0] * r[3 * b] + binv[b, i, 1] * r[3 * b + 1]
                            + binv[b, i, 2] * r[3 * b + 2])


@njit(cache=True)
def pcg(indptr, indices, data, rhs, rtol, max_iter, x):
    """Conjugate gradients with 3x3 block-Jacobi preconditioning for the symmetric positive
    definite CSR matrix (3n x 3n): x (3n,) <- solution of A x = rhs to |r| <= rtol |rhs|.
    Returns the iterations."""
    nd = rhs.shape[0]
    binv = np.empty((nd // 3, 3, 3))
    _block_jacobi(nd // 3, indptr, indices, data, binv)
    r = rhs.copy()
    for i in range(nd):
        x[i] = 0.0
    z = np.empty(nd)
    q = np.empty(nd)
    _precondition(binv, r, z)
    p = z.copy()
    rz = 0.0
    bn = 0.0
    for i in range(nd):
        rz += r[i] * z[i]
        bn += rhs[i] * rhs[i]
    stop = rtol * rtol * bn
    for it in range(max_iter):
        rr = 0.0
        for i in range(nd):
            rr += r[i] * r[i]
        if rr <= stop:
            return it
        _matvec(indptr, indices, data, p, q)
        pq = 0.0
        for i in range(nd):
            pq += p[i] * q[i]
        if pq <= 0.0:
            return it
        alpha = rz / pq
        for i in range(nd):
            x[i] += alpha * p[i]
            r[i] -= alpha * q[i]
        _precondition(binv, r, z)
        rz_new = 0.0
        for i in range(nd):
            rz_new += r[i] * z[i]
        beta = rz_new / rz
        rz = rz_new
        for i in range(nd):
            p[i] = z[i] + beta * p[i]
    return max_iter
