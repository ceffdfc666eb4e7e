"""Settings that change during a run (docs/guide/configuration.md: tables over the braided length).

A step in the angular speed on a cylinder, kinematic model: after the step the convergence length
follows Du & Popper's transient from where the step found it towards the new speed's H_inf, the
braid angle settles on Ko's angle of the new speed, and the summary's ``transients`` reports the
step with the braided length the braid needed to settle, where the closed forms put it. An
eccentricity table moves the pose as the constant eccentricity of each row would.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from preform import analytic
from preform.analysis.derived import summary_dict
from preform.analysis.steady import STEADY, setting_changes
from preform.geometry import shapes
from preform.simulation import simulate
from preform.tolerances import tol
from support.simcase import make_config, write_centerline, write_stl

R, r, V = 0.3, 0.075, 0.01              # spool radius, cylinder radius (m), take-up speed (m/s)
ALPHA1, ALPHA2 = 55.0, 60.0             # Ko's angle (deg) before and after the step
OMEGA1 = V * np.tan(np.radians(ALPHA1)) / r
OMEGA2 = V * np.tan(np.radians(ALPHA2)) / r
STEP_AT, STEP_END = 0.45, 0.46          # m braided: the table's ramp from OMEGA1 to OMEGA2


@pytest.fixture(scope="module")
def stepped(tmp_path_factory):
    d = tmp_path_factory.mktemp("step")
    verts, faces = shapes.cylinder(radius=r, length=1.8, n_around=128)
    stl = write_stl(d / "cyl.stl", verts, faces)
    cl = write_centerline(d / "cyl.csv", [[0, 0, 0], [0, 0, 1.8]])
    # the tip started where the yarns, lifted off for the tangency lag, reach H_inf: the start-up
    # transient is short and the step meets a braid already near steady state
    h1 = analytic.steady_convergence_length(OMEGA1, r, V, R)
    lift = V * analytic.tangency_lag(r, R) / OMEGA1
    cfg = make_config(stl, cl, carriers=8, spool_radius=R, angular_speed=OMEGA1, take_up_speed=V,
                      initial_position=h1 - lift, braid_length=1.2, snapshots=0)
    table = ((0.0, OMEGA1), (STEP_AT, OMEGA1), (STEP_END, OMEGA2))
    cfg = dataclasses.replace(cfg, machine=dataclasses.replace(cfg.machine, angular_speed_table=table))
    return simulate(cfg, progress=False)


def test_the_step_is_found_in_the_table(stepped):
    (change,) = setting_changes(stepped.config)
    assert change["setting"] == "angular_speed"
    assert (change["starts_at_m"], change["ends_at_m"]) == (STEP_AT, STEP_END)
    assert change["from"] == pytest.approx(np.degrees(OMEGA1), rel=1e-12)
    assert change["to"] == pytest.approx(np.degrees(OMEGA2), rel=1e-12)


def test_the_carriers_turn_at_the_table_speed(stepped):
    # process.csv's angular speed is the table's at the braided length of each step (the
    # stepper reads the braided length every few steps, so the step lands within a few steps)
    h, p = stepped.history, stepped.process
    L, omega = h["braided_length_m"], p[:, 2]
    assert np.all(omega[L < STEP_AT - 0.005] == OMEGA1)
    assert np.all(omega[L > STEP_END + 0.005] == OMEGA2)


def test_after_the_step_h_follows_du_popper(stepped):
    h = stepped.history
    t, L, H = h["time_s"], h["braided_length_m"], h["convergence_length_mean_m"]
    # the step's end as the run met it: the first row turning at the new speed
    k = int(np.argmax(stepped.process[:, 2] == OMEGA2))
    after = t >= t[k]
    ref = analytic.du_popper_convergence_length(t[after] - t[k], H[k], OMEGA2, r, V, R)
    # the start-up transient's test allows 2 mm for the lift-off from the tie points; here the
    # step starts from a braid in steady state, and the model integrates Du & Popper's equation
    # to second order in the step: 0.1 mm (4 um measured, the 1 cm ramp included)
    assert np.abs(H[after] - ref).max() < 1e-4
    assert H[k] - H[-1] > 0.03         # a real transient: H fell from ~H_inf(55) to H_inf(60)
    assert L[k] == pytest.approx(STEP_AT, abs=0.02)


def test_after_the_transient_the_angle_is_ko_of_the_new_speed(stepped):
    h = stepped.history
    ko2 = np.degrees(analytic.ko_braid_angle(OMEGA2, r, V))
    # the steady state's tolerance on an angle (SteadySettings.angle_deg, 0.25 deg)
    assert h["braid_angle_warp_deg"][-1] == pytest.approx(ko2, abs=STEADY.angle_deg)
    assert h["braid_angle_weft_deg"][-1] == pytest.approx(ko2, abs=STEADY.angle_deg)
    before = h["braided_length_m"] < STEP_AT
    ko1 = np.degrees(analytic.ko_braid_angle(OMEGA1, r, V))
    assert h["braid_angle_warp_deg"][before][-1] == pytest.approx(ko1, abs=STEADY.angle_deg)


def test_the_summary_reports_the_transient_where_du_popper_puts_it(stepped):
    (tr,) = summary_dict(stepped)["transients"]
    assert tr["setting"] == "angular_speed" and tr["settled"]
    ko2 = np.degrees(analytic.ko_braid_angle(OMEGA2, r, V))
    assert tr["braid_angle_deg"]["warp"] == pytest.approx(ko2, abs=STEADY.angle_deg)
    assert tr["convergence_length_m"] == pytest.approx(
        analytic.steady_convergence_length(OMEGA2, r, V, R), rel=STEADY.rel_H)
    # Du & Popper after the step: H within 1 % of H_inf at t* = tau ln(|H0 - H_inf| / (0.01
    # H_inf)); the braid angle, atan(omega r / (v - dH/dt)), within 0.25 deg about when
    # (5.2 deg exp(-t / tau) here); read as braided lengths on the run's own history
    h = stepped.history
    t, L, H = h["time_s"], h["braided_length_m"], h["convergence_length_mean_m"]
    k = int(np.argmax(stepped.process[:, 2] == OMEGA2))
    tau = np.sqrt(R * R - r * r) / (OMEGA2 * r)
    H_inf = analytic.steady_convergence_length(OMEGA2, r, V, R)
    t_h = tau * np.log(abs(H[k] - H_inf) / (STEADY.rel_H * H_inf))
    dH0 = (H[k] - H_inf) / tau
    alpha = lambda s: np.degrees(np.arctan(OMEGA2 * r / (V + dH0 * np.exp(-s / tau))))  # noqa: E731
    s = np.linspace(0.0, 10 * tau, 20001)
    t_a = s[np.argmax(np.abs(alpha(s) - alpha(s[-1])) <= STEADY.angle_deg)]
    L_expected = np.interp(t[k] + max(t_h, t_a), t, L)
    # the reading is on history rows and a fitted asymptote: a few centimetres of braid, as for
    # the start-up transient (test_steady_state_is_detected_where_du_popper_puts_it)
    assert L_expected - 0.02 <= tr["settled_at_m"] <= L_expected + 0.1
    assert tr["length_m"] == pytest.approx(tr["settled_at_m"] - STEP_AT, abs=1e-12)


@pytest.fixture(scope="module")
def eccentric(tmp_path_factory):
    d = tmp_path_factory.mktemp("ecc")
    verts, faces = shapes.cylinder(radius=r, length=0.5, n_around=64)
    stl = write_stl(d / "cyl.stl", verts, faces)
    cl = write_centerline(d / "cyl.csv", [[0, 0, 0], [0, 0, 0.5]])
    cfg = make_config(stl, cl, carriers=8, spool_radius=R, angular_speed=OMEGA2, take_up_speed=V,
                      initial_position=0.15, braid_length=0.12, snapshots=0)
    table = ((0.0, 0.0, 0.0), (0.05, 0.0, 0.0), (0.09, 0.02, -0.01))
    return simulate(dataclasses.replace(cfg, process=dataclasses.replace(
        cfg.process, eccentricity_table=table)), progress=False)


def test_an_eccentricity_table_moves_the_mandrel_with_the_braided_length(eccentric):
    h, p = eccentric.history, eccentric.process
    L = h["braided_length_m"]
    # a straight mandrel along the machine axis: its origin's x, y are the eccentricity of the
    # braided length the step was taken at (read every few steps: the rows well inside)
    first, last = L < 0.045, L > 0.095
    np.testing.assert_allclose(p[first, 3:5], 0.0, atol=1e-12)
    np.testing.assert_allclose(p[last, 3:5], [[0.02, -0.01]] * int(last.sum()), atol=1e-12)
    mid = (L > 0.06) & (L < 0.08)
    assert np.all((p[mid, 3] > 0.0) & (p[mid, 3] < 0.02))


def test_a_run_with_tables_resumed_from_its_state_goes_on_to_the_same_bits(tmp_path):
    """The carriers' clock and the process rows are state: a stepper restored mid-change (the
    angular speed and the eccentricity changing) steps on exactly as the one never stopped."""
    from preform.simulation import load_geometry, make_stepper

    verts, faces = shapes.cylinder(radius=r, length=0.4, n_around=48)
    stl = write_stl(tmp_path / "cyl.stl", verts, faces)
    cl = write_centerline(tmp_path / "cyl.csv", [[0, 0, 0], [0, 0, 0.4]])
    cfg = make_config(stl, cl, carriers=8, spool_radius=R, angular_speed=OMEGA1, take_up_speed=V,
                      initial_position=0.05, braid_length=0.2, snapshots=0)
    cfg = dataclasses.replace(
        cfg, machine=dataclasses.replace(cfg.machine, angular_speed_table=(
            (0.0, OMEGA1), (0.1, OMEGA2))),
        process=dataclasses.replace(cfg.process, eccentricity_table=(
            (0.0, 0.0, 0.0), (0.1, 0.004, 0.0))))
    mandrel, centerline = load_geometry(cfg)

    def steps(s, n):
        for _ in range(n):
            s.advance(*s.speeds())
            if s.step % s.tolerances.braided_length_every == 0:
                s.braided = s.braided_length_estimate()

    once = make_stepper(cfg, mandrel, centerline)
    steps(once, 120)
    assert OMEGA1 < once.speeds()[1] < OMEGA2        # stopped inside the change
    state = once.state_arrays()
    again = make_stepper(cfg, mandrel, centerline)
    again.restore(state)
    steps(once, 60)
    steps(again, 60)
    assert again.clock == once.clock and again.clock.carrier_t != again.clock.t
    np.testing.assert_array_equal(again.F, once.F)
    np.testing.assert_array_equal(again.process_array(), once.process_array())


@pytest.fixture(scope="module")
def stepped_interaction(tmp_path_factory):
    """The interaction model through the same step (16 carriers, yarn friction 0.2): friction
    shortens its convergence zone, not the steady braid angle, which is Ko's on a cylinder."""
    d = tmp_path_factory.mktemp("step_interaction")
    verts, faces = shapes.cylinder(radius=r, length=1.6, n_around=64)
    stl = write_stl(d / "cyl.stl", verts, faces)
    cl = write_centerline(d / "cyl.csv", [[0, 0, 0], [0, 0, 1.6]])
    cfg = make_config(stl, cl, carriers=16, spool_radius=R, angular_speed=OMEGA1, take_up_speed=V,
                      initial_position=0.15, braid_length=1.2, snapshots=0, friction=0.2)
    table = ((0.0, OMEGA1), (STEP_AT, OMEGA1), (STEP_END, OMEGA2))
    return simulate(dataclasses.replace(
        cfg, model=dataclasses.replace(cfg.model, kind="interaction"),
        machine=dataclasses.replace(cfg.machine, angular_speed_table=table)), progress=False)


def test_the_interaction_model_settles_on_ko_of_each_speed(stepped_interaction):
    res = stepped_interaction
    assert res.status == "done"
    h, omega = res.history, res.process[:, 2]
    L = h["braided_length_m"]
    # the speed of the braided length the stepper last read: every braided_length_every steps,
    # of about 3 mm each here
    lag = res.config.process.braid_length / res.steps * tol.braided_length_every
    assert np.all(omega[L < STEP_AT] == OMEGA1) and np.all(omega[L > STEP_END + lag] == OMEGA2)
    # before the step and at the end (0.74 m, ~4.4 H after it): Ko's angle of the speed then,
    # within the steady-state tolerance on an angle (measured: 54.85 and 59.95 deg)
    before = np.flatnonzero(L < STEP_AT)[-1]
    for group in ("warp", "weft"):
        angle = h[f"braid_angle_{group}_deg"]
        assert angle[before] == pytest.approx(ALPHA1, abs=STEADY.angle_deg)
        assert angle[-1] == pytest.approx(ALPHA2, abs=STEADY.angle_deg)
