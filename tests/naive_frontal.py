"""Slow, obvious NumPy twins of the frontal sweeps (``preform._kernels.frontal``), frictionless.

With ``mu = 0`` every crossing slips on both yarns and the internal tensions equal the external
ones, so the single contact is the force triangle ``f_X u_X + f_O u_O = -S`` in the plane of
``A_X, A_O, S``: solved here with vectors and rotations, not with the kernel's angle formulas.
"""

from __future__ import annotations

import numpy as np


def unit(v):
    return v / np.linalg.norm(v)


def yarn_point(st, c, side, h):
    s = st["over"][c] if side == 0 else -st["over"][c]
    return st["pos"][c] + s * h * st["normal"][c]


def rotate(v, axis, angle):
    """Rodrigues rotation of v about the unit axis."""
    return (v * np.cos(angle) + np.cross(axis, v) * np.sin(angle)
            + axis * (axis @ v) * (1 - np.cos(angle)))


def frictionless_sweeps(st, fell, top, f_top, h):
    """One force sweep (newest first) and one position sweep (oldest first) on the dict ``st``
    (arrays of ``ZoneState`` cut to its ``m`` crossings; ``normal`` is updated in place).
    Returns new positions (m, 3), tensions (m, 2), angles (m, 2), relax (m,)."""
    m = len(st["pos"])
    yarn, low, up = st["yarn"], st["low"], st["up"]
    tension = np.zeros((m, 2))
    S_all = np.zeros((m, 3))
    angles = np.zeros((m, 2))
    relax = np.ones(m)
    for c in range(m - 1, -1, -1):
        B, Q, fe = [], [], []
        for side in range(2):
            k = yarn[c, side]
            u = up[c, side]
            B.append(yarn_point(st, u, side, h) if u >= 0 else top[k])
            fe.append(tension[u, side] if u >= 0 else f_top[k])
            lo = low[c, side]
            Q.append(yarn_point(st, lo, side, h) if lo >= 0 else fell[k])
        N = np.cross(B[0] - Q[0], B[1] - Q[1])
        N = unit(N)
        if N[:2] @ st["pos"][c][:2] < 0:
            N = -N
        st["normal"][c] = N
        sg = st["over"][c] * h
        P = [st["pos"][c] + sg * N, st["pos"][c] - sg * N]
        A = [Q[0] - sg * N, Q[1] + sg * N]
        u_ext = [unit(B[i] - P[i]) for i in range(2)]
        lu = min(np.linalg.norm(B[i] - P[i]) for i in range(2))
        la = max(np.linalg.norm(A[i] - P[i]) for i in range(2))
        relax[c] = max(0.02, lu / (lu + la))
        S = fe[0] * u_ext[0] + fe[1] * u_ext[1]
        # force triangle: -f_X u_X is S rotated by the angle opposite f_O ... (law of cosines)
        Smag = np.linalg.norm(S)
        e1 = unit(A[1] - A[0])
        axis = unit(np.cross(e1, S))        # rotating e1 towards S is positive about axis
        ang_x = np.arccos(np.clip((fe[0] ** 2 + Smag ** 2 - fe[1] ** 2) / (2 * fe[0] * Smag), -1, 1))
        ang_o = np.arccos(np.clip((fe[1] ** 2 + Smag ** 2 - fe[0] ** 2) / (2 * fe[1] * Smag), -1, 1))
        dX = rotate(unit(S), axis, -ang_x)   # direction A_X -> C (= -u_X)
        dO = rotate(unit(S), axis, ang_o)    # direction A_O -> C (= -u_O)
        angles[c] = (np.arccos(np.clip(dX @ e1, -1, 1)), np.arccos(np.clip(-dO @ e1, -1, 1)))
        tension[c] = fe
        S_all[c] = S
    out = st["pos"].copy()
    for c in range(m):
        Q = []
        for side in range(2):
            lo = low[c, side]
            Q.append(yarn_point({**st, "pos": out}, lo, side, h) if lo >= 0 else fell[yarn[c, side]])
        N = st["normal"][c]
        sg = st["over"][c] * h
        A = [Q[0] - sg * N, Q[1] + sg * N]
        e1 = unit(A[1] - A[0])
        S = S_all[c]
        e2 = unit(S - (S @ e1) * e1)
        tx, to = angles[c]
        b = np.linalg.norm(A[1] - A[0])
        C = A[0] + b * np.sin(to) / np.sin(tx + to) * (np.cos(tx) * e1 + np.sin(tx) * e2)
        out[c] = st["pos"][c] + relax[c] * (C - st["pos"][c])
    return out, tension, angles, relax

