"""The interlacing measure (``preform.analysis.interlacing``) against closed forms: helices on a cylinder,
and warp and weft laid in separate bands."""

import numpy as np
import pytest

from preform.geometry.centerline import centerline_from_points
from preform.analysis.interlacing import interlacing
from preform.result import YarnPaths

R = 0.05          # m, cylinder radius
L = 0.3           # m, band length


def _axis():
    return centerline_from_points(np.array([[0.0, 0.0, z] for z in np.linspace(-0.05, L + 0.05, 9)]))


def _helices(n, tan_alpha, phase_warp, phase_weft, rng, length=L):
    """YarnPaths of n warp helices (+alpha) and n weft helices (-alpha) on the cylinder of radius
    R about the z axis, each sampled at its own random points along z (ends included)."""
    cl = _axis()
    _, _, N, B = cl.frames_at([0.0])
    pts, off, group = [], [0], []
    for sign, phases, g in ((1.0, phase_warp, 0), (-1.0, phase_weft, 1)):
        for p0 in phases:
            z = np.sort(np.concatenate([[0.0, length], rng.uniform(0.0, length, 400)]))
            phi = p0 + sign * z * tan_alpha / R
            pts.append(R * (np.cos(phi)[:, None] * N[0] + np.sin(phi)[:, None] * B[0])
                       + z[:, None] * np.array([0.0, 0.0, 1.0]))
            off.append(off[-1] + len(z))
            group.append(g)
    P = np.vstack(pts)
    m = len(P)
    yarns = YarnPaths(points=P, offsets=np.array(off), time_s=np.zeros(m),
                      braid_angle_deg=np.zeros(m), face=np.zeros(m, dtype=np.int64),
                      flags=np.zeros(m, dtype=np.uint8), group=np.array(group, dtype=np.int8))
    return yarns, cl


@pytest.mark.parametrize("n, turns", [(8, 2.0), (12, 3.0)])
def test_helices_on_a_cylinder(n, turns):
    """n helices a group at +-alpha, tan(alpha) chosen so that every pair turns ``turns`` whole
    times about each other over the band: each pair crosses exactly that often, and the
    pattern's density is the closed form 2 n^2 tan(alpha) / P^2."""
    rng = np.random.default_rng(1)
    tan_alpha = turns * 2.0 * np.pi * R / (2.0 * L)       # 2 L tan(alpha) / R = 2 pi turns
    warp = 2 * np.pi * np.arange(n) / n
    weft = warp + np.pi / n + 0.01                        # no pair meets at the band's ends
    yarns, cl = _helices(n, tan_alpha, warp, weft, rng)
    res = interlacing(yarns, cl)
    assert res.pairs == n * n
    assert res.measured == int(round(turns * n * n))
    # the pattern: sum of |d_ij| variations / 2 pi, linear in s on a helix: exact to round-off
    assert res.pattern == pytest.approx(turns * n * n, rel=1e-9)
    P = 2 * np.pi * R
    # area from the yarns' mean radius (the centerline has no perimeters): R to round-off
    assert res.area_m2 == pytest.approx(P * L, rel=1e-9)
    assert res.pattern_per_m2 == pytest.approx(2 * n * n * tan_alpha / P ** 2, rel=1e-9)
    assert res.ratio == pytest.approx(1.0, abs=1e-9)


def test_separated_bands_do_not_cross():
    """Warp in one quarter of the section, weft in the opposite one, their relative turn over the
    band (0.2) less than the quarter between them: no crossing, though the pattern gives 0.2 a
    pair; the same yarns spread around the section give exactly 0.2 a pair (10 yarns a group:
    0.2 turn spans 2 of the 10 relative phases)."""
    n = 10
    rng = np.random.default_rng(2)
    tan_alpha = 0.2 * 2.0 * np.pi * R / (2.0 * L)
    bands, cl = _helices(n, tan_alpha, np.linspace(0.0, np.pi / 2, n),
                         np.linspace(np.pi, 1.5 * np.pi, n), rng)
    res = interlacing(bands, cl)
    assert res.measured == 0
    assert res.pattern == pytest.approx(0.2 * n * n, rel=1e-9)
    assert res.ratio == 0.0
    spread = 2 * np.pi * np.arange(n) / n
    mixed, cl = _helices(n, tan_alpha, spread, spread + np.pi / n, rng)
    res = interlacing(mixed, cl)
    assert res.measured == int(0.2 * n * n)
    assert res.ratio == pytest.approx(1.0, rel=1e-9)


def test_band_and_backward_points():
    """The band is where every yarn has been laid (``s_range`` narrows it); a point laid back
    along the centerline is dropped (the yarn's running maximum of s), not counted twice."""
    n = 6
    rng = np.random.default_rng(3)
    tan_alpha = 2.0 * 2.0 * np.pi * R / (2.0 * L)
    spread = 2 * np.pi * np.arange(n) / n
    yarns, cl = _helices(n, tan_alpha, spread, spread + np.pi / n + 0.01, rng)
    half = interlacing(yarns, cl, s_range=(0.05, 0.05 + L / 2))   # s from the axis start, z = -0.05
    assert half.s_end == pytest.approx(0.05 + L / 2)
    assert half.pattern == pytest.approx(n * n, rel=1e-9)
    # a yarn whose points are shuffled in s a little keeps its crossings
    P = yarns.points.copy()
    k = yarns.offsets[0] + 50
    P[k, 2] -= 0.004
    res = interlacing(YarnPaths(**{**yarns.__dict__, "points": P}), cl)
    assert res.measured == 2 * n * n
