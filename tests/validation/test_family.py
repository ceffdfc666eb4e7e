"""The interaction model against the kinematic model on a curved part behind a guide ring
(``shapes.family_part``, a small version of ``benchmarks/bench_family.py``).

Frictionless, the interaction model's yarns slide freely through their crossings: each yarn is
then straight between its supply and its fell point, as the kinematic model has it, and the two
models must give the same braid angle and convergence length (to the crossings' kinks that a
non-axisymmetric zone forces on interlaced yarns, ``docs/decisions.md``). The part is the
family's S-bend (two 35 deg bends of 300 mm, a 50 mm circle), eccentric by 10 mm, on a well-shaped
triangulation in metres and on a CAD-sliver one in millimetres: the two meshes are one surface, so
the interaction runs on them must agree too. Braiding onto a bend from near the tip, the models
agree where the kinematic yarns follow the bend's inner side (``bend_tip``, 0.45 m); on the
S-bend's 0.3 m bend both models' inner-side fell points stall, each its own way (a strict xfail).
With friction the braid must stay interlaced: its warp-weft crossings per unit area
(``preform.analysis.interlacing``) those of the pattern.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from preform.geometry import shapes
from preform.analysis.interlacing import interlacing
from preform.simulation import load_geometry, simulate

from support.simcase import make_config, write_stl

#: a case-B-like machine at 24 carriers: ring 0.17 m, spool 0.85 m, 18 deg/s, 26.3 mm/s, the
#: mandrel tip 0.2 m beyond the ring; 0.06 m braided (about 200 steps, the bends in the zone)
MACHINE = dict(carriers=24, spool_radius=0.85, guide_ring=(0.17, 0.0), initial_position=0.2,
               angular_speed=np.radians(18.0), take_up_speed=0.0263, braid_length=0.06,
               eccentricity=(0.01, 0.0), pose_lead=None, snapshots=0)
#: m, the yarn width of ``make_config``'s default yarn
YARN_WIDTH = 4e-3
#: braided lengths (m) at which the models are compared: past the first row's deposit
AT = (0.02, 0.03, 0.04, 0.05, 0.06)


def _config(stl, unit, kind, friction, ring_friction):
    cfg = make_config(stl, "auto", stl_unit=unit, friction=friction,
                      ring_friction=ring_friction, **MACHINE)
    return dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind=kind))


@pytest.fixture(scope="module")
def parts(tmp_path_factory):
    """{triangulation: (STL path, unit)}: the S-bend well-shaped in metres, with CAD slivers
    (aspect ratios near 100) in millimetres."""
    folder = tmp_path_factory.mktemp("family")
    out = {}
    for tri, unit, scale in (("even", "m", 1.0), ("sliver", "mm", 1000.0)):
        V, F, _ = shapes.family_part("s_bend", triangulation=tri, scale=scale)
        out[tri] = write_stl(folder / f"s_bend_{tri}.stl", V, F), unit
    return out


@pytest.fixture(scope="module")
def runs(parts):
    """{(triangulation, kind, friction): Result} of the runs the tests compare."""
    out = {}
    for tri, kind, mu, mu_r in (("even", "kinematic", 0.0, 0.0), ("even", "interaction", 0.0, 0.0),
                                ("sliver", "interaction", 0.0, 0.0),
                                ("even", "interaction", 0.25, 0.17)):
        stl, unit = parts[tri]
        out[tri, kind, mu] = simulate(_config(stl, unit, kind, mu, mu_r), progress=False)
    return out


def _at(result, L):
    """(braid angle deg, mean H m) of the first recorded step with braided length >= L."""
    h = result.history
    i = int(np.searchsorted(h["braided_length_m"], L))
    assert i < len(h["time_s"]), f"the run stopped at {h['braided_length_m'][-1]:.4g} m"
    alpha = 0.5 * (h["braid_angle_warp_deg"][i] + h["braid_angle_weft_deg"][i])
    return alpha, h["convergence_length_mean_m"][i]


def test_frictionless_interaction_reproduces_the_kinematic_model_on_a_bend(runs):
    kin = runs["even", "kinematic", 0.0]
    for tri in ("even", "sliver"):
        inter = runs[tri, "interaction", 0.0]
        assert inter.status == "done", inter.message
        # every step converged (the frictionless case A's figure: below 1e-7)
        assert np.max(inter.history["residual"]) < 1e-6
        for L in AT:
            a_k, h_k = _at(kin, L)
            a_i, h_i = _at(inter, L)
            # the agreement asked of the two models: 1 deg and 3 % (measured: 0.45 deg, 1.3 %)
            assert a_i == pytest.approx(a_k, abs=1.0), (tri, L)
            assert h_i == pytest.approx(h_k, rel=0.03), (tri, L)


def test_interaction_run_is_the_same_on_a_sliver_triangulation(runs):
    """One surface, two triangulations: the crossings' distance to the mandrel (deposit, wall)
    is the closest point's, whatever the faces' shapes (the nearest face centroid's plane put
    the sliver run 4 deg and 25 % in H off the even one)."""
    even, sliver = runs["even", "interaction", 0.0], runs["sliver", "interaction", 0.0]
    for L in AT:
        a_e, h_e = _at(even, L)
        a_s, h_s = _at(sliver, L)
        # the facets differ: the smooth normals and the closest points by the chord error
        # (0.1 mm on 2.6 mm edges at r = 25 mm), the braid by a fraction of a degree
        assert a_s == pytest.approx(a_e, abs=0.5), L
        assert h_s == pytest.approx(h_e, rel=0.01), L


def test_braid_with_friction_stays_interlaced(runs, parts):
    """With yarn friction 0.25 and ring friction 0.17 the laid warp and weft cross each other as
    the pattern has them: over the braided band, the measured crossings are those of the
    pattern (``preform.analysis.interlacing``, ratio 1 for an interlaced braid, towards 0 for warp and
    weft in separate bands), and their density that of two families of n yarns at the laid
    braid angle, ``2 n^2 tan(alpha) / P^2``."""
    res = runs["even", "interaction", 0.25]
    assert res.status == "done", res.message
    stl, unit = parts["even"]
    mandrel, cl = load_geometry(_config(stl, unit, "interaction", 0.25, 0.17))
    it = interlacing(res.yarns, cl)
    assert it is not None and it.s_end - it.s_start > 0.03
    # within one crossing per pair at the band's two ends over the 144 pairs' ~30 crossings
    assert it.measured == pytest.approx(it.pattern, rel=0.25)
    n = MACHINE["carriers"] // 2
    inside = np.zeros(len(res.yarns.points), dtype=bool)
    s, _ = cl.project(res.yarns.points)
    inside = (s >= it.s_start) & (s <= it.s_end)
    tan_alpha = np.tan(np.radians(np.median(res.yarns.braid_angle_deg[inside])))
    P = 2 * np.pi * 0.025
    # the laid angle varies over the band (median against the mean of tan): a fifth
    assert it.measured_per_m2 == pytest.approx(2 * n * n * tan_alpha / P ** 2, rel=0.2)


@pytest.mark.parametrize("tri", ["even", "sliver"])
def test_mandrel_distance_is_the_closest_points_on_a_sliver_mesh(tri):
    """``MandrelDistance``'s signed distance of points near the S-tube (up to 6 mm off its
    surface, where crossings are looked up; the wall holds them outside) against the exact
    closest points (``Mandrel.closest_points``) on both triangulations: to 1e-5 m (a point over
    a face but beside a concave ridge of the bends is nearer the face's plane than the
    polyhedron; the facets' chord error is 0.1 mm), where the plane of the face with the
    nearest centroid is off by millimetres beside a sliver."""
    from preform.geometry import mandrel_from_arrays
    from preform.interaction.mandrel_distance import MandrelDistance

    V, F, _ = shapes.family_part("s_tube", triangulation=tri)
    m = mandrel_from_arrays(V, F)
    rng = np.random.default_rng(5)
    f = rng.integers(len(F), size=2000)
    foot = np.einsum("ij,ijk->ik", rng.dirichlet([1.0, 1.0, 1.0], len(f)), V[F[f]])
    n = np.asarray(m.face_normals)
    P = foot + n[f] * rng.uniform(0.0, 6e-3, (len(f), 1))
    c, fc = m.closest_points(P)
    exact = np.linalg.norm(P - c, axis=1) * np.sign(np.einsum("ij,ij->i", P - c, n[fc]))
    d = MandrelDistance(m)
    err = np.abs(d(P) - exact)
    assert err.max() < 1e-5
    # the nearest centroid's plane, which the deposit and the wall used
    _, g = d.tree.query(P)
    centroid = np.abs(np.einsum("ij,ij->i", P - d.centroids[g], n[g]) - exact)
    if tri == "sliver":
        assert centroid.max() > 1e-3


def _bend_tip_runs(tmp_path, name, length):
    """{kind: Result} of both models, frictionless, braiding 0.03 m onward onto the bend of the
    family's part ``name`` (sliver mesh in millimetres, its own centerline: the automatic one
    finds fewer than two sections on a part that bends this near its tip)."""
    from support.simcase import write_centerline

    V, F, path = shapes.family_part(name, triangulation="sliver", scale=1000.0)
    stl = write_stl(tmp_path / f"{name}.stl", V, F)
    csv = write_centerline(tmp_path / f"{name}.csv", path)
    out = {}
    for kind in ("kinematic", "interaction"):
        cfg = _config(stl, "mm", kind, 0.0, 0.0)
        cfg = dataclasses.replace(cfg, mandrel=dataclasses.replace(cfg.mandrel, centerline=csv),
                                  process=dataclasses.replace(cfg.process, braid_length=length))
        out[kind] = simulate(cfg, progress=False)
    return out


def _longest_laid_step(result):
    """m: the longest straight piece between consecutive laid points of any yarn."""
    pts, off = np.asarray(result.yarns.points), np.asarray(result.yarns.offsets)
    return max(float(np.linalg.norm(np.diff(pts[a:b], axis=0), axis=1).max())
               for a, b in zip(off[:-1], off[1:]) if b - a > 1)


def test_frictionless_models_agree_braiding_on_a_bend(tmp_path):
    """Braiding onto the bend itself (``bend_tip``: 35 deg of 0.45 m radius from 30 mm of the
    tip, under a 0.32-0.39 m zone): frictionless, the interaction model gives the kinematic
    model's braid angle and H (measured at 0.04-0.1 m: 0.26-0.58 deg below, H 0.8-1.7 % longer;
    on 0.6 m: 0.31-0.39 deg, 0.1-1.0 %)."""
    out = _bend_tip_runs(tmp_path, "bend_tip", 0.1)
    kin, inter = out["kinematic"], out["interaction"]
    assert inter.status == "done", inter.message
    # the reference: the kinematic yarns follow the bend's inner side, no laid piece longer
    # than 2.5 yarn widths (measured 1.4 mm; on the 0.3 m bend they lift off there and catch
    # 47-90 mm ahead from 0.092 m braided, where the kinematic run is no reference)
    assert _longest_laid_step(kin) < 2.5 * YARN_WIDTH
    for L in (0.04, 0.06, 0.08, 0.1):
        a_k, h_k = _at(kin, L)
        a_i, h_i = _at(inter, L)
        # the agreement asked of the two models: 1 deg and 3 %
        assert a_i == pytest.approx(a_k, abs=1.0), L
        assert h_i == pytest.approx(h_k, rel=0.03), L


@pytest.mark.xfail(strict=True, reason="on the inner side of a 0.3 m bend two first-row "
                   "crossings hover 0.3-1 mm up between fell points whose free yarns lift off, "
                   "so neither the walk nor the deposit moves four yarns' fell points from "
                   "the arc's start (docs/decisions.md)")
def test_frictionless_models_agree_braiding_on_a_tight_bend(tmp_path):
    """Braiding onto the S-bend's first bend (0.3 m radius, from 30 mm of the tip): up to
    0.08 m braided the kinematic reference still follows the surface (its inner-side yarns
    lift off from about 0.08 m and catch 47-90 mm ahead from 0.092 m on); the interaction
    model's H is 3.8 % longer at 0.08 m (angle 0.58 / 0.76 deg below at 0.06 / 0.08 m)."""
    out = _bend_tip_runs(tmp_path, "s_bend_tip", 0.08)
    kin, inter = out["kinematic"], out["interaction"]
    assert inter.status == "done", inter.message
    # no catch yet (the longest piece 9 mm, a fast walk along the inner side at 0.075 m)
    assert _longest_laid_step(kin) < 2.5 * YARN_WIDTH
    for L in (0.06, 0.08):
        a_k, h_k = _at(kin, L)
        a_i, h_i = _at(inter, L)
        assert a_i == pytest.approx(a_k, abs=1.0), L
        assert h_i == pytest.approx(h_k, rel=0.03), L
