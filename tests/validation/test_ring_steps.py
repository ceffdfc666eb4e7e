"""Every time step behind a guide ring converged in the paper's sense: balance, the tension
below the ring Capstan of the step's own converged geometry (eq. 9), every crossing's friction
bound that of its converged geometry, no yarn slack; and the relaxation and Newton landing on
the same state from every step's posed state.

A case-B-like run (``simcase.case_b_like_config``: case B's ring 0.17 m and spool 0.85 m, 16
carriers, ring friction 0.17, yarn friction 0, 0.25 and 0.5, 20 mm eccentricity) stepped
through its start-up by the relaxation (the default solver) under default settings, each time
step's solve recorded (the zone's ``solve_zone`` hook); with yarn friction, each step's posed
state is also solved by the Newton reference, on a copy.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from support import naive_frontal
from preform.interaction import frontal, relax as R
from preform.interaction.model import InteractionZone
from preform.interaction.settings import DEFAULT
from preform.machine import Machine
from preform.reference import resolve_pose_lead
from preform.simulation import load_geometry
from preform.stepping import Stepper, take_up_speed
from support.simcase import case_b_like_config

MU_R = 0.17
#: steps of the run: the first crossings form below the ring by step ~60, rows are deposited
#: from step ~250 (the start-up, where runs behind a ring had failed to converge)
STEPS = 420
#: the history's residual on 99 % of the steps, and its largest value (the target the run's
#: verdict uses)
TARGET, CEILING = 1e-2, 0.1
#: a step whose posed iteration stopped at ``posed_iterations`` ends within this of its fixed
#: point (measured: 1.1e-4 to 3.2e-4 on 0-4 of ~390 steps at yarn friction 0.25 and 0.5); every
#: other step within ``posed_tolerance``
LIMIT = 1e-3


def _run(folder, mu, newton_too):
    cfg = case_b_like_config(folder, MU_R)
    cfg = dataclasses.replace(cfg, yarn=dataclasses.replace(cfg.yarn, friction=mu))
    mandrel, cl = load_geometry(cfg)
    cfg = resolve_pose_lead(cfg, mandrel, cl)
    machine = Machine.from_config(cfg.machine)
    steps = []

    def solve(st, bc, **kw):
        time_step = kw.get("mode", "step") == "step"
        fresh = set(st.uid[: st.m][~np.isfinite(st.bound[: st.m]).any(axis=1)].tolist())
        posed = st.copy() if time_step and newton_too else None
        report = R.solve_zone(st, bc, **kw)
        if time_step:
            newton = None
            if posed is not None:
                newton = (frontal.solve_zone_inplace(posed, bc, **kw), posed)
            steps.append((report, st.copy(), bc, fresh, newton))
        return report

    zone = InteractionZone(cfg, machine, mandrel, solve_zone=solve)
    s = Stepper(cfg, machine, mandrel, cl, zone)
    for _ in range(STEPS):
        s.advance(take_up_speed(cfg.process.take_up_speed, s.braided))
    return steps


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    cache = {}

    def get(mu):
        if mu not in cache:
            cache[mu] = _run(tmp_path_factory.mktemp(f"ring{mu}"), mu, newton_too=mu > 0.0)
        return cache[mu]

    return get


def _capstan(st, bc, k):
    """f_spool exp(-mu_r eta) of yarn k, eta its deflection at the ring point between the
    segment to its highest crossing's yarn point (or fell point) and the one to the spool."""
    c = st.highest[k]
    side = 0 if k < st.n_yarns // 2 else 1
    a = naive_frontal.yarn_point(st, c, side, bc.h) if c >= 0 else bc.fell[k]
    u_int = (a - bc.top[k]) / np.linalg.norm(a - bc.top[k])
    u_ext = (bc.spool[k] - bc.top[k]) / np.linalg.norm(bc.spool[k] - bc.top[k])
    eta = np.pi - np.arccos(np.clip(u_int @ u_ext, -1.0, 1.0))
    return bc.f_spool * np.exp(-bc.mu_r * eta)


def _with_crossings(steps):
    return [(rep, st) for rep, st, _, _, _ in steps if st.m]


@pytest.mark.parametrize("mu", [0.0, 0.25, 0.5])
def test_every_ring_step_is_converged_and_no_yarn_slack(mu, runs):
    steps = runs(mu)
    with_crossings = _with_crossings(steps)
    assert len(with_crossings) > STEPS // 2       # the run reached its braiding rows
    residual = np.array([rep.residual for rep, _ in with_crossings])
    assert np.all(np.isfinite(residual))
    assert np.percentile(residual, 99) <= TARGET and residual.max() <= CEILING
    # the posed iteration's own test: every step at posed_tolerance, but for those at its
    # limit, and those within LIMIT
    assert residual.max() < LIMIT
    assert all(rep.residual < DEFAULT.frontal.posed_tolerance
               for rep, _ in with_crossings if rep.posed_converged)
    # every yarn under tension: the least segment tension of any step, in spool tensions (a
    # slack segment has none; Capstan and friction take a yarn down to ~0.6 f_spool here)
    least = min(float(st.tension[: st.m].min()) for _, st in with_crossings)
    assert least > 0.3 * steps[0][2].f_spool


@pytest.mark.parametrize("mu", [0.0, 0.25, 0.5])
def test_tension_below_the_ring_is_capstan_of_the_converged_geometry(mu, runs):
    """Eq. 9 on every step's result: the top tension the solve balanced with is f_spool
    exp(-mu_r eta) of the deflection eta at the ring point of the converged crossings, to the
    step's own residual (below ``posed_tolerance`` where the posed iteration converged)."""
    worst = 0.0
    for rep, st, bc, _, _ in runs(mu):
        expect = np.array([_capstan(st, bc, k) for k in range(st.n_yarns)])
        off = float(np.max(np.abs(rep.f_top - expect) / expect))
        # the iteration measures the change in the top tensions relative to the new ones, as
        # here; the residual is the largest such change of the step's last solve
        assert off <= max(rep.residual, 1e-12) * (1.0 + 1e-6) + 1e-12
        worst = max(worst, off)
    assert worst < LIMIT
    # and the Capstan factor matters here: it is not the spool tension
    assert np.max(np.abs(rep.f_top - bc.f_spool)) > 0.1 * bc.f_spool


@pytest.mark.parametrize("mu", [0.25, 0.5])
def test_every_crossing_meets_its_converged_friction_bounds(mu, runs):
    """Every crossing's tension jump stays inside the friction cone of its converged geometry
    (``naive_frontal.bounds``), old and new crossings alike, to the step's residual."""
    worst, seen, fresh_seen = -np.inf, 0, 0
    for rep, st, bc, fresh, _ in runs(mu):
        if not st.m:
            continue
        g = naive_frontal.bounds(st, bc.fell, bc.top, st.tension[: st.m], rep.f_top, bc.h,
                                 bc.friction)
        step_worst = -np.inf
        for c in range(st.m):
            seen += 1
            fresh_seen += int(st.uid[c]) in fresh
            for side in range(2):
                u = st.up[c, side]
                above = st.tension[u, side] if u >= 0 else rep.f_top[st.yarn[c, side]]
                jump = abs(above - st.tension[c, side])
                # the scale of the iteration's change (``contact.bound_scale``)
                scale = max(above + st.tension[c, side],
                            DEFAULT.frontal.change_scale_floor * rep.f_top[st.yarn[c, side]])
                step_worst = max(step_worst, (jump - g[c, side]) / scale)
        # the jump exceeds the bound of the converged geometry by at most the change of the
        # bounds the step's last solve held (its residual) and the balance tolerance (1e-7 of
        # the four tensions, to a relative 1e-6 of the two here)
        assert step_worst <= rep.residual + 1e-6
        worst = max(worst, step_worst)
    assert seen > 5000 and fresh_seen > 50
    assert worst < LIMIT


@pytest.mark.parametrize("mu", [0.25, 0.5])
def test_relaxation_and_newton_land_on_the_same_state_every_step(mu, runs):
    """Each step's posed state solved by the relaxation and by Newton: the same crossings,
    positions and tensions to the solvers' tolerances, the same residuals (the posed
    iteration's fixed point is the model's, not a solver's)."""
    moved, dten, res_a, res_b, stopped = [], [], [], [], 0
    for ra, sa, bc, _, (rb, sb) in runs(mu):
        assert sa.m == sb.m
        if not sa.m:
            continue
        res_a.append(ra.residual)
        res_b.append(rb.residual)
        if not (ra.posed_converged and rb.posed_converged):
            # a step at the posed iteration's limit in either solver: the first rows of the
            # start-up (16 crossings), on which 1e-4 of the bounds moves crossings by
            # millimetres (measured 3.5 mm apart at 1.3e-4); held to LIMIT below
            stopped += 1
            continue
        moved.append(np.abs(sa.pos[: sa.m] - sb.pos[: sb.m]).max())
        dten.append(np.abs(sa.tension[: sa.m] - sb.tension[: sb.m]).max() / bc.f_spool)
    # measured 0 (mu 0.5) and 6 (mu 0.25) of ~390 steps
    assert stopped <= 0.02 * len(res_a)
    assert len(moved) > STEPS // 2
    # each solve stops at the balance tolerance (1e-7: micrometres along soft modes) and its
    # posed iteration once the bounds and top tensions change by less than posed_tolerance;
    # where the map contracts slowly (by rho ~0.93 a solve, the mode the mixing is for) that
    # leaves a result up to posed_tolerance / (1 - rho) from the fixed point, each solver on
    # its side of it: tensions within twice that of the spool tension (measured: median
    # 1.3e-5, max 2.1e-3 at yarn friction 0.5), positions within a millimetre (median 0.4 um,
    # max 0.64 mm)
    near = 2.0 * DEFAULT.frontal.posed_tolerance / (1.0 - 0.93)
    assert np.median(dten) < 0.01 * near and max(dten) < near
    assert np.median(moved) < 1e-5 and max(moved) < 1e-3
    assert max(res_b) < LIMIT and max(res_a) < LIMIT
