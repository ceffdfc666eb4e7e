"""Interaction zone (DESIGN.md §3.3): state, frontal kernels vs NumPy twins, balance of snapshots
read back from the written .vtp files, friction law, convergence of the frontal iteration.

Synthetic set-up (no mandrel walk): 16 carriers, fell points held fixed on a circle of radius
75 mm at z = 0.15 m, crossings created at every carrier pass, deposition by a cylinder distance.
"""

from __future__ import annotations

import copy
from types import SimpleNamespace as NS

import numpy as np
import pytest

import naive_frontal as naive
from preform._kernels import frontal as K
from preform.config import MachineConfig
from preform.errors import SimulationError
from preform.interaction import frontal, model
from preform.interaction.model import InteractionZone, creation_point
from preform.io.vtk_yarns import write_convergence
from preform.interaction.zone_state import ZoneState
from preform.machine import Machine
from snapshot_checks import balance_and_psi, read_snapshot

R_MANDREL = 0.075


class _Identity:
    def to_mandrel(self, x):
        return np.asarray(x)

    def to_machine(self, x):
        return np.asarray(x)


def _cylinder_distance(p):
    return np.hypot(p[:, 0], p[:, 1]) - R_MANDREL


def run_zone(mu=0.2, tension=4.7, steps=60, carriers=16):
    mc = MachineConfig(carriers=carriers, spool_radius=0.3, angular_speed=0.2309401, pattern="regular")
    machine = Machine.from_config(mc)
    cfg = NS(yarn=NS(width=4e-3, thickness=2.5e-4, tension=tension, friction=mu, ring_friction=0.0),
             machine=mc)
    zone = InteractionZone(cfg, machine, None, distance=_cylinder_distance)
    phi = machine.azimuths(0.0)
    F = np.stack([R_MANDREL * np.cos(phi), R_MANDREL * np.sin(phi), np.full_like(phi, 0.15)], 1)
    zone.start(0.0, F, _Identity())
    dt = 0.01 / machine.omega
    t = 0.0
    last = None
    for _ in range(steps):
        last = zone.step(t, dt, F, _Identity())
        for k, p in last.deposits:
            F[k] = p
        t += dt
    return zone, F, t, last


def test_state_chains_stay_consistent():
    rng = np.random.default_rng(1)
    st = ZoneState(8, capacity=2)
    for _ in range(40):
        st.add(int(rng.integers(4)), int(4 + rng.integers(4)), rng.normal(size=3), [0, 0, 1.0],
               bool(rng.integers(2)), 0.0)
        st.check()
    assert st.capacity >= 40   # grown by doubling from 2
    uids = set(st.uid[: st.m])
    # remove the lowest crossings of yarn 0 and everything below them on the other yarn
    def below(c, acc):   # c and everything under it on both its yarns
        acc.add(int(c))
        for side in range(2):
            if st.low[c, side] >= 0:
                below(st.low[c, side], acc)
        return acc

    for _ in range(5):
        if st.lowest[0] < 0:
            break
        st.remove(sorted(below(st.lowest[0], set())))
        st.check()
    assert set(st.uid[: st.m]) < uids


def test_creation_point_is_closest_point_midpoint():
    px, gx = np.array([0.0, 0, 0]), np.array([1.0, 0, 0])
    po, go = np.array([0.5, -1, 1]), np.array([0.5, 1, 1])
    C, N = creation_point(px, gx, po, go)
    assert np.allclose(C, [0.5, 0, 0.5])
    assert np.allclose(np.abs(N), [0, 0, 1])


def _perturbed(mu=0.3, steps=60, seed=0):
    """A zone after some steps with its crossings, material coordinates and bounds shaken."""
    zone, F, t, _ = run_zone(mu=mu, steps=steps)
    st = zone.state
    rng = np.random.default_rng(seed)
    st.pos[: st.m] += rng.normal(scale=2e-3, size=(st.m, 3))
    bc = zone.boundary(t, F)
    frontal.anchor_fell(st, bc)
    # material coordinates that give every segment a tension in 3..6 N (in tension, where the
    # Hessian is exact, see _kernels/frontal.py)
    EA = frontal.axial_stiffness(bc.f_spool)
    for k, (side, chain) in enumerate(naive.chains(st)):
        prev, s_prev = bc.fell[k], st.s_fell[k]
        for c in chain:
            p = naive.yarn_point(st, c, side, bc.h)
            l = np.sqrt(np.sum((p - prev) ** 2) + frontal.LENGTH_SMOOTHING)
            st.s[c, side] = s_prev + l / (1 + rng.uniform(3.0, 6.0) / EA)
            prev, s_prev = p, st.s[c, side]
    ten = naive.tensions(st, bc.fell, EA, bc.h, frontal.LENGTH_SMOOTHING)
    assert 3.0 - 1e-6 < ten.min() and ten.max() < 6.0 + 1e-6
    return zone, bc


def _net(zone, bc, seed=1):
    st = zone.state
    rng = np.random.default_rng(seed)
    f_top = rng.uniform(4.0, 5.0, st.n_yarns)
    net = frontal._Network(st, bc, f_top)
    net.s_old = st.s[: st.m] + rng.normal(scale=3 * frontal.FRICTION_CREEP, size=(st.m, 2))
    net.g = rng.uniform(0.0, 0.5, size=(st.m, 2))
    return net, f_top


def _naive_energy(zone, bc, net, f_top):
    return naive.energy(zone.state, bc.fell, bc.top, f_top, net.g, net.s_old,
                        net.EA, frontal.FRICTION_CREEP, frontal.KAPPA0, bc.h,
                        frontal.LENGTH_SMOOTHING, K.TOP_SMOOTHING2, bc.width,
                        frontal.JAM_FORCE * bc.f_spool / bc.width)


def _inner_lengths(st, h):
    """Lengths of the segments between two crossings of a yarn."""
    out = []
    for side, chain in naive.chains(st):
        for a, b in zip(chain[:-1], chain[1:]):
            out.append(np.linalg.norm(naive.yarn_point(st, b, side, h)
                                      - naive.yarn_point(st, a, side, h)))
    return np.array(out)


def test_jamming_energy_and_gradient_match_numpy():
    """With a jamming length longer than some segments between crossings, the kernel's energy is
    the NumPy twin's and its gradient the central difference of it (the Gauss-Newton Hessian of
    the jamming term is not exact: not checked here)."""
    import dataclasses
    zone, bc = _perturbed()
    st = zone.state
    lengths = _inner_lengths(st, bc.h)
    bc = dataclasses.replace(bc, width=float(np.median(lengths)))
    assert np.sum(lengths < bc.width) >= 3                      # jams active
    net, f_top = _net(zone, bc)
    E, _ = net.assemble()
    E_jam = _naive_energy(zone, bc, net, f_top)
    E_free = naive.energy(st, bc.fell, bc.top, f_top, net.g, net.s_old, net.EA,
                          frontal.FRICTION_CREEP, frontal.KAPPA0, bc.h, frontal.LENGTH_SMOOTHING,
                          K.TOP_SMOOTHING2)
    assert E_jam > E_free                                       # the term is there
    assert E == pytest.approx(E_jam, rel=1e-12)
    v = np.random.default_rng(3).normal(size=(st.m, 5))
    x0 = np.hstack([st.pos[: st.m], st.s[: st.m]]).copy()
    hstep = 1e-9       # as in the test below
    Es = []
    for sgn in (1, -1):
        st.pos[: st.m] = x0[:, :3] + sgn * hstep * v[:, :3]
        st.s[: st.m] = x0[:, 3:] + sgn * hstep * v[:, 3:]
        Es.append(_naive_energy(zone, bc, net, f_top))
    st.pos[: st.m], st.s[: st.m] = x0[:, :3], x0[:, 3:]
    assert (Es[0] - Es[1]) / (2 * hstep) == pytest.approx(float(np.sum(net.grad * v)), rel=1e-4,
                                                          abs=1e-6 * abs(E))


def test_assemble_matches_numpy_energy_gradient_and_hessian():
    zone, bc = _perturbed()
    st = zone.state
    assert 0 < bc.width < _inner_lengths(st, bc.h).min()   # no jam: the Hessian is exact
    net, f_top = _net(zone, bc)
    E, nnz = net.assemble()
    E_ref = _naive_energy(zone, bc, net, f_top)
    assert np.isfinite(E)
    assert E == pytest.approx(E_ref, rel=1e-12)          # same sums, other order: round-off
    # gradient and Hessian vs central differences of the NumPy energy / kernel gradient along a
    # random direction v (5 unknowns per crossing). Steps: 1e-9 m for the energy (its curvature
    # EA / q ~ 1e7 N/m makes the O(h^2) error ~1e-8 of the slope), 1e-10 m for the gradient
    import scipy.sparse as sp
    v = np.random.default_rng(2).normal(size=(st.m, 5))
    x0 = np.hstack([st.pos[: st.m], st.s[: st.m]]).copy()

    def put(x):
        st.pos[: st.m] = x[:, :3]
        st.s[: st.m] = x[:, 3:]

    h = 1e-9
    put(x0 + h * v)
    Ep = _naive_energy(zone, bc, net, f_top)
    put(x0 - h * v)
    Em = _naive_energy(zone, bc, net, f_top)
    put(x0)
    slope = float(np.sum(net.grad * v))
    assert (Ep - Em) / (2 * h) == pytest.approx(slope, rel=1e-4, abs=1e-6 * abs(E))
    H = sp.csr_matrix((net.vals[:nnz], (net.rows[:nnz], net.cols[:nnz])), shape=(5 * st.m,) * 2)
    h = 1e-10
    put(x0 + h * v)
    net.assemble()
    gp = net.grad.copy()
    put(x0 - h * v)
    net.assemble()
    gm = net.grad.copy()
    put(x0)
    fd = ((gp - gm) / (2 * h)).ravel()
    assert np.allclose(H @ v.ravel(), fd, rtol=1e-4, atol=1e-4 * np.abs(fd).max())


@pytest.mark.parametrize("cholmod", [True, False])
def test_newton_direction_solves_the_assembled_system(cholmod, monkeypatch):
    """The Newton direction solves H dx = -g for the assembled Hessian, by CHOLMOD's Cholesky or
    by SuperLU's LU (its fallback), in the nested-dissection order: the order is a permutation of
    the 5 unknowns of every crossing, and both give the direction of a plain dense solve (to the
    round-off of refined factorisations of a matrix with condition ~1e9: EA / q against the
    tension stiffness f / l)."""
    import scipy.sparse as sp
    monkeypatch.setattr(frontal, "USE_CHOLMOD", cholmod)
    zone, bc = _perturbed()
    st = zone.state
    net, _ = _net(zone, bc)
    _, nnz = net.assemble()
    n = 5 * st.m
    dof = net.order
    assert np.array_equal(np.sort(dof), np.arange(n))
    assert np.array_equal(dof.reshape(-1, 5) % 5, np.tile(np.arange(5), (st.m, 1)))
    H = sp.csr_matrix((net.vals[:nnz], (net.rows[:nnz], net.cols[:nnz])), shape=(n, n))
    g = net.grad[: st.m].ravel()
    dx = frontal._newton_direction(net, nnz, g)
    assert np.linalg.norm(H @ dx + g) <= 1e-8 * np.linalg.norm(g)
    dense = np.linalg.solve(H.toarray(), -g)
    assert np.allclose(dx, dense, rtol=1e-6, atol=1e-9 * np.abs(dense).max())
    out = np.empty(n)
    K.triplet_matvec(nnz, net.rows, net.cols, net.vals, dx, out)   # the kernel vs scipy
    assert np.allclose(out, H @ dx, rtol=1e-12, atol=1e-12 * np.abs(H @ dx).max())
    # the pattern's entries are the lower triangle of H in the dissection order (kernel vs scipy)
    pattern = net.pattern(nnz)
    v = np.empty(pattern.size)
    K.accumulate(nnz, pattern.slot, net.vals, v)
    lower = sp.tril(H[dof][:, dof]).tocsc()
    assert np.array_equal(lower.indices, pattern.r) and np.array_equal(
        np.repeat(np.arange(n), np.diff(lower.indptr)), pattern.c)
    assert np.allclose(v, lower.data, rtol=1e-12, atol=1e-12 * np.abs(lower.data).max())
    # a second Newton step reuses the pattern (and CHOLMOD's analysis) with new values
    net.vals[:nnz] *= 2.0
    assert np.allclose(frontal._newton_direction(net, nnz, g), 0.5 * dx, rtol=1e-6,
                       atol=1e-9 * np.abs(dx).max())
    assert net.pattern(nnz) is pattern


def test_tension_and_bound_kernels_match_numpy_twins():
    zone, bc = _perturbed()
    st = zone.state
    net, f_top = _net(zone, bc)
    net.f_top = f_top
    net.update_tensions()
    ref = naive.tensions(st, bc.fell, net.EA, bc.h, frontal.LENGTH_SMOOTHING)
    assert np.allclose(net.tension, ref, rtol=1e-9, atol=1e-9)
    g = np.empty((st.m, 2))
    psi = np.empty((st.m, 2))
    K.friction_bounds(st.m, st.yarn, st.pos, st.normal, st.over, st.low, st.up, bc.fell, bc.top,
                      net.tension, f_top, bc.h, 0.3, g, psi)
    assert np.allclose(g, naive.bounds(st, bc.fell, bc.top, net.tension, f_top, bc.h, 0.3),
                       rtol=1e-9)


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_snapshot_file_crossings_in_balance(mu, tmp_path):
    zone, F, t, _ = run_zone(mu=mu, steps=90)
    snap = zone.snapshot(t, F)
    paths = write_convergence([snap], tmp_path)
    yarns = read_snapshot(paths[1])
    assert sum(int(np.sum(c >= 0)) for _, _, c in yarns) == 2 * zone.state.m > 0
    err, psi = balance_and_psi(yarns, mu)
    assert err < 1e-3     # issue 4: relative force-balance error < 1e-3
    assert psi < 1e-3     # issue 4: Psi <= 1e-3 tension


def test_frictionless_tension_equals_spool_tension_along_yarns():
    zone, F, t, _ = run_zone(mu=0.0, steps=90)
    snap = zone.snapshot(t, F)
    # mu = 0: f_int = f_ext at every crossing (DESIGN.md §3.3); to the Newton tolerance (1e-8)
    # and KAPPA0 x slide (1e-9 N)
    assert np.allclose(snap.tension_N, 4.7, rtol=1e-7)


def test_friction_makes_tensions_differ_and_stays_in_the_cone():
    zone, F, t, _ = run_zone(mu=0.3, steps=90)
    st = zone.state
    ten = st.tension[: st.m]
    assert np.ptp(ten) > 1e-4          # friction acts
    # new crossings slide down the yarns: the tension falls towards the mandrel (to the Newton
    # tolerance)
    assert np.all(ten <= 4.7 * (1 + 1e-7))


def test_spool_tension_scales_out():
    # Amontons friction is homogeneous in the forces: same positions for 2 N and 8 N
    z2, *_ = run_zone(mu=0.3, tension=2.0, steps=90)
    z8, *_ = run_zone(mu=0.3, tension=8.0, steps=90)
    assert z2.state.m == z8.state.m
    # EA scales with the spool tension (frontal.TOW_STRAIN), so the whole model is homogeneous:
    # the same solution up to the solver tolerance (1e-7 relative imbalance: measured 3e-11 m)
    assert np.abs(z2.state.pos[: z2.state.m] - z8.state.pos[: z8.state.m]).max() < 1e-8
    assert np.allclose(z8.state.tension[: z8.state.m], 4.0 * z2.state.tension[: z2.state.m],
                       rtol=1e-6)


def test_residual_falls_over_frontal_iterations():
    zone, F, t, _ = run_zone(mu=0.3, steps=40)
    st = zone.state
    st.pos[: st.m] += 1e-3 * np.random.default_rng(2).normal(size=(st.m, 3))
    rep = frontal.solve_zone(st, zone.boundary(t, F), zone.f_top.copy(),
                             max_iter=frontal.SNAPSHOT_ITERATIONS)
    h = rep.history
    assert not rep.lagged
    assert h[-1] < frontal.FRICTION_TOLERANCE
    assert np.all(np.diff(h) < 0)


def test_newton_lowers_the_energy_at_every_iteration():
    """The solve's Newton trace (SolveReport.newton_energy/newton_residual): Armijo backtracking
    on E never lets it rise (beyond its round-off, frontal.ROUNDOFF), and the last iterate is
    the balanced one."""
    zone, F, t, _ = run_zone(mu=0.3, steps=40)
    st = zone.state
    st.pos[: st.m] += 1e-3 * np.random.default_rng(3).normal(size=(st.m, 3))
    rep = frontal.solve_zone(st, zone.boundary(t, F), zone.f_top.copy())
    E, res = rep.newton_energy, rep.newton_residual
    assert len(E) == len(res) == rep.newton + 1 > 3
    assert np.all(np.diff(E) <= frontal.ROUNDOFF * np.abs(E[1:]))
    assert res[-1] < frontal.BALANCE_TOLERANCE <= res[0]


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_a_failed_step_is_solved_again_in_stages(monkeypatch, mu):
    """InteractionZone._staged: where a step's solve fails, the step is solved again with the
    boundary moved in stages from where the last step left it. Without friction the last stage
    is the step's own problem and lands where the direct solve does; with friction the bounds
    are re-evaluated at every stage (they lag the geometry by a solve, frontal.MAX_ITERATIONS),
    so it lands near it, in balance."""
    zone, F, t, _ = run_zone(mu=mu, steps=40)
    dt = 0.01 / zone.machine.omega
    twin = copy.deepcopy(zone)
    zone.step(t, dt, F, _Identity())
    assert zone.staged == 0
    solve = model.frontal.solve_zone
    calls = []

    def fail_first(*a, **k):
        calls.append(k.get("where", ""))
        if len(calls) == 1:
            raise SimulationError("no balance (a stand-in for a failed solve)")
        return solve(*a, **k)

    monkeypatch.setattr(model.frontal, "solve_zone", fail_first)
    twin.step(t, dt, F, _Identity())
    assert twin.staged == 1
    assert len(calls) == 1 + len(model.BOUNDARY_STAGES)
    assert all("stages" in w for w in calls[1:])
    assert twin.last_report.residual < frontal.FRICTION_TOLERANCE or twin.last_report.lagged
    a, b = zone.state, twin.state
    assert a.m == b.m and np.array_equal(a.uid[: a.m], b.uid[: b.m])
    moved = np.abs(a.pos[: a.m] - b.pos[: b.m]).max()
    if mu == 0.0:
        # one energy, one minimum: the solver tolerance (measured below 1e-9 m)
        assert moved < 1e-6
    else:
        # the bounds' lag: measured 1.7 mm on this zone, whose crossings move by 6.8 mm a step
        assert moved < 5e-3


def test_non_convergence_names_step_and_residual():
    zone, F, t, _ = run_zone(mu=0.3, steps=40)
    st = zone.state
    st.pos[: st.m] += 1e-2
    with pytest.raises(SimulationError, match=r"step 7 .*residual"):
        frontal.solve_zone(st, zone.boundary(t, F), zone.f_top.copy(), max_iter=1, tol=1e-30,
                           where="at step 7 (t = 1 s)")


@pytest.mark.parametrize("memory", [frontal.FRICTION_MEMORY, 0.0])
def test_friction_memory_keeps_a_loaded_sticking_yarn_in_place(memory, monkeypatch):
    """Elastic-plastic friction (frontal.FRICTION_MEMORY): a yarn that sticks under a load keeps
    its friction force into the next step, so solving the same step again leaves it where it is.
    Without the memory every step starts without friction force and the yarn creeps again by
    about as much as in the first solve (the control case: the test can tell them apart)."""
    monkeypatch.setattr(frontal, "FRICTION_MEMORY", memory)
    zone, F, t, _ = run_zone(mu=0.3, steps=60)
    st = zone.state
    bc = zone.boundary(t, F)
    f_top = zone.f_top.copy()
    centre = st.s[: st.m] - st.offset[: st.m]
    frontal.solve_zone(st, bc, f_top, max_iter=frontal.SNAPSHOT_ITERATIONS)
    s1 = st.s[: st.m].copy()
    x = s1 - centre                   # the friction slip of the first solve
    cap = 0.95 / np.sqrt(1 - 0.95**2) * frontal.FRICTION_CREEP
    loaded = (np.abs(x) > 0.3 * frontal.FRICTION_CREEP) & (np.abs(x) < 0.5 * cap)
    assert loaded.sum() > 10
    frontal.solve_zone(st, bc, f_top, max_iter=frontal.SNAPSHOT_ITERATIONS)
    moved = np.abs(st.s[: st.m] - s1)[loaded]
    if memory:
        # to the solver's tolerances (balance 1e-7, bounds 1e-6 of the tensions) times the
        # friction compliance FRICTION_CREEP / g
        assert moved.max() < 1e-2 * frontal.FRICTION_CREEP
    else:
        assert np.median(moved) > 0.2 * frontal.FRICTION_CREEP


def test_lower_pattern_kernel_matches_numpy_unique():
    """``K.lower_pattern`` (O(nnz)) against the obvious NumPy: unique keys c n + r of the
    permuted lower triplets, and each triplet's entry."""
    rng = np.random.default_rng(3)
    n, nnz = 60, 900
    rows = rng.integers(0, n, nnz)
    cols = rng.integers(0, n, nnz)
    rank = rng.permutation(n)
    slot, er, ec, size = K.lower_pattern(nnz, rows, cols, rank, n)
    r, c = rank[rows], rank[cols]
    lower = r >= c
    key, inverse = np.unique(c[lower] * n + r[lower], return_inverse=True)
    assert size == key.size
    assert np.array_equal(er, key % n) and np.array_equal(ec, key // n)
    assert np.array_equal(slot[lower], inverse) and np.all(slot[~lower] == -1)


@pytest.mark.parametrize("offset", [1e-9, 1e-4])
def test_newton_step_below_the_energys_round_off_is_taken_whole(offset, monkeypatch):
    """Where the decrease of E that Newton predicts is below E's round-off, E cannot judge the
    step (``frontal.ROUNDOFF_SLOPE``): the full step is taken, else Newton stalls (case A with
    friction 0 stopped at step 278 with the residual at 1.3e-6). Here E's evaluations are made
    pure noise (always a little higher): near balance (1e-9 m off) the step is still taken
    whole; far from it (1e-4 m) the line search refuses it, as it must."""
    zone, F, t, _ = run_zone(mu=0.0, steps=40)
    st = zone.state
    m = st.m
    bc = zone.boundary(t, F)
    st.s[:m] += 1e3            # m of yarn: E ~ 1e5 J (the spool's work), physics unchanged
    frontal.anchor_fell(st, bc)
    frontal.solve_zone(st, bc, zone.f_top.copy())
    st.pos[:m] += offset * np.random.default_rng(4).normal(size=(m, 3))
    net = frontal._Network(st, bc, zone.f_top.copy())
    E, nnz = net.assemble()
    g = net.grad[:m].ravel().copy()
    dx = frontal._newton_direction(net, nnz, g)
    near = -float(g @ dx) < frontal.ROUNDOFF_SLOPE * frontal.ROUNDOFF * abs(E)
    assert near == (offset < 1e-6)
    monkeypatch.setattr(net, "energy", lambda pos, s: E + 1e-6 * abs(E))
    pos0 = st.pos[:m].copy()
    frontal._newton_step(net, E, nnz)
    moved = np.abs(st.pos[:m] - pos0).max()
    full = np.abs(dx.reshape(m, 5)[:, :3]).max()
    if near:
        assert moved == pytest.approx(full, rel=1e-6)
    else:
        assert moved < 1e-9 * full
