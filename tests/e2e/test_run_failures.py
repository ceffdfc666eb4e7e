"""Runs that cannot be converged or fault inside a step: they stop as ``failed`` with a message
naming the step, the figure and the cause, keep their results up to the last good step, and are
never called ``ok``; the kernels guard their divisions; the verdict's reasons each triggered by
a constructed history."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace as NS

import numpy as np
import pytest

import preform as pf
from preform.analysis import quality
from preform.analysis.derived import summary_dict
from preform._kernels import kinematic as K
from preform.errors import SimulationError
from preform.geometry import shapes
from preform.interaction import relax
from preform.interaction.model import InteractionZone
from preform.interaction.settings import DEFAULT
from preform.machine import Machine
from preform.reference import resolve_pose_lead
from preform.result import FLAG_SLIP
from preform.simulation import load_geometry
from preform.stepping import Stepper
from support.simcase import make_config, write_centerline, write_cylinder_case, write_stl


def _cylinder_interaction(tmp_path, braid=0.02):
    cfg = pf.load_config(write_cylinder_case(tmp_path, kind="interaction", friction=0.25,
                                             braid=braid, snapshots=2))
    return cfg


def test_a_step_that_cannot_converge_fails_the_run_and_keeps_its_results(tmp_path):
    """A residual limit no step can meet (1e-12, below the bounds' lag of every step with
    friction): the run stops at its first step with crossings, as ``failed``, the message naming
    the step, the residual and the likely cause; the steps before it are kept, and the verdict
    is suspect, saying the run did not finish."""
    cfg = _cylinder_interaction(tmp_path)
    strict = dataclasses.replace(DEFAULT, zone=dataclasses.replace(DEFAULT.zone,
                                                                   max_step_residual=1e-12))
    res = pf.simulate(cfg, progress=False, settings=pf.Settings(interaction=strict))
    assert res.status == "failed"
    assert "did not converge at step" in res.message and "residual" in res.message
    assert "likely cause:" in res.message
    assert res.steps >= 2                               # the tie and the steps before the failure
    assert np.all(np.isfinite(res.history["residual"]))
    q = quality.assess(res)
    assert q["verdict"] == "suspect"
    assert any(r.startswith("the run did not finish: status failed") for r in q["reasons"])
    s = summary_dict(res)
    assert s["status"] == "failed" and s["quality"]["verdict"] == "suspect"
    # the same run with the default limit goes on past that step
    ok = pf.simulate(cfg, progress=False)
    assert ok.status == "done" and ok.steps > res.steps


def test_a_slack_yarn_fails_the_step(tmp_path):
    """A slack limit above every tension the zone has (the spool tension itself: the top rows'
    tensions fall below it by Capstan friction): the step stops as a slack yarn, named."""
    cfg = _cylinder_interaction(tmp_path)
    slack = dataclasses.replace(DEFAULT, zone=dataclasses.replace(DEFAULT.zone, slack_tension=1.0))
    res = pf.simulate(cfg, progress=False, settings=pf.Settings(interaction=slack))
    assert res.status == "failed"
    assert "slack yarn" in res.message and "yarn" in res.message and "likely cause:" in res.message


def test_a_fault_inside_a_step_names_the_step_and_the_part(tmp_path):
    """A division by zero inside the zone's solve (a stand-in solver raising it at step 3) reaches
    the caller as a SimulationError naming the step and the part of the model, not as a bare
    ZeroDivisionError; simulate's caller would get status failed."""
    cfg = _cylinder_interaction(tmp_path)
    mandrel, cl = load_geometry(cfg)
    cfg = resolve_pose_lead(cfg, mandrel, cl)
    machine = Machine.from_config(cfg.machine)
    calls = [0]

    def solve(state, bc, **kw):
        calls[0] += 1
        if calls[0] == 3:
            raise ZeroDivisionError("division by zero")
        from preform.interaction.frontal import solve_zone_inplace
        return solve_zone_inplace(state, bc, **kw)

    s = Stepper(cfg, machine, mandrel, cl, InteractionZone(cfg, machine, mandrel, solve_zone=solve))
    with pytest.raises(SimulationError) as err:
        s.run(progress=False)
    msg = str(err.value)
    assert "step" in msg and "the solve of the zone's crossings" in msg
    assert "ZeroDivisionError: division by zero" in msg
    assert s.recording.n_rows == s.step + 1           # the record holds the last good step


def _degenerate_square():
    """A unit square in z = 0 with a face of no area on its diagonal: (0, 0), (1, 0), (1, 1),
    (0, 1) and (0.5, 0.5) on the diagonal; faces (0, 1, 4), (1, 2, 4), (0, 4, 2) (collinear) and
    (0, 2, 3): every edge shared by two faces."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]], dtype=float)
    T = np.array([[0, 1, 4], [1, 2, 4], [0, 4, 2], [0, 2, 3]], dtype=np.int64)
    FN = np.tile([0.0, 0.0, 1.0], (4, 1))
    CN = np.tile([0.0, 0.0, 1.0], (4, 3, 1))
    NB = -np.ones((4, 3), dtype=np.int64)
    edges = {}
    for f in range(4):
        for k in range(3):
            a, b = T[f, k], T[f, (k + 1) % 3]
            edges.setdefault(frozenset((a, b)), []).append((f, k))
    for pair in edges.values():
        if len(pair) == 2:
            (f, k), (g, j) = pair
            NB[f, k], NB[g, j] = g, f
    return V, T, FN, CN, NB


def test_the_walk_passes_a_face_of_no_area():
    """The walk from (0.2, 0.7) towards the projection of (0.9, 0.1) crosses the diagonal, where
    the face of no area lies (its barycentric basis has den = 0: a ZeroDivisionError in the
    kernel before its guard); it passes it and walks its budget (the plane is flat: no tangency)
    to the point 0.5 m along the straight line."""
    V, T, FN, CN, NB = _degenerate_square()
    # on its longer edge (corner 0 to corner 2) from corner 0
    assert K.barycentric(V, T, 2, 0.3, 0.3, 0.0) == pytest.approx((0.7, 0.0, 0.3))
    F = np.array([[0.2, 0.7, 0.0]])
    G = np.array([[0.9, 0.1, -1.0]])
    out, face = np.empty((1, 3)), np.empty(1, dtype=np.int64)
    status, walked = np.empty(1, dtype=np.int64), np.empty(1)
    K.advance_fell_points(V, T, FN, CN, NB, F, np.array([3]), G, G, np.ones(1, dtype=np.bool_),
                          0.05, 0.5, out, face, status, walked)
    d = np.array([0.7, -0.6]) / np.hypot(0.7, -0.6)
    assert status[0] == K.WALK_BUDGET and walked[0] == pytest.approx(0.5)
    assert out[0, :2] == pytest.approx(F[0, :2] + 0.5 * d, abs=1e-12)
    assert face[0] in (0, 1)                      # below the diagonal, past the face of no area


@pytest.mark.parametrize("mu, ring", [(0.0, (0.12, 0.0)), (0.25, None)])
def test_a_curved_millimetre_part_runs_or_fails_cleanly(tmp_path, mu, ring):
    """A bent rounded square in millimetres, the two variants that ended in a bare
    ZeroDivisionError: yarn friction 0 behind a guide ring, friction 0.25 without one. A short
    interaction run ends as done or failed (measured: done, 201 and 31 steps, 4 s and 1 s), with
    finite residuals, and is not ``ok`` when failed."""
    a = np.radians(35)
    s = np.linspace(0, 1, 60)
    path = [[0, 0, 0], [0, 0, 0.05]]
    for t in s[1:]:
        path.append([0.3 * (1 - np.cos(a * t)), 0, 0.05 + 0.3 * np.sin(a * t)])
    path = np.array(path)
    v, f = shapes.sweep(path, lambda _: shapes.rounded_square(0.05, 0.01, 64), 64,
                        np.linspace(0, 0.05 + 0.3 * a, 40))
    stl = write_stl(tmp_path / "s.stl", v, f, scale=1000.0)
    csv = write_centerline(tmp_path / "s.csv", path, scale=1000.0)
    cfg = make_config(stl, csv, stl_unit="mm", carriers=16, spool_radius=0.2, friction=mu,
                      ring_friction=0.17, guide_ring=ring, braid_length=0.02,
                      initial_position=0.05, snapshots=1)
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"))
    res = pf.simulate(cfg, progress=False)
    assert res.status in ("done", "failed"), res.message
    assert np.all(np.isfinite(res.history["residual"]))
    if res.status == "failed":
        assert "step" in res.message
        assert quality.assess(res)["verdict"] == "suspect"


def test_the_bounds_change_of_a_slack_yarn_is_finite():
    """A crossing whose yarn has no tension (slack): the change of its bound is measured against
    the floor (1 % of the top tension), not against zero: a finite figure."""
    lat = NS(up=np.array([[0, 0]]), yarn=np.array([[0, 1]]))     # the crossing above: its own row
    tension = np.zeros((1, 2))
    f_top = np.array([4.7, 4.7])
    change = relax._bound_change(lat, np.array([[0.1, 0.0]]), np.zeros((1, 2)), tension, f_top,
                                 DEFAULT.frontal.change_scale_floor)
    assert change == pytest.approx(0.1 / (0.01 * 4.7))
    # where the tensions are there, the scale is f_int + f_ext as before
    tension = np.array([[2.0, 2.0]])
    change = relax._bound_change(lat, np.array([[0.1, 0.0]]), np.zeros((1, 2)), tension, f_top,
                                 DEFAULT.frontal.change_scale_floor)
    assert change == pytest.approx(0.1 / (2.0 + 2.0))


# -- the verdict's reasons, each from a constructed history -----------------------------------

def _history(n=200, v=0.01, dt=0.1, residual=1e-3):
    t = np.arange(n) * dt
    return {"time_s": t, "braided_length_m": v * t, "residual": np.full(n, residual)}


def test_residual_reasons():
    h = _history()
    assert quality.residual_reasons(h) == []
    h["residual"][5] = 2e-2            # 1 of 199 steps above 1e-2: 0.5 %
    assert quality.residual_reasons(h) == []
    h["residual"][6:8] = 2e-2          # 3 of 199: 1.5 %
    (r,) = quality.residual_reasons(h)
    assert "3 of 199 steps" in r
    h = _history()
    h["residual"][50] = 0.2            # one step above 0.1
    (r,) = quality.residual_reasons(h)
    assert "1 steps have a residual above 0.1, up to 0.2" in r
    h["residual"][60] = np.inf         # a non-finite residual counts
    assert any("2 steps have a residual above 0.1, up to inf" in r
               for r in quality.residual_reasons(h))


def test_fell_jump_reasons():
    h = _history()
    table = ((0.0, 0.01),)
    assert quality.fell_jump_reasons(h, table) == []
    h["braided_length_m"] = h["braided_length_m"].copy()
    h["braided_length_m"][100:] += 3.9e-3         # one step moves 3.9 mm + 1 mm of advance: 4.9x
    assert quality.fell_jump_reasons(h, table) == []     # not more than 5x
    h["braided_length_m"][100:] += 0.6e-3         # 5.5x
    (r,) = quality.fell_jump_reasons(h, table)
    assert "1 steps" in r and "5.5x" in r


def test_slip_reasons_say_the_models_keep_the_yarn_where_it_was_laid():
    flags = np.zeros(1000, dtype=np.uint8)
    flags[:100] = FLAG_SLIP
    assert quality.slip_reasons(flags) == []      # 10 %: not above
    flags[100] = FLAG_SLIP
    (r,) = quality.slip_reasons(flags)
    assert "slip tendency" in r and "keep deposited yarn where it was laid" in r


def test_a_failed_run_is_never_ok():
    yarns = NS(flags=np.zeros(0, dtype=np.uint8), points=np.zeros((0, 3)))
    res = NS(status="failed", message="step 3: residual 2", steps=0, history={}, yarns=yarns,
             snapshots=[], config=None, centerline=None)
    q = quality.assess(res)
    assert q["verdict"] == "suspect" and "status failed (step 3: residual 2)" in q["reasons"][0]


def test_snapshot_reasons_flag_a_state_far_from_its_rebalance_and_a_failed_rebalance():
    """A snapshot whose crossings lie further than 5 yarn widths from the re-balanced ones, one
    whose re-balance failed, one with a slack segment: each is a reason."""
    from preform.result import Snapshot

    pts = np.array([[0, 0, 0], [0, 0, 1.0]])
    base = Snapshot(time_s=1.0, points=pts, offsets=np.array([0, 2]), tension_N=np.array([1.0]),
                    contact_id=np.array([-1, -1]), slip=np.zeros(2, dtype=np.int8),
                    group=np.zeros(1, dtype=np.int8))
    assert quality.snapshot_reasons([base], 0.2, width=4e-3) == []
    far = dataclasses.replace(base, rebalance_shift_m=0.021)
    near = dataclasses.replace(base, rebalance_shift_m=0.019)
    assert quality.snapshot_reasons([near], 0.2, width=4e-3) == []
    (r,) = quality.snapshot_reasons([far], 0.2, width=4e-3)
    assert "21 mm" in r and "run's own states" in r
    # one reason a kind, with the worst snapshot and the count
    (r,) = quality.snapshot_reasons([far, near, dataclasses.replace(far, rebalance_shift_m=0.03)],
                                    0.2, width=4e-3)
    assert r.startswith("2 of 3 convergence-zone snapshots") and "30 mm" in r
    failed = dataclasses.replace(base, rebalance_error="no balance")
    assert "could not be checked" in quality.snapshot_reasons([failed], 0.2)[0]
    slack = dataclasses.replace(base, tension_N=np.array([0.0]))
    assert "slack yarn" in quality.snapshot_reasons([slack], 0.2)[0]


def test_the_interaction_note_gives_this_runs_steps(tmp_path):
    """Before an interaction run starts, its note gives the work estimate's step count for this
    run (the figure the estimate prints after the run)."""
    from preform.pipeline import checked_geometry, estimate

    cfg = _cylinder_interaction(tmp_path)
    mandrel, cl, notes = checked_geometry(cfg)
    steps = estimate(cfg, mandrel, cl).steps
    (line,) = [n for n in notes if '[model] kind = "interaction"' in n]
    assert line.startswith("note: ") and f"about {steps:,} time steps" in line
    assert "slow on large machines" not in " ".join(notes)
    kin = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="kinematic"))
    assert not [n for n in checked_geometry(kin)[2] if "[model] kind" in n]


def test_interlacing_reasons():
    """Warp and weft crossing below half the pattern's count separate; a band where the pattern
    gives less than half a crossing per pair is not judged."""
    from preform.analysis.interlacing import Interlacing

    il = dict(s_start=0.0, s_end=0.1, area_m2=0.01, pairs=100)
    assert quality.interlacing_reasons(Interlacing(measured=60, pattern=100.0, **il)) == []
    (r,) = quality.interlacing_reasons(Interlacing(measured=40, pattern=100.0, **il))
    assert "warp and weft separate: 40 warp-weft crossings" in r and "0.40" in r
    assert quality.interlacing_reasons(Interlacing(measured=0, pattern=40.0, **il)) == []
    assert quality.interlacing_reasons(None) == []


def test_a_solve_that_fails_also_in_stages_names_its_likely_cause(tmp_path):
    """A solver that gives up from step 3 on (also on the staged retries): the error keeps the
    solver's message and adds the likely cause read off the zone."""
    cfg = _cylinder_interaction(tmp_path)
    mandrel, cl = load_geometry(cfg)
    cfg = resolve_pose_lead(cfg, mandrel, cl)
    machine = Machine.from_config(cfg.machine)
    calls = [0]

    def solve(state, bc, **kw):
        calls[0] += 1
        if calls[0] >= 3 and state.m:
            raise SimulationError("the solver gave up at this step")
        from preform.interaction.frontal import solve_zone_inplace
        return solve_zone_inplace(state, bc, **kw)

    s = Stepper(cfg, machine, mandrel, cl, InteractionZone(cfg, machine, mandrel, solve_zone=solve))
    with pytest.raises(SimulationError) as err:
        s.run(progress=False)
    assert "the solver gave up at this step; likely cause: " in str(err.value)


def test_the_summary_says_which_snapshots_differ_from_their_rebalance(tmp_path):
    """summary.json's snapshot_checks: the largest shift, the tolerance (5 yarn widths) and the
    snapshots beyond it, from a short interaction run whose snapshots' shifts are set."""
    cfg = _cylinder_interaction(tmp_path)
    res = pf.simulate(cfg, progress=False)
    assert all(np.isfinite(s.rebalance_shift_m) for s in res.snapshots)   # every one checked
    snaps = [dataclasses.replace(s, rebalance_shift_m=v)
             for s, v in zip(res.snapshots, (0.001, 0.05, 0.0))]
    s = summary_dict(dataclasses.replace(res, snapshots=snaps))["snapshot_checks"]
    assert s["rebalance_shift_max_m"] == 0.05
    assert s["rebalance_shift_tolerance_m"] == pytest.approx(5 * cfg.yarn.width)
    assert s["beyond_tolerance_at_s"] == [snaps[1].time_s] and s["rebalance_failed_at_s"] == []


def test_crossing_shift_matches_yarn_points_by_crossing():
    """The shift compares each yarn's point at each crossing with the same yarn's at the same
    crossing in the other snapshot; crossings in only one (deposited by the re-balance) and the
    fell, ring and spool points are not compared."""
    from preform.interaction.model import crossing_shift
    from preform.result import Snapshot

    def snap(points, cid):
        n = len(points) // 2
        return Snapshot(time_s=0.0, points=np.array(points, dtype=float),
                        offsets=np.array([0, n, 2 * n]), tension_N=np.ones(2 * n - 2),
                        contact_id=np.array(cid), slip=np.zeros(2 * n, dtype=np.int8),
                        group=np.array([0, 1], dtype=np.int8))

    a = snap([[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2]], [-1, 7, -1, -1, 7, -1])
    b = snap([[5, 0, 0], [0, 0.003, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [9, 0, 2]], [-1, 7, -1, -1, 7, -1])
    assert crossing_shift(a, b) == pytest.approx(0.003)
    gone = snap([[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2]], [-1, 8, -1, -1, 8, -1])
    assert crossing_shift(a, gone) == 0.0
