"""Slow, obvious NumPy/SciPy references for the contact kernels (``preform._kernels.contact/ring``).

Written from the equations (paper §2.2-2.3, DESIGN.md §3.3) with vectors, rotations, least squares
and scipy root finders, not from the kernel code: the crossing is built by rotating ``e1`` about the
plane normal and intersecting two 3D lines; tensions come from a least-squares decomposition; the
friction functions use the Eulerian frame of eqs. 6-7; the slip cases are root searches on a grid
plus ``brentq`` (one unknown) or ``fsolve`` (both yarns slipping).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq, fsolve
from scipy.spatial.transform import Rotation


def unit(v):
    return v / np.linalg.norm(v)


class Crossing:
    """One crossing problem: A_X, A_O (3,), F_X_ext, F_O_ext (3,), mu."""

    def __init__(self, A_X, A_O, F_X_ext, F_O_ext, mu):
        self.A_X, self.A_O = np.asarray(A_X, float), np.asarray(A_O, float)
        self.F_X_ext, self.F_O_ext = np.asarray(F_X_ext, float), np.asarray(F_O_ext, float)
        self.mu = float(mu)
        self.S = self.F_X_ext + self.F_O_ext
        self.e1 = unit(self.A_O - self.A_X)
        self.e2 = unit(self.S - (self.S @ self.e1) * self.e1)  # Gram-Schmidt: plane holding S
        self.m = np.cross(self.e1, self.e2)

    def valid(self, tx, to):
        return tx > 0 and to > 0 and tx + to < np.pi

    def geometry(self, tx, to):
        """C, u_X (C->A_X), u_O (C->A_O), f_X, f_O for the Eulerian angles (tx, to)."""
        d_x = Rotation.from_rotvec(tx * self.m).apply(self.e1)      # A_X -> C
        d_o = Rotation.from_rotvec(-to * self.m).apply(-self.e1)    # A_O -> C
        # A_X + p d_x = A_O + q d_o (least squares on the two lines)
        (p, q), *_ = np.linalg.lstsq(np.column_stack([d_x, -d_o]), self.A_O - self.A_X, rcond=None)
        C = self.A_X + p * d_x
        u_x, u_o = unit(self.A_X - C), unit(self.A_O - C)
        (f_x, f_o), *_ = np.linalg.lstsq(np.column_stack([u_x, u_o]), -self.S, rcond=None)
        return C, u_x, u_o, f_x, f_o

    def signed_psi(self, f_int, u_int, F_ext, sign):
        """sign * F^t - mu |F^n| in the yarn's Eulerian frame (eqs. 6-7), t from ext to int."""
        u_ext = unit(F_ext)
        F = f_int * u_int + F_ext
        n = -unit(u_int + u_ext)
        t = unit(u_int - u_ext)
        return sign * (F @ t) - self.mu * abs(F @ n)

    def psis(self, tx, to):
        C, u_x, u_o, f_x, f_o = self.geometry(tx, to)
        px = self.signed_psi(f_x, u_x, self.F_X_ext, np.sign(f_x - np.linalg.norm(self.F_X_ext)))
        po = self.signed_psi(f_o, u_o, self.F_O_ext, np.sign(f_o - np.linalg.norm(self.F_O_ext)))
        return px, po

    def _root_1d(self, fun, lo, hi, x0, n=400):
        """Root of fun on (lo, hi) nearest x0, from sign changes on a grid of valid points."""
        xs = np.linspace(lo, hi, n + 2)[1:-1]
        vals = np.array([fun(x) for x in xs])
        best = None
        for i in range(n - 1):
            a, b = vals[i], vals[i + 1]
            if np.isfinite(a) and np.isfinite(b) and a * b <= 0:
                r = brentq(fun, xs[i], xs[i + 1], xtol=1e-15, rtol=1e-15)
                if best is None or abs(r - x0) < abs(best - x0):
                    best = r
        return best

    def warp_slips(self, tx, to0, sign):
        """theta_O with the warp on its bound (theta_X kept), or None."""
        def fun(to):
            if not self.valid(tx, to):
                return np.nan
            C, u_x, u_o, f_x, f_o = self.geometry(tx, to)
            if f_o <= 0:
                return np.nan
            return self.signed_psi(f_x, u_x, self.F_X_ext, sign)
        return self._root_1d(fun, 0.0, np.pi - tx, to0)

    def weft_slips(self, to, tx0, sign):
        def fun(tx):
            if not self.valid(tx, to):
                return np.nan
            C, u_x, u_o, f_x, f_o = self.geometry(tx, to)
            if f_x <= 0:
                return np.nan
            return self.signed_psi(f_o, u_o, self.F_O_ext, sign)
        return self._root_1d(fun, 0.0, np.pi - to, tx0)

    def both_slip(self, tx0, to0, sx, so):
        """Both on their bounds: fsolve from several starts, the valid root nearest (tx0, to0)."""
        def fun(v):
            tx, to = v
            C, u_x, u_o, f_x, f_o = self.geometry(tx, to)
            return [self.signed_psi(f_x, u_x, self.F_X_ext, sx), self.signed_psi(f_o, u_o, self.F_O_ext, so)]
        scale = np.linalg.norm(self.F_X_ext) + np.linalg.norm(self.F_O_ext)
        starts = [(tx0, to0)] + [(tx0 + a, to0 + b) for a in (-0.2, 0.2) for b in (-0.2, 0.2)]
        fl = self.frictionless()
        if fl is not None:
            starts.append(tuple(fl))
        best = None
        for start in starts:
            if not self.valid(*start):
                continue
            v, info, ier, msg = fsolve(fun, start, xtol=1e-14, full_output=True)
            if np.max(np.abs(info["fvec"])) < 1e-11 * scale and self.valid(*v):  # ier 3 is fine there
                *_, f_x, f_o = self.geometry(*v)
                if f_x > 0 and f_o > 0 and (best is None or abs(v[0] - tx0) < abs(best[0] - tx0)):
                    best = v
        return best

    def frictionless(self):
        """mu = 0: internal forces of the external magnitudes, fsolve on both tensions."""
        fxe, foe = np.linalg.norm(self.F_X_ext), np.linalg.norm(self.F_O_ext)
        for tx0 in np.linspace(0.2, 2.8, 14):
            for to0 in np.linspace(0.2, 2.8, 14):
                if not self.valid(tx0, to0):
                    continue
                def fun(v):
                    *_, f_x, f_o = self.geometry(*v)
                    return [f_x - fxe, f_o - foe]
                v, info, ier, msg = fsolve(fun, (tx0, to0), xtol=1e-14, full_output=True)
                if np.max(np.abs(info["fvec"])) < 1e-11 * (fxe + foe) and self.valid(*v):
                    return v
        return None

    def solve(self, theta_prev=None, rel_tol=1e-12):
        """Predictor-corrector of paper Fig. 6. Returns a dict, ``ok`` False when no solution."""
        fxe, foe = np.linalg.norm(self.F_X_ext), np.linalg.norm(self.F_O_ext)
        tx, to = self.frictionless() if theta_prev is None else theta_prev

        def over(tx, to):
            C, u_x, u_o, f_x, f_o = self.geometry(tx, to)
            px, po = self.psis(tx, to)
            return px > rel_tol * (abs(f_x) + fxe), po > rel_tol * (abs(f_o) + foe), f_x, f_o

        ox, oo, f_x, f_o = over(tx, to)
        sx, so = np.sign(f_x - fxe), np.sign(f_o - foe)
        slip_x, slip_o = ox, oo
        fail = {"ok": False}
        if ox and not oo:
            to = self.warp_slips(tx, to, sx)
            if to is None:
                return fail
            _, oo, _, f_o = over(tx, to)
            so, slip_o = np.sign(f_o - foe), oo
        elif oo and not ox:
            tx = self.weft_slips(to, tx, so)
            if tx is None:
                return fail
            ox, _, f_x, _ = over(tx, to)
            sx, slip_x = np.sign(f_x - fxe), ox
        if slip_x and slip_o:
            v = self.both_slip(tx, to, sx, so)
            if v is None:
                return fail
            tx, to = v
        C, u_x, u_o, f_x, f_o = self.geometry(tx, to)
        if f_x <= 0 or f_o <= 0:
            return fail
        px, po = self.psis(tx, to)
        return {"ok": True, "C": C, "f_X": f_x, "f_O": f_o, "theta_X": tx, "theta_O": to,
                "slip_X": int(slip_x), "slip_O": int(slip_o), "psi_X": px, "psi_O": po,
                "u_X": u_x, "u_O": u_o}


def ring_forces(theta, A, B, f_ext, r, z, mu, capstan_sign=-1):
    """(F^t, |F^n|, f_int, eta, R) at ring angle theta, from eqs. 9-13 with numpy."""
    R = np.array([r * np.cos(theta), r * np.sin(theta), z])
    u_i, u_e = unit(np.asarray(A) - R), unit(np.asarray(B) - R)
    eta = np.arccos(np.clip(-u_i @ u_e, -1.0, 1.0))
    f_int = f_ext * np.exp(capstan_sign * mu * eta)
    F = f_int * u_i + f_ext * u_e
    t = np.array([-np.sin(theta), np.cos(theta), 0.0])
    ft = F @ t
    n = unit(F - ft * t)   # n_r in the plane of F_r and t_r, normal to t_r (eq. 12)
    return ft, abs(F @ n), f_int, eta, R


def solve_ring(A, B, f_ext, r, z, theta_prev, mu, capstan_sign=-1, rel_tol=1e-12):
    """Stick keeps theta; slip: first root of sign(F^t) F^t - mu |F^n| from theta_prev, on a grid."""
    ft, fn, f_int, eta, R = ring_forces(theta_prev, A, B, f_ext, r, z, mu, capstan_sign)
    theta, slip = theta_prev, abs(ft) - mu * fn > rel_tol * (f_int + f_ext)
    if slip:
        s = np.sign(ft)

        def h(th):
            ft, fn, *_ = ring_forces(th, A, B, f_ext, r, z, mu, capstan_sign)
            return s * ft - mu * fn
        grid = theta_prev + s * np.arange(1, 3200) * 1e-3
        vals = np.array([h(th) for th in grid])
        k = int(np.argmax(vals <= 0))
        if vals[k] > 0:
            return {"ok": False}
        a = theta_prev if k == 0 else grid[k - 1]
        theta = brentq(h, min(a, grid[k]), max(a, grid[k]), xtol=1e-15, rtol=1e-15)
        ft, fn, f_int, eta, R = ring_forces(theta, A, B, f_ext, r, z, mu, capstan_sign)
    return {"ok": True, "theta": theta, "R": R, "f_int": f_int, "eta": eta, "psi": abs(ft) - mu * fn,
            "slip": int(slip)}
