"""The frontal solver of the interaction model over a :class:`ZoneState` (paper §2.4; DESIGN.md §3.3).

Which reading of the paper this is, and why
-------------------------------------------
The paper's Fig. 10 alternates a force sweep from the supply side (single-contact solves give the
tensions and directions) with a position sweep from the fell points (two-line intersections), and
damps it with minimum-residual mixing (eq. 17). As a map ``C -> G(C)`` that iteration amplifies a
position error at a crossing by about (lower segment length / upper segment length) per sweep; new
crossings sit next to the supply points, so on realistic machines (case A: spool radius 1.382 m,
144 carriers) it diverges even without friction, and under-relaxation only slows the divergence.
A first version here kept the force sweep (discrete Capstan with the sliding direction of the last
step) and solved positions exactly for the tensions it gave; a sticking crossing then kept a
*tension ratio*, not its place on the yarns, and with friction on case A and case B the iteration
found no balance after a few hundred steps. So stick is now what it is physically.

Stick and slip as a material constraint
---------------------------------------
Every yarn carries a material coordinate ``s`` (m of yarn from a point of its deposited part):
``s[c, side]`` is the yarn material at crossing ``c``. A yarn *sticks* at a crossing when that
material does not move through it during the step (``s = s_old``): for inextensible yarns with
fixed neighbours this is the paper's "Eulerian angles fixed while sticking", and it holds the
crossing where it was on its yarns instead of letting it run to wherever a force ratio sends it.
A yarn *slips* when material passes (``s != s_old``); the friction force then is on the Amontons
bound, opposing the sliding.

One time step is the minimum of an energy over the crossing positions ``C`` and the material
coordinates ``s`` (``_kernels.frontal.assemble`` writes it out; convex but for the geometric part
of slack segments, see there):

* each segment between two crossings (or a crossing and the fell point) is a stiff tow of material
  length ``q = s_upper - s_lower`` and tension ``f = EA (l - q) / q``, ``EA = f_spool /
  TOW_STRAIN``: the paper's yarns are inextensible, and a real tow stretches ~5e-5 at the spool
  tension; 1e-3 is stiff enough to leave the geometry inextensible to 0.1 % and soft enough that a
  crossing's transverse motion of a millimetre (second order in the length) does not swamp the
  stretch, which is what Newton's steps must resolve. Tying EA to the spool tension keeps the
  model homogeneous in the forces, as Amontons friction is. A slack segment keeps 1 % of the
  stiffness (a yarn does not push);
* the spool pays yarn out at the top tension ``f_top`` (the spool tension, or Capstan ``exp(-mu_r
  eta)`` times it behind the guide ring, paper eq. 9);
* friction at every crossing and yarn is ``g |s - s_old|``, the work of the friction force against
  the sliding, with the bound ``g = mu (f_int + f_ext) tan(delta/2)`` held fixed: its
  stationarity ``f_int - f_ext in g d|s - s_old|`` *is* the discrete Capstan law of DESIGN.md
  §3.3 (``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``, equality while slipping, on the
  side that opposes the sliding). ``|x|`` is smoothed to ``sqrt(x^2 + eps^2) - eps``
  (``FRICTION_CREEP``, 0.1 mm): a sticking yarn gives ``eps r / sqrt(1 - r^2)`` to build up
  its friction force, ``r`` the used fraction of its bound (below ``eps`` while ``r < 0.7``),
  and its ``Psi`` stays strictly negative: a regularised Coulomb law, the price of Newton steps
  that converge. The friction term is centred where the last step left the friction force
  (``s_old = s - offset``, ``FRICTION_MEMORY``), so that give is not repeated at every step
  while the load stays, and a slipping yarn starts the step with its friction force. The three
  slip cases of the paper (warp, weft, both) come out of the one minimisation without case
  analysis. (An exact active set, stick as a stiff pin and slip with a fixed sense,
  was tried first: on case A and case B the set cycled between steps' worth of yarns.);
* jamming: two crossings of a yarn closer than a yarn width along it push apart (``JAM_FORCE``),
  as the crossing yarns lying side by side do; it keeps a yarn that friction has left slack from
  having its crossings pulled into one point;
* the mandrel is a wall: each crossing stays in front of the tangent plane of the mandrel surface
  nearest to it (a convex penalty, ``WALL_STIFFNESS``), so the lowest rows rest on the mandrel,
  where ``model.py`` deposits them, instead of being pulled through it.

``dE/dC = 0`` is pair balance at every crossing (paper eqs. 3-4, both yarns' internal and external
forces); ``dE/ds = 0`` is the friction law of each yarn. Damped Newton (sparse Hessian with 5
unknowns per crossing, positive definite by construction, see ``_kernels/frontal.py``; Armijo line
search on ``E``) descends from any start and converges quadratically near the solution; where it
does not converge within NEWTON_STEPS, the step is solved again by continuation in the friction
(``_balance_or_continue``). Each Newton direction is one sparse Cholesky factorisation (CHOLMOD)
of the Hessian in the nested-dissection order of the crossing lattice (``dissection_order``,
``_newton_direction``): its cost per crossing stays flat as the zone grows from 48 to 144
carriers, where SuperLU's minimum-degree order filled the factor ever more.

The bounds ``g`` depend on the tensions and the deflections (Amontons: the normal force), and the
top tensions on the ring deflections: an outer fixed point (the frontal iteration) re-evaluates them
from the balanced geometry and solves again until they change by less than ``FRICTION_TOLERANCE``
relative to the tensions; the residual history of a solve is that change per iteration. A time
step makes MAX_ITERATIONS of them (the bounds lag by up to a step), a snapshot up to
SNAPSHOT_ITERATIONS, to SNAPSHOT_TOLERANCE. Then every crossing is in balance to
``BALANCE_TOLERANCE`` and ``Psi <=`` the last change times ``(f_int + f_ext)``.
The friction state (stick or slip, the sliding direction) and the material coordinates carry over
from one step to the next: that history is what makes the model differ from a frictionless one.
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxopt as cvx
import numpy as np
import pymetis
import scipy.sparse as sp
from cvxopt import cholmod
from scipy.sparse.linalg import splu, spsolve

from .._kernels import frontal as K
from ..errors import SimulationError

#: Newton convergence: largest relative residual (force imbalance over the sum of the four
#: tensions; friction equation over f_int + f_ext); 1e4 times below what the exported snapshots
#: must meet (1e-3)
BALANCE_TOLERANCE = 1e-7
#: frontal (outer) convergence: change of the friction bounds and top tensions between iterations,
#: relative to the tensions; bounds Psi / (f_int + f_ext) of the result
FRICTION_TOLERANCE = 1e-6
#: frontal (outer) iterations per time step. The bounds of a crossing that slides through its
#: yarns settle slowly (a crossing that slides further deflects its yarns less and lowers its own
#: bound: the frontal map has slopes near 1 there), so a step stops after MAX_ITERATIONS and the
#: next step starts from the newest bounds: the bounds lag the geometry by up to a step, like any
#: explicit update of a state variable, and ``residual`` in history.csv says by how much. On the
#: 16-carrier cylinder of tests/test_interaction_sim.py with mu = 0.5, 1 iteration instead of 20
#: changes the mean convergence length by 0.08 % and the steady angle by 0.015 deg (2: 0.02 %,
#: 0.002 deg), and a second iteration costs as much as the first (on case A its Newton solve
#: moves sliding crossings by centimetres for a 1e-3 change of the bounds)
MAX_ITERATIONS = 1
#: frontal iterations for a snapshot: the exported crossings satisfy Psi to FRICTION_TOLERANCE
#: where the iteration converges within them, else to its last change, relative to the tensions
#: (benchmarks/bench_interaction.py plots it: most steps settle in 30-170 iterations, some hover
#: near 5e-4). Where it hovers, the largest change sits at a crossing where both yarns slip: its
#: balance ties its deflection to its tension jump, so a larger bound deflects it just enough to
#: raise the bound again by as much (the map has slope 1 there) and the bound drifts, by about
#: the change per iteration, until the crossing sticks. Anderson mixing of the last 5 iterates
#: (the paper's eq. 17 in a general form) and a Gauss-Seidel sweep of the bounds from the supply
#: side were tried: neither shortens that drift, since the residual does not depend on the bound
#: along it
SNAPSHOT_ITERATIONS = 100
#: frontal convergence of a snapshot (the ``friction_tol`` of its last solve): the written
#: crossings must satisfy Psi <= 1e-3 x tension (issue 4, read back from the files); a change of
#: the bounds below 1e-4 of f_int + f_ext (about twice the tension) leaves Psi a factor 5 below
#: that. FRICTION_TOLERANCE (1e-6) took 2 to 4 times as many frontal iterations where the
#: iteration converges (benchmarks/bench_interaction.py's plot), and the snapshots had taken 28 %
#: of the Newton steps of case A with 48 carriers and 20 snapshots
SNAPSHOT_TOLERANCE = 1e-4
#: Newton steps per inner solve
NEWTON_STEPS = 80
#: friction fractions of the continuation a step falls back to (``_balance_or_continue``)
CONTINUATION = (0.0, 0.25, 0.5, 0.75, 1.0)
#: strain of the tow at the spool tension: EA = f_spool / TOW_STRAIN (module docstring)
TOW_STRAIN = 1e-3
#: smoothing of |s - s_old| in the friction term, m of yarn per step (module docstring). Newton's
#: cost falls steeply with it: on a case A step (432 crossings, mu = 0.25) 1e-5 does not converge
#: in 80 steps, 3e-5 takes 67, 1e-4 takes 9 (7.5 with FRICTION_MEMORY; 3e-4 would save one
#: more). A sticking yarn gives less than 0.1 mm while its force grows to 70 % of its bound;
#: sliding yarns move millimetres per step
FRICTION_CREEP = 1e-4
#: friction memory: the friction term of the next step is centred where the yarn's friction force
#: carries over (``ZoneState.offset``), up to this fraction of the bound (a yarn slipping on its
#: bound starts the next step at 95 % of it, three FRICTION_CREEP from the centre; a yarn that
#: stops slipping moves back by at most that to lower its friction force): elastic-plastic
#: Coulomb friction, as contact codes regularise it. A sticking yarn then creeps only while its
#: force grows, not again at every step; and a slipping one starts each step with its friction
#: force instead of none, so Newton does not find its way out of the stick region anew
FRICTION_MEMORY = 0.95
#: a yarn whose material lies more than this from its friction centre at a crossing is reported
#: as slipping (it then uses more than 99.5 % of its friction bound), m
SLIP_REPORT = 10 * FRICTION_CREEP
#: tiny stiffness (N/m) that pins the material coordinate of a slack segment; changes a tension
#: jump by at most KAPPA0 x (slide in a step, < 0.1 m) = 1e-8 N
KAPPA0 = 1e-7
#: smoothing of the segment length, m^2: l = sqrt(|d|^2 + LENGTH_SMOOTHING)
LENGTH_SMOOTHING = 1e-12
#: Armijo constant and halvings of the line search
ARMIJO = 1e-4
LINE_SEARCH_HALVINGS = 50
ROUNDOFF = 1e-13
#: a Newton step whose predicted decrease of E (-slope) is below ROUNDOFF_SLOPE ROUNDOFF |E| is
#: taken whole (``_newton_step``)
ROUNDOFF_SLOPE = 10.0
#: iterative refinement steps of the Newton direction
REFINEMENT_STEPS = 2
#: relative residual of the Newton direction above which it is refined
REFINEMENT_TRIGGER = 1e-10
#: stiffness (N/m) of the mandrel wall that keeps crossings outside: 10 N push 1 um
WALL_STIFFNESS = 1e7
#: jamming: two crossings of a yarn closer than a yarn width along it push apart (the crossing
#: yarns lie side by side) with a force that reaches JAM_FORCE x the spool tension where they
#: would coincide: soft, of the order of the forces in the zone, so that crossings created close
#: together at a guide ring move apart instead of stopping Newton. Without it, a yarn gone slack
#: behind high friction (case B, mu 0.5, at 0.4 m) let the other yarns pull its crossings into one
#: point, with a 300 N segment between them, and Newton found no balance from there
JAM_FORCE = 1.0
#: factorise the Newton systems with CHOLMOD (else SuperLU's LU; ``_newton_direction``)
USE_CHOLMOD = True


@dataclass(frozen=True)
class Boundary:
    """What the zone hangs from at the end of a step, machine frame.

    fell : (2n, 3) float64, m, fell points; top : (2n, 3) ring points (guide ring) or spool points;
    spool : (2n, 3) spool points; f_spool : N; mu, mu_r : friction; has_ring : bool; h : m, half
    the yarn thickness; plane : (m, 6) or None, per crossing a point and the outward unit normal
    of the mandrel surface nearest to it (the crossings may not pass behind it); width : m, the
    yarn width, the least distance of two crossings along a yarn (jamming; 0: none).
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
    width: float = 0.0


@dataclass(frozen=True)
class SolveReport:
    """iterations (frontal), newton (Newton steps in all), residual (the larger of the balance
    residual and the last friction change), history (friction change per frontal iteration);
    lagged: the friction bounds had not settled to ``friction_tol`` after ``max_iter`` iterations
    (the balance holds; Psi is off by at most the last change, relative to the tensions);
    newton_residual, newton_energy: the balance residual and the energy E (J) at every Newton
    iterate of the solve, in order (over all its frontal iterations and continuation stages)."""

    iterations: int
    residual: float
    history: np.ndarray
    newton: int = 0
    lagged: bool = False
    newton_residual: np.ndarray | None = None
    newton_energy: np.ndarray | None = None


@dataclass
class _Pattern:
    nnz: int
    slot: np.ndarray
    size: int
    r: np.ndarray
    c: np.ndarray
    A: object


class _Network:
    """The arrays of a state and a boundary, bound for the kernels; ``g`` (m, 2) friction bounds
    and ``f_top`` (2n,) top tensions are the iterate of the frontal loop."""

    def __init__(self, state, bc, f_top):
        self.st, self.bc = state, bc
        m = state.m
        if bc.plane is None:
            self.plane = np.zeros((m, 6))
            self.plane[:, 2] = -1e300      # no mandrel: a wall far away
            self.plane[:, 5] = 1.0
        else:
            self.plane = np.ascontiguousarray(bc.plane[:m])
        self.s_old = state.s[:m].copy()
        self.EA = axial_stiffness(bc.f_spool)
        self.f_top = np.asarray(f_top, dtype=float).copy()
        self.g = np.zeros((m, 2))
        self.grad = np.zeros((m, 5))
        self.tension = np.zeros((m, 2))
        nmax = K.triplet_capacity(m, state.n_yarns)
        self.rows = np.empty(nmax, dtype=np.int64)
        self.cols = np.empty(nmax, dtype=np.int64)
        self.vals = np.empty(nmax)
        self.order = dissection_order(state.low[:m])
        self.rank = np.empty_like(self.order)
        self.rank[self.order] = np.arange(self.order.size)
        self.symbolic = None     # CHOLMOD's analysis of the Hessian's pattern
        self._pattern = None
        self.trace = []          # (residual, E) at every Newton iterate

    def pattern(self, nnz):
        """The lower triangle of the Hessian in the dissection order, from the triplets of
        ``assemble`` (the same triplets at every Newton step of a solve): ``size`` entries at
        ``r``, ``c`` (column-major, as cvxopt stores them), ``slot`` (the entry of each triplet,
        -1 above the diagonal) and ``A``, cvxopt's matrix of that pattern (its values are
        replaced at every Newton step: building it anew cost 5 ms on case A)."""
        p = self._pattern
        if p is not None and p.nnz == nnz:
            return p
        n = 5 * self.st.m
        slot, er, ec, size = K.lower_pattern(nnz, self.rows, self.cols, self.rank, n)
        er, ec = er.astype(np.intp), ec.astype(np.intp)
        A = cvx.spmatrix(cvx.matrix(np.zeros(size)), cvx.matrix(er), cvx.matrix(ec), (n, n))
        self._pattern = p = _Pattern(nnz=nnz, slot=slot, size=size, r=er, c=ec, A=A)
        self.symbolic = None
        return p

    def _args(self, pos, s):
        st, bc = self.st, self.bc
        return (st.m, st.n_yarns, st.yarn, pos, st.normal, st.over, st.low, st.highest, bc.fell,
                bc.top, s, st.s_fell, self.s_old, self.f_top, self.g, self.EA,
                FRICTION_CREEP, KAPPA0, bc.h, LENGTH_SMOOTHING, self.plane, WALL_STIFFNESS,
                bc.width, JAM_FORCE * bc.f_spool / max(bc.width, 1e-300))

    def assemble(self):
        st = self.st
        return K.assemble(*self._args(st.pos, st.s), self.grad, self.rows, self.cols, self.vals)

    def energy(self, pos, s):
        return K.energy(*self._args(pos, s))

    def update_tensions(self):
        st, bc = self.st, self.bc
        K.tensions(st.m, st.yarn, st.pos, st.normal, st.over, st.low, bc.fell, st.s, st.s_fell,
                   self.EA, bc.h, LENGTH_SMOOTHING, self.tension)

    def bounds(self):
        """Friction bounds, Psi / (f_int + f_ext) (m, 2) and top tensions of the current geometry
        and tensions."""
        st, bc = self.st, self.bc
        g = np.empty((st.m, 2))
        psi = np.empty((st.m, 2))
        f_top = np.empty(st.n_yarns)
        K.top_tensions(st.n_yarns, st.highest, st.pos, st.normal, st.over, bc.fell, bc.top,
                       bc.spool, bc.h, bc.f_spool, bc.mu_r, bc.has_ring, f_top)
        K.friction_bounds(st.m, st.yarn, st.pos, st.normal, st.over, st.low, st.up, bc.fell,
                          bc.top, self.tension, f_top, bc.h, bc.mu, g, psi)
        return g, psi, f_top

    def balance(self, tol, max_steps):
        """Newton on E with g and f_top fixed until the residual is below tol; (residual, steps)."""
        st = self.st
        for k in range(max_steps + 1):
            E, nnz = self.assemble()
            if not np.isfinite(E):
                raise SimulationError("a yarn segment between crossings lost its material length")
            self.update_tensions()
            res = K.imbalance(st.m, st.yarn, st.up, self.grad, self.tension, self.f_top)
            self.trace.append((res, E))
            if res < tol or k == max_steps:
                return res, k
            _newton_step(self, E, nnz)


def dissection_order(low):
    """Fill-reducing order of the 5 unknowns per crossing: METIS nested dissection of the crossing
    graph (crossings joined by a yarn segment; ``low`` (m, 2) the crossing below on each yarn,
    -1 at the fell point). Returns ``dof`` (5m,): row k of the reordered Hessian is row dof[k].

    The zone is a lattice of crossings wrapped around the mandrel; SuperLU's minimum-degree
    orderings fill a case A Hessian (11160 unknowns) with 2.5 M entries in 240 ms, nested
    dissection with 1.2 M in 50 ms (``benchmarks/bench_interaction.py``)."""
    m = low.shape[0]
    if m < 3:
        return np.arange(5 * m, dtype=np.intp)
    i = np.repeat(np.arange(m), 2)
    j = low.ravel()
    keep = j >= 0
    a = sp.coo_matrix((np.ones(int(keep.sum())), (i[keep], j[keep])), shape=(m, m))
    a = (a + a.T).tocsr()
    a.sum_duplicates()
    a.setdiag(0)
    a.eliminate_zeros()
    perm, _ = pymetis.nested_dissection(
        pymetis.CSRAdjacency(a.indptr.astype(np.int32), a.indices.astype(np.int32)))
    perm = np.asarray(perm).astype(np.intp)   # array("q") from pymetis: cvxopt wants "l"
    return (5 * perm[:, None] + np.arange(5)).ravel()


def _newton_direction(net, nnz, g):
    """Newton direction -H^-1 g of the assembled Hessian (``net.rows/cols/vals[:nnz]``).

    H is symmetric and positive definite by construction (``_kernels/frontal.py``: geometric
    floor, KAPPA0 in slack directions): a supernodal Cholesky factorisation (CHOLMOD, through
    cvxopt) in the nested-dissection order of the crossing lattice (``dissection_order``). Its
    analysis is made once per solve (the pattern of H is that of the crossing links). On a case A
    Hessian (11160 unknowns) it factorises in 15 ms where SuperLU's LU took 240 ms in its own
    order and 50 ms in this one. Where CHOLMOD finds H not positive definite (round-off on a
    nearly slack network), SuperLU's LU in the same order solves it. Then up to
    REFINEMENT_STEPS steps of iterative refinement where the direction's residual is above
    REFINEMENT_TRIGGER (H spans stiffnesses from KAPPA0 to EA / q)."""
    n = g.size
    dof = net.order
    pattern = net.pattern(nnz)
    v = np.empty(pattern.size)
    K.accumulate(nnz, pattern.slot, net.vals, v)
    solve_ordered = None       # a solve of H x = rhs in the dissection order
    if USE_CHOLMOD:
        A = pattern.A
        A.V = cvx.matrix(v)
        try:
            if net.symbolic is None:
                net.symbolic = cholmod.symbolic(A, p=cvx.matrix(np.arange(n, dtype=np.int64)))
            cholmod.numeric(A, net.symbolic)
        except ArithmeticError:
            net.symbolic = None   # not positive definite: LU below
        else:
            def solve_ordered(rhs):
                x = cvx.matrix(rhs)
                cholmod.solve(net.symbolic, x)
                return np.asarray(x).ravel()
    if solve_ordered is None:
        H = sp.csc_matrix((v, (pattern.r, pattern.c)), shape=(n, n))
        H = H + sp.tril(H, -1, format="csc").T
        try:
            solve_ordered = splu(H, permc_spec="NATURAL", diag_pivot_thresh=0.01,
                                 options=dict(SymmetricMode=True)).solve
        except RuntimeError:
            def solve_ordered(rhs):
                return spsolve(H, rhs)

    def solve(rhs):
        out = np.empty(n)
        out[dof] = solve_ordered(rhs[dof])
        return out

    dx = solve(-g)
    Hx = np.empty(n)
    gnorm = np.linalg.norm(g)
    for _ in range(REFINEMENT_STEPS):
        K.triplet_matvec(nnz, net.rows, net.cols, net.vals, dx, Hx)
        res = -g - Hx
        if not np.linalg.norm(res) > REFINEMENT_TRIGGER * gnorm:
            break
        dx += solve(res)
    return dx


def _newton_step(net, E, nnz):
    """One Newton step on E with Armijo backtracking; moves state.pos and state.s in place."""
    st = net.st
    m = st.m
    g = net.grad[:m].ravel()
    dx = _newton_direction(net, nnz, g)
    slope = float(g @ dx) if np.all(np.isfinite(dx)) else 0.0
    if not slope < 0.0:
        diag = np.bincount(net.rows[:nnz], weights=np.where(
            net.rows[:nnz] == net.cols[:nnz], net.vals[:nnz], 0.0), minlength=g.size)
        dx = -g / max(np.abs(diag).max(), 1e-300)   # gradient step as a fallback
        slope = float(g @ dx)
    pos0 = st.pos[:m].copy()
    s0 = st.s[:m].copy()
    step = dx.reshape(m, 5)
    t = 1.0
    # the decrease of E that Newton predicts (-slope / 2) below E's round-off: E cannot judge
    # the step (its change is noise of either sign), the full step is taken, and the balance
    # residual, which ``balance`` checks, judges it. (Case A, friction 0, step 278: E = 1026 J,
    # its round-off 1.2e-10 J, the predicted decrease 8e-14 J; every halving was refused and
    # Newton stalled at a residual of 1.3e-6.) Above it, Armijo backtracking on E, with the
    # allowance ROUNDOFF |E| for the last steps
    if not -slope < ROUNDOFF_SLOPE * ROUNDOFF * abs(E):
        for _ in range(LINE_SEARCH_HALVINGS):
            if net.energy(pos0 + t * step[:, :3], s0 + t * step[:, 3:]) <= (
                    E + ARMIJO * t * slope + ROUNDOFF * abs(E)):
                break
            t *= 0.5
    st.pos[:m] = pos0 + t * step[:, :3]
    st.s[:m] = s0 + t * step[:, 3:]


def solve_zone(state, bc: Boundary, f_top, *, tol=BALANCE_TOLERANCE,
               friction_tol=FRICTION_TOLERANCE, max_iter=MAX_ITERATIONS, where="",
               s_old=None) -> SolveReport:
    """Bring every crossing of ``state`` to balance with its friction law (module docstring), in
    place: positions, material coordinates, tensions, friction bounds and slip states of the
    crossings; f_top (2n,) receives the top tensions. ``state.s_fell`` must be anchored
    (``anchor_fell``). ``s_old`` (m, 2): where each yarn's material sticks (default:
    ``friction_centres(state)``). ``where`` names the step and time in the error message;
    :class:`SimulationError` if the residual stays above the tolerances."""
    m = state.m
    net = _Network(state, bc, f_top)
    net.s_old = np.array((friction_centres(state) if s_old is None else s_old)[:m], dtype=float)
    if m == 0:
        net.f_top = net.bounds()[2]
        f_top[:] = net.f_top
        return SolveReport(0, 0.0, np.zeros(0))
    # start: the bounds of the last step (new crossings: of the start geometry)
    net.tension[:] = state.tension[:m]
    g0, _, ft0 = net.bounds()
    fresh = ~np.isfinite(state.g[:m])
    net.g = np.where(fresh, g0, state.g[:m])
    net.f_top = ft0
    history = []
    newton = 0
    residual = np.inf
    change = np.inf
    for it in range(1, max_iter + 1):
        residual, steps = _balance_or_continue(net, tol)
        newton += steps
        if not residual < tol:
            break
        g1, psi, ft1 = net.bounds()
        scale = np.empty((m, 2))
        for side in range(2):
            u = state.up[:m, side]
            f_ext = np.where(u >= 0, net.tension[np.maximum(u, 0), side],
                             ft1[state.yarn[:m, side]])
            scale[:, side] = net.tension[:, side] + f_ext
        change = max(float(np.max(np.abs(g1 - net.g) / np.maximum(scale, 1e-300))),
                     float(np.max(np.abs(ft1 - net.f_top) / ft1)))
        history.append(change)
        if change < friction_tol:
            _accept(state, net, f_top)
            return SolveReport(it, max(float(residual), change), np.array(history), newton,
                               **_trace(net))
        if it == max_iter:
            # friction bounds lagged: balance holds, Psi to within the last change; the next
            # step starts from the newest bounds
            _accept(state, net, f_top)
            state.g[:m] = g1
            return SolveReport(it, max(float(residual), change), np.array(history), newton,
                               lagged=True, **_trace(net))
        net.g, net.f_top = g1, ft1
    raise SimulationError(
        f"the frontal solver of the yarn-interaction model did not converge {where}: relative "
        f"force imbalance (residual) {residual:.3g} after {newton} Newton steps (tolerance "
        f"{tol:.3g}, {m} crossings)")


def _trace(net):
    t = np.array(net.trace, dtype=float).reshape(-1, 2)
    return dict(newton_residual=t[:, 0], newton_energy=t[:, 1])


def _balance_or_continue(net, tol):
    """``net.balance``; where Newton does not converge from the step's start (a crossing that
    must slide far against friction), the same solve by continuation in the friction: from the
    start again without friction (the frictionless network converges robustly), then with the
    bounds scaled up in CONTINUATION stages, each warm-started from the last."""
    st = net.st
    m = st.m
    pos0, s0 = st.pos[:m].copy(), st.s[:m].copy()
    residual, steps = net.balance(tol, NEWTON_STEPS)
    if residual < tol or not np.any(net.g > 0.0):
        return residual, steps
    g = net.g
    st.pos[:m], st.s[:m] = pos0, s0
    total = steps
    try:
        for frac in CONTINUATION:
            net.g = frac * g
            residual, steps = net.balance(tol, NEWTON_STEPS)
            total += steps
            if not residual < tol:
                break
    finally:
        net.g = g
    return residual, total


def _accept(state, net, f_top):
    m = state.m
    state.tension[:m] = net.tension
    state.g[:m] = net.g
    slide = state.s[:m] - net.s_old
    state.slip[:m] = np.where(np.abs(slide) > SLIP_REPORT, np.sign(slide), 0)
    cap = memory_cap()
    state.offset[:m] = np.clip(slide, -cap, cap)
    f_top[:] = net.f_top


def friction_centres(state):
    """(m, 2) m: where each yarn's friction term at each crossing is centred for the next solve,
    its material coordinate less the friction offset the last step carried over
    (``FRICTION_MEMORY``)."""
    return state.s[: state.m] - state.offset[: state.m]


def memory_cap():
    """Largest friction offset carried to the next step (m): where the smoothed friction force
    g x / sqrt(x^2 + eps^2) reaches FRICTION_MEMORY g."""
    r = FRICTION_MEMORY
    return FRICTION_CREEP * r / np.sqrt(1.0 - r * r)


def axial_stiffness(f_spool):
    """EA of the tow (N) for the spool tension f_spool (N): f_spool / TOW_STRAIN."""
    return float(f_spool) / TOW_STRAIN


def anchor_fell(state, bc):
    """Material coordinate of every yarn's fell point (``_kernels.frontal.reanchor``): the yarn
    laid since the last step leaves the tension of the lowest segment as it was."""
    K.reanchor(state.n_yarns, state.lowest, state.yarn, state.pos, state.normal, state.over,
               np.ascontiguousarray(bc.fell, dtype=float), state.s, state.tension,
               axial_stiffness(bc.f_spool), bc.h, LENGTH_SMOOTHING, state.s_fell)


def new_material(state, c, side, below_point, f, bc):
    """Material coordinate for yarn ``side`` of a crossing ``c`` just created on top of its
    yarn: the new segment from ``below_point`` (the yarn point below) carries the tension f."""
    k = state.yarn[c, side]
    lo = state.low[c, side]
    s_below = state.s[lo, side] if lo >= 0 else state.s_fell[k]
    p = state.centerline_point(c, side, bc.h)
    l = float(np.sqrt(np.sum((p - below_point) ** 2) + LENGTH_SMOOTHING))
    return s_below + l / (1.0 + f / axial_stiffness(bc.f_spool))
