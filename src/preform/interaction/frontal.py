"""The iterative frontal solver over a :class:`ZoneState` (paper §2.4, Fig. 10; DESIGN.md §3.3).

``solve_zone`` runs the numba kernel ``preform._kernels.frontal.frontal_solve`` (force sweep from
the supply side, position sweep from the fell points, minimum-residual mixing; see that module for
the single-contact reading and the sweeps) on all crossings. If that does not converge within
``MAX_ITERATIONS`` it starts again from the step's initial positions growing the active rows in
steps (paper Fig. 10: the newest ``ROW_STEP`` rows, then ``2 ROW_STEP``, ...; the older crossings are
held where they are until their turn), and raises :class:`preform.errors.SimulationError` if that
fails too. A *row* is one carrier pass period's worth of crossings (``n`` of them); rows are ragged
on a non-axisymmetric mandrel, so only the creation order is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._kernels import frontal as K
from ..errors import SimulationError

#: convergence of the frontal iteration: max |Delta C| over the crossings, m (paper's epsilon)
FRONTAL_TOLERANCE = 1e-8
#: frontal iterations per attempt
MAX_ITERATIONS = 300
#: a yarn slips when Psi > PSI_TOLERANCE * (f_int + f_ext)
PSI_TOLERANCE = 1e-9
#: bound of the mixing factor lambda of the minimum-residual step (paper eq. 17)
LAMBDA_MAX = 1.0
#: rows added per stage when the plain iteration fails (paper's h_step)
ROW_STEP = 4


@dataclass(frozen=True)
class Boundary:
    """What the zone hangs from at the end of a step, machine frame.

    fell : (2n, 3) float64, m, fell points; top : (2n, 3) ring points (guide ring) or spool points;
    spool : (2n, 3) spool points; f_spool : N; mu, mu_r : friction; has_ring : bool; h : m, half
    the yarn thickness.
    """

    fell: np.ndarray
    top: np.ndarray
    spool: np.ndarray
    f_spool: float
    mu: float
    mu_r: float
    has_ring: bool
    h: float


@dataclass(frozen=True)
class SolveReport:
    """iterations (total over attempts), residual (m), history (residual per iteration, m)."""

    iterations: int
    residual: float
    history: np.ndarray


def _run(state, bc, first, f_top, eps, max_iter):
    m = state.m
    work = np.zeros((3, m, 3))
    history = np.zeros(max_iter)
    it, res, ok = K.frontal_solve(
        m, first, state.n_yarns, state.yarn, state.pos, state.normal, state.over, state.theta_ref,
        state.low, state.up, state.highest, bc.fell, bc.top, bc.spool, bc.h, bc.f_spool, bc.mu,
        bc.mu_r, bc.has_ring, PSI_TOLERANCE, eps, max_iter, LAMBDA_MAX, state.theta, state.slip,
        state.tension, state.resultant, f_top, work, history)
    return it, res, ok, history[:it]


def solve_zone(state, bc: Boundary, f_top, *, eps=FRONTAL_TOLERANCE, max_iter=MAX_ITERATIONS,
               where="") -> SolveReport:
    """Bring every crossing of ``state`` to balance (in place). f_top (2n,) receives the top
    tensions. ``where`` names the step and time in the error message."""
    K.top_tensions(state.n_yarns, state.highest, state.pos, state.normal, state.over, bc.fell,
                   bc.top, bc.spool, bc.h, bc.f_spool, bc.mu_r, bc.has_ring, f_top)
    if state.m == 0:
        return SolveReport(0, 0.0, np.zeros(0))
    start = state.pos[: state.m].copy()
    it, res, ok, hist = _run(state, bc, 0, f_top, eps, max_iter)
    total, hists = it, [hist]
    if not ok:
        state.pos[: state.m] = start
        row = state.n_yarns // 2
        n_active = ROW_STEP * row
        while True:
            first = max(0, state.m - n_active)
            it, res, ok, hist = _run(state, bc, first, f_top, eps, max_iter)
            total += it
            hists.append(hist)
            if not ok or first == 0:
                break
            n_active += ROW_STEP * row
    if not ok:
        raise SimulationError(
            f"the frontal solver of the yarn-interaction model did not converge {where}: residual "
            f"{res:.3g} m after {total} iterations (tolerance {eps:.3g} m, {state.m} crossings)")
    return SolveReport(total, float(res), np.concatenate(hists))
