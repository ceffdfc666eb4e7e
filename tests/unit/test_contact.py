"""The friction function of a yarn at a contact (paper §2.2, eqs. 5-7; docs/theory.md §4): its tension
form, its Eulerian-frame form and the stick cone, which the frontal solver's friction bounds use."""

from __future__ import annotations

import numpy as np
import pytest

from preform.errors import PreformError
from preform.interaction.contact import (ContactInputError, as_friction, as_vector, cone_ratio,
                                         psi, psi_frame)


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


def test_stick_cone_is_the_discrete_capstan():
    """Psi <= 0 exactly when f_int / f_ext lies within cone_ratio (docs/theory.md §4: the
    friction law as a discrete Capstan)."""
    rng = np.random.default_rng(1)
    for _ in range(300):
        delta, mu = rng.uniform(0.01, 2.5), rng.uniform(0, 0.6)
        u_e = np.array([0.0, 1.0, 0.0])
        u_i = np.array([np.sin(delta), -np.cos(delta), 0.0])  # deflection delta from -u_e
        ratio = rng.uniform(0.3, 3.0)
        low, high = cone_ratio(delta, mu)
        inside = low <= ratio <= high
        assert (psi(ratio, 1.0, u_i, u_e, mu) <= 1e-14) == inside


def test_self_locking_cone_has_no_upper_ratio():
    """mu tan(delta/2) >= 1: any higher internal tension sticks (high = inf)."""
    low, high = cone_ratio(np.radians(170.0), 0.5)
    assert high == np.inf and low == pytest.approx((1 - 0.5 * np.tan(np.radians(85))) /
                                                   (1 + 0.5 * np.tan(np.radians(85))))


@pytest.mark.parametrize("check, value, match", [
    (as_vector, [0, 0], "A_X"),
    (as_vector, [0, np.nan, 1], "A_X"),
    (as_friction, -0.1, "A_X"),
])
def test_input_errors_name_the_argument(check, value, match):
    with pytest.raises(ContactInputError, match=match) as err:
        check("A_X", value)
    assert isinstance(err.value, PreformError)


def test_crossing_coefficient_kernel_matches_the_law_written_as_a_power_of_the_load():
    """``_kernels.friction.crossing_coefficient`` times N is Howell's a N^n (``naive_frontal.
    howell_bound``, a = mu N_ref^(1 - n)) above the linear force and the straight line through 0
    below it; index 1 gives mu exactly; ``CrossingFriction.coefficient_at`` is the same law."""
    from support.naive_frontal import howell_bound
    from preform._kernels.friction import crossing_coefficient
    from preform.interaction.contact import CrossingFriction

    rng = np.random.default_rng(3)
    load = rng.uniform(0.01, 10.0, 400)
    delta = rng.uniform(0.0, np.pi / 2, 400)
    N = load * np.sin(delta / 2)
    for mu, n, ref, lin in [(0.25, 0.8, 1.0, 1e-3), (0.4, 0.67, 0.2, 0.05), (0.3, 1.0, 3.0, 1e-3)]:
        law = CrossingFriction(law="howell", coefficient=mu, index=n, reference_force=ref,
                               linear_below=lin)
        assert law.n_lin == lin * ref
        kernel = np.array([crossing_coefficient(x, mu, n, ref, lin * ref) for x in N])
        expect = howell_bound(load, delta, mu, n, ref, lin * ref)
        # the same law by two formulas: rounding of pow and sin, 1e-15 relative
        assert np.allclose(kernel * N, expect, rtol=1e-12, atol=1e-300)
        assert np.allclose(law.coefficient_at(N), kernel, rtol=1e-12)
        assert (N < lin * ref).any() or lin < 0.01      # the linear part seen where it is wide
    # index 1: the coefficient itself, to the bit, at any force and reference
    assert all(crossing_coefficient(x, 0.3, 1.0, 0.5, 5e-4) == 0.3 for x in [0.0, 1e-9, 0.7, 80.0])
    # N -> 0: the bound goes to 0 with a finite slope, the coefficient stays bounded
    c0 = crossing_coefficient(0.0, 0.25, 0.8, 1.0, 1e-3)
    assert np.isfinite(c0) and c0 == pytest.approx(0.25 * 1e-3 ** -0.2, rel=1e-14)


def test_crossing_friction_per_pair_looks_up_each_crossings_two_types():
    from preform.interaction.contact import CrossingFriction

    types = np.array([0, 1, 1, 0, 2, 2])
    coef = np.array([[0.2, 0.1, 0.3], [0.1, 0.25, 0.15], [0.3, 0.15, 0.4]])
    index = np.array([[1.0, 0.9, 0.8], [0.9, 0.85, 0.95], [0.8, 0.95, 0.7]])
    law = CrossingFriction(law="howell", coefficient=0.2, index=0.8, yarn_type=types,
                           pair_coefficient=coef, pair_index=index)
    yarn = np.array([[0, 3], [1, 4], [2, 5], [0, 4]])
    mu, n = law.per_crossing(yarn)
    assert mu.tolist() == [0.2, 0.15, 0.15, 0.3] and n.tolist() == [1.0, 0.95, 0.95, 0.8]
    N = np.array([0.01, 0.02, 0.5, 1.5])
    assert np.allclose(law.coefficient_at(N, yarn), mu * (np.maximum(N, 1e-3) / 1.0) ** (n - 1.0),
                       rtol=1e-14)
    # one coefficient: every crossing gets it
    one = CrossingFriction(coefficient=0.25)
    assert one.per_crossing(yarn)[0].tolist() == [0.25] * 4
    assert one.per_crossing(yarn)[1].tolist() == [1.0] * 4
