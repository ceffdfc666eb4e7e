"""Yarn-ring contact (paper §2.3, eqs. 9-13, Fig. A.17) against closed forms, a length minimum and
the SciPy reference in ``naive_contact.py``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from preform._kernels import ring as ring_kernels
from preform.interaction.contact import ContactInputError
from preform.interaction.ring import ring_arguments, ring_point, solve_ring
from preform.interaction.settings import RingSettings
from support import naive_contact as naive

R_RING, Z_RING = 0.17, 0.05
# the slip root stops at ~1e-15 relative Psi (RingSettings.root_rel_tol); 1e-9 is the brief's figure
REL = 1e-9


def random_ring_problem(rng):
    """Fell point or last crossing near the axis at z 0.15-0.4 m, supply point on the spool circle
    (0.85 m, z = 0), previous ring angle near the carrier's azimuth; f_ext 2-8 N, mu_r 0-0.4."""
    phi_b = rng.uniform(-np.pi, np.pi)
    phi_a = phi_b + rng.uniform(-1.2, 1.2)
    A = np.array([0.05 * np.cos(phi_a), 0.05 * np.sin(phi_a), rng.uniform(0.15, 0.4)])
    B = np.array([0.85 * np.cos(phi_b), 0.85 * np.sin(phi_b), 0.0])
    theta_prev = phi_b + rng.uniform(-0.4, 0.4)
    return A, B, rng.uniform(2, 8), theta_prev, rng.choice([0.0, rng.uniform(0.05, 0.4)], p=[0.2, 0.8])


def problems(n, seed):
    rng = np.random.default_rng(seed)
    return [random_ring_problem(rng) for _ in range(n)]


def deflection(A, R, B):
    u_i, u_e = (A - R) / np.linalg.norm(A - R), (B - R) / np.linalg.norm(B - R)
    return np.arccos(np.clip(-u_i @ u_e, -1, 1))


@pytest.mark.parametrize("capstan_sign", [-1, 1])
def test_tension_ratio_is_the_capstan_factor(capstan_sign):
    for A, B, f, th, mu in problems(60, seed=1):
        s = solve_ring(A, B, f, R_RING, Z_RING, th, mu, capstan_sign=capstan_sign)
        assert s.ok, s.message
        eta = deflection(A, s.R, B)
        assert s.eta == pytest.approx(eta, abs=1e-7)  # arccos loses ~sqrt(eps) near eta = 0
        assert s.f_int / s.f_ext == pytest.approx(np.exp(capstan_sign * mu * s.eta), rel=1e-13)


def test_stick_along_the_ring_holds_its_tension_within_the_cone():
    """capstan_sign 0: f_int is the held tension clipped to f_ext exp(-+mu eta), and the
    transverse solve matches the NumPy/SciPy twin with that tension."""
    seen = set()
    for A, B, f, th, mu in problems(40, seed=11):
        for hold in (0.5 * f, f, 1.05 * f, 2.0 * f):
            s = solve_ring(A, B, f, R_RING, Z_RING, th, mu, capstan_sign=0, f_hold=hold)
            assert s.ok, s.message
            lo, hi = f * np.exp(-mu * s.eta), f * np.exp(mu * s.eta)
            assert s.f_int == pytest.approx(min(max(hold, lo), hi), rel=1e-13)
            seen.add("inside" if lo < hold < hi else "clipped")
            ref = naive.solve_ring(A, B, f, R_RING, Z_RING, th, mu, capstan_sign=0, f_hold=hold)
            assert ref["ok"]
            assert s.theta_r == pytest.approx(ref["theta"], abs=1e-9)
            assert s.f_int == pytest.approx(ref["f_int"], rel=REL)
    assert seen == {"inside", "clipped"}


def test_sliding_along_the_ring_leaves_no_transverse_stick():
    """With a slide s_long along the ring in the step, along and across are one Coulomb cone:
    any transverse pull moves the ring point, to where |F^t| = mu r |dtheta| / |(s_long,
    r dtheta)| |F^n| (the NumPy/SciPy twin); a larger s_long leaves less transverse friction,
    so the point moves further; s_long -> 0 gives Amontons' stick back."""
    moved = 0
    for A, B, f, th, mu in problems(40, seed=12):
        if mu == 0.0:
            continue
        plain = solve_ring(A, B, f, R_RING, Z_RING, th, mu, capstan_sign=0.5)
        prev = None
        for s_long in (1e-3, 1e-2, 1e-1):
            s = solve_ring(A, B, f, R_RING, Z_RING, th, mu, capstan_sign=0.5, s_long=s_long)
            assert s.ok, s.message
            ref = naive.solve_ring(A, B, f, R_RING, Z_RING, th, mu, capstan_sign=0.5,
                                   s_long=s_long)
            assert ref["ok"] and s.theta_r == pytest.approx(ref["theta"], abs=1e-9)
            a = R_RING * abs(s.theta_r - th)
            mu_t = mu * a / np.hypot(s_long, a)
            Fr = s.F_r
            t = np.array([-np.sin(s.theta_r), np.cos(s.theta_r), 0.0])
            ft = Fr @ t
            assert abs(abs(ft) - mu_t * np.linalg.norm(Fr - ft * t)) < 1e-9 * (s.f_int + f)
            if prev is not None:
                assert abs(s.theta_r - th) >= abs(prev - th) - 1e-12
            prev = s.theta_r
        if plain.slip == 0:
            moved += abs(prev - th) > 0       # Amontons held it; the cone does not
    assert moved > 5


def test_paper_eq9_default_lowers_the_mandrel_side():
    A, B, f, th, mu = problems(1, seed=2)[0]
    s = solve_ring(A, B, f, R_RING, Z_RING, th, 0.3)
    assert s.f_int < s.f_ext  # f_ext = f_int exp(mu_r eta)


def test_ring_point_on_the_ring_and_force_sum():
    for A, B, f, th, mu in problems(40, seed=3):
        s = solve_ring(A, B, f, R_RING, Z_RING, th, mu)
        assert np.hypot(s.R[0], s.R[1]) == pytest.approx(R_RING, rel=1e-14) and s.R[2] == Z_RING
        np.testing.assert_allclose(s.R, ring_point(s.theta_r, R_RING, Z_RING), atol=1e-15)
        np.testing.assert_allclose(s.F_r, s.f_int * s.u_int + s.f_ext * s.u_ext, atol=1e-13)


def test_stick_keeps_theta_exactly():
    """Start at the transverse equilibrium (F^t = 0, from mu = 0), then move the supply point a
    little: with friction the ring point sticks."""
    sticks = 0
    for A, B, f, th, mu in problems(40, seed=4):
        eq = solve_ring(A, B, f, R_RING, Z_RING, th, 0.0)
        rot = np.array([[np.cos(0.01), -np.sin(0.01), 0], [np.sin(0.01), np.cos(0.01), 0], [0, 0, 1]])
        s = solve_ring(A, rot @ B, f, R_RING, Z_RING, eq.theta_r, 0.3)
        if s.slip == 0:
            sticks += 1
            assert s.theta_r == eq.theta_r and s.psi_r <= 0 and s.slide == 0
    assert sticks >= 35


def test_transverse_slip_lands_on_the_friction_limit():
    slips = 0
    for A, B, f, th, mu in problems(80, seed=5):
        s = solve_ring(A, B, f, R_RING, Z_RING, th, mu)
        assert s.psi_r <= REL * f
        if s.slip:
            slips += 1
            assert abs(s.psi_r) < REL * f
            # R moved the way the tangential pull F_r . t_r pointed at the predictor
            ft0 = naive.ring_forces(th, A, B, f, R_RING, Z_RING, mu)[0]
            assert s.slide == np.sign(ft0) == np.sign(s.theta_r - th)
    assert slips >= 40


def test_frictionless_ring_point_minimises_the_yarn_length():
    """mu_r = 0: equal tensions and F^t = 0, i.e. R(theta) minimises |A - R| + |R - B|."""
    for A, B, f, th, mu in problems(30, seed=6):
        s = solve_ring(A, B, f, R_RING, Z_RING, th, 0.0)
        length = lambda t: (np.linalg.norm(A - ring_point(t, R_RING, Z_RING))
                            + np.linalg.norm(B - ring_point(t, R_RING, Z_RING)))
        ref = minimize_scalar(length, bracket=(s.theta_r - 0.3, s.theta_r, s.theta_r + 0.3),
                              tol=1e-12)
        assert s.f_int == f
        assert s.theta_r == pytest.approx(ref.x, abs=1e-6)  # Brent's minimum: sqrt(eps) in theta


def test_matches_scipy_reference():
    for A, B, f, th, mu in problems(100, seed=7):
        s = solve_ring(A, B, f, R_RING, Z_RING, th, mu)
        ref = naive.solve_ring(A, B, f, R_RING, Z_RING, th, mu)
        assert s.ok == ref["ok"]
        assert s.slip == ref["slip"]
        assert s.theta_r == pytest.approx(ref["theta"], abs=1e-10)
        assert s.f_int == pytest.approx(ref["f_int"], rel=REL)


def test_homogeneous_in_the_spool_tension():
    for A, B, f, th, mu in problems(30, seed=8):
        s, s3 = (solve_ring(A, B, k * f, R_RING, Z_RING, th, mu) for k in (1, 3))
        assert s3.slip == s.slip
        assert s3.theta_r == pytest.approx(s.theta_r, abs=1e-12)
        assert s3.f_int == pytest.approx(3 * s.f_int, rel=REL)


def test_batch_kernel_matches_wrapper():
    ps = problems(20, seed=9)
    A, B = np.array([p[0] for p in ps]), np.array([p[1] for p in ps])
    f, th = np.array([p[2] for p in ps]), np.array([p[3] for p in ps])
    out, status = ring_kernels.empty_out(len(ps)), np.zeros(len(ps), np.int64)
    ring_kernels.solve_rings(A, B, f, R_RING, Z_RING, th, np.full(len(ps), 0.2),
                             np.full(len(ps), -1.0), f,
                             np.zeros(len(ps)), *ring_arguments(RingSettings()), out, status)
    for i, p in enumerate(ps):
        s = solve_ring(p[0], p[1], p[2], R_RING, Z_RING, p[3], 0.2)
        assert status[i] == s.status and out[i, ring_kernels.RING_OUT_THETA] == s.theta_r


def test_status_and_errors():
    B = np.array([0.85, 0, 0])
    s = solve_ring(ring_point(0.0, R_RING, Z_RING), B, 4.0, R_RING, Z_RING, 0.0, 0.2)
    assert s.status == ring_kernels.RING_DEGENERATE and not s.ok and np.all(s.R == 0)
    with pytest.raises(ContactInputError, match="f_ext"):
        solve_ring([0, 0, 0.2], B, -1.0, R_RING, Z_RING, 0.0, 0.2)
    with pytest.raises(ContactInputError, match="capstan_sign"):
        solve_ring([0, 0, 0.2], B, 1.0, R_RING, Z_RING, 0.0, 0.2, capstan_sign=2)
    with pytest.raises(ContactInputError, match="s_long"):
        solve_ring([0, 0, 0.2], B, 1.0, R_RING, Z_RING, 0.0, 0.2, s_long=-1.0)
    with pytest.raises(ContactInputError, match="f_hold"):
        solve_ring([0, 0, 0.2], B, 1.0, R_RING, Z_RING, 0.0, 0.2, capstan_sign=0)
    with pytest.raises(ContactInputError, match="mu_r"):
        solve_ring([0, 0, 0.2], B, 1.0, R_RING, Z_RING, 0.0, np.nan)


def test_root_tolerance_comes_from_the_settings():
    """A looser root tolerance (RingSettings.root_rel_tol) leaves the slipping ring points
    further from Psi_r = 0 and takes fewer evaluations: the setting reaches the kernel."""
    loose = RingSettings(root_rel_tol=1e-3)
    slipped = fewer = 0
    for A, B, f, th, mu in problems(60, seed=10):
        s = solve_ring(A, B, f, R_RING, Z_RING, th, mu)
        if not s.slip or mu == 0.0:
            continue
        slipped += 1
        c = solve_ring(A, B, f, R_RING, Z_RING, th, mu, settings=loose)
        assert c.slip and c.iterations <= s.iterations
        fewer += c.iterations < s.iterations
        assert abs(s.psi_r) <= 1e-12 * (s.f_int + f)          # the default: round-off
        assert abs(c.psi_r) <= 1e-3 * (c.f_int + f)           # the loose tolerance
    assert slipped >= 10 and fewer > 0
