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
