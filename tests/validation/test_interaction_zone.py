"""Interaction zone (docs/theory.md §4): state, frontal kernels vs NumPy twins, balance of snapshots
read back from the written .vtp files, friction law, convergence of the frontal iteration.

Synthetic set-up (no mandrel walk): 16 carriers, fell points held fixed on a circle of radius
75 mm at z = 0.15 m, crossings created at every carrier pass, deposition by a cylinder distance
(or a faceted cylinder mandrel, whose tangent planes are the wall).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace as NS

import numpy as np
import pytest
import scipy.sparse as sp

from support import naive_frontal as naive
from preform._kernels import frontal as frontal_kernels
from preform.config import MachineConfig
from preform.errors import SimulationError
from preform.geometry import shapes
from preform.interaction import frontal, linalg
from preform.interaction.contact import psi as friction_function
from preform.geometry.mandrel import mandrel_from_arrays
from preform.interaction.mandrel_distance import NEAR, MandrelDistance, NearSettings
from preform.interaction.model import InteractionZone, creation_point
from preform.interaction.settings import DEFAULT
from preform.interaction.zone_state import ZoneState
from preform.io.vtk_yarns import write_convergence
from preform.machine import Machine
from support.snapshot_checks import balance_and_psi, read_snapshot

R_MANDREL = 0.075


class _Identity:
    def to_mandrel(self, x):
        return np.asarray(x)

    def to_machine(self, x):
        return np.asarray(x)


def _cylinder_distance(p):
    return np.hypot(p[:, 0], p[:, 1]) - R_MANDREL


def _flared(z):
    """Mandrel radius (m) at z: R_MANDREL from the fell circle (z = 0.15 m) on, flaring towards
    the spool plane with slope 1.25 (steeper than the yarns, which leave the fell circle with
    slope ~1.5 in r(z) but at a braid angle, so the lowest crossings reach it)."""
    return R_MANDREL + 1.25 * max(0.0, 0.15 - z)


class _Mandrel:
    """A faceted surface of revolution r(z) = ``_flared`` about the z axis, z in [0, 0.6] m:
    its tangent planes make the mandrel wall of the solve (``MandrelDistance``)."""

    def __init__(self):
        v, f = shapes.revolution(_flared, 0.6, n_around=96, n_along=240)
        self.vertices, self.faces = v, f
        a, b, c = (v[f[:, i]] for i in range(3))
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n, axis=1)[:, None]
        radial = np.einsum("ij,ij->i", n[:, :2], ((a + b + c) / 3.0)[:, :2])
        self.face_normals = np.where(radial[:, None] >= 0, n, -n)       # outward


def run_zone(mu=0.2, tension=4.7, steps=60, carriers=16, settings=None, solve_zone=None,
             wall=False, near=NEAR):
    """A zone after ``steps`` steps; wall: deposit and wall on the flared mandrel ``_Mandrel``
    (``MandrelDistance`` with the look-up settings ``near``) instead of the plain cylinder
    distance (no wall)."""
    mc = MachineConfig(carriers=carriers, spool_radius=0.3, angular_speed=0.2309401, pattern="regular")
    machine = Machine.from_config(mc)
    cfg = NS(yarn=NS(width=4e-3, thickness=2.5e-4, tension=tension, friction=mu, ring_friction=0.0),
             machine=mc)
    distance = MandrelDistance(_Mandrel(), near) if wall else _cylinder_distance
    zone = InteractionZone(cfg, machine, None, distance=distance, settings=settings,
                           solve_zone=solve_zone)
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


def test_near_bounds_the_distance_to_the_surface_from_below():
    """``MandrelDistance.near``'s lower bound never exceeds the exact distance to the faces
    (``Mandrel.closest_points``) of points around the flared mandrel, from mm to 0.3 m off, also
    from its cache after the points moved; every point within the clearance is near; and
    ``below`` equals the full nearest-face-plane test wherever the point is near the surface."""
    m = _Mandrel()
    exact = mandrel_from_arrays(m.vertices, m.faces, check=False)
    d = MandrelDistance(m)
    rng = np.random.default_rng(3)
    z = rng.uniform(0.05, 0.55, 400)
    phi = rng.uniform(0, 2 * np.pi, 400)
    r = np.array([_flared(zz) for zz in z]) + np.concatenate(
        [rng.uniform(-2e-3, 8e-3, 300), rng.uniform(0.01, 0.3, 100)])
    P = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    D = np.linalg.norm(exact.closest_points(P)[0] - P, axis=1)
    cache = np.full(len(P), -np.inf), np.full(len(P), np.inf), np.zeros((len(P), 3))
    for step in range(3):
        near, lower = d.near(P, 5e-3, cache)
        assert np.all(lower <= D + 1e-12)        # a bound from below (round-off of the query)
        assert np.all(near[D < 5e-3])
        # the cache changes which points are looked up, not the answer
        fresh, fresh_lower = d.near(P, 5e-3)
        assert np.array_equal(near, fresh) and np.all(fresh_lower <= D + 1e-12)
        P = P + rng.normal(scale=1e-3, size=P.shape)   # moved: the cache's bound decays
        D = np.linalg.norm(exact.closest_points(P)[0] - P, axis=1)
    height = 2.5e-4
    full = d(P) < height
    assert np.array_equal(d.below(P, height), full & (D < 0.05))
    assert full.any()


@pytest.mark.parametrize("clearance", [NEAR.wall_clearance, 1e-3])
def test_near_planes_give_the_states_of_every_crossings_plane(clearance):
    """The zone on the flared mandrel (wall and deposits active) with the tangent planes of the
    crossings near it only (``NearSettings``) and with every crossing's plane (a clearance of
    10 m): the same states, bit for bit, the same deposits, also where a step moves a crossing
    without its plane as far as it is from the mandrel and is solved again with every plane (6
    and 16 of the 90 steps)."""
    near, _, _, last = run_zone(mu=0.3, steps=90, wall=True,
                                near=NearSettings(wall_clearance=clearance))
    every, _, _, last_every = run_zone(mu=0.3, steps=90, wall=True,
                                       near=NearSettings(wall_clearance=10.0))
    assert near.wall_resolves > 0 and every.wall_resolves == 0
    assert near.state.m == every.state.m > 0
    assert np.array_equal(near.state.pos[: near.state.m], every.state.pos[: every.state.m])
    assert np.array_equal(near.state.tension[: near.state.m],
                          every.state.tension[: every.state.m])
    assert near.state.next_uid == every.state.next_uid


def _creation_point_numpy(px, gx, po, go, lowest=0.0):
    """NumPy twin of ``_kernels.frontal.creation_point``: the closest points of two segments
    (Ericson, Real-Time Collision Detection, 5.1.9), clamped below at ``lowest``."""
    d1, d2, r = gx - px, go - po, px - po
    a, e, b = d1 @ d1, d2 @ d2, d1 @ d2
    c, f = d1 @ r, d2 @ r
    if a <= 1e-30 and e <= 1e-30:
        tx = to = 0.0
    elif a <= 1e-30:
        tx, to = 0.0, float(np.clip(f / e, 0.0, 1.0))
    elif e <= 1e-30:
        tx, to = float(np.clip(-c / a, 0.0, 1.0)), 0.0
    else:
        den = a * e - b * b
        tx = float(np.clip((b * f - c * e) / den, 0.0, 1.0)) if den > 1e-30 else 1.0
        to = (b * tx + f) / e
        if to < 0.0:
            tx, to = float(np.clip(-c / a, 0.0, 1.0)), 0.0
        elif to > 1.0:
            tx, to = float(np.clip((b - c) / a, 0.0, 1.0)), 1.0
    tx, to = max(tx, lowest), max(to, lowest)
    C = 0.5 * (px + tx * d1 + po + to * d2)
    N = np.cross(d1, d2)
    nn = np.linalg.norm(N)
    N = N / nn if nn > 0 else np.array([C[0], C[1], 0.0]) / max(np.hypot(C[0], C[1]), 1e-300)
    return C, (-N if N[0] * C[0] + N[1] * C[1] < 0 else N)


def test_creation_point_kernel_matches_numpy_twin():
    """Random segment pairs, parallel ones, degenerate (zero-length) ones and a lower clamp:
    the kernel equals the NumPy twin to round-off (1e-12 m on points within 1 m)."""
    rng = np.random.default_rng(7)
    cases = [tuple(rng.uniform(-1, 1, (4, 3))) + (lo,) for lo in (0.0, 0.3) for _ in range(50)]
    p, g = rng.uniform(-1, 1, (2, 3))
    cases += [(p, g, p + [0, 0, 0.1], g + [0, 0, 0.1], 0.0),       # parallel
              (p, p, p + 0.1, g, 0.0), (p, g, g, g, 0.0), (p, p, g, g, 0.2)]   # no length
    for px, gx, po, go, lo in cases:
        C, N = creation_point(px, gx, po, go, lowest=lo)
        C0, N0 = _creation_point_numpy(px, gx, po, go, lowest=lo)
        assert np.allclose(C, C0, atol=1e-12) and np.allclose(N, N0, atol=1e-12)


def _perturbed(mu=0.3, steps=60, seed=0):
    """A zone after some steps with its crossings, material coordinates and bounds shaken."""
    zone, F, t, _ = run_zone(mu=mu, steps=steps)
    st = zone.state
    rng = np.random.default_rng(seed)
    st.pos[: st.m] += rng.normal(scale=2e-3, size=(st.m, 3))
    bc = zone.boundary(t, F)
    st.material_fell[:] = frontal.fell_material(st, bc)
    # material coordinates that give every segment a tension in 3..6 N (in tension, where the
    # Hessian is exact, see _kernels/frontal.py)
    EA = frontal.axial_stiffness(bc.f_spool)
    eps2 = DEFAULT.energy.length_smoothing
    for k, (side, chain) in enumerate(naive.chains(st)):
        prev, u_prev = bc.fell[k], st.material_fell[k]
        for c in chain:
            p = naive.yarn_point(st, c, side, bc.h)
            l = np.sqrt(np.sum((p - prev) ** 2) + eps2)
            st.material[c, side] = u_prev + l / (1 + rng.uniform(3.0, 6.0) / EA)
            prev, u_prev = p, st.material[c, side]
    ten = naive.tensions(st, bc.fell, EA, DEFAULT.energy.compression, bc.h, eps2)
    assert 3.0 - 1e-6 < ten.min() and ten.max() < 6.0 + 1e-6
    return zone, bc


def _net(zone, bc, seed=1, settings=DEFAULT):
    st = zone.state
    rng = np.random.default_rng(seed)
    f_top = rng.uniform(4.0, 5.0, st.n_yarns)
    net = frontal._Network(st, bc, settings)
    net.f_top = f_top
    net.centre = st.material[: st.m] + rng.normal(scale=3 * settings.frontal.friction_creep,
                                                  size=(st.m, 2))
    net.bound = rng.uniform(0.0, 0.5, size=(st.m, 2))
    return net, f_top


def _naive_energy(zone, bc, net, f_top, jam=True, **iterate):
    """The NumPy twin's energy of the network's problem (wall where ``bc.plane`` is given)."""
    e = DEFAULT.energy
    return naive.energy(zone.state, bc.fell, bc.top, f_top, net.bound, net.centre, net.EA,
                        e.compression, DEFAULT.frontal.friction_creep, e.kappa0, bc.h,
                        e.length_smoothing, e.top_smoothing2,
                        bc.width if jam else 0.0, e.jam_force * bc.f_spool / bc.width,
                        plane=bc.plane, k_wall=e.wall_stiffness, **iterate)


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
    zone, bc = _perturbed()
    st = zone.state
    lengths = _inner_lengths(st, bc.h)
    bc = dataclasses.replace(bc, width=float(np.median(lengths)))
    assert np.sum(lengths < bc.width) >= 3                      # jams active
    net, f_top = _net(zone, bc)
    E, _ = net.assemble()
    E_jam = _naive_energy(zone, bc, net, f_top)
    E_free = _naive_energy(zone, bc, net, f_top, jam=False)
    assert E_jam > E_free                                       # the term is there
    assert E == pytest.approx(E_jam, rel=1e-12)
    v = np.random.default_rng(3).normal(size=(st.m, 5))
    x0 = np.hstack([st.pos[: st.m], st.material[: st.m]]).copy()
    hstep = 1e-9       # as in the test below
    Es = []
    for sgn in (1, -1):
        st.pos[: st.m] = x0[:, :3] + sgn * hstep * v[:, :3]
        st.material[: st.m] = x0[:, 3:] + sgn * hstep * v[:, 3:]
        Es.append(_naive_energy(zone, bc, net, f_top))
    st.pos[: st.m], st.material[: st.m] = x0[:, :3], x0[:, 3:]
    assert (Es[0] - Es[1]) / (2 * hstep) == pytest.approx(float(np.sum(net.grad * v)), rel=1e-4,
                                                          abs=1e-6 * abs(E))


def test_line_search_energy_matches_the_assembled_energy_and_numpy_sum():
    """The line-search kernel ``frontal_kernels.energy`` (what Armijo evaluates) against the
    energy ``assemble`` returns and the NumPy twin's sum over segments, with every term active:
    friction, jamming (some segments shorter than the yarn width) and the mandrel wall (some
    crossings behind their tangent plane), at the state's iterate and at another one."""
    zone, bc = _perturbed()
    st = zone.state
    m = st.m
    rng = np.random.default_rng(5)
    lengths = _inner_lengths(st, bc.h)
    depth = rng.uniform(-1e-4, 1e-4, m)                   # m: < 0 behind the wall
    plane = np.hstack([st.pos[:m] - depth[:, None] * st.normal[:m], st.normal[:m]])
    bc = dataclasses.replace(bc, width=float(np.median(lengths)), plane=plane)
    assert np.sum(lengths < bc.width) >= 3 and np.sum(depth < 0) >= 3     # jams and wall act
    net, f_top = _net(zone, bc)
    E_assembled, _ = net.assemble()
    E_line = net.energy(st.pos[:m].copy(), st.material[:m].copy())
    E_ref = _naive_energy(zone, bc, net, f_top)
    no_wall = dataclasses.replace(bc, plane=None)
    assert E_ref > _naive_energy(zone, no_wall, net, f_top)        # the wall term is there
    # the same terms summed in another order: round-off of sums of ~1e3 terms (1e-12 relative)
    assert E_line == pytest.approx(E_assembled, rel=1e-12)
    assert E_line == pytest.approx(E_ref, rel=1e-12)
    pos = st.pos[:m] + rng.normal(scale=2e-5, size=(m, 3))
    material = st.material[:m] + rng.normal(scale=2e-5, size=(m, 2))
    assert net.energy(pos, material) == pytest.approx(
        _naive_energy(zone, bc, net, f_top, pos=pos, material=material), rel=1e-12)
    assert net.energy(pos, material) != pytest.approx(E_line, rel=1e-9)  # another iterate


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
    v = np.random.default_rng(2).normal(size=(st.m, 5))
    x0 = np.hstack([st.pos[: st.m], st.material[: st.m]]).copy()

    def put(x):
        st.pos[: st.m] = x[:, :3]
        st.material[: st.m] = x[:, 3:]

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


def _with_solver(name):
    return dataclasses.replace(DEFAULT, newton=dataclasses.replace(DEFAULT.newton,
                                                                   linear_solver=name))


#: both factorisations of ``interaction/linalg.py``; CHOLMOD only where cvxopt is installed
SOLVERS = [pytest.param("cholmod", marks=pytest.mark.skipif(
    "cholmod" not in linalg.AVAILABLE, reason="cvxopt (the cholmod extra) is not installed")),
    "splu"]


@pytest.mark.parametrize("solver", SOLVERS)
def test_newton_direction_solves_the_assembled_system(solver):
    """The Newton direction solves H dx = -g for the assembled Hessian, by CHOLMOD's Cholesky or
    by SuperLU's LU, in the nested-dissection order: the order is a permutation of the 5
    unknowns of every crossing, and both give the direction of a plain dense solve (to the
    round-off of refined factorisations of a matrix with condition ~1e9: EA / q against the
    tension stiffness f / l)."""
    zone, bc = _perturbed()
    st = zone.state
    net, _ = _net(zone, bc, settings=_with_solver(solver))
    assert net.pattern(net.assemble()[1]).factoriser.backend == solver
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
    frontal_kernels.triplet_matvec(nnz, net.rows, net.cols, net.vals, dx, out)   # kernel vs scipy
    assert np.allclose(out, H @ dx, rtol=1e-12, atol=1e-12 * np.abs(H @ dx).max())
    # the pattern's entries are the lower triangle of H in the dissection order (kernel vs scipy)
    pattern = net.pattern(nnz)
    v = np.empty(pattern.size)
    frontal_kernels.accumulate(nnz, pattern.slot, net.vals, v)
    lower = sp.tril(H[dof][:, dof]).tocsc()
    assert np.array_equal(lower.indices, pattern.r) and np.array_equal(
        np.repeat(np.arange(n), np.diff(lower.indptr)), pattern.c)
    assert np.allclose(v, lower.data, rtol=1e-12, atol=1e-12 * np.abs(lower.data).max())
    # a second Newton step reuses the pattern (and CHOLMOD's analysis) with new values
    net.vals[:nnz] *= 2.0
    assert np.allclose(frontal._newton_direction(net, nnz, g), 0.5 * dx, rtol=1e-6,
                       atol=1e-9 * np.abs(dx).max())
    assert net.pattern(nnz) is pattern


def test_linear_solver_auto_is_cholmod_when_cvxopt_imports_else_superlu():
    """``linalg.backend``: "auto" is CHOLMOD where cvxopt is installed, else SuperLU; asking for
    CHOLMOD without it, or for an unknown backend, is an error that names the value and the fix."""
    assert linalg.backend("auto") == linalg.DEFAULT == linalg.AVAILABLE[0]
    assert linalg.backend("splu") == "splu"
    with pytest.raises(ValueError, match="'bogus'.*'auto', 'cholmod' or 'splu'"):
        linalg.backend("bogus")
    if "cholmod" in linalg.AVAILABLE:
        assert linalg.DEFAULT == "cholmod"
    else:
        assert linalg.DEFAULT == "splu"
        with pytest.raises(ValueError, match=r"cvxopt is not installed.*preform\[cholmod\]"):
            linalg.backend("cholmod")


def test_tension_bound_and_psi_kernels_match_numpy_twins():
    """Segment tensions, friction bounds and Psi / (f_int + f_ext) of the kernels against the
    NumPy twins (Psi from the vectorised tension form ``interaction.contact.psi``)."""
    zone, bc = _perturbed()
    st = zone.state
    net, f_top = _net(zone, bc)
    net.update_tensions()
    ref = naive.tensions(st, bc.fell, net.EA, DEFAULT.energy.compression, bc.h,
                         DEFAULT.energy.length_smoothing)
    assert np.allclose(net.tension, ref, rtol=1e-9, atol=1e-9)
    bound = np.empty((st.m, 2))
    psi = np.empty((st.m, 2))
    # every crossing its own coefficient (mixed yarns), against the twin
    mu = np.random.default_rng(5).uniform(0.0, 0.6, st.m)
    frontal_kernels.friction_bounds(st.m, st.yarn, st.pos, st.normal, st.over, st.low, st.up,
                                    bc.fell, bc.top, net.tension, f_top, bc.h, mu, bound, psi)
    assert np.allclose(bound, naive.bounds(st, bc.fell, bc.top, net.tension, f_top, bc.h, mu),
                       rtol=1e-9)
    psi_ref = np.empty((st.m, 2))
    for k, (side, chain) in enumerate(naive.chains(st)):
        pts = naive.polyline(st, k, side, chain, bc.fell, bc.top, bc.h)
        ten = [net.tension[c, side] for c in chain] + [f_top[k]]
        for i, c in enumerate(chain):
            u_int, u_ext = pts[i] - pts[i + 1], pts[i + 2] - pts[i + 1]
            u_int, u_ext = u_int / np.linalg.norm(u_int), u_ext / np.linalg.norm(u_ext)
            psi_ref[c, side] = friction_function(ten[i], ten[i + 1], u_int, u_ext, mu[c]) / (
                ten[i] + ten[i + 1])
    assert np.any(psi_ref > 0) and np.any(psi_ref < 0)     # both sides of the cone seen
    # the same formula evaluated by two codes: double rounding of unit vectors (1e-15)
    assert np.allclose(psi, psi_ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_snapshot_file_crossings_in_balance(mu, tmp_path):
    zone, F, t, _ = run_zone(mu=mu, steps=90)
    snap = zone.snapshot(t, F)
    paths = write_convergence([snap], tmp_path)
    yarns = read_snapshot(paths[1])
    assert sum(int(np.sum(c >= 0)) for _, _, c in yarns) == 2 * zone.state.m > 0
    err, psi = balance_and_psi(yarns, mu)
    assert err < 1e-3     # required: relative force-balance error < 1e-3
    assert psi < 1e-3     # required: Psi <= 1e-3 tension


def test_frictionless_tension_equals_spool_tension_along_yarns():
    zone, F, t, _ = run_zone(mu=0.0, steps=90)
    snap = zone.snapshot(t, F)
    # mu = 0: f_int = f_ext at every crossing (docs/theory.md §4); to the Newton tolerance (1e-8)
    # and KAPPA0 x slide (1e-9 N)
    assert np.allclose(snap.tension_N, 4.7, rtol=1e-7)


def _external_tensions(st, tension, f_top):
    """(m, 2) N: the tension above every crossing on both yarns (the next segment's, or f_top)."""
    out = np.empty((st.m, 2))
    for side in range(2):
        u = st.up[: st.m, side]
        out[:, side] = np.where(u >= 0, tension[np.maximum(u, 0), side], f_top[st.yarn[: st.m, side]])
    return out


def test_friction_makes_tensions_differ_and_keeps_every_crossing_in_the_cone():
    """With mu = 0.3 the tensions differ along the yarns, each crossing's tension jump lies within
    the discrete Capstan cone |f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2) of its geometry
    (docs/theory.md §4; bounds from the NumPy twin), and the tension falls towards the mandrel."""
    zone, F, t, _ = run_zone(mu=0.3, steps=90)
    st = zone.state
    bc = zone.boundary(t, F)
    # the step's bounds lag the geometry by a frontal iteration (settings.frontal.max_iterations);
    # solved with the bounds to convergence, the cone holds to the frontal tolerance
    rep = frontal.solve_zone_inplace(st, bc, max_iter=DEFAULT.frontal.snapshot_iterations,
                                     mode="pass")
    assert not rep.lagged
    ten = st.tension[: st.m]
    f_ext = _external_tensions(st, ten, rep.f_top)
    bound = naive.bounds(st, bc.fell, bc.top, ten, rep.f_top, bc.h, 0.3)
    assert np.ptp(ten) > 1e-4          # friction acts
    jump = np.abs(ten - f_ext)
    assert np.any(jump > 0.5 * bound)  # some yarns use their friction
    # the bound to the frontal tolerance (1e-6 of f_int + f_ext)
    assert np.all(jump <= bound + 1e-6 * (ten + f_ext))
    # new crossings slide down the yarns: the tension falls towards the mandrel (to the Newton
    # tolerance)
    assert np.all(ten <= 4.7 * (1 + 1e-7))


def test_spool_tension_scales_out_with_the_mandrel_wall():
    """Amontons friction is homogeneous in the forces, and EA scales with the spool tension
    (``tow_strain``): the same positions for 2 N and 8 N and 4x the tensions, here with the
    mandrel wall active: a flared mandrel (``_Mandrel``) whose crossings are deposited only once
    they lie on it (``deposit_height`` 0), so the lowest crossings are held by the wall in the
    solves that bring them there. The control run with a wall of no stiffness ends elsewhere."""
    on_wall = dataclasses.replace(DEFAULT, zone=dataclasses.replace(DEFAULT.zone,
                                                                    deposit_height=0.0))
    soft = dataclasses.replace(on_wall, energy=dataclasses.replace(on_wall.energy,
                                                                   wall_stiffness=0.0))
    z2, *_ = run_zone(mu=0.3, tension=2.0, steps=90, wall=True, settings=on_wall)
    z8, *_ = run_zone(mu=0.3, tension=8.0, steps=90, wall=True, settings=on_wall)
    free, *_ = run_zone(mu=0.3, tension=2.0, steps=90, wall=True, settings=soft)
    assert z2.state.m == z8.state.m == free.state.m > 0
    a, b = z2.state.pos[: z2.state.m], z8.state.pos[: z8.state.m]
    # the same solution up to the solver tolerance (1e-7 relative imbalance: measured 1.7e-9 m;
    # the wall's give f / wall_stiffness is below 1 um and deposited with its crossing)
    assert np.abs(a - b).max() < 1e-8
    assert np.allclose(z8.state.tension[: z8.state.m], 4.0 * z2.state.tension[: z2.state.m],
                       rtol=1e-6)
    # the wall acted: without its stiffness the crossings end 0.1 mm elsewhere (measured)
    assert np.abs(free.state.pos[: free.state.m] - a).max() > 1e-5


def test_residual_falls_over_frontal_iterations():
    zone, F, t, _ = run_zone(mu=0.3, steps=40)
    st = zone.state
    st.pos[: st.m] += 1e-3 * np.random.default_rng(2).normal(size=(st.m, 3))
    rep = frontal.solve_zone_inplace(st, zone.boundary(t, F),
                                     max_iter=DEFAULT.frontal.snapshot_iterations)
    h = rep.history
    assert not rep.lagged
    assert h[-1] < DEFAULT.frontal.friction_tolerance
    assert np.all(np.diff(h) < 0)


def test_newton_lowers_the_energy_at_every_iteration():
    """The solve's Newton trace (SolveReport.newton_energy/newton_residual): Armijo backtracking
    on E never lets it rise (beyond its round-off, settings.newton.roundoff), and the last
    iterate is the balanced one."""
    zone, F, t, _ = run_zone(mu=0.3, steps=40)
    st = zone.state
    st.pos[: st.m] += 1e-3 * np.random.default_rng(3).normal(size=(st.m, 3))
    rep = frontal.solve_zone_inplace(st, zone.boundary(t, F))
    E, res = rep.newton_energy, rep.newton_residual
    assert len(E) == len(res) == rep.newton + 1 > 3
    assert np.all(np.diff(E) <= DEFAULT.newton.roundoff * np.abs(E[1:]))
    assert res[-1] < DEFAULT.newton.balance_tolerance <= res[0]


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_a_failed_step_is_solved_again_in_stages(mu):
    """InteractionZone._staged: where a step's solve fails, the step is solved again with the
    boundary moved in stages from where the last step left it. Every stage is posed from the
    step's posed state (the stages' results are only starts), so the last stage is the step's
    own problem, with or without friction, and lands where the direct solve does. The failure
    is injected through the zone's solver (the constructor's solve_zone)."""
    calls = []
    armed = [False]

    def fail_first(*a, **k):
        if armed[0]:
            calls.append(k.get("where", ""))
            if len(calls) == 1:
                raise SimulationError("no balance (a stand-in for a failed solve)")
        return frontal.solve_zone_inplace(*a, **k)

    zone, F, t, _ = run_zone(mu=mu, steps=40)
    twin, F2, t2, _ = run_zone(mu=mu, steps=40, solve_zone=fail_first)
    assert np.array_equal(F, F2) and t == t2 and twin.staged == 0
    dt = 0.01 / zone.machine.omega
    zone.step(t, dt, F, _Identity())
    assert zone.staged == 0
    armed[0] = True
    twin.step(t, dt, F, _Identity())
    assert twin.staged == 1
    assert len(calls) == 1 + len(DEFAULT.zone.boundary_stages)
    assert all("stages" in w for w in calls[1:])
    assert (twin.last_report.residual < DEFAULT.frontal.friction_tolerance
            or twin.last_report.lagged)
    a, b = zone.state, twin.state
    assert a.m == b.m and np.array_equal(a.uid[: a.m], b.uid[: b.m])
    # one problem (bounds and top tensions of the posed state held), one minimum of E: the
    # balance tolerance 1e-7 apart (measured 2e-14 m without friction, 3.5e-9 m with 0.3; when
    # each stage took new crossings' bounds from the last stage's result: 1.7 mm)
    assert np.abs(a.pos[: a.m] - b.pos[: b.m]).max() < 1e-6
    assert np.array_equal(a.slip[: a.m], b.slip[: b.m])


def test_non_convergence_names_step_and_residual():
    zone, F, t, _ = run_zone(mu=0.3, steps=40)
    st = zone.state
    st.pos[: st.m] += 1e-2
    with pytest.raises(SimulationError, match=r"step 7 .*residual"):
        frontal.solve_zone_inplace(st, zone.boundary(t, F), max_iter=1, tol=1e-30,
                                   where="at step 7 (t = 1 s)")


@pytest.mark.parametrize("memory", [DEFAULT.frontal.friction_memory, 0.0])
def test_friction_memory_keeps_a_loaded_sticking_yarn_in_place(memory):
    """Elastic-plastic friction (settings.frontal.friction_memory): a yarn that sticks under a
    load keeps its friction force into the next step, so solving the same step again leaves it
    where it is. Without the memory every step starts without friction force and the yarn creeps
    again by about as much as in the first solve (the control case: the test can tell them
    apart)."""
    settings = dataclasses.replace(DEFAULT, frontal=dataclasses.replace(DEFAULT.frontal,
                                                                        friction_memory=memory))
    creep = settings.frontal.friction_creep
    zone, F, t, _ = run_zone(mu=0.3, steps=60, settings=settings)
    st = zone.state
    bc = zone.boundary(t, F)
    centre = st.material[: st.m] - st.offset[: st.m]
    iterations = settings.frontal.snapshot_iterations
    frontal.solve_zone_inplace(st, bc, settings=settings, max_iter=iterations)
    u1 = st.material[: st.m].copy()
    x = u1 - centre                   # the friction slip of the first solve
    cap = 0.95 / np.sqrt(1 - 0.95**2) * creep
    loaded = (np.abs(x) > 0.3 * creep) & (np.abs(x) < 0.5 * cap)
    assert loaded.sum() > 10
    frontal.solve_zone_inplace(st, bc, settings=settings, max_iter=iterations)
    moved = np.abs(st.material[: st.m] - u1)[loaded]
    if memory:
        # to the solver's tolerances (balance 1e-7, bounds 1e-6 of the tensions) times the
        # friction compliance friction_creep / bound
        assert moved.max() < 1e-2 * creep
    else:
        assert np.median(moved) > 0.2 * creep


def test_lower_pattern_kernel_matches_numpy_unique():
    """``frontal_kernels.lower_pattern`` (O(nnz)) against the obvious NumPy: unique keys c n + r
    of the permuted lower triplets, and each triplet's entry."""
    rng = np.random.default_rng(3)
    n, nnz = 60, 900
    rows = rng.integers(0, n, nnz)
    cols = rng.integers(0, n, nnz)
    rank = rng.permutation(n)
    slot, er, ec, size = frontal_kernels.lower_pattern(nnz, rows, cols, rank, n)
    r, c = rank[rows], rank[cols]
    lower = r >= c
    key, inverse = np.unique(c[lower] * n + r[lower], return_inverse=True)
    assert size == key.size
    assert np.array_equal(er, key % n) and np.array_equal(ec, key // n)
    assert np.array_equal(slot[lower], inverse) and np.all(slot[~lower] == -1)


class _NoisyEnergy(frontal._Network):
    """A network whose line-search energy is pure noise: always a little above E."""

    def __init__(self, state, bc, E):
        super().__init__(state, bc)
        self.E = E

    def energy(self, pos, material):
        return self.E + 1e-6 * abs(self.E)


@pytest.mark.parametrize("offset", [1e-9, 1e-4])
def test_newton_step_below_the_energys_round_off_is_taken_whole(offset):
    """Where the decrease of E that Newton predicts is below E's round-off, E cannot judge the
    step (``settings.newton.roundoff_slope``): the full step is taken, else Newton stalls. Here
    E's evaluations are made pure noise (always a little higher): near balance (1e-9 m off) the
    step is still taken whole; far from it (1e-4 m) the line search refuses it, as it must."""
    zone, F, t, _ = run_zone(mu=0.0, steps=40)
    st = zone.state
    m = st.m
    bc = zone.boundary(t, F)
    st.material[:m] += 1e3     # m of yarn: E ~ 1e5 J (the spool's work), physics unchanged
    st.material_fell[:] = frontal.fell_material(st, bc)
    rep = frontal.solve_zone_inplace(st, bc)
    st.pos[:m] += offset * np.random.default_rng(4).normal(size=(m, 3))
    net = frontal._Network(st, bc)
    net.f_top = rep.f_top
    E, nnz = net.assemble()
    noisy = _NoisyEnergy(st, bc, E)
    noisy.f_top = rep.f_top
    assert noisy.assemble() == (E, nnz)
    g = noisy.grad[:m].ravel().copy()
    dx = frontal._newton_direction(noisy, nnz, g)
    newton = DEFAULT.newton
    near = -float(g @ dx) < newton.roundoff_slope * newton.roundoff * abs(E)
    assert near == (offset < 1e-6)
    pos0 = st.pos[:m].copy()
    frontal._newton_step_inplace(noisy, E, nnz)
    moved = np.abs(st.pos[:m] - pos0).max()
    full = np.abs(dx.reshape(m, 5)[:, :3]).max()
    if near:
        assert moved == pytest.approx(full, rel=1e-6)
    else:
        assert moved < 1e-9 * full
