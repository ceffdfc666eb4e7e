"""The friction law of a yarn at a contact, and argument checks of the contact solvers (paper §2.2;
docs/theory.md §4).

A yarn at a crossing has two segments, the internal one (towards the mandrel, tension ``f_int``,
unit vector ``u_int`` from the contact along it) and the external one (towards the supply,
``f_ext``, ``u_ext``); its deflection ``delta`` there has ``cos delta = -u_int . u_ext``. Amontons
friction in the yarn's Eulerian frame (paper eqs. 5-7) gives the friction function
``Psi = |f_int - f_ext| cos(delta/2) - mu (f_int + f_ext) sin(delta/2)`` (:func:`psi`, the frame
form :func:`psi_frame`): a yarn sticks while ``Psi <= 0`` and slips on ``Psi = 0``, i.e. the
discrete Capstan law ``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)`` (:func:`cone_ratio`).
The frontal solver (``interaction/frontal.py``) imposes it at every crossing through the friction
bounds of ``_kernels.frontal.friction_bounds``; these vectorised forms are its reference.
"""

from __future__ import annotations

import numpy as np

from ..errors import PreformError


class ContactInputError(PreformError, ValueError):
    """An argument of a contact solver has the wrong shape, is not finite or is out of range."""


def as_vector(name: str, value) -> np.ndarray:
    """``value`` as a finite (3,) float64 array, or ContactInputError naming ``name``."""
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ContactInputError(f"{name} = {value!r}: expected 3 finite numbers")
    return v


def crossing_friction(type_a, type_b, pairs) -> np.ndarray:
    """(m,) float64: the yarn-yarn coefficient of friction of every crossing, from the types
    ``type_a``, ``type_b`` (m,) int of its two yarns and the (nt, nt) table ``pairs`` of every
    pair of types (``Config.pair_friction``: symmetric, a type with itself on the diagonal).
    The one place a crossing's coefficient is formed; the friction bounds of both solvers
    (``_kernels.frontal.friction_bounds``, ``_kernels.relax.friction_bounds``) take it per
    crossing."""
    pairs = np.asarray(pairs, dtype=np.float64)
    return np.ascontiguousarray(pairs[np.asarray(type_a, np.int64), np.asarray(type_b, np.int64)])


def as_friction(name: str, value) -> float:
    """``value`` as a finite float >= 0, or ContactInputError naming ``name``."""
    mu = float(value)
    if not (np.isfinite(mu) and mu >= 0.0):
        raise ContactInputError(f"{name} = {value!r}: expected a finite friction coefficient >= 0")
    return mu


def psi(f_int, f_ext, u_int, u_ext, mu):
    """Friction function of a yarn at a contact, N (paper eq. 5, tension form; vectorised).

    f_int, f_ext : (...) N, tensions of the two segments; u_int, u_ext : (..., 3) unit vectors from
    the contact along them. ``Psi = |f_int - f_ext| cos(d/2) - mu (f_int + f_ext) sin(d/2)`` with
    ``cos d = -u_int . u_ext``. Sticking: Psi <= 0; slipping: Psi = 0.
    """
    d = np.sum(np.asarray(u_int, float) * np.asarray(u_ext, float), axis=-1)
    c = np.sqrt(np.maximum(0.5 * (1.0 - d), 0.0))
    s = np.sqrt(np.maximum(0.5 * (1.0 + d), 0.0))
    f_int, f_ext = np.asarray(f_int, float), np.asarray(f_ext, float)
    return np.abs(f_int - f_ext) * c - mu * (f_int + f_ext) * s


def psi_frame(F_int, F_ext, mu):
    """Friction function from the force vectors in the Eulerian frame (paper eqs. 5-7), N.

    F_int, F_ext : (..., 3) N, the two segment forces on the contact. ``n = -(u_int + u_ext)/|.|``,
    ``F = F_int + F_ext``, ``F^n = F . n``, ``F^t = |F - F^n n|``, ``Psi = F^t - mu |F^n|``. Equal to
    :func:`psi` except for a straight yarn, where ``n`` is undefined (use :func:`psi` there).
    """
    F_int, F_ext = np.asarray(F_int, float), np.asarray(F_ext, float)
    u_i = F_int / np.linalg.norm(F_int, axis=-1, keepdims=True)
    u_e = F_ext / np.linalg.norm(F_ext, axis=-1, keepdims=True)
    n = -(u_i + u_e)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    F = F_int + F_ext
    fn = np.sum(F * n, axis=-1)
    ft = np.linalg.norm(F - fn[..., None] * n, axis=-1)
    return ft - mu * np.abs(fn)


def cone_ratio(delta, mu):
    """Bounds (low, high) of f_int / f_ext for a sticking yarn with deflection delta (rad).

    ``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``: ratio within
    ``(1 - m) / (1 + m)`` and ``(1 + m) / (1 - m)``, ``m = mu tan(delta/2)``; high is inf when m >= 1.
    """
    m = mu * np.tan(0.5 * np.asarray(delta, float))
    with np.errstate(divide="ignore"):
        high = np.where(m < 1.0, (1.0 + m) / np.where(m < 1.0, 1.0 - m, 1.0), np.inf)
    return (1.0 - m) / (1.0 + m), high


def bound_scale(up, yarn, tension, f_top, floor) -> np.ndarray:
    """(m, 2) N: the scale of each crossing's friction bound, its ``f_int + f_ext``, at least
    ``floor`` times the yarn's top tension: a scale that cannot vanish where a yarn goes slack.

    up : (m, 2) the crossing above on each yarn, -1 below the yarn's top (``f_ext`` is then the
    top tension); yarn : (m, 2) the yarns; tension : (m, 2) ``f_int``; f_top : (n_yarns,)."""
    scale = np.empty_like(tension)
    for side in range(2):
        u = up[:, side]
        top = f_top[yarn[:, side]]
        scale[:, side] = np.maximum(tension[:, side] + np.where(
            u >= 0, tension[np.maximum(u, 0), side], top), floor * top)
    return scale


def bound_change(up, yarn, tension, f_top, new, old, floor) -> float:
    """Largest change from friction bounds ``old`` to ``new`` (m, 2), each relative to its
    crossing's scale (:func:`bound_scale`: ``f_int + f_ext``, the scale of the friction law, at
    least ``floor`` times the yarn's top tension)."""
    return float(np.max(np.abs(new - old) / bound_scale(up, yarn, tension, f_top, floor)))
