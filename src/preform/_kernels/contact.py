"""Numba kernel of the single yarn-yarn crossing (paper §2.2, Fig. 5/6; DESIGN.md §3.3).

Scalars in, one float64 output row out, an integer status back: a frontal solver can call
:func:`solve_crossing` from inside its own ``@njit`` loop (``out`` may be a row view of a 2D array).
The public wrapper is ``preform.interaction.contact``; the slow reference is ``tests/naive_contact.py``.

Geometry (DESIGN.md §3.3, "one reading of §2.2"). Lower points ``A_X`` (warp) and ``A_O`` (weft),
already offset by the yarn thickness; external forces ``F_X^ext``, ``F_O^ext`` (tension times the unit
vector from the crossing towards the supply side). With ``S = F_X^ext + F_O^ext``:

* ``e1 = (A_O - A_X) / L``; ``e2`` = unit part of ``S`` normal to ``e1``; ``s1 = S.e1``, ``s2 = |S - s1 e1|``.
  Pair balance ``f_X u_X + f_O u_O = -S`` forces ``C`` into the plane (A_X; e1, e2), on the ``+e2`` side.
* ``theta_X`` = angle at ``A_X`` between ``e1`` and ``A_X->C``; ``theta_O`` = angle at ``A_O`` between
  ``-e1`` and ``A_O->C``; valid when ``theta_X, theta_O > 0`` and ``theta_X + theta_O < pi`` (the two
  rays meet in front). Then ``u_X = -(cos tX e1 + sin tX e2)`` (C->A_X), ``u_O = cos tO e1 - sin tO e2``
  (C->A_O), ``C = A_X + L sin tO / sin(tX + tO) (cos tX e1 + sin tX e2)`` and
  ``f_X = (s2 cos tO + s1 sin tO) / sin(tX + tO)``, ``f_O = (s2 cos tX - s1 sin tX) / sin(tX + tO)``.

Friction (paper eqs. 5-7). For yarn Y in its own Eulerian frame ``n = -(u_int + u_ext)/|.|`` the pull of
its two segments on the crossing, ``F_Y = f_int u_int + f_ext u_ext`` (minus the contact force the other
yarn exerts on Y), splits into ``F^n = (f_int + f_ext) sin(delta/2)`` and ``F^t = (f_int - f_ext)
cos(delta/2)`` along ``t = (u_int - u_ext)/|.|``, with ``delta`` the deflection of Y at C
(``u_int . u_ext = -cos delta``). So
``Psi_Y = |f_int - f_ext| cos(delta/2) - mu (f_int + f_ext) sin(delta/2)``,
which is what this kernel evaluates (no division by ``|u_int + u_ext|``, which vanishes for a straight
yarn); ``tests/test_contact.py`` checks it against the frame form of eq. 7 on random vectors.
``slip_Y = 1`` means Y's tension jump sits on the bound (Y's material slides through C).
Sliding sign ``slide_Y = sign(f_int - f_ext)``: ``+1`` Y slides towards its lower point ``A_Y`` (mandrel
side, higher tension there), ``-1`` towards its supply; ``0`` while sticking.

Pairing of criteria and Eulerian angles. With ``theta_X`` fixed the warp's internal direction and its
deflection are fixed, so ``Psi_X = 0`` fixes ``f_X`` in closed form and pair balance gives ``u_O`` and
``f_O`` (``f_O u_O = -S - f_X u_X``): the warp slip is resolved by moving ``theta_O`` (C slides along
the warp line). This is the paper's case 1, "the weft slips over the warp, solve Psi_s(theta_O) = 0 with
theta_X kept", whose Psi_s the paper writes in the warp's frame (eq. 7: "the warp yarn is the reference
for the sliding direction") and solves "analytically". Symmetrically ``Psi_O`` is resolved by
``theta_X``. Both slipping (case 3): the paper alternates the two closed forms; that fixed-point
iteration stalls or wanders off in a few per cent of random configurations, so here the same pair of
equations is solved as one scalar equation ``g(theta_X) = f_O(theta_X) - bound_O = 0`` (eliminating
``theta_O`` with the closed form): the root a Newton step from the predictor points at is bracketed
(growing steps) and refined by Illinois regula falsi; if that finds no bracket, the root nearest
to the predictor on either side is searched by marching outwards.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# status codes
CROSSING_OK = 0
CROSSING_DEGENERATE = 1        # A_X == A_O, or a zero external force
CROSSING_PARALLEL = 2          # F_X^ext + F_O^ext parallel to A_O - A_X (or zero): no plane
CROSSING_NO_INTERSECTION = 3   # angles give rays that do not meet in front of A_X A_O
CROSSING_NEGATIVE_TENSION = 4  # the solution would put a yarn segment in compression
CROSSING_NO_SLIP_SOLUTION = 5  # no configuration with both yarns on the friction bound

# layout of the output row
OUT_C = 0            # 0..2 crossing position C, m
OUT_F_X = 3          # internal warp tension f_X^int, N
OUT_F_O = 4          # internal weft tension f_O^int, N
OUT_THETA_X = 5      # Eulerian angle theta_X, rad
OUT_THETA_O = 6      # Eulerian angle theta_O, rad
OUT_SLIP_X = 7       # 0 stick, 1 slip (warp tension jump on the bound)
OUT_SLIP_O = 8       # 0 stick, 1 slip (weft)
OUT_PSI_X = 9        # Psi_X, N
OUT_PSI_O = 10       # Psi_O, N
OUT_U_X = 11         # 11..13 unit vector C -> A_X
OUT_U_O = 14         # 14..16 unit vector C -> A_O
OUT_SLIDE_X = 17     # -1, 0, +1 (see module docstring)
OUT_SLIDE_O = 18
OUT_ITERATIONS = 19  # residual evaluations of the both-slip solve
OUT_SIZE = 20

# numerics (kept here: jitted code reads module constants at compile time)
PSI_REL_TOL = 1e-12     # Psi <= this * (f_int + f_ext) counts as sticking
ANGLE_EPS = 1e-12       # rad, margin of the valid angle domain
PARALLEL_REL_TOL = 1e-12  # s2 below this * |S|: S along e1, no plane
SCAN_FIRST_STEP = 1e-3  # rad, first bracket step of the both-slip solve
SCAN_GROWTH = 1.25      # growth of the bracket steps
SCAN_MAX_STEP = 0.05    # rad, largest bracket step
SCAN_MAX = 120
SCAN_EDGE_POINTS = 16   # fine look before the edge of the valid domain
NEWTON_FD_STEP = 1e-7   # rad, finite-difference step of the Newton bracket
NEWTON_OVERSHOOT = 0.1  # the first bracket end lies 10 % beyond the Newton point
NEWTON_EXPANSIONS = 8
ROOT_MAX_ITER = 200
ROOT_REL_TOL = 1e-15    # on g / f_O^ext


@njit(cache=True)
def half_angles(d):
    """cos(delta/2), sin(delta/2) of a yarn's deflection from d = u_int . u_ext = -cos(delta)."""
    c = math.sqrt(max(0.5 * (1.0 - d), 0.0))
    s = math.sqrt(max(0.5 * (1.0 + d), 0.0))
    return c, s


@njit(cache=True)
def psi_tension(f_int, f_ext, d, mu):
    """Psi = |f_int - f_ext| cos(delta/2) - mu (f_int + f_ext) sin(delta/2), N; d = u_int . u_ext."""
    c, s = half_angles(d)
    return abs(f_int - f_ext) * c - mu * (f_int + f_ext) * s


@njit(cache=True)
def slip_tension(f_ext, d, mu, slide):
    """Internal tension on the friction bound for sliding sign ``slide`` (+1: f_int > f_ext), N.

    ``s (f_int - f_ext) cos(delta/2) = mu (f_int + f_ext) sin(delta/2)``; -1.0 when the cone
    self-locks (``mu tan(delta/2) >= 1`` with ``slide = +1``): no slip that way.
    """
    c, s = half_angles(d)
    den = c - slide * mu * s
    if den <= 0.0:
        return -1.0
    return f_ext * (c + slide * mu * s) / den


@njit(cache=True)
def tensions(tx, to, s1, s2):
    """Internal tensions (f_X, f_O), N, of the configuration (tx, to) under the in-plane load (s1, s2)."""
    sn = math.sin(tx + to)
    fx = (s2 * math.cos(to) + s1 * math.sin(to)) / sn
    fo = (s2 * math.cos(tx) - s1 * math.sin(tx)) / sn
    return fx, fo


@njit(cache=True)
def valid_angles(tx, to):
    """True when the rays from A_X and A_O at these angles meet in front of the segment."""
    return tx > ANGLE_EPS and to > ANGLE_EPS and tx + to < math.pi - ANGLE_EPS


@njit(cache=True)
def warp_dot(tx, a1, a2):
    """u_X^int . u_X^ext, with (a1, a2) the in-plane components of u_X^ext."""
    return -(math.cos(tx) * a1 + math.sin(tx) * a2)


@njit(cache=True)
def weft_dot(to, b1, b2):
    """u_O^int . u_O^ext, with (b1, b2) the in-plane components of u_O^ext."""
    return math.cos(to) * b1 - math.sin(to) * b2


@njit(cache=True)
def warp_slips(tx, s1, s2, fxe, a1, a2, mu, slide):
    """Warp on its bound with theta_X kept: returns (ok, theta_O). Closed form (paper case 1)."""
    t = slip_tension(fxe, warp_dot(tx, a1, a2), mu, slide)
    if t < 0.0:
        return False, 0.0
    r1 = -s1 + t * math.cos(tx)  # f_O u_O = -S - f_X u_X
    r2 = -s2 + t * math.sin(tx)
    to = math.atan2(-r2, r1)
    return valid_angles(tx, to), to


@njit(cache=True)
def weft_slips(to, s1, s2, foe, b1, b2, mu, slide):
    """Weft on its bound with theta_O kept: returns (ok, theta_X). Closed form (paper case 2)."""
    t = slip_tension(foe, weft_dot(to, b1, b2), mu, slide)
    if t < 0.0:
        return False, 0.0
    r1 = -s1 - t * math.cos(to)  # f_X u_X = -S - f_O u_O
    r2 = -s2 + t * math.sin(to)
    tx = math.atan2(-r2, -r1)
    return valid_angles(tx, to), tx


@njit(cache=True)
def both_slip_residual(tx, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o):
    """g(theta_X) = (f_O - bound_O) / f_O^ext with the warp on its bound: (ok, g, theta_O)."""
    ok, to = warp_slips(tx, s1, s2, fxe, a1, a2, mu, slide_x)
    if not ok:
        return False, 0.0, 0.0
    t = slip_tension(foe, weft_dot(to, b1, b2), mu, slide_o)
    if t < 0.0:
        return False, 0.0, 0.0
    fx, fo = tensions(tx, to, s1, s2)
    return True, (fo - t) / foe, to


@njit(cache=True)
def _scan_edge(x0, g0, x1, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o):
    """From valid x0 towards invalid x1: sign change of g on a fine grid before the domain edge.

    Returns (found, x_a, g_a, x_b, g_b, evaluations) with x_a, x_b the bracket in the order met.
    """
    xa = x0
    ga = g0
    for k in range(1, SCAN_EDGE_POINTS + 1):
        x = x0 + (x1 - x0) * k / (SCAN_EDGE_POINTS + 1)
        ok, g, to = both_slip_residual(x, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
        if not ok:
            return False, xa, ga, x, 0.0, k
        if g * ga <= 0.0:
            return True, xa, ga, x, g, k
        xa = x
        ga = g
    return False, xa, ga, x1, 0.0, SCAN_EDGE_POINTS


@njit(cache=True)
def _scan_side(tx0, ok0, g0, direction, max_dist, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o):
    """March from tx0 in ``direction`` (+1/-1) with growing steps, up to ``max_dist``, to the first
    sign change of g between valid points; where the march enters or leaves the valid domain the
    step is searched on a fine grid first. Returns (found, x_a, g_a, x_b, g_b, distance, evaluations).
    """
    x_prev = tx0
    g_prev = g0
    ok_prev = ok0
    step = SCAN_FIRST_STEP
    dist = 0.0
    evals = 0
    for _ in range(SCAN_MAX):
        dist += step
        step = min(step * SCAN_GROWTH, SCAN_MAX_STEP)
        x = tx0 + direction * dist
        if x <= 0.0 or x >= math.pi or dist > max_dist:
            break
        ok, g, to = both_slip_residual(x, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
        evals += 1
        if ok and ok_prev and g * g_prev <= 0.0:
            return True, x_prev, g_prev, x, g, dist, evals
        if ok_prev and not ok:  # leaving the valid domain within this step
            found, xa, ga, xb, gb, n = _scan_edge(x_prev, g_prev, x, s1, s2, fxe, foe, a1, a2, b1, b2,
                                                  mu, slide_x, slide_o)
            evals += n
            if found:
                return True, xa, ga, xb, gb, dist, evals
        elif ok and not ok_prev:  # entering it: the root may sit just inside the edge
            found, xa, ga, xb, gb, n = _scan_edge(x, g, x_prev, s1, s2, fxe, foe, a1, a2, b1, b2,
                                                  mu, slide_x, slide_o)
            evals += n
            if found:
                return True, xa, ga, xb, gb, dist, evals
        x_prev = x
        g_prev = g
        ok_prev = ok
    return False, tx0, g0, tx0, g0, math.inf, evals


@njit(cache=True)
def _newton_bracket(tx0, g0, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o):
    """Bracket the root a Newton step from tx0 points at: try tx0 + dx, then 2 dx, 4 dx, ...

    Returns (found, x_a, g_a, x_b, g_b, evaluations). The fast path of :func:`both_slip`.
    """
    h = NEWTON_FD_STEP * (1.0 if tx0 < 0.5 * math.pi else -1.0)
    ok, g1, to = both_slip_residual(tx0 + h, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
    if not ok or g1 == g0:
        return False, tx0, g0, tx0, g0, 1
    dx = -g0 * h / (g1 - g0)
    x_prev = tx0
    g_prev = g0
    evals = 1
    for k in range(NEWTON_EXPANSIONS):
        x = tx0 + dx * (1.0 + NEWTON_OVERSHOOT) * (2.0 ** k)
        if x <= 0.0 or x >= math.pi:
            break
        ok, g, to = both_slip_residual(x, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
        evals += 1
        if ok and g * g_prev <= 0.0:
            return True, x_prev, g_prev, x, g, evals
        if not ok:
            found, xa, ga, xb, gb, n = _scan_edge(x_prev, g_prev, x, s1, s2, fxe, foe, a1, a2, b1, b2,
                                                  mu, slide_x, slide_o)
            return found, xa, ga, xb, gb, evals + n
        x_prev = x
        g_prev = g
    return False, tx0, g0, tx0, g0, evals


@njit(cache=True)
def both_slip(tx0, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o):
    """Case 3: both yarns on their bounds. Returns (ok, tx, to, evaluations).

    The root of g the Newton step from the predictor tx0 points at (bracketed), else the root
    nearest tx0 found by marching outwards on both sides.
    """
    ok0, g0, to0 = both_slip_residual(tx0, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
    evals = 1
    if ok0 and g0 == 0.0:
        return True, tx0, to0, evals
    found = False
    if ok0:
        found, xa, ga, xb, gb, n = _newton_bracket(tx0, g0, s1, s2, fxe, foe, a1, a2, b1, b2, mu,
                                                   slide_x, slide_o)
        evals += n
    if not found:
        f_up, xa, ga, xb, gb, d_up, n = _scan_side(tx0, ok0, g0, 1.0, math.pi, s1, s2, fxe, foe,
                                                   a1, a2, b1, b2, mu, slide_x, slide_o)
        evals += n
        f_dn, xc, gc, xd, gd, d_dn, n = _scan_side(tx0, ok0, g0, -1.0, d_up, s1, s2, fxe, foe,
                                                   a1, a2, b1, b2, mu, slide_x, slide_o)
        evals += n
        if f_dn:
            xa, ga, xb, gb = xc, gc, xd, gd
        elif not f_up:
            return False, tx0, 0.0, evals
    if xa < xb:
        lo, g_a, hi, g_b = xa, ga, xb, gb
    else:
        lo, g_a, hi, g_b = xb, gb, xa, ga
    # Illinois regula falsi on [lo, hi], g(lo) = g_a, g(hi) = g_b, opposite signs
    x = lo
    to = 0.0
    side = 0
    for _ in range(ROOT_MAX_ITER):
        x = (lo * g_b - hi * g_a) / (g_b - g_a)
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        ok, g, to = both_slip_residual(x, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
        evals += 1
        if not ok:  # the domain is not convex in theta_X: give up this bracket
            return False, tx0, 0.0, evals
        if abs(g) <= ROOT_REL_TOL or hi - lo <= 4e-16 * (1.0 + hi):
            break
        if g * g_a < 0.0:
            hi, g_b = x, g
            if side == -1:
                g_a *= 0.5
            side = -1
        else:
            lo, g_a = x, g
            if side == 1:
                g_b *= 0.5
            side = 1
    return True, x, to, evals


@njit(cache=True)
def frictionless_angles(fxx, fxy, fxz, fox, foy, foz, s1, s2):
    """Angles of the mu = 0 equilibrium (f_int = f_ext on both yarns): (ok, tx, to).

    The internal forces are a copy of the external ones mirrored to the other side of -S, so the
    angle between u_X and -S equals the angle a_X between F_X^ext and S (same for the weft).
    """
    sx = fxx + fox
    sy = fxy + foy
    sz = fxz + foz
    cx = fxy * sz - fxz * sy
    cy = fxz * sx - fxx * sz
    cz = fxx * sy - fxy * sx
    cross = math.sqrt(cx * cx + cy * cy + cz * cz)  # |F_X x S| = |F_O x S|
    a_x = math.atan2(cross, fxx * sx + fxy * sy + fxz * sz)
    a_o = math.atan2(cross, fox * sx + foy * sy + foz * sz)
    psi_s = math.atan2(-s2, -s1)  # direction of -S from e1 towards e2
    tx = psi_s - a_x + math.pi
    to = -(psi_s + a_o)
    return valid_angles(tx, to), tx, to


@njit(cache=True)
def crossing_angles(axx, axy, axz, aox, aoy, aoz, cx, cy, cz):
    """Eulerian angles (theta_X, theta_O), rad, of the triangle A_X, A_O, C (any plane)."""
    ex = aox - axx
    ey = aoy - axy
    ez = aoz - axz
    px = cx - axx
    py = cy - axy
    pz = cz - axz
    qx = cx - aox
    qy = cy - aoy
    qz = cz - aoz
    # angle between e1 and A_X->C; between -e1 and A_O->C (atan2 form: accurate near 0 and pi)
    kx = ey * pz - ez * py
    ky = ez * px - ex * pz
    kz = ex * py - ey * px
    tx = math.atan2(math.sqrt(kx * kx + ky * ky + kz * kz), ex * px + ey * py + ez * pz)
    kx = ey * qz - ez * qy
    ky = ez * qx - ex * qz
    kz = ex * qy - ey * qx
    to = math.atan2(math.sqrt(kx * kx + ky * ky + kz * kz), -(ex * qx + ey * qy + ez * qz))
    return tx, to


@njit(cache=True)
def _fail(out, status):
    for k in range(OUT_SIZE):
        out[k] = 0.0
    return status


@njit(cache=True)
def _sign(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def solve_crossing(axx, axy, axz, aox, aoy, aoz, fxx, fxy, fxz, fox, foy, foz,
                   theta_x_prev, theta_o_prev, mu, out):
    """Solve one crossing (paper Fig. 6). Writes ``out[:OUT_SIZE]`` and returns a status code.

    A_X = (axx, axy, axz), A_O = (aox, aoy, aoz): lower points, m. F_X^ext = (fxx, fxy, fxz),
    F_O^ext = (fox, foy, foz): external forces, N (pointing to the supply side). theta_*_prev: the
    previous Eulerian angles, rad; NaN for none (the predictor is then the frictionless equilibrium).
    mu: yarn-yarn friction coefficient. On a status other than CROSSING_OK, ``out`` is zeroed.
    """
    ex = aox - axx
    ey = aoy - axy
    ez = aoz - axz
    length = math.sqrt(ex * ex + ey * ey + ez * ez)
    fxe = math.sqrt(fxx * fxx + fxy * fxy + fxz * fxz)
    foe = math.sqrt(fox * fox + foy * foy + foz * foz)
    if not (length > 0.0 and fxe > 0.0 and foe > 0.0):
        return _fail(out, CROSSING_DEGENERATE)
    ex /= length
    ey /= length
    ez /= length
    sx = fxx + fox
    sy = fxy + foy
    sz = fxz + foz
    s1 = sx * ex + sy * ey + sz * ez
    px = sx - s1 * ex
    py = sy - s1 * ey
    pz = sz - s1 * ez
    s2 = math.sqrt(px * px + py * py + pz * pz)
    if not (s2 > PARALLEL_REL_TOL * (fxe + foe)):
        return _fail(out, CROSSING_PARALLEL)
    e2x = px / s2
    e2y = py / s2
    e2z = pz / s2
    a1 = (fxx * ex + fxy * ey + fxz * ez) / fxe  # in-plane components of the unit external forces
    a2 = (fxx * e2x + fxy * e2y + fxz * e2z) / fxe
    b1 = (fox * ex + foy * ey + foz * ez) / foe
    b2 = (fox * e2x + foy * e2y + foz * e2z) / foe

    # predictor: the previous angles (stick), or the frictionless equilibrium
    if math.isnan(theta_x_prev) or math.isnan(theta_o_prev):
        ok, tx, to = frictionless_angles(fxx, fxy, fxz, fox, foy, foz, s1, s2)
    else:
        tx = theta_x_prev
        to = theta_o_prev
        ok = valid_angles(tx, to)
    if not ok:
        return _fail(out, CROSSING_NO_INTERSECTION)
    fx, fo = tensions(tx, to, s1, s2)
    over_x = psi_tension(fx, fxe, warp_dot(tx, a1, a2), mu) > PSI_REL_TOL * (abs(fx) + fxe)
    over_o = psi_tension(fo, foe, weft_dot(to, b1, b2), mu) > PSI_REL_TOL * (abs(fo) + foe)
    slide_x = _sign(fx - fxe)
    slide_o = _sign(fo - foe)
    evals = 0

    if over_x and not over_o:  # case 1: warp tension jump beyond the bound, move theta_O
        ok, to = warp_slips(tx, s1, s2, fxe, a1, a2, mu, slide_x)
        if not ok:
            return _fail(out, CROSSING_NO_INTERSECTION)
        fx, fo = tensions(tx, to, s1, s2)
        over_o = psi_tension(fo, foe, weft_dot(to, b1, b2), mu) > PSI_REL_TOL * (abs(fo) + foe)
        slide_o = _sign(fo - foe)
    elif over_o and not over_x:  # case 2: weft beyond the bound, move theta_X
        ok, tx = weft_slips(to, s1, s2, foe, b1, b2, mu, slide_o)
        if not ok:
            return _fail(out, CROSSING_NO_INTERSECTION)
        fx, fo = tensions(tx, to, s1, s2)
        over_x = psi_tension(fx, fxe, warp_dot(tx, a1, a2), mu) > PSI_REL_TOL * (abs(fx) + fxe)
        slide_x = _sign(fx - fxe)
    slip_x = over_x
    slip_o = over_o
    if over_x and over_o:  # case 3: both on their bounds
        if mu == 0.0:
            ok, tx3, to3 = frictionless_angles(fxx, fxy, fxz, fox, foy, foz, s1, s2)
        else:
            ok, tx3, to3, evals = both_slip(tx, s1, s2, fxe, foe, a1, a2, b1, b2, mu, slide_x, slide_o)
        if ok:
            tx = tx3
            to = to3
        else:  # no both-slip state: accept one yarn slipping if the other then sticks
            ok, to1 = warp_slips(tx, s1, s2, fxe, a1, a2, mu, slide_x)
            if ok:
                fx, fo = tensions(tx, to1, s1, s2)
                ok = psi_tension(fo, foe, weft_dot(to1, b1, b2), mu) <= PSI_REL_TOL * (abs(fo) + foe)
            if ok:
                to = to1
                slip_o = False
            else:
                ok, tx1 = weft_slips(to, s1, s2, foe, b1, b2, mu, slide_o)
                if ok:
                    fx, fo = tensions(tx1, to, s1, s2)
                    ok = psi_tension(fx, fxe, warp_dot(tx1, a1, a2), mu) <= PSI_REL_TOL * (abs(fx) + fxe)
                if not ok:
                    return _fail(out, CROSSING_NO_SLIP_SOLUTION)
                tx = tx1
                slip_x = False

    fx, fo = tensions(tx, to, s1, s2)
    if not (fx > 0.0 and fo > 0.0):
        return _fail(out, CROSSING_NEGATIVE_TENSION)
    cos_x = math.cos(tx)
    sin_x = math.sin(tx)
    cos_o = math.cos(to)
    sin_o = math.sin(to)
    reach = length * sin_o / math.sin(tx + to)  # |A_X C|, sine rule
    ux = -(cos_x * ex + sin_x * e2x)
    uy = -(cos_x * ey + sin_x * e2y)
    uz = -(cos_x * ez + sin_x * e2z)
    out[OUT_C] = axx - reach * ux
    out[OUT_C + 1] = axy - reach * uy
    out[OUT_C + 2] = axz - reach * uz
    out[OUT_F_X] = fx
    out[OUT_F_O] = fo
    out[OUT_THETA_X] = tx
    out[OUT_THETA_O] = to
    out[OUT_SLIP_X] = 1.0 if slip_x else 0.0
    out[OUT_SLIP_O] = 1.0 if slip_o else 0.0
    out[OUT_PSI_X] = psi_tension(fx, fxe, warp_dot(tx, a1, a2), mu)
    out[OUT_PSI_O] = psi_tension(fo, foe, weft_dot(to, b1, b2), mu)
    out[OUT_U_X] = ux
    out[OUT_U_X + 1] = uy
    out[OUT_U_X + 2] = uz
    out[OUT_U_O] = cos_o * ex - sin_o * e2x
    out[OUT_U_O + 1] = cos_o * ey - sin_o * e2y
    out[OUT_U_O + 2] = cos_o * ez - sin_o * e2z
    out[OUT_SLIDE_X] = _sign(fx - fxe) if slip_x else 0.0
    out[OUT_SLIDE_O] = _sign(fo - foe) if slip_o else 0.0
    out[OUT_ITERATIONS] = evals
    return CROSSING_OK


@njit(cache=True)
def solve_crossings(A_X, A_O, F_X_ext, F_O_ext, theta_prev, mu, out, status):
    """Batch driver: row i of each (n, 3) input, theta_prev (n, 2) (NaN: none), mu (n,).

    Writes out (n, OUT_SIZE) and status (n,) int64. For tests, benchmarks and simple callers.
    """
    for i in range(A_X.shape[0]):
        status[i] = solve_crossing(A_X[i, 0], A_X[i, 1], A_X[i, 2], A_O[i, 0], A_O[i, 1], A_O[i, 2],
                                   F_X_ext[i, 0], F_X_ext[i, 1], F_X_ext[i, 2],
                                   F_O_ext[i, 0], F_O_ext[i, 1], F_O_ext[i, 2],
                                   theta_prev[i, 0], theta_prev[i, 1], mu[i], out[i])


def empty_out(n):
    """A zeroed (n, OUT_SIZE) float64 output array."""
    return np.zeros((n, OUT_SIZE), dtype=np.float64)
