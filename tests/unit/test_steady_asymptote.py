"""Steady state read against the asymptote the run approaches (preform.analysis.steady), on closed forms:
an exponential approach y = y_inf + b exp(-L / lambda) whose asymptote and whose entry into the
tolerance band are known exactly."""

from __future__ import annotations

import numpy as np
import pytest

from preform.analysis.steady import STEADY, fit_asymptote, steady_state


def approach(L, y_inf, b, decay):
    return y_inf + b * np.exp(-L / decay)


def history(L, H, angle):
    return {"braided_length_m": L, "convergence_length_mean_m": H,
            "convergence_length_min_m": H, "convergence_length_max_m": H,
            "braid_angle_warp_deg": angle, "braid_angle_weft_deg": angle.copy()}


def test_the_fit_recovers_an_exponential_approach():
    L = np.linspace(1.0, 2.0, 500)
    fit = fit_asymptote(L, approach(L, 60.0, -5.0, 0.8))
    # exact data: the golden-section search brackets lambda to 1e-7 relative; what is left is
    # the flatness of the squared residual at its minimum, measured 1e-6 relative in lambda
    # and 1e-5 deg in the asymptote: the bounds leave a margin of ten
    assert fit["decay_length_m"] == pytest.approx(0.8, rel=1e-4)
    assert fit["asymptote"] == pytest.approx(60.0, abs=1e-4)
    assert fit["rms"] < 1e-3


def test_a_synthetic_approach_is_steady_at_its_asymptote_from_where_it_is_within_tolerance():
    # case A's shape: the angle rises to Ko's 60 deg, H rises to H_inf = 0.8 m, over lambda = 0.8 m
    L = np.linspace(0.0, 4.0, 4001)
    H = approach(L, 0.8, -0.3, 0.8)
    angle = approach(L, 60.0, -5.0, 0.8)
    st = steady_state(history(L, H, angle))
    assert st["reached"]
    # the steady values are the asymptotes, not the final values (which lie below them)
    assert st["braid_angle_deg"]["warp"] == pytest.approx(60.0, abs=1e-4)
    assert st["convergence_length_m"] == pytest.approx(0.8, rel=1e-4)
    assert st["braid_angle_deg"]["warp"] > angle[-1]
    # the band is entered where b exp(-L / lambda) = tolerance, for H and for the angle; the
    # later of the two decides: H at 0.8 ln(0.3 / 0.008), the angle at 0.8 ln(5 / 0.25)
    L_H = 0.8 * np.log(0.3 / (STEADY.rel_H * 0.8))
    L_angle = 0.8 * np.log(5.0 / STEADY.angle_deg)
    L_star = max(L_H, L_angle)
    # to the grid's 1 mm and the fitted asymptote's error (1e-3 deg over a slope of 0.3 deg/m)
    assert st["braided_length_m"] == pytest.approx(L_star, abs=5e-3)


def test_a_curve_still_rising_is_not_steady():
    # case A's own numbers at 2 m: still 0.17 deg below 60 and rising; with lambda = 1.2 m and a
    # run of 2 m the angle at the end is 2.3 deg short of its asymptote: no steady state
    L = np.linspace(0.0, 2.0, 2001)
    H = approach(L, 0.8, -0.3, 1.2)
    angle = approach(L, 60.0, -12.0, 1.2)
    st = steady_state(history(L, H, angle))
    assert not st["reached"]
    assert "braided_length_m" not in st and "braid_angle_deg" not in st
    # the drift: the slope of 12/1.2 exp(-L/1.2) over the last half, 1.9 to 4.3 deg/m
    assert 1.9 < st["drift"]["braid_angle_warp_deg_per_m"] < 4.4
    # and the asymptote it heads for is still named
    assert st["fits"]["warp"]["asymptote"] == pytest.approx(60.0, abs=0.05)


def test_a_straight_rise_is_not_steady_even_if_its_last_stretch_looks_flat():
    # 0.2 deg/m: inside the 0.25 deg tolerance over any 1 m, but it approaches nothing
    L = np.linspace(0.0, 3.0, 3001)
    st = steady_state(history(L, np.full_like(L, 0.8), 55.0 + 0.2 * L))
    assert not st["reached"]
    assert st["drift"]["braid_angle_warp_deg_per_m"] == pytest.approx(0.2, rel=1e-6)


def test_a_curve_the_exponential_does_not_describe_is_not_steady():
    # a changing section: the angle swings by +-1 deg along the part; no asymptote
    L = np.linspace(0.0, 3.0, 3001)
    angle = 45.0 + np.sin(2 * np.pi * L / 0.7)
    st = steady_state(history(L, np.full_like(L, 0.8), angle))
    assert not st["reached"]


def test_after_a_section_change_the_stretch_beyond_it_is_read_alone():
    # case B's shape: an approach to 0.26 m and 33 deg, then a section change at 1.0 m and a new
    # flat level (0.25 m, 32.9 deg) over the last 0.2 m, more than half a convergence length
    L = np.linspace(0.0, 1.2, 1201)
    after = L >= 1.0
    H = np.where(after, 0.25, approach(L, 0.26, 0.04, 0.2))
    angle = np.where(after, 32.9, approach(L, 33.5, 2.0, 0.2))
    st = steady_state(history(L, H, angle))
    assert st["reached"]
    # the window halved twice (0.6, 0.3, 0.15 m) lies beyond the change: its asymptotes are the
    # new levels exactly (flat data), and every value from the change on is within tolerance
    assert st["fit_window_m"][0] >= 1.0
    assert st["convergence_length_m"] == pytest.approx(0.25, abs=1e-9)
    assert st["braid_angle_deg"]["warp"] == pytest.approx(32.9, abs=1e-9)
    assert st["braided_length_m"] == pytest.approx(1.0, abs=1e-3)
