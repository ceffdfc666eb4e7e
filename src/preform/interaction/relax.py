"""Force-density relaxation of one time step of the convergence zone (docs/theory.md §4).

What is solved
--------------
The same equations as the Newton reference (``interaction/frontal.py``, ``_kernels/frontal.
assemble``): at every crossing the pair balance of both yarns' segment tensions, the jamming
pushes and the mandrel wall; along every yarn the friction law at every crossing (the smoothed
Coulomb term ``g |s - s_old|``, written here with ``s`` the material coordinates (the state's
``material``), ``s_old`` the friction centres and ``g`` the friction bounds (``bound``), with the
bounds and top tensions ``f_top`` held, or, with
``relax(consistent=True)``, the bounds of the converged geometry itself); segments are
stiff tows ``f = EA (l - q) / q`` of material length ``q``; thickness offsets of the yarn points
(paper eq. 16). Only the wall differs: here it is an exact constraint (no crossing behind its
tangent plane, a non-negative wall force), where Newton has a penalty of 1e7 N/m (its crossings
sit up to f / 1e7 m behind the plane: ~1 um).

How (one iteration)
-------------------
1. *Material sweep* (``_kernels.relax.material_sweep``): for the current positions, every yarn's
   material coordinates solve its friction law exactly (a convex chain problem in the material
   alone: tridiagonal Newton, O(crossings of the yarn)); a sticking yarn keeps its material at the
   crossing within the friction creep, a slipping one sits on its discrete Capstan bound. This
   gives the tensions and the net force ``F(C)`` on every crossing.
2. *Position update* ``C <- C + K^-1 F(C)`` with a preconditioner ``K`` (``preconditioner``; the
   fixed point ``F = 0`` does not depend on it):

   - ``"block"`` (the default): the lattice's geometric stiffness in 3 x 3 blocks per pair of
     crossings, ``sum_seg (f/l) (I - d d^T)`` (a taut yarn resists a crossing moving across
     it, not along it) plus jamming's ``k d d^T`` and ``block_reg f / l I`` that keeps ``K``
     definite (``block_values``). It is factorised once per solve at the start tensions (block
     LDL^T, ``ldl_numeric3``, in a nested-dissection order of the band of crossings around the
     axis, ``band_dissection``; O(m^1.5) work for the factor, O(m log m) fill, so per
     iteration the solve is nearly linear), and anew, with Anderson's history cleared, where
     the set of jammed segments changed (the jamming stiffness enters or leaves ``K``). A
     crossing resting on the wall moves in its tangent plane (its rows projected, ``P K P + n
     n^T``).
   - ``"scalar"``: the force-density Laplacian (Schek 1974): with ``w = f / l`` per segment,
     node balance ``sum_j w_cj (P_j - P_c) = 0`` is linear in the positions, one scalar weighted
     Laplacian ``L`` shared by x, y and z (``w`` floored where a segment is nearly slack, the
     jamming stiffness added), factorised every ``refactor_every`` iterations (QDLDL,
     Apache-2.0); then ``smoothing`` block-Jacobi corrections (``block_jacobi``), each after a
     new material sweep: each crossing moves by ``H_c^-1 F_c`` with its own 3 x 3 stiffness,
     because ``L`` gives a segment the stiffness ``f / l`` along itself too. The corrections stop
     for the rest of a solve that makes no progress with them (``stall_iterations``).

   - ``"full"`` (behind a guide ring, ``ring_preconditioner``): the Hessian of the energy in
     the positions and the materials together, 5 x 5 blocks per pair of crossings in the same
     pattern and order (``full_values``, ``ldl_numeric5``), solved with the right-hand side
     ``(F, 0)`` (the material equations hold after every sweep): its Schur complement on the
     positions is the exact stiffness ``-dF/dC`` of the map with the materials swept, so the
     update is a Newton step on the positions. ``"block"`` leaves out the yarns' axial
     stiffness, none where a yarn slides (its tension is set by the top tension and the
     friction bounds), but ``EA / q`` in series with the friction creep stiffness ``g /
     eps_f`` where it sticks: behind a ring the new crossings form a few millimetres below
     the ring points, at their friction centres, with large bounds (the yarns bend sharply
     there), and hold their yarns along themselves at ~1e4 N/m against a geometric stiffness
     of ~1e2 N/m, where the yarns cross at low angles; the block iteration's linearised map
     has a spectral radius of 15 there (``docs/decisions.md``). Its elimination order is
     METIS's nested dissection of the lattice (``ring_order``: half the factorisation's work
     of ``band_dissection``'s). Factorised at the start, anew where a segment newly jams (one
     that left the jam keeps its k_jam in K: stiffer than the map there, the update falls
     short rather than beyond), after a step the line search shortened (item 5) and after
     ``ring_refactor_stall`` iterations without a new lowest residual since the last
     factorisation: each factorisation is a Newton refresh of K. A step without a new lowest
     residual in ``ring_stall`` iterations is Newton's.

   ``"block"`` needs 10-17 iterations on case A steps where ``"scalar"`` needs 33-44 of three
   sweeps each. Where it stalls (``block_stall`` iterations without a new lowest residual: steps
   with friction 0.5 and jammed crossings, the first rows of a run) the step is not converged
   (``solve_zone`` gives it to Newton) or, with ``scalar_retry``, solved again from its start
   with ``"scalar"``.
3. *Wall active set*: a crossing resting on its tangent plane moves in it (block) or is a
   Dirichlet row of ``L`` (scalar); its own balance, ``wall_update`` (the point its segments'
   force densities put it at), decides whether it stays: it leaves the set when that point lies
   more than ``wall_release`` in front, the wall taking the normal force otherwise; a free
   crossing that lands more than that behind its plane is projected onto it and joins.
4. *Anderson mixing* of the positions over the last ``anderson_depth`` iterates: the paper's
   eq. 17 (the minimum-residual combination of two iterates) in its general form. History is
   cleared when the active set changes (the map changes).
5. *Line search* (``"full"`` only, ``ring_line_search``): the iterate is judged by the reduced
   energy ``E_r(C) = E(C, s(C))``, the step energy with the materials swept for the positions
   (``reduced_energy``; without the wall, which the active set keeps exactly). Its gradient is
   ``-F`` (the materials are stationary), so the update ``delta = K^-1 F`` with K positive
   definite descends it: ``dE_r = -F . delta < 0``. The Anderson-mixed iterate is taken where
   it does not raise ``E_r`` (to its round-off, 1e-13 |E_r|); otherwise Anderson's history is
   cleared and ``delta`` is backtracked to Armijo's ``E_r(C + t delta) <= E_r(C) + 1e-4 t dE_r``
   (``ring_halvings`` halvings at most, the last taken as it is). The sweep of the accepted
   trial is the next iteration's. Without it the iteration cycles where the jamming law's
   kink (``l = width``) or a stale K sends a Newton step beyond the minimum and back: 18 % of
   the bent tube's steps stalled and went to Newton; with it 0-4 of 1200 do.

Convergence: the largest relative imbalance over the crossings (``wall_residual``: force over the
sum of the four tensions; at a wall crossing its tangential part and any pull away from the
wall) below ``tol``; the material equations hold to ``material_tol`` at every iterate. With
``"block"`` and ``"scalar"`` the iteration is not monotone in any merit; with ``"full"`` and
its line search it is monotone in the reduced energy ``E_r`` (up to its round-off, and except
where ``ring_halvings`` halvings found no decrease), the merit the iteration is judged by. A step that
does not reach ``tol`` in ``max_iter`` (some steps where crossings must slide far stall) is
solved by the Newton reference (``solve_zone``, ``newton_fallback``) or raises
:class:`SimulationError`.

Behind a guide ring ``solve_zone`` also gives the frontal iterations of the bounds that a
snapshot asks for (its ring passes and its final solve) to the relaxation with consistent
bounds (``ring_frontal``), and without a ring a snapshot's final solve (``snapshot_frontal``);
the final one is finished by Newton's frontal iteration from that result, whose wall penalty
puts the wall force into the written files (``frontal.point_forces``).

Code: this module holds the settings, the outer loops (``relax``: consistent bounds and the
retries; ``solve_zone`` and ``_ring_frontal``: the zone solver's modes) and the iteration
(``_relax_held``); each preconditioner is a class of ``preconditioners.py`` behind its
``Preconditioner`` protocol, with the matrices' structures and Anderson's mixer; the kernels
are ``_kernels/relax.py`` (sweep, forces, wall), ``_kernels/stiffness.py`` (the matrices'
values) and ``_kernels/ldl.py`` (their block LDL^T and orders), taking the arrays packed in
``_kernels/zone.py``'s NamedTuples.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from .._kernels import relax as RK
from .._kernels import zone as KZ
from .._kernels.zone import Lattice
from ..errors import SimulationError
from . import preconditioners as PC
from .contact import bound_change, bound_scale
from .settings import DEFAULT, InteractionSettings, RelaxSettings


@dataclass
class RelaxResult:
    """pos (m, 3), s (m, 2), tension (m, 2) N, bounds (m, 2) N (the newest: of the converged
    geometry), psi (m, 2) Psi / (f_int + f_ext), f_top (2n,) N, wall_force (m,) N (>= 0),
    active (m,) bool (resting on the wall); iterations, residual, history (residual per
    iteration), bound_change (last relative change of the bounds; consistent bounds only),
    set_changes (changes of the wall's active set), sweep_stats (Newton steps and energy
    evaluations of the yarns' material problems, summed over yarns),
    times (s per part: setup (order, pattern, symbolic analysis), sweep (segments and material
    sweep), forces (net forces, residual, friction bounds), factor, solve, wall, smooth
    (block-Jacobi corrections), mix (Anderson)); fallback_scalar: the block preconditioner
    stalled and the scalar one solved the step."""

    pos: np.ndarray
    s: np.ndarray
    tension: np.ndarray
    bounds: np.ndarray
    psi: np.ndarray
    f_top: np.ndarray
    wall_force: np.ndarray
    active: np.ndarray
    iterations: int
    residual: float
    history: np.ndarray
    bound_change: float = 0.0
    converged: bool = True
    times: dict = field(default_factory=dict)
    set_changes: int = 0
    sweep_stats: tuple = (0, 0)
    #: the block preconditioner stalled and the scalar one solved the step
    fallback_scalar: bool = False
    #: factorisations of the preconditioner
    factorisations: int = 0
    #: behind a guide ring, the posed iteration (``frontal.PosedIteration``; None: none)
    posed: object = None


def relax(lat: Lattice, pos, s, s_fell, s_old, fell, top, f_top, bounds, *, f_spool, friction, h,
          width, plane=None, settings: RelaxSettings = DEFAULT.relax,
          model: InteractionSettings = DEFAULT, top_tensions=None, fresh=None, consistent=False,
          tol=None, bound_iterations=None, friction_tol=None):
    """Solve one step of the zone (module docstring) from the start ``pos`` (m, 3), ``s`` (m, 2)
    (not modified). s_fell (2n,) material of the fell points (anchored), s_old (m, 2) the friction
    centres, fell, top (2n, 3) m, f_top (2n,) N top tensions, bounds (m, 2) N friction bounds
    (held unless ``consistent``), f_spool N, friction the crossings' law
    (``contact.CrossingFriction``), h m half the yarn thickness,
    width m (jamming; 0 none), plane (m, 6) or None: per crossing a point and the outward unit
    normal of the mandrel's tangent plane. model: the model's constants (the Newton reference's
    ``InteractionSettings``). top_tensions: with consistent bounds, a function of
    the positions (m, 3) giving the top tensions (2n,) (the guide ring's Capstan); None: f_top
    held. fresh: (m, 2) bool, the bounds a step behind a guide ring takes of its converged
    geometry (``_posed_bounds``); given, a step with held bounds is solved again with them and
    the top tensions taken of its converged geometry (``_posed_fixed_point``). tol: the balance
    tolerance (relative residual; None: the Newton reference's
    ``NewtonSettings.balance_tolerance``, so that both solve to the same). Returns a
    :class:`RelaxResult` (``converged`` False if ``tol`` was not reached).

    Consistent bounds (``consistent``; else the bounds are held): an outer fixed point, as
    Newton's frontal loop (``frontal.solve_zone``): the step is solved with the bounds held, the
    bounds (and ring top tensions) are taken anew from its converged geometry and tensions, and
    the step is solved again from there, at most ``bound_iterations`` times (None: a step's
    frontal iterations after the first, ``FrontalSettings.max_iterations - 1``), until they
    change by less than ``friction_tol`` relative to the tensions (None:
    ``FrontalSettings.friction_tolerance``)."""
    fr = model.frontal
    tol = model.newton.balance_tolerance if tol is None else float(tol)
    bound_iterations = fr.max_iterations - 1 if bound_iterations is None else int(bound_iterations)
    friction_tol = fr.friction_tolerance if friction_tol is None else float(friction_tol)
    kw = dict(f_spool=f_spool, friction=friction, h=h, width=width, plane=plane,
              settings=settings, model=model, tol=tol)
    posed_loop = fresh is not None and not consistent
    # the posed iteration's solves start from K as the last one left it
    carry = PC.FactorCarry() if posed_loop else None
    res = _held_with_fallback(lat, pos, s, s_fell, s_old, fell, top, f_top, bounds, carry=carry,
                              **kw)
    m = lat.m
    if posed_loop and res.converged and m:
        res, bounds, res.posed = _posed_fixed_point(lat, res, s_fell, s_old, fell, top,
                                                    bounds, fresh, top_tensions, kw, carry)
    if not consistent or not res.converged:
        if res.converged and m:
            # bounds held at the last step's (lagged): how far they are from those of the
            # converged geometry, the change Newton's frontal loop reports after its one
            # iteration (history.csv's residual)
            res.bound_change = _lag_change(lat, res, bounds, top_tensions, f_top,
                                           model.frontal.change_scale_floor)[0]
        return res
    iterations, history, times = res.iterations, [res.history], dict(res.times)
    factorisations = res.factorisations
    change = np.inf
    for _ in range(bound_iterations):
        change, f_top = (_lag_change(lat, res, bounds, top_tensions, f_top,
                                     model.frontal.change_scale_floor) if m else (0.0, f_top))
        if change < friction_tol:
            break
        bounds = res.bounds
        res = _held_with_fallback(lat, res.pos, res.s, s_fell, s_old, fell, top, f_top, bounds,
                                  **kw)
        iterations += res.iterations
        factorisations += res.factorisations
        history.append(res.history)
        for key, v in res.times.items():
            times[key] += v
        if not res.converged:
            break
    res.iterations, res.history, res.times = iterations, np.concatenate(history), times
    res.factorisations = factorisations
    res.bound_change = change
    res.converged = res.converged and change < friction_tol
    return res


def _posed_fixed_point(lat, res, s_fell, s_old, fell, top, bounds, fresh, top_tensions, kw,
                       carry=None):
    """The step solved again with what has no state of its own taken of its converged
    geometry (``FrontalSettings.posed_iterations``, ``frontal.PosedIteration``): the top
    tensions behind a guide ring (``top_tensions`` of the result's positions: Capstan, eq. 9)
    and the friction bounds of ``fresh`` (m, 2) bool (every crossing's with
    ``posed_all_bounds``, else the new crossings'), the other bounds held, until these change
    by less than ``posed_tolerance`` relative to the tensions or after ``posed_iterations``
    solves; each solve starts from the last one's result. The iterations, histories and times
    of all are summed into the returned result (the last one; not converged where a solve did
    not converge, which gives the step to Newton), with the iteration (``posed``); each solve
    starts from the last one's factorisation of K (``carry``, ``RelaxSettings.reuse_factor``).
    Returns (result, the bounds it held, the iteration)."""
    from .frontal import PosedIteration
    fr = kw["model"].frontal
    iterations, history, times = res.iterations, [res.history], dict(res.times)
    factorisations = res.factorisations
    held_top = res.f_top
    pi = PosedIteration(fr, fresh, bound_scale(lat.up, lat.yarn, res.tension, res.f_top,
                                               fr.change_scale_floor), res.f_top)
    rs, tol = kw["settings"], kw["tol"]
    loose = rs.posed_inexact > 0.0      # re-solves to a share of the change, then finished
    solved_to = tol
    while True:
        bound1 = np.where(fresh, res.bounds, bounds)
        change = _bound_change(lat, bound1, bounds, res.tension, res.f_top,
                               fr.change_scale_floor)
        f_top1 = res.f_top
        if top_tensions is not None:
            f_top1 = np.asarray(top_tensions(res.pos), dtype=float)
            change = max(change, float(np.max(np.abs(f_top1 - res.f_top) / f_top1)))
        x = pi.step(bounds, held_top, bound1, f_top1, change)
        if x is None and solved_to > tol:
            # the iteration stops at a solve short of the balance tolerance: that solve is
            # finished (the same held bounds, from its result) and its change measured again,
            # which the iteration then judges in place of the loose one
            pi.changes.pop()
            x, loose = (bounds, held_top), False
        elif x is None:
            break
        solved_to = max(tol, rs.posed_inexact * change) if loose else tol
        nxt = _held_with_fallback(lat, res.pos, res.s, s_fell, s_old, fell, top, x[1], x[0],
                                  carry=carry, **dict(kw, tol=solved_to))
        iterations += nxt.iterations
        factorisations += nxt.factorisations
        history.append(nxt.history)
        for key, v in nxt.times.items():
            times[key] = times.get(key, 0.0) + v
        res = nxt
        if not nxt.converged:
            # not converged: the step is Newton's (``solve_zone``'s fallback)
            break
        bounds, held_top = x
    res.iterations, res.history, res.times = iterations, np.concatenate(history), times
    res.factorisations = factorisations
    return res, bounds, pi


def _held_with_fallback(lat, pos, s, s_fell, s_old, fell, top, f_top, bounds, *, settings,
                        carry=None, **kw):
    """``_relax_held``; where the block preconditioner stalls (no new lowest residual in
    ``block_stall`` iterations: steps with friction 0.5 and jammed crossings, where it moves
    the crossings too far) and ``full_retry`` (or ``scalar_retry``), the step again from the
    same start with the "full" (or the scalar) one, the iterations and times of both counted
    (``fallback_scalar`` set for either)."""
    res = _relax_held(lat, pos, s, s_fell, s_old, fell, top, f_top, bounds, settings=settings,
                      carry=carry, **kw)
    retry = "full" if settings.full_retry else "scalar" if settings.scalar_retry else None
    if res.converged or settings.preconditioner != "block" or retry is None:
        return res
    again = _relax_held(lat, pos, s, s_fell, s_old, fell, top, f_top, bounds,
                        settings=dataclasses.replace(settings, preconditioner=retry), **kw)
    again.iterations += res.iterations
    again.history = np.concatenate([res.history, again.history])
    for key, v in res.times.items():
        again.times[key] += v
    again.set_changes += res.set_changes
    again.factorisations += res.factorisations
    again.sweep_stats = tuple(a + b for a, b in zip(again.sweep_stats, res.sweep_stats))
    again.fallback_scalar = True
    return again


def _lag_change(lat, res, held, top_tensions, f_top, floor=DEFAULT.frontal.change_scale_floor):
    """(change, top tensions): the relative change from the held bounds ``held`` and top
    tensions ``res.f_top`` to those of the converged geometry of ``res`` (:func:`_bound_change`;
    the top tensions' relative to themselves, behind a guide ring, where ``top_tensions`` gives
    them; else ``f_top`` is returned as it is)."""
    change = _bound_change(lat, res.bounds, held, res.tension, res.f_top, floor)
    if top_tensions is not None:
        f_top = np.asarray(top_tensions(res.pos), dtype=float)
        change = max(change, float(np.max(np.abs(f_top - res.f_top) / f_top)))
    return change, f_top


def _bound_change(lat, new, old, tension, f_top, floor=DEFAULT.frontal.change_scale_floor):
    """Largest change of the bounds relative to f_int + f_ext of their crossing and yarn, at
    least ``floor`` times the yarn's top tension (``contact.bound_change``)."""
    return bound_change(lat.up, lat.yarn, tension, f_top, new, old, floor)


def _relax_held(lat: Lattice, pos, s, s_fell, s_old, fell, top, f_top, bounds, *, f_spool,
                friction, h, width, plane, settings, model, tol, carry=None):
    """The iteration with the bounds and top tensions held (``relax``), to the relative
    residual ``tol``: sweep, forces and residual, then the preconditioner's update, wall step
    and mixing (``preconditioners``). ``carry``: a ``preconditioners.FactorCarry``; the solve
    starts from its factorisation where it is valid (``RelaxSettings.reuse_factor``) and
    leaves its own last one in it."""
    st = settings
    e = model.energy
    m, ny = lat.m, lat.n_yarns
    EA = float(f_spool) / e.tow_strain
    l_jam = float(width)
    k_jam = e.jam_force * f_spool / max(l_jam, 1e-300)
    times = dict(setup=0.0, sweep=0.0, forces=0.0, factor=0.0, solve=0.0, wall=0.0, smooth=0.0,
                 mix=0.0)
    t_setup = time.perf_counter()
    pos = np.array(pos, dtype=float)
    s = np.array(s, dtype=float)
    f_top = np.array(f_top, dtype=float)
    g = np.array(bounds, dtype=float)
    if plane is None:
        plane = np.zeros((m, 6))
        plane[:, 2] = -1e300
        plane[:, 5] = 1.0
        has_wall = False
    else:
        plane = np.ascontiguousarray(plane[:m], dtype=float)
        has_wall = True
    x = PC.Iterate(
        lat=lat, law=KZ.law(EA, e.compression, model.frontal.friction_creep, e.kappa0, h,
                            e.length_smoothing, e.top_smoothing2, l_jam, k_jam,
                            e.geometric_floor),
        prob=KZ.problem(fell, top, s_fell, s_old, g, f_top), settings=st, pos=pos, s=s,
        tension=np.empty((m, 2)), seg=KZ.segments(m, ny), fo=KZ.forces(m, ny), plane=plane,
        active=np.zeros(m, dtype=np.bool_), has_wall=has_wall,
        chain=np.empty(max(m, 1), dtype=np.int64), work=np.empty((max(m, 1), 6)),
        stats=np.zeros(2, dtype=np.int64), l_prev=np.empty((m, 2)), wall_force=np.zeros(m),
        dist=np.empty(m))
    if has_wall:
        dist = x.dist
        RK.wall_distance(m, pos, plane, dist)
        x.active[:] = dist < st.wall_contact
        behind = x.active & (dist < 0.0)
        pos[behind] -= dist[behind, None] * plane[behind, 3:]
    pc = PC.make(st.preconditioner, x)
    delta = np.empty((m, 3))
    new = np.empty((m, 3))
    times["setup"] = time.perf_counter() - t_setup
    mixer = PC.Anderson(st.anderson_depth)
    history = []
    residual = np.inf
    it = 0
    converged = False
    factored_active = None
    best, best_it = np.inf, 0
    best_f, best_f_it = np.inf, 0
    factorisations = 0
    blk = getattr(pc, "blk", None)
    if carry is not None and st.reuse_factor and carry.valid_for(blk, x.active):
        # the last solve's K: the same lattice, active set and (as far as K holds it) jam
        factored_active = carry.active.copy()
        pc.factored_jam = carry.jam.copy()
        pc.jammed[:] = carry.jam
    while True:
        t0 = time.perf_counter()
        if not pc.take_sweep(x):
            RK.sweep(x.klat, x.klaw, x.kprob, pos, s, x.kseg, x.tension, x.chain, x.work,
                     x.stats, x.l_prev, x.predict, pc.predict, st.material_tol,
                     st.material_newton)
        x.predict = pc.predict
        t1 = time.perf_counter()
        residual = RK.forces_residual(x.klat, x.klaw, x.kprob, x.kseg, x.tension, plane,
                                      x.active, st.wall_release, x.kfo)
        history.append(residual)
        pc.measure(x)
        t2 = time.perf_counter()
        times["sweep"] += t1 - t0
        times["forces"] += t2 - t1
        if residual < tol:
            converged = True
            break
        # safeguard: the block-Jacobi corrections can undo the force-density move where the
        # local model fails (a jammed crossing of the 48-carrier, friction 0.5 step: a fixed
        # point of the composite map at residual 6e-2); without progress the iteration goes on
        # without them
        if residual < best_f:
            best_f, best_f_it = residual, it
        if residual < best:
            best, best_it = residual, it
        elif pc.smoothing and it - best_it > st.stall_iterations:
            pc.smoothing = 0
            mixer.reset()
            best_it = it
        if it >= st.max_iter or (pc.stall is not None and it - best_it > pc.stall):
            break
        it += 1
        due = pc.due(x, it, best_f_it, mixer)
        if due or factored_active is None or not RK.same_flags(m, x.active, factored_active):
            factorisations += 1
            best_f, best_f_it = np.inf, it - 1
            factored = pc.factor(x)
            factored_active = x.active.copy()
            if not factored:
                factored_active = None      # no factor to hand on
                break
        t3 = time.perf_counter()
        pc.update(x, delta)
        t4 = time.perf_counter()
        changed = pc.move(x, delta, new)
        t5 = time.perf_counter()
        times["wall"] += t5 - t4
        pc.smooth(x, new, delta)
        t6 = time.perf_counter()
        times["smooth"] += t6 - t5
        t5 = t6
        if changed:
            mixer.reset()
        pc.mix(x, mixer, new)
        # a combination of iterates on the planes stays on them; one that reaches behind a
        # plane (Anderson's weights may be negative) is projected onto it and rests there
        if has_wall and RK.wall_project(m, pos, plane, x.active, st.wall_release):
            mixer.reset()
            x.set_changes += 1
        pc.projected(x)
        times["factor"] += t3 - t2
        times["solve"] += t4 - t3
        times["mix"] += time.perf_counter() - t5
    if carry is not None and blk is not None and factored_active is not None:
        carry.keep(blk, factored_active, pc.factored_jam)
    # the friction bounds of the last (converged) geometry, for the next step
    seg, tension, active, force = x.seg, x.tension, x.active, x.fo.force
    g_new = np.empty((m, 2))
    psi = np.zeros((m, 2))
    RK.friction_bounds(m, ny, lat.yarn, lat.up, seg.d_below, seg.l_below, seg.d_top, tension,
                       x.prob.f_top, *friction.kernel_arguments(lat.yarn), g_new, psi)
    # the wall's push at the converged state: the normal pull of the yarns at resting crossings
    fn = -np.einsum("ij,ij->i", force, plane[:, 3:]) if m else np.zeros(0)
    wall_force = np.where(active, np.maximum(fn, 0.0), 0.0)
    return RelaxResult(pos=pos, s=s, tension=tension, bounds=g_new.copy(), psi=psi.copy(),
                       f_top=x.prob.f_top, wall_force=wall_force, active=active.copy(),
                       iterations=it, residual=float(residual), history=np.array(history),
                       converged=converged, times=times, set_changes=x.set_changes,
                       factorisations=factorisations,
                       sweep_stats=(int(x.stats[0]), int(x.stats[1])))


def _accept(state, res, centres, fr):
    """Write a relaxation's result into the zone's state (first m rows): positions, material,
    tensions, bounds; the slip states (material slid beyond ``fr.slip_report`` from the friction
    centres) and the friction offsets (that slide, capped at ``fr.memory_cap``)."""
    m = state.m
    state.pos[:m] = res.pos
    state.material[:m] = res.s
    state.tension[:m] = res.tension
    state.bound[:m] = res.bounds
    slide = res.s - centres
    state.slip[:m] = np.where(np.abs(slide) > fr.slip_report, np.sign(slide), 0)
    state.offset[:m] = np.clip(slide, -fr.memory_cap, fr.memory_cap)


def _ring_frontal(state, bc, settings, rs, where, centre, tol, friction_tol, max_iter,
                  finish, start=None):
    """``solve_zone``'s frontal iteration of a snapshot (``RelaxSettings.ring_frontal`` behind a
    guide ring, ``snapshot_frontal`` without one; the ring preconditioner in both):
    ``max_iter`` solves at most (Newton's frontal iterations), the bounds and ring top tensions
    taken anew from each converged geometry until they change by less than ``friction_tol``
    (``relax`` with consistent bounds). With ``finish`` (a snapshot's final solve, which
    gives ``friction_tol``) Newton's frontal iteration (``frontal.solve_zone_inplace``)
    finishes from that state: its wall penalty sets the crossings on the mandrel the micrometre behind their
    planes that ``frontal.point_forces`` writes as the wall force, and it takes one iteration
    where the bounds have converged. Otherwise the relaxation's state is the result, the
    newest bounds (of its converged geometry) lagged, as Newton's after ``max_iter``
    iterations. None (state untouched) where a relaxation did not converge: then Newton's
    alone. ``start``: the initial iterate (``solve_zone``)."""
    from . import frontal
    fr = settings.frontal
    friction_tol = fr.friction_tolerance if friction_tol is None else friction_tol
    max_iter = fr.max_iterations if max_iter is None else max_iter
    m = state.m
    centres = np.array((frontal.friction_centres(state) if centre is None else centre)[:m],
                       dtype=float)
    bounds, ft = start_bounds(state, bc, settings)
    if m == 0:
        return None
    rsc = dataclasses.replace(rs, preconditioner=rs.ring_preconditioner)
    balance = settings.newton.balance_tolerance if tol is None else float(tol)
    pos0, s0 = (state.pos, state.material) if start is None else start
    res = relax(lattice_of(state), pos0[:m], s0[:m], state.material_fell,
                centres, bc.fell, bc.top, ft, bounds, f_spool=bc.f_spool,
                friction=bc.friction, h=bc.h, width=bc.width, plane=bc.plane,
                settings=rsc, model=settings,
                top_tensions=ring_top_tensions(state, bc), consistent=True, tol=balance,
                bound_iterations=max_iter - 1, friction_tol=friction_tol)
    if not res.residual < balance:
        return None
    _accept(state, res, centres, fr)
    if finish:
        return frontal.solve_zone_inplace(state, bc, settings=settings, tol=tol,
                                          friction_tol=friction_tol, max_iter=max_iter,
                                          where=where, centre=centres, mode="final")
    return frontal.SolveReport(res.iterations, max(res.residual, res.bound_change),
                               res.history, res.f_top.copy(), lagged=not res.converged)


# -- adapter from the zone's state ------------------------------------------------------------

def lattice_of(state) -> Lattice:
    """The :class:`Lattice` of a ``ZoneState`` (views of its first m rows)."""
    m = state.m
    return Lattice(m=m, n_yarns=state.n_yarns, yarn=state.yarn[:m], low=state.low[:m],
                   up=state.up[:m], over=state.over[:m], normal=state.normal[:m],
                   lowest=state.lowest, highest=state.highest)


def start_bounds(state, bc, model: InteractionSettings = DEFAULT):
    """(bounds (m, 2), f_top (2n,)) of a step's problem, as ``frontal.solve_zone_inplace`` takes
    them from the posed ``state``: each crossing's bound of the last step, a new crossing's of
    the posed geometry with its posed tensions; the top tensions of the posed geometry (guide
    ring: Capstan). Not of the solver's initial iterate (``solve_zone``'s ``start``)."""
    from .._kernels import frontal as FK
    m, ny = state.m, state.n_yarns
    lat = lattice_of(state)
    f_top = np.empty(ny)
    FK.top_tensions(ny, state.highest, state.pos, state.normal, state.over, bc.fell, bc.top,
                    bc.spool, bc.h, bc.spool_tensions(), bc.ring_frictions(), bc.has_ring,
                    *bc.capstan_arguments(), f_top)
    d_below = np.empty((m, 2, 3))
    l_below = np.empty((m, 2))
    d_top = np.empty((ny, 3))
    l_top = np.empty(ny)
    e = model.energy
    RK.segment_vectors(m, ny, lat.yarn, state.pos[:m], lat.normal, lat.over, lat.low,
                       lat.highest, np.ascontiguousarray(bc.fell, dtype=float),
                       np.ascontiguousarray(bc.top, dtype=float), bc.h, e.length_smoothing,
                       e.top_smoothing2, d_below, l_below, d_top, l_top)
    g0 = np.empty((m, 2))
    psi = np.empty((m, 2))
    RK.friction_bounds(m, ny, lat.yarn, lat.up, d_below, l_below, d_top,
                       np.ascontiguousarray(state.tension[:m]), f_top,
                       *bc.friction.kernel_arguments(lat.yarn), g0, psi)
    old = state.bound[:m]
    return np.where(np.isfinite(old), old, g0), f_top


def _posed_bounds(state, settings):
    """(m, 2) bool: the bounds a time step behind a guide ring takes of its converged geometry
    (``FrontalSettings.posed_all_bounds``: all, else the new crossings')."""
    fresh = ~np.isfinite(state.bound[:state.m])
    return np.ones_like(fresh) if settings.frontal.posed_all_bounds else fresh


def ring_top_tensions(state, bc):
    """Function of the positions giving the top tensions (guide ring: Capstan, eq. 9), for
    consistent bounds; None without a ring (the spool tension)."""
    if not bc.has_ring:
        return None
    from .._kernels import frontal as FK
    ny = state.n_yarns
    fell = np.ascontiguousarray(bc.fell, dtype=float)
    capstan, f_hold = bc.capstan_arguments()

    def f(pos):
        out = np.empty(ny)
        FK.top_tensions(ny, state.highest, pos, state.normal, state.over, fell, bc.top,
                        bc.spool, bc.h, bc.spool_tensions(), bc.ring_frictions(), bc.has_ring,
                        capstan, f_hold, out)
        return out
    return f


def solve_zone(state, bc, *, settings: InteractionSettings = DEFAULT, where="", centre=None,
               tol=None, friction_tol=None, max_iter=None,
               relax_settings: RelaxSettings | None = None, start=None, mode="step"):
    """The zone solver with ``frontal.solve_zone_inplace``'s contract (``InteractionZone``'s
    ``solve_zone``; ``[model] solver = "relax"``): brings ``state`` to balance in place
    (positions, material, tensions, friction bounds, slip states, friction offsets) and returns a
    ``frontal.SolveReport`` (iterations: relaxation iterations; ``f_top``: the top tensions).

    ``mode`` (``frontal.SOLVE_MODES``) says what the solve is for. A time step ("step") is one
    relaxation with the bounds held, as Newton's single frontal iteration per step; the bounds
    of the converged geometry go into ``state.bound`` for the next step. Behind a guide ring it
    is solved again with the top tensions and the bounds (``posed_all_bounds``: every
    crossing's, else the new crossings') of its converged geometry until they settle
    (``relax``'s ``fresh``, ``FrontalSettings.posed_iterations``, ``frontal.PosedIteration``),
    as Newton's step is. With ``FrontalSettings.max_iterations`` k > 1 it is up to k
    relaxations, each posed by the last one's converged state (its bounds and top tensions,
    the same friction centres), until the bounds change by less than ``friction_tolerance``,
    as Newton's frontal iteration. A snapshot's frontal iteration of the bounds ("pass": its
    ring passes of ``max_iter`` iterations; "final": its re-balance to ``friction_tol``, which
    must meet Psi to 1e-3) is Newton's (``frontal.solve_zone_inplace``; the relaxation's with
    consistent bounds first, ``_ring_frontal``: its passes and its final solve, behind a guide
    ring by ``ring_frontal``, without one by ``snapshot_frontal``), as is a step the
    relaxation does not converge on (``relax_settings.max_iter`` reached, or the block
    preconditioner stalled: the first rows of a run, friction-0.5 steps with jamming;
    ``newton_fallback``; the report's ``fallback`` is then set). The report's
    ``relax_iterations``: the relaxation's iterations of a time step, converged or not.
    Behind a guide ring the relaxation uses
    ``relax_settings.ring_preconditioner``. ``tol``: the balance tolerance (default
    ``NewtonSettings.balance_tolerance``, as Newton's). ``state`` as handed in is the step's posed state, which defines
    the problem (the bounds of new crossings and the top tensions, ``start_bounds``); ``start``
    ``(pos (m, 3), material (m, 2))`` is only the initial iterate (default: the posed one), as in
    ``frontal.solve_zone_inplace``.
    :class:`SimulationError` if it does not converge and the fallback is off."""
    from . import frontal
    rs = settings.relax if relax_settings is None else relax_settings
    if rs.full_retry is None:   # on where a step takes more than one frontal iteration
        rs = dataclasses.replace(rs, full_retry=settings.frontal.max_iterations > 1)
    frontal_iteration = frontal.check_mode(mode) != "step"
    by_relaxation = rs.ring_frontal if bc.has_ring else rs.snapshot_frontal
    if frontal_iteration and by_relaxation and not settings.frontal.consistent_bounds:
        report = _ring_frontal(state, bc, settings, rs, where, centre, tol, friction_tol,
                               max_iter, finish=mode == "final", start=start)
        if report is not None:
            return report
    if frontal_iteration or settings.frontal.consistent_bounds:
        # consistent bounds: the relaxation does not converge on steps whose crossings stick
        # (docs/decisions.md), Newton's frontal iteration solves them
        return frontal.solve_zone_inplace(state, bc, settings=settings, tol=tol,
                                          friction_tol=friction_tol, max_iter=max_iter,
                                          where=where, centre=centre, start=start, mode=mode)
    balance = settings.newton.balance_tolerance if tol is None else float(tol)
    if bc.has_ring and rs.ring_preconditioner != rs.preconditioner:
        rs = dataclasses.replace(rs, preconditioner=rs.ring_preconditioner)
    fr = settings.frontal
    # ``max_iterations`` frontal iterations a step, as Newton's: each relaxation posed by the
    # last one's converged state (its bounds and top tensions), until they change by less than
    # ``friction_tolerance``; not reaching it is the lag, not a failure
    passes = fr.max_iterations > 1
    m = state.m
    centres = np.array((frontal.friction_centres(state) if centre is None else centre)[:m],
                       dtype=float)
    bounds, ft = start_bounds(state, bc, settings)
    if m == 0:
        return frontal.SolveReport(0, 0.0, np.zeros(0), ft)
    pos0, s0 = (state.pos, state.material) if start is None else start
    res = relax(lattice_of(state), pos0[:m], s0[:m], state.material_fell,
                centres, bc.fell, bc.top, ft, bounds, f_spool=bc.f_spool, friction=bc.friction,
                h=bc.h, width=bc.width, plane=bc.plane, settings=rs, model=settings,
                top_tensions=ring_top_tensions(state, bc),
                fresh=_posed_bounds(state, settings) if bc.has_ring else None, consistent=passes,
                tol=balance)
    if not (res.residual < balance if passes else res.converged):
        if rs.newton_fallback:
            # the relaxation stalls on some steps (the first rows of a run; friction 0.5 with
            # jammed crossings): the Newton reference solves that step instead
            report = frontal.solve_zone_inplace(state, bc, settings=settings, where=where,
                                                centre=centres, start=start)
            return dataclasses.replace(report, relax_iterations=res.iterations, fallback=True,
                                       relax_times=res.times,
                                       factorisations=res.factorisations)
        raise SimulationError(
            f"the force-density solver of the yarn-interaction model did not converge {where}: "
            f"relative force imbalance (residual) {res.residual:.3g} after {res.iterations} "
            f"iterations (tolerance {balance:.3g}, {m} crossings)")
    _accept(state, res, centres, fr)
    posed = {} if res.posed is None else dict(posed_solves=res.posed.solves,
                                              posed_converged=res.posed.converged)
    return frontal.SolveReport(res.iterations, max(res.residual, res.bound_change),
                               res.history, res.f_top.copy(),
                               lagged=not (passes and res.converged),
                               relax_iterations=res.iterations, relax_times=res.times,
                               factorisations=res.factorisations, **posed)
