"""Numerical settings of the yarn-interaction model (docs/theory.md §4), in one place.

Every tolerance, iteration limit, regularisation constant and staging fraction of the interaction
model is a field of :class:`InteractionSettings`, with the reason for its value: the classes
below, and ``NearSettings``, defined beside the mandrel look-ups it tunes
(``interaction/mandrel_distance.py``). ``InteractionZone(config, machine, mandrel,
settings=...)`` passes them down to the step solvers (``interaction/frontal.py``,
``interaction/relax.py``), the ring contact (``interaction/ring.py``), the mandrel look-ups and
the numba kernels, which receive them as scalar arguments. A run takes them as the
``interaction`` branch of ``preform.Settings`` (``preform/settings.py``). The defaults are the
model's; a test or a study varies one by passing another object, e.g.
``dataclasses.replace(s, frontal=dataclasses.replace(s.frontal, friction_memory=0.0))``.
The measurements behind the values are in ``docs/decisions.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .mandrel_distance import NearSettings


@dataclass(frozen=True)
class EnergySettings:
    """Constants of the step energy E (``_kernels/frontal.py`` writes it out)."""

    #: strain of the tow at the spool tension, EA = f_spool / tow_strain: stiff enough to leave the
    #: yarns inextensible to 0.1 %, soft enough that a crossing's transverse millimetre (second
    #: order in the length) does not swamp the stretch; tied to f_spool so the model stays
    #: homogeneous in the forces, as Amontons friction is
    tow_strain: float = 1e-3
    #: a segment shorter than its material pushes back with this fraction of EA: a yarn does not
    #: push, but a small stiffness keeps a slack stretch's material coordinates defined and E's
    #: second derivative bounded below
    compression: float = 1e-2
    #: N, smallest tension the Hessian's geometric stiffness of a segment uses: keeps the Newton
    #: matrix positive definite where a segment is in compression (the gradient stays exact)
    geometric_floor: float = 1e-3
    #: N/m, stiffness pinning the material coordinate of a yarn without friction or tension; it
    #: changes a tension jump by at most kappa0 x (slide in a step, < 0.1 m) = 1e-8 N
    kappa0: float = 1e-7
    #: m^2, smoothing of a segment's length, l = sqrt(|d|^2 + length_smoothing): keeps l and its
    #: derivatives finite where two yarn points meet
    length_smoothing: float = 1e-12
    #: m, extra smoothing of the top segment's length, sqrt(l^2 + top_smoothing^2): a crossing
    #: whose balance lies at its yarn's ring or spool point sits within 30 um of it instead of on a
    #: kink of E; it changes the top force by top_smoothing^2 / (2 l^2), < 5e-4 for l > 1 mm
    top_smoothing: float = 3e-5
    #: N/m, stiffness of the mandrel wall that keeps crossings outside: 10 N push 1 um
    wall_stiffness: float = 1e7
    #: jamming force where two crossings of a yarn would coincide, in spool tensions: of the order
    #: of the zone's forces, so crossings created close together move apart instead of stopping
    #: Newton, and a yarn gone slack behind friction keeps its crossings apart
    jam_force: float = 1.0

    @property
    def top_smoothing2(self) -> float:
        """top_smoothing^2, m^2, as the kernels add it to the squared length."""
        return self.top_smoothing ** 2


@dataclass(frozen=True)
class NewtonSettings:
    """The inner solve: damped Newton on E with the friction bounds and top tensions fixed."""

    #: largest relative residual (force imbalance over the sum of the four tensions; friction
    #: equation over f_int + f_ext): 1e4 times below what exported snapshots must meet (1e-3)
    balance_tolerance: float = 1e-7
    #: Newton steps per inner solve before the solve falls back to continuation in the friction
    newton_steps: int = 80
    #: friction fractions of that continuation (``frontal._balance_or_continue``): from the
    #: frictionless network, which converges robustly, up to the full bounds
    continuation: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
    #: Armijo constant of the line search on E (sufficient decrease)
    armijo: float = 1e-4
    #: halvings of the line search before the step is taken as small as it got
    line_search_halvings: int = 50
    #: relative round-off of E: Armijo allows E to rise by roundoff |E|
    roundoff: float = 1e-13
    #: a Newton step whose predicted decrease (-slope) is below roundoff_slope x roundoff |E| is
    #: taken whole: E cannot judge it, the balance residual does
    roundoff_slope: float = 10.0
    #: iterative refinement steps of a Newton direction (H spans stiffnesses kappa0 to EA / q)
    refinement_steps: int = 2
    #: relative residual of a Newton direction above which it is refined
    refinement_trigger: float = 1e-10
    #: sparse factorisation of the Newton systems (``interaction/linalg.py``): "auto" (CHOLMOD
    #: when cvxopt is installed, else SuperLU), "cholmod" or "splu"
    linear_solver: str = "auto"


@dataclass(frozen=True)
class FrontalSettings:
    """The outer (frontal) iteration of the friction bounds and top tensions, and the friction
    regularisation."""

    #: convergence of the outer iteration: change of the bounds and top tensions between
    #: iterations, relative to the tensions; bounds Psi / (f_int + f_ext) of the result
    friction_tolerance: float = 1e-6
    #: the change of a crossing's bounds is relative to f_int + f_ext there, but at least to
    #: this fraction of the yarn's top tension: a slack yarn's tensions vanish, and a change
    #: relative to them read 1e298 in history.csv; a crossing with tensions above 1 % of the
    #: top tension is measured as before
    change_scale_floor: float = 1e-2
    #: outer iterations per time step (Newton and the relaxation): the bounds lag the geometry by
    #: up to a step (an explicit update of a state variable; history.csv's residual says by how
    #: much). Each iteration costs about a solve; on 48-carrier case A runs the lag of 1 moves H
    #: by ~0.15 % (up to 1.2 %) and the braid angle by up to 0.6 deg from the time-step-converged
    #: run whatever the step, 3 by 0.09 % and 0.14 deg (docs/decisions.md, "A time step's
    #: problem posed by its posed state")
    max_iterations: int = 1
    #: outer iterations of a snapshot's final solve (the exported crossings meet Psi to
    #: snapshot_tolerance where the iteration converges within them, else to its last change)
    snapshot_iterations: int = 100
    #: convergence of a snapshot's final solve: a change below 1e-4 of f_int + f_ext leaves Psi a
    #: factor 5 below the 1e-3 x tension the written crossings must meet
    snapshot_tolerance: float = 1e-4
    #: a snapshot's final solve whose change has not fallen over two iterations, after
    #: snapshot_damping_after of them, moves the bounds this fraction of the way to the new ones
    #: from then on: the plain iteration can cycle between stick and slip states (the bent
    #: tube's start-up: 100 iterations at 2-3e-3); a contracting one is left plain
    snapshot_damping: float = 0.5
    snapshot_damping_after: int = 10
    #: m of yarn, smoothing eps of |x| in the friction term sqrt(x^2 + eps^2) - eps: a sticking
    #: yarn gives eps r / sqrt(1 - r^2) at the used fraction r of its bound; Newton's cost falls
    #: steeply with it, sliding yarns move millimetres per step
    friction_creep: float = 1e-4
    #: fraction of the bound up to which a yarn's friction force carries over to the next step
    #: (elastic-plastic Coulomb friction): a sticking yarn creeps only while its force grows
    friction_memory: float = 0.95
    #: a yarn whose material lies more than this many friction_creep from its friction centre is
    #: reported as slipping (it uses more than 99.5 % of its bound)
    slip_report_creeps: float = 10.0

    #: behind a guide ring, solves a time step takes at most to bring the tension below the
    #: ring (Capstan, eq. 9, of the deflection at the ring point of the step's result) and the
    #: friction bounds (``posed_all_bounds``) to those of its converged geometry
    #: (``frontal.PosedIteration``). The posed ones come from the posed geometry, whose new
    #: crossings (below the ring) the solve moves by centimetres (case-B-like, 96 carriers,
    #: yarn friction 0: top tensions up to 23 % off, residual p99 0.21). With every bound a
    #: step takes 3.7 (yarn friction 0.25) to 5.3 (0.5) solves on average at 16 carriers, the
    #: most 23-29; 8 left 93-139 of ~390 steps at 1e-4 to 1.4e-3 (docs/decisions.md, "Every
    #: step converged behind a guide ring"). Without a ring the new crossings keep their
    #: posed bounds, as case A was validated
    posed_iterations: int = 30
    #: that iteration takes every crossing's bound of the converged geometry, not only the new
    #: crossings' (the old ones' one-step lag is 1-2 % of the tensions behind a ring: bent tube
    #: residual median 0.016, p99 0.06): the paper's bounds consistent with the converged
    #: geometry, to ``posed_tolerance``
    posed_all_bounds: bool = True
    #: that iteration stops once they change by less than this, relative to the tensions:
    #: the snapshots' frontal tolerance (snapshot_tolerance; a step's state then meets Psi to
    #: the 1e-3 the written crossings must)
    posed_tolerance: float = 1e-4
    #: that iteration takes the plain x <- G(x) while its change falls by at least this factor a
    #: solve (the map contracts by ~15 a solve where the stick and slip states settle)
    posed_contraction: float = 0.5
    #: from the first solve that contracts less, Anderson's combination of the last this many
    #: iterates of the bounds and top tensions (0: the plain iteration throughout): the plain
    #: one creeps at ~0.93 a solve there (16 carriers, yarn friction 0.5: 45 of 387 steps not
    #: at 1e-4 in 30 solves); depth 1 to 5 with the history cleared where the change rose:
    #: none (depth 5 without that clearing: 46); to 1e-10 on a captured step, depth 5 takes
    #: 51 solves where depth 2 is at 1e-8 after 100
    posed_mixing: int = 5

    #: iterate every time step's bounds and top tensions to those of its own converged geometry
    #: and tensions (to consistent_tolerance), so that a step's result does not depend on its
    #: start; off by default: such steps go to Newton (the relaxation does not
    #: converge where crossings stick), 110x the default's time a step at 144 carriers, and in
    #: whole runs a quarter of the steps do not reach the tolerance (docs/decisions.md)
    consistent_bounds: bool = False
    #: convergence of that iteration: a change of the bounds below 1e-9 of f_int + f_ext leaves two
    #: starts 1e-7 m apart on 48-carrier steps (1e-8: 1.2e-6 m)
    consistent_tolerance: float = 1e-9
    #: its frontal iterations at most (48-carrier case A steps take 18-29 with friction 0.25,
    #: 260 with friction 0.5, where the bounds tail off more slowly)
    consistent_iterations: int = 400
    #: Anderson depth of the mixing of the bounds and top tensions in that iteration: plain
    #: iteration tails off linearly at a factor 0.965 an iteration (174 to 1e-7), with
    #: Anderson(5) 18-29 iterations to 1e-9
    bound_mixing: int = 5
    #: change of the bounds (relative to f_int + f_ext) below which the mixing starts: above it
    #: crossings switch between stick and slip from one iteration to the next and Anderson
    #: diverges (the bounds jump with the states)
    mixing_start: float = 1e-3

    @property
    def slip_report(self) -> float:
        """m of yarn: the slide above which a yarn is reported as slipping."""
        return self.slip_report_creeps * self.friction_creep

    @property
    def memory_cap(self) -> float:
        """Largest friction offset carried to the next step (m): where the smoothed friction force
        bound x / sqrt(x^2 + eps^2) reaches friction_memory x bound."""
        r = self.friction_memory
        return self.friction_creep * r / math.sqrt(1.0 - r * r)


@dataclass(frozen=True)
class ZoneSettings:
    """Creation, deposition, staging and the snapshot's ring alternation (``interaction/model.py``)."""

    #: a crossing closer to the mandrel than this many yarn thicknesses is deposited: the solver
    #: keeps crossings outside the mandrel's tangent planes, so the lowest rows rest there
    deposit_height: float = 1.0
    #: a new crossing starts no lower than this fraction of its yarns' top segments: behind a
    #: guide ring two yarns whose carriers have passed may not cross yet below the ring
    creation_lowest: float = 0.5
    #: snapshot: alternations of the zone solve and the ring points' stick/slip, at most
    ring_iterations: int = 20
    #: m, ring-point motion below which that alternation stops
    ring_tolerance: float = 1e-9
    #: frontal iterations per pass of that alternation (its last solve iterates to convergence)
    ring_pass_iterations: int = 3
    #: where a step's solve fails, the step is solved again with its boundary moved in these
    #: fractions of the move, each stage warm-started from the last (empty: no staging)
    boundary_stages: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0)
    #: the material coordinate of a yarn's fell point (``InteractionZone.fell_anchor``): "laid"
    #: conserves the yarn, the fell point's material advancing by the yarn laid on the mandrel
    #: since the last step (and jumping to a deposited crossing's), so the yarn the braid
    #: consumes is drawn through the zone and over the ring; "tension" re-anchors it so that the
    #: lowest segment keeps its tension (about half the yarn laid appears at the fell point, and
    #: hardly any is drawn over the ring). "tension" stays the default until "laid"'s break of
    #: the case-B mirror symmetry (0.37 deg) is understood (docs/decisions.md)
    fell_material: str = "tension"
    #: a step whose residual (history.csv's: its balance, or the change of the friction bounds
    #: it held to those of its converged geometry, relative to the tensions) exceeds this stops
    #: the run as failed: the verdict's ceiling (``quality.QualitySettings``); converged steps
    #: stay below 1e-2 (case A's lag, 9.4e-3 at most) and behind a ring below 1e-3 (the
    #: posed iteration's fixed point, docs/decisions.md)
    max_step_residual: float = 0.1
    #: a step whose residual exceeds max_step_residual is first solved again with this many
    #: frontal iterations of its bounds (``FrontalSettings.max_iterations``), and fails only
    #: if it still does: without a ring the one-step lag spikes where crossings slide far in a
    #: step (a 16-carrier cylinder at friction 0.5 and a quarter of the default step: 3 of 520
    #: steps above 0.1, up to 0.50)
    lag_iterations: int = 5
    #: a yarn segment of the zone at or below this fraction of the spool tension is slack, which
    #: the model does not admit (every free yarn is pulled by its carrier's tensioner): the run
    #: stops as failed at that step
    slack_tension: float = 0.0


@dataclass(frozen=True)
class RingSettings:
    """Root solve of a yarn's slip across the guide ring (``_kernels/ring.py``)."""

    #: Psi_r <= psi_rel_tol (f_int + f_ext) counts as sticking: round-off of the force sum
    psi_rel_tol: float = 1e-12
    #: rad, step of the bracket march along the ring
    march_step: float = 0.01
    #: bracket steps at most: about half a turn (315 x 0.01 rad)
    march_max: int = 315
    #: Illinois regula-falsi iterations at most (it converges superlinearly in ~10)
    root_max_iter: int = 200
    #: root tolerance on Psi_r / (f_int + f_ext): double-precision round-off
    root_rel_tol: float = 1e-15
    #: the Capstan law over the ring (``interaction/model.py``): "paper" f = f_spool exp(-mu_r eta)
    #: always (eq. 9 as written; decoupled Amontons across the ring), the validated default;
    #: "flow" by the yarn's slide over the ring in the last step (towards the mandrel: the
    #: mandrel side higher; towards the spool: lower; stick in between, one Coulomb cone along
    #: and across the ring); "drawn" exp(+mu_r eta) always. "flow" locks the ring points at
    #: mu_r 0.6 and reads no slide once crossings exist unless ``ZoneSettings.fell_material`` is
    #: "laid" (docs/decisions.md)
    capstan: str = "paper"
    #: m of yarn over the ring in a step below which the yarn sticks along the ring (holds its
    #: tension within the Capstan cone): the friction creep of the crossings (friction_creep)
    stick_slide: float = 1e-4


@dataclass(frozen=True)
class RelaxSettings:
    """The force-density relaxation (``interaction/relax.py``, ``[model] solver = "relax"``).
    The model's constants (tow strain, friction creep, jamming, the geometric floor, ...) and
    its tolerances are not here: they come from the same :class:`InteractionSettings` the
    Newton reference uses, so that both solve the same equations to the same balance
    (``NewtonSettings.balance_tolerance``) and bounds (``FrontalSettings.friction_tolerance``).
    Whether a solve holds the friction bounds or iterates them to its converged geometry, and
    how often, is the solver's mode (``relax``'s ``consistent`` and ``bound_iterations``), set
    from ``FrontalSettings``."""

    #: iterations before the step is declared failed (a case A step takes 10-17 with the block
    #: preconditioner, 15-45 with the scalar one; one that has not converged by then stalls)
    max_iter: int = 200
    #: a step the relaxation does not converge on is solved by the Newton reference
    #: (``solve_zone``; its report says ``fallback``) instead of stopping the run
    newton_fallback: bool = True
    #: Anderson history: 10 iterates (more brought no fewer iterations on case A steps)
    anderson_depth: int = 10
    #: iterations between factorisations of the Laplacian (scalar preconditioner): in between,
    #: the last factor preconditions the update C <- C + L^-1 F(C) (same fixed point)
    refactor_every: int = 3
    #: block-Jacobi corrections per iteration after the force-density solve (scalar
    #: preconditioner; 0: none)
    smoothing: int = 2
    #: their weight (damping) and the isotropic share of f / l added to each 3 x 3 block
    smoothing_weight: float = 1.0
    smoothing_reg: float = 0.05
    #: iterations without a new lowest residual after which the block-Jacobi corrections stop
    #: for the rest of the solve (a step converges in 15-45 iterations with them)
    stall_iterations: int = 30
    #: longest block-Jacobi move, as a fraction of the crossing's shortest segment
    smoothing_cap: float = 0.1
    #: a crossing within this distance (m) of its tangent plane at the start rests on the wall
    wall_contact: float = 1e-7
    #: hysteresis of the wall's active set (m): a resting crossing leaves when its own balance
    #: lies further than this in front of the plane, a free one joins when it is further behind
    #: (a resting one may keep a pull below this times its stiffness); 10x below the 1 um the
    #: wall must meet, and it keeps crossings at the threshold from joining and leaving in turn
    wall_release: float = 1e-7
    #: relative residual of the per-yarn material problems: 1e3 below the balance tolerance;
    #: 1e-12 is below what the round-off of stiff tows (EA / q ~ 5e5 N/m) lets Newton reach
    material_tol: float = 1e-10
    #: with the block preconditioner, each material sweep starts from the material that keeps
    #: the segments' strains of the last one at the new lengths (a slipping yarn's material
    #: follows its lengths), not from the last material itself: 3.4x fewer Newton steps and no
    #: line search on case A steps (the block update moves crossings by millimetres); not with
    #: the scalar one, on whose friction-0.5 steps it costs iterations (48 carriers: 322
    #: against 241)
    material_predict: bool = True
    #: Newton steps of one material sweep at most
    material_newton: int = 60
    #: the position update's preconditioner: "block", the lattice's geometric stiffness with
    #: each crossing's 3 x 3 blocks (block LDL^T; a yarn has no stiffness along itself),
    #: "full", the Hessian in the positions and materials (5 x 5 blocks), or "scalar", the
    #: force-density Laplacian shared by x, y, z with ``smoothing`` block-Jacobi
    #: corrections (``docs/decisions.md``: 10-17 iterations of one material sweep on case A
    #: steps with "block", 33-44 of three with "scalar")
    preconditioner: str = "block"
    #: isotropic share of f / l in the block preconditioner: keeps it definite where the
    #: geometric stiffness alone is singular (a straight chain across itself); 1e-3: 10-15
    #: iterations at 144 carriers (1e-2: 12-17; 1e-4 moves soft modes too far at once)
    block_reg: float = 1e-3
    #: sets of crossings up to this size keep their order in the nested dissection of the
    #: block preconditioners (``band_dissection``); 4: 2908 crossings, 11.8 blocks of L a
    #: column against 12.8 with 8 (docs/decisions.md, "The block order: a band dissection
    #: within 15 % of the middle")
    order_leaf: int = 4
    #: the dissection cuts a set at the smallest separator within this fraction of its size
    #: from the middle; 0.15: 19 % less fill than the median cut (0), 4 % less than METIS
    order_window: float = 0.15
    #: iterations between factorisations of the block preconditioner (0: once per solve, and
    #: when the wall's active set or the set of jammed segments changes): a preconditioner
    #: that changes within a solve changes Anderson's map under it (144 carriers: 12-15
    #: iterations factorising once, 25-35 every 3 iterations)
    block_refactor_every: int = 0
    #: iterations without a new lowest residual after which the block preconditioner gives
    #: the step to the scalar one (from the same start); case A steps converge in 10-17
    block_stall: int = 20
    #: a step the block preconditioner stalls on is solved again with the scalar one (off: it
    #: is not converged, and ``solve_zone`` gives it to Newton, which is cheaper than the
    #: scalar iteration there: 218-241 iterations on the friction-0.5 steps of 16 and 48
    #: carriers, and the start-up steps of a case A run it does not converge on at all)
    scalar_retry: bool = False
    #: a step the block preconditioner stalls on is solved again with the "full" one (it has
    #: the stick stiffness along stuck yarns) before it goes to Newton: with 3 frontal
    #: iterations a step (``FrontalSettings.max_iterations``) a third of the 48-carrier steps
    #: stall, and this makes them 2.5x the lagged run's time instead of 6x
    #: (docs/decisions.md, "A time step's problem posed by its posed state"); None: on
    #: exactly when a step takes more than one frontal iteration, so that the lagged
    #: default's results stay as they were
    full_retry: bool | None = None
    #: largest move of a crossing in one block update, as a fraction of its shortest segment
    #: (the whole update is scaled down to it: the stiffness holds for moves small against
    #: the segments)
    block_cap: float = 2.0
    #: the preconditioner of a zone behind a guide ring (``solve_zone``): "full", the Hessian
    #: in the positions and the materials (``docs/decisions.md``, "Why the block preconditioner
    #: fails behind a ring": the block one leaves out the axial stiffness of yarns that stick
    #: at the new crossings below the ring, and stalls on 80-98 % of case B's steps)
    ring_preconditioner: str = "full"
    #: ``block_stall`` of the full preconditioner: a step it converges on takes a median 8
    #: iterations (case B); one without a new lowest residual in 10 goes to Newton sooner
    #: (case B end to end: CPU 132 s against 180 s with 20, fallbacks 13.8 % against 12.5 %)
    ring_stall: int = 10
    #: with the full preconditioner, the line search on the reduced energy (module docstring,
    #: item 5): without it the iteration cycles on 18 % of the bent tube's steps (those go to
    #: Newton); with it 400 of 400 sampled steps converge, at the same median of 12 iterations
    ring_line_search: bool = True
    #: halvings of that line search at most; the last step is taken as it is (a step shortened
    #: 256 times moves by millimetres / 256; K is factorised anew after it)
    ring_halvings: int = 8
    #: a step the line search shortened was taken with a stale K: K is factorised anew at the
    #: next iteration (on 48 of the bent tube's steps the plain iteration stalls on, 47
    #: converge in a median 18 iterations against 45 in 24 without)
    ring_refactor_damped: bool = True
    #: iterations without a new lowest residual since the last factorisation after which K is
    #: factorised anew (0: never): a chord iteration from a stale K converges linearly and
    #: slowly (a 48-carrier case-B-like step: 55 iterations, stalled at ring_stall; with 3, 18
    #: iterations and 2 factorisations; neutral on the bent tube's steps)
    ring_refactor_stall: int = 3
    #: the full preconditioner's elimination order: "metis" (METIS's nested dissection of the
    #: lattice, pymetis, ~3 ms at 1230 crossings: 27 % less fill than "band" and half its
    #: factorisation work; bent tube 0.6 m end to end: 31 s of CPU against 40 s) or "band"
    #: (``band_dissection``, the block preconditioner's)
    ring_order: str = "metis"
    #: behind a guide ring the frontal iterations of the bounds a snapshot asks for (its ring
    #: passes and final solve) by the relaxation with consistent bounds, the final one finished
    #: by Newton's (module docstring); off: Newton's alone (a bent-tube snapshot 1.4 s against
    #: 2.1-2.3 s, its crossings within 0.4 mm of Newton's alone)
    ring_frontal: bool = True
    #: without a guide ring a snapshot's frontal iterations likewise (its pass and its final
    #: solve by the relaxation with consistent bounds and the ring preconditioner, which has the
    #: stick stiffness along a stuck yarn; the final one finished by Newton's frontal
    #: iteration); off: Newton's alone (SuperLU without the cholmod extra: case A's full-size
    #: run with 20 snapshots 185 s against 111 s with the final solves alone by the relaxation)
    snapshot_frontal: bool = True


@dataclass(frozen=True)
class InteractionSettings:
    """All numerical settings of the interaction model (module docstring)."""

    energy: EnergySettings = field(default_factory=EnergySettings)
    newton: NewtonSettings = field(default_factory=NewtonSettings)
    frontal: FrontalSettings = field(default_factory=FrontalSettings)
    zone: ZoneSettings = field(default_factory=ZoneSettings)
    ring: RingSettings = field(default_factory=RingSettings)
    relax: RelaxSettings = field(default_factory=RelaxSettings)
    near: NearSettings = field(default_factory=NearSettings)


#: the model's settings
DEFAULT = InteractionSettings()
