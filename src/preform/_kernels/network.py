"""Numba kernel of the frictionless crossing network (``interaction/network.py``).

Crossing c joins warp yarn ``yw[c]`` and weft yarn ``yf[c]``. Its neighbours along the warp are
``low_w[c]`` / ``up_w[c]`` and along the weft ``low_f[c]`` / ``up_f[c]``: a crossing id, or -1 for
the yarn's fell point (below) / top point (above, ring or spool point). ``side[c]`` is +1 where
the warp passes over (outside), -1 where it passes under. The yarn centerlines pass the crossing at
``C +/- side h n`` with ``n`` the radial unit vector of ``C`` (away from the machine axis) and
``h`` half the yarn thickness (paper eq. 16, with the contact normal taken radial).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _radial(x, y):
    r = np.sqrt(x * x + y * y)
    if r < 1e-300:
        return 1.0, 0.0
    return x / r, y / r


@njit(cache=True)
def centerline_point(pos, side, c, yarn_is_warp, h, out):
    """The yarn's centerline point at crossing c into out (3,)."""
    nx, ny = _radial(pos[c, 0], pos[c, 1])
    s = side[c] * h if yarn_is_warp else -side[c] * h
    out[0] = pos[c, 0] + s * nx
    out[1] = pos[c, 1] + s * ny
    out[2] = pos[c, 2]


@njit(cache=True)
def _anchor(pos, side, nb, yarn, is_warp, fell, top, lower, h, out):
    if nb >= 0:
        centerline_point(pos, side, nb, is_warp, h, out)
    elif lower:
        out[0] = fell[yarn, 0]
        out[1] = fell[yarn, 1]
        out[2] = fell[yarn, 2]
    else:
        out[0] = top[yarn, 0]
        out[1] = top[yarn, 1]
        out[2] = top[yarn, 2]


@njit(cache=True)
def relax(pos, alive, order, side, yw, yf, low_w, up_w, low_f, up_f, fell, top, tension, h,
          eps, max_sweeps, inner):
    """Gauss-Seidel sweeps of weighted Weiszfeld steps (each crossing to the tension-weighted
    geometric median of its four neighbours, thickness offsets included) until no crossing moves
    more than eps (m). Returns (sweeps, last max move)."""
    anchors = np.empty((4, 3))
    weights = np.empty(4)
    tmp = np.empty(3)
    move = 0.0
    for sweep in range(max_sweeps):
        move = 0.0
        for q in range(order.shape[0]):
            c = order[q]
            if not alive[c]:
                continue
            _anchor(pos, side, low_w[c], yw[c], True, fell, top, True, h, anchors[0])
            _anchor(pos, side, up_w[c], yw[c], True, fell, top, False, h, anchors[1])
            _anchor(pos, side, low_f[c], yf[c], False, fell, top, True, h, anchors[2])
            _anchor(pos, side, up_f[c], yf[c], False, fell, top, False, h, anchors[3])
            weights[0] = tension[yw[c]]
            weights[1] = tension[yw[c]]
            weights[2] = tension[yf[c]]
            weights[3] = tension[yf[c]]
            x0 = pos[c, 0]
            y0 = pos[c, 1]
            z0 = pos[c, 2]
            for _ in range(inner):
                nx, ny = _radial(pos[c, 0], pos[c, 1])
                sw = side[c] * h
                sx = 0.0
                sy = 0.0
                sz = 0.0
                sw_tot = 0.0
                for a in range(4):
                    # shift the anchor by the crossing's own offset so the update is for C itself
                    off = -sw if a < 2 else sw
                    ax = anchors[a, 0] - off * nx
                    ay = anchors[a, 1] - off * ny
                    az = anchors[a, 2]
                    dx = pos[c, 0] - ax
                    dy = pos[c, 1] - ay
                    dz = pos[c, 2] - az
                    d = np.sqrt(dx * dx + dy * dy + dz * dz)
                    if d < 1e-9:
                        d = 1e-9
                    w = weights[a] / d
                    sx += w * ax
                    sy += w * ay
                    sz += w * az
                    sw_tot += w
                pos[c, 0] = sx / sw_tot
                pos[c, 1] = sy / sw_tot
                pos[c, 2] = sz / sw_tot
            dx = pos[c, 0] - x0
            dy = pos[c, 1] - y0
            dz = pos[c, 2] - z0
            m = np.sqrt(dx * dx + dy * dy + dz * dz)
            if m > move:
                move = m
        if move < eps:
            return sweep + 1, move
    return max_sweeps, move
