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
