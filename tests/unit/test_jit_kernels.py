"""Kernels written for a short compile against the library forms they stand for, bit for bit
(docs/decisions.md, "Kernel code written for compile time, same results"): ``cell_order``
against numba's own ``np.argsort`` (quicksort)."""

from __future__ import annotations

import numpy as np
from numba import njit

from preform._kernels.fields import cell_order


@njit
def numba_argsort(keys):
    """numba's own np.argsort (quicksort), the order ``cell_order`` writes out."""
    return np.argsort(keys)


def test_cell_order_is_numbas_argsort_including_the_order_of_equal_keys():
    rng = np.random.default_rng(11)
    cases = [np.zeros(0, np.int64), np.array([5], np.int64), np.arange(100, dtype=np.int64)[::-1].copy(),
             np.zeros(1000, np.int64)]
    for n, span in ((14, 3), (15, 3), (16, 2), (200, 7), (5000, 40), (20000, 20000), (60000, 300)):
        cases.append(rng.integers(0, span, size=n).astype(np.int64))
    cases.append(np.sort(rng.integers(0, 50, size=3000)).astype(np.int64))   # sorted input with ties
    for keys in cases:
        got = cell_order(keys)
        np.testing.assert_array_equal(got, numba_argsort(keys))
        # and it is a sort (ties in numba's order, which NumPy's quicksort need not share)
        np.testing.assert_array_equal(keys[got], np.sort(keys))
