"""Numba kernel of the friction law at a yarn-yarn crossing (docs/theory.md §4, "Friction law").

A yarn pressed onto the other yarn of a crossing with the normal force ``N`` (N) may carry a
friction force ``F^t`` up to a bound: Amontons' ``F^t <= mu N``, or Howell's ``F^t <= a N^n``
(``0 < n <= 1``) for fibre assemblies, written with the coefficient ``mu`` at a reference force
``N_ref`` (``a = mu N_ref^(1 - n)``), i.e. the coefficient ``mu (N / N_ref)^(n - 1)``. Both are
one function here: :func:`crossing_coefficient` gives the coefficient at ``N``, which the
friction bounds of ``_kernels.frontal`` and ``_kernels.relax`` multiply by their own ``N``.
For ``n = 1`` it is ``mu`` exactly (returned as it is; ``x ** 0.0 == 1.0`` for every ``x``
too), so Howell's law at index 1 gives Amontons' bounds to the bit. Below ``n_lin`` the
coefficient is held at its value there: the bound ``coefficient * N`` then is linear in ``N``,
goes to 0 with ``N`` and keeps a finite slope, where ``a N^n`` would have an infinite one at
``N = 0`` (a straight yarn) and the coefficient itself would blow up. The slow NumPy twin is
``tests/support/naive_frontal.py`` (``howell_bound``).
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def crossing_coefficient(normal, mu, index, n_ref, n_lin):
    """Friction coefficient (-) at the normal force ``normal`` (N) of a crossing whose law has
    the coefficient ``mu`` at the reference force ``n_ref`` (N) and Howell's index ``index``
    (1: Amontons): ``mu (max(normal, n_lin) / n_ref) ** (index - 1)``, ``n_lin`` (N, > 0) the
    force below which the bound is linear in ``normal`` (module docstring). Index 1 returns
    ``mu`` without the power (the same value, ``x ** 0.0 == 1.0``; the power would add 60 % to an
    Amontons bounds kernel's time)."""
    if index == 1.0:
        return mu
    return mu * (max(normal, n_lin) / n_ref) ** (index - 1.0)
