"""Interaction zone (DESIGN.md §3.3): state, frontal sweeps vs a NumPy twin, balance of snapshots.

Synthetic set-up (no mandrel walk): 16 carriers, fell points held fixed on a circle of radius
75 mm at z = 0.15 m, crossings created at every carrier pass, deposition by a cylinder distance.
"""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from naive_frontal import frictionless_sweeps
from preform._kernels import frontal as K
from preform.config import MachineConfig
from preform.errors import SimulationError
from preform.interaction import frontal
from preform.interaction.model import InteractionZone, creation_point
from preform.interaction.zone_state import ZoneState
from preform.machine import Machine

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
               bool(rng.integers(2)), (1.0, 1.0), 0.0)
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


def _state_dict(st):
    m = st.m
    return {k: getattr(st, k)[:m].copy() for k in ("yarn", "pos", "normal", "over", "low", "up")}


def test_frictionless_sweeps_match_numpy_twin():
    zone, F, t, _ = run_zone(mu=0.0, steps=90)
    st = zone.state
    assert st.m >= 16
    bc = zone.boundary(t, F)
    f_top = np.full(st.n_yarns, 4.7)
    rng = np.random.default_rng(0)
    st.pos[: st.m] += rng.normal(scale=2e-3, size=(st.m, 3))   # off balance
    ref = _state_dict(st)
    relax = np.ones(st.m)
    K.force_sweep(st.m, 0, st.n_yarns, st.yarn, st.pos, st.normal, st.over, st.theta_ref, st.low,
                  st.up, bc.fell, bc.top, f_top, bc.h, 0.0, 1e-9, st.theta, st.slip, st.tension,
                  st.resultant, relax)
    out = np.empty((st.m, 3))
    K.position_sweep(st.m, 0, st.yarn, st.pos, st.normal, st.over, st.theta, st.low, bc.fell,
                     st.resultant, relax, bc.h, out)
    pos, tension, angles, relax_ref = frictionless_sweeps(ref, bc.fell, bc.top, f_top, bc.h)
    # both are exact closed forms of the same equations: agreement to round-off (1e-9 m)
    assert np.allclose(relax, relax_ref, rtol=1e-12)
    assert np.allclose(st.theta[: st.m], angles, atol=1e-8)
    assert np.allclose(st.tension[: st.m], tension, rtol=1e-12)
    assert np.abs(out - pos).max() < 1e-9


def _balance_and_psi(snap, mu):
    """Max relative force imbalance and max Psi / tension over the crossings of a snapshot."""
    pts, off, ten, cid = snap.points, snap.offsets, snap.tension_N, snap.contact_id
    forces = {}
    psis = []
    for k in range(len(off) - 1):
        a, b = off[k], off[k + 1]
        seg0 = a - k   # first segment index of yarn k
        for i in range(a + 1, b - 1):
            if cid[i] < 0:
                continue
            lo = pts[i - 1] - pts[i]
            hi = pts[i + 1] - pts[i]
            f_lo, f_hi = ten[seg0 + i - a - 1], ten[seg0 + i - a]
            u_lo, u_hi = lo / np.linalg.norm(lo), hi / np.linalg.norm(hi)
            forces.setdefault(cid[i], []).append((f_lo * u_lo + f_hi * u_hi, f_lo + f_hi))
            cb = u_lo @ u_hi
            c, s = np.sqrt(max(0, (1 - cb) / 2)), np.sqrt(max(0, (1 + cb) / 2))
            psis.append((abs(f_lo - f_hi) * c - mu * (f_lo + f_hi) * s) / max(f_lo, f_hi))
    err = [np.linalg.norm(v[0][0] + v[1][0]) / (0.5 * (v[0][1] + v[1][1]))
           for v in forces.values() if len(v) == 2]
    assert all(len(v) == 2 for v in forces.values())
    return max(err), max(psis)


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_snapshot_crossings_in_balance(mu):
    zone, F, t, _ = run_zone(mu=mu, steps=90)
    snap = zone.snapshot(t, F)
    assert np.sum(snap.contact_id >= 0) == 2 * zone.state.m > 0
    err, psi = _balance_and_psi(snap, mu)
    assert err < 1e-3     # issue 4: relative force-balance error < 1e-3
    assert psi < 1e-3     # issue 4: Psi <= 1e-3 tension


def test_frictionless_tension_equals_spool_tension_along_yarns():
    zone, F, t, _ = run_zone(mu=0.0, steps=90)
    snap = zone.snapshot(t, F)
    # mu = 0: Psi = 0 means f_int = f_ext at every crossing (DESIGN.md §3.3); to round-off
    assert np.allclose(snap.tension_N, 4.7, rtol=1e-9)
    assert not np.any(snap.slip[snap.contact_id < 0])


def test_spool_tension_scales_out():
    # Amontons friction is homogeneous in the forces: same positions for 2 N and 8 N
    z2, *_ = run_zone(mu=0.3, tension=2.0, steps=90)
    z8, *_ = run_zone(mu=0.3, tension=8.0, steps=90)
    assert z2.state.m == z8.state.m
    # limited by the frontal tolerance (1e-8 m) accumulated over the steps
    assert np.abs(z2.state.pos[: z2.state.m] - z8.state.pos[: z8.state.m]).max() < 1e-6
    assert np.allclose(z8.state.tension[: z8.state.m], 4.0 * z2.state.tension[: z2.state.m],
                       rtol=1e-5)


def test_residual_falls_over_frontal_iterations():
    zone, F, t, _ = run_zone(mu=0.3, steps=89)
    dt = 0.01 / zone.machine.omega
    st = zone.state
    zone._create_crossings(t, t + dt, zone.boundary(t + dt, F))
    st.pos[: st.m] += 1e-3 * np.random.default_rng(2).normal(size=(st.m, 3))
    rep = frontal.solve_zone(st, zone.boundary(t + dt, F), zone.f_top.copy())
    h = rep.history
    assert h[-1] < frontal.FRONTAL_TOLERANCE
    assert h[-1] < 1e-4 * h[0]
    # falls overall: every 5 iterations below the best of the 5 before
    best = np.minimum.accumulate(h)
    assert np.all(best[5::5] < best[:-5:5])


def test_non_convergence_names_step_and_residual():
    zone, F, t, _ = run_zone(mu=0.3, steps=80)
    st = zone.state
    st.pos[: st.m] += 1e-2
    with pytest.raises(SimulationError, match=r"step 7 .*residual"):
        frontal.solve_zone(st, zone.boundary(t, F), zone.f_top.copy(), max_iter=2,
                           where="at step 7 (t = 1 s)")
