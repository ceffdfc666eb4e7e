"""Closed forms for overbraiding on axisymmetric mandrels (docs/theory.md §2).

Used by the validation tests and by the examples; SI units, angles in radians unless the name says
``_deg``. ``omega`` is the carrier angular speed (rad/s), ``v`` the take-up speed (m/s), ``r`` the
mandrel radius (m), ``R`` the supply radius (m): the guide-ring radius if there is one, else the
spool radius.
"""

from __future__ import annotations

import numpy as np


def ko_braid_angle(omega, r, v):
    """Steady braid angle on a cylinder (Ko; paper eq. 2 with P = 2 pi r): atan(omega r / v)."""
    return np.arctan(omega * np.asarray(r, dtype=float) / v)


def ko_braid_angle_perimeter(omega, perimeter, v):
    """Paper eq. 2: atan(P omega / (2 pi v)) for a cross-section of perimeter P (m)."""
    return np.arctan(np.asarray(perimeter, dtype=float) * omega / (2.0 * np.pi * v))


def quasi_static_braid_angle(omega, r, v, dr_ds):
    """Braid angle where the radius changes slowly: atan(omega r / (v sqrt(1 + r'^2)))."""
    r = np.asarray(r, dtype=float)
    return np.arctan(omega * r / (v * np.sqrt(1.0 + np.asarray(dr_ds, dtype=float) ** 2)))


def steady_convergence_length(omega, r, v, R):
    """Steady convergence length H_inf = v sqrt(R^2 - r^2) / (omega r)."""
    return v * np.sqrt(R * R - r * r) / (omega * r)


def du_popper_convergence_length(t, H0, omega, r, v, R):
    """Du & Popper transient H(t) = H_inf + (H0 - H_inf) exp(-omega r t / sqrt(R^2 - r^2)).

    Valid from the moment the free yarn is tangent to the cylinder (t = 0 there).
    """
    H_inf = steady_convergence_length(omega, r, v, R)
    return H_inf + (H0 - H_inf) * np.exp(-omega * r * np.asarray(t, dtype=float) / np.sqrt(R * R - r * r))


def tangency_lag(r, R):
    """Azimuth (rad) by which a tangent free yarn's fell point trails its supply point: acos(r/R)."""
    return np.arccos(r / R)


def yarn_coverage(n_per_group, width, r, alpha):
    """Coverage of one yarn group on a cylinder: k = n w / (2 pi r cos alpha), not capped."""
    return n_per_group * width / (2.0 * np.pi * r * np.cos(alpha))


def cover_factor(carriers, width, r, alpha):
    """Biaxial cover factor CF = 1 - (1 - k)^2 with k = N w / (4 pi r cos alpha), N all carriers."""
    k = np.minimum(1.0, yarn_coverage(carriers / 2, width, r, alpha))
    return 1.0 - (1.0 - k) ** 2


def jamming_angle(carriers, width, r):
    """Braid angle (rad) above which the yarns of a group touch (k = 1): acos(N w / (4 pi r))."""
    return np.arccos(np.clip(carriers * width / (4.0 * np.pi * r), -1.0, 1.0))
