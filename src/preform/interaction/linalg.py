"""Sparse factorisation of the interaction model's Newton systems, with a backend chosen at import.

The Newton matrix H of ``interaction/frontal.py`` is symmetric positive definite by construction
(``_kernels/frontal.py``), with the same pattern at every Newton step of a solve. It is handed over
as its lower triangle in an elimination order (METIS nested dissection of the crossing lattice,
``frontal.dissection_order``), column-major, and factorised in that order:

* ``"cholmod"``: CHOLMOD's supernodal Cholesky through ``cvxopt`` (an optional extra,
  ``pip install preform[cholmod]``; cvxopt is GPL-3), its symbolic analysis made once per pattern;
* ``"splu"``: SciPy's SuperLU (BSD) on the same matrix in the same order (``permc_spec=
  "NATURAL"``), always available.

Both solve H x = b to round-off; ``frontal`` refines the direction against the assembled H, so
the two give the same Newton steps to the solver's round-off. CHOLMOD is about 3x faster on a
case A Hessian (figures: ``docs/decisions.md``). Where CHOLMOD finds H not positive
definite in floating point (a nearly slack network), the LU solves that system.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu, spsolve

try:  # the optional accelerator (module docstring)
    import cvxopt as _cvx
    from cvxopt import cholmod as _cholmod
except ImportError:  # pragma: no cover - depends on the installation
    _cvx = _cholmod = None

#: the backends this installation has, fastest first
AVAILABLE: tuple[str, ...] = (("cholmod",) if _cholmod is not None else ()) + ("splu",)
#: the backend ``"auto"`` stands for
DEFAULT: str = AVAILABLE[0]
#: partial pivoting threshold of the LU: small, so that SuperLU keeps the given order (H is
#: positive definite, its diagonal dominates) and pivots only where round-off demands it
LU_PIVOT_THRESHOLD = 0.01


def backend(name: str) -> str:
    """The backend for ``[newton] linear_solver = name`` ("auto", "cholmod", "splu")."""
    if name == "auto":
        return DEFAULT
    if name not in ("cholmod", "splu"):
        raise ValueError(f"linear_solver = {name!r}: expected 'auto', 'cholmod' or 'splu'")
    if name not in AVAILABLE:
        raise ValueError(f"linear_solver = {name!r}: cvxopt is not installed "
                         "(pip install 'preform[cholmod]'), or use 'auto' or 'splu'")
    return name


class LowerFactoriser:
    """Factorisations of symmetric matrices of one pattern: the lower triangle's ``size`` entries
    at rows ``r``, columns ``c`` (sorted by column, then row) of an n x n matrix.
    ``factorise(values)`` returns ``solve(b) -> x`` for the matrix with those entry values."""

    def __init__(self, r: np.ndarray, c: np.ndarray, n: int, name: str = "auto"):
        self.r = np.asarray(r, dtype=np.intp)
        self.c = np.asarray(c, dtype=np.intp)
        self.n = int(n)
        self.backend = backend(name)
        self.matrix = None       # cvxopt's matrix of the pattern (its values replaced each time)
        self.symbolic = None     # CHOLMOD's analysis of the pattern, made on first use
        if self.backend == "cholmod":
            self.matrix = _cvx.spmatrix(_cvx.matrix(np.zeros(self.r.size)), _cvx.matrix(self.r),
                                        _cvx.matrix(self.c), (self.n, self.n))

    def factorise(self, values: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        if self.backend == "cholmod":
            solve = self._cholmod(values)
            if solve is not None:
                return solve
        return self._lu(values)

    def _cholmod(self, values):
        A = self.matrix
        A.V = _cvx.matrix(values)
        try:
            if self.symbolic is None:
                self.symbolic = _cholmod.symbolic(A, p=_cvx.matrix(np.arange(self.n, dtype=np.int64)))
            _cholmod.numeric(A, self.symbolic)
        except ArithmeticError:
            self.symbolic = None   # not positive definite in floating point: the LU solves it
            return None
        symbolic = self.symbolic

        def solve(rhs):
            x = _cvx.matrix(rhs)
            _cholmod.solve(symbolic, x)
            return np.asarray(x).ravel()
        return solve

    def _lu(self, values):
        n = self.n
        H = sp.csc_matrix((values, (self.r, self.c)), shape=(n, n))
        H = H + sp.tril(H, -1, format="csc").T
        try:
            return splu(H, permc_spec="NATURAL", diag_pivot_thresh=LU_PIVOT_THRESHOLD,
                        options=dict(SymmetricMode=True)).solve
        except RuntimeError:   # exactly singular: SciPy's general solve says so
            return lambda rhs: spsolve(H, rhs)
