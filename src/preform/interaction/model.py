"""The yarn-interaction convergence zone (paper §2; docs/theory.md §4) behind ``[model] kind =
"interaction"``: a :class:`preform.zone.Zone`, like the kinematic model's.

Each step (``step``):

1. the material coordinate of every fell point is anchored to the new fell points
   (``fell_anchor``, ``ZoneSettings.fell_material``): by default the yarn laid on the mandrel
   leaves the lowest segment's tension (``frontal.fell_material``); "laid" conserves the yarn,
   the fell material advancing by the yarn laid since the last step;
2. a crossing is created at every carrier pass of the step (``machine.pass_times``) at the top of
   both yarns, at the midpoint of the closest points of the two top segments (from the yarn's
   highest crossing, or fell point, to its ring or spool point at the step's end); over/under from
   the horn-gear pattern; its new segments carry the top tension. This is only the start of the
   solve: the solver moves it to where the two yarns balance, which is below the supply as soon
   as the carriers have parted (no crossing is pinned at the supply);
3. the contact normals become the radial directions of the crossings (held during the solve), and
   the frontal solver (``interaction/frontal.py``) brings all crossings to balance with the fell
   points of the step's end, each yarn sticking (its material at the crossing stays) or slipping
   on its friction bound. The state after 1-3 is the step's *posed* state: it defines the
   step's problem (friction centres, the bounds of new crossings, the top tensions), and the
   solver starts from it; a solve started elsewhere (``solve_zone``'s ``start``, the stages of
   ``_staged``) lands on the same state, to the balance tolerance;
4. a crossing that lies closer to the mandrel than ``deposit_height`` yarn thicknesses (the
   solver keeps the crossings outside the mandrel's tangent planes, ``frontal.Boundary.plane``)
   is deposited: it becomes the
   fell point of both its yarns (``ZoneStep.deposits``) and leaves the zone; crossings below it on
   its other yarn go with it (lowest first), so chains stay consistent on ragged rows;
5. every yarn's free yarn runs to its lowest crossing (its yarn centerline point there), or to its
   supply point (ring point, else spool) when it has none: ``G_end``; ``G_mid`` is the mean of the
   previous and the new one while the lowest crossing stays the same, else ``G_end``.

Guide ring (paper §2.3): every yarn's ring point ``R(theta_r)`` sticks or slips across the ring
with Amontons friction (``slide_rings``, the single ring-contact solver, after each step's solve:
the ring point lags the yarn by a step), and the tension below it follows Capstan from the spool
tension by the direction the yarn's material slides over the ring (``_kernels/frontal.
top_tensions``): towards the mandrel while the zone draws yarn from the spool, ``f = f_spool
exp(mu_r eta)`` (the mandrel side higher); towards the spool while the carrier's tensioner takes
yarn back, ``f = f_spool exp(-mu_r eta)`` (the paper's eq. 9 as written); in between the yarn
sticks along the ring and holds its tension within that cone. The slide along the ring is the
change, over the step, of the material coordinate at the ring point (``ring_material``: the
highest crossing's material plus the top segment's material length); along and across the ring
are one Coulomb cone (``_ring_flow``, ``_kernels/ring.py``): while the yarn slides along, it cannot
stick across, and the Capstan exponent is scaled by the share of the slide that runs along.
Explicit, like the ring point's transverse slip: the next step's solve uses this step's slide
(``RingSettings.capstan``, ``stick_slide``).

The numerical settings (deposit height, creation, staging, the snapshot's ring alternation and
everything the solver uses) are an :class:`~preform.interaction.settings.InteractionSettings`,
passed to the constructor.

Distances to the mandrel are to the face under a crossing (``MandrelDistance._closest``: the
nearest centroid's face where the crossing lies over it, else the closest point over the faces
round the nearest vertex and that face's corners, so that the long thin faces of a CAD export
are found), the wall's
tangent planes those faces' planes. Only the bottom rows come near the mandrel, so the faces are
looked up only for the crossings a bound does not prove far from it (``MandrelDistance.near``: the bounding box, then a KD-tree of
face samples with a per-crossing cache of its distances, 1-Lipschitz): the tangent planes for the
crossings that may lie within ``NearSettings.wall_clearance`` of the surface at the step's start
(the others have no wall; if the solve moves one of them as far as it was from the mandrel, the
step is solved again with every crossing's plane), the deposit test for those that may lie within
the deposit height. Where no iterate of the solve reaches the
plane of a crossing that has none, the states are those with every crossing's plane (measured:
case A, bent tube and bulge histories bit-identical, ``docs/decisions.md``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._kernels import frontal as frontal_kernels
from .._kernels import ring as ring_kernels
from ..errors import SimulationError
from .. import plain
from ..kinematic import KinematicZone
from ..result import Snapshot
from ..zone import ZoneStep, solver_of
from . import frontal, step_check
from .ring import ring_arguments, ring_point
from .mandrel_distance import MandrelDistance
from .settings import DEFAULT, InteractionSettings
from .zone_state import ZoneState

#: ``RingSettings.capstan`` -> the Capstan direction a yarn starts with (``_ring_flow``)
CAPSTAN_MODES = {"flow": 0.0, "paper": -1.0, "drawn": 1.0}


class InteractionZone:
    """Crossings with stick/slip friction between the fell points and the supply side.

    config: the run's :class:`~preform.config.Config` (its ``yarn`` section is read); machine:
    :class:`~preform.machine.Machine`; mandrel: the mandrel (mandrel frame) whose distance decides
    deposition and whose tangent planes are the wall, or None; distance: instead of the mandrel, a
    :class:`MandrelDistance` or a plain callable ``points (k, 3) -> signed distance (k,)`` (no
    wall: it has no planes); settings: the numerical settings (default ``settings.DEFAULT``; its
    ``near`` for the look-ups of ``mandrel``);
    solve_zone: the zone solver, ``frontal.solve_zone_inplace`` or a stand-in with its signature
    (failure-injection tests).
    """

    #: said before a run starts (``Zone.cost_note``)
    cost_note = ('[model] kind = "interaction": about {steps:,} time steps, each a solve of every '
                 "crossing of the convergence zone; a step that does not converge stops the run, "
                 "which keeps the results up to it")
    #: the first-run worker's jobs are the kinematic run's kernels (``Zone.first_run_worker``)
    first_run_worker = False

    def __init__(self, config, machine, mandrel=None, *, distance=None,
                 settings: InteractionSettings | None = None, solve_zone=None):
        self.config = config
        self.machine = machine
        self.settings = DEFAULT if settings is None else settings
        self.solve_zone = frontal.solve_zone_inplace if solve_zone is None else solve_zone
        self.distance = distance if distance is not None else (
            MandrelDistance(mandrel, self.settings.near) if mandrel is not None else None)
        # the tangent planes of the wall: only a mandrel has them
        self.planes = self.distance.planes if isinstance(self.distance, MandrelDistance) else None
        y = config.yarn
        self.h = 0.5 * float(y.thickness)
        self.width = float(y.width)
        self.mu = float(y.friction)
        self.mu_r = float(y.ring_friction)
        self.f_spool = float(y.tension)
        # mixed yarns: every yarn's type, and the friction and tension of the types
        # (``frontal.Boundary``); None: every yarn is [yarn]
        self.types = _yarn_types(config) if getattr(config, "is_mixed", False) else {}
        self.state = ZoneState(machine.n_yarns)
        self.f_top = (np.full(machine.n_yarns, self.f_spool) if not self.types else
                      self.types["type_tension"][self.types["yarn_type"]])   # N, every yarn's top tension
        self.step_index = 0
        self.G_prev = None            # (2n, 3) free-yarn ends of the last step
        self.lowest_uid_prev = None   # (2n,) uid of every yarn's lowest crossing at the last step
        self.last_report = None       # frontal.SolveReport of the last step
        self.fell = None              # (2n, 3) fell points of the last step
        self.fell_ref = None          # (2n, 3) where the next step's boundary moves from
        self.staged = 0               # steps solved in stages (``_staged``)
        self.wall_resolves = 0        # steps solved again with every crossing's plane (``step``)
        self.lag_resolves = 0         # steps solved again with their bounds iterated (``step``)
        self.t = 0.0
        self.stage = ""               # the part of the step under way (a fault's message names it)
        self.snapshot_due = False     # set by the stepper before a step whose state it snapshots
        self._own = None              # the Snapshot of the last such step's solved state
        self._own_problem = None      # (state, boundary) that step solved
        self.pose_end = None          # the mandrel's pose at the end of the last step
        self.pending = []             # carrier passes waiting for their ring points (``_ready_passes``)
        self.ring_theta = None        # (2n,) rad, ring angles (guide ring only)
        self.ring_anchor = None       # (2n,) rad, ring angles at the start of the last step
        self.ring_capstan = None      # (2n,) in [-1, 1]: Capstan factor by the yarn's slide (_ring_flow)
        self.ring_u = None            # (2n,) m, material coordinate at the ring point, last step
        self.ring_s_long = None       # (2n,) m, slide along the ring in the last step (``_ring_flow``)
        if self.settings.zone.fell_material not in ("laid", "tension"):
            raise ValueError(f"ZoneSettings.fell_material = {self.settings.zone.fell_material!r}: "
                             "expected 'laid' or 'tension'")
        if self.settings.ring.capstan not in CAPSTAN_MODES:
            raise ValueError(f"RingSettings.capstan = {self.settings.ring.capstan!r}: expected one "
                             f"of {', '.join(map(repr, CAPSTAN_MODES))}")

    # -- interface --------------------------------------------------------------------------
    @classmethod
    def for_run(cls, config, machine, mandrel, settings=None):
        """The zone of a run (``Zone.for_run``): ``settings.interaction`` (None: the defaults),
        the solver of ``[model] solver`` (``zone.SOLVERS``), and ``[model] frontal_iterations``
        (the user's input for ``FrontalSettings.max_iterations``) friction-bound updates a
        step where it is not 1."""
        model = DEFAULT if settings is None else settings.interaction
        iterations = config.model.frontal_iterations
        if iterations != 1:
            model = dataclasses.replace(
                model, frontal=dataclasses.replace(model.frontal, max_iterations=iterations))
        return cls(config, machine, mandrel, settings=model,
                   solve_zone=solver_of(config.model.solver))

    @classmethod
    def default_time_step(cls, machine, per_width, tolerances):
        """Without a guide ring the model is quasi-static: a step is one solve of the zone with
        the friction history of the last; what it must resolve is the arrival of new crossings
        (at most ``interaction_pass_fraction`` of the pass period per step: a yarn meets a new
        crossing every third step at most) and the mandrel's shape under the fell points
        (``interaction_fell_advance`` widths per step). Behind a guide ring it keeps the
        kinematic step: its ring points slide explicitly once a step (``slide_rings``), so a
        longer step moves them further between solves. The measurements behind these bounds
        are in docs/decisions.md."""
        if machine.has_ring:
            return KinematicZone.default_time_step(machine, per_width, tolerances)
        return min(tolerances.interaction_pass_fraction * machine.pass_period(),
                   tolerances.interaction_fell_advance * per_width)

    def start(self, t, F_machine, pose):
        """Tie points (machine frame) at time t; the zone starts without crossings."""
        self.t = float(t)
        self.fell = np.array(F_machine, dtype=float)
        self.fell_ref = self.fell.copy()
        self.G_prev = self.machine.supply_points(t)
        self.lowest_uid_prev = np.full(self.machine.n_yarns, -1, dtype=np.int64)
        self.pending = []
        if self.machine.has_ring:    # ring points start at the carriers' azimuths
            self.ring_theta = np.arctan2(self.G_prev[:, 1], self.G_prev[:, 0])
            self.ring_anchor = self.ring_theta
            # no yarn has slid over the ring yet: it sticks at the spool tension
            self.ring_capstan = np.full(self.machine.n_yarns, CAPSTAN_MODES[
                self.settings.ring.capstan])
            self.ring_u = np.full(self.machine.n_yarns, np.nan)
            self.ring_s_long = np.zeros(self.machine.n_yarns)

    def boundary(self, t, F_machine, ring_theta=None) -> frontal.Boundary:
        """The zone's boundary at time t: fell points F_machine, ring points at ``ring_theta``
        (default: the zone's), spool points."""
        m = self.machine
        if m.has_ring:
            theta = self.ring_theta if ring_theta is None else ring_theta
            top = ring_point(theta, m.ring_radius, m.supply_z)
        else:
            top = m.supply_points(t)
        ring = dict(capstan=self.ring_capstan.astype(float), f_hold=np.array(self.f_top, float)) \
            if m.has_ring and self.ring_capstan is not None else {}
        return frontal.Boundary(fell=np.ascontiguousarray(F_machine, dtype=float),
                                top=top, spool=m.spool_points(t),
                                f_spool=self.f_spool, mu=self.mu, mu_r=self.mu_r,
                                has_ring=bool(m.has_ring), h=self.h, width=self.width, **ring,
                                **self.types)

    def step(self, t0, dt, F_machine, pose_end) -> ZoneStep:
        t1 = t0 + dt
        self.step_index += 1
        bc = self.boundary(t1, F_machine)
        st = self.state
        fell_start = st.material_fell.copy()
        self.stage = "the new crossings (the fell points' anchoring, the carriers' passes)"
        st.material_fell[:] = self.fell_anchor(st, bc, self.fell_ref, pose_end)
        self._create_crossings(t0, t1, bc)
        where = f"at step {self.step_index} (t = {t1:.6g} s)"
        frontal_kernels.radial_normals(st.m, st.pos, st.normal)
        self.pose_end = pose_end
        centre = frontal.friction_centres(st)
        # the posed state: what defines the step's problem (the solvers take the bounds of new
        # crossings and the top tensions from it) and what a solve sets, for the step solved
        # again with every crossing's plane or in stages
        posed = {name: getattr(st, name)[: st.m].copy()
                 for name in ("pos", "material", "tension", "bound", "slip", "offset")}
        self.stage = "the solve of the zone's crossings"
        try:
            wall, clear = self._with_near_wall(bc)
            self.last_report = self.solve_zone(st, wall, settings=self.settings, where=where,
                                               centre=centre)
            if clear is not None and self._left_clearance(posed["pos"], clear):
                # a crossing without its plane moved as far as it was from the mandrel (it
                # may have reached the wall): the step again with every crossing's plane
                self.wall_resolves += 1
                _restore(st, posed)
                wall = self._with_wall(bc)
                self.last_report = self.solve_zone(st, wall, settings=self.settings,
                                                   where=where, centre=centre)
            bc = wall
        except SimulationError as err:
            if self.fell_ref is None or not self.settings.zone.boundary_stages:
                raise step_check.with_cause(self, err) from None
            try:
                bc = self._staged(t0, t1, bc, where, centre, fell_start, posed)
            except SimulationError as again:
                raise step_check.with_cause(self, again) from None
        zs = self.settings.zone
        if (not self.last_report.residual <= zs.max_step_residual
                and self.settings.frontal.max_iterations < zs.lag_iterations):
            # the bounds' lag above the limit: the step again with its bounds iterated to
            # those of its converged geometry (``lag_iterations`` frontal iterations)
            self.lag_resolves += 1
            _restore(st, posed)
            again = dataclasses.replace(self.settings, frontal=dataclasses.replace(
                self.settings.frontal, max_iterations=zs.lag_iterations))
            try:
                self.last_report = self.solve_zone(st, bc, settings=again, where=where,
                                                   centre=centre)
            except SimulationError as err:
                raise step_check.with_cause(self, err) from None
        step_check.check_step(self, where, posed["bound"])
        self.f_top = self.last_report.f_top
        self.stage = "the guide ring's contact"
        if self.machine.has_ring:
            self.ring_anchor = self.ring_theta
            u = self.ring_material(st, bc)
            if self.settings.ring.capstan == "flow":
                du = u - self.ring_u
                self.ring_s_long = np.where(np.isfinite(du), du, 0.0)
            self.ring_u = u
            self.ring_theta = self.slide_rings(st, bc, self.ring_anchor)
            self._ring_flow()
        if self.snapshot_due:
            # the state the step solved, before its deposit: what its snapshot writes, and its
            # boundary, which its check holds
            self._own = _snapshot(st, bc, self.last_report.f_top, t1, self.machine,
                                  self.settings, wall="reaction")
            self._own_problem = (st.copy(), bc)
        self.stage = "the deposit of crossings on the mandrel"
        deposits = self._deposit(pose_end)
        self.fell_ref = bc.fell.copy()       # where the next step's boundary moves from
        for k, p in deposits:
            self.fell_ref[k] = p
        G_end = self.lowest_points(bc.top)
        uid = np.where(st.lowest >= 0, st.uid[np.maximum(st.lowest, 0)], -1)
        same = (uid >= 0) & (uid == self.lowest_uid_prev)
        G_mid = np.where(same[:, None], 0.5 * (self.G_prev + G_end), G_end)
        none = st.lowest < 0
        G_mid[none] = (bc.top if self.machine.has_ring
                       else self.machine.supply_points(t0 + 0.5 * dt))[none]
        self.G_prev, self.lowest_uid_prev = G_end, uid
        self.fell = bc.fell
        self.t = t1
        return ZoneStep(G_mid=G_mid, G_end=G_end, deposits=deposits, contacts=st.m,
                        iterations=self.last_report.iterations,
                        residual=self.last_report.residual)

    def _staged(self, t0, t1, bc, where, centre, fell_start, posed):
        """The step solved again with its boundary moved in the ``boundary_stages`` (fell points
        from where the last step left them, supply or ring points from their last places, each
        solve started from the last one's result; the same friction centres ``centre``): where
        the boundary's move in one go takes Newton out of its reach. Every stage is posed from
        ``posed`` (the step's posed state: positions, material, tensions, bounds, slip states,
        offsets), the last stage's result being only its start, so the last stage is the step's
        own problem and lands where a direct solve that converged would. ``fell_start``: the
        fell points' material the last step left ("laid" anchoring; "tension" anchors the
        stages' start itself). Sets ``last_report``; returns the final boundary (with the
        wall)."""
        st = self.state
        m = self.machine
        stages = self.settings.zone.boundary_stages
        where = f"{where}, also with the boundary moved in {len(stages)} stages"
        report, bcl = None, bc

        def at(lam):
            fell = self.fell_ref + lam * (bc.fell - self.fell_ref)
            theta = (self.ring_anchor + lam * (self.ring_theta - self.ring_anchor)
                     if m.has_ring else None)
            return self.boundary(t0 + lam * (t1 - t0), fell, theta)

        # the fell points' material moves with them: from the last step's anchoring to the
        # step's own (``fell_anchor``), so the last stage is the step's problem itself
        fell_end = st.material_fell.copy()
        _restore(st, posed)                        # what the failed solve left moved
        if self.settings.zone.fell_material == "tension":
            fell_start = frontal.fell_material(st, at(0.0), self.settings)
        start = posed["pos"], posed["material"]
        for lam in stages:
            bcl = at(lam) if lam < 1.0 else bc
            st.material_fell[:] = fell_start + lam * (fell_end - fell_start)
            _restore(st, posed)
            bcl = self._with_wall(bcl)
            report = self.solve_zone(st, bcl, settings=self.settings, where=where, centre=centre,
                                     start=start)
            start = st.pos[: st.m].copy(), st.material[: st.m].copy()
        self.staged += 1
        self.last_report = report
        return bcl

    def snapshot(self, t, F_machine) -> Snapshot:
        """Polyline per yarn: fell point, its crossings upwards, ring point, spool point: the
        state the last step solved (before its deposit, with the fell points and ring points it
        was solved with; ``snapshot_due``), or, before the first step, the zone as it is.

        The snapshot is checked by a re-balance (``rebalanced``, on a copy): the zone brought to
        balance with the fell points given and friction bounds iterated to convergence; the
        written state stays the run's own, and ``rebalance_shift_m`` says how far its yarns'
        points at the crossings are from the re-balanced ones (``rebalance_error`` where the
        re-balance failed)."""
        snap, self._own = self._own, None
        problem, self._own_problem = self._own_problem, None
        if snap is None or snap.time_s != float(t):
            bc = self._with_wall(self.boundary(t, F_machine))
            snap = _snapshot(self.state, bc, self.f_top, t, self.machine, self.settings,
                             wall="reaction")
            problem = None
        try:
            checked = (self._rebalanced(t, F_machine) if problem is None else
                       self._rebalanced_own(t, *problem))
        except SimulationError as err:
            return dataclasses.replace(snap, rebalance_error=str(err))
        return dataclasses.replace(snap, rebalance_shift_m=crossing_shift(snap, checked),
                                   rebalanced=checked)

    def _rebalanced_own(self, t, state, bc) -> Snapshot:
        """The state a step solved, re-balanced on a copy with its boundary held (the fell points
        and ring points it was solved with), each yarn's friction centre at each crossing where
        the step left it, and the friction bounds iterated to those of the geometry
        (``FrontalSettings.snapshot_tolerance``): a converged state is its own fixed point, a
        state out of balance or outside its friction cone moves. The ring points' slide and
        the fell points' walk after the step belong to the next step, not to this one's
        balance (sliding the ring points to their fixed point moved the crossings of converged
        runs behind a ring by up to 112 mm), and friction centres from before the step would
        let the re-balance slide crossings along the zone's neutral directions."""
        st = state.copy()
        fr = self.settings.frontal
        report = self.solve_zone(st, bc, settings=self.settings, max_iter=fr.snapshot_iterations,
                                 where=f"in the snapshot at t = {t:.6g} s",
                                 centre=frontal.friction_centres(st),
                                 friction_tol=fr.snapshot_tolerance, mode="final")
        return _snapshot(st, bc, report.f_top, t, self.machine, self.settings)

    def _rebalanced(self, t, F_machine) -> Snapshot:
        """The zone re-balanced on a copy with the fell points given: the ring points and the
        zone solved in turn, the friction bounds to convergence
        (``FrontalSettings.snapshot_tolerance``), crossings the re-solve lays on the mandrel
        deposited."""
        st = self.state.copy()
        # each yarn's friction centre at each crossing (``frontal.solve_zone_inplace``)
        anchor = dict(zip(st.uid[: st.m].tolist(), frontal.friction_centres(st)))
        fell = np.array(F_machine, dtype=float)
        # the fell points' material as the last step left it, and where they were then: the
        # snapshot's fell points are those the stepper laid the yarn to since (same pose)
        ref, ref_material = self.fell_ref.copy(), st.material_fell.copy()
        theta = self.ring_theta
        zs = self.settings.zone
        where = f"in the snapshot at t = {t:.6g} s"
        for i in range(zs.ring_iterations):
            # the same stick anchors (yarn material, ring angles) in every pass: a fixed point
            # of the step's state, not further steps
            bc = self._with_wall(self.boundary(t, fell, theta), st)
            st.material_fell[:] = ref_material
            st.material_fell[:] = self.fell_anchor(st, bc, ref, self.pose_end)
            centre = np.array([anchor[u] for u in st.uid[: st.m].tolist()]).reshape(-1, 2)
            self.solve_zone(st, bc, settings=self.settings, max_iter=zs.ring_pass_iterations,
                            where=where, centre=centre, mode="pass")
            # a crossing the re-solve laid on the mandrel is deposited there, as a step would
            deposits = self._deposit(self.pose_end, st)
            for k, p in deposits:
                fell[k] = ref[k] = p
                ref_material[k] = st.material_fell[k]
            moved = 0.0
            if self.machine.has_ring:
                new = self.slide_rings(st, bc, self.ring_anchor)
                moved = float(np.abs(new - theta).max()) * self.machine.ring_radius
                theta = new
            if moved < zs.ring_tolerance and not deposits:
                break
        # the friction bounds to convergence at the final ring points and fell points
        bc = self._with_wall(self.boundary(t, fell, theta), st)
        st.material_fell[:] = ref_material
        st.material_fell[:] = self.fell_anchor(st, bc, ref, self.pose_end)
        centre = np.array([anchor[u] for u in st.uid[: st.m].tolist()]).reshape(-1, 2)
        fr = self.settings.frontal
        report = self.solve_zone(st, bc, settings=self.settings, max_iter=fr.snapshot_iterations,
                                 where=where, centre=centre, friction_tol=fr.snapshot_tolerance,
                                 mode="final")
        return _snapshot(st, bc, report.f_top, t, self.machine, self.settings)

    def slide_rings(self, st, bc, theta):
        """Ring angles (2n,) for the next solve: each yarn's ring point sticks or slips across the
        ring with Amontons friction (paper §2.3, ``_kernels.ring.solve_ring``), the yarn running
        from its highest crossing (or fell point) over the ring to its spool point. Explicit: the
        zone's solve that follows uses them, so the ring point lags its yarn by a step (snapshots
        iterate to ``ring_tolerance``)."""
        n = st.n_yarns
        A = np.array([self._top_point(k, bc.fell, st) for k in range(n)])
        out = ring_kernels.empty_out(n)
        status = np.empty(n, dtype=np.int64)
        capstan, _ = bc.capstan_arguments()
        # a yarn sticking along the ring holds the tension the solve left below it
        hold = np.ascontiguousarray(self.f_top, dtype=float)
        # sliding along the ring in this step, the yarn has one friction cone along and across
        s_long = np.ascontiguousarray(np.abs(self.ring_s_long), dtype=float)
        ring_kernels.solve_rings(A, np.ascontiguousarray(bc.spool), bc.spool_tensions(),
                                 self.machine.ring_radius, self.machine.supply_z,
                                 np.asarray(theta, float), bc.ring_frictions(), capstan, hold, s_long,
                                 *ring_arguments(self.settings.ring), out, status)
        ok = status == ring_kernels.RING_OK
        return np.where(ok, out[:, ring_kernels.RING_OUT_THETA], theta)

    def ring_material(self, st, bc) -> np.ndarray:
        """(2n,) m: the material coordinate of every yarn at its ring point, its highest
        crossing's (or fell point's) plus the top segment's material length at its tension,
        ``l_top / (1 + f_top / EA)`` (``frontal.new_material``)."""
        n = st.n_yarns
        EA = frontal.axial_stiffness(self.f_spool, self.settings)
        out = np.empty(n)
        for k in range(n):
            c = st.highest[k]
            side = 0 if k < self.machine.n_per_group else 1
            u = st.material[c, side] if c >= 0 else st.material_fell[k]
            l = float(np.linalg.norm(bc.top[k] - self._top_point(k, bc.fell, st)))
            out[k] = u + l / (1.0 + self.f_top[k] / EA)
        return out

    def _ring_flow(self):
        """The Capstan factor of every yarn for the next step (``RingSettings.capstan``). "flow":
        the yarn slid ``s = ring_s_long`` along the ring (positive: material from the spool side
        arrived at the ring point, the yarn slides towards the mandrel) and ``r dtheta`` across
        it in this step; one Coulomb cone opposes that slide, so the Capstan exponent is
        ``sign(s) mu_r eta |s| / |(s, r dtheta)|`` (the factor ``ring_capstan``); below
        ``stick_slide`` in all the yarn sticks (0: holding its tension within the cone)."""
        rs = self.settings.ring
        if rs.capstan != "flow":
            return
        s = self.ring_s_long
        a = self.machine.ring_radius * np.abs(self.ring_theta - self.ring_anchor)
        total = np.hypot(s, a)
        self.ring_capstan = np.where(total > rs.stick_slide,
                                     s / np.maximum(total, 1e-300), 0.0)

    # -- checkpoints ------------------------------------------------------------------------
    def export_state(self) -> dict:
        """What the zone carries from step to step, as plain arrays (``preform.checkpoint``): the
        crossings (``ZoneState.to_arrays``, names ``state.*``), top tensions, fell points, the
        last step's lowest points, waiting passes, ring angles and pose. (``last_report`` is
        not state: each step sets it before reading it.)"""
        out = plain.prefixed("state.", self.state.to_arrays())
        pending = self.pending
        out.update(
            f_top=self.f_top, fell=self.fell, fell_ref=self.fell_ref, G_prev=self.G_prev,
            lowest_uid_prev=self.lowest_uid_prev, t=np.float64(self.t),
            step_index=np.int64(self.step_index), staged=np.int64(self.staged),
            pending_time=np.array([p[0] for p in pending], dtype=np.float64),
            pending_yarns=np.array([p[1:3] for p in pending], dtype=np.int64).reshape(-1, 2),
            pending_over=np.array([p[3] for p in pending], dtype=bool))
        if self.pose_end is not None:
            out.update(pose_R=self.pose_end.R, pose_t=self.pose_end.t)
        if self.ring_theta is not None:
            out.update(ring_theta=self.ring_theta, ring_anchor=self.ring_anchor,
                       ring_capstan=self.ring_capstan, ring_u=self.ring_u,
                       ring_s_long=self.ring_s_long)
        return {k: np.array(v) for k, v in out.items()}

    def import_state(self, arrays) -> None:
        """Replace the state by one ``export_state`` gave, checked first (ValueError)."""
        from ..geometry.pose import Pose

        ny, n = self.machine.n_yarns, self.machine.n_per_group
        f64 = np.float64

        def points(name):
            return plain.finite(name, plain.take(arrays, name, (ny, 3), f64))

        state = ZoneState.from_arrays(plain.unprefixed("state.", arrays), ny)
        f_top = plain.finite("f_top", plain.take(arrays, "f_top", (ny,), f64))
        fell, fell_ref, G_prev = points("fell"), points("fell_ref"), points("G_prev")
        uid_prev = plain.in_range("lowest_uid_prev",
                                  plain.take(arrays, "lowest_uid_prev", (ny,), np.int64), -1, 2**62)
        t = plain.finite("t", plain.take(arrays, "t", (), f64)).item()
        step_index = plain.scalar(arrays, "step_index", np.int64)
        staged = plain.scalar(arrays, "staged", np.int64)
        times = plain.finite("pending_time", plain.take(arrays, "pending_time", (None,), f64))
        yarns = plain.take(arrays, "pending_yarns", (len(times), 2), np.int64)
        plain.in_range("pending_yarns (warp)", yarns[:, 0], 0, n)
        plain.in_range("pending_yarns (weft)", yarns[:, 1], n, 2 * n)
        over = plain.take(arrays, "pending_over", (len(times),), bool)
        pose = None
        if "pose_R" in arrays:
            pose = Pose(R=plain.finite("pose_R", plain.take(arrays, "pose_R", (3, 3), f64)),
                        t=plain.finite("pose_t", plain.take(arrays, "pose_t", (3,), f64)))
        if self.machine.has_ring != ("ring_theta" in arrays):
            raise ValueError("the ring angles do not match the machine's guide ring")
        theta = anchor = capstan = ring_u = s_long = None
        if self.machine.has_ring:
            theta = plain.finite("ring_theta", plain.take(arrays, "ring_theta", (ny,), f64))
            anchor = plain.finite("ring_anchor", plain.take(arrays, "ring_anchor", (ny,), f64))
            capstan = plain.finite("ring_capstan", plain.take(arrays, "ring_capstan", (ny,), f64))
            if np.any(np.abs(capstan) > 1.0):
                raise ValueError("array 'ring_capstan' holds values outside [-1, +1]")
            s_long = plain.finite("ring_s_long", plain.take(arrays, "ring_s_long", (ny,), f64))
            # NaN: no step solved yet
            ring_u = plain.finite("ring_u", plain.take(arrays, "ring_u", (ny,), f64),
                                  allow_nan=True)
        self.ring_theta, self.ring_anchor = theta, anchor
        self.ring_capstan, self.ring_u, self.ring_s_long = capstan, ring_u, s_long
        self.state, self.f_top, self.fell, self.fell_ref, self.G_prev = state, f_top, fell, fell_ref, G_prev
        self.lowest_uid_prev, self.t, self.step_index, self.staged = uid_prev, t, step_index, staged
        self.pending = [(float(tp), int(kx), int(ko), bool(o))
                        for tp, (kx, ko), o in zip(times, yarns, over)]
        self.pose_end = pose

    # -- pieces -----------------------------------------------------------------------------
    def fell_anchor(self, st, bc, ref, pose) -> np.ndarray:
        """(2n,) m: the material coordinate of every yarn's fell point ``bc.fell`` (machine
        frame, pose ``pose``), ``ZoneSettings.fell_material``:

        * "laid": the yarn is conserved. The fell point ``ref`` of the last step (where it
          stuck to the mandrel: a deposited crossing or the end of the yarn laid on it) moves
          with the mandrel to ``ref' = pose (pose_last^-1 ref)``; the yarn laid since, from
          the foot of ``ref'`` on the surface (a deposited crossing lies up to the deposit
          height above it, the distance ``d`` to the mandrel) to ``bc.fell`` along the surface,
          takes its material from the free segment: ``u_fell = u_fell_last + sqrt(|bc.fell -
          ref'|^2 - d^2) / (1 + f / EA)``, ``f`` the tension of the
          lowest segment (the chord for the laid arc: both are one step of laying apart,
          a second-order difference). The mandrel's advance thus pulls the yarn through the
          crossings and over the ring, at the rate the braid consumes it. A yarn without a
          lowest crossing (none at the last step or now), and the first step, anchor as
          "tension".
        * "tension": ``frontal.fell_material``, the lowest segment keeps its tension.

        Reads ``st.material_fell`` as the last step left it."""
        new = frontal.fell_material(st, bc, self.settings)
        if self.settings.zone.fell_material == "tension" or self.pose_end is None or ref is None:
            return new
        on_mandrel = self.pose_end.to_mandrel(ref)
        carried = pose.to_machine(on_mandrel)
        gap = np.sum((bc.fell - carried) ** 2, axis=1)
        if self.distance is not None:
            # a deposited crossing sat up to the deposit height off the surface, and the yarn
            # was laid from its foot (the stepper's closest point): that drop along the normal
            # is no yarn laid
            gap = np.maximum(gap - self.distance(on_mandrel) ** 2, 0.0)
        laid = np.sqrt(gap)
        n = st.n_yarns
        lo = st.lowest
        side = (np.arange(n) >= n // 2).astype(np.int64)
        f = st.tension[np.maximum(lo, 0), side]
        EA = frontal.axial_stiffness(bc.f_spool, self.settings)
        stiff = np.where(f >= 0.0, EA, self.settings.energy.compression * EA)
        return np.where(lo >= 0, st.material_fell + laid / (1.0 + f / stiff), new)

    def _with_wall(self, bc, state=None):
        """bc with the mandrel's tangent planes at every crossing (no wall without a mandrel)."""
        st = self.state if state is None else state
        if self.planes is None or st.m == 0 or self.pose_end is None:
            return bc
        return dataclasses.replace(bc, plane=self.planes(st.pos[: st.m], self.pose_end))

    def _with_near_wall(self, bc):
        """(bc with the tangent planes of the crossings that may lie within
        ``NearSettings.wall_clearance`` of the mandrel, the others without a wall; the lower
        bound (m) of each crossing's distance to the surface, ``inf`` where it has its plane),
        or (``_with_wall(bc)``, None) without a mandrel to bound distances on."""
        st = self.state
        if self.planes is None or st.m == 0 or self.pose_end is None:
            return self._with_wall(bc), None
        d = self.distance
        plane, clear = d.near_planes(st.pos[: st.m], self.pose_end, d.settings.wall_clearance,
                                     _near_cache(st))
        return dataclasses.replace(bc, plane=plane), clear

    def _left_clearance(self, start, clear) -> bool:
        """Whether a crossing without its tangent plane moved in the solve (from ``start``, (m,
        3)) at least as far as it was from the mandrel, ``clear`` (m,) (``_with_near_wall``: a
        bound from below, that of the face samples within the look-up's reach, else that reach;
        for a crossing that moved further than that, ``MandrelDistance.clear_of``)."""
        moved = np.linalg.norm(self.state.pos[: self.state.m] - start, axis=1)
        far = np.nonzero(moved >= clear)[0]
        if len(far) == 0:
            return False
        return not bool(np.all(self.distance.clear_of(self.pose_end.to_mandrel(start[far]),
                                                      moved[far])))

    def lowest_points(self, top) -> np.ndarray:
        """(2n, 3): each yarn's centerline point at its lowest crossing, or its top point."""
        st = self.state
        out = np.array(top, dtype=float)
        k = np.nonzero(st.lowest >= 0)[0]
        c = st.lowest[k]
        # the yarn's centerline point: C + over h N on the warp, C - over h N on the weft
        o = np.where(k < self.machine.n_per_group, 1.0, -1.0) * st.over[c]
        out[k] = st.pos[c] + (o * self.h)[:, None] * st.normal[c]
        return out

    def _top_point(self, k, fell, state=None):
        st = self.state if state is None else state
        c = st.highest[k]
        if c < 0:
            return fell[k]
        return st.centerline_point(c, 0 if k < self.machine.n_per_group else 1, self.h)

    def _ready_passes(self, t0, t1):
        """The carrier passes whose crossings are due now, in pass order: every pass of the step
        without a guide ring; behind a ring, a pass's two yarns cross where their ring points
        pass, which lag the carriers when they stick on the ring, so a pass waits (in
        ``self.pending``) until the warp's ring angle is no longer ahead of the weft's (the warp
        turns towards smaller angles). A yarn's later passes wait behind its earlier ones."""
        passes = self.machine.pass_times(t0, t1)
        n = self.machine.n_per_group
        self.pending.extend((float(tp), int(i), int(n + j), bool(o)) for tp, i, j, o in
                            zip(passes.time, passes.warp, passes.weft, passes.warp_over))
        if not self.machine.has_ring:
            ready, self.pending = self.pending, []
            return ready
        ready, wait, blocked = [], [], set()
        for item in self.pending:
            _, kx, ko, _ = item
            d = (self.ring_theta[kx] - self.ring_theta[ko] + np.pi) % (2 * np.pi) - np.pi
            if kx in blocked or ko in blocked or d > 0.0:
                wait.append(item)
                blocked.update((kx, ko))
            else:
                ready.append(item)
        self.pending = wait
        return ready

    def _create_crossings(self, t0, t1, bc):
        for tp, kx, ko, over in self._ready_passes(t0, t1):
            px, po = self._top_point(kx, bc.fell), self._top_point(ko, bc.fell)
            gx, go = bc.top[kx], bc.top[ko]
            C, N = creation_point(px, gx, po, go, lowest=self.settings.zone.creation_lowest)
            st = self.state
            r = float(np.hypot(C[0], C[1]))
            if r > 0.0:     # the normal the solve uses (``radial_normals``): material matches it
                N = np.array([C[0] / r, C[1] / r, 0.0])
            c = st.add(kx, ko, C, N, bool(over), float(tp))
            for side, (k, below) in enumerate(((kx, px), (ko, po))):
                st.material[c, side] = frontal.new_material(st, c, side, below, self.f_top[k], bc,
                                                            self.settings)
                st.tension[c, side] = self.f_top[k]

    def _deposit(self, pose, state=None):
        st = self.state if state is None else state
        if self.distance is None or st.m == 0 or pose is None:
            return []
        height = self.settings.zone.deposit_height * 2.0 * self.h
        points = pose.to_mandrel(st.pos[: st.m])
        if isinstance(self.distance, MandrelDistance):
            # the faces looked up only near the surface (``MandrelDistance.below``)
            hit = np.nonzero(self.distance.below(points, height, _near_cache(st)))[0]
        else:
            hit = np.nonzero(self.distance(points) < height)[0]
        if len(hit) == 0:
            return []
        dead = []
        marked = np.zeros(st.m, dtype=bool)

        def take(c):
            # everything below c on both its yarns first (lowest first)
            for side in range(2):
                below = st.low[c, side]
                if below >= 0 and not marked[below]:
                    take(below)
            if not marked[c]:
                marked[c] = True
                dead.append(c)

        for c in hit:
            take(int(c))
        deposits = []
        laid = self.settings.zone.fell_material == "laid"
        for c in dead:      # lowest first: a yarn's last is its highest deposited crossing
            for side in range(2):
                k = int(st.yarn[c, side])
                deposits.append((k, st.pos[c].copy()))
                if laid:    # the yarn sticks to the mandrel there (``fell_anchor``)
                    st.material_fell[k] = st.material[c, side]
        st.remove(np.array(dead, dtype=np.int64))
        return deposits


def _yarn_types(config) -> dict:
    """The mixed yarns' arrays of ``frontal.Boundary``: every yarn's type (``Config.
    carrier_types``), the friction of every pair of types (``Config.pair_friction``), every
    type's spool tension and yarn-ring friction."""
    types = config.types
    return dict(yarn_type=np.ascontiguousarray(config.carrier_types(), dtype=np.int64),
                pair_mu=np.ascontiguousarray(config.pair_friction()[0], dtype=float),
                type_tension=np.array([t.tension for t in types], dtype=float),
                type_ring_friction=np.array([t.ring_friction for t in types], dtype=float))


def _restore(st, posed):
    """Write a step's posed arrays (``InteractionZone.step``: name -> the first m rows) back into
    the zone state ``st``, in place."""
    for name, value in posed.items():
        getattr(st, name)[: st.m] = value


def _near_cache(st):
    """The look-up cache of the crossings of ``st`` (``ZoneState``) for ``MandrelDistance.near``:
    views, updated in place."""
    return st.near_lo[: st.m], st.near_hi[: st.m], st.near_at[: st.m]


def creation_point(px, gx, po, go, lowest=0.0):
    """Where a new crossing starts: midpoint of the closest points of the segments px->gx and
    po->go (m, machine frame), and the outward unit normal of the two directions
    (``_kernels.frontal.creation_point``). ``lowest``: the closest points are taken no lower
    than this fraction of each segment (a crossing created on top of the one below would start
    with a segment of no length)."""
    out = np.empty(6)
    frontal_kernels.creation_point(np.asarray(px, dtype=float), np.asarray(gx, dtype=float),
                                   np.asarray(po, dtype=float), np.asarray(go, dtype=float),
                                   float(lowest), out)
    return out[:3], out[3:]


def _snapshot(st, bc, f_top, t, machine, settings: InteractionSettings = DEFAULT,
              wall="penalty") -> Snapshot:
    """The zone as a :class:`Snapshot`: per yarn its fell point, its crossings' centerline
    points, its ring point (guide ring) and its top point; ``external_force_N`` at a crossing's
    points the jamming and wall forces (``frontal.point_forces``), at a ring point the ring's
    contact force (normal and friction: the point is held by the ring, so it balances the two
    tensions there), zero at the fell and spool points (held ends: their supports, the laid yarn
    and the carrier, are outside the zone).

    ``wall``: "penalty", the wall force of Newton's penalty (its crossings sit the micrometre
    behind their planes that carries it); "reaction", for a state either solver left: at a
    crossing on or behind its tangent plane (``wall_contact``) the wall takes the yarns' pull
    into the mandrel along the plane's normal, as the relaxation's exact wall does (a
    non-negative normal force; the pull along the plane stays unbalanced where it is)."""
    n = machine.n_per_group
    ny = machine.n_yarns
    ring = machine.has_ring
    e = settings.energy
    if wall == "reaction" and bc.plane is not None and st.m:
        ext_c = frontal.point_forces(st, dataclasses.replace(bc, plane=None), settings)
        _add_wall_reaction(st, bc, ext_c, f_top)
    else:
        ext_c = frontal.point_forces(st, bc, settings)
    points, offsets, tension, cid, slip, ext = [], [0], [], [], [], []
    for k in range(ny):
        side = 0 if k < n else 1
        chain = st.chain(k)
        pts = [bc.fell[k]] + [st.centerline_point(c, side, bc.h) for c in chain] + [bc.top[k]]
        # the top segment pulls with f_top along d / sqrt(|d|^2 + eps2 + eps2_top) (the smoothed
        # length of the energy, ``EnergySettings.top_smoothing``): that is the tension written,
        # so the highest crossing balances from the file also when it sits within a millimetre
        # of its ring point (f_top less by eps2_top / (2 |d|^2), 2e-3 at 0.45 mm)
        d = pts[-1] - pts[-2]
        dd = float(d @ d)
        f_written = f_top[k] * math.sqrt(dd / (dd + e.length_smoothing + e.top_smoothing2))
        ten = [st.tension[c, side] for c in chain] + [f_written]
        ids = [-1] + [int(st.uid[c]) for c in chain] + [-1]
        sl = [0] + [int(st.slip[c, side] != 0) for c in chain] + [0]
        fx = [np.zeros(3)] + [ext_c[c, side] for c in chain] + [np.zeros(3)]
        if ring:
            pts.append(bc.spool[k])
            f_spool = float(bc.spool_tensions()[k])
            ten.append(f_spool)
            ids.append(-1)
            sl.append(0)
            fx.append(np.zeros(3))
            below, at, above = pts[-3], pts[-2], pts[-1]
            fx[-2] = -(f_written * _unit(below - at) + f_spool * _unit(above - at))
        points.extend(pts)
        tension.extend(ten)
        cid.extend(ids)
        slip.extend(sl)
        ext.extend(fx)
        offsets.append(len(points))
    return Snapshot(time_s=float(t), points=np.array(points, dtype=float).reshape(-1, 3),
                    offsets=np.array(offsets, dtype=np.int64),
                    tension_N=np.array(tension, dtype=float),
                    contact_id=np.array(cid, dtype=np.int64),
                    slip=np.array(slip, dtype=np.int8), group=machine.group.copy(),
                    external_force_N=np.array(ext, dtype=float).reshape(-1, 3))


#: m, a crossing within this of its tangent plane (or behind it) rests on the wall in a
#: snapshot's "reaction" forces: the relaxation's wall tolerance (``RelaxSettings.wall_release``)
#: is 1e-7 m and Newton's penalty holds crossings about 1 um behind their planes
WALL_CONTACT = 1e-5


def _add_wall_reaction(st, bc, ext_c, f_top):
    """Add to ``ext_c`` (m, 2, 3) the wall's reaction at the crossings resting on their tangent
    planes (``WALL_CONTACT``): the normal part of the net force of the four segments' tensions
    and ``ext_c`` pressing into the mandrel, on the inner yarn's point (``point_forces``)."""
    m = st.m
    plane = bc.plane[:m]
    pos = st.pos[:m]
    sd = np.einsum("ij,ij->i", pos - plane[:, :3], plane[:, 3:])
    resting = np.nonzero(sd < WALL_CONTACT)[0]
    if not len(resting):
        return
    net = ext_c[:m].sum(axis=1)
    for c in resting.tolist():
        for side in range(2):
            here = st.centerline_point(c, side, bc.h)
            lo = st.low[c, side]
            k = int(st.yarn[c, side])
            below = st.centerline_point(lo, side, bc.h) if lo >= 0 else bc.fell[k]
            up = st.up[c, side]
            above = st.centerline_point(up, side, bc.h) if up >= 0 else bc.top[k]
            f_hi = st.tension[up, side] if up >= 0 else f_top[k]
            net[c] += st.tension[c, side] * _unit(below - here) + f_hi * _unit(above - here)
    normal = plane[resting, 3:]
    push = np.maximum(-np.einsum("ij,ij->i", net[resting], normal), 0.0)
    inner = np.where(st.over[resting] > 0, 1, 0)
    ext_c[resting, inner] += push[:, None] * normal


def crossing_shift(a: Snapshot, b: Snapshot) -> float:
    """m: the largest distance between a yarn's point at a crossing in snapshot ``a`` and the
    same yarn's point at the same crossing (contact id) in ``b``; 0 where they share none."""
    def keyed(snap):
        yarn = np.repeat(np.arange(len(snap.offsets) - 1), np.diff(snap.offsets))
        cid = np.asarray(snap.contact_id)
        at = np.nonzero(cid >= 0)[0]
        return cid[at] * (len(snap.offsets) - 1) + yarn[at], np.asarray(snap.points)[at]

    ka, pa = keyed(a)
    kb, pb = keyed(b)
    _, ia, ib = np.intersect1d(ka, kb, assume_unique=True, return_indices=True)
    return float(np.max(np.linalg.norm(pa[ia] - pb[ib], axis=1))) if len(ia) else 0.0


def _unit(v):
    n = float(np.linalg.norm(v))
    return v / n if n > 0.0 else np.zeros(3)
