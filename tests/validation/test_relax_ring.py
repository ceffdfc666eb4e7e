"""The relaxation behind a guide ring: the ``"full"`` preconditioner, the
Hessian of the zone's energy in the positions and the materials (``_kernels.stiffness.full_values``,
5 x 5 blocks, ``ldl_numeric5`` / ``ldl_solve5``), against a dense NumPy twin; its Schur
complement on the positions against the finite-difference Jacobian of the relaxation's force
map (materials swept), which is what makes its position update a Newton step; whole steps of a
case-B-like run through a guide ring against the Newton reference.

A captured step is the problem ``InteractionZone.step`` poses its solver (``tests/validation/test_relax.py``
says how), here of the case-B-like mandrel (``simcase.case_b_like_config``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from preform._kernels import relax as RK
from preform._kernels import stiffness as SK
from preform._kernels import zone as KZ
from preform.interaction import frontal, relax as R
from preform.interaction import preconditioners as PC
from preform.interaction.settings import DEFAULT
from support.simcase import advanced_stepper, capture_step, case_b_like_config

E = DEFAULT.energy
EPS_F = DEFAULT.frontal.friction_creep


def _stepper(folder, mu, steps):
    cfg = case_b_like_config(folder, 0.17)
    return advanced_stepper(dataclasses.replace(cfg, yarn=dataclasses.replace(cfg.yarn, friction=mu)),
                            steps)


def _capture(s, speed):
    st, bc, _, centres = capture_step(s, speed)
    return st, bc, centres


@pytest.fixture(scope="module")
def ring_steps(tmp_path_factory):
    """``ring_steps(mu, steps)``: (state, boundary with wall planes, friction centres) of the
    next step of the case-B-like run after ``steps`` steps, on copies."""
    runs = {}
    folder = tmp_path_factory.mktemp("ring")

    def get(mu, steps):
        key = (mu, steps)
        if key not in runs:
            runs[key] = _stepper(folder, mu, steps)
        return _capture(*runs[key])

    return get


class _Force:
    """The relaxation's force map F(C): segments, the material swept exactly for the lengths
    (``material_sweep`` to 1e-13, from the same start each time, so that F depends on C
    alone), net forces."""

    def __init__(self, st, bc, s_old, g, f_top, l_jam):
        self.st, self.bc, self.s_old, self.g, self.f_top = st, bc, s_old, g, f_top
        m, ny = st.m, st.n_yarns
        self.m, self.ny = m, ny
        self.lat = R.lattice_of(st)
        self.EA = frontal.axial_stiffness(bc.f_spool)
        self.l_jam = l_jam
        self.k_jam = E.jam_force * bc.f_spool / max(l_jam, 1e-300)
        self.d_below, self.l_below = np.empty((m, 2, 3)), np.empty((m, 2))
        self.d_top, self.l_top = np.empty((ny, 3)), np.empty(ny)
        self.tension = np.empty((m, 2))
        self.force = np.empty((m, 3))

    def __call__(self, pos):
        lat, bc, m, ny = self.lat, self.bc, self.m, self.ny
        self.s = np.array(self.st.material[:m])
        RK.segment_vectors(m, ny, lat.yarn, pos, lat.normal, lat.over, lat.low, lat.highest,
                           np.ascontiguousarray(bc.fell), np.ascontiguousarray(bc.top), bc.h,
                           E.length_smoothing, E.top_smoothing2, self.d_below, self.l_below,
                           self.d_top, self.l_top)
        RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, self.l_below, self.s,
                          self.st.material_fell, self.s_old, self.g, self.f_top, self.EA,
                          E.compression, EPS_F, E.kappa0, 1e-13, 200, self.tension,
                          np.empty(m, np.int64), np.empty((m, 6)), np.zeros(2, np.int64), None)
        RK.forces(m, ny, lat.yarn, lat.low, lat.highest, self.d_below, self.l_below,
                  self.d_top, self.l_top, self.tension, self.f_top, self.l_jam, self.k_jam,
                  1e-3, self.force, np.empty((m, 2)), np.empty(ny), np.empty(m), np.empty(m))
        return self.force.copy()


def _dense_hessian(F, reg, floor, plane, active, axial=True):
    """NumPy twin of ``full_values``: the dense Hessian (5m x 5m; unknowns 5 c + (0, 1, 2) the
    position, 5 c + 3 + side the material) at F's last geometry, written from the energy
    directly: per segment ``W(l, q) = k (l - q)^2 / (2 q)`` in l = |P_c - P_lo|, q = s_c -
    s_lo, its geometric part floored and an isotropic share ``reg``; friction, top segments
    and the wall as the kernel's docstring says. axial False: without the segments' axial
    stiffness and coupling to the material (the position block is then ``block_values``' K)."""
    lat, st, m = F.lat, F.st, F.m
    H = np.zeros((5 * m, 5 * m))
    I3 = np.eye(3)
    P = [I3 - np.outer(plane[c, 3:], plane[c, 3:]) if active[c] else I3 for c in range(m)]
    for c in range(m):
        for side in range(2):
            lo = lat.low[c, side]
            l = F.l_below[c, side]
            u = F.d_below[c, side] / l
            f = F.tension[c, side]
            below = F.s[lo, side] if lo >= 0 else st.material_fell[lat.yarn[c, side]]
            q = F.s[c, side] - below
            k = F.EA if l >= q else E.compression * F.EA
            gap = F.l_jam - l
            fj = F.k_jam * gap if (gap > 0 and lo >= 0) else 0.0
            kj = F.k_jam if fj > 0 else 0.0
            A = np.zeros((4, 4))
            A[:3, :3] = ((k / q * axial + kj) * np.outer(u, u) + max(f - fj, floor) / l
                         * (I3 - np.outer(u, u)) + reg * max(f, floor) / l * I3)
            A[:3, 3] = A[3, :3] = -k * l / q ** 2 * u * axial
            A[3, 3] = k * l * l / q ** 3
            # A acts on (P_c - P_lo, s_c - s_lo): +A on both diagonals, -A between them
            ends = [(c, 1.0)] + ([(lo, -1.0)] if lo >= 0 else [])
            for a, sa in ends:
                for b, sb in ends:
                    Pa = np.eye(4)
                    Pa[:3, :3] = P[a]
                    Pb = np.eye(4)
                    Pb[:3, :3] = P[b]
                    ia = [5 * a, 5 * a + 1, 5 * a + 2, 5 * a + 3 + side]
                    ib = [5 * b, 5 * b + 1, 5 * b + 2, 5 * b + 3 + side]
                    H[np.ix_(ia, ib)] += sa * sb * (Pa @ A @ Pb)
            x = F.s[c, side] - F.s_old[c, side]
            r = np.hypot(x, EPS_F)
            H[5 * c + 3 + side, 5 * c + 3 + side] += F.g[c, side] * EPS_F ** 2 / r ** 3 + E.kappa0
        if active[c]:
            H[5 * c:5 * c + 3, 5 * c:5 * c + 3] += np.outer(plane[c, 3:], plane[c, 3:])
    for k in range(F.ny):
        c = lat.highest[k]
        if c < 0:
            continue
        u = F.d_top[k] / F.l_top[k]
        w = max(F.f_top[k], floor) / F.l_top[k]
        K = w * (I3 - np.outer(u, u)) + reg * w * I3
        H[5 * c:5 * c + 3, 5 * c:5 * c + 3] += P[c] @ K @ P[c]
    return H


def _from_pattern(blk, m):
    H = np.zeros((5 * m, 5 * m))
    for col in range(m):
        for q in range(blk.Ap[col], blk.Ap[col + 1]):
            i, j = blk.perm[blk.Ai[q]], blk.perm[col]
            H[5 * i:5 * i + 5, 5 * j:5 * j + 5] = blk.vals[q]
            H[5 * j:5 * j + 5, 5 * i:5 * i + 5] = blk.vals[q].T
    return H


def _inputs(ring_steps, mu=0.25):
    st, bc, s_old = ring_steps(mu, 150)
    g, f_top = R.start_bounds(st, bc)
    return st, bc, s_old[: st.m], g, f_top


def test_full_hessian_matches_its_twin_and_its_ldl_solves_it(ring_steps):
    """``full_values`` in the band-dissection order against the dense twin, entry by entry,
    with jamming (a jamming length that makes a third of the segments jam) and a fifth of the
    crossings on random tangent planes; ``ldl_numeric5`` / ``ldl_solve5`` against a dense solve;
    a matrix that is not positive definite is refused."""
    st, bc, s_old, g, f_top = _inputs(ring_steps)
    m, ny = st.m, st.n_yarns
    assert m >= 20
    F = _Force(st, bc, s_old, g, f_top, 0.0)
    F(st.pos[:m])
    F.l_jam = float(np.quantile(F.l_below[st.low[:m] >= 0], 0.3))
    F.k_jam = 50.0
    rng = np.random.default_rng(4)
    active = rng.uniform(size=m) < 0.2
    nrm = rng.normal(size=(m, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    plane = np.hstack([st.pos[:m], nrm])
    reg, floor = 1e-3, 1e-3
    H_ref = _dense_hessian(F, reg, floor, plane, active)
    lat = F.lat
    blk = PC.BlockStiffness(lat, st.pos[:m], 5)
    SK.full_values(lat, KZ.law(F.EA, E.compression, EPS_F, E.kappa0, 0.0, 0.0, 0.0, F.l_jam,
                               F.k_jam, floor),
                   KZ.problem(np.zeros((ny, 3)), np.zeros((ny, 3)), st.material_fell, s_old, g,
                              f_top),
                   KZ.Segments(F.d_below, F.l_below, F.d_top, F.l_top), F.tension, F.s, reg,
                   plane, active, blk.slots, blk.vals, blk.Dg)
    H = _from_pattern(blk, m)
    # sums of a few products of entries up to EA / q ~ 1e6: round-off
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()
    assert blk.factor()
    b = rng.normal(size=(m, 3))
    for c in np.nonzero(active)[0]:
        b[c] -= (b[c] @ nrm[c]) * nrm[c]
    x = np.empty((m, 3))
    blk.solve(b, x)
    rhs = np.zeros((m, 5))
    rhs[:, :3] = b
    x_ref = np.linalg.solve(H_ref, rhs.ravel()).reshape(m, 5)[:, :3]
    # H spans kappa0 (1e-7) to EA / q (1e6): its condition number is large, but a solve of
    # the same factorisation order loses only a few digits on this right-hand side
    assert np.abs(x - x_ref).max() < 1e-6 * np.abs(x_ref).max()
    blk.vals[blk.slot_diag[m // 2]] *= -1.0
    assert not blk.factor()


@pytest.mark.parametrize("mu", [0.0, 0.25])
def test_full_update_is_a_newton_step_of_the_force_map(mu, ring_steps):
    """Without the wall, jamming and the isotropic share, the position part of H^-1 (F, 0) is
    J^-1 F with J = -dF/dC the Jacobian of the force map with the materials swept (the Schur
    complement of H on the positions), checked against central differences of F: the
    materials' response (the axial stiffness of a yarn that sticks, which the ``"block"``
    preconditioner leaves out) is in it. Tolerance: the differences' truncation and the
    sweep's round-off, 1e-13 of the tensions over a 1e-7 m step, on stiffnesses of 1e2-1e4
    N/m: 1e-6 of the largest entry (measured 2e-8 and 5e-8). Without friction no yarn sticks
    and the geometric stiffness alone is J too."""
    st, bc, s_old, g, f_top = _inputs(ring_steps, mu)
    m = st.m
    F = _Force(st, bc, s_old, g, f_top, 0.0)
    pos = np.array(st.pos[:m])
    J = np.empty((3 * m, 3 * m))
    h = 1e-7
    for j in range(3 * m):
        p = pos.copy()
        p.reshape(-1)[j] += h
        fp = F(p).ravel()
        p.reshape(-1)[j] -= 2 * h
        J[:, j] = -(fp - F(p).ravel()) / (2 * h)
    F(pos)
    H = _dense_hessian(F, 0.0, 1e-12, np.zeros((m, 6)), np.zeros(m, bool))
    ip = (5 * np.arange(m)[:, None] + np.arange(3)).ravel()
    im = (5 * np.arange(m)[:, None] + 3 + np.arange(2)).ravel()
    S = H[np.ix_(ip, ip)] - H[np.ix_(ip, im)] @ np.linalg.solve(H[np.ix_(im, im)],
                                                                 H[np.ix_(im, ip)])
    assert np.abs(S - J).max() < 1e-6 * np.abs(J).max()
    # the geometric stiffness alone (the "block" preconditioner's K) is not J where yarns
    # stick (mu > 0): measured 0.29 of J's largest entry apart on this step (2e-8 at mu 0)
    K = _dense_hessian(F, 0.0, 1e-12, np.zeros((m, 6)), np.zeros(m, bool), axial=False)
    gap = np.abs(K[np.ix_(ip, ip)] - J).max() / np.abs(J).max()
    assert gap > 0.1 if mu > 0 else gap < 1e-6


# both solvers to 1e-10 of the tensions (``tests/validation/test_relax.py``: at 1e-7 soft modes leave
# them up to 3 um apart)
TIGHT = 1e-10
#: the posed iteration of both to 1e-9 of the tensions (a captured step at yarn friction 0.25:
#: 1.9e-10 after 59 solves, positions 3.6e-8 m apart)
POSED_TIGHT = 1e-9


@pytest.mark.parametrize("mu", [0.0, 0.25, 0.5])
def test_ring_steps_land_on_the_newton_solution(mu, ring_steps):
    """Captured steps of the case-B-like run through a guide ring, solved with the ring's
    preconditioner (``RelaxSettings.ring_preconditioner``, ``"full"``): the same state as the
    Newton reference (positions within 1e-6 m), every crossing in balance to the
    tolerance."""
    st, bc, s_old = ring_steps(mu, 150)
    m = st.m
    ref = st.copy()
    # both iterate the top tensions (Capstan) and every crossing's bound to those of the
    # converged geometry (``FrontalSettings.posed_iterations``), here to POSED_TIGHT
    model = dataclasses.replace(DEFAULT, frontal=dataclasses.replace(
        DEFAULT.frontal, posed_tolerance=POSED_TIGHT, posed_iterations=100))
    rep = frontal.solve_zone_inplace(ref, bc, centre=s_old, tol=TIGHT, settings=model)
    assert rep.posed_converged
    b0, f0 = R.start_bounds(st, bc)
    rs = R.RelaxSettings(max_iter=300, ring_stall=60)
    res = R.relax(R.lattice_of(st), st.pos[:m], st.material[:m], st.material_fell, s_old[:m],
                  bc.fell, bc.top, f0, b0, f_spool=bc.f_spool, mu=bc.mu, h=bc.h,
                  width=bc.width, plane=bc.plane,
                  settings=dataclasses.replace(rs, preconditioner=rs.ring_preconditioner),
                  model=model, top_tensions=R.ring_top_tensions(st, bc),
                  fresh=R._posed_bounds(st, model), tol=TIGHT)
    assert res.converged and res.residual < TIGHT
    assert res.posed.converged and res.bound_change < POSED_TIGHT
    assert np.abs(res.pos - ref.pos[:m]).max() < 1e-6
    assert np.abs(res.tension - ref.tension[:m]).max() < 1e-6 * bc.f_spool
