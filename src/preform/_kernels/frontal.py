"""Numba kernels of the iterative frontal solver (paper §2.4, Fig. 10; DESIGN.md §3.3).

Arrays and scalars only; the layout of the crossing arrays is documented in
``preform/interaction/zone_state.py`` (creation order, ``low``/``up`` links, ``over``, ``normal``).
The slow NumPy twins live in ``tests/naive_frontal.py``.

Single contact, the reading of DESIGN.md §3.3 ("positions drive forces"). Given a crossing's
virtual fixed points ``A_X``, ``A_O`` (its lower neighbours' yarn centerline points shifted by the
thickness offset, paper eq. 16) and the external resultant ``S = f_X^ext u_X^ext + f_O^ext u_O^ext``
(tensions and directions towards the upper neighbours), pair balance puts the crossing in the plane
through ``A_X, A_O`` that contains ``S``. In that plane, with ``e1 = (A_O - A_X) / b`` and ``e2``
the unit part of ``S`` normal to ``e1``, the Eulerian angles are ``theta_X`` (at ``A_X`` between
``e1`` and ``A_X -> C``) and ``theta_O`` (at ``A_O`` between ``-e1`` and ``A_O -> C``), and

    C = A_X + b sin(theta_O) / sin(theta_X + theta_O) (cos theta_X e1 + sin theta_X e2),
    f_X^int = |S| sin(theta_O + sigma) / sin(theta_X + theta_O),
    f_O^int = |S| sin(sigma - theta_X) / sin(theta_X + theta_O),

``sigma = atan2(S.e2, S.e1)`` (decomposition of ``-S`` along the two internal directions).

Friction (Amontons in the yarn's Eulerian frame, paper eqs. 5-8), written with the yarn's deflection
``delta`` at the crossing: ``Psi = |f_int - f_ext| cos(delta/2) - mu (f_int + f_ext) sin(delta/2)``.
Predictor: both angles from the last converged step (stick). A yarn with ``Psi > 0`` slips: its
internal tension goes on the bound of the friction cone on the side of the predictor's imbalance,
``f_int = f_ext (1 +/- mu tan(delta/2)) / (1 -/+ mu tan(delta/2))``, and the angle(s) follow in closed
form (one yarn slipping: the other angle is kept and ``sin(theta_X + theta_O)`` follows from the
tension; both slipping: the force triangle ``S = -f_X u_X - f_O u_O`` by the law of cosines). The
bound depends on ``delta`` and so on the angles: a short fixed-point loop (exact in one pass with
``mu = 0``). Case 1/2 are followed by a check of the other yarn (paper Fig. 6), which may lead to
case 3.

Frontal sweeps. The force sweep runs over the crossings newest first (supply side to fell points:
on every yarn the upper neighbour comes first) and solves each contact with the single-contact
kernel ``_kernels.contact.solve_crossing`` at the positions of the current iterate, storing angles,
tensions and ``S``; the position sweep runs oldest first and places every crossing from its
(already moved) lower neighbours with those angles and ``S`` (the paper's two-line intersection,
eqs. 14-15). One pair of sweeps is a map ``C -> G(C)``; ``frontal_solve`` iterates it with
minimum-residual (Anderson type-1) mixing, our reading of paper eq. 17: the next iterate is
``G_h + lambda (G_h - G_{h-1})`` with ``lambda`` minimising ``|r_h + lambda (r_h - r_{h-1})|^2``,
``r = G(C) - C``, until the largest undamped move ``< eps``.

Two additions of ours, found necessary for convergence (plain sweeps diverge on a row just created
at the supply side):

* per-crossing under-relaxation: the position sweep moves a crossing by ``w (C_new - C)``,
  ``w = l_up / (l_up + l_low)`` (shortest upper segment, longest lower one; floor ``RELAX_MIN``),
  because a move of the crossing turns its short upper segments and so ``S`` by about ``|C A| /
  |C B|`` times more;
* return mapping along the iteration: after each force sweep the stick predictor ``theta_ref``
  becomes the angles just solved, so a yarn that slipped sticks where it slipped to unless the
  friction bound is exceeded again (no stick/slip cycling between sweeps; ``Psi <= 0`` holds at
  the fixed point either way).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import contact as CK

#: fixed-point passes of the slip bound (tension bound depends on the deflection)
SLIP_ITERATIONS = 40
#: stop the slip loop when the angles change less than this (rad)
SLIP_ANGLE_TOL = 1e-13
#: floor of the per-crossing under-relaxation factor of the position sweep
RELAX_MIN = 0.02
#: angles are kept inside (ANGLE_MARGIN, pi - ANGLE_MARGIN)
ANGLE_MARGIN = 1e-9


@njit(cache=True)
def tensions(smag, sigma, thx, tho):
    """Internal tensions (f_X, f_O) that balance |S| at angle sigma for the angles (thx, tho)."""
    d = math.sin(thx + tho)
    if d < 1e-300:
        d = 1e-300
    return smag * math.sin(tho + sigma) / d, smag * math.sin(sigma - thx) / d


@njit(cache=True)
def half_deflection(cos_beta):
    """(cos(delta/2), sin(delta/2)) of a yarn whose two segments make the angle beta (cos given);
    delta = pi - beta is the deflection (0 for a straight yarn)."""
    c = 0.5 * (1.0 - cos_beta)
    s = 0.5 * (1.0 + cos_beta)
    return math.sqrt(c if c > 0.0 else 0.0), math.sqrt(s if s > 0.0 else 0.0)


@njit(cache=True)
def slip_function(f_int, f_ext, cos_beta, mu):
    """Psi = |F^t| - mu |F^n| (paper eq. 5), N, from the tensions and the deflection."""
    c, s = half_deflection(cos_beta)
    return abs(f_int - f_ext) * c - mu * (f_int + f_ext) * s


@njit(cache=True)
def cone_bound(f_ext, cos_beta, mu, direction):
    """Internal tension on the bound of the friction cone, side ``direction`` (+1: f_int > f_ext)."""
    c, s = half_deflection(cos_beta)
    if c <= 0.0:
        return f_ext
    mt = mu * s / c
    if direction > 0:
        if mt >= 1.0:
            return 1e300
        return f_ext * (1.0 + mt) / (1.0 - mt)
    if mt >= 1.0:
        return 0.0
    return f_ext * (1.0 - mt) / (1.0 + mt)


@njit(cache=True)
def _cos_beta_x(thx, p1x, p2x):
    # u_int_X = -(cos thx e1 + sin thx e2); p = (e1, e2) . u_ext_X
    return -(math.cos(thx) * p1x + math.sin(thx) * p2x)


@njit(cache=True)
def _cos_beta_o(tho, p1o, p2o):
    # u_int_O = cos tho e1 - sin tho e2
    return math.cos(tho) * p1o - math.sin(tho) * p2o


@njit(cache=True)
def _clamp_angle(a):
    if a < ANGLE_MARGIN:
        return ANGLE_MARGIN
    if a > math.pi - ANGLE_MARGIN:
        return math.pi - ANGLE_MARGIN
    return a


@njit(cache=True)
def _one_angle_for_tension(f_target, smag, sigma, th_other, th_near):
    """The angle of the slipping yarn (the other angle fixed) that gives it tension f_target.

    f = |S| sin(th_other + sigma) / sin(th + th_other): two roots in (0, pi - th_other); the one
    nearest ``th_near`` (continuity from the predictor)."""
    q = smag * math.sin(th_other + sigma) / f_target if f_target > 0.0 else 2.0
    if q >= 1.0:
        a = 0.5 * math.pi
    elif q <= 0.0:
        a = ANGLE_MARGIN
    else:
        a = math.asin(q)
    r1 = _clamp_angle(a - th_other)
    r2 = _clamp_angle(math.pi - a - th_other)
    return r1 if abs(r1 - th_near) <= abs(r2 - th_near) else r2


@njit(cache=True)
def _both_angles_for_tensions(fx, fo, smag, sigma):
    """Angles for given tensions of both yarns: the force triangle S = -f_X u_X - f_O u_O."""
    fx = max(fx, 1e-150)
    fo = max(fo, 1e-150)
    smag = max(smag, 1e-150)
    ca = (fx * fx + fo * fo - smag * smag) / (2.0 * fx * fo)
    ca = min(1.0, max(-1.0, ca))
    a = math.acos(ca)
    cp = (fx * fx + smag * smag - fo * fo) / (2.0 * fx * smag)
    cp = min(1.0, max(-1.0, cp))
    thx = _clamp_angle(sigma - math.acos(cp))
    tho = _clamp_angle(a - thx)
    return thx, tho


@njit(cache=True)
def solve_contact(smag, sigma, thx_ref, tho_ref, fxe, foe, p1x, p2x, p1o, p2o, mu, psi_tol):
    """One crossing in its plane (module docstring): stick predictor, slip corrector (Fig. 6).

    smag, sigma : |S| (N) and its angle from e1 (rad); thx_ref, tho_ref : predictor angles (rad);
    fxe, foe : external tensions (N); p1x, p2x : e1 . u_X^ext, e2 . u_X^ext (same for O); mu;
    psi_tol : relative tolerance of Psi > 0 (times f_int + f_ext).
    Returns thx, tho, f_X, f_O, slip_X, slip_O (0 stick, +1/-1 slipping, side of f_int - f_ext).
    """
    thx = thx_ref
    tho = tho_ref
    fx, fo = tensions(smag, sigma, thx, tho)
    cbx = _cos_beta_x(thx, p1x, p2x)
    cbo = _cos_beta_o(tho, p1o, p2o)
    sx = 0
    so = 0
    if slip_function(fx, fxe, cbx, mu) > psi_tol * (abs(fx) + fxe):
        sx = 1 if fx > fxe else -1
    if slip_function(fo, foe, cbo, mu) > psi_tol * (abs(fo) + foe):
        so = 1 if fo > foe else -1
    if sx == 0 and so == 0:
        return thx, tho, fx, fo, 0, 0
    if so == 0:   # case 2: the warp slips, the weft sticks
        for _ in range(SLIP_ITERATIONS):
            target = cone_bound(fxe, _cos_beta_x(thx, p1x, p2x), mu, sx)
            new = _one_angle_for_tension(target, smag, sigma, tho, thx_ref)
            done = abs(new - thx) < SLIP_ANGLE_TOL
            thx = new
            if done:
                break
        fx, fo = tensions(smag, sigma, thx, tho)
        if slip_function(fo, foe, _cos_beta_o(tho, p1o, p2o), mu) > psi_tol * (abs(fo) + foe):
            so = 1 if fo > foe else -1
    elif sx == 0:  # case 1: the weft slips, the warp sticks
        for _ in range(SLIP_ITERATIONS):
            target = cone_bound(foe, _cos_beta_o(tho, p1o, p2o), mu, so)
            new = _one_angle_for_tension(target, smag, -sigma + math.pi, thx, tho_ref)
            done = abs(new - tho) < SLIP_ANGLE_TOL
            tho = new
            if done:
                break
        fx, fo = tensions(smag, sigma, thx, tho)
        if slip_function(fx, fxe, _cos_beta_x(thx, p1x, p2x), mu) > psi_tol * (abs(fx) + fxe):
            sx = 1 if fx > fxe else -1
    if sx != 0 and so != 0:  # case 3: both slip
        for _ in range(SLIP_ITERATIONS):
            tx = cone_bound(fxe, _cos_beta_x(thx, p1x, p2x), mu, sx)
            to = cone_bound(foe, _cos_beta_o(tho, p1o, p2o), mu, so)
            nx, no = _both_angles_for_tensions(tx, to, smag, sigma)
            done = abs(nx - thx) + abs(no - tho) < SLIP_ANGLE_TOL
            thx = nx
            tho = no
            if done:
                break
        fx, fo = tensions(smag, sigma, thx, tho)
    return thx, tho, fx, fo, sx, so


@njit(cache=True)
def _yarn_point(pos, normal, over, c, side, h, out):
    """Centerline point of yarn ``side`` at crossing ``c`` into out (3,)."""
    s = over[c] if side == 0 else -over[c]
    out[0] = pos[c, 0] + s * h * normal[c, 0]
    out[1] = pos[c, 1] + s * h * normal[c, 1]
    out[2] = pos[c, 2] + s * h * normal[c, 2]


@njit(cache=True)
def _plane(ax, ay, az, ox, oy, oz, sx, sy, sz, gx, gy, gz):
    """e1 (A_X -> A_O), b, e2 (unit part of S normal to e1; fallback g if S is along e1), s1, s2."""
    dx = ox - ax
    dy = oy - ay
    dz = oz - az
    b = math.sqrt(dx * dx + dy * dy + dz * dz)
    if b < 1e-300:
        b = 1e-300
    e1x = dx / b
    e1y = dy / b
    e1z = dz / b
    s1 = sx * e1x + sy * e1y + sz * e1z
    px = sx - s1 * e1x
    py = sy - s1 * e1y
    pz = sz - s1 * e1z
    s2 = math.sqrt(px * px + py * py + pz * pz)
    smag = math.sqrt(sx * sx + sy * sy + sz * sz)
    if s2 <= 1e-12 * smag or s2 < 1e-300:
        g1 = gx * e1x + gy * e1y + gz * e1z
        px = gx - g1 * e1x
        py = gy - g1 * e1y
        pz = gz - g1 * e1z
        gn = math.sqrt(px * px + py * py + pz * pz)
        if gn < 1e-300:
            gn = 1e-300
        e2x = px / gn
        e2y = py / gn
        e2z = pz / gn
        s2 = sx * e2x + sy * e2y + sz * e2z
    else:
        e2x = px / s2
        e2y = py / s2
        e2z = pz / s2
    return e1x, e1y, e1z, b, e2x, e2y, e2z, s1, s2


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
        if c >= 0:
            _yarn_point(pos, normal, over, c, 0 if k < n else 1, h, p)
        else:
            p[0] = fell[k, 0]
            p[1] = fell[k, 1]
            p[2] = fell[k, 2]
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
def force_sweep(m, first, n_yarns, yarn, pos, normal, over, theta_ref, low, up, fell, top, f_top,
                h, mu, psi_tol, theta, slip, tension, resultant, relax):
    """Supply side -> fell points over crossings m-1 .. first (module docstring).

    Each crossing is solved by ``_kernels.contact.solve_crossing`` (the single-contact kernel),
    with the in-plane ``solve_contact`` here as the fallback where that reports a degenerate case;
    returns the number of fallbacks. Updates normal (outward unit normal of the two yarn directions), theta, slip, tension (the
    segment below, per side) and resultant (S) of the active crossings; reads pos.
    """
    n = n_yarns // 2
    B = np.empty((2, 3))
    Q = np.empty((2, 3))
    fe = np.empty(2)
    q = np.empty(3)
    buf = np.empty(CK.OUT_SIZE)
    fallbacks = 0
    for c in range(m - 1, first - 1, -1):
        for side in range(2):
            k = yarn[c, side]
            u = up[c, side]
            if u >= 0:
                _yarn_point(pos, normal, over, u, side, h, q)
                fe[side] = tension[u, side]
            else:
                q[0] = top[k, 0]
                q[1] = top[k, 1]
                q[2] = top[k, 2]
                fe[side] = f_top[k]
            B[side, 0] = q[0]
            B[side, 1] = q[1]
            B[side, 2] = q[2]
            lo = low[c, side]
            if lo >= 0:
                _yarn_point(pos, normal, over, lo, side, h, q)
            else:
                q[0] = fell[k, 0]
                q[1] = fell[k, 1]
                q[2] = fell[k, 2]
            Q[side, 0] = q[0]
            Q[side, 1] = q[1]
            Q[side, 2] = q[2]
        # contact normal: outward normal of the two yarn directions (lower -> upper neighbour)
        dxx = B[0, 0] - Q[0, 0]
        dxy = B[0, 1] - Q[0, 1]
        dxz = B[0, 2] - Q[0, 2]
        dox = B[1, 0] - Q[1, 0]
        doy = B[1, 1] - Q[1, 1]
        doz = B[1, 2] - Q[1, 2]
        nx = dxy * doz - dxz * doy
        ny = dxz * dox - dxx * doz
        nz = dxx * doy - dxy * dox
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nn > 1e-300:
            if nx * pos[c, 0] + ny * pos[c, 1] < 0.0:
                nn = -nn
            normal[c, 0] = nx / nn
            normal[c, 1] = ny / nn
            normal[c, 2] = nz / nn
        ov = over[c]
        # yarn points at c, virtual fixed points A (eq. 16) and external unit vectors
        sgx = ov * h
        sgo = -ov * h
        pxx = pos[c, 0] + sgx * normal[c, 0]
        pxy = pos[c, 1] + sgx * normal[c, 1]
        pxz = pos[c, 2] + sgx * normal[c, 2]
        pox = pos[c, 0] + sgo * normal[c, 0]
        poy = pos[c, 1] + sgo * normal[c, 1]
        poz = pos[c, 2] + sgo * normal[c, 2]
        axx = Q[0, 0] - sgx * normal[c, 0]
        axy = Q[0, 1] - sgx * normal[c, 1]
        axz = Q[0, 2] - sgx * normal[c, 2]
        aox = Q[1, 0] - sgo * normal[c, 0]
        aoy = Q[1, 1] - sgo * normal[c, 1]
        aoz = Q[1, 2] - sgo * normal[c, 2]
        uxx = B[0, 0] - pxx
        uxy = B[0, 1] - pxy
        uxz = B[0, 2] - pxz
        lux = max(math.sqrt(uxx * uxx + uxy * uxy + uxz * uxz), 1e-300)
        l = lux
        uxx /= l
        uxy /= l
        uxz /= l
        uox = B[1, 0] - pox
        uoy = B[1, 1] - poy
        uoz = B[1, 2] - poz
        luo = max(math.sqrt(uox * uox + uoy * uoy + uoz * uoz), 1e-300)
        l = luo
        uox /= l
        uoy /= l
        uoz /= l
        # under-relaxation of the position update: a crossing's move is amplified about
        # |C A| / |C B| by the sweep (short upper segments near the supply side)
        lxa = math.sqrt((pxx - axx) ** 2 + (pxy - axy) ** 2 + (pxz - axz) ** 2)
        loa = math.sqrt((pox - aox) ** 2 + (poy - aoy) ** 2 + (poz - aoz) ** 2)
        l_up = min(lux, luo)
        relax[c] = max(RELAX_MIN, l_up / (l_up + max(lxa, loa)))
        sx = fe[0] * uxx + fe[1] * uox
        sy = fe[0] * uxy + fe[1] * uoy
        sz = fe[0] * uxz + fe[1] * uoz
        status = CK.solve_crossing(axx, axy, axz, aox, aoy, aoz,
                                   fe[0] * uxx, fe[0] * uxy, fe[0] * uxz,
                                   fe[1] * uox, fe[1] * uoy, fe[1] * uoz,
                                   theta_ref[c, 0], theta_ref[c, 1], mu, buf)
        if status == CK.CROSSING_OK:
            thx = buf[CK.OUT_THETA_X]
            tho = buf[CK.OUT_THETA_O]
            fx = buf[CK.OUT_F_X]
            fo = buf[CK.OUT_F_O]
            slx = int(buf[CK.OUT_SLIDE_X])
            slo = int(buf[CK.OUT_SLIDE_O])
        else:
            # degenerate for the single-contact kernel (S along A_X A_O, rays not meeting,
            # compression...): the clamped in-plane solve keeps the iteration going
            e1x, e1y, e1z, b, e2x, e2y, e2z, s1, s2 = _plane(
                axx, axy, axz, aox, aoy, aoz, sx, sy, sz,
                pos[c, 0] - axx, pos[c, 1] - axy, pos[c, 2] - axz)
            smag = math.sqrt(s1 * s1 + s2 * s2)
            sigma = math.atan2(s2, s1)
            p1x = e1x * uxx + e1y * uxy + e1z * uxz
            p2x = e2x * uxx + e2y * uxy + e2z * uxz
            p1o = e1x * uox + e1y * uoy + e1z * uoz
            p2o = e2x * uox + e2y * uoy + e2z * uoz
            thx, tho, fx, fo, slx, slo = solve_contact(smag, sigma, theta_ref[c, 0],
                                                       theta_ref[c, 1], fe[0], fe[1], p1x, p2x,
                                                       p1o, p2o, mu, psi_tol)
            fallbacks += 1
        theta[c, 0] = thx
        theta[c, 1] = tho
        slip[c, 0] = slx
        slip[c, 1] = slo
        tension[c, 0] = fx
        tension[c, 1] = fo
        resultant[c, 0] = sx
        resultant[c, 1] = sy
        resultant[c, 2] = sz
    return fallbacks


@njit(cache=True)
def position_sweep(m, first, yarn, pos, normal, over, theta, low, fell, resultant, relax, h, out):
    """Fell points -> supply side over crossings first .. m-1: two-line intersection in the plane
    of (A_X, A_O, S) with the angles of the force sweep (paper eqs. 14-15). Writes out (m, 3);
    crossings below ``first`` are copied (frozen)."""
    for c in range(first):
        out[c, 0] = pos[c, 0]
        out[c, 1] = pos[c, 1]
        out[c, 2] = pos[c, 2]
    q = np.empty(3)
    a = np.empty((2, 3))
    for c in range(first, m):
        for side in range(2):
            k = yarn[c, side]
            lo = low[c, side]
            if lo >= 0:
                _yarn_point(out, normal, over, lo, side, h, q)
            else:
                q[0] = fell[k, 0]
                q[1] = fell[k, 1]
                q[2] = fell[k, 2]
            sg = over[c] * h if side == 0 else -over[c] * h
            a[side, 0] = q[0] - sg * normal[c, 0]
            a[side, 1] = q[1] - sg * normal[c, 1]
            a[side, 2] = q[2] - sg * normal[c, 2]
        e1x, e1y, e1z, b, e2x, e2y, e2z, s1, s2 = _plane(
            a[0, 0], a[0, 1], a[0, 2], a[1, 0], a[1, 1], a[1, 2],
            resultant[c, 0], resultant[c, 1], resultant[c, 2],
            pos[c, 0] - a[0, 0], pos[c, 1] - a[0, 1], pos[c, 2] - a[0, 2])
        thx = theta[c, 0]
        tho = theta[c, 1]
        l = b * math.sin(tho) / max(math.sin(thx + tho), 1e-300)
        cx = math.cos(thx)
        sx = math.sin(thx)
        w = relax[c]
        out[c, 0] = pos[c, 0] + w * (a[0, 0] + l * (cx * e1x + sx * e2x) - pos[c, 0])
        out[c, 1] = pos[c, 1] + w * (a[0, 1] + l * (cx * e1y + sx * e2y) - pos[c, 1])
        out[c, 2] = pos[c, 2] + w * (a[0, 2] + l * (cx * e1z + sx * e2z) - pos[c, 2])


@njit(cache=True)
def frontal_solve(m, first, n_yarns, yarn, pos, normal, over, theta_ref, low, up, highest, fell,
                  top, spool, h, f_spool, mu, mu_r, has_ring, psi_tol, eps, max_iter, lambda_max,
                  theta, slip, tension, resultant, f_top, work, history):
    """Iterate the two sweeps from ``pos`` until ``max |G(C) - C| < eps`` (m) over the active
    crossings ``first .. m-1`` (module docstring). ``pos`` ends as the last sweep's output.

    work : (3, m, 3) float64 scratch; history : (max_iter,) float64, residual (m) per iteration.
    Returns (iterations, residual, converged).
    """
    g = work[0]
    g_prev = work[1]
    r_prev = work[2]
    relax = np.ones(m)
    residual = np.inf
    it = 0
    while it < max_iter:
        top_tensions(n_yarns, highest, pos, normal, over, fell, top, spool, h, f_spool, mu_r,
                     has_ring, f_top)
        force_sweep(m, first, n_yarns, yarn, pos, normal, over, theta_ref, low, up, fell, top,
                    f_top, h, mu, psi_tol, theta, slip, tension, resultant, relax)
        # return mapping along the iteration: the stick predictor of the next sweep is where the
        # crossing slipped to (keeps Psi <= 0 and stops stick/slip cycling between sweeps)
        for c in range(first, m):
            theta_ref[c, 0] = theta[c, 0]
            theta_ref[c, 1] = theta[c, 1]
        position_sweep(m, first, yarn, pos, normal, over, theta, low, fell, resultant, relax, h, g)
        residual = 0.0
        num = 0.0
        den = 0.0
        for c in range(first, m):
            d2 = 0.0
            for i in range(3):
                r = g[c, i] - pos[c, i]
                d2 += r * r
                dr = r - r_prev[c, i]
                num += r * dr
                den += dr * dr
            d2 /= relax[c] * relax[c]   # the undamped move
            if d2 > residual:
                residual = d2
        residual = math.sqrt(residual)
        history[it] = residual
        it += 1
        if residual < eps:
            for c in range(first, m):
                for i in range(3):
                    pos[c, i] = g[c, i]
            return it, residual, True
        # paper eq. 17 (minimum residual of two successive sweeps), Anderson type-1 form
        lam = 0.0
        if it > 1 and den > 0.0:
            lam = -num / den
            lam = min(lambda_max, max(-lambda_max, lam))
        for c in range(first, m):
            for i in range(3):
                r = g[c, i] - pos[c, i]
                new = g[c, i] + lam * (g[c, i] - g_prev[c, i])
                r_prev[c, i] = r
                g_prev[c, i] = g[c, i]
                pos[c, i] = new
    return it, residual, False
