"""Numba kernels on triangle-mesh arrays (smooth corner normals)."""

from __future__ import annotations

import numpy as np
from numba import njit


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


@njit(cache=True)
def project_to_polyline(points, P, S, out_s, out_d):
    """Closest point of the polyline P (n, 3) (arc lengths S (n,)) to each of points (m, 3).

    For every point, every segment ``a + u (b - a)``, ``u = clip((p - a).(b - a) / |b - a|^2, 0, 1)``,
    keeps the nearest (the first of equal ones). Writes the arc length of the closest point
    into out_s (m,) and its distance into out_d (m,). Degenerate segments project to their start.
    """
    n = P.shape[0]
    for i in range(points.shape[0]):
        px = points[i, 0]
        py = points[i, 1]
        pz = points[i, 2]
        best = np.inf
        best_s = 0.0
        for j in range(n - 1):
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
            d2 = dx * dx + dy * dy + dz * dz
            if d2 < best:
                best = d2
                best_s = S[j] + u * (S[j + 1] - S[j])
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
