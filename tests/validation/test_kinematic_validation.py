"""Kinematic model against closed forms (docs/theory.md §2) and invariants.

Cylinder: Ko's braid angle, the steady convergence length and the Du & Popper transient. Cone:
the quasi-static braid angle. Convergence in the time step and the mesh; frame and unit
invariance; warp/weft mirror symmetry; eccentric and bent mandrels; flags.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from preform import analytic
from preform.geometry import shapes
from preform.result import FLAG_BRIDGE, FLAG_CATCH, FLAG_SLIP
from preform.simulation import simulate
from support.simcase import make_config, write_centerline, write_stl

OMEGA = 0.2309401    # rad/s: Ko angle 60 deg at r = 75 mm and v = 10 mm/s
V = 0.01


@pytest.fixture(scope="module")
def cylinder_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("cyl")
    verts, faces = shapes.cylinder(radius=0.075, length=1.2, n_around=128)
    stl = write_stl(d / "cyl.stl", verts, faces)
    cl = write_centerline(d / "cyl.csv", [[0, 0, 0], [0, 0, 1.2]])
    cfg = make_config(stl, cl, carriers=8, spool_radius=0.3, angular_speed=OMEGA, take_up_speed=V,
                      initial_position=0.02, braid_length=0.8)
    return simulate(cfg, progress=False)


def test_cylinder_steady_braid_angle_is_ko(cylinder_run):
    h = cylinder_run.history
    ko = np.degrees(analytic.ko_braid_angle(OMEGA, 0.075, V))
    # required: within 0.25 deg of Ko in steady state (5 time constants after wrapping)
    assert h["braid_angle_warp_deg"][-1] == pytest.approx(ko, abs=0.25)
    assert h["braid_angle_weft_deg"][-1] == pytest.approx(ko, abs=0.25)
    # the laid yarn too, over the last 10 cm of braid
    y = cylinder_run.yarns
    s = cylinder_run.centerline.project(y.points)[0]
    late = (s > 0.65) & (s < 0.75)
    assert np.abs(y.braid_angle_deg[late] - ko).max() < 0.25


def test_cylinder_steady_convergence_length(cylinder_run):
    h = cylinder_run.history
    H_inf = analytic.steady_convergence_length(OMEGA, 0.075, V, 0.3)
    # required: within 1 %; the transient left after ~5.4 time constants is ~0.3 %
    assert h["convergence_length_mean_m"][-1] == pytest.approx(H_inf, rel=0.01)
    # a centred cylinder: every yarn alike
    assert h["convergence_length_max_m"][-1] - h["convergence_length_min_m"][-1] < 1e-4


def test_cylinder_transient_follows_du_popper(cylinder_run):
    h = cylinder_run.history
    t = h["time_s"]
    H = h["convergence_length_mean_m"]
    # lift-off phase: the tied yarns do not wrap until the carrier is acos(r/R) ahead
    t_wrap = analytic.tangency_lag(0.075, 0.3) / OMEGA
    free = H - (H[0] + V * t)
    i_wrap = int(np.argmax(np.abs(free) > 1e-6))
    assert t[i_wrap] == pytest.approx(t_wrap, abs=2 * (t[1] - t[0]))
    # from there on, Du & Popper with H0 = H(t_wrap): "within a few mm" -> 2 mm
    after = t > t_wrap
    H0 = H[0] + V * t_wrap
    ref = analytic.du_popper_convergence_length(t[after] - t_wrap, H0, OMEGA, 0.075, V, 0.3)
    assert np.abs(H[after] - ref).max() < 2e-3
    assert H[after][-1] - H0 > 0.05     # a real transient was tested, not a flat line


def test_no_flags_on_steady_cylinder(cylinder_run):
    assert not np.any(cylinder_run.yarns.flags & (FLAG_BRIDGE | FLAG_CATCH | FLAG_SLIP))


def test_warp_and_weft_mirror_on_centred_mandrel(cylinder_run):
    h = cylinder_run.history
    np.testing.assert_allclose(h["braid_angle_warp_deg"], h["braid_angle_weft_deg"], atol=1e-6)
    H = cylinder_run.convergence_length
    g = cylinder_run.yarns.group
    np.testing.assert_allclose(np.sort(H[:, g == 0], axis=1), np.sort(H[:, g == 1], axis=1), atol=1e-7)


def test_steady_state_is_detected_where_du_popper_puts_it(cylinder_run):
    from preform.analysis.steady import steady_state

    st = steady_state(cylinder_run.history)
    assert st["reached"]
    # Du & Popper from below: H = H_inf - (H_inf - H0) exp(-t/tau) reaches 99 % of H_inf (the
    # asymptote steady state is read against) at t = t_wrap + tau ln((H_inf - H0) / (0.01 H_inf));
    # the braid angle settles alongside.
    R, r = 0.3, 0.075
    tau = np.sqrt(R * R - r * r) / (OMEGA * r)
    t_wrap = analytic.tangency_lag(r, R) / OMEGA
    H_inf = analytic.steady_convergence_length(OMEGA, r, V, R)
    H0 = cylinder_run.history["convergence_length_mean_m"][0] + V * t_wrap
    h = cylinder_run.history
    t_steady = t_wrap + tau * np.log((H_inf - H0) / (0.01 * H_inf))
    L_expected = np.interp(t_steady, h["time_s"], h["braided_length_m"])
    # the angle criterion (0.25 deg) may bind a little later than the 1 % one on H
    assert L_expected - 0.01 <= st["braided_length_m"] <= L_expected + 0.1
