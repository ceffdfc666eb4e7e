"""Numba kernels on triangle-mesh and polyline arrays: smooth corner normals, closest points on a
polyline and on triangles."""

from __future__ import annotations

import numpy as np
from numba import njit

from . import INNER


@njit(cache=True)
def corner_normals(T, FN, angles, vert_ptr, vert_faces, vert_corner, cos_crease):
    """Crease-split, angle-weighted smooth normal at every face corner.

    T (nf, 3) faces; FN (nf, 3) unit face normals; angles (nf, 3) interior angles (rad);
    vert_ptr (nv + 1,), vert_faces / vert_corner: faces around each vertex (CSR) and the corner of
    the vertex in each. Corner (f, k) averages, weighted by angle, the normals of the faces around
    its vertex whose normal is within the crease angle of FN[f] (cos >= cos_crease).
    Returns (nf, 3, 3) float64, unit.
    """
    nf = T.shape[0]
    out = np.empty((nf, 3, 3))
    for f in range(nf):
        for k in range(3):
            v = T[f, k]
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for p in range(vert_ptr[v], vert_ptr[v + 1]):
                g = vert_faces[p]
                c = FN[g, 0] * FN[f, 0] + FN[g, 1] * FN[f, 1] + FN[g, 2] * FN[f, 2]
                if c >= cos_crease:
                    w = angles[g, vert_corner[p]]
                    sx += w * FN[g, 0]
                    sy += w * FN[g, 1]
                    sz += w * FN[g, 2]
            s = np.sqrt(sx * sx + sy * sy + sz * sz)
            if s > 0.0:
                out[f, k, 0] = sx / s
                out[f, k, 1] = sy / s
                out[f, k, 2] = sz / s
            else:
                out[f, k, 0] = FN[f, 0]
                out[f, k, 1] = FN[f, 1]
                out[f, k, 2] = FN[f, 2]
    return out


@njit(cache=True, inline="always")
def _segment_d2(px, py, pz, P, S, j):
    """Squared distance from p to segment j of the polyline P and the arc length of the closest
    point: ``a + u (b - a)``, ``u = clip((p - a).(b - a) / |b - a|^2, 0, 1)`` (u = 0 for a
    degenerate segment)."""
    ax = P[j, 0]
    ay = P[j, 1]
    az = P[j, 2]
    ex = P[j + 1, 0] - ax
    ey = P[j + 1, 1] - ay
    ez = P[j + 1, 2] - az
    L2 = ex * ex + ey * ey + ez * ez
    u = 0.0
    if L2 > 0.0:
        u = ((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / L2
        if u < 0.0:
            u = 0.0
        elif u > 1.0:
            u = 1.0
    dx = ax + u * ex - px
    dy = ay + u * ey - py
    dz = az + u * ez - pz
    return dx * dx + dy * dy + dz * dz, S[j] + u * (S[j + 1] - S[j])


@njit(cache=True)
def project_to_polyline(points, P, S, out_s, out_d):
    """Closest point of the polyline P (n, 3) (arc lengths S (n,)) to each of points (m, 3).

    The nearest segment (``_segment_d2``), the lowest-index one of equal distances, exactly as
    trying every segment for every point (``tests/support/naive_kinematic.project_to_polyline``), but
    with the segments in runs of about sqrt(n) under bounding spheres: a run whose sphere is
    farther than the best distance so far cannot hold the nearest segment and is skipped. The
    previous point's run is searched first (points come in spatial order along yarns or faces).
    The sphere bound ``|p - c| - r`` is lowered by ``1e-9 (|p - c| + r) + 1e-12 max|P|``, far
    more than the rounding of the distances it is compared with (1e-16 relative to the
    coordinates), so no run that could hold the nearest segment or an equal one is skipped. Writes the arc length of the closest point into
    out_s (m,) and its distance into out_d (m,).
    """
    n_seg = P.shape[0] - 1
    run = max(1, int(np.sqrt(n_seg)))
    n_run = (n_seg + run - 1) // run
    C = np.empty((n_run, 3))
    R = np.empty(n_run)
    for b in range(n_run):
        j0 = b * run
        j1 = min(j0 + run, n_seg)          # segments j0 .. j1 - 1, vertices j0 .. j1
        lo0 = hi0 = P[j0, 0]
        lo1 = hi1 = P[j0, 1]
        lo2 = hi2 = P[j0, 2]
        for v in range(j0 + 1, j1 + 1):
            lo0 = min(lo0, P[v, 0])
            hi0 = max(hi0, P[v, 0])
            lo1 = min(lo1, P[v, 1])
            hi1 = max(hi1, P[v, 1])
            lo2 = min(lo2, P[v, 2])
            hi2 = max(hi2, P[v, 2])
        cx = 0.5 * (lo0 + hi0)
        cy = 0.5 * (lo1 + hi1)
        cz = 0.5 * (lo2 + hi2)
        r2 = 0.0
        for v in range(j0, j1 + 1):
            r2 = max(r2, (P[v, 0] - cx) ** 2 + (P[v, 1] - cy) ** 2 + (P[v, 2] - cz) ** 2)
        C[b, 0] = cx
        C[b, 1] = cy
        C[b, 2] = cz
        R[b] = np.sqrt(r2)      # the ball holds the run's vertices, so (convex) its segments
    scale = 0.0
    for v in range(P.shape[0]):
        scale = max(scale, abs(P[v, 0]), abs(P[v, 1]), abs(P[v, 2]))
    pad = 1e-12 * scale
    hint = 0
    for i in range(points.shape[0]):
        px = points[i, 0]
        py = points[i, 1]
        pz = points[i, 2]
        best = np.inf
        best_j = n_seg
        best_s = 0.0
        for k in range(n_run + 1):
            if k == 0:
                b = hint
            else:
                b = k - 1
                if b == hint:
                    continue
                dc = np.sqrt((px - C[b, 0]) ** 2 + (py - C[b, 1]) ** 2 + (pz - C[b, 2]) ** 2)
                lb = dc - R[b] - 1e-9 * (dc + R[b]) - pad
                if lb > 0.0 and lb * lb > best:
                    continue
            for j in range(b * run, min(b * run + run, n_seg)):
                d2, s = _segment_d2(px, py, pz, P, S, j)
                if d2 < best or (d2 == best and j < best_j):
                    best = d2
                    best_j = j
                    best_s = s
        hint = best_j // run if best_j < n_seg else 0
        out_s[i] = best_s
        out_d[i] = np.sqrt(best)


@njit(cache=True)
def closest_on_triangle(px, py, pz, V, tri):
    """Closest point of triangle ``tri`` (3 vertex indices into V (nv, 3)) to p: (x, y, z, d^2).

    The Voronoi-region walk of Ericson (Real-Time Collision Detection, 5.1.5): vertex regions,
    edge regions, else the face's interior by barycentric coordinates."""
    a0, a1, a2 = V[tri[0], 0], V[tri[0], 1], V[tri[0], 2]
    b0, b1, b2 = V[tri[1], 0], V[tri[1], 1], V[tri[1], 2]
    c0, c1, c2 = V[tri[2], 0], V[tri[2], 1], V[tri[2], 2]
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = px - a0, py - a1, pz - a2
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        x, y, z = a0, a1, a2
    else:
        bp0, bp1, bp2 = px - b0, py - b1, pz - b2
        d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
        d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
        vc = d1 * d4 - d3 * d2
        if d3 >= 0.0 and d4 <= d3:
            x, y, z = b0, b1, b2
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v = d1 / (d1 - d3)
            x, y, z = a0 + v * ab0, a1 + v * ab1, a2 + v * ab2
        else:
            cp0, cp1, cp2 = px - c0, py - c1, pz - c2
            d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
            d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
            vb = d5 * d2 - d1 * d6
            va = d3 * d6 - d5 * d4
            if d6 >= 0.0 and d5 <= d6:
                x, y, z = c0, c1, c2
            elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                w = d2 / (d2 - d6)
                x, y, z = a0 + w * ac0, a1 + w * ac1, a2 + w * ac2
            elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                x, y, z = b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2)
            else:
                den = 1.0 / (va + vb + vc)
                v = vb * den
                w = vc * den
                x = a0 + ab0 * v + ac0 * w
                y = a1 + ab1 * v + ac1 * w
                z = a2 + ab2 * v + ac2 * w
    dx, dy, dz = px - x, py - y, pz - z
    return x, y, z, dx * dx + dy * dy + dz * dz


@njit(cache=True)
def closest_on_candidates(points, V, F, ptr, cand, out_point, out_face, out_d2):
    """For each point i, the closest point over the faces ``cand[ptr[i]:ptr[i + 1]]`` (the
    lowest face index on a tie) into out_point (m, 3), out_face (m,), out_d2 (m,)."""
    for i in range(points.shape[0]):
        best = np.inf
        bf = -1
        bx = by = bz = 0.0
        for j in range(ptr[i], ptr[i + 1]):
            f = cand[j]
            x, y, z, d2 = closest_on_triangle(points[i, 0], points[i, 1], points[i, 2], V, F[f])
            if d2 < best or (d2 == best and f < bf):
                best, bf, bx, by, bz = d2, f, x, y, z
        out_point[i, 0] = bx
        out_point[i, 1] = by
        out_point[i, 2] = bz
        out_face[i] = bf
        out_d2[i] = best


# ------------------------------------------------- arc length through a dense resampling
# ``laid.CenterlineProjector``: the centerline resampled at a fine spacing, the nearest sample
# found exactly through a box tree over runs of consecutive samples, then the two resampled
# segments at that sample projected. Dot products are summed as (x0 y0 + x2 y2) + x1 y1, the
# order NumPy's einsum("ij,ij->i") takes on this code's reference machine, and norms as
# (x0^2 + x1^2) + x2^2 (np.linalg.norm), so the arc lengths are those of the whole-array NumPy
# projector (tests/unit/test_polyline_projection.py) to the last bit.

_LEAF = 32  # samples per leaf box of the tree (8, 16, 32: 0.34, 0.21, 0.19 s for 442 k points near a bend)


@njit(cache=True)
def sample_tree(Q):
    """Box tree over the samples Q (n, 3): node k covers samples lo[k] .. hi[k] - 1 with the
    bounding box box[k] = (min x, min y, min z, max x, max y, max z); children 2k + 1, 2k + 2,
    the range halved; a node of at most ``_LEAF`` samples is a leaf (left child -1).
    Returns (lo, hi, left, box)."""
    n = Q.shape[0]
    cap = 1
    while cap * _LEAF < n:
        cap *= 2
    size = 4 * cap
    lo = np.full(size, -1, dtype=np.int64)
    hi = np.full(size, -1, dtype=np.int64)
    left = np.full(size, -1, dtype=np.int64)
    box = np.zeros((size, 6))
    lo[0] = 0
    hi[0] = n
    for k in range(size):
        if lo[k] < 0:
            continue
        a = lo[k]
        b = hi[k]
        for c in range(3):
            box[k, c] = Q[a, c]
            box[k, 3 + c] = Q[a, c]
        for i in range(a + 1, b):
            for c in range(3):
                box[k, c] = min(box[k, c], Q[i, c])
                box[k, 3 + c] = max(box[k, 3 + c], Q[i, c])
        if b - a > _LEAF:
            m = (a + b) // 2
            left[k] = 2 * k + 1
            lo[2 * k + 1] = a
            hi[2 * k + 1] = m
            lo[2 * k + 2] = m
            hi[2 * k + 2] = b
    return lo, hi, left, box


@njit(cache=True, inline="always")
def _box_d2(px, py, pz, box, k):
    """Squared distance from p to box k (0 inside); no larger than the squared distance from p
    to any point in the box, also in floating point (each term is monotone in the coordinate)."""
    dx = max(box[k, 0] - px, 0.0, px - box[k, 3])
    dy = max(box[k, 1] - py, 0.0, py - box[k, 4])
    dz = max(box[k, 2] - pz, 0.0, pz - box[k, 5])
    return (dx * dx + dy * dy) + dz * dz


@njit(**INNER)
def nearest_sample(px, py, pz, Q, lo, hi, left, box, stack):
    """Index of the sample of Q nearest to p (the lowest of equal ones); ``stack`` (>= 2 x tree
    depth + 2,) int64 scratch."""
    best = np.inf
    best_i = -1
    top = 0
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        k = stack[top]
        if _box_d2(px, py, pz, box, k) > best:
            continue
        c = left[k]
        if c < 0:
            for i in range(lo[k], hi[k]):
                dx = px - Q[i, 0]
                dy = py - Q[i, 1]
                dz = pz - Q[i, 2]
                d2 = (dx * dx + dy * dy) + dz * dz
                if d2 < best or (d2 == best and i < best_i):
                    best = d2
                    best_i = i
            continue
        d_l = _box_d2(px, py, pz, box, c)
        d_r = _box_d2(px, py, pz, box, c + 1)
        if d_l <= d_r:            # the nearer child on top of the stack
            stack[top] = c + 1
            stack[top + 1] = c
        else:
            stack[top] = c
            stack[top + 1] = c + 1
        top += 2
    return best_i


@njit(cache=True)
def project_sampled(points, Q, Sq, lo, hi, left, box, out_s):
    """Arc length of each of points (m, 3) on the resampled centerline Q (n, 3) at arc lengths
    Sq (n,), with the tree ``sample_tree(Q)``: the nearest sample i, then the segments
    (i - 1, i) and (i, i + 1) (clamped at the ends), ``u = clip((p - a).(b - a) / |b - a|^2, 0, 1)``
    (the denominator 1 for a zero-length segment), the nearer of the two (the first on a tie).
    Writes out_s (m,)."""
    n = Q.shape[0]
    depth = 1
    while (1 << depth) < lo.shape[0]:
        depth += 1
    stack = np.empty(2 * depth + 4, dtype=np.int64)
    for j in range(points.shape[0]):
        px = points[j, 0]
        py = points[j, 1]
        pz = points[j, 2]
        i = nearest_sample(px, py, pz, Q, lo, hi, left, box, stack)
        best_d = np.inf
        best_s = Sq[i]
        for w in range(2):
            a = max(i - 1, 0) if w == 0 else i
            b = min(a + 1, n - 1)
            abx = Q[b, 0] - Q[a, 0]
            aby = Q[b, 1] - Q[a, 1]
            abz = Q[b, 2] - Q[a, 2]
            L2 = (abx * abx + abz * abz) + aby * aby
            if not L2 > 0:
                L2 = 1.0
            qx = px - Q[a, 0]
            qy = py - Q[a, 1]
            qz = pz - Q[a, 2]
            u = ((qx * abx + qz * abz) + qy * aby) / L2
            u = min(max(u, 0.0), 1.0)
            dx = Q[a, 0] + u * abx - px
            dy = Q[a, 1] + u * aby - py
            dz = Q[a, 2] + u * abz - pz
            d = np.sqrt((dx * dx + dy * dy) + dz * dz)
            if d < best_d:
                best_d = d
                best_s = Sq[a] + u * (Sq[b] - Sq[a])
        out_s[j] = best_s


# ------------------------------------------------------------- segment queries through embree
@njit(cache=True)
def segment_rays(starts, ends, offset, diagonal, scene_origin, scene_scale, dirs, length, live,
                 origin32, dirs32, far32):
    """The rays of ``Mandrel.intersect_segments`` for segments starts -> ends (m, 3), float64.

    Writes dirs (m, 3) unit (zeros for a zero-length segment) and length (m,) ``|end - start|``
    (squares summed in order, as np.linalg.norm); then for each segment longer than ``offset``,
    in order, its index into live (m,) and its embree ray: origin ``start + offset d`` in the
    scene's frame ``(x - scene_origin) * scene_scale``, direction d, and the far distance
    ``(length - offset + 1e-6 (length + diagonal)) * scene_scale`` (a little past the end, as
    float32 resolves 6e-8 of a distance), each rounded to float32 (origin32, dirs32, far32).
    Returns the number of rays. The operations are those of the NumPy set-up they replace, so the
    rays are the same to the last bit."""
    m = 0
    for i in range(starts.shape[0]):
        dx = ends[i, 0] - starts[i, 0]
        dy = ends[i, 1] - starts[i, 1]
        dz = ends[i, 2] - starts[i, 2]
        L = np.sqrt((dx * dx + dy * dy) + dz * dz)
        length[i] = L
        if L > 0:
            dx = dx / L
            dy = dy / L
            dz = dz / L
        else:
            dx = dy = dz = 0.0
        dirs[i, 0] = dx
        dirs[i, 1] = dy
        dirs[i, 2] = dz
        if L > 0 and L > offset:
            live[m] = i
            origin32[m, 0] = np.float32(((starts[i, 0] + offset * dx) - scene_origin[0]) * scene_scale)
            origin32[m, 1] = np.float32(((starts[i, 1] + offset * dy) - scene_origin[1]) * scene_scale)
            origin32[m, 2] = np.float32(((starts[i, 2] + offset * dz) - scene_origin[2]) * scene_scale)
            dirs32[m, 0] = np.float32(dx)
            dirs32[m, 1] = np.float32(dy)
            dirs32[m, 2] = np.float32(dz)
            far32[m] = np.float32((L - offset + 1e-6 * (L + diagonal)) * scene_scale)
            m += 1
    return m


# ------------------------------------------------------ self-intersection test by edge rays
# ``geometry.repair.self_intersections``: every edge is cast along itself from just past its
# start; each triangle met before its end is tested, the ray restarted just past the hit.


@njit(cache=True)
def edge_ray_batch(live, origin, a, u, length, eps, scene_origin, scene_scale, out_live, origin32,
                   dirs32, far32):
    """The embree rays of the edges ``live`` still being cast: what is left of edge r,
    ``length - 2 eps - (origin - a).u``; the edges with some left, in order, into out_live, their
    rays in the scene's frame ``(x - scene_origin) * scene_scale`` and far distances (float32).
    Returns their number."""
    m = 0
    for j in range(live.shape[0]):
        r = live[j]
        left = length[r] - 2.0 * eps[r] - ((origin[r, 0] - a[r, 0]) * u[r, 0]
                                            + (origin[r, 1] - a[r, 1]) * u[r, 1]
                                            + (origin[r, 2] - a[r, 2]) * u[r, 2])
        if not left > 0:
            continue
        out_live[m] = r
        for c in range(3):
            origin32[m, c] = np.float32((origin[r, c] - scene_origin[c]) * scene_scale)
            dirs32[m, c] = np.float32(u[r, c])
        far32[m] = np.float32(left * scene_scale)
        m += 1
    return m


@njit(cache=True)
def edge_ray_hits(live, prim, V, F, FN, e, origin, a, u, length, eps, base, offset, last, bad,
                  out_live):
    """Process one embree pass of the edge rays ``live`` (hit triangle ``prim``, -1 for none).

    A hit on a new triangle: the ray's line meets the triangle's plane at
    ``origin + u (p0 - origin).n / u.n`` (no hit if |u.n| <= 1e-5, a grazing ray, which ends);
    it pierces when that point lies before the edge's end (``(x - a).u < length - 2 eps``) and
    the triangle holds neither end of the edge (flag ``bad``, the ray ends); otherwise the ray
    restarts ``base`` past the point. The same triangle hit again (float32 rounding put the
    origin behind it): the ray moves on by twice its last advance. Writes the rays still going
    into out_live; returns their number."""
    m = 0
    for j in range(live.shape[0]):
        r = live[j]
        p = prim[j]
        if p < 0:
            continue
        if last[r] == p:
            offset[r] *= 2.0
            for c in range(3):
                origin[r, c] += u[r, c] * offset[r]
            out_live[m] = r
            m += 1
            continue
        last[r] = p
        q0 = F[p, 0]
        den = u[r, 0] * FN[p, 0] + u[r, 1] * FN[p, 1] + u[r, 2] * FN[p, 2]
        if not abs(den) > 1e-5:
            continue
        num = ((V[q0, 0] - origin[r, 0]) * FN[p, 0] + (V[q0, 1] - origin[r, 1]) * FN[p, 1]
               + (V[q0, 2] - origin[r, 2]) * FN[p, 2])
        dist = num / den
        x0 = u[r, 0] * dist + origin[r, 0]
        x1 = u[r, 1] * dist + origin[r, 1]
        x2 = u[r, 2] * dist + origin[r, 2]
        t = (x0 - a[r, 0]) * u[r, 0] + (x1 - a[r, 1]) * u[r, 1] + (x2 - a[r, 2]) * u[r, 2]
        own = False
        for c in range(3):
            if F[p, c] == e[r, 0] or F[p, c] == e[r, 1]:
                own = True
        if t < length[r] - 2.0 * eps[r] and not own:
            bad[r] = True
            continue
        origin[r, 0] = x0 + u[r, 0] * base
        origin[r, 1] = x1 + u[r, 1] * base
        origin[r, 2] = x2 + u[r, 2] * base
        offset[r] = base
        out_live[m] = r
        m += 1
    return m


# ------------------------------------------------------------------------------ exact welding
@njit(cache=True, inline="always")
def hash_slot(x, y, z, size):
    """Slot in an open-addressing table of ``size`` (a power of two) for three 64-bit words:
    FNV-1a style mixing, ``h = (h ^ w) * 1099511628211; h ^= h >> 29`` per word."""
    h = np.uint64(1469598103934665603)
    for w in (np.uint64(x), np.uint64(y), np.uint64(z)):
        h = (h ^ w) * np.uint64(1099511628211)
        h ^= h >> np.uint64(29)
    return np.int64(h & np.uint64(size - 1))


@njit(cache=True, inline="always")
def empty_table(n):
    """An open-addressing table for n keys: int64 slots, all -1 (empty), its size the smallest
    power of two at least 2 n (at most half full, so every probe ends; ``hash_slot`` masks by
    size - 1)."""
    size = 1
    while size < 2 * n:
        size *= 2
    return np.full(size, -1, dtype=np.int64)


@njit(cache=True)
def weld_exact(V, inverse):
    """Distinct rows of V (n, 3) float64 in order of first appearance: writes the index of each
    row's distinct row into inverse (n,) and returns the index in V of each distinct row's first
    appearance. Rows are equal when their coordinates are (so 0.0 and -0.0 are one value), through
    an open-addressing hash table on the coordinates' bits."""
    n = V.shape[0]
    table = empty_table(n)
    size = table.shape[0]
    first = np.empty(n, dtype=np.int64)
    bits = np.empty(3, dtype=np.float64)
    ibits = bits.view(np.uint64)
    k = 0
    for i in range(n):
        for c in range(3):
            bits[c] = V[i, c] + 0.0            # -0.0 -> 0.0
        slot = hash_slot(ibits[0], ibits[1], ibits[2], size)
        while True:
            j = table[slot]
            if j < 0:
                table[slot] = k
                first[k] = i
                inverse[i] = k
                k += 1
                break
            r = first[j]
            if V[r, 0] == V[i, 0] and V[r, 1] == V[i, 1] and V[r, 2] == V[i, 2]:
                inverse[i] = j
                break
            slot = (slot + 1) & (size - 1)
    return first[:k].copy()


@njit(cache=True)
def degenerate_faces(V, F, radius, collapsed, caps, longest):
    """Per face of F (m, 3) on V (n, 3): collapsed (a repeated vertex), cap (not collapsed, and
    twice its area ``|s0 x s1|`` at most ``radius`` times its longest side, sides
    s_k = p_(k+1) - p_k) and the index of its longest side (the first of equal ones), into the
    (m,) arrays collapsed, caps (bool) and longest (int64). The operations of the NumPy form in
    ``geometry.repair._drop_degenerate``'s docstring, in its order."""
    for f in range(F.shape[0]):
        i0 = F[f, 0]
        i1 = F[f, 1]
        i2 = F[f, 2]
        collapsed[f] = i0 == i1 or i1 == i2 or i0 == i2
        s0x = V[i1, 0] - V[i0, 0]
        s0y = V[i1, 1] - V[i0, 1]
        s0z = V[i1, 2] - V[i0, 2]
        s1x = V[i2, 0] - V[i1, 0]
        s1y = V[i2, 1] - V[i1, 1]
        s1z = V[i2, 2] - V[i1, 2]
        s2x = V[i0, 0] - V[i2, 0]
        s2y = V[i0, 1] - V[i2, 1]
        s2z = V[i0, 2] - V[i2, 2]
        L0 = np.sqrt((s0x * s0x + s0y * s0y) + s0z * s0z)
        L1 = np.sqrt((s1x * s1x + s1y * s1y) + s1z * s1z)
        L2 = np.sqrt((s2x * s2x + s2y * s2y) + s2z * s2z)
        cx = s0y * s1z - s0z * s1y
        cy = s0z * s1x - s0x * s1z
        cz = s0x * s1y - s0y * s1x
        area2 = np.sqrt((cx * cx + cy * cy) + cz * cz)
        if L0 >= L1 and L0 >= L2:
            k = 0
            top = L0
        elif L1 >= L2:
            k = 1
            top = L1
        else:
            k = 2
            top = L2
        longest[f] = k
        caps[f] = (not collapsed[f]) and area2 <= radius * top


@njit(cache=True)
def centroids_and_reach(V, F, centroids, reach):
    """Face centroids ``(p0 + p1 + p2) / 3`` into centroids (m, 3) and each face's largest
    centroid-to-corner distance into reach (m,), summed in the order of NumPy's
    ``tri.mean(axis=1)`` and ``sqrt(((tri - c) ** 2).sum(axis=2).max(axis=1))``."""
    for f in range(F.shape[0]):
        i0 = F[f, 0]
        i1 = F[f, 1]
        i2 = F[f, 2]
        for c in range(3):
            centroids[f, c] = ((V[i0, c] + V[i1, c]) + V[i2, c]) / 3.0
        best = 0.0
        for k in range(3):
            i = F[f, k]
            dx = V[i, 0] - centroids[f, 0]
            dy = V[i, 1] - centroids[f, 1]
            dz = V[i, 2] - centroids[f, 2]
            d2 = (dx ** 2 + dy ** 2) + dz ** 2
            if k == 0 or d2 > best:
                best = d2
        reach[f] = np.sqrt(best)


@njit(cache=True)
def corner_cosines(V, F, out):
    """Cosine of the interior angle at every face corner into out (m, 3): ``u.w / max(|u| |w|,
    1e-300)`` with u, w the sides from corner k to corners k+1, k+2 (the dot summed as NumPy's
    einsum does here, (x0 y0 + x2 y2) + x1 y1; norms as np.linalg.norm)."""
    for f in range(F.shape[0]):
        for k in range(3):
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            c = F[f, (k + 2) % 3]
            ux = V[b, 0] - V[a, 0]
            uy = V[b, 1] - V[a, 1]
            uz = V[b, 2] - V[a, 2]
            wx = V[c, 0] - V[a, 0]
            wy = V[c, 1] - V[a, 1]
            wz = V[c, 2] - V[a, 2]
            dot = (ux * wx + uz * wz) + uy * wy
            nu = np.sqrt((ux * ux + uy * uy) + uz * uz)
            nw = np.sqrt((wx * wx + wy * wy) + wz * wz)
            out[f, k] = dot / max(nu * nw, 1e-300)


@njit(cache=True)
def corners_by_vertex(F, n_vertices, vert_ptr, vert_faces, vert_corner):
    """The faces around each vertex (CSR): vert_ptr (nv + 1,), and for the corners of vertex v,
    ``vert_faces / vert_corner[vert_ptr[v]:vert_ptr[v + 1]]`` their faces and corner indices in
    the order of the flattened corners (a counting sort: the order of a stable argsort)."""
    vert_ptr[:] = 0
    for f in range(F.shape[0]):
        for k in range(3):
            vert_ptr[F[f, k] + 1] += 1
    for v in range(n_vertices):
        vert_ptr[v + 1] += vert_ptr[v]
    fill = vert_ptr[:-1].copy()
    for f in range(F.shape[0]):
        for k in range(3):
            v = F[f, k]
            vert_faces[fill[v]] = f
            vert_corner[fill[v]] = k
            fill[v] += 1


@njit(cache=True, inline="always")
def _side_longer(V, F, f, h):
    """Whether face f has a side ``|p_k - p_(k-1)|`` longer than h, the norm summed as
    np.linalg.norm does, ``(dx^2 + dy^2) + dz^2``."""
    for k in range(3):
        a = F[f, k]
        b = F[f, (k + 2) % 3]
        dx = V[a, 0] - V[b, 0]
        dy = V[a, 1] - V[b, 1]
        dz = V[a, 2] - V[b, 2]
        if np.sqrt((dx * dx + dy * dy) + dz * dz) > h:
            return True
    return False


@njit(cache=True)
def any_side_longer(V, F, h):
    """True when some face of F has a side longer than h (``_side_longer``), the test
    ``geometry.remesh.subdivide_long_edges`` starts with."""
    for f in range(F.shape[0]):
        if _side_longer(V, F, f, h):
            return True
    return False


@njit(cache=True)
def long_side_faces(V, F, h, out):
    """Faces of F with a side longer than h (``_side_longer``) into out (m,) bool: the mask
    ``(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2) > h).any(axis=1)``."""
    for f in range(F.shape[0]):
        out[f] = _side_longer(V, F, f, h)


@njit(cache=True, inline="always")
def face_cross(V, F, f):
    """``(p1 - p0) x (p2 - p0)`` of face f, in the operations of ``np.cross``."""
    i0 = F[f, 0]
    i1 = F[f, 1]
    i2 = F[f, 2]
    ux = V[i1, 0] - V[i0, 0]
    uy = V[i1, 1] - V[i0, 1]
    uz = V[i1, 2] - V[i0, 2]
    wx = V[i2, 0] - V[i0, 0]
    wy = V[i2, 1] - V[i0, 1]
    wz = V[i2, 2] - V[i0, 2]
    return uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx


@njit(cache=True)
def triangle_moments(V, F, area, centroid, second):
    """Area, centroid and second moment of every face of F (m, 3) on V (n, 3), into area (m,),
    centroid (m, 3) and second (m, 3, 3): with corners a, b, c, ``A = |(b - a) x (c - a)| / 2``,
    ``s = a + b + c``, centroid ``s / 3`` and ``A / 12 (a a^T + b b^T + c c^T + s s^T)``, each
    sum in the order of the NumPy form in ``geometry.centerline.surface_moments``'s docstring
    (corner by corner, the norm as np.linalg.norm), so the arrays are bit-identical to it."""
    for f in range(F.shape[0]):
        i0 = F[f, 0]
        i1 = F[f, 1]
        i2 = F[f, 2]
        cx, cy, cz = face_cross(V, F, f)
        a = 0.5 * np.sqrt((cx * cx + cy * cy) + cz * cz)
        area[f] = a
        w = a / 12.0
        for i in range(3):
            si = (V[i0, i] + V[i1, i]) + V[i2, i]
            centroid[f, i] = si / 3.0
            for j in range(3):
                sj = (V[i0, j] + V[i1, j]) + V[i2, j]
                corners = (V[i0, i] * V[i0, j] + V[i1, i] * V[i1, j]) + V[i2, i] * V[i2, j]
                second[f, i, j] = (corners + si * sj) * w


@njit(cache=True)
def vertex_bounds(V, F, lo, hi):
    """Least and greatest coordinates (3,) into lo, hi of the finite vertices V (n, 3): of all of
    them when F has no rows, else of those F (m, 3) uses (``V[np.unique(F)].min(axis=0)`` and
    ``.max(axis=0)``; min and max are exact, so the order of the pass does not matter)."""
    for c in range(3):
        lo[c] = np.inf
        hi[c] = -np.inf
    if F.shape[0] == 0:
        for i in range(V.shape[0]):
            for c in range(3):
                x = V[i, c]
                if x < lo[c]:
                    lo[c] = x
                if x > hi[c]:
                    hi[c] = x
        return
    for f in range(F.shape[0]):
        for k in range(3):
            i = F[f, k]
            for c in range(3):
                x = V[i, c]
                if x < lo[c]:
                    lo[c] = x
                if x > hi[c]:
                    hi[c] = x


@njit(cache=True)
def face_cross_normals(V, F, cross, normals):
    """Per face of F (m, 3): ``c = (p1 - p0) x (p2 - p0)`` into cross (m, 3) and the unit normal
    ``c / |c|`` (``c`` itself where ``|c| = 0``) into normals (m, 3), in the operations of
    ``np.cross`` and ``np.linalg.norm`` (bit-identical to ``c / np.where(a > 0, a, 1)``)."""
    for f in range(F.shape[0]):
        cx, cy, cz = face_cross(V, F, f)
        cross[f, 0] = cx
        cross[f, 1] = cy
        cross[f, 2] = cz
        a = np.sqrt((cx * cx + cy * cy) + cz * cz)
        if not a > 0:
            a = 1.0
        normals[f, 0] = cx / a
        normals[f, 1] = cy / a
        normals[f, 2] = cz / a


@njit(cache=True)
def edge_ray_geometry(V, e, keep, a, u, length, eps, origin):
    """The rays of ``repair.self_intersections``: for each edge (p, q) of e (k, 2) of nonzero
    length ``L = |V[q] - V[p]|``, in order, its start ``a = V[p]``, unit direction ``u``, L, the
    hair ``eps = 1e-6 L`` and the ray origin ``a + eps u``, into the first rows of a, u (k, 3),
    length, eps (k,) and origin (k, 3); keep (k,) marks those edges. Returns their number.
    The operations of the NumPy form (``d / L``, norms as np.linalg.norm)."""
    m = 0
    for i in range(e.shape[0]):
        p = e[i, 0]
        q = e[i, 1]
        dx = V[q, 0] - V[p, 0]
        dy = V[q, 1] - V[p, 1]
        dz = V[q, 2] - V[p, 2]
        L = np.sqrt((dx * dx + dy * dy) + dz * dz)
        keep[i] = L > 0
        if not L > 0:
            continue
        h = 1e-6 * L
        length[m] = L
        eps[m] = h
        for c, dc in ((0, dx), (1, dy), (2, dz)):
            uc = dc / L
            a[m, c] = V[p, c]
            u[m, c] = uc
            origin[m, c] = V[p, c] + uc * h
        m += 1
    return m


@njit(cache=True)
def grid_neighbours_exist(P, cell):
    """False when no two rows of P (n, 3) lie in the same or in adjacent cubes of a grid of edge
    ``cell`` (index ``floor(x / cell)`` per axis), True otherwise. Two points closer than
    ``cell / 2`` in every axis lie in the same or adjacent cubes, so False proves that no pair is
    within ``cell / 2`` of each other. The cubes are kept in an open-addressing hash table; the
    caller keeps ``|x| / cell`` far below 2^52 so that the division rounds by far less than a cube.
    """
    n = P.shape[0]
    table = empty_table(n)
    size = table.shape[0]
    cube = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for c in range(3):
            cube[i, c] = np.int64(np.floor(P[i, c] / cell))
    for i in range(n):
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    qx = cube[i, 0] + dx
                    qy = cube[i, 1] + dy
                    qz = cube[i, 2] + dz
                    slot = hash_slot(qx, qy, qz, size)
                    while True:
                        j = table[slot]
                        if j < 0:
                            break
                        if cube[j, 0] == qx and cube[j, 1] == qy and cube[j, 2] == qz:
                            return True
                        slot = (slot + 1) & (size - 1)
        # then enter the point's own cube (a second point in it is found by the lookups above)
        slot = hash_slot(cube[i, 0], cube[i, 1], cube[i, 2], size)
        while table[slot] >= 0:
            slot = (slot + 1) & (size - 1)
        table[slot] = i
    return False


@njit(cache=True)
def winding_numbers(V, F, P, out):
    """The generalised winding number of the closed surface (V, F) at each point of P (k, 3), into
    out (k,): ``w(p) = sum_f Omega_f(p) / (4 pi)``, with the solid angle of triangle (a, b, c)
    seen from p by Van Oosterom and Strackee (1983), ``tan(Omega / 2) = a . (b x c) / (|a||b||c|
    + (a . b)|c| + (a . c)|b| + (b . c)|a|)`` on the corners relative to p. 1 inside an outward
    surface, 0 outside, 1/2 on it; exact for any triangulation (no rays, no closest points)."""
    for k in range(P.shape[0]):
        px = P[k, 0]
        py = P[k, 1]
        pz = P[k, 2]
        total = 0.0
        for f in range(F.shape[0]):
            i0 = F[f, 0]
            i1 = F[f, 1]
            i2 = F[f, 2]
            ax = V[i0, 0] - px
            ay = V[i0, 1] - py
            az = V[i0, 2] - pz
            bx = V[i1, 0] - px
            by = V[i1, 1] - py
            bz = V[i1, 2] - pz
            cx = V[i2, 0] - px
            cy = V[i2, 1] - py
            cz = V[i2, 2] - pz
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (ax * cx + ay * cy + az * cz) * lb + (bx * cx + by * cy + bz * cz) * la)
            total += 2.0 * np.arctan2(det, den)
        out[k] = total / (4.0 * np.pi)
