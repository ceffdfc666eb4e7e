"""Slow, obvious NumPy/SciPy reference for the yarn-ring contact kernel (``preform._kernels.ring``).

Written from the equations (paper §2.3, eqs. 9-13; docs/theory.md §4) with vectors and a grid search
plus ``brentq`` for the slip root, not from the kernel code.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq


def unit(v):
    return v / np.linalg.norm(v)


def ring_forces(theta, A, B, f_ext, r, z, mu, capstan_sign=-1, f_hold=None):
    """(F^t, |F^n|, f_int, eta, R) at ring angle theta, from eqs. 9-13 with numpy; capstan_sign 0:
    f_int = f_hold clipped to the Capstan cone."""
    R = np.array([r * np.cos(theta), r * np.sin(theta), z])
    u_i, u_e = unit(np.asarray(A) - R), unit(np.asarray(B) - R)
    eta = np.arccos(np.clip(-u_i @ u_e, -1.0, 1.0))
    if capstan_sign == 0:
        f_int = float(np.clip(f_hold, f_ext * np.exp(-mu * eta), f_ext * np.exp(mu * eta)))
    else:
        f_int = f_ext * np.exp(capstan_sign * mu * eta)
    F = f_int * u_i + f_ext * u_e
    t = np.array([-np.sin(theta), np.cos(theta), 0.0])
    ft = F @ t
    n = unit(F - ft * t)   # n_r in the plane of F_r and t_r, normal to t_r (eq. 12)
    return ft, abs(F @ n), f_int, eta, R


def solve_ring(A, B, f_ext, r, z, theta_prev, mu, capstan_sign=-1, rel_tol=1e-12, f_hold=None,
               s_long=0.0):
    """Stick keeps theta; slip: first root of sign(F^t) F^t - mu_t |F^n| from theta_prev, on a
    grid; mu_t = mu, or with a slide s_long along the ring the transverse share of one Coulomb
    cone, mu r |theta - theta_prev| / |(s_long, r (theta - theta_prev))| (no stick then)."""
    ft, fn, f_int, eta, R = ring_forces(theta_prev, A, B, f_ext, r, z, mu, capstan_sign, f_hold)

    def mu_t(th):
        a = r * abs(th - theta_prev)
        return mu if s_long == 0 else mu * a / np.hypot(s_long, a)
    theta, slip = theta_prev, abs(ft) - mu_t(theta_prev) * fn > rel_tol * (f_int + f_ext)
    if slip:
        s = np.sign(ft)

        def h(th):
            ft, fn, *_ = ring_forces(th, A, B, f_ext, r, z, mu, capstan_sign, f_hold)
            return s * ft - mu_t(th) * fn
        grid = theta_prev + s * np.arange(1, 3200) * 1e-3
        vals = np.array([h(th) for th in grid])
        k = int(np.argmax(vals <= 0))
        if vals[k] > 0:
            return {"ok": False}
        a = theta_prev if k == 0 else grid[k - 1]
        theta = brentq(h, min(a, grid[k]), max(a, grid[k]), xtol=1e-15, rtol=1e-15)
        ft, fn, f_int, eta, R = ring_forces(theta, A, B, f_ext, r, z, mu, capstan_sign, f_hold)
    return {"ok": True, "theta": theta, "R": R, "f_int": f_int, "eta": eta,
            "psi": abs(ft) - mu_t(theta) * fn,
            "slip": int(slip)}
