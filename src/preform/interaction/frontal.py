"""The frontal solver of the interaction model over a :class:`ZoneState` (paper §2.4; DESIGN.md §3.3).

Which reading of the paper this is, and why
-------------------------------------------
The paper's Fig. 10 alternates a force sweep from the supply side (single-contact solves give the
tensions and directions) with a position sweep from the fell points (two-line intersections), and
damps it with minimum-residual mixing (eq. 17). As a map ``C -> G(C)`` that iteration amplifies a
position error at a crossing by about (lower segment length / upper segment length) per sweep; new
crossings sit next to the supply points, so on realistic machines (case A: spool radius 1.382 m,
144 carriers) it diverges even without friction, and under-relaxation only slows the divergence.

Here the same two half-steps are kept, but the position half-step is solved exactly:

1. *Force sweep* (supply side -> fell points, ``_kernels.frontal.capstan_sweep``): every yarn's
   tension below a crossing from the tension above it, by the friction law in its discrete Capstan
   form (DESIGN.md §3.3): ``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``, ``delta`` the
   yarn's deflection at the crossing. A slipping yarn sits on the bound on the side of its sliding
   direction (``Psi = 0``); a sticking yarn keeps the tension ratio it had, clipped into the cone
   (``Psi <= 0``). The top tension is the spool tension, or the Capstan ``exp(mu_r eta)`` of the
   guide ring (paper eq. 9).
2. *Position step*: with those tensions, pair balance at every crossing (paper eqs. 3-4, both
   yarns' internal and external forces) is the stationary point of the convex function
   ``E(C) = sum over segments of tension x length``: a weighted Fermat point at every crossing,
   coupled through the segments. The mandrel is a wall: each crossing stays in front of the
   tangent plane of the mandrel surface nearest to it (a convex penalty, ``WALL_STIFFNESS``), so
   the lowest rows rest on the mandrel, where ``model.py`` deposits them, instead of being pulled
   through it by the yarns that wrap around it. One damped Newton step on ``E`` (sparse Hessian, 3x3 blocks per
   segment, Armijo line search on ``E``) moves all crossings at once, so the long-wave modes that
   make a Gauss-Seidel or shooting sweep slow or unstable are solved directly, and the convexity
   of ``E`` makes every step a descent step whatever the segment lengths.

The two steps repeat until the relative force imbalance (``|sum of the four yarn forces| / sum of
the four tensions``, the largest over the crossings) is below ``BALANCE_TOLERANCE`` with the
tensions of the current geometry: then balance holds and every yarn satisfies its friction law.
The tensions depend on the geometry only through the deflections, weakly (``mu tan(delta/2)``
is small), so this outer loop contracts fast; Newton makes the inner problem quadratic. No
minimum-residual mixing is needed (it is not used). Cost per iteration: an assembly linear in the
crossings and a sparse factorisation of the crossing lattice (a 2D grid: nearly linear).

The Eulerian angles of the paper are not the unknowns here; the friction state is carried as the
sliding direction per yarn and crossing (``ZoneState.slip``) and decided kinematically between
steps (``update_slide``): the yarn length from the fell point up to the crossing, plus the yarn
laid on the mandrel in the step, changes by the material that passed through the crossing. Its
sign gives the sliding direction, and so the side of the friction bound, for the next step (an
explicit, one-step-lagged return mapping); where it vanishes or reverses the crossing sticks with
its current tension ratio. New crossings start sliding with ``-1``: near the supply a crossing
runs down its yarns much faster than the yarns are drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from .._kernels import frontal as K
from ..errors import SimulationError

#: convergence: largest relative force imbalance over the crossings
BALANCE_TOLERANCE = 1e-9
#: outer iterations (force sweep, position step) per solve
MAX_ITERATIONS = 25
#: Newton steps per position step
NEWTON_STEPS = 30
#: depth of the minimum-residual (Anderson) mixing of the tensions
ANDERSON_DEPTH = 5
#: the final check (balance with the last friction tensions) accepts this times the tolerance
BALANCE_ACCEPT = 10.0
#: smoothing of the segment length, m^2: l = sqrt(|d|^2 + LENGTH_SMOOTHING). Changes a force by
#: the relative amount LENGTH_SMOOTHING / (2 l^2): < 1e-6 for segments longer than 0.7 um
LENGTH_SMOOTHING = 1e-12
#: Armijo constant and halvings of the line search
ARMIJO = 1e-4
LINE_SEARCH_HALVINGS = 40
ROUNDOFF = 1e-13
#: conjugate-gradient iterations before the sparse LU fallback
CG_MAX_ITERATIONS = 3000
#: stiffness (N/m) of the mandrel wall that keeps crossings outside: 10 N push 1 um
WALL_STIFFNESS = 1e7
#: |material slid through a crossing in a step| below this (m) counts as sticking
SLIDE_TOLERANCE = 1e-7


@dataclass(frozen=True)
class Boundary:
    """What the zone hangs from at the end of a step, machine frame.

    fell : (2n, 3) float64, m, fell points; top : (2n, 3) ring points (guide ring) or spool points;
    spool : (2n, 3) spool points; f_spool : N; mu, mu_r : friction; has_ring : bool; h : m, half
    the yarn thickness; plane : (m, 6) or None, per crossing a point and the outward unit normal
    of the mandrel surface nearest to it (the crossings may not pass behind it).
    """

    fell: np.ndarray
    top: np.ndarray
    spool: np.ndarray
    f_spool: float
    mu: float
    mu_r: float
    has_ring: bool
    h: float
    plane: np.ndarray | None = None


@dataclass(frozen=True)
class SolveReport:
    """iterations, residual (relative force imbalance), history (residual per iteration)."""

    iterations: int
    residual: float
    history: np.ndarray
    lagged: bool = False
    stuck: bool = False


class _Network:
    """The arrays of a state and a boundary, bound for the kernels. ``tension`` / ``f_top`` are
    the tensions the position step uses (the iterate of the outer loop)."""

    def __init__(self, state, bc, f_top):
        self.st, self.bc = state, bc
        m = state.m
        if bc.plane is None:
            self.plane = np.zeros((m, 6))
            self.plane[:, 2] = -1e300      # no mandrel: a wall far away
            self.plane[:, 5] = 1.0
        else:
            self.plane = np.ascontiguousarray(bc.plane[:m])
        self.tension = state.tension[:m].copy()
        self.f_top = np.asarray(f_top, dtype=float).copy()
        self.grad = np.zeros((m, 3))
        nmax = 36 * (2 * m + state.n_yarns) + 9 * m
        self.rows = np.empty(nmax, dtype=np.int64)
        self.cols = np.empty(nmax, dtype=np.int64)
        self.vals = np.empty(nmax)

    def friction_tensions(self):
        """The force sweep at the current positions: (tension (m, 2), f_top (2n,)), N."""
        st, bc = self.st, self.bc
        f_top = np.empty(st.n_yarns)
        tension = np.zeros((st.m, 2))
        K.top_tensions(st.n_yarns, st.highest, st.pos, st.normal, st.over, bc.fell, bc.top,
                       bc.spool, bc.h, bc.f_spool, bc.mu_r, bc.has_ring, f_top)
        K.capstan_sweep(st.m, st.yarn, st.pos, st.normal, st.over, st.low, st.up, bc.fell, bc.top,
                        f_top, bc.h, bc.mu, st.slip, st.ratio, tension)
        return tension, f_top

    def assemble(self):
        st, bc = self.st, self.bc
        E, nnz = K.assemble(st.m, st.n_yarns, st.yarn, st.pos, st.normal, st.over, st.low,
                            st.highest, bc.fell, bc.top, self.f_top, self.tension, bc.h,
                            LENGTH_SMOOTHING, self.plane, WALL_STIFFNESS, self.grad, self.rows,
                            self.cols, self.vals)
        return E, nnz

    def energy(self, pos):
        st, bc = self.st, self.bc
        return K.energy(st.m, st.n_yarns, st.yarn, pos, st.normal, st.over, st.low, st.highest,
                        bc.fell, bc.top, self.f_top, self.tension, bc.h, LENGTH_SMOOTHING,
                        self.plane, WALL_STIFFNESS)

    def imbalance(self):
        st = self.st
        return K.balance_error(st.m, st.yarn, st.up, self.grad, self.tension, self.f_top)

    def balance(self, tol, max_steps):
        """Newton steps on E with the tensions fixed until the imbalance is below tol; the last
        imbalance and the number of steps."""
        for k in range(max_steps + 1):
            E, nnz = self.assemble()
            res = self.imbalance()
            if res < tol or k == max_steps:
                return res, k
            _newton_step(self, E, nnz, res)


class _Anderson:
    """Minimum-residual (Anderson type II) mixing of a fixed point x = Phi(x), depth ``depth``:
    the paper's eq. 17 generalised from one to several past residuals."""

    def __init__(self, depth):
        self.depth = depth
        self.dx, self.dr = [], []
        self.x_prev = self.r_prev = None

    def next(self, x, phi):
        r = phi - x
        if self.x_prev is not None:
            self.dx.append(x - self.x_prev)
            self.dr.append(r - self.r_prev)
            if len(self.dx) > self.depth:
                self.dx.pop(0)
                self.dr.pop(0)
        self.x_prev, self.r_prev = x, r
        if not self.dx:
            return phi
        DR = np.stack(self.dr, axis=1)
        DX = np.stack(self.dx, axis=1)
        gamma = np.linalg.lstsq(DR, r, rcond=1e-12)[0]
        return phi - (DX + DR) @ gamma


def _newton_direction(H, g, forcing):
    """Newton direction: block-Jacobi conjugate gradients to the relative accuracy ``forcing``
    (inexact Newton), sparse LU where CG stalls."""
    H.sum_duplicates()
    dx = np.empty_like(g)
    it = K.pcg(H.indptr.astype(np.int64), H.indices.astype(np.int64), H.data, -g, forcing,
               CG_MAX_ITERATIONS, dx)
    if it >= CG_MAX_ITERATIONS or not np.all(np.isfinite(dx)):
        dx = spsolve(H.tocsc(), -g, permc_spec="MMD_ATA")
    return dx


def _newton_step(net, E, nnz, residual=1.0):
    """One (inexact) Newton step on E with Armijo backtracking; moves state.pos in place.
    ``residual``: the current relative imbalance (sets the CG accuracy). Returns |step|."""
    st = net.st
    m = st.m
    H = sp.csr_matrix((net.vals[:nnz], (net.rows[:nnz], net.cols[:nnz])), shape=(3 * m, 3 * m))
    g = net.grad[:m].ravel()
    # Eisenstat-Walker-like forcing: what this step must reach, no more
    forcing = min(0.1, max(residual, 0.1 * BALANCE_TOLERANCE / max(residual, 1e-300), 1e-12))
    dx = _newton_direction(H, g, forcing)
    if not np.all(np.isfinite(dx)):
        dx = -g / max(np.abs(H.diagonal()).max(), 1e-300)   # gradient step as a fallback
    slope = float(g @ dx)
    if slope >= 0.0:
        dx = -g / max(np.abs(H.diagonal()).max(), 1e-300)
        slope = float(g @ dx)
    pos0 = st.pos[:m].copy()
    step = dx.reshape(m, 3)
    t = 1.0
    for _ in range(LINE_SEARCH_HALVINGS):
        trial = pos0 + t * step
        # the allowance ROUNDOFF |E| lets the last Newton steps through, whose decrease of E is
        # below the round-off of E
        if net.energy(trial) <= E + ARMIJO * t * slope + ROUNDOFF * abs(E):
            break
        t *= 0.5
    st.pos[:m] = pos0 + t * step
    return t * float(np.abs(step).max())


def solve_zone(state, bc: Boundary, f_top, *, tol=BALANCE_TOLERANCE, max_iter=MAX_ITERATIONS,
               where="") -> SolveReport:
    """Balance the zone with the friction law solved with the geometry (``_solve``). Where that
    finds no converged balance within ``max_iter`` iterations (a slipping yarn's bound can lose
    its equilibrium nearby: the coupled tension-geometry iteration then drifts), the step falls
    back to *lagged* friction: the friction tensions of the step's start geometry, held fixed,
    and one exact (convex) balance solve. Then force balance is exact and ``Psi`` holds up to the
    change of the deflections in one step (first order in the time step); ``SolveReport.lagged``
    says so. If that fails too, every crossing sticks with equal tensions (``SolveReport.stuck``).
    SimulationError if even that solve fails."""
    start = state.pos[: state.m].copy()
    try:
        return _solve(state, bc, f_top, tol, max_iter, where)
    except SimulationError:
        if state.m == 0:
            raise
    state.pos[: state.m] = start
    try:
        return _lagged(state, bc, f_top, tol, where)
    except SimulationError:
        pass
    # last resort: every crossing sticks with equal tensions (inside every cone, Psi <= 0): the
    # frictionless network, which is convex with geometry-independent tensions
    state.pos[: state.m] = start
    state.slip[: state.m] = 0
    state.ratio[: state.m] = 1.0
    rep = _lagged(state, bc, f_top, tol, where)
    return SolveReport(rep.iterations, rep.residual, rep.history, lagged=True, stuck=True)


def _lagged(state, bc, f_top, tol, where) -> SolveReport:
    """Friction tensions of the start geometry held fixed, one convex balance solve."""
    net = _Network(state, bc, f_top)
    net.tension, net.f_top = net.friction_tensions()
    residual, steps = net.balance(tol, 4 * NEWTON_STEPS)
    if not residual < tol:
        raise SimulationError(
            f"the frontal solver of the yarn-interaction model did not converge {where}: relative "
            f"force imbalance (residual) {residual:.3g} after {steps} Newton steps with lagged "
            f"friction (tolerance {tol:.3g}, {state.m} crossings)")
    state.tension[: state.m] = net.tension
    f_top[:] = net.f_top
    return SolveReport(steps, float(residual), np.array([residual]), lagged=True)


def _solve(state, bc, f_top, tol, max_iter, where) -> SolveReport:
    """Bring every crossing of ``state`` to balance with its friction law (in place; module
    docstring). f_top (2n,) receives the top tensions. ``where`` names the step and time in the
    error message; :class:`SimulationError` if the residual stays above ``tol``.

    Outer loop (``max_iter`` iterations): position step to balance with the current tensions,
    force sweep at the new positions; the residual is the larger of the relative change of the
    tensions and the relative force imbalance. The tensions are mixed by ``_Anderson``."""
    m = state.m
    net = _Network(state, bc, f_top)
    t0, ft0 = net.friction_tensions()
    if m == 0:
        f_top[:] = ft0
        return SolveReport(0, 0.0, np.zeros(0))
    net.tension, net.f_top = t0, ft0
    mix = _Anderson(ANDERSON_DEPTH)
    history = []
    residual = np.inf
    x = np.concatenate([t0.ravel(), ft0])
    scale = max(float(np.abs(ft0).max()), 1e-300)
    for it in range(1, max_iter + 1):
        imbalance, _ = net.balance(tol, NEWTON_STEPS)
        t1, ft1 = net.friction_tensions()
        phi = np.concatenate([t1.ravel(), ft1])
        change = float(np.abs(phi - x).max()) / scale
        residual = max(change, imbalance)
        history.append(residual)
        if change < tol:
            # the friction tensions of the final geometry: Psi exact, balance to ~tol
            net.tension, net.f_top = t1, ft1
            net.assemble()
            residual = max(residual, net.imbalance())
            state.tension[:m] = t1
            f_top[:] = ft1
            history[-1] = residual
            if residual < BALANCE_ACCEPT * tol:
                return SolveReport(it, float(residual), np.array(history))
            break
        x = np.maximum(mix.next(x, phi), 1e-12 * scale)
        net.tension = x[: 2 * m].reshape(m, 2).copy()
        net.f_top = x[2 * m:].copy()
    raise SimulationError(
        f"the frontal solver of the yarn-interaction model did not converge {where}: residual "
        f"(relative force imbalance / tension change) {residual:.3g} after {len(history)} "
        f"iterations (tolerance {tol:.3g}, {m} crossings)")


def update_slide(state, bc: Boundary, f_top, laid):
    """Decide each crossing's friction state for the next step (module docstring), in place.

    f_top : (2n,) N, top tensions of the last solve; laid : (2n,) float64, m, yarn laid on the mandrel by each yarn since the last call.
    """
    m = state.m
    if m == 0:
        return
    L = np.empty((m, 2))
    K.below_lengths(m, state.yarn, state.pos, state.normal, state.over, state.low, bc.fell,
                    bc.h, L)
    old = state.below_len[:m]
    known = np.isfinite(old)
    w = L - old + np.asarray(laid)[state.yarn[:m]]          # material passed down through C
    new = np.where(w > SLIDE_TOLERANCE, 1, np.where(w < -SLIDE_TOLERANCE, -1, 0)).astype(np.int8)
    prev = state.slip[:m]
    stick = known & ((new == 0) | ((prev != 0) & (new != prev)))
    slide = known & ~stick
    f_ext = np.empty((m, 2))
    for side in range(2):
        u = state.up[:m, side]
        f_ext[:, side] = np.where(u >= 0, state.tension[np.maximum(u, 0), side],
                                  np.asarray(f_top)[state.yarn[:m, side]])
    ratio = state.tension[:m] / f_ext
    keep = np.isfinite(ratio)
    state.ratio[:m][keep] = ratio[keep]
    state.slip[:m][stick] = 0
    state.slip[:m][slide] = new[slide]
    state.below_len[:m] = L
