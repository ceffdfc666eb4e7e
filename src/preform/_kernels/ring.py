"""Numba kernel of the yarn-ring contact (paper §2.3, eqs. 9-13, Fig. A.17; docs/theory.md §4).

Scalars in, one float64 output row out, an integer status back (callable from another ``@njit``
kernel). Public wrapper: ``preform.interaction.ring``; slow reference: ``tests/support/naive_contact.py``.

Machine frame: the ring is the circle of radius ``r`` about the z axis in the plane ``z = z_ring``;
its point ``R(theta) = (r cos theta, r sin theta, z_ring)`` with tangent ``t_r = (-sin, cos, 0)``
(eq. 13, normalised). The yarn runs straight from the fixed point ``A`` (last crossing or fell point)
to ``R`` and on to the supply point ``B``, where the spool tension ``f_ext`` acts.

Longitudinal (Capstan, eq. 9): ``f_int = f_ext exp(capstan_sign mu_r eta)`` with ``eta`` the yarn's
deflection at ``R``, the angle between ``R->A`` and the continuation of ``B->R``
(``cos eta = -u_int . u_ext``), the sign from the direction the yarn slides along the ring:
``capstan_sign = +1`` while it slides towards ``A`` (drawn from the spool to the mandrel: higher
tension on the mandrel side), ``-1`` towards ``B`` (the paper's eq. 9 as written, ``f_ext = f_int
exp(mu_r eta)``), ``0`` while it sticks along the ring: then ``f_int = f_hold``, held within the
Capstan cone ``f_ext exp(-mu_r eta) <= f_int <= f_ext exp(mu_r eta)``. The caller tracks the
sliding direction (``interaction.model``).

Transverse (eqs. 10-12): contact force ``F_r = f_int u_int + f_ext u_ext`` (the pull of the yarn on
the ring), ``F^t = F_r . t_r``, ``|F^n| = |F_r - F^t t_r|`` (``n_r`` in the plane of ``F_r`` and
``t_r``), ``Psi_r = |F^t| - mu_r |F^n|``. While the yarn also slides along the ring by ``s_long``
in the step, the two are one Coulomb cone: the friction force opposes the slide ``(s_long,
r dtheta)``, its transverse part is ``mu_r r |dtheta| / |(s_long, r dtheta)|``
(``transverse_friction``), and the yarn cannot stick across the ring. Stick keeps ``theta``; slip moves ``R`` along ``sign(F^t)
t_r`` (``slide = sign(F^t)``, +1: theta grows) to the first ``theta`` with ``Psi_r = 0``, found by a
marching bracket and Illinois regula falsi. The tolerances and iteration limits are arguments
(``preform.interaction.settings.RingSettings``); the status codes and the layout of ``out`` are the
named module constants below.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

RING_OK = 0
RING_DEGENERATE = 1   # A or B on the ring point, non-positive tension or radius
RING_NO_ROOT = 2      # no theta within half a turn brings the transverse force inside the cone

RING_OUT_R = 0          # 0..2 ring point R, m
RING_OUT_THETA = 3      # theta_r, rad
RING_OUT_F_INT = 4      # tension on the A side, N
RING_OUT_ETA = 5        # Capstan (deflection) angle, rad
RING_OUT_PSI = 6        # Psi_r, N
RING_OUT_SLIP = 7       # 0 stick, 1 slip (transverse)
RING_OUT_SLIDE = 8      # -1, 0, +1: direction of theta while slipping
RING_OUT_U_INT = 9      # 9..11 unit R -> A
RING_OUT_U_EXT = 12     # 12..14 unit R -> B
RING_OUT_F_R = 15       # 15..17 contact force F_r = f_int u_int + f_ext u_ext, N
RING_OUT_ITERATIONS = 18
RING_OUT_SIZE = 19


@njit(cache=True)
def ring_state(theta, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu, capstan_sign, f_hold):
    """(ok, F^t, |F^n|, f_int, eta) of the ring point at ``theta``; ok False if A or B sits on R.
    capstan_sign 0 (the yarn sticks along the ring): f_int is f_hold within the Capstan cone."""
    c = math.cos(theta)
    s = math.sin(theta)
    vx = ax - r * c
    vy = ay - r * s
    vz = az - z_ring
    wx = bx - r * c
    wy = by - r * s
    wz = bz - z_ring
    li = math.sqrt(vx * vx + vy * vy + vz * vz)
    le = math.sqrt(wx * wx + wy * wy + wz * wz)
    if not (li > 0.0 and le > 0.0):
        return False, 0.0, 0.0, 0.0, 0.0
    vx /= li
    vy /= li
    vz /= li
    wx /= le
    wy /= le
    wz /= le
    kx = vy * wz - vz * wy
    ky = vz * wx - vx * wz
    kz = vx * wy - vy * wx
    eta = math.atan2(math.sqrt(kx * kx + ky * ky + kz * kz), -(vx * wx + vy * wy + vz * wz))
    if capstan_sign != 0.0:
        f_int = f_ext * math.exp(capstan_sign * mu * eta)
    else:
        f_int = min(max(f_hold, f_ext * math.exp(-mu * eta)), f_ext * math.exp(mu * eta))
    fx = f_int * vx + f_ext * wx
    fy = f_int * vy + f_ext * wy
    fz = f_int * vz + f_ext * wz
    ft = -s * fx + c * fy
    fn = math.sqrt(max(fx * fx + fy * fy + fz * fz - ft * ft, 0.0))
    return True, ft, fn, f_int, eta


@njit(cache=True)
def transverse_friction(mu, r, dtheta, s_long):
    """The friction coefficient across the ring for a transverse slide ``r |dtheta|`` while the
    yarn slides ``s_long`` (m) along it in the same step: one Coulomb cone, the friction force
    opposing the slide (s_long, r dtheta), so its transverse part is ``mu r |dtheta| / |slide|``;
    ``mu`` itself while the yarn does not slide along (s_long = 0)."""
    if s_long <= 0.0:
        return mu
    a = r * abs(dtheta)
    return mu * a / math.sqrt(s_long * s_long + a * a)


@njit(cache=True)
def _signed_psi(theta, slide, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu, capstan_sign, f_hold,
                theta0, s_long):
    """(ok, slide F^t - mu_t |F^n|, scaled by 1 / (f_int + f_ext)); mu_t from
    ``transverse_friction`` for the slide from theta0."""
    ok, ft, fn, f_int, eta = ring_state(theta, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu,
                                        capstan_sign, f_hold)
    mu_t = transverse_friction(mu, r, theta - theta0, s_long)
    return ok, (slide * ft - mu_t * fn) / (f_int + f_ext)


@njit(cache=True)
def _fail(out, status):
    for k in range(RING_OUT_SIZE):
        out[k] = 0.0
    return status


@njit(cache=True)
def slip_theta(theta0, slide, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu, capstan_sign,
               f_hold, s_long, march_step, march_max, root_max_iter, root_rel_tol):
    """First theta from theta0 in direction ``slide`` with Psi_r = 0: (ok, theta, evaluations).
    The root is bracketed by at most ``march_max`` steps of ``march_step`` (rad) and refined by
    at most ``root_max_iter`` Illinois iterations to ``|Psi_r| <= root_rel_tol (f_int + f_ext)``."""
    lo = theta0
    ok, h_lo = _signed_psi(theta0, slide, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu,
                           capstan_sign, f_hold, theta0, s_long)
    hi = theta0
    h_hi = 0.0
    evals = 1
    found = False
    for k in range(1, march_max + 1):
        x = theta0 + slide * k * march_step
        ok, h = _signed_psi(x, slide, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu, capstan_sign,
                            f_hold, theta0, s_long)
        evals += 1
        if not ok:
            return False, theta0, evals
        if h <= 0.0:
            hi = x
            h_hi = h
            found = True
            break
        lo = x
        h_lo = h
    if not found:
        return False, theta0, evals
    # Illinois regula falsi on the parameter u in [0, 1] between lo (h > 0) and hi (h <= 0)
    ua = 0.0
    ub = 1.0
    ha = h_lo
    hb = h_hi
    x = hi
    side = 0
    for _ in range(root_max_iter):
        if hb == 0.0:
            x = lo + (hi - lo) * ub
            break
        u = (ua * hb - ub * ha) / (hb - ha)
        if not (ua < u < ub):
            u = 0.5 * (ua + ub)
        x = lo + (hi - lo) * u
        ok, h = _signed_psi(x, slide, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu, capstan_sign,
                            f_hold, theta0, s_long)
        evals += 1
        if abs(h) <= root_rel_tol or ub - ua <= 1e-15:
            break
        if h > 0.0:
            ua, ha = u, h
            if side == 1:
                hb *= 0.5
            side = 1
        else:
            ub, hb = u, h
            if side == -1:
                ha *= 0.5
            side = -1
    return True, x, evals


@njit(cache=True)
def solve_ring(ax, ay, az, bx, by, bz, f_ext, r, z_ring, theta_prev, mu, capstan_sign, f_hold,
               s_long, psi_rel_tol, march_step, march_max, root_max_iter, root_rel_tol, out):
    """Solve the yarn-ring contact (paper Fig. A.17). Writes ``out[:RING_OUT_SIZE]``, returns a status.

    A = (ax, ay, az), B = (bx, by, bz): fixed and supply points, m, machine frame. f_ext: spool
    tension at B, N. r, z_ring: ring radius and plane, m. theta_prev: previous ring angle, rad.
    mu: yarn-ring friction. capstan_sign: the direction the yarn slides along the ring, -1 towards
    B (paper eq. 9 as written: lower tension on the A side), +1 towards A (higher on the A side),
    0 stick along the ring (f_int = f_hold, N, within the Capstan cone); a fraction of +-1
    where the slide along the ring is part of a slide also across it (``interaction.model``).
    s_long: m, the yarn's slide along the ring in the step (0: none; then the transverse law is
    Amontons with mu, else one Coulomb cone, ``transverse_friction``: no transverse stick).
    psi_rel_tol: Psi_r <= psi_rel_tol (f_int + f_ext) sticks; march_step .. root_rel_tol: the slip
    root solve (``slip_theta``; ``interaction.settings.RingSettings``).
    """
    if not (f_ext > 0.0 and r > 0.0):
        return _fail(out, RING_DEGENERATE)
    theta = theta_prev
    ok, ft, fn, f_int, eta = ring_state(theta, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu,
                                        capstan_sign, f_hold)
    if not ok:
        return _fail(out, RING_DEGENERATE)
    # sliding along the ring, the yarn cannot stick across it: its friction opposes the slide
    slip = abs(ft) - (mu * fn if s_long <= 0.0 else 0.0) > psi_rel_tol * (f_int + f_ext)
    slide = 0.0
    evals = 0
    if slip:
        slide = 1.0 if ft > 0.0 else -1.0
        ok, theta, evals = slip_theta(theta, slide, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu,
                                      capstan_sign, f_hold, s_long, march_step, march_max,
                                      root_max_iter, root_rel_tol)
        if not ok:
            return _fail(out, RING_NO_ROOT)
        ok, ft, fn, f_int, eta = ring_state(theta, ax, ay, az, bx, by, bz, f_ext, r, z_ring, mu,
                                            capstan_sign, f_hold)
    c = math.cos(theta)
    s = math.sin(theta)
    rx = r * c
    ry = r * s
    vx = ax - rx
    vy = ay - ry
    vz = az - z_ring
    wx = bx - rx
    wy = by - ry
    wz = bz - z_ring
    li = math.sqrt(vx * vx + vy * vy + vz * vz)
    le = math.sqrt(wx * wx + wy * wy + wz * wz)
    out[RING_OUT_R] = rx
    out[RING_OUT_R + 1] = ry
    out[RING_OUT_R + 2] = z_ring
    out[RING_OUT_THETA] = theta
    out[RING_OUT_F_INT] = f_int
    out[RING_OUT_ETA] = eta
    out[RING_OUT_PSI] = abs(ft) - (transverse_friction(mu, r, theta - theta_prev, s_long) * fn
                                   if slip else mu * fn)
    out[RING_OUT_SLIP] = 1.0 if slip else 0.0
    out[RING_OUT_SLIDE] = slide
    out[RING_OUT_U_INT] = vx / li
    out[RING_OUT_U_INT + 1] = vy / li
    out[RING_OUT_U_INT + 2] = vz / li
    out[RING_OUT_U_EXT] = wx / le
    out[RING_OUT_U_EXT + 1] = wy / le
    out[RING_OUT_U_EXT + 2] = wz / le
    out[RING_OUT_F_R] = f_int * vx / li + f_ext * wx / le
    out[RING_OUT_F_R + 1] = f_int * vy / li + f_ext * wy / le
    out[RING_OUT_F_R + 2] = f_int * vz / li + f_ext * wz / le
    out[RING_OUT_ITERATIONS] = evals
    return RING_OK


@njit(cache=True)
def solve_rings(A, B, f_ext, r, z_ring, theta_prev, mu, capstan_sign, f_hold, s_long,
                psi_rel_tol, march_step, march_max, root_max_iter, root_rel_tol, out, status):
    """Batch driver over rows of A, B (n, 3) and f_ext, theta_prev, mu (each yarn's yarn-ring
    friction), capstan_sign, f_hold, s_long (n,); out (n, RING_OUT_SIZE)."""
    for i in range(A.shape[0]):
        status[i] = solve_ring(A[i, 0], A[i, 1], A[i, 2], B[i, 0], B[i, 1], B[i, 2], f_ext[i], r,
                               z_ring, theta_prev[i], mu[i], capstan_sign[i], f_hold[i], s_long[i],
                               psi_rel_tol, march_step, march_max, root_max_iter, root_rel_tol,
                               out[i])


def empty_out(n):
    """A zeroed (n, RING_OUT_SIZE) float64 output array."""
    return np.zeros((n, RING_OUT_SIZE), dtype=np.float64)
