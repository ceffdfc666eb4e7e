"""Machine kinematics and horn-gear pattern (docs/theory.md §1), against brute force scans."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from preform.config import GuideRingConfig, MachineConfig
from preform.machine import Machine, carrier_count_problem

OMEGA = np.radians(18.0)


def make_machine(carriers=16, pattern="regular", ring=None, omega=OMEGA, spool=0.85):
    guide = None if ring is None else GuideRingConfig(*ring)
    return Machine.from_config(MachineConfig(carriers=carriers, spool_radius=spool, angular_speed=omega,
                                             pattern=pattern, guide_ring=guide))


def test_groups_and_initial_phases():
    mach = make_machine(carriers=8)
    n = 4
    assert mach.n_per_group == n and mach.n_yarns == 8
    assert mach.group.dtype == np.int8
    assert list(mach.group) == [0] * n + [1] * n
    np.testing.assert_allclose(mach.phase0[:n], 2 * np.pi * np.arange(n) / n)
    np.testing.assert_allclose(mach.phase0[n:], 2 * np.pi * (np.arange(n) + 0.5) / n)


def test_warp_turns_clockwise_seen_from_plus_z():
    mach = make_machine()
    dt = 0.01
    p0, p1 = mach.spool_points(0.0), mach.spool_points(dt)
    turn_z = p0[:, 0] * p1[:, 1] - p0[:, 1] * p1[:, 0]  # z of p0 x p1: > 0 counter-clockwise from +z
    warp = mach.group == 0
    assert np.all(turn_z[warp] < 0) and np.all(turn_z[~warp] > 0)
    # angular speed: each carrier turns by omega dt (chord angle)
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", p0, p1) / mach.spool_radius**2, -1, 1))
    np.testing.assert_allclose(angle, OMEGA * dt, rtol=1e-6)


def test_supply_points_on_the_guide_ring_at_the_carrier_azimuth():
    mach = make_machine(ring=(0.17, 0.05))
    t = 3.7
    g, s = mach.supply_points(t), mach.spool_points(t)
    assert mach.supply_radius == 0.17 and mach.supply_z == 0.05
    np.testing.assert_allclose(np.hypot(g[:, 0], g[:, 1]), 0.17, rtol=1e-12)
    np.testing.assert_allclose(g[:, 2], 0.05)
    np.testing.assert_allclose(np.hypot(s[:, 0], s[:, 1]), 0.85, rtol=1e-12)
    np.testing.assert_allclose(s[:, 2], 0.0)
    # same azimuth: the ring point is the spool point scaled towards the axis
    np.testing.assert_allclose(g[:, :2] / 0.17, s[:, :2] / 0.85, atol=1e-12)


def test_without_ring_supply_is_the_spool():
    mach = make_machine()
    assert mach.supply_radius == 0.85 and mach.supply_z == 0.0
    np.testing.assert_allclose(mach.supply_points(1.3), mach.spool_points(1.3))


def brute_force_passes(mach, t0, t1, samples=200001):
    """(time, warp, weft) where the wrapped azimuth difference warp - weft crosses zero (scan)."""
    n = mach.n_per_group
    t = np.linspace(t0, t1, samples)
    dt = t[1] - t[0]
    found = []
    for i, j in itertools.product(range(n), range(n)):
        d = np.angle(np.exp(1j * (mach.phase0[i] - mach.phase0[n + j] - 2 * mach.omega * t)))
        # the difference falls at 2 omega; a zero crossing goes from >= 0 to < 0 (not the 2 pi wrap)
        idx = np.nonzero((d[:-1] >= 0) & (d[1:] < 0) & (d[:-1] - d[1:] < np.pi))[0]
        for k in idx:
            tc = t[k] + d[k] / (2 * mach.omega)  # linear within the sample
            found.append((tc, i, j))
    found.sort()
    return found, dt


@pytest.mark.parametrize("carriers", [8, 12])
def test_pass_times_match_a_brute_force_scan(carriers):
    mach = make_machine(carriers=carriers)
    t0, t1 = 0.3, 0.3 + 1.3 * np.pi / mach.omega  # more than one relative revolution
    ref, dt = brute_force_passes(mach, t0, t1)
    got = mach.pass_times(t0, t1)
    assert len(got.time) == len(ref)
    assert np.all(np.diff(got.time) >= 0)
    # n passes happen at once, so compare ordered by (pair, time)
    ours = sorted(zip(got.warp.tolist(), got.weft.tolist(), got.time.tolist()))
    theirs = sorted((i, j, tc) for tc, i, j in ref)
    assert [o[:2] for o in ours] == [r[:2] for r in theirs]
    np.testing.assert_allclose([o[2] for o in ours], [r[2] for r in theirs], atol=2 * dt)  # scan step
    # each pass sits at its location's azimuth pi (p + 1/2) / n
    n = mach.n_per_group
    phi = mach.phase0[got.warp] - mach.omega * got.time
    loc_phi = np.pi * (got.location + 0.5) / n
    np.testing.assert_allclose(np.angle(np.exp(1j * (phi - loc_phi))), 0.0, atol=1e-9)


def test_pass_times_half_open_interval_and_count():
    mach = make_machine(carriers=16)
    period = mach.pass_period()
    n = mach.n_per_group
    p = mach.pass_times(0.0, 10 * period)
    # every warp meets one weft each period: n passes per period in the machine
    assert len(p.time) == 10 * n
    first = p.time[0]
    assert len(mach.pass_times(first, first + period).time) == n  # [t0, t1): the start counts
    assert np.all(mach.pass_times(first + 1e-9, first + period).time > first)


def runs(flags):
    """Lengths of runs of equal values, dropping the first and last (cut by the window)."""
    edges = np.flatnonzero(np.diff(flags.astype(int))) + 1
    return np.diff(edges)


@pytest.mark.parametrize("carriers,pattern", [(8, "diamond"), (6, "diamond"), (16, "regular"),
                                              (12, "regular"), (12, "hercules"), (18, "hercules")])
def test_each_yarn_goes_over_m_then_under_m(carriers, pattern):
    mach = make_machine(carriers=carriers, pattern=pattern)
    m = mach.m
    p = mach.pass_times(0.0, 6 * mach.n_per_group * mach.pass_period())
    for i in range(mach.n_per_group):
        along_warp = p.warp_over[p.warp == i]
        along_weft = ~p.warp_over[p.weft == i]  # the weft is over where the warp is under
        for flags in (along_warp, along_weft):
            r = runs(flags)
            assert len(r) > 4 and np.all(r == m), (i, r)
    # a warp meets the pass locations in decreasing order, a weft in increasing order
    for i in range(mach.n_per_group):
        loc = p.location[p.warp == i]
        assert np.all((loc[:-1] - loc[1:]) % (2 * mach.n_per_group) == 1)
        loc = p.location[p.weft == i]
        assert np.all((loc[1:] - loc[:-1]) % (2 * mach.n_per_group) == 1)


def test_warp_over_by_pair_when_the_pattern_is_fixed_per_pair():
    mach = make_machine(carriers=16, pattern="regular")  # n/m = 4 even
    assert mach.pair_pattern_fixed()
    p = mach.pass_times(0.0, 20 * mach.pass_period())
    np.testing.assert_array_equal(mach.warp_over(p.warp, p.weft), p.warp_over)
    np.testing.assert_array_equal(mach.warp_over(p.warp, p.weft), ((p.warp + p.weft) // 2) % 2 == 0)
    np.testing.assert_array_equal(mach.warp_over(p.warp, p.weft, p.time), p.warp_over)


def test_warp_over_needs_the_pass_time_when_pairs_alternate():
    mach = make_machine(carriers=12, pattern="regular")  # n/m = 3 odd
    assert not mach.pair_pattern_fixed()
    with pytest.raises(ValueError, match="pass time"):
        mach.warp_over(0, 1)
    p = mach.pass_times(0.0, 3 * np.pi / mach.omega)
    np.testing.assert_array_equal(mach.warp_over(p.warp, p.weft, p.time), p.warp_over)
    # the same pair really does alternate between its meetings here
    pair = (p.warp == 0) & (p.weft == 1)
    assert len(set(p.warp_over[pair])) == 2
    with pytest.raises(ValueError, match="not a pass time"):
        mach.warp_over(0, 1, p.time[pair][0] + 0.1)


@pytest.mark.parametrize("carriers,pattern,ok", [
    (96, "regular", True), (144, "regular", True), (36, "regular", True), (4, "diamond", True),
    (6, "diamond", True), (2, "diamond", False), (95, "regular", False), (94, "regular", False),
    (4, "regular", False), (8, "regular", True), (12, "hercules", True), (16, "hercules", False),
    (6, "hercules", False), (0, "diamond", False), (-8, "regular", False)])
def test_runnable_carrier_counts(carriers, pattern, ok):
    problem = carrier_count_problem(carriers, pattern)
    assert (problem is None) == ok
    if not ok:
        assert pattern in problem and "even" in problem
