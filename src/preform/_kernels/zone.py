"""The arrays of a convergence-zone step as the kernels of ``relax``, ``stiffness`` and
``frontal`` take them: tuples of arrays and numbers, one argument each in place of the dozens
of plain arguments a kernel would need (numba reads their fields without a copy).

The NamedTuples below name the fields; a kernel unpacks its tuples by position in its first
lines (``m, n_yarns, yarn, ... = lat``), so it takes the NamedTuple or the plain tuple of its
fields. The solvers pass plain tuples (``tuple(lat)``, built once a solve): numba's dispatcher
types a plain tuple in C and a NamedTuple in Python, 1.6 against 4.5 us a call with four of
them, which at 10-15 kernel calls a step is 20-35 % of a small zone's relaxation.

Layout as in ``preform/interaction/zone_state.py``: crossings ``c < m``, yarns ``k < 2n``
(warps first). The constructors cast the numbers to float, so that a kernel is compiled once
whatever Python type a setting has.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Lattice(NamedTuple):
    """Connectivity of the crossings: ``yarn``, ``low``, ``up`` (m, 2) int64 (warp and weft
    index; neighbour crossing below / above on each yarn, -1 at the fell / top end), ``over``
    (m,) (+1: the warp is outside), contact normals ``normal`` (m, 3), per yarn ``lowest``,
    ``highest`` (2n,) int64; ``m`` crossings, ``n_yarns`` (2n) yarns."""

    m: int
    n_yarns: int
    yarn: np.ndarray
    low: np.ndarray
    up: np.ndarray
    over: np.ndarray
    normal: np.ndarray
    lowest: np.ndarray
    highest: np.ndarray


class Law(NamedTuple):
    """The constants of the step's equations (``interaction/settings.py``): tow stiffness
    ``EA`` (N), its share ``compression`` when slack, friction creep ``eps_f`` and ``kappa0``,
    half the yarn thickness ``h`` (m), the length smoothings ``eps2``, ``eps2_top`` (m^2), the
    jamming length ``l_jam`` (m) and stiffness ``k_jam`` (N/m), the least net segment force
    ``floor`` (N) in the geometric stiffness."""

    EA: float
    compression: float
    eps_f: float
    kappa0: float
    h: float
    eps2: float
    eps2_top: float
    l_jam: float
    k_jam: float
    floor: float


class Problem(NamedTuple):
    """What a step holds: the fell and top points ``fell``, ``top`` (2n, 3), the fell points'
    material ``s_fell`` (2n,), the friction centres ``s_old`` (m, 2), the friction bounds ``g``
    (m, 2) N and the top tensions ``f_top`` (2n,) N."""

    fell: np.ndarray
    top: np.ndarray
    s_fell: np.ndarray
    s_old: np.ndarray
    g: np.ndarray
    f_top: np.ndarray


class Segments(NamedTuple):
    """Every segment's vector (upper yarn point less lower) and smoothed length: below each
    crossing on both yarns ``d_below`` (m, 2, 3), ``l_below`` (m, 2); the top segments ``d_top``
    (2n, 3), ``l_top`` (2n,)."""

    d_below: np.ndarray
    l_below: np.ndarray
    d_top: np.ndarray
    l_top: np.ndarray


class Forces(NamedTuple):
    """The net forces and their by-products: ``force`` (m, 3) N on each crossing, the force
    densities ``w_below`` (m, 2) and ``w_top`` (2n,) N/m, ``total`` (m,) the sum of a
    crossing's four tensions, ``W`` (m,) its summed force densities, ``res`` (m,) its relative
    imbalance."""

    force: np.ndarray
    w_below: np.ndarray
    w_top: np.ndarray
    total: np.ndarray
    W: np.ndarray
    res: np.ndarray


class BlockSlots(NamedTuple):
    """Where a crossing's blocks go in a block matrix's pattern (``relax.block_pattern``):
    ``diag`` (m,) the slot of its diagonal block, ``below`` (m, 2) the slot coupling it to the
    crossing below on each yarn, ``below_first`` (m, 2) whether the one below comes first in
    the elimination order (the slot holds its row)."""

    diag: np.ndarray
    below: np.ndarray
    below_first: np.ndarray


def law(EA, compression, eps_f, kappa0, h, eps2, eps2_top, l_jam, k_jam, floor) -> Law:
    """A :class:`Law` of floats."""
    return Law(float(EA), float(compression), float(eps_f), float(kappa0), float(h), float(eps2),
               float(eps2_top), float(l_jam), float(k_jam), float(floor))


def problem(fell, top, s_fell, s_old, g, f_top) -> Problem:
    """A :class:`Problem` of contiguous float arrays (the given ones where they are)."""
    def f(a):
        return np.ascontiguousarray(a, dtype=float)
    return Problem(f(fell), f(top), f(s_fell), f(s_old), f(g), f(f_top))


def segments(m, n_yarns) -> Segments:
    """Empty :class:`Segments` for m crossings and n_yarns yarns."""
    return Segments(np.empty((m, 2, 3)), np.empty((m, 2)), np.empty((n_yarns, 3)),
                    np.empty(n_yarns))


def forces(m, n_yarns) -> Forces:
    """Empty :class:`Forces` for m crossings and n_yarns yarns."""
    return Forces(np.empty((m, 3)), np.empty((m, 2)), np.empty(n_yarns), np.empty(m),
                  np.empty(m), np.empty(m))
