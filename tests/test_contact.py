"""Yarn-yarn crossing solver (paper §2.2, Fig. 6; DESIGN.md §3.3) against closed forms, invariants
and the SciPy reference in ``naive_contact.py``."""

from __future__ import annotations

import numpy as np
import pytest

from preform._kernels import contact as K
from preform.errors import PreformError
from preform.interaction.contact import (ContactInputError, cone_ratio, crossing_angles, psi, psi_frame,
                                         solve_crossing)
import naive_contact as naive

# Tolerances. The kernel's root solves stop at ~1e-15 relative residual (ROOT_REL_TOL) and every
# other step is a closed form, so 1e-9 relative (the brief's figure) leaves six digits of margin for
# the conditioning of the 2x2 decompositions near grazing angles.
REL = 1e-9


def random_crossing(rng, predictor_noise=4e-4, direction_noise=0.15):
    """A braid-like crossing: lower points 4 mm apart, C about 4 mm above, supply directions near
    the continuation of A->C with an over/under tilt; tensions 2-8 N; previous angles from a
    perturbed C (predictor_noise, m); mu 0 (15 %) or 0.05-0.5."""
    A_X = np.array([-0.002, 0, 0]) + rng.normal(0, 3e-4, 3)
    A_O = np.array([0.002, 0, 0]) + rng.normal(0, 3e-4, 3)
    C0 = np.array([0, 0.004, 0]) + rng.normal(0, 5e-4, 3)
    tilt = rng.choice([-1, 1]) * rng.uniform(0.05, 0.3)
    u_x = (C0 - A_X) / np.linalg.norm(C0 - A_X) + rng.normal(0, direction_noise, 3) + [0, 0, tilt]
    u_o = (C0 - A_O) / np.linalg.norm(C0 - A_O) + rng.normal(0, direction_noise, 3) - [0, 0, tilt]
    F_X = rng.uniform(2, 8) * u_x / np.linalg.norm(u_x)
    F_O = rng.uniform(2, 8) * u_o / np.linalg.norm(u_o)
    theta = crossing_angles(A_X, A_O, C0 + rng.normal(0, predictor_noise, 3))
    mu = rng.choice([0.0, rng.uniform(0.05, 0.5)], p=[0.15, 0.85])
    return A_X, A_O, F_X, F_O, theta, mu


def sample(n, seed, **kw):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        noise = rng.choice([5e-5, 2e-4, 6e-4])  # a mix of sticking, one-slip and both-slip crossings
        yield random_crossing(rng, predictor_noise=noise, **kw)


@pytest.fixture(scope="module")
def solved():
    out = []
    for A_X, A_O, F_X, F_O, theta, mu in sample(300, seed=11):
        s = solve_crossing(A_X, A_O, F_X, F_O, theta, mu)
        out.append(((A_X, A_O, F_X, F_O, theta, mu), s))
    return out


def test_psi_tension_form_equals_frame_form():
    """Eq. 7 in the Eulerian frame equals |f_i - f_e| cos(d/2) - mu (f_i + f_e) sin(d/2)."""
    rng = np.random.default_rng(0)
    u_i = rng.normal(size=(500, 3))
    u_e = rng.normal(size=(500, 3))
    u_i /= np.linalg.norm(u_i, axis=1)[:, None]
    u_e /= np.linalg.norm(u_e, axis=1)[:, None]
    f_i, f_e, mu = rng.uniform(0.5, 9, 500), rng.uniform(0.5, 9, 500), rng.uniform(0, 0.6, 500)
    frame = psi_frame(f_i[:, None] * u_i, f_e[:, None] * u_e, mu)
    tension = psi(f_i, f_e, u_i, u_e, mu)
    np.testing.assert_allclose(tension, frame, rtol=0, atol=1e-12 * 20)  # double rounding of ~10 N
    kern = [K.psi_tension(a, b, float(np.dot(c, d)), m) for a, b, c, d, m in zip(f_i, f_e, u_i, u_e, mu)]
    np.testing.assert_allclose(kern, tension, rtol=0, atol=1e-12 * 20)


def test_stick_cone_is_the_discrete_capstan():
    """Psi <= 0 exactly when f_int / f_ext lies within cone_ratio (DESIGN.md friction equivalent)."""
    rng = np.random.default_rng(1)
    for _ in range(300):
        delta, mu = rng.uniform(0.01, 2.5), rng.uniform(0, 0.6)
        u_e = np.array([0.0, 1.0, 0.0])
        u_i = np.array([np.sin(delta), -np.cos(delta), 0.0])  # deflection delta from -u_e
        ratio = rng.uniform(0.3, 3.0)
        low, high = cone_ratio(delta, mu)
        inside = low <= ratio <= high
        assert (psi(ratio, 1.0, u_i, u_e, mu) <= 1e-14) == inside


@pytest.mark.parametrize("use_prev", [True, False])
def test_frictionless_limit_equal_tensions(use_prev):
    for A_X, A_O, F_X, F_O, theta, mu in sample(60, seed=2):
        s = solve_crossing(A_X, A_O, F_X, F_O, theta if use_prev else None, 0.0)
        assert s.ok, s.message
        assert s.f_X_int == pytest.approx(np.linalg.norm(F_X), rel=REL)
        assert s.f_O_int == pytest.approx(np.linalg.norm(F_O), rel=REL)
        assert abs(s.psi_X) < REL * np.linalg.norm(F_X) and abs(s.psi_O) < REL * np.linalg.norm(F_O)


def test_frictionless_predictor_then_stick_keeps_it():
    """theta_prev=None starts at the frictionless equilibrium, which sticks for any mu > 0."""
    A_X, A_O, F_X, F_O, theta, mu = next(sample(1, seed=3))
    s0 = solve_crossing(A_X, A_O, F_X, F_O, None, 0.0)
    s1 = solve_crossing(A_X, A_O, F_X, F_O, None, 0.3)
    assert (s1.slip_X, s1.slip_O) == (0, 0)
    np.testing.assert_array_equal(s1.C, s0.C)


def test_sticking_keeps_the_angles_exactly():
    """A small change of the external tensions inside the cone: angles identical, tensions within
    the cone, C moves only by the rotation about e1."""
    n_stick = 0
    for A_X, A_O, F_X, F_O, theta, mu in sample(40, seed=4):
        base = solve_crossing(A_X, A_O, F_X, F_O, None, 0.4)
        if not base.ok:
            continue
        s = solve_crossing(A_X, A_O, 1.01 * F_X, F_O, (base.theta_X, base.theta_O), 0.4)
        if (s.slip_X, s.slip_O) != (0, 0):
            continue
        n_stick += 1
        assert (s.theta_X, s.theta_O) == (base.theta_X, base.theta_O)
        assert s.psi_X <= 0 and s.psi_O <= 0
        for f_int, F_ext, u in ((s.f_X_int, 1.01 * F_X, s.u_X_int), (s.f_O_int, F_O, s.u_O_int)):
            delta = np.pi - np.arccos(np.clip(u @ F_ext / np.linalg.norm(F_ext), -1, 1))
            low, high = cone_ratio(delta, 0.4)
            assert low - 1e-12 <= f_int / np.linalg.norm(F_ext) <= high + 1e-12
        assert np.linalg.norm(s.C - A_X) == pytest.approx(np.linalg.norm(base.C - A_X), rel=1e-12)
    assert n_stick >= 30


def test_every_case_appears_and_lands_on_the_bound(solved):
    cases = set()
    for (A_X, A_O, F_X, F_O, theta, mu), s in solved:
        assert s.ok, s.message
        cases.add((s.slip_X, s.slip_O))
        for slip, p, F in ((s.slip_X, s.psi_X, F_X), (s.slip_O, s.psi_O, F_O)):
            scale = REL * np.linalg.norm(F)
            assert p <= scale
            if slip:
                assert abs(p) < scale
    assert cases == {(0, 0), (1, 0), (0, 1), (1, 1)}


def test_single_slip_keeps_the_other_angle(solved):
    """Warp slip (case 1 of the paper) moves only theta_O; weft slip moves only theta_X."""
    seen = 0
    for (A_X, A_O, F_X, F_O, theta, mu), s in solved:
        if (s.slip_X, s.slip_O) == (1, 0):
            assert s.theta_X == theta[0] and s.theta_O != theta[1]
            seen += 1
        elif (s.slip_X, s.slip_O) == (0, 1):
            assert s.theta_O == theta[1] and s.theta_X != theta[0]
            seen += 1
        elif (s.slip_X, s.slip_O) == (0, 0):
            assert (s.theta_X, s.theta_O) == tuple(theta)
    assert seen > 10


def test_slide_sign_follows_the_tension_jump(solved):
    """slide = sign(f_int - f_ext) while slipping with friction, 0 while sticking."""
    for (A_X, A_O, F_X, F_O, theta, mu), s in solved:
        for slip, slide, f_int, F in ((s.slip_X, s.slide_X, s.f_X_int, F_X),
                                      (s.slip_O, s.slide_O, s.f_O_int, F_O)):
            if not slip:
                assert slide == 0
            elif mu > 0:
                assert slide == np.sign(f_int - np.linalg.norm(F))


def test_force_balance_and_geometry(solved):
    for (A_X, A_O, F_X, F_O, theta, mu), s in solved:
        scale = np.linalg.norm(F_X) + np.linalg.norm(F_O)
        residual = s.F_X_int + F_X + s.F_O_int + F_O
        assert np.linalg.norm(residual) < REL * scale
        # internal directions point from C to the lower points, tensions positive
        for A, u in ((A_X, s.u_X_int), (A_O, s.u_O_int)):
            d = A - s.C
            np.testing.assert_allclose(d / np.linalg.norm(d), u, atol=1e-12)
        assert s.f_X_int > 0 and s.f_O_int > 0
        # C lies in the plane through A_X, A_O holding F_X + F_O; the angles describe C
        normal = np.cross(A_O - A_X, F_X + F_O)
        assert abs((s.C - A_X) @ normal) < 1e-12 * np.linalg.norm(normal) * np.linalg.norm(s.C - A_X) * 10
        np.testing.assert_allclose(crossing_angles(A_X, A_O, s.C), (s.theta_X, s.theta_O), atol=1e-11)


def test_matches_scipy_reference_on_200_configurations():
    for A_X, A_O, F_X, F_O, theta, mu in sample(200, seed=5):
        s = solve_crossing(A_X, A_O, F_X, F_O, theta, mu)
        ref = naive.Crossing(A_X, A_O, F_X, F_O, mu).solve(theta)
        assert s.ok == ref["ok"]
        if not s.ok:
            continue
        assert (s.slip_X, s.slip_O) == (ref["slip_X"], ref["slip_O"])
        # fsolve/brentq stop near 1e-14 on Psi; positions mm, so 1e-9 relative is ~pm
        np.testing.assert_allclose(s.C, ref["C"], rtol=0, atol=REL * 4e-3)
        assert s.f_X_int == pytest.approx(ref["f_X"], rel=REL)
        assert s.f_O_int == pytest.approx(ref["f_O"], rel=REL)
        assert s.psi_X == pytest.approx(ref["psi_X"], abs=REL * np.linalg.norm(F_X))
        assert s.psi_O == pytest.approx(ref["psi_O"], abs=REL * np.linalg.norm(F_O))


def test_homogeneous_in_the_external_tensions(solved):
    """Amontons friction is homogeneous: 3x the forces -> 3x the tensions, the same C and angles."""
    for (A_X, A_O, F_X, F_O, theta, mu), s in solved[:80]:
        s3 = solve_crossing(A_X, A_O, 3 * F_X, 3 * F_O, theta, mu)
        assert (s3.slip_X, s3.slip_O) == (s.slip_X, s.slip_O)
        assert s3.f_X_int == pytest.approx(3 * s.f_X_int, rel=REL)
        assert s3.f_O_int == pytest.approx(3 * s.f_O_int, rel=REL)
        np.testing.assert_allclose(s3.C, s.C, rtol=0, atol=REL * 4e-3)


def test_higher_friction_keeps_more_of_the_history():
    """With mu large enough (mu tan(delta/2) >= 1 self-locks) every crossing sticks."""
    for A_X, A_O, F_X, F_O, theta, mu in sample(30, seed=6):
        s = solve_crossing(A_X, A_O, F_X, F_O, theta, 50.0)
        if s.ok:
            assert (s.slip_X, s.slip_O) == (0, 0)


def test_batch_kernel_called_from_njit_matches_wrapper():
    problems = list(sample(50, seed=7))
    A_X, A_O, F_X, F_O = (np.array([p[k] for p in problems]) for k in range(4))
    theta = np.array([p[4] for p in problems])
    theta[::5] = np.nan  # no history: frictionless predictor
    mu = np.array([p[5] for p in problems])
    out, status = K.empty_out(len(problems)), np.zeros(len(problems), np.int64)
    K.solve_crossings(A_X, A_O, F_X, F_O, theta, mu, out, status)
    for i, p in enumerate(problems):
        s = solve_crossing(p[0], p[1], p[2], p[3], None if np.isnan(theta[i, 0]) else p[4], p[5])
        assert status[i] == s.status
        np.testing.assert_array_equal(out[i, K.OUT_C:K.OUT_C + 3], s.C)


def test_status_codes_instead_of_nan():
    A_X, A_O = np.zeros(3), np.array([4e-3, 0, 0])
    # S along e1: no plane
    s = solve_crossing(A_X, A_O, [1.0, 0.5, 0], [1.0, -0.5, 0], None, 0.2)
    assert s.status == K.CROSSING_PARALLEL and not s.ok and np.all(np.isfinite(s.C))
    # coincident lower points
    assert solve_crossing(A_X, A_X, [0, 1.0, 0], [0, 1.0, 0.1]).status == K.CROSSING_DEGENERATE
    # F_X makes an obtuse angle with S: the frictionless rays cross behind A_X A_O
    s = solve_crossing(A_X, A_O, [1.0, -0.5, 0], [-1.0, 1.5, 0], None, 0.2)
    assert s.status == K.CROSSING_NO_INTERSECTION and "meet" in s.message
    assert s.f_X_int == 0.0 and not np.any(np.isnan(s.C))


@pytest.mark.parametrize("kwargs, match", [
    (dict(A_X=[0, 0]), "A_X"),
    (dict(F_O_ext=[0, np.nan, 1]), "F_O_ext"),
    (dict(mu=-0.1), "mu"),
    (dict(theta_prev=(2.0, 1.5)), "theta_prev"),
])
def test_input_errors_name_the_argument(kwargs, match):
    args = dict(A_X=[-2e-3, 0, 0], A_O=[2e-3, 0, 0], F_X_ext=[1, 2, 0.1], F_O_ext=[-1, 2, -0.1])
    args.update(kwargs)
    with pytest.raises(ContactInputError, match=match) as err:
        solve_crossing(**args)
    assert isinstance(err.value, PreformError)


def test_crossing_angles_of_a_known_triangle():
    # right isosceles: C above the midpoint at half the base -> 45 degrees on each side
    tx, to = crossing_angles([0, 0, 0], [2, 0, 0], [1, 0, 1])
    assert tx == pytest.approx(np.pi / 4, abs=1e-15) and to == pytest.approx(np.pi / 4, abs=1e-15)
