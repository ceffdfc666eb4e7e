"""The line search of the relaxation behind a guide ring: the reduced energy
it judges steps by (``_kernels.relax.reduced_energy``) against a NumPy twin and against the Newton
reference's own energy (``_kernels.frontal.energy``), its gradient against the force map the
relaxation balances, and steps of case-B-like runs that the iteration without the line search
does not converge on, which with it land on the Newton solution.

A captured step is the problem ``InteractionZone.step`` poses its solver (``tests/validation/test_relax.py``
says how), here of the case-B-like mandrel (``simcase.case_b_like_config``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from preform._kernels import frontal as FK
from preform._kernels import relax as RK
from preform._kernels import zone as KZ
from preform.interaction import frontal, relax as R
from preform.interaction.settings import DEFAULT
from support.simcase import advanced_stepper, capture_step, case_b_like_config

E = DEFAULT.energy
# one solve a step at the posed top tensions and bounds (no re-solve at the converged
# geometry's, ``FrontalSettings.posed_iterations``): the runs whose steps these tests capture,
# and the reference solves of those steps with the bounds the relaxation is given; such steps
# lag the ring's Capstan tension by up to 0.3 of the tensions, which the runs carry on through
# (``ZoneSettings.max_step_residual``) to reach the steps captured here
POSED_OFF = dataclasses.replace(
    DEFAULT, frontal=dataclasses.replace(DEFAULT.frontal, posed_iterations=1),
    zone=dataclasses.replace(DEFAULT.zone, max_step_residual=1.0))
EPS_F = DEFAULT.frontal.friction_creep


@pytest.fixture(scope="module")
def ring_steps(tmp_path_factory):
    """``ring_steps(mu, steps, carriers=16)``: (state, boundary with wall planes, friction
    centres) of the next step of the case-B-like run after ``steps`` steps, on copies."""
    runs = {}
    folder = tmp_path_factory.mktemp("ring_search")

    def get(mu, steps, carriers=16):
        key = (mu, carriers)
        if key not in runs or runs[key][2] > steps:
            cfg = case_b_like_config(folder, 0.17)
            cfg = dataclasses.replace(
                cfg, yarn=dataclasses.replace(cfg.yarn, friction=mu),
                machine=dataclasses.replace(cfg.machine, carriers=carriers))
            runs[key] = [*advanced_stepper(cfg, 0, settings=POSED_OFF), 0]
        s, speed, done = runs[key]
        for _ in range(steps - done):
            s.advance(speed())
        runs[key][2] = steps
        st, bc, _, centres = capture_step(s, speed)
        return st, bc, centres[: st.m]

    return get


class _Swept:
    """Segments and the materials swept exactly for the lengths (``material_sweep`` to 1e-13,
    from the same start each time, so that everything depends on the positions alone), the net
    forces and the reduced energy of positions ``pos``."""

    def __init__(self, st, bc, s_old, g, f_top, l_jam, k_jam):
        self.st, self.bc, self.s_old, self.g, self.f_top = st, bc, s_old, g, f_top
        m, ny = st.m, st.n_yarns
        self.m, self.ny = m, ny
        self.lat = R.lattice_of(st)
        self.EA = frontal.axial_stiffness(bc.f_spool)
        self.l_jam, self.k_jam = l_jam, k_jam
        n = ny // 2
        self.s_ref = np.array([st.material[st.highest[k], 0 if k < n else 1]
                               if st.highest[k] >= 0 else 0.0 for k in range(ny)])

    def __call__(self, pos):
        lat, bc, m, ny = self.lat, self.bc, self.m, self.ny
        self.pos = np.array(pos)
        self.s = np.array(self.st.material[:m])
        self.d_below, self.l_below = np.empty((m, 2, 3)), np.empty((m, 2))
        self.d_top, self.l_top = np.empty((ny, 3)), np.empty(ny)
        self.tension = np.empty((m, 2))
        self.force = np.empty((m, 3))
        RK.segment_vectors(m, ny, lat.yarn, self.pos, lat.normal, lat.over, lat.low,
                           lat.highest, np.ascontiguousarray(bc.fell),
                           np.ascontiguousarray(bc.top), bc.h, E.length_smoothing,
                           E.top_smoothing2, self.d_below, self.l_below, self.d_top, self.l_top)
        RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, self.l_below, self.s,
                          self.st.material_fell, self.s_old, self.g, self.f_top, self.EA,
                          E.compression, EPS_F, E.kappa0, 1e-13, 200, self.tension,
                          np.empty(m, np.int64), np.empty((m, 6)), np.zeros(2, np.int64), None)
        RK.forces(m, ny, lat.yarn, lat.low, lat.highest, self.d_below, self.l_below,
                  self.d_top, self.l_top, self.tension, self.f_top, self.l_jam, self.k_jam,
                  1e-3, self.force, np.empty((m, 2)), np.empty(ny), np.empty(m), np.empty(m))
        return RK.reduced_energy(lat, self.law(), self.problem(),
                                 KZ.Segments(self.d_below, self.l_below, self.d_top, self.l_top),
                                 self.s, self.s_ref)

    def law(self):
        return KZ.law(self.EA, E.compression, EPS_F, E.kappa0, self.bc.h, E.length_smoothing,
                      E.top_smoothing2, self.l_jam, self.k_jam, E.geometric_floor)

    def problem(self):
        return KZ.problem(self.bc.fell, self.bc.top, self.st.material_fell, self.s_old, self.g,
                          self.f_top)


def _energy_twin(S):
    """NumPy twin of ``reduced_energy`` at S's last state, written segment by segment from the
    energy of ``interaction/frontal.py``."""
    st, lat, m = S.st, S.lat, S.m
    total = 0.0
    for c in range(m):
        for side in range(2):
            lo = lat.low[c, side]
            below = S.s[lo, side] if lo >= 0 else st.material_fell[lat.yarn[c, side]]
            q = S.s[c, side] - below
            l = S.l_below[c, side]
            k = S.EA if l >= q else E.compression * S.EA
            total += k * (l - q) ** 2 / (2 * q)
            if lo >= 0:
                total += 0.5 * S.k_jam * max(S.l_jam - l, 0.0) ** 2
            x = S.s[c, side] - S.s_old[c, side]
            total += S.g[c, side] * (np.hypot(x, EPS_F) - EPS_F) + 0.5 * E.kappa0 * x * x
    n = S.ny // 2
    for k in range(S.ny):
        c = lat.highest[k]
        if c < 0:
            continue
        side = 0 if k < n else 1
        f = S.f_top[k]
        total += f * S.l_top[k] + (f + f * f / (2 * S.EA)) * (S.s[c, side] - S.s_ref[k])
    return total


def _jammed_inputs(ring_steps):
    """A captured step (mu 0.25, after 150 steps) with a jamming length that makes a third of
    its inner segments jam, and a jamming stiffness of 50 N/m."""
    st, bc, s_old = ring_steps(0.25, 150)
    g, f_top = R.start_bounds(st, bc)
    S = _Swept(st, bc, s_old, g, f_top, 0.0, 0.0)
    S(st.pos[: st.m])
    S.l_jam = float(np.quantile(S.l_below[st.low[: st.m] >= 0], 0.3))
    S.k_jam = 50.0
    return S


def test_reduced_energy_matches_its_twin_and_newtons_energy(ring_steps):
    """``reduced_energy`` against the NumPy twin and against the Newton reference's E
    (``_kernels.frontal.energy`` without its wall penalty, k_wall 0) less the payout of the
    reference materials: the same function. Tolerance: sums of about 10^3 terms of up to
    f_top l_top (~1.5 J) and the payout's metres, so round-off of 1e-13 of the total."""
    S = _jammed_inputs(ring_steps)
    st, lat, m = S.st, S.lat, S.m
    value = S(st.pos[:m])
    jammed = (S.l_below < S.l_jam) & (lat.low >= 0)
    assert jammed.sum() > 0.2 * (lat.low >= 0).sum()
    twin = _energy_twin(S)
    assert abs(value - twin) < 1e-13 * max(abs(twin), 1.0)
    bc = S.bc
    n = S.ny // 2
    payout = sum((S.f_top[k] + S.f_top[k] ** 2 / (2 * S.EA)) * S.s_ref[k]
                 for k in range(S.ny) if lat.highest[k] >= 0)
    newton = FK.energy(lat, S.law(), S.problem(), S.pos, S.s, bc.plane[:m], 0.0)
    assert n > 0
    assert abs((newton - payout) - value) < 1e-12 * (abs(newton) + abs(payout))
    # a material length that is not positive: inf, as Newton's E
    s = S.s.copy()
    c = int(np.nonzero(lat.low[:, 0] >= 0)[0][0])
    s[c, 0] = s[lat.low[c, 0], 0]
    assert RK.reduced_energy(lat, S.law(), S.problem(),
                             KZ.Segments(S.d_below, S.l_below, S.d_top, S.l_top), s,
                             S.s_ref) == np.inf


def test_reduced_energy_gradient_is_the_force_map(ring_steps):
    """With the materials swept for the lengths, the reduced energy's negative gradient in the
    positions is the net force the relaxation balances (``forces``: tensions and jamming
    pushes), checked by central differences on 40 coordinates: so a step along a direction
    with F . delta > 0 lowers it, and the line search judges the relaxation's own equations.
    Tolerance: the differences' truncation, E''' h^2 / 6 with stiffnesses up to 1e5 N/m over
    millimetres, and their round-off, 1e-16 of E (~4 J) over the 1e-6 m step: 1e-6 of the
    largest force (measured 1.2e-7; 1.2e-5 with h 1e-5, 3e-9 with h 1e-7)."""
    S = _jammed_inputs(ring_steps)
    m = S.m
    pos = np.array(S.st.pos[:m])
    S(pos)
    force = S.force.copy()
    rng = np.random.default_rng(7)
    h = 1e-6
    for j in rng.choice(3 * m, size=40, replace=False):
        p = pos.copy()
        p.reshape(-1)[j] += h
        up = S(p)
        p.reshape(-1)[j] -= 2 * h
        down = S(p)
        assert abs(-(up - down) / (2 * h) - force.reshape(-1)[j]) < 1e-6 * np.abs(force).max()


# both solvers to 1e-10 of the tensions (``tests/validation/test_relax.py``: at 1e-7 soft modes leave
# them up to 3 um apart)
TIGHT = 1e-10

#: the iteration as it was before the line search (``RelaxSettings``' other defaults)
PLAIN = dict(ring_line_search=False, ring_refactor_damped=False, ring_refactor_stall=0)


@pytest.mark.parametrize("mu, steps, carriers", [
    (0.5, 38, 16),      # a start-up step: 8 crossings, the jammed set flips
    (0.25, 22, 48),     # 24 crossings
    (0.25, 96, 48),     # 111 crossings: the chord from a stale K, refactorised
])
def test_steps_the_plain_iteration_stalls_on_land_on_newton(mu, steps, carriers, ring_steps):
    """Captured steps of case-B-like runs through a guide ring that the full preconditioner
    without the line search and its refactorisations (``PLAIN``) does not converge on (found
    by solving every step of the runs with both): with the defaults they converge, to the
    tight tolerance, on the Newton reference's state (positions within 1e-6 m, tensions within
    1e-6 of the spool tension, as ``tests/validation/test_relax_ring.py``)."""
    st, bc, s_old = ring_steps(mu, steps, carriers)
    m = st.m
    b0, f0 = R.start_bounds(st, bc)
    args = (R.lattice_of(st), st.pos[:m], st.material[:m], st.material_fell, s_old, bc.fell,
            bc.top, f0, b0)
    kw = dict(f_spool=bc.f_spool, mu=bc.mu, h=bc.h, width=bc.width, plane=bc.plane)
    base = R.RelaxSettings()
    full = dataclasses.replace(base, preconditioner=base.ring_preconditioner)
    plain = R.relax(*args, settings=dataclasses.replace(full, **PLAIN), **kw)
    assert not plain.converged
    res = R.relax(*args, settings=dataclasses.replace(full, max_iter=300), tol=TIGHT, **kw)
    assert res.converged and res.residual < TIGHT
    ref = st.copy()
    # the relaxation above solves the step with its posed bounds and top tensions, so the
    # Newton reference does too (``POSED_OFF``)
    frontal.solve_zone_inplace(ref, bc, centre=s_old, tol=TIGHT, settings=POSED_OFF)
    assert np.abs(res.pos - ref.pos[:m]).max() < 1e-6
    assert np.abs(res.tension - ref.tension[:m]).max() < 1e-6 * bc.f_spool
