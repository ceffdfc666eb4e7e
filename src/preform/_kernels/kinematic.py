"""Numba kernels of the kinematic fell-point walk (docs/theory.md §3). Arrays and scalars only.

Mesh arrays (mandrel frame, m):
  V  (nv, 3) float64 vertices;  T (nf, 3) int64 faces (outward winding);
  FN (nf, 3) float64 unit face normals;  CN (nf, 3, 3) float64 smooth unit normals at the corners;
  NB (nf, 3) int64 face across edge k (corners k, k+1), -1 on a boundary.

A point on the surface is a face index plus its 3D position on that face. The smooth normal
``n(x)`` is the barycentric interpolation of the corner normals, normalised, so braid angles do not
inherit the facets. The tangency gap of a free yarn from ``x`` to its supply point ``G`` is
``g = (G - x) . n(x)``: ``g < 0`` means the straight yarn would cut into the mandrel, so the fell
point wraps on along the surface until ``g = 0``.

Status codes of the walk (``WALK_*``): the slow NumPy twin lives in ``tests/support/naive_kinematic.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import INNER
from .mesh import face_cross

WALK_TANGENT = 0     # walked until the free yarn became tangent (g = 0)
WALK_CONCAVE = 1     # g started to fall: a concave stretch the yarn cannot follow (bridge)
WALK_BUDGET = 2      # walked the allowed length without reaching tangency
WALK_DEGENERATE = 3  # the supply point is along the normal: no walking direction
WALK_BOUNDARY = 4    # walked off an open mesh edge
WALK_LIFTOFF = -1    # g >= 0 at the start: the yarn stays put (unilateral contact)

_MAX_SUBSTEPS = 100000


@njit(**INNER)
def face_basis(V, T, f):
    """The parts of ``barycentric`` that depend on face f only: its first corner p0, the edge
    vectors a = p1 - p0, b = p2 - p0, their dots d00 = a.a, d01 = a.b, d11 = b.b and
    den = d00 d11 - d01^2, as a tuple (p0x, p0y, p0z, ax, ay, az, bx, by, bz, d00, d01, d11, den)."""
    i0 = T[f, 0]
    i1 = T[f, 1]
    i2 = T[f, 2]
    ax = V[i1, 0] - V[i0, 0]
    ay = V[i1, 1] - V[i0, 1]
    az = V[i1, 2] - V[i0, 2]
    bx = V[i2, 0] - V[i0, 0]
    by = V[i2, 1] - V[i0, 1]
    bz = V[i2, 2] - V[i0, 2]
    d00 = ax * ax + ay * ay + az * az
    d01 = ax * bx + ay * by + az * bz
    d11 = bx * bx + by * by + bz * bz
    den = d00 * d11 - d01 * d01
    return V[i0, 0], V[i0, 1], V[i0, 2], ax, ay, az, bx, by, bz, d00, d01, d11, den


@njit(**INNER)
def barycentric_in(q, x, y, z):
    """Barycentric coordinates of (x, y, z) in the plane of the face with ``q = face_basis(...)``.

    A face of no area (collinear corners: CAD exports have them) has no plane: the point is
    placed on its longer edge from the first corner (its projection there), or at the first
    corner where all three coincide, so the walk passes over the face instead of dividing by
    zero."""
    p0x, p0y, p0z, ax, ay, az, bx, by, bz, d00, d01, d11, den = q
    cx = x - p0x
    cy = y - p0y
    cz = z - p0z
    d20 = cx * ax + cy * ay + cz * az
    d21 = cx * bx + cy * by + cz * bz
    if not den > 1e-14 * (d00 * d11):
        if d00 >= d11 and d00 > 0.0:
            return 1.0 - d20 / d00, d20 / d00, 0.0
        if d11 > 0.0:
            return 1.0 - d21 / d11, 0.0, d21 / d11
        return 1.0, 0.0, 0.0
    b1 = (d11 * d20 - d01 * d21) / den
    b2 = (d00 * d21 - d01 * d20) / den
    return 1.0 - b1 - b2, b1, b2


@njit(cache=True)
def barycentric(V, T, f, x, y, z):
    """Barycentric coordinates of the point (x, y, z) in the plane of face f."""
    return barycentric_in(face_basis(V, T, f), x, y, z)


@njit(**INNER)
def face_double_area(V, T, f):
    """Twice the area of face f, |(p1 - p0) x (p2 - p0)|."""
    qx, qy, qz = face_cross(V, T, f)
    return np.sqrt(qx * qx + qy * qy + qz * qz)


@njit(cache=True)
def smooth_normal(V, T, CN, f, x, y, z):
    """Unit smooth normal at (x, y, z) on face f: normalised barycentric blend of corner normals."""
    b0, b1, b2 = barycentric(V, T, f, x, y, z)
    return blended_normal(CN, f, b0, b1, b2)


@njit(**INNER)
def blended_normal(CN, f, b0, b1, b2):
    """Unit smooth normal of face f at barycentric coordinates (b0, b1, b2); the first corner's
    where the blend vanishes (corner normals that cancel at a knife edge)."""
    nx = b0 * CN[f, 0, 0] + b1 * CN[f, 1, 0] + b2 * CN[f, 2, 0]
    ny = b0 * CN[f, 0, 1] + b1 * CN[f, 1, 1] + b2 * CN[f, 2, 1]
    nz = b0 * CN[f, 0, 2] + b1 * CN[f, 1, 2] + b2 * CN[f, 2, 2]
    s = np.sqrt(nx * nx + ny * ny + nz * nz)
    if not s > 0.0:
        return CN[f, 0, 0], CN[f, 0, 1], CN[f, 0, 2]
    return nx / s, ny / s, nz / s


@njit(cache=True)
def tangency_gap(V, T, CN, f, x, y, z, gx, gy, gz):
    """g = (G - x) . n(x), m."""
    nx, ny, nz = smooth_normal(V, T, CN, f, x, y, z)
    return (gx - x) * nx + (gy - y) * ny + (gz - z) * nz


@njit(**INNER)
def walk_direction(FN, f, x, y, z, gx, gy, gz):
    """Unit projection of (G - x) onto the plane of face f; zeros if degenerate."""
    dx = gx - x
    dy = gy - y
    dz = gz - z
    nx = FN[f, 0]
    ny = FN[f, 1]
    nz = FN[f, 2]
    dn = dx * nx + dy * ny + dz * nz
    dx -= dn * nx
    dy -= dn * ny
    dz -= dn * nz
    s = np.sqrt(dx * dx + dy * dy + dz * dz)
    if s < 1e-300:
        return 0.0, 0.0, 0.0
    return dx / s, dy / s, dz / s


@njit(**INNER)
def exit_distance(V, T, FN, f, x, y, z, dx, dy, dz):
    """Distance along the in-plane unit direction d from x to the boundary of face f.

    Returns (distance, k) with k the edge index (corners k, k+1) crossed; (inf, -1) if none.
    Uses the gradients of the barycentric functions: grad b_i = n x e_i / (2A).
    """
    b0, b1, b2 = barycentric(V, T, f, x, y, z)
    return exit_distance_at(V, T, FN, f, b0, b1, b2, face_double_area(V, T, f), dx, dy, dz)


@njit(**INNER)
def exit_distance_at(V, T, FN, f, b0, b1, b2, two_area, dx, dy, dz):
    """``exit_distance`` from the point's barycentric coordinates (b0, b1, b2) on face f and the
    face's double area, when the walk already has them."""
    best = np.inf
    edge = -1
    # a face of no area is left at once, across the edge the direction leaves by (t = 0)
    two_area = max(two_area, 1e-300)
    nx = FN[f, 0]
    ny = FN[f, 1]
    nz = FN[f, 2]
    for i in range(3):
        j = T[f, (i + 1) % 3]
        k = T[f, (i + 2) % 3]
        # edge opposite corner i, oriented from corner i+1 to corner i+2
        ex = V[k, 0] - V[j, 0]
        ey = V[k, 1] - V[j, 1]
        ez = V[k, 2] - V[j, 2]
        # n x e
        cx = ny * ez - nz * ey
        cy = nz * ex - nx * ez
        cz = nx * ey - ny * ex
        rate = (cx * dx + cy * dy + cz * dz) / two_area
        if rate < -1e-14:
            if i == 0:
                b = b0
            elif i == 1:
                b = b1
            else:
                b = b2
            t = b / (-rate)
            if t < 0.0:
                t = 0.0
            if t < best:
                best = t
                edge = (i + 1) % 3
    return best, edge


@njit(**INNER)
def tangency_root(V, T, CN, f, x, y, z, dx, dy, dz, h, g_lo, g_hi, gex, gey, gez):
    """Smallest-bracket end ``t`` in [0, h] with ``g(x + t d) >= 0``, given g(0) = g_lo < 0 <= g_hi = g(h).

    Regula falsi with the Illinois modification (the retained end's value is halved when the same
    end is kept twice, so the bracket shrinks from both sides; superlinear, order about 1.44):
    along one face ``g`` is a smooth, nearly linear function of ``t`` (the normal is a normalised
    linear blend), so a handful of evaluations reach the bracket width 1e-13 m that bisection
    needed about 40 for. Returns the end where ``g >= 0``, so the free yarn never cuts in.
    """
    q = face_basis(V, T, f)
    lo = 0.0
    hi = h
    side = 0
    for _it in range(100):
        if hi - lo < 1e-13:
            break
        den = g_hi - g_lo
        mid = hi - g_hi * (hi - lo) / den if den > 0.0 else 0.5 * (lo + hi)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        px = x + mid * dx
        py = y + mid * dy
        pz = z + mid * dz
        b0, b1, b2 = barycentric_in(q, px, py, pz)
        nx, ny, nz = blended_normal(CN, f, b0, b1, b2)
        gm = (gex - px) * nx + (gey - py) * ny + (gez - pz) * nz      # tangency_gap
        if gm >= 0.0:
            hi = mid
            g_hi = gm
            if side == 1:
                g_lo *= 0.5
            side = 1
            if gm == 0.0:
                break
        else:
            lo = mid
            g_lo = gm
            if side == -1:
                g_hi *= 0.5
            side = -1
    return hi


@njit(cache=True)
def walk_to_tangency(V, T, FN, CN, NB, x, y, z, f, gmx, gmy, gmz, gex, gey, gez, h_max, max_len):
    """Walk the fell point over the surface until the free yarn is tangent (docs/theory.md §3).

    The walking direction is the surface projection of the free yarn towards ``G_mid`` (the supply
    point at the middle of the time step: midpoint rule, second order in time); tangency is tested
    against ``G_end`` (the supply point at the end of the step). Sub-steps of at most ``h_max`` use
    the direction at their own midpoint; the last one is cut at the root of ``g`` by bisection.

    The face's barycentric basis (``face_basis``) and double area, and the point's barycentric
    coordinates, are kept from one use to the next (the same values the helpers would compute
    again).

    Returns (x, y, z, face, status, walked_length).
    """
    q = face_basis(V, T, f)
    b0, b1, b2 = barycentric_in(q, x, y, z)
    nx, ny, nz = blended_normal(CN, f, b0, b1, b2)
    g_prev = (gex - x) * nx + (gey - y) * ny + (gez - z) * nz       # tangency_gap
    if g_prev >= 0.0:
        return x, y, z, f, WALK_LIFTOFF, 0.0
    two_area = face_double_area(V, T, f)
    walked = 0.0
    for _ in range(_MAX_SUBSTEPS):
        if walked >= max_len:
            return x, y, z, f, WALK_BUDGET, walked
        dx, dy, dz = walk_direction(FN, f, x, y, z, gmx, gmy, gmz)
        if dx == 0.0 and dy == 0.0 and dz == 0.0:
            return x, y, z, f, WALK_DEGENERATE, walked
        t_exit, edge = exit_distance_at(V, T, FN, f, b0, b1, b2, two_area, dx, dy, dz)
        h = min(h_max, t_exit, max_len - walked)
        # midpoint direction of this sub-step
        mx, my, mz = walk_direction(FN, f, x + 0.5 * h * dx, y + 0.5 * h * dy, z + 0.5 * h * dz,
                                    gmx, gmy, gmz)
        if not (mx == 0.0 and my == 0.0 and mz == 0.0):
            dx, dy, dz = mx, my, mz
            t_exit, edge = exit_distance_at(V, T, FN, f, b0, b1, b2, two_area, dx, dy, dz)
            h = min(h_max, t_exit, max_len - walked)
        x1 = x + h * dx
        y1 = y + h * dy
        z1 = z + h * dz
        c0, c1, c2 = barycentric_in(q, x1, y1, z1)
        nx, ny, nz = blended_normal(CN, f, c0, c1, c2)
        g1 = (gex - x1) * nx + (gey - y1) * ny + (gez - z1) * nz     # tangency_gap at x1
        if g1 >= 0.0:
            hi = tangency_root(V, T, CN, f, x, y, z, dx, dy, dz, h, g_prev, g1, gex, gey, gez)
            return x + hi * dx, y + hi * dy, z + hi * dz, f, WALK_TANGENT, walked + hi
        if g1 < g_prev - 1e-12 * (1.0 + abs(g_prev)) and h > 0.0:
            return x1, y1, z1, f, WALK_CONCAVE, walked + h
        walked += h
        x, y, z = x1, y1, z1
        b0, b1, b2 = c0, c1, c2
        g_prev = g1
        if h >= t_exit and edge >= 0:
            nf = NB[f, edge]
            if nf < 0:
                return x, y, z, f, WALK_BOUNDARY, walked
            f = nf
            q = face_basis(V, T, f)
            b0, b1, b2 = barycentric_in(q, x, y, z)
            two_area = face_double_area(V, T, f)
    return x, y, z, f, WALK_BUDGET, walked


@njit(cache=True)
def advance_fell_points(V, T, FN, CN, NB, F, face, G_mid, G_end, active, h_max, max_len,
                        F_out, face_out, status_out, walked_out):
    """One time step of every active yarn's fell point (mandrel frame).

    F (ny, 3), face (ny,), G_mid / G_end (ny, 3) supply points at the middle / end of the step,
    active (ny,) bool. Writes F_out, face_out, status_out (WALK_*), walked_out (m).
    """
    for k in range(F.shape[0]):
        if not active[k]:
            F_out[k, 0] = F[k, 0]
            F_out[k, 1] = F[k, 1]
            F_out[k, 2] = F[k, 2]
            face_out[k] = face[k]
            status_out[k] = WALK_LIFTOFF
            walked_out[k] = 0.0
            continue
        x, y, z, f, status, walked = walk_to_tangency(
            V, T, FN, CN, NB, F[k, 0], F[k, 1], F[k, 2], face[k],
            G_mid[k, 0], G_mid[k, 1], G_mid[k, 2], G_end[k, 0], G_end[k, 1], G_end[k, 2],
            h_max, max_len)
        F_out[k, 0] = x
        F_out[k, 1] = y
        F_out[k, 2] = z
        face_out[k] = f
        status_out[k] = status
        walked_out[k] = walked


@njit(cache=True)
def smooth_normals_batch(V, T, CN, faces, points, out):
    """Smooth unit normals of points (m, 3) on faces (m,) into out (m, 3)."""
    for i in range(points.shape[0]):
        nx, ny, nz = smooth_normal(V, T, CN, faces[i], points[i, 0], points[i, 1], points[i, 2])
        out[i, 0] = nx
        out[i, 1] = ny
        out[i, 2] = nz


@njit(cache=True)
def lifted_points(V, T, CN, faces, points, clearance, out):
    """points (m, 3) on faces (m,) lifted along their smooth normal: ``p + clearance[i] n(p)``
    (clearance (m,), m: each yarn's), into out (m, 3) (where the catch test's free yarn starts)."""
    for i in range(points.shape[0]):
        nx, ny, nz = smooth_normal(V, T, CN, faces[i], points[i, 0], points[i, 1], points[i, 2])
        out[i, 0] = points[i, 0] + clearance[i] * nx
        out[i, 1] = points[i, 1] + clearance[i] * ny
        out[i, 2] = points[i, 2] + clearance[i] * nz


# ---------------------------------------------------------------- braid angles of laid yarn
# Post-processing of a run (``preform.laid``): per point, the centerline tangent at its arc
# length s (linear blend of the polyline's vertex tangents, as ``Centerline.frames_at``), the
# smooth normal n, and the braid angle between a direction d and t, both projected on the tangent
# plane: alpha = arccos(|d_p . t_p| / (|d_p| |t_p|)); the kernels give the cosine, NumPy takes the
# arccos (its vectorised arccos and libm's differ in the last bit). The operations follow the NumPy
# reference (``tests/support/naive_analysis.py``) in order, so the results agree to the last bit.


@njit(**INNER)
def centerline_tangent(S, CT, s):
    """Unit tangent at arc length s of a polyline with arc lengths S (n,), vertex tangents CT (n, 3)."""
    n = S.shape[0]
    lo = 0
    hi = n
    while lo < hi:                      # searchsorted(S, s, side="right")
        mid = (lo + hi) // 2
        if S[mid] <= s:
            lo = mid + 1
        else:
            hi = mid
    i = min(max(lo - 1, 0), n - 2)
    ds = S[i + 1] - S[i]
    u = (s - S[i]) / ds if ds > 0.0 else 0.0      # a repeated centerline point: its tangent
    w = min(max(u, 0.0), 1.0)
    tx = (1 - w) * CT[i, 0] + w * CT[i + 1, 0]
    ty = (1 - w) * CT[i, 1] + w * CT[i + 1, 1]
    tz = (1 - w) * CT[i, 2] + w * CT[i + 1, 2]
    tn = np.sqrt(tx * tx + ty * ty + tz * tz)
    if not tn > 0.0:                                # opposite vertex tangents: the first
        return CT[i, 0], CT[i, 1], CT[i, 2]
    return tx / tn, ty / tn, tz / tn


@njit(**INNER)
def braid_angle_cos(dx, dy, dz, tx, ty, tz, nx, ny, nz):
    """cos of the braid angle, |d_p . t_p| / (|d_p| |t_p|) (1 where either projection vanishes
    gives 0), of direction d against tangent t, both projected normal to n."""
    dn = dx * nx + dy * ny + dz * nz
    px = dx - dn * nx
    py = dy - dn * ny
    pz = dz - dn * nz
    tdn = tx * nx + ty * ny + tz * nz
    qx = tx - tdn * nx
    qy = ty - tdn * ny
    qz = tz - tdn * nz
    pl = np.sqrt(px * px + py * py + pz * pz)
    ql = np.sqrt(qx * qx + qy * qy + qz * qz)
    den = pl * ql
    if not den > 0:
        den = 1.0
    return abs(px * qx + py * qy + pz * qz) / den


@njit(cache=True)
def braid_cosines_batch(V, T, CN, S, CT, points, faces, s, directions, out):
    """cos of the braid angle (``braid_angle_cos``) at points (m, 3) on faces (m,) with arc
    lengths s (m,) of directions (m, 3) against the centerline tangent, into out (m,)."""
    for i in range(points.shape[0]):
        tx, ty, tz = centerline_tangent(S, CT, s[i])
        nx, ny, nz = smooth_normal(V, T, CN, faces[i], points[i, 0], points[i, 1], points[i, 2])
        out[i] = braid_angle_cos(directions[i, 0], directions[i, 1], directions[i, 2],
                                 tx, ty, tz, nx, ny, nz)


@njit(cache=True)
def laid_yarn_angles(V, T, CN, S, CT, points, faces, s, prev_i, next_i, mu, curvature_tol,
                     cosines, slip):
    """cos of the braid angle and slip tendency of laid yarn (``laid.laid_braid_angles``).

    points (m, 3), faces (m,), s (m,) arc lengths; prev_i / next_i (m,) the neighbours along the
    yarn (the point itself at the ends). Direction: the chord points[next] - points[prev], or the
    centerline tangent where it is zero. Slip: |kappa_g| > mu |kappa_n| + curvature_tol with
    kvec = (t2 - t1) / ((l1 + l2) / 2), kappa_g = kvec . (n x tm), kappa_n = (n_b - n_a) . tm /
    (l1 + l2), tm the unit mean of the chord directions t1, t2 (points with l1, l2 > 0 only).
    The smooth normal of every point is evaluated once (each point is also its neighbours'
    neighbour).
    """
    normals = np.empty((points.shape[0], 3))
    for i in range(points.shape[0]):
        nx, ny, nz = smooth_normal(V, T, CN, faces[i], points[i, 0], points[i, 1], points[i, 2])
        normals[i, 0] = nx
        normals[i, 1] = ny
        normals[i, 2] = nz
    for i in range(points.shape[0]):
        a = prev_i[i]
        b = next_i[i]
        px = points[i, 0]
        py = points[i, 1]
        pz = points[i, 2]
        dx = points[b, 0] - points[a, 0]
        dy = points[b, 1] - points[a, 1]
        dz = points[b, 2] - points[a, 2]
        tx, ty, tz = centerline_tangent(S, CT, s[i])
        nx = normals[i, 0]
        ny = normals[i, 1]
        nz = normals[i, 2]
        if np.sqrt(dx * dx + dy * dy + dz * dz) == 0:
            dx, dy, dz = tx, ty, tz
        cosines[i] = braid_angle_cos(dx, dy, dz, tx, ty, tz, nx, ny, nz)
        e1x = px - points[a, 0]
        e1y = py - points[a, 1]
        e1z = pz - points[a, 2]
        e2x = points[b, 0] - px
        e2y = points[b, 1] - py
        e2z = points[b, 2] - pz
        l1 = np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
        l2 = np.sqrt(e2x * e2x + e2y * e2y + e2z * e2z)
        slip[i] = False
        if not (l1 > 0 and l2 > 0):
            continue
        t1x = e1x / l1
        t1y = e1y / l1
        t1z = e1z / l1
        t2x = e2x / l2
        t2y = e2y / l2
        t2z = e2z / l2
        mx = t1x + t2x
        my = t1y + t2y
        mz = t1z + t2z
        ml = max(np.sqrt(mx * mx + my * my + mz * mz), 1e-300)
        mx /= ml
        my /= ml
        mz /= ml
        half = 0.5 * (l1 + l2)
        kx = (t2x - t1x) / half
        ky = (t2y - t1y) / half
        kz = (t2z - t1z) / half
        cx = ny * mz - nz * my
        cy = nz * mx - nx * mz
        cz = nx * my - ny * mx
        kappa_g = kx * cx + ky * cy + kz * cz
        kappa_n = ((normals[b, 0] - normals[a, 0]) * mx + (normals[b, 1] - normals[a, 1]) * my
                   + (normals[b, 2] - normals[a, 2]) * mz) / (l1 + l2)
        slip[i] = abs(kappa_g) > mu[i] * abs(kappa_n) + curvature_tol
