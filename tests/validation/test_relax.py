"""Force-density relaxation of a zone step (``interaction/relax.py``): kernels against their NumPy
twins and the Newton reference's gradient; whole steps captured from case A runs (16 and 48
carriers, friction 0, 0.25, 0.5) against the Newton solver (``frontal.solve_zone_inplace``); the exact
wall active set.

A captured step is the problem ``InteractionZone.step`` poses its solver (fell points anchored,
crossings created, normals radial, friction centres, wall planes), taken from a copy of the zone
of a case A run (``simulation.make_stepper``) after some steps.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from support import naive_frontal
from preform.reference import resolve_pose_lead
from preform.simulation import load_geometry, make_stepper
from preform.stepping import take_up_speed
from support import naive_relax as naive
from support.simcase import FULL_SIZE, advanced_stepper, capture_step, case_a_interaction_config
from preform._kernels import frontal as FK
from preform._kernels import relax as RK
from preform._kernels import stiffness as SK
from preform._kernels import zone as KZ
from preform.interaction import frontal, relax as R
from preform.interaction import preconditioners as PC
from preform.interaction.contact import CrossingFriction
from preform.interaction.settings import DEFAULT

E = DEFAULT.energy


def _stepper(carriers, mu, steps):
    return advanced_stepper(case_a_interaction_config(carriers, mu), steps)


@pytest.fixture(scope="module")
def captured():
    """``captured(carriers, mu, steps)``: (state, boundary with wall planes, f_top, friction
    centres) of the next step of a case A run after ``steps`` steps, on copies; the runs are
    shared by the module's tests."""
    runs = {}

    def capture(carriers, mu, steps):
        key = (carriers, mu, steps)
        if key not in runs:
            runs[key] = _stepper(carriers, mu, steps)
        return capture_step(*runs[key])

    return capture


def _newton(st, bc, f_top, s_old, tol):
    stN = st.copy()
    frontal.solve_zone_inplace(stN, bc, centre=s_old, tol=tol)
    return stN


def _relax(st, bc, s_old, settings, plane="bc", pos=None, bounds=None, tol=None):
    b0, f0 = R.start_bounds(st, bc)
    m = st.m
    return R.relax(R.lattice_of(st), st.pos[:m] if pos is None else pos, st.material[:m],
                   st.material_fell,
                   s_old[:m], bc.fell, bc.top, f0, b0 if bounds is None else bounds,
                   f_spool=bc.f_spool, friction=bc.friction, h=bc.h, width=bc.width,
                   plane=bc.plane if plane == "bc" else plane, settings=settings, tol=tol)


def _model_args(bc):
    EA = frontal.axial_stiffness(bc.f_spool)
    k_jam = E.jam_force * bc.f_spool / bc.width
    return EA, k_jam


def test_kernels_match_numpy_twins_and_the_newton_gradient(captured):
    """Segment lengths, the material sweep, net forces, the Laplacian and the friction bounds
    against the twins on a perturbed 16-carrier step (positions shaken by 2 mm, a jamming length
    that makes a third of the segments jam); the net force also against -dE/dC of the Newton energy
    (``_kernels.frontal.assemble``, no wall), and the swept material against dE/ds = 0 there."""
    st, bc, f_top, s_old = captured(16, 0.25, 60)
    st = st.copy()
    m, ny = st.m, st.n_yarns
    rng = np.random.default_rng(3)
    st.pos[:m] += rng.normal(scale=2e-3, size=(m, 3))
    eps2, eps_f, kappa0 = E.length_smoothing, DEFAULT.frontal.friction_creep, E.kappa0
    EA, k_jam = _model_args(bc)
    g = rng.uniform(0.0, 1.0, size=(m, 2))
    lat = R.lattice_of(st)
    fell, top = np.ascontiguousarray(bc.fell), np.ascontiguousarray(bc.top)
    d_below, l_below = np.empty((m, 2, 3)), np.empty((m, 2))
    d_top, l_top = np.empty((ny, 3)), np.empty(ny)
    RK.segment_vectors(m, ny, lat.yarn, st.pos[:m], lat.normal, lat.over, lat.low, lat.highest,
                       fell, top, bc.h, eps2, E.top_smoothing2, d_below, l_below, d_top, l_top)
    segs = naive.segments(st, fell, top, bc.h, eps2)
    for k, (side, chain, pts, l, lt) in enumerate(segs):
        assert np.allclose(l_below[chain, side], l, rtol=1e-13)
        if chain:
            assert np.isclose(l_top[k], lt, rtol=1e-13)
    # material sweep from the captured material (all segments stretched there)
    s = st.material[:m].copy()
    ten = np.empty((m, 2))
    worst = RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, l_below, s, st.material_fell,
                              s_old[:m], g, f_top, EA, E.compression, eps_f, kappa0, 1e-10, 60, ten,
                              np.empty(m, dtype=np.int64), np.empty((m, 6)),
                              np.zeros(2, dtype=np.int64))
    assert worst < 1e-10
    s_ref, ten_ref = naive.material(st, fell, top, st.material[:m], s_old[:m], g, f_top, EA, eps_f,
                                    kappa0, bc.h, eps2)
    # the yarn problem's stiffness EA / q ~ 1e6 N/m: 1e-10 of a 5 N tension is 1e-15 m
    assert np.abs(s - s_ref).max() < 1e-10
    assert np.abs(ten - ten_ref).max() < 1e-6
    # started from the strain-keeping prediction for lengths 1 % off: the same minimum
    s2 = st.material[:m].copy()
    ten2 = np.empty((m, 2))
    l_prev = l_below * rng.uniform(0.99, 1.01, size=l_below.shape)
    worst = RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, l_below, s2, st.material_fell,
                              s_old[:m], g, f_top, EA, E.compression, eps_f, kappa0, 1e-10, 60,
                              ten2, np.empty(m, dtype=np.int64), np.empty((m, 6)),
                              np.zeros(2, dtype=np.int64), l_prev)
    assert worst < 1e-10
    assert np.abs(s2 - s_ref).max() < 1e-10
    assert np.abs(ten2 - ten_ref).max() < 1e-6
    # net forces against the twin and against the Newton energy's gradient at this state
    # a jamming length that makes a third of the segments between crossings jam
    l_jam = float(np.quantile(l_below[st.low[:m] >= 0], 0.3))
    force, w_below, w_top, total = np.empty((m, 3)), np.empty((m, 2)), np.empty(ny), np.empty(m)
    W = np.empty(m)
    RK.forces(m, ny, lat.yarn, lat.low, lat.highest, d_below, l_below, d_top, l_top, ten, f_top,
              l_jam, k_jam, 1e-3, force, w_below, w_top, total, W)
    F_ref = naive.net_forces(st, fell, top, ten, f_top, bc.h, eps2, l_jam, k_jam)
    assert np.abs(force - F_ref).max() < 1e-9 * np.abs(F_ref).max()
    stE = st.copy()
    stE.material[:m] = s
    plane = np.zeros((m, 6))
    plane[:, 2] = -1e300
    plane[:, 5] = 1.0
    grad = np.zeros((m, 5))
    cap = FK.triplet_capacity(m, ny)
    FK.assemble(KZ.Lattice(m, ny, stE.yarn, stE.low, stE.up, stE.over, stE.normal, stE.lowest,
                           stE.highest),
                KZ.law(EA, E.compression, eps_f, kappa0, bc.h, eps2, E.top_smoothing2, l_jam,
                       k_jam, E.geometric_floor),
                KZ.problem(fell, top, stE.material_fell, s_old[:m], g, f_top), stE.pos,
                stE.material, plane, 0.0, grad, np.empty(cap, np.int64),
                np.empty(cap, np.int64), np.empty(cap))
    assert np.abs(force + grad[:, :3]).max() < 1e-9 * np.abs(force).max()
    assert np.abs(grad[:, 3:]).max() < 1e-9 * f_top.max()
    # Laplacian of the fixed pattern against the dense one, with some wall rows
    active = rng.uniform(size=m) < 0.2
    lap = PC.Laplacian(lat)
    diag = np.empty(m)
    SK.laplacian_values(m, ny, lat.low, lat.highest, w_below, w_top, active, lap.slot_diag,
                        lap.slot_below, lap.nslots, lap.vals, diag)
    lap.A.data[:] = lap.vals
    U = lap.A.toarray()
    L_ref, diag_ref = naive.laplacian(st, w_below, w_top, active)
    assert np.allclose(U + np.triu(U, 1).T, L_ref, rtol=1e-13, atol=0)
    assert np.allclose(diag, diag_ref, rtol=1e-13)
    assert np.allclose(W, diag, rtol=1e-13)   # the stiffness the wall residual uses
    # friction bounds against the Newton reference's twin
    gb, psi = np.empty((m, 2)), np.empty((m, 2))
    howell = CrossingFriction(law="howell", coefficient=bc.friction.coefficient, index=0.75,
                              reference_force=0.5)
    for law in (bc.friction, howell):
        RK.friction_bounds(m, ny, lat.yarn, lat.up, d_below, l_below, d_top, ten, f_top,
                           *law.kernel_arguments(lat.yarn), gb, psi)
        assert np.allclose(gb, naive_frontal.bounds(st, fell, top, ten, f_top, bc.h, law),
                           rtol=1e-9, atol=1e-12)
    # every crossing its own coefficient (mixed yarns), against the twin
    mu = np.random.default_rng(3).uniform(0.0, 0.5, m)
    RK.friction_bounds(m, ny, lat.yarn, lat.up, d_below, l_below, d_top, ten, f_top, mu,
                       np.ones(m), 1.0, 1e-3, gb, psi)
    assert np.allclose(gb, naive_frontal.bounds(st, fell, top, ten, f_top, bc.h, mu),
                       rtol=1e-9, atol=1e-12)


# Newton and the relaxation both to 1e-10 of the tensions: both converge there (Newton
# quadratically); at the default 1e-7 soft modes of the lattice (long top segments, ~10 N/m)
# leave them up to 3 um apart
TIGHT = 1e-10


@pytest.mark.parametrize("carriers, mu, steps", [
    (16, 0.0, 80), (16, 0.25, 80), (16, 0.5, 80),
    pytest.param(48, 0.0, 250, marks=FULL_SIZE), pytest.param(48, 0.25, 250, marks=FULL_SIZE),
    # with the crossings' distances taken from the face under them (``MandrelDistance``), the
    # run reaches another state at step 250, on which the relaxation (block, then scalar
    # retry) stops short of 1e-10 within 400 iterations
    pytest.param(48, 0.5, 250, marks=[FULL_SIZE, pytest.mark.xfail(
        strict=True, reason="the relaxation stalls above 1e-10 on this captured step")])])
def test_step_lands_on_the_newton_solution(carriers, mu, steps, captured):
    """Same friction bounds held, same equations: the same state (positions within 1e-6 m,
    measured 1e-9 m), every crossing in balance to the tolerance."""
    st, bc, f_top, s_old = captured(carriers, mu, steps)
    ref = _newton(st, bc, f_top, s_old, TIGHT)
    # max_iter: at 1e-10 the 48-carrier step with friction 0.5 takes 216 iterations (the block-
    # Jacobi corrections stall at a jammed crossing and stop after 30; 285 without them)
    # scalar_retry: where the block preconditioner stalls (friction 0.5), the scalar one
    res = _relax(st, bc, s_old, R.RelaxSettings(max_iter=400, scalar_retry=True), tol=TIGHT)
    m = st.m
    assert res.converged and res.residual < TIGHT
    assert np.abs(res.pos - ref.pos[:m]).max() < 1e-6
    assert np.abs(res.tension - ref.tension[:m]).max() < 1e-6 * bc.f_spool


@pytest.mark.parametrize("mu", [0.0, 0.25])
def test_wall_is_exact_and_pushes(mu, captured):
    """Tangent planes moved out so that the lowest 15 % of the crossings would lie behind them:
    no crossing behind its plane by more than 1 um (here: round-off), the wall force
    non-negative and in balance with the yarns, and the state that of the Newton reference
    within its penalty's give (k_wall = 1e7 N/m: 3 N sink 0.3 um) plus the tolerance."""
    st, bc, f_top, s_old = captured(48, mu, 250)
    m = st.m
    r = np.hypot(st.pos[:m, 0], st.pos[:m, 1])
    nrm = np.column_stack([st.pos[:m, 0] / r, st.pos[:m, 1] / r, np.zeros(m)])
    plane = np.hstack([nrm * np.quantile(r, 0.15), nrm])
    plane[:, 2] = st.pos[:m, 2]
    bcw = dataclasses.replace(bc, plane=plane)
    ref = _newton(st, bcw, f_top, s_old, 1e-9)
    res = _relax(st, bcw, s_old, R.RelaxSettings(), tol=1e-9)
    assert res.converged
    dist = np.einsum("ij,ij->i", res.pos - plane[:, :3], plane[:, 3:])
    assert dist.min() > -1e-6
    assert res.active.sum() >= 10
    assert np.all(res.wall_force >= 0.0) and res.wall_force.max() > 0.1
    d_ref = np.einsum("ij,ij->i", ref.pos[:m] - plane[:, :3], plane[:, 3:])
    assert set(np.nonzero(d_ref < 0)[0]) == set(np.nonzero(res.active)[0])
    # wall force: the Newton penalty's push k_wall |d| at the same crossings (its own give
    # shifts the force by k_wall x the motion it causes: 1e-2 N)
    assert np.allclose(res.wall_force[res.active], -1e7 * d_ref[res.active], atol=2e-2)
    assert np.abs(res.pos - ref.pos[:m]).max() < 2e-6


def test_block_jacobi_matches_its_definition(captured):
    """``block_jacobi``: each move solves the crossing's own 3 x 3 system, built here from the
    twin's segments (geometric stiffness (f/l)(I - d d^T), jamming k d d^T, reg f/l I), and a
    crossing on the wall moves in its tangent plane, solving the system projected onto it."""
    st, bc, f_top, s_old = captured(16, 0.25, 60)
    m, ny = st.m, st.n_yarns
    lat = R.lattice_of(st)
    eps2 = E.length_smoothing
    EA, k_jam = _model_args(bc)
    fell, top = np.ascontiguousarray(bc.fell), np.ascontiguousarray(bc.top)
    d_below, l_below = np.empty((m, 2, 3)), np.empty((m, 2))
    d_top, l_top = np.empty((ny, 3)), np.empty(ny)
    RK.segment_vectors(m, ny, lat.yarn, st.pos[:m], lat.normal, lat.over, lat.low, lat.highest,
                       fell, top, bc.h, eps2, E.top_smoothing2, d_below, l_below, d_top, l_top)
    rng = np.random.default_rng(5)
    ten = rng.uniform(3.0, 6.0, size=(m, 2))
    l_jam = float(np.quantile(l_below[st.low[:m] >= 0], 0.3))
    force = rng.normal(size=(m, 3))
    active = rng.uniform(size=m) < 0.3
    nrm = rng.normal(size=(m, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    plane = np.hstack([st.pos[:m], nrm])
    delta = np.empty((m, 3))
    reg = 0.05
    SK.block_jacobi(lat, KZ.law(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, l_jam, k_jam, 1e-3),
                    KZ.Problem(fell, top, np.zeros(ny), np.zeros((m, 2)), np.zeros((m, 2)),
                               f_top),
                    KZ.Segments(d_below, l_below, d_top, l_top), ten, reg, np.inf, force, plane,
                    active, np.empty((m, 3, 3)),
                    np.empty(m), delta)
    H = np.zeros((m, 3, 3))
    I3 = np.eye(3)
    for k, (side, chain, pts, l, lt) in enumerate(naive.segments(st, fell, top, bc.h, eps2)):
        for i, c in enumerate(chain):
            d = (pts[i + 1] - pts[i]) / l[i]
            fj = k_jam * (l_jam - l[i]) if (i > 0 and l[i] < l_jam) else 0.0
            block = (max(ten[c, side] - fj, 1e-3) / l[i] * (I3 - np.outer(d, d))
                     + (k_jam if fj > 0 else 0.0) * np.outer(d, d) + reg * ten[c, side] / l[i] * I3)
            H[c] += block
            if i > 0:
                H[chain[i - 1]] += block
        if chain:
            d = (pts[-1] - pts[-2]) / lt
            H[chain[-1]] += f_top[k] / lt * ((1 + reg) * I3 - np.outer(d, d))
    for c in range(m):
        if active[c]:
            n = nrm[c]
            T = np.linalg.svd(I3 - np.outer(n, n))[0][:, :2]     # a basis of the plane
            ref = T @ np.linalg.solve(T.T @ H[c] @ T, T.T @ force[c])
            assert abs(delta[c] @ n) < 1e-12 * np.linalg.norm(delta[c])
        else:
            ref = np.linalg.solve(H[c], force[c])
        assert np.allclose(delta[c], ref, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("settings", [
    dict(preconditioner="scalar", smoothing=0, refactor_every=1),
    dict(preconditioner="scalar", smoothing=2, refactor_every=3),
    dict(preconditioner="block", block_refactor_every=1, block_reg=1e-2),
    dict(preconditioner="block", block_reg=1e-3)])
def test_settings_change_the_iteration_not_its_solution(settings, captured):
    """The scalar preconditioner without the block-Jacobi corrections or with them, the block
    one factorised once or at every iteration, with another isotropic share: the relaxation
    lands on the same state (they change the map, not its fixed point)."""
    st, bc, f_top, s_old = captured(48, 0.25, 250)
    ref = _newton(st, bc, f_top, s_old, TIGHT)
    res = _relax(st, bc, s_old, R.RelaxSettings(**settings), tol=TIGHT)
    assert res.converged and not res.fallback_scalar
    assert np.abs(res.pos - ref.pos[: st.m]).max() < 1e-6


def test_jammed_step_refactorises_and_lands_on_newton(captured):
    """A 48-carrier step with a yarn width that makes a tenth of the segments between
    crossings jam at the start (as a fifth do late in a 144-carrier case A run): the block
    preconditioner is factorised anew where the jammed set changes, and the step lands on the
    Newton solution (positions within 1e-6 m at 1e-10)."""
    st, bc, f_top, s_old = captured(48, 0.25, 250)
    m = st.m
    d = np.diff(np.vstack([st.pos[st.low[:m, 0]], st.pos[:m]]).reshape(2, m, 3), axis=0)[0]
    inner = st.low[:m, 0] >= 0
    width = float(np.quantile(np.linalg.norm(d, axis=1)[inner], 0.1))
    bcj = dataclasses.replace(bc, width=width)
    ref = _newton(st, bcj, f_top, s_old, TIGHT)
    res = _relax(st, bcj, s_old, R.RelaxSettings(), tol=TIGHT)
    assert res.converged and not res.fallback_scalar
    assert res.factorisations > 1
    assert np.abs(res.pos - ref.pos[:m]).max() < 1e-6


def test_anderson_matches_its_twin():
    """``preconditioners.Anderson`` (the numba passes over a ring of differences) against the
    NumPy twin on a contracting affine map, past the ring's wrap-around: the same iterates
    (round-off of the Gram matrix's sums), converging to the map's fixed point."""
    rng = np.random.default_rng(7)
    n, depth = 40, 5
    A = rng.normal(size=(n, n))
    A *= 0.9 / np.abs(np.linalg.eigvals(A)).max()
    c = rng.normal(size=n)
    fixed = np.linalg.solve(np.eye(n) - A, c)
    mine, twin = PC.Anderson(depth), naive.Anderson(depth)
    x = y = np.zeros(n)
    for _ in range(4 * depth):
        x = mine(x, A @ x + c).copy()
        y = twin(y, A @ y + c)
        assert np.abs(x - y).max() < 1e-9 * np.abs(y).max()
    for _ in range(200):
        x = mine(x, A @ x + c).copy()
    # plain iteration would be at 0.9^220 = 1e-10 of the start at best, Anderson is faster
    assert np.abs(x - fixed).max() < 1e-8 * np.abs(fixed).max()


def _block_inputs(captured):
    """A perturbed 16-carrier step's segments with random tensions, a jamming length that jams
    a third of the segments, and a fifth of the crossings on random planes."""
    st, bc, f_top, s_old = captured(16, 0.25, 60)
    st = st.copy()
    m, ny = st.m, st.n_yarns
    rng = np.random.default_rng(11)
    st.pos[:m] += rng.normal(scale=2e-3, size=(m, 3))
    lat = R.lattice_of(st)
    fell, top = np.ascontiguousarray(bc.fell), np.ascontiguousarray(bc.top)
    d_below, l_below = np.empty((m, 2, 3)), np.empty((m, 2))
    d_top, l_top = np.empty((ny, 3)), np.empty(ny)
    RK.segment_vectors(m, ny, lat.yarn, st.pos[:m], lat.normal, lat.over, lat.low, lat.highest,
                       fell, top, bc.h, E.length_smoothing, E.top_smoothing2, d_below, l_below,
                       d_top, l_top)
    ten = rng.uniform(-0.5, 6.0, size=(m, 2))          # some slack segments: the floor acts
    l_jam = float(np.quantile(l_below[st.low[:m] >= 0], 0.3))
    active = rng.uniform(size=m) < 0.2
    nrm = rng.normal(size=(m, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    plane = np.hstack([st.pos[:m], nrm])
    return st, bc.h, lat, fell, top, d_below, l_below, d_top, l_top, ten, f_top, l_jam, active, plane


def test_block_preconditioner_matches_its_twin_and_solves_it(captured):
    """``block_values`` in the band-dissection order against the dense twin
    (``naive_relax.block_stiffness``), entry by entry; the block LDL^T (``ldl_numeric3``,
    ``ldl_solve3``) against a dense solve of it; a matrix that is not positive definite is
    refused."""
    st, h, lat, fell, top, d_below, l_below, d_top, l_top, ten, f_top, l_jam, active, plane = \
        _block_inputs(captured)
    m, ny = st.m, st.n_yarns
    k_jam = 50.0
    K_ref, P = naive.block_stiffness(st, fell, top, ten, f_top, h, E.length_smoothing, l_jam,
                                     k_jam, 1e-3, 1e-3, plane, active)
    blk = PC.BlockStiffness(lat, st.pos[:m])
    assert np.array_equal(np.sort(blk.perm), np.arange(m))
    SK.block_values(lat, KZ.law(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, l_jam, k_jam, 1e-3),
                    KZ.Problem(fell, top, np.zeros(ny), np.zeros((m, 2)), np.zeros((m, 2)),
                               f_top),
                    KZ.Segments(d_below, l_below, d_top, l_top), ten, 1e-3, plane, active,
                    blk.slots, blk.vals, blk.Dg)
    K = np.zeros((3 * m, 3 * m))
    for col in range(m):
        for q in range(blk.Ap[col], blk.Ap[col + 1]):
            i, j = blk.perm[blk.Ai[q]], blk.perm[col]
            K[3 * i:3 * i + 3, 3 * j:3 * j + 3] = blk.vals[q]
            K[3 * j:3 * j + 3, 3 * i:3 * i + 3] = blk.vals[q].T
    # sums of a few products of O(1e3 N/m) entries: round-off
    assert np.abs(K - K_ref).max() < 1e-12 * np.abs(K_ref).max()
    assert blk.factor()
    rng = np.random.default_rng(2)
    b = (P @ rng.normal(size=3 * m)).reshape(m, 3)
    x = np.empty((m, 3))
    blk.solve(b, x)
    x_ref = np.linalg.solve(K_ref, b.ravel()).reshape(m, 3)
    # K's condition number is about 1e3 / 1e-3 = 1e6 here (reg 1e-3): 1e-16 * 1e6 with margin
    assert np.abs(x - x_ref).max() < 1e-8 * np.abs(x_ref).max()
    blk.vals[blk.slot_diag[m // 2]] *= -1.0
    assert not blk.factor()


def test_tangent_part_and_cap_moves_match_numpy(captured):
    """``tangent_part``: the force less its normal part at the resting crossings only;
    ``cap_moves``: the whole update scaled so that no crossing moves further than the cap times
    its shortest segment, the crossing that sets it exactly at the cap."""
    st, h, lat, fell, top, d_below, l_below, d_top, l_top, ten, f_top, l_jam, active, plane = \
        _block_inputs(captured)
    m = st.m
    rng = np.random.default_rng(4)
    force = rng.normal(size=(m, 3))
    out = np.empty((m, 3))
    RK.tangent_part(m, force, plane, active, out)
    n = plane[:, 3:]
    ref = force - np.where(active, np.einsum("ij,ij->i", force, n), 0.0)[:, None] * n
    assert np.allclose(out, ref, rtol=0, atol=1e-15)
    lmin = np.full(m, np.inf)
    for c in range(m):
        for side in range(2):
            lmin[c] = min(lmin[c], l_below[c, side])
            if lat.low[c, side] >= 0:
                lmin[lat.low[c, side]] = min(lmin[lat.low[c, side]], l_below[c, side])
    delta = rng.normal(size=(m, 3)) * 1e-3
    size = np.linalg.norm(delta, axis=1)
    cap = 0.5 * float(np.min(size / lmin)) * 3.0        # some moves beyond the cap
    want = min(1.0, float(np.min(cap * lmin / size)))
    d2 = delta.copy()
    scale = RK.cap_moves(m, lat.low, l_below, cap, np.empty(m), d2)
    assert want < 1.0 and np.isclose(scale, want, rtol=1e-12)
    assert np.allclose(d2, want * delta, rtol=1e-12)
    assert np.max(np.linalg.norm(d2, axis=1) / lmin) <= cap * (1 + 1e-12)
    d3 = delta.copy()
    assert RK.cap_moves(m, lat.low, l_below, 1e9, np.empty(m), d3) == 1.0
    assert np.array_equal(d3, delta)


def test_band_dissection_orders_with_little_fill(captured):
    """``band_dissection`` gives a permutation, and the block factor's fill in its order is
    within 1.5x of METIS nested dissection's (``frontal.dissection_order``; at most METIS's on
    case A at 144 carriers, ``test_relax_flat.test_band_dissection_fill_at_most_metis``) and
    well below the natural order's."""
    st, bc, f_top, s_old = captured(48, 0.25, 250)
    m = st.m
    lat = R.lattice_of(st)

    def fill(perm):
        return naive.block_fill(lat.low, perm)

    blk = PC.BlockStiffness(lat, st.pos[:m])
    assert np.array_equal(np.sort(blk.perm), np.arange(m))
    metis = frontal.dissection_order(lat.low)[::5] // 5
    assert fill(blk.perm) < 1.5 * fill(metis)
    assert fill(blk.perm) < 0.5 * fill(np.arange(m))


def test_interaction_zone_runs_with_the_relaxation():
    """``[model] solver = "relax"`` (``simulation.make_zone``): a 16-carrier case A run with
    friction 0.25 takes the same steps as with the Newton solver, the same crossings, and
    positions within 1e-5 m after 80 steps (both to 1e-7 of the tensions; the friction history
    carries the difference of each step along), with at most a few steps solved by the Newton
    fallback (measured: 1)."""
    runs = []
    fallbacks = []
    for solver in ("newton", "relax"):
        cfg = case_a_interaction_config(16, 0.25, solver)
        mandrel, cl = load_geometry(cfg)
        cfg = resolve_pose_lead(cfg, mandrel, cl)
        s = make_stepper(cfg, mandrel, cl)
        want = R.solve_zone if solver == "relax" else frontal.solve_zone_inplace
        assert s.zone.solve_zone is want

        def counted(*a, solve=want, **k):
            report = solve(*a, **k)
            fallbacks.append(report.fallback)
            return report
        s.zone.solve_zone = counted
        for _ in range(80):
            s.advance(take_up_speed(cfg.process.take_up_speed, s.braided))
        runs.append(s.zone)
    a, b = runs
    assert sum(fallbacks) <= 3
    assert a.state.m == b.state.m > 0
    assert np.array_equal(a.state.uid[: a.state.m], b.state.uid[: b.state.m])
    assert np.abs(a.state.pos[: a.state.m] - b.state.pos[: b.state.m]).max() < 1e-5
    assert np.allclose(a.fell, b.fell, atol=1e-5)


def test_unknown_preconditioner_and_solve_mode_are_refused():
    """A preconditioner (``RelaxSettings.preconditioner``) or a zone solve mode
    (``frontal.SOLVE_MODES``) other than the known ones is a ValueError that names it and the
    choices, not a silent default."""
    with pytest.raises(ValueError, match="'diagonal': expected 'block', 'full' or 'scalar'"):
        PC.make("diagonal", None)
    with pytest.raises(ValueError, match="'snapshot': expected one of step, pass, final"):
        frontal.check_mode("snapshot")
