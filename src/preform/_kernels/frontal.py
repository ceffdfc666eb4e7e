"""Numba kernels of the frontal solver of the interaction model (paper §2.4; docs/theory.md §4).

Arrays and scalars only; the layout of the crossing arrays is documented in
``preform/interaction/zone_state.py`` (creation order, ``low``/``up`` links, ``over``, ``normal``,
material coordinates ``material``); the reading of the paper implemented here is in
``preform/interaction/frontal.py``; the numerical constants arrive as arguments from
``preform/interaction/settings.py``. The slow NumPy twins live in ``tests/support/naive_frontal.py``.

Geometry. The centerline point of yarn ``side`` (0 warp, 1 weft) at crossing ``c`` is
``P = C + o h N`` with ``o = over[c]`` for the warp and ``-over[c]`` for the weft, ``h`` half the
yarn thickness and ``N = normal[c]`` the contact normal held fixed during a solve (paper eq. 16, one
normal per crossing). Segments: below every crossing on both yarns (to the lower crossing's yarn
point or the fell point), and the top segment of every yarn (its highest crossing to its top point:
ring point or spool point).

Unknowns: 5 per crossing, ``x[5 c + 0..2] = C`` (m, machine frame) and ``x[5 c + 3 + side] =
material[c, side]`` (written ``u`` below), the material coordinate (m of yarn) of yarn ``side``
at the crossing. The function ``assemble`` returns (value, gradient, Hessian as COO triplets) of

    E = sum_below W(l, q) + sum_yarns (F(f_top) u_highest + f_top l_top)
        + sum_(c, side) friction(u - centre)
        + sum_c k_wall min(0, dist_c)^2 / 2
        + sum_(segments between crossings) k_jam max(0, l_jam - l)^2 / 2

* ``W(l, q) = k (l - q)^2 / (2 q)``: a segment of material length ``q = u_upper - u_lower``
  (or ``- material_fell``) stretched to length ``l``, tension ``f = dW/dl = k (l - q) / q`` with
  ``k = EA`` (a stiff tow) or ``compression EA`` when slack; convex in ``(l, q)``, its Hessian
  ``k / q v v^T``, ``v = (1, -l/q)``;
* ``F(f_top) u_highest + f_top l_top``: the spool pays yarn out at the tension ``f_top``
  (``F = material_force``, the force ``-dW/dq`` of a segment at that tension), with ``l_top``
  smoothed by ``eps2_top``;
* friction at the crossing (``_friction``): ``bound |u - centre|`` with ``|x|`` smoothed to
  ``sqrt(x^2 + eps^2) - eps``, ``bound`` the friction bound held fixed in a solve. ``dE/du = 0``
  reads ``F(f_below) - F(f_above) = bound x / sqrt(x^2 + eps^2)``: a yarn that slides through the
  crossing (``|x| >> eps``) sits on the bound, one that does not stays inside it (stick);
* the wall keeps crossings in front of the mandrel's tangent planes (``plane``: a point and the
  outward unit normal per crossing, ``dist_c`` the signed distance to it);
* jamming pushes two crossings of a yarn apart when closer than ``l_jam`` along it.

All terms are convex in the unknowns except the geometric part of a segment in compression
(``l < q``, a state Newton may pass through; at a solution every yarn is in tension): its
geometric stiffness in the Hessian is floored at ``geometric_floor`` (the gradient stays exact),
so the Newton matrix is positive definite and every Newton direction descends.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def yarn_point(pos, normal, over, c, side, h, out):
    """Centerline point (m) of yarn ``side`` at crossing ``c`` into out (3,)."""
    d = over[c] * h if side == 0 else -over[c] * h
    out[0] = pos[c, 0] + d * normal[c, 0]
    out[1] = pos[c, 1] + d * normal[c, 1]
    out[2] = pos[c, 2] + d * normal[c, 2]


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
def half_angles(d):
    """cos(delta/2), sin(delta/2) of a yarn's deflection delta from d = u_int . u_ext = -cos(delta)."""
    c = math.sqrt(max(0.5 * (1.0 - d), 0.0))
    s = math.sqrt(max(0.5 * (1.0 + d), 0.0))
    return c, s


@njit(cache=True)
def _lower(k, c, side, lo, pos, normal, over, fell, material, material_fell, h, out):
    """Yarn point below crossing c on yarn k (lower crossing lo, or the fell point) into out;
    returns the lower material coordinate."""
    _end_point(pos, normal, over, lo, side, k, fell, h, out)
    return material[lo, side] if lo >= 0 else material_fell[k]


@njit(cache=True)
def _sub(pa, pb, eps2):
    dx = pa[0] - pb[0]
    dy = pa[1] - pb[1]
    dz = pa[2] - pb[2]
    return dx, dy, dz, math.sqrt(dx * dx + dy * dy + dz * dz + eps2)


@njit(cache=True)
def segment_tension(l, q, EA, compression):
    """Tension (N) of a segment of length l (m) and material length q (m); negative, with the
    small stiffness ``compression EA``, when it is shorter than its material (a yarn that cannot
    push: slack, kept just stiff enough for Newton; see ``assemble``)."""
    return axial(l, q, EA, compression) * (l - q) / q


@njit(cache=True)
def axial(l, q, EA, compression):
    """Axial stiffness (N) of a segment: EA stretched, compression x EA compressed."""
    return EA if l >= q else compression * EA


@njit(cache=True)
def material_force(f, EA):
    """-dW/dq of a segment at tension f (N): the force that moves material along the yarn,
    f + f^2 / (2 EA). The spool's pull on the top material is written with it, so that across a
    frictionless crossing the tensions are equal exactly."""
    return f + f * f / (2.0 * EA)


@njit(cache=True)
def _put(rows, cols, vals, nnz, r, c, v):
    rows[nnz] = r
    cols[nnz] = c
    vals[nnz] = v
    return nnz + 1


@njit(cache=True)
def assemble(lat, law, prob, pos, material, plane, k_wall, grad, rows, cols, vals):
    """E (N m), gradient grad (m, 5) and Hessian triplets of the step's energy (module
    docstring) at the crossings' positions ``pos`` and materials ``material``. Returns (E, nnz);
    E = inf when a segment's material length is not positive (the line search then backs off).
    rows, cols, vals need ``triplet_capacity(m, n_yarns)``. ``lat``, ``law``, ``prob``:
    ``_kernels.zone``'s Lattice, Law (``floor``: the geometric floor) and Problem (``s_old``:
    the friction centres, ``g``: the bounds); plane (m, 6) the wall's tangent planes, k_wall
    its penalty (N/m)."""
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, material_fell, centre, bound, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, geometric_floor = law
    n = n_yarns // 2
    pa = np.empty(3)
    pb = np.empty(3)
    idx = np.empty(8, dtype=np.int64)
    w = np.empty(8)
    E = 0.0
    nnz = 0
    for c in range(m):
        for i in range(5):
            grad[c, i] = 0.0
    for c in range(m):
        for side in range(2):
            k = yarn[c, side]
            lo = low[c, side]
            yarn_point(pos, normal, over, c, side, h, pa)
            sb = _lower(k, c, side, lo, pos, normal, over, fell, material, material_fell, h, pb)
            q = material[c, side] - sb
            if q <= 0.0:
                return np.inf, 0
            dx, dy, dz, l = _sub(pa, pb, eps2)
            dx /= l
            dy /= l
            dz /= l
            f = segment_tension(l, q, EA, compression)
            # jamming: two crossings of a yarn push apart when closer than l_jam along it (the
            # crossing yarns lie side by side) with the force fj = k_jam (l_jam - l); its
            # Hessian k_jam d d^T joins the axial block below. Geometric stiffness of the net
            # force, (f - fj) / l (I - d d^T) at both ends, floored (Hessian only; the gradient
            # stays exact)
            gap = l_jam - l
            kj = k_jam if (gap > 0.0 and lo >= 0) else 0.0
            nnz = _geometric(rows, cols, vals, nnz, c, lo, max(f - kj * gap, geometric_floor) / l,
                             dx, dy, dz)
            if lo >= 0:
                E += 0.5 * kj * gap * gap
                grad[c, 0] -= kj * gap * dx
                grad[c, 1] -= kj * gap * dy
                grad[c, 2] -= kj * gap * dz
                grad[lo, 0] += kj * gap * dx
                grad[lo, 1] += kj * gap * dy
                grad[lo, 2] += kj * gap * dz
            e = l - q
            ka = axial(l, q, EA, compression)
            E += 0.5 * ka * e * e / q
            wq = -f - f * f / (2.0 * ka)               # dW/dq
            grad[c, 0] += f * dx
            grad[c, 1] += f * dy
            grad[c, 2] += f * dz
            grad[c, 3 + side] += wq
            if lo >= 0:
                grad[lo, 0] -= f * dx
                grad[lo, 1] -= f * dy
                grad[lo, 2] -= f * dz
                grad[lo, 3 + side] -= wq
            # axial part EA / q w w^T, w = (d, -d, -l/q, +l/q) over (C_a, C_b, s_a, s_b)
            na = 4
            idx[0] = 5 * c
            idx[1] = 5 * c + 1
            idx[2] = 5 * c + 2
            idx[3] = 5 * c + 3 + side
            w[0] = dx
            w[1] = dy
            w[2] = dz
            w[3] = -l / q
            if lo >= 0:
                na = 8
                idx[4] = 5 * lo
                idx[5] = 5 * lo + 1
                idx[6] = 5 * lo + 2
                idx[7] = 5 * lo + 3 + side
                w[4] = -dx
                w[5] = -dy
                w[6] = -dz
                w[7] = l / q
            a = ka / q
            for i in range(na):
                for j in range(na):
                    v = a * w[i] * w[j]
                    if i != 3 and j != 3 and i != 7 and j != 7:
                        v += kj * w[i] * w[j]    # the jamming's k d d^T on the positions
                    nnz = _put(rows, cols, vals, nnz, idx[i], idx[j], v)
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        side = 0 if k < n else 1
        yarn_point(pos, normal, over, c, side, h, pa)
        dx, dy, dz, l = _sub(pa, top[k], eps2 + eps2_top)
        fm = material_force(f_top[k], EA)
        E += fm * material[c, side] + f_top[k] * l
        grad[c, 0] += f_top[k] * dx / l
        grad[c, 1] += f_top[k] * dy / l
        grad[c, 2] += f_top[k] * dz / l
        grad[c, 3 + side] += fm
        nnz = _geometric(rows, cols, vals, nnz, c, -1, f_top[k] / l, dx / l, dy / l, dz / l)
    for c in range(m):
        for side in range(2):
            x = material[c, side] - centre[c, side]
            e, d1, d2 = _friction(x, bound[c, side], eps_f, kappa0)
            E += e
            grad[c, 3 + side] += d1
            i = 5 * c + 3 + side
            nnz = _put(rows, cols, vals, nnz, i, i, d2)
        sd = _wall_distance(pos, plane, c)
        # the wall's entries are written whether it pushes or not: the triplets of a zone are
        # the same from one Newton step to the next (frontal.py maps them once per solve)
        kw = k_wall if sd < 0.0 else 0.0
        E += 0.5 * kw * sd * sd
        for i in range(3):
            grad[c, i] += kw * sd * plane[c, 3 + i]
            for j in range(3):
                nnz = _put(rows, cols, vals, nnz, 5 * c + i, 5 * c + j,
                           kw * plane[c, 3 + i] * plane[c, 3 + j])
    return E, nnz


@njit(cache=True)
def _friction(x, bound, eps_f, kappa0):
    """Friction term of one yarn at one crossing and its first and second derivative in the slide
    x = material - centre (m): bound (sqrt(x^2 + eps_f^2) - eps_f), the work of the friction force
    against the sliding, |x| smoothed over eps_f; plus kappa0 x^2 / 2, which keeps the material
    coordinate of a yarn without friction and without tension defined."""
    r = math.sqrt(x * x + eps_f * eps_f)
    return (bound * (r - eps_f) + 0.5 * kappa0 * x * x, bound * x / r + kappa0 * x,
            bound * eps_f * eps_f / (r * r * r) + kappa0)


@njit(cache=True)
def triplet_matvec(nnz, rows, cols, vals, x, out):
    """out = H x for H given as ``nnz`` COO triplets (repeated entries add up)."""
    out[:] = 0.0
    for i in range(nnz):
        out[rows[i]] += vals[i] * x[cols[i]]


@njit(cache=True)
def accumulate(nnz, slot, vals, out):
    """out[slot[i]] += vals[i] for the triplets with slot[i] >= 0 (out zeroed first): the
    values of a sparse matrix's entries from its COO triplets."""
    out[:] = 0.0
    for i in range(nnz):
        k = slot[i]
        if k >= 0:
            out[k] += vals[i]


@njit(cache=True)
def lower_pattern(nnz, rows, cols, rank, n):
    """The lower triangle's pattern of the n x n matrix of COO triplets ``rows``, ``cols`` after
    the symmetric permutation ``rank`` (row i goes to rank[i]): (slot, er, ec, size), the
    ``size`` distinct entries at (er, ec) sorted by column then row, and slot (nnz,) the entry of
    each triplet, -1 for the triplets above the diagonal (what ``np.unique`` of the keys
    ``c n + r`` gives, in O(nnz))."""
    count = np.zeros(n + 1, dtype=np.int64)
    for i in range(nnz):
        r, c = rank[rows[i]], rank[cols[i]]
        if r >= c:
            count[c + 1] += 1
    for j in range(n):
        count[j + 1] += count[j]
    fill = count[:n].copy()
    bucket = np.empty(count[n], dtype=np.int64)        # lower triplets grouped by column
    for i in range(nnz):
        r, c = rank[rows[i]], rank[cols[i]]
        if r >= c:
            bucket[fill[c]] = i
            fill[c] += 1
    slot = np.full(nnz, -1, dtype=np.int64)
    er = np.empty(count[n], dtype=np.int64)
    ec = np.empty(count[n], dtype=np.int64)
    where = np.full(n, -1, dtype=np.int64)             # entry of row r in the current column
    size = 0
    for c in range(n):
        first = size
        for b in range(count[c], count[c + 1]):        # distinct rows of the column
            r = rank[rows[bucket[b]]]
            if where[r] < first:
                where[r] = size
                er[size] = r
                size += 1
        for a in range(first + 1, size):               # sort them (a column has ~25)
            v = er[a]
            b = a - 1
            while b >= first and er[b] > v:
                er[b + 1] = er[b]
                b -= 1
            er[b + 1] = v
        for a in range(first, size):
            where[er[a]] = a
            ec[a] = c
        for b in range(count[c], count[c + 1]):
            i = bucket[b]
            slot[i] = where[rank[rows[i]]]
    return slot, er[:size].copy(), ec[:size].copy(), size


@njit(cache=True)
def triplet_capacity(m, n_yarns):
    """Length of the rows/cols/vals arrays ``assemble`` needs."""
    return m * (2 * (64 + 36) + 2 + 9) + n_yarns * 9


@njit(cache=True)
def _geometric(rows, cols, vals, nnz, a, b, w, dx, dy, dz):
    """Blocks w (I - d d^T) of a segment between crossing a and crossing b (or a fixed point)."""
    for i in range(3):
        di = dx if i == 0 else (dy if i == 1 else dz)
        for j in range(3):
            dj = dx if j == 0 else (dy if j == 1 else dz)
            kij = w * ((1.0 if i == j else 0.0) - di * dj)
            nnz = _put(rows, cols, vals, nnz, 5 * a + i, 5 * a + j, kij)
            if b >= 0:
                nnz = _put(rows, cols, vals, nnz, 5 * b + i, 5 * b + j, kij)
                nnz = _put(rows, cols, vals, nnz, 5 * a + i, 5 * b + j, -kij)
                nnz = _put(rows, cols, vals, nnz, 5 * b + i, 5 * a + j, -kij)
    return nnz


@njit(cache=True)
def energy(lat, law, prob, pos, material, plane, k_wall):
    """E as in ``assemble``, without derivatives (inf when a material length is not positive)."""
    m, n_yarns, yarn, low, up, over, normal, lowest, highest = lat
    fell, top, material_fell, centre, bound, f_top = prob
    EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, geometric_floor = law
    n = n_yarns // 2
    pa = np.empty(3)
    pb = np.empty(3)
    E = 0.0
    for c in range(m):
        for side in range(2):
            k = yarn[c, side]
            yarn_point(pos, normal, over, c, side, h, pa)
            sb = _lower(k, c, side, low[c, side], pos, normal, over, fell, material,
                        material_fell, h, pb)
            q = material[c, side] - sb
            if q <= 0.0:
                return np.inf
            l = _sub(pa, pb, eps2)[3]
            E += 0.5 * axial(l, q, EA, compression) * (l - q) ** 2 / q
            if low[c, side] >= 0 and l < l_jam:
                E += 0.5 * k_jam * (l_jam - l) ** 2
            E += _friction(material[c, side] - centre[c, side], bound[c, side], eps_f, kappa0)[0]
        sd = _wall_distance(pos, plane, c)
        if sd < 0.0:
            E += 0.5 * k_wall * sd * sd
    for k in range(n_yarns):
        c = highest[k]
        if c < 0:
            continue
        side = 0 if k < n else 1
        yarn_point(pos, normal, over, c, side, h, pa)
        E += (material_force(f_top[k], EA) * material[c, side]
              + f_top[k] * _sub(pa, top[k], eps2 + eps2_top)[3])
    return E


@njit(cache=True)
def tensions(m, yarn, pos, normal, over, low, fell, material, material_fell, EA, compression, h,
             eps2, out):
    """Tension (N) of the segment below every crossing on both yarns into out (m, 2)."""
    pa = np.empty(3)
    pb = np.empty(3)
    for c in range(m):
        for side in range(2):
            k = yarn[c, side]
            yarn_point(pos, normal, over, c, side, h, pa)
            sb = _lower(k, c, side, low[c, side], pos, normal, over, fell, material,
                        material_fell, h, pb)
            out[c, side] = segment_tension(_sub(pa, pb, eps2)[3], material[c, side] - sb, EA,
                                           compression)


@njit(cache=True)
def friction_bounds(m, yarn, pos, normal, over, low, up, fell, top, tension, f_top, h, mu, bound,
                    psi):
    """Per crossing and yarn the friction bound mu (f_int + f_ext) tan(delta/2) (N) of the
    current geometry and tensions into bound (m, 2) (docs/theory.md §4), and Psi / (f_int + f_ext),
    Psi = |F^t| - mu |F^n| (paper §2.2), into psi (m, 2); mu (m,): each crossing's coefficient
    (``interaction.contact.crossing_friction``)."""
    p = np.empty(3)
    a = np.empty(3)
    b = np.empty(3)
    for c in range(m):
        for side in range(2):
            k = yarn[c, side]
            u = up[c, side]
            fi = tension[c, side]
            fe = tension[u, side] if u >= 0 else f_top[k]
            yarn_point(pos, normal, over, c, side, h, p)
            _end_point(pos, normal, over, low[c, side], side, k, fell, h, a)
            _end_point(pos, normal, over, u, side, k, top, h, b)
            ch, sh = half_angles(deflection_dot(p, a, b))
            tot = max(fi + fe, 1e-300)
            bound[c, side] = mu[c] * (fi + fe) * sh / max(ch, 1e-300)
            psi[c, side] = (abs(fi - fe) * ch - mu[c] * (fi + fe) * sh) / tot


@njit(cache=True)
def imbalance(m, yarn, up, grad, tension, f_top):
    """Largest relative residual over the crossings: |force sum| / (sum of the 4 tensions) and
    |dE/ds| / (f_int + f_ext) per yarn (the friction equation)."""
    worst = 0.0
    for c in range(m):
        tot = 0.0
        for side in range(2):
            u = up[c, side]
            fe = tension[u, side] if u >= 0 else f_top[yarn[c, side]]
            pair = max(abs(tension[c, side]) + abs(fe), 1e-300)
            tot += pair
            e = abs(grad[c, 3 + side]) / pair
            if e > worst:
                worst = e
        e = math.sqrt(grad[c, 0] ** 2 + grad[c, 1] ** 2 + grad[c, 2] ** 2) / max(tot, 1e-300)
        if e > worst:
            worst = e
    return worst


@njit(cache=True)
def reanchor(n_yarns, lowest, yarn, pos, normal, over, fell, material, tension, EA, compression, h,
             eps2, material_fell):
    """Material coordinate of every yarn's fell point into material_fell (2n,), such that the
    segment from it to the yarn's lowest crossing keeps its tension: material_fell =
    material_lowest - l / (1 + f / EA) (0 for a yarn without crossings). Yarn laid on
    the mandrel leaves the free segment along the yarn (the fell point advances along it), so
    the tension does not jump when the fell point moves."""
    n = n_yarns // 2
    p = np.empty(3)
    for k in range(n_yarns):
        c = lowest[k]
        if c < 0:
            material_fell[k] = 0.0
            continue
        side = 0 if k < n else 1
        yarn_point(pos, normal, over, c, side, h, p)
        l = _sub(p, fell[k], eps2)[3]
        f = tension[c, side]
        material_fell[k] = material[c, side] - l / (1.0 + f / (EA if f >= 0.0 else compression * EA))

@njit(cache=True)
def top_tensions(n_yarns, highest, pos, normal, over, fell, top, spool, h, f_spool, mu_r,
                 has_ring, capstan, f_hold, f_top):
    """Tension (N) of every yarn's top segment into f_top (2n,): the spool tension, or behind a
    guide ring Capstan over the ring point (paper eq. 9) by the direction the yarn's material
    slides over it, ``capstan[k]``: +1 towards the mandrel (the zone draws yarn from the spool:
    the mandrel side carries the higher tension, f = f_spool exp(mu_r eta)), -1 towards the spool
    (the tensioner takes yarn back: f = f_spool exp(-mu_r eta), eq. 9 as the paper writes it), 0
    stick: the held tension f_hold[k] within that cone. eta is the yarn's deflection at the ring
    point (``interaction/model.py``). f_spool, mu_r (2n,): every yarn's spool tension (N) and
    yarn-ring friction (its yarn type's)."""
    n = n_yarns // 2
    p = np.empty(3)
    for k in range(n_yarns):
        if not has_ring:
            f_top[k] = f_spool[k]
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
        if capstan[k] != 0.0:
            f_top[k] = f_spool[k] * math.exp(capstan[k] * mu_r[k] * eta)
        else:
            f_top[k] = min(max(f_hold[k], f_spool[k] * math.exp(-mu_r[k] * eta)),
                           f_spool[k] * math.exp(mu_r[k] * eta))


@njit(cache=True)
def _wall_distance(pos, plane, c):
    return ((pos[c, 0] - plane[c, 0]) * plane[c, 3] + (pos[c, 1] - plane[c, 1]) * plane[c, 4]
            + (pos[c, 2] - plane[c, 2]) * plane[c, 5])


@njit(cache=True)
def creation_point(px, gx, po, go, lowest, out):
    """Where a new crossing starts (``interaction.model.creation_point``): out[:3] the midpoint of
    the closest points ``px + tx d1`` and ``po + to d2`` of the segments px->gx (``d1``) and
    po->go (``d2``) (3,), ``tx, to`` in [lowest, 1]; out[3:] the unit normal ``d1 x d2``
    turned outward (away from the machine axis at the midpoint), the radial direction where the
    segments are parallel."""
    d1x, d1y, d1z = gx[0] - px[0], gx[1] - px[1], gx[2] - px[2]
    d2x, d2y, d2z = go[0] - po[0], go[1] - po[1], go[2] - po[2]
    rx, ry, rz = px[0] - po[0], px[1] - po[1], px[2] - po[2]
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    b = d1x * d2x + d1y * d2y + d1z * d2z
    c = d1x * rx + d1y * ry + d1z * rz
    f = d2x * rx + d2y * ry + d2z * rz
    tiny = 1e-30
    if a <= tiny and e <= tiny:
        tx = 0.0
        to = 0.0
    elif a <= tiny:
        tx = 0.0
        to = min(max(f / e, 0.0), 1.0)
    elif e <= tiny:
        tx = min(max(-c / a, 0.0), 1.0)
        to = 0.0
    else:
        den = a * e - b * b
        tx = min(max((b * f - c * e) / den, 0.0), 1.0) if den > tiny else 1.0
        to = (b * tx + f) / e
        if to < 0.0:
            tx = min(max(-c / a, 0.0), 1.0)
            to = 0.0
        elif to > 1.0:
            tx = min(max((b - c) / a, 0.0), 1.0)
            to = 1.0
    tx = max(tx, lowest)
    to = max(to, lowest)
    cx = 0.5 * (px[0] + tx * d1x + po[0] + to * d2x)
    cy = 0.5 * (px[1] + tx * d1y + po[1] + to * d2y)
    cz = 0.5 * (px[2] + tx * d1z + po[2] + to * d2z)
    nx = d1y * d2z - d1z * d2y
    ny = d1z * d2x - d1x * d2z
    nz = d1x * d2y - d1y * d2x
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn > 0.0:
        nx, ny, nz = nx / nn, ny / nn, nz / nn
    else:
        r = max(math.sqrt(cx * cx + cy * cy), 1e-300)
        nx, ny, nz = cx / r, cy / r, 0.0
    if nx * cx + ny * cy < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    out[0] = cx
    out[1] = cy
    out[2] = cz
    out[3] = nx
    out[4] = ny
    out[5] = nz
