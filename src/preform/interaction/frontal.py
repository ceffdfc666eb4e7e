"""The frontal solver of the interaction model over a :class:`ZoneState` (paper §2.4; docs/theory.md §4).

Stick and slip as a material constraint
---------------------------------------
Every yarn carries a material coordinate (m of yarn from a point of its deposited part):
``material[c, side]`` is the yarn material at crossing ``c``. A yarn *sticks* at a crossing when
that material does not move through it during the step (``material = centre``, its friction
centre): for inextensible yarns with fixed neighbours this is the paper's "Eulerian angles fixed
while sticking", and it holds the crossing where it was on its yarns. A yarn *slips* when material
passes; the friction force then is on the bound of its friction law, opposing the sliding. The
paper's force/position sweeps (its Fig. 10) are replaced by this formulation because, as a map, that
iteration diverges on realistic machines (``docs/decisions.md``).

One time step is the minimum of an energy over the crossing positions ``C`` and the material
coordinates ``u`` (``_kernels.frontal.assemble`` writes it out; convex but for the geometric part
of slack segments, see there). The constants below are fields of
:class:`~preform.interaction.settings.InteractionSettings` (``s.energy``, ``s.newton``,
``s.frontal``):

* each segment between two crossings (or a crossing and the fell point) is a stiff tow of material
  length ``q = u_upper - u_lower`` and tension ``f = EA (l - q) / q``, ``EA = f_spool /
  tow_strain`` (the paper's yarns are inextensible; tying EA to the spool tension keeps the model
  homogeneous in the forces, as Amontons friction is). A slack segment keeps ``compression`` of
  the stiffness (a yarn does not push);
* the spool pays yarn out at the top tension ``f_top`` (the spool tension, or Capstan ``exp(-mu_r
  eta)`` times it behind the guide ring, paper eq. 9);
* friction at every crossing and yarn is ``bound |u - centre|``, the work of the friction force
  against the sliding, with the bound ``mu (f_int + f_ext) tan(delta/2)`` held fixed (``mu`` the
  crossing's law at its normal force, ``Boundary.friction``: Amontons' constant or Howell's
  ``friction (N / N_ref)^(n - 1)``): its
  stationarity ``f_int - f_ext in bound d|u - centre|`` *is* the discrete Capstan law of
  docs/theory.md §4 (``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``, equality while slipping, on the
  side that opposes the sliding). ``|x|`` is smoothed to ``sqrt(x^2 + eps^2) - eps`` (``eps =
  friction_creep``): a sticking yarn gives ``eps r / sqrt(1 - r^2)`` to build up its friction
  force, ``r`` the used fraction of its bound, and its ``Psi`` stays strictly negative: a
  regularised Coulomb law. The friction centre is where the last step left the friction force
  (``centre = material - offset``, ``friction_memory``: elastic-plastic Coulomb friction), so that
  give is not repeated at every step while the load stays, and a slipping yarn starts the step
  with its friction force. The three slip cases of the paper (warp, weft, both) come out of the
  one minimisation without case analysis;
* jamming: two crossings of a yarn closer than a yarn width along it push apart (``jam_force``),
  as the crossing yarns lying side by side do;
* the mandrel is a wall: each crossing stays in front of the tangent plane of the mandrel surface
  nearest to it (a convex penalty, ``wall_stiffness``), so the lowest rows rest on the mandrel,
  where ``model.py`` deposits them, instead of being pulled through it.

``dE/dC = 0`` is pair balance at every crossing (paper eqs. 3-4, both yarns' internal and external
forces); ``dE/du = 0`` is the friction law of each yarn. Damped Newton (sparse Hessian with 5
unknowns per crossing, positive definite by construction, see ``_kernels/frontal.py``; Armijo line
search on ``E``) descends from any start and converges quadratically near the solution; where it
does not converge within ``newton_steps``, the step is solved again by continuation in the
friction (``_balance_or_continue``). Each Newton direction is one sparse factorisation of the
Hessian in the nested-dissection order of the crossing lattice (``dissection_order``), by CHOLMOD
where cvxopt is installed, else by SuperLU (``interaction/linalg.py``): in that order the cost per
crossing stays flat as the zone grows.

The bounds depend on the tensions and the deflections (Amontons: the normal force), and the top
tensions on the ring deflections: an outer fixed point (the frontal iteration) re-evaluates them
from the balanced geometry and solves again until they change by less than
``friction_tolerance`` relative to the tensions; the residual history of a solve is that change per
iteration. The first iteration holds the bounds and top tensions of the step's *posed* state
(the state handed in: the last step's converged state plus the crossings created from it): an
existing crossing keeps the bound of the last step's converged geometry, a new one takes that of
its creation geometry, and ``f_top`` is that of the posed geometry (behind a guide ring: Capstan
over the posed deflection). With those held E has one minimum, so the step's result does not
depend on the solver's initial iterate (``start``), only on the posed state, to the balance
tolerance. A time step makes ``max_iterations`` of them (the bounds lag by up to a step);
behind a guide ring each re-solves the step with the top tensions and the bounds of its
converged geometry until they change by less than ``posed_tolerance`` (``PosedIteration``: a
fixed point from that posed state, so the result still depends only on it). A
snapshot up to ``snapshot_iterations``, to ``snapshot_tolerance``; one that has made no progress
over two iterations after ``snapshot_damping_after`` moves each bound only ``snapshot_damping``
of the way to its new value from then on (x+ = x + w (G(x) - x): a plain iteration that cycles
between stick and slip states settles when averaged). With ``consistent_bounds`` a
time step iterates to ``consistent_tolerance`` instead, from the bounds of its posed geometry,
Anderson-mixing the bounds and top tensions once they change by less than ``mixing_start``
(``_BoundMixing``): the plain iteration converges linearly at ~0.965 an iteration, the mixed
one in 18-29 iterations on 48-carrier steps; the step is then the fixed point of the equations
with consistent bounds, whatever its start. Then every crossing is in balance
to ``balance_tolerance`` and ``Psi <=`` the last change times ``(f_int + f_ext)``. The friction
state (stick or slip, the sliding direction) and the material coordinates carry over from one step
to the next: that history is what makes the model differ from a frictionless one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import math

import numpy as np
import pymetis
import scipy.sparse as sp

from .._kernels import frontal as frontal_kernels
from .._kernels import zone as zone_kernels
from ..errors import SimulationError
from .contact import CrossingFriction, bound_change, bound_scale, crossing_friction
from .linalg import LowerFactoriser
from .settings import DEFAULT, InteractionSettings


@dataclass(frozen=True)
class Boundary:
    """What the zone hangs from at the end of a step, machine frame.

    fell : (2n, 3) float64, m, fell points; top : (2n, 3) ring points (guide ring) or spool points;
    spool : (2n, 3) spool points; f_spool : N; mu, mu_r : friction; has_ring : bool; h : m, half
    the yarn thickness; plane : (m, 6) or None, per crossing a point and the outward unit normal
    of the mandrel surface nearest to it (the crossings may not pass behind it); width : m, the
    yarn width, the least distance of two crossings along a yarn (jamming; 0: none); capstan :
    (2n,) or None, per yarn the direction its material slides over the guide ring (+1 towards
    the mandrel, -1 towards the spool, 0 stick; None: -1, the paper's eq. 9 as written) and
    f_hold : (2n,) N, the tension a sticking yarn holds below the ring
    (``_kernels.frontal.top_tensions``). Mixed yarns (``[[yarn_type]]``): yarn_type (2n,) int64,
    every yarn's type; pair_mu (nt, nt), the yarn-yarn friction of every pair of types;
    type_tension, type_ring_friction (nt,), every type's spool tension (N) and yarn-ring friction;
    None: every yarn is [yarn], with f_spool, mu and mu_r. law: the crossings' friction law
    (``contact.CrossingFriction``: Howell's index and reference force; None: Amontons), whose
    coefficients are mu or pair_mu (:attr:`friction`).
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
    capstan: np.ndarray | None = None
    f_hold: np.ndarray | None = None
    yarn_type: np.ndarray | None = None
    pair_mu: np.ndarray | None = None
    type_tension: np.ndarray | None = None
    type_ring_friction: np.ndarray | None = None
    law: CrossingFriction | None = None

    @property
    def friction(self) -> CrossingFriction:
        """The crossings' friction law with this boundary's coefficients (``mu``, or ``pair_mu``
        over the yarns' types, each pair at the law's one index), as the bounds' kernels take it
        (``CrossingFriction.kernel_arguments``)."""
        law = CrossingFriction() if self.law is None else self.law
        law = dataclasses.replace(law, coefficient=float(self.mu))
        if self.pair_mu is None:
            return law
        pair = np.asarray(self.pair_mu, dtype=float)
        return dataclasses.replace(law, yarn_type=np.asarray(self.yarn_type), pair_coefficient=pair,
                                   pair_index=np.full_like(pair, law.index))

    def crossing_mu(self, yarn) -> np.ndarray:
        """(m,) float64: the yarn-yarn friction of every crossing of the two yarns ``yarn`` (m, 2)
        (``contact.crossing_friction``): ``mu`` everywhere without yarn types."""
        yarn = np.asarray(yarn)
        if self.pair_mu is None:
            return np.full(len(yarn), float(self.mu))
        t = self.yarn_type
        return crossing_friction(t[yarn[:, 0]], t[yarn[:, 1]], self.pair_mu)

    def spool_tensions(self) -> np.ndarray:
        """(2n,) float64, N: every yarn's spool tension (its type's)."""
        if self.type_tension is None:
            return np.full(len(self.fell), float(self.f_spool))
        return np.ascontiguousarray(self.type_tension[self.yarn_type], dtype=float)

    def ring_frictions(self) -> np.ndarray:
        """(2n,) float64: every yarn's yarn-ring friction (its type's)."""
        if self.type_ring_friction is None:
            return np.full(len(self.fell), float(self.mu_r))
        return np.ascontiguousarray(self.type_ring_friction[self.yarn_type], dtype=float)

    def capstan_arguments(self) -> tuple[np.ndarray, np.ndarray]:
        """(capstan, f_hold) as (2n,) float64 arrays for the kernels (defaults filled in)."""
        n = len(self.fell)
        c = np.full(n, -1.0) if self.capstan is None else np.asarray(self.capstan, dtype=float)
        f = self.spool_tensions() if self.f_hold is None else np.asarray(self.f_hold, dtype=float)
        return np.ascontiguousarray(c), np.ascontiguousarray(f)


@dataclass(frozen=True)
class SolveReport:
    """iterations (frontal), residual (the larger of the balance residual and the last friction
    change), history (friction change per frontal iteration), f_top (2n,) N, the top tensions of
    the result; newton (Newton steps in all); lagged: the friction bounds had not settled to
    ``friction_tol`` after ``max_iter`` iterations (the balance holds; Psi is off by at most the
    last change, relative to the tensions); newton_residual, newton_energy: the balance residual
    and the energy E (J) at every Newton iterate of the solve, in order (over all its frontal
    iterations and continuation stages)."""

    iterations: int
    residual: float
    history: np.ndarray
    f_top: np.ndarray
    newton: int = 0
    lagged: bool = False
    newton_residual: np.ndarray | None = None
    newton_energy: np.ndarray | None = None
    #: iterations of the force-density relaxation in the solve (``relax.solve_zone``; 0 for
    #: Newton's alone), converged or not
    relax_iterations: int = 0
    #: the relaxation did not converge and Newton's solve gave the result (``relax.solve_zone``,
    #: ``RelaxSettings.newton_fallback``)
    fallback: bool = False
    #: behind a guide ring, the solves of the posed iteration after the first
    #: (``PosedIteration``), and whether its change fell below ``posed_tolerance``
    posed_solves: int = 0
    posed_converged: bool = True
    #: the relaxation's time (s) by part (``relax.RelaxResult.times``), summed over its solves,
    #: and its factorisations of the preconditioner (None and 0 for Newton's alone)
    relax_times: dict | None = None
    factorisations: int = 0


#: what a zone solve is for (``solve_zone_inplace``'s and ``relax.solve_zone``'s ``mode``):
#: "step", a time step (``FrontalSettings.max_iterations`` frontal iterations, or consistent
#: bounds); "pass", a snapshot's ring pass (``max_iter`` frontal iterations of the bounds);
#: "final", a snapshot's final solve (the frontal iteration to ``friction_tol``)
SOLVE_MODES = ("step", "pass", "final")


def check_mode(mode):
    """``mode`` if it is one of :data:`SOLVE_MODES`; ValueError otherwise."""
    if mode not in SOLVE_MODES:
        raise ValueError(f"zone solve mode {mode!r}: expected one of {', '.join(SOLVE_MODES)}")
    return mode


@dataclass
class _Pattern:
    """The lower triangle of a Hessian in the dissection order (``_Network.pattern``)."""

    nnz: int
    slot: np.ndarray
    size: int
    r: np.ndarray
    c: np.ndarray
    factoriser: LowerFactoriser


class _Network:
    """The arrays of a state and a boundary, bound for the kernels. ``centre`` (m, 2) friction
    centres, ``bound`` (m, 2) friction bounds and ``f_top`` (2n,) top tensions are the iterate of
    the frontal loop (the caller sets them); the Newton iterate lives in ``state.pos`` and
    ``state.material``, which ``balance`` moves in place."""

    def __init__(self, state, bc, settings: InteractionSettings = DEFAULT):
        self.st, self.bc = state, bc
        self.settings = settings
        m = state.m
        if bc.plane is None:
            self.plane = np.zeros((m, 6))
            self.plane[:, 2] = -1e300      # no mandrel: a wall far away
            self.plane[:, 5] = 1.0
        else:
            self.plane = np.ascontiguousarray(bc.plane[:m])
        self.centre = state.material[:m].copy()
        self.EA = axial_stiffness(bc.f_spool, settings)
        self.f_top = bc.spool_tensions()
        self.bound = np.zeros((m, 2))
        self.grad = np.zeros((m, 5))
        self.tension = np.zeros((m, 2))
        nmax = frontal_kernels.triplet_capacity(m, state.n_yarns)
        self.rows = np.empty(nmax, dtype=np.int64)
        self.cols = np.empty(nmax, dtype=np.int64)
        self.vals = np.empty(nmax)
        self.order = dissection_order(state.low[:m])
        self.rank = np.empty_like(self.order)
        self.rank[self.order] = np.arange(self.order.size)
        self._pattern = None
        self.trace = []          # (residual, E) at every Newton iterate

    def pattern(self, nnz):
        """The lower triangle of the Hessian in the dissection order, from the triplets of
        ``assemble`` (the same triplets at every Newton step of a solve): ``size`` entries at
        ``r``, ``c`` (column-major), ``slot`` (the entry of each triplet, -1 above the diagonal)
        and the factoriser of that pattern (it keeps CHOLMOD's analysis between Newton steps)."""
        p = self._pattern
        if p is not None and p.nnz == nnz:
            return p
        n = 5 * self.st.m
        slot, er, ec, size = frontal_kernels.lower_pattern(nnz, self.rows, self.cols, self.rank, n)
        er, ec = er.astype(np.intp), ec.astype(np.intp)
        factoriser = LowerFactoriser(er, ec, n, self.settings.newton.linear_solver)
        self._pattern = p = _Pattern(nnz=nnz, slot=slot, size=size, r=er, c=ec,
                                     factoriser=factoriser)
        return p

    def _args(self):
        """The kernels' (Lattice, Law, Problem) of the state and the frontal loop's iterate, as
        plain tuples (``_kernels.zone``: the kernels' dispatcher types them in C)."""
        st, bc, e = self.st, self.bc, self.settings.energy
        lat = zone_kernels.Lattice(st.m, st.n_yarns, st.yarn, st.low, st.up, st.over, st.normal,
                                   st.lowest, st.highest)
        law = zone_kernels.law(self.EA, e.compression, self.settings.frontal.friction_creep,
                               e.kappa0, bc.h, e.length_smoothing, e.top_smoothing2, bc.width,
                               e.jam_force * bc.f_spool / max(bc.width, 1e-300),
                               e.geometric_floor)
        prob = zone_kernels.Problem(bc.fell, bc.top, st.material_fell, self.centre, self.bound,
                                    self.f_top)
        return tuple(lat), tuple(law), tuple(prob)

    def assemble(self):
        """(E, nnz): the energy at the state's iterate, its gradient into ``grad`` and its
        Hessian's triplets into ``rows``, ``cols``, ``vals``."""
        st = self.st
        return frontal_kernels.assemble(*self._args(), st.pos, st.material, self.plane,
                                        self.settings.energy.wall_stiffness, self.grad,
                                        self.rows, self.cols, self.vals)

    def energy(self, pos, material):
        """E at crossing positions ``pos`` (m, 3) and material coordinates ``material`` (m, 2)."""
        return frontal_kernels.energy(*self._args(), pos, material, self.plane,
                                      self.settings.energy.wall_stiffness)

    def update_tensions(self):
        """The segment tensions of the state's iterate into ``tension`` (m, 2)."""
        st, bc, e = self.st, self.bc, self.settings.energy
        frontal_kernels.tensions(st.m, st.yarn, st.pos, st.normal, st.over, st.low, bc.fell,
                                 st.material, st.material_fell, self.EA, e.compression, bc.h,
                                 e.length_smoothing, self.tension)

    def bounds(self):
        """Friction bounds, Psi / (f_int + f_ext) (m, 2) and top tensions of the current geometry
        and tensions."""
        st, bc = self.st, self.bc
        bound = np.empty((st.m, 2))
        psi = np.empty((st.m, 2))
        f_top = np.empty(st.n_yarns)
        frontal_kernels.top_tensions(st.n_yarns, st.highest, st.pos, st.normal, st.over, bc.fell,
                                     bc.top, bc.spool, bc.h, bc.spool_tensions(),
                                     bc.ring_frictions(), bc.has_ring, *bc.capstan_arguments(),
                                     f_top)
        frontal_kernels.friction_bounds(st.m, st.yarn, st.pos, st.normal, st.over, st.low, st.up,
                                        bc.fell, bc.top, self.tension, f_top, bc.h,
                                        *bc.friction.kernel_arguments(st.yarn[:st.m]), bound, psi)
        return bound, psi, f_top

    def balance(self, tol, max_steps):
        """Newton on E with the bounds and f_top fixed until the residual is below tol; moves
        the state's iterate; (residual, steps)."""
        st = self.st
        for k in range(max_steps + 1):
            E, nnz = self.assemble()
            if not np.isfinite(E):
                raise SimulationError("a yarn segment between crossings lost its material length")
            self.update_tensions()
            res = frontal_kernels.imbalance(st.m, st.yarn, st.up, self.grad, self.tension,
                                            self.f_top)
            self.trace.append((res, E))
            if res < tol or k == max_steps:
                return res, k
            _newton_step_inplace(self, E, nnz)


def dissection_order(low):
    """Fill-reducing order of the 5 unknowns per crossing: METIS nested dissection of the crossing
    graph (crossings joined by a yarn segment; ``low`` (m, 2) the crossing below on each yarn,
    -1 at the fell point). Returns ``dof`` (5m,): row k of the reordered Hessian is row dof[k].
    The zone is a lattice of crossings wrapped around the mandrel; nested dissection keeps the
    factor's fill, and so its cost per crossing, flat as it grows."""
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
    perm = np.asarray(perm).astype(np.intp)   # array("q") from pymetis
    return (5 * perm[:, None] + np.arange(5)).ravel()


def _newton_direction(net, nnz, grad):
    """Newton direction -H^-1 grad of the assembled Hessian (``net.rows/cols/vals[:nnz]``).

    H is symmetric and positive definite by construction (``_kernels/frontal.py``: geometric
    floor, kappa0 in slack directions): factorised in the nested-dissection order of the crossing
    lattice (``dissection_order``) by ``linalg.LowerFactoriser``. Then up to ``refinement_steps``
    steps of iterative refinement x += H^-1 (-grad - H x) where the direction's relative residual
    is above ``refinement_trigger`` (H spans stiffnesses from kappa0 to EA / q)."""
    newton = net.settings.newton
    n = grad.size
    dof = net.order
    pattern = net.pattern(nnz)
    v = np.empty(pattern.size)
    frontal_kernels.accumulate(nnz, pattern.slot, net.vals, v)
    solve_ordered = pattern.factoriser.factorise(v)   # solves H x = rhs in the dissection order

    def solve(rhs):
        out = np.empty(n)
        out[dof] = solve_ordered(rhs[dof])
        return out

    dx = solve(-grad)
    Hx = np.empty(n)
    gnorm = math.sqrt(_dot(grad, grad))
    for _ in range(newton.refinement_steps):
        frontal_kernels.triplet_matvec(nnz, net.rows, net.cols, net.vals, dx, Hx)
        res = -grad - Hx
        if not math.sqrt(_dot(res, res)) > newton.refinement_trigger * gnorm:
            break
        dx += solve(res)
    return dx


def _dot(a, b) -> float:
    """a . b of two vectors without BLAS: OpenBLAS runs a dot of more than ~10 000 entries (5
    per crossing) on all its threads, whose workers then spin while CHOLMOD factorises, and
    wait for a busy core on a shared machine (measured at 144 carriers under load: a snapshot's
    solve 5.9 s against 2.3 s with one BLAS thread, 12 ms per such dot)."""
    return float(np.einsum("i,i->", a, b))


def _newton_step_inplace(net, E, nnz):
    """One Newton step on E with Armijo backtracking; moves ``net.st.pos`` and
    ``net.st.material`` in place.

    Where the decrease of E that Newton predicts (-slope) is below ``roundoff_slope x roundoff
    |E|``, E's change is round-off of either sign and cannot judge the step: the full step is
    taken and the balance residual, which ``balance`` checks, judges it. Above it, Armijo
    backtracking ``E(x + t dx) <= E + armijo t slope + roundoff |E|``, halving t."""
    newton = net.settings.newton
    st = net.st
    m = st.m
    grad = net.grad[:m].ravel()
    dx = _newton_direction(net, nnz, grad)
    slope = _dot(grad, dx) if np.all(np.isfinite(dx)) else 0.0
    if not slope < 0.0:
        diag = np.bincount(net.rows[:nnz], weights=np.where(
            net.rows[:nnz] == net.cols[:nnz], net.vals[:nnz], 0.0), minlength=grad.size)
        dx = -grad / max(np.abs(diag).max(), 1e-300)   # gradient step as a fallback
        slope = _dot(grad, dx)
    pos0 = st.pos[:m].copy()
    material0 = st.material[:m].copy()
    step = dx.reshape(m, 5)
    t = 1.0
    if not -slope < newton.roundoff_slope * newton.roundoff * abs(E):
        for _ in range(newton.line_search_halvings):
            if net.energy(pos0 + t * step[:, :3], material0 + t * step[:, 3:]) <= (
                    E + newton.armijo * t * slope + newton.roundoff * abs(E)):
                break
            t *= 0.5
    st.pos[:m] = pos0 + t * step[:, :3]
    st.material[:m] = material0 + t * step[:, 3:]


def solve_zone_inplace(state, bc: Boundary, *, settings: InteractionSettings = DEFAULT, tol=None,
                       friction_tol=None, max_iter=None, where="", centre=None,
                       start=None, mode="step") -> SolveReport:
    """Bring every crossing of ``state`` to balance with its friction law (module docstring),
    updating ``state`` in place: positions, material coordinates, tensions, friction bounds, slip
    states and friction offsets of the crossings. The top tensions of the result are
    ``SolveReport.f_top``. ``state.material_fell`` must be anchored (``fell_material``).

    ``state`` as handed in is the step's *posed* state: it defines the problem, i.e. the friction
    bounds a new crossing (``state.bound`` not finite) starts with and the top tensions ``f_top``
    (both ``_Network.bounds`` of its positions and tensions), which the first frontal iteration
    holds. ``start``: ``(pos (m, 3), material (m, 2))``, the solver's initial iterate only
    (default: the posed positions and material). With the bounds and top tensions held, E has one
    minimum (its Hessian is positive definite), so the result of a time step does not depend on
    ``start`` beyond the balance tolerance (``tests/validation/test_start_independence.py``).
    ``centre`` (m, 2): where each yarn's friction term is centred (default:
    ``friction_centres(state)``). ``tol``, ``friction_tol``, ``max_iter``: the balance
    tolerance, the frontal tolerance and the frontal iterations (default: ``settings``'
    ``balance_tolerance``, ``friction_tolerance``, ``max_iterations``). ``mode``: what the
    solve is for (:data:`SOLVE_MODES`); a time step ("step") with
    ``FrontalSettings.consistent_bounds`` iterates the bounds to ``consistent_tolerance``.
    ``where`` names the step and time in the error message; :class:`SimulationError` if the
    residual stays above the tolerances."""
    fr = settings.frontal
    time_step = check_mode(mode) == "step"
    # a time step with consistent bounds: the frontal iteration to convergence, mixed
    consistent = fr.consistent_bounds and time_step
    # behind a guide ring a time step's top tensions (Capstan, eq. 9) and friction bounds
    # (``posed_all_bounds``; else the new crossings' only) are those of its own converged
    # geometry (``FrontalSettings.posed_iterations``, ``PosedIteration``)
    posed_loop = time_step and not consistent and bc.has_ring and fr.posed_iterations > 1
    tol = settings.newton.balance_tolerance if tol is None else tol
    if consistent:
        friction_tol, max_iter = fr.consistent_tolerance, fr.consistent_iterations
    friction_tol = fr.friction_tolerance if friction_tol is None else friction_tol
    max_iter = fr.max_iterations if max_iter is None else max_iter
    m = state.m
    net = _Network(state, bc, settings)
    net.centre = np.array((friction_centres(state) if centre is None else centre)[:m],
                          dtype=float)
    if m == 0:
        return SolveReport(0, 0.0, np.zeros(0), net.bounds()[2])
    # the problem: the bounds of the last step (new crossings: of the posed geometry); with
    # consistent bounds those of the posed geometry for all (the step's boundary moved since the
    # last step: near the fell and top points they are closer to the step's own, and the
    # iteration needs 18-29 iterations instead of 31-33 on 48-carrier steps)
    net.tension[:] = state.tension[:m]
    bound0, _, f_top0 = net.bounds()
    fresh = ~np.isfinite(state.bound[:m]) | consistent
    # the bounds the posed iteration takes of the converged geometry
    posed = np.ones((m, 2), dtype=bool) if fr.posed_all_bounds else fresh
    net.bound = np.where(fresh, bound0, state.bound[:m])
    net.f_top = f_top0
    if start is not None:
        # the solver's initial iterate (the posed state stays the problem's)
        state.pos[:m], state.material[:m] = start[0][:m], start[1][:m]
    mixer = _BoundMixing(fr.bound_mixing if consistent else 0, fr.mixing_start)
    # a snapshot's final solve (a tolerance and iterations given, not a time step's lag)
    damped = not consistent and friction_tol is not None and fr.snapshot_damping < 1.0
    cycling = False
    history = []
    newton = 0
    pi = None
    residual = np.inf
    change = np.inf
    for it in range(1, max_iter + 1):
        residual, steps = _balance_or_continue(net, tol)
        newton += steps
        if residual < tol and posed_loop:
            scale = bound_scale(state.up[:m], state.yarn[:m], net.tension, net.f_top,
                                fr.change_scale_floor)
            pi = PosedIteration(fr, posed, scale, net.f_top, pi)
            while residual < tol:
                bound1, _, f_top1 = net.bounds()
                bound1 = np.where(posed, bound1, net.bound)
                x = pi.step(net.bound, net.f_top, bound1, f_top1,
                            _relative_change(state, net, bound1, f_top1))
                if x is None:
                    break
                net.bound, net.f_top = x
                residual, steps = _balance_or_continue(net, tol)
                newton += steps
        if not residual < tol:
            break
        bound1, psi, f_top1 = net.bounds()
        change = _relative_change(state, net, bound1, f_top1)
        history.append(change)
        if change < friction_tol:
            _accept_inplace(state, net)
            return SolveReport(it, max(float(residual), change), np.array(history),
                               net.f_top.copy(), newton, **_trace(net), **_posed_report(pi))
        if it == max_iter:
            # friction bounds lagged: balance holds, Psi to within the last change; the next
            # step starts from the newest bounds
            _accept_inplace(state, net)
            state.bound[:m] = bound1
            return SolveReport(it, max(float(residual), change), np.array(history),
                               net.f_top.copy(), newton, lagged=True, **_trace(net),
                               **_posed_report(pi))
        if damped and not cycling and it >= max(fr.snapshot_damping_after, 3):
            cycling = history[-1] >= history[-3]     # no progress over two iterations
        if cycling:
            # an iteration cycling between stick and slip states: part steps to the new bounds
            w = fr.snapshot_damping
            net.bound = net.bound + w * (bound1 - net.bound)
            net.f_top = net.f_top + w * (f_top1 - net.f_top)
        else:
            net.bound, net.f_top = mixer(net.bound, net.f_top, bound1, f_top1, change)
    raise SimulationError(
        f"the frontal solver of the yarn-interaction model did not converge {where}: relative "
        f"force imbalance (residual) {residual:.3g} after {newton} Newton steps (tolerance "
        f"{tol:.3g}, {m} crossings)")


def _relative_change(state, net, bound1, f_top1):
    """Largest change from the network's bounds and top tensions to ``bound1``, ``f_top1``:
    a bound's relative to f_int + f_ext of its crossing and yarn (at ``f_top1``,
    ``contact.bound_change``), a top tension's relative to itself."""
    m = state.m
    change = bound_change(state.up[:m], state.yarn[:m], net.tension, f_top1, bound1, net.bound,
                          net.settings.frontal.change_scale_floor)
    return max(change, float(np.max(np.abs(f_top1 - net.f_top) / f_top1)))


class _BoundMixing:
    """Anderson (type II) mixing of the frontal iteration's map (bounds, top tensions) -> the
    bounds and top tensions of the balanced geometry, over the last ``depth`` iterates, once the
    change is below ``start``: x+ = G(x) - dG gamma, gamma = argmin |r - dR gamma| (r = G(x) - x).
    Above ``start`` (crossings still switching between stick and slip, the map not smooth) and
    with depth 0 it is the plain iteration x+ = G(x), and the history is cleared."""

    def __init__(self, depth, start):
        self.depth, self.start = depth, start
        self.x, self.g = [], []

    def __call__(self, bound, f_top, bound1, f_top1, change):
        if self.depth <= 0 or not change < self.start:
            self.x, self.g = [], []
            return bound1, f_top1
        m = bound.shape[0]
        self.x.append(np.concatenate([bound.ravel(), f_top]))
        self.g.append(np.concatenate([bound1.ravel(), f_top1]))
        del self.x[:-(self.depth + 1)], self.g[:-(self.depth + 1)]
        new = self.g[-1]
        if len(self.x) > 1:
            G = np.array(self.g)
            R = G - np.array(self.x)
            gamma = np.linalg.lstsq(np.diff(R, axis=0).T, R[-1], rcond=None)[0]
            new = G[-1] - np.diff(G, axis=0).T @ gamma
        # a combination may reach below zero where a yarn runs straight (bound 0): no bound is
        return np.maximum(new[:2 * m], 0.0).reshape(m, 2), new[2 * m:]


class PosedIteration:
    """The posed iteration of a time step behind a guide ring, for both solvers
    (``FrontalSettings.posed_iterations``): the map x -> G(x) from the held top tensions and
    friction bounds of ``posed`` (m, 2) bool to those of the geometry a solve with x converges
    to. ``step(bound, f_top, bound1, f_top1, change)`` is given the held x = (bound, f_top),
    G(x) = (bound1, f_top1) and their relative change (``_relative_change``); it returns the
    next x to solve with, or None where the iteration stops: the change below
    ``posed_tolerance`` (converged), or ``posed_iterations`` solves made. The next x is G(x)
    while the change contracts by at least ``posed_contraction`` a solve, and Anderson's
    combination (type II, depth ``posed_mixing``) of the last iterates from the first solve
    that contracts less (the plain iteration creeps there, at ~0.93 a solve): each entry
    relative to its scale ``scale`` ((m, 2) f_int + f_ext; the top tensions relative to
    themselves), so that the combination weighs the entries as the change does. A solve whose
    change rose clears the combination's history (a crossing switched between stick and slip,
    where the map is not smooth) and takes x <- G(x). ``changes``:
    the change of every solve, in order; ``solves``: the solves after the first. ``before``:
    the iteration of an earlier frontal iteration of the same step, whose solves count
    against the same limit."""

    def __init__(self, fr, posed, scale, f_top_scale, before=None):
        self.left = fr.posed_iterations - 1 if before is None else before.left
        self.solves = 0 if before is None else before.solves
        self.tol = fr.posed_tolerance
        self.contraction = fr.posed_contraction
        self.depth = fr.posed_mixing
        self.posed = posed
        self.w = np.concatenate([1.0 / scale[posed], 1.0 / np.asarray(f_top_scale, float)])
        self.x, self.g = [], []
        self.mixing = False
        self.changes = []

    @property
    def converged(self) -> bool:
        """Whether the last change was below ``posed_tolerance``."""
        return bool(self.changes) and self.changes[-1] < self.tol

    def step(self, bound, f_top, bound1, f_top1, change):
        self.changes.append(float(change))
        if not change >= self.tol or self.left <= 0:
            return None
        self.left -= 1
        self.solves += 1
        bound1 = np.where(self.posed, bound1, bound)
        c = self.changes
        if len(c) > 1 and c[-1] > self.contraction * c[-2]:
            self.mixing = True
        if not self.mixing or self.depth <= 0:
            return bound1, f_top1
        if self.x and c[-1] > c[-2]:
            # a combination that raised the change (a crossing switched between stick and
            # slip: the map is not smooth across that): the history is cleared, x <- G(x)
            self.x, self.g = [], []
            return bound1, f_top1
        self.x.append(np.concatenate([bound[self.posed], f_top]) * self.w)
        self.g.append(np.concatenate([bound1[self.posed], f_top1]) * self.w)
        del self.x[:-(self.depth + 1)], self.g[:-(self.depth + 1)]
        new = self.g[-1]
        if len(self.x) > 1:
            G = np.array(self.g)
            R = G - np.array(self.x)
            gamma = np.linalg.lstsq(np.diff(R, axis=0).T, R[-1], rcond=None)[0]
            new = G[-1] - np.diff(G, axis=0).T @ gamma
        new = new / self.w
        k = int(np.count_nonzero(self.posed))
        out = bound.copy()
        # a combination may reach below zero where a yarn runs straight (bound 0): no bound is
        out[self.posed] = np.maximum(new[:k], 0.0)
        # nor a top tension below a thousandth of Capstan's (a yarn over the ring is pulled)
        return out, np.maximum(new[k:], 1e-3 * np.asarray(f_top1, float))


def _posed_report(pi):
    """SolveReport's fields of a posed iteration (None: none)."""
    if pi is None:
        return {}
    return dict(posed_solves=pi.solves, posed_converged=pi.converged)


def _trace(net):
    t = np.array(net.trace, dtype=float).reshape(-1, 2)
    return dict(newton_residual=t[:, 0], newton_energy=t[:, 1])


def _balance_or_continue(net, tol):
    """``net.balance``; where Newton does not converge from the step's start (a crossing that
    must slide far against friction), the same solve by continuation in the friction: from the
    start again without friction (the frictionless network converges robustly), then with the
    bounds scaled up in the ``continuation`` stages, each warm-started from the last."""
    newton = net.settings.newton
    st = net.st
    m = st.m
    pos0, material0 = st.pos[:m].copy(), st.material[:m].copy()
    residual, steps = net.balance(tol, newton.newton_steps)
    if residual < tol or not np.any(net.bound > 0.0):
        return residual, steps
    bound = net.bound
    st.pos[:m], st.material[:m] = pos0, material0
    total = steps
    try:
        for frac in newton.continuation:
            net.bound = frac * bound
            residual, steps = net.balance(tol, newton.newton_steps)
            total += steps
            if not residual < tol:
                break
    finally:
        net.bound = bound
    return residual, total


def _accept_inplace(state, net):
    """The solve's tensions, bounds, slip states and friction offsets into ``state``."""
    m = state.m
    fr = net.settings.frontal
    state.tension[:m] = net.tension
    state.bound[:m] = net.bound
    slide = state.material[:m] - net.centre
    state.slip[:m] = np.where(np.abs(slide) > fr.slip_report, np.sign(slide), 0)
    cap = fr.memory_cap
    state.offset[:m] = np.clip(slide, -cap, cap)


def friction_centres(state):
    """(m, 2) m: where each yarn's friction term at each crossing is centred for the next solve,
    its material coordinate less the friction offset the last step carried over
    (``friction_memory``)."""
    return state.material[: state.m] - state.offset[: state.m]


def axial_stiffness(f_spool, settings: InteractionSettings = DEFAULT):
    """EA of the tow (N) for the spool tension f_spool (N): f_spool / tow_strain."""
    return float(f_spool) / settings.energy.tow_strain


def fell_material(state, bc, settings: InteractionSettings = DEFAULT):
    """(2n,) m: the material coordinate of every yarn's fell point
    (``_kernels.frontal.reanchor``): the yarn laid since the last step leaves the tension of the
    lowest segment as it was. The caller stores it in ``state.material_fell``."""
    e = settings.energy
    out = np.empty(state.n_yarns)
    frontal_kernels.reanchor(state.n_yarns, state.lowest, state.yarn, state.pos, state.normal,
                             state.over, np.ascontiguousarray(bc.fell, dtype=float),
                             state.material, state.tension, axial_stiffness(bc.f_spool, settings),
                             e.compression, bc.h, e.length_smoothing, out)
    return out


def new_material(state, c, side, below_point, f, bc, settings: InteractionSettings = DEFAULT):
    """Material coordinate for yarn ``side`` of a crossing ``c`` just created on top of its
    yarn: the new segment from ``below_point`` (the yarn point below) carries the tension f,
    ``u = u_below + l / (1 + f / EA)``."""
    k = int(state.yarn[c, side])
    lo = int(state.low[c, side])
    u_below = float(state.material[lo, side] if lo >= 0 else state.material_fell[k])
    # the yarn point C + o h N (``ZoneState.centerline_point``), in floats: a crossing is
    # created a few dozen times a step at 144 carriers, where NumPy's per-call cost dominates
    o = float(state.over[c]) if side == 0 else -float(state.over[c])
    a = o * bc.h
    C, N = state.pos[c].tolist(), state.normal[c].tolist()
    b = np.asarray(below_point, dtype=float).tolist()
    d0, d1, d2 = C[0] + a * N[0] - b[0], C[1] + a * N[1] - b[1], C[2] + a * N[2] - b[2]
    l = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2 + settings.energy.length_smoothing)
    return u_below + l / (1.0 + f / axial_stiffness(bc.f_spool, settings))


def point_forces(state, bc, settings: InteractionSettings = DEFAULT):
    """(m, 2, 3) N: every force on yarn ``side``'s centerline point at crossing ``c`` other than
    the yarns' tensions, as the step's energy E has them (``_kernels/frontal.assemble``), so that
    at every crossing the tensions of its four segments plus these forces sum to ``-dE/dC``, zero
    at a balanced state:

    * jamming: a segment between two crossings of a yarn shorter than the yarn width ``w``
      (``l < w``, ``l`` the smoothed length of the segment between the two yarn points) pushes
      them apart along it with ``f_j = k_jam (w - l)``, ``k_jam = jam_force f_spool / w``: on
      the upper crossing ``+f_j d``, on the lower ``-f_j d`` (``d`` the unit vector from the
      lower yarn point to the upper), both on that yarn's points;
    * the mandrel wall (``bc.plane``): a crossing behind its tangent plane by ``-s > 0`` is
      pushed out along the plane's normal ``n`` with ``k_wall (-s) n``, on the point of the inner
      yarn (the one lying on the mandrel: the weft where ``over = +1``)."""
    m = state.m
    out = np.zeros((m, 2, 3))
    if m == 0:
        return out
    e = settings.energy
    pos, normal, over = state.pos[:m], state.normal[:m], state.over[:m]
    sign = np.stack([over, -over], axis=1)                        # (m, 2): warp +over, weft -over
    pts = pos[:, None, :] + (sign * bc.h)[:, :, None] * normal[:, None, :]
    width = float(bc.width)
    if width > 0.0:
        k_jam = e.jam_force * bc.f_spool / width
        for side in range(2):
            lo = state.low[:m, side]
            c = np.nonzero(lo >= 0)[0]
            d = pts[c, side] - pts[lo[c], side]
            l = np.sqrt(np.sum(d * d, axis=1) + e.length_smoothing)
            gap = np.maximum(width - l, 0.0)
            f = (k_jam * gap / l)[:, None] * d
            np.add.at(out[:, side], c, f)
            np.add.at(out[:, side], lo[c], -f)
    if bc.plane is not None:
        plane = bc.plane[:m]
        sd = np.einsum("ij,ij->i", pos - plane[:, :3], plane[:, 3:])
        push = (e.wall_stiffness * np.maximum(-sd, 0.0))[:, None] * plane[:, 3:]
        inner = np.where(over > 0, 1, 0)
        out[np.arange(m), inner] += push
    return out
