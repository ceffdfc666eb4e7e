"""Quasi-static references (Ko, H_inf, settling length) of a set-up."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from preform import analytic
from preform.config import load_config
from preform.reference import SETTLED_FRACTION, check_lines, references

RADIUS = 0.075   # case A's cylinder


@pytest.fixture(scope="module")
def case_a():
    """The paper's case A as its friction study starts it: 0.4 m from the spool plane, 1 m braided."""
    cfg = load_config("examples/case_a.toml")
    return dataclasses.replace(cfg, process=dataclasses.replace(cfg.process, initial_position=0.4,
                                                                braid_length=1.0))


def test_references_on_a_cylinder_are_the_closed_forms(case_a):
    s = np.linspace(0.0, 2.0, 21)
    refs = references(case_a, s, np.full_like(s, 2 * math.pi * RADIUS))
    omega, v, R = case_a.machine.angular_speed, 0.01, case_a.machine.spool_radius
    assert refs.ko_deg == pytest.approx(np.degrees(analytic.ko_braid_angle(omega, RADIUS, v)), rel=1e-12)
    H_inf = analytic.steady_convergence_length(omega, RADIUS, v, R)
    assert refs.h_inf == pytest.approx(H_inf, rel=1e-12)
    # Du & Popper from H0 = 0.4 m: |0.4 - H_inf| exp(-L / H_inf) = 1 % of H_inf
    L = H_inf * math.log(abs(0.4 - H_inf) / (SETTLED_FRACTION * H_inf))
    assert refs.settle_length == pytest.approx(L, rel=1e-12)
    H = analytic.du_popper_convergence_length(L / v, 0.4, omega, RADIUS, v, R)
    assert abs(H - H_inf) == pytest.approx(SETTLED_FRACTION * H_inf, rel=1e-9)


def test_check_says_when_the_braid_is_too_short_to_settle(case_a):
    s = np.linspace(0.0, 2.0, 21)
    per = np.full_like(s, 2 * math.pi * RADIUS)
    lines = check_lines(case_a, references(case_a, s, per))
    assert lines[0].startswith("Ko's braid angle 60.0-60.0 deg") and "H_inf 0.797-0.797 m" in lines[0]
    assert "will not reach steady state" in lines[1]
    # the settling length from 0.4 m: 0.797 ln(0.397 / 0.00797) = 3.11 m
    assert "braid at least 3.11 m, or start nearer H_inf: [process] initial_position = 0.797 m" in lines[1]
    # a mandrel that cannot hold that braid (3.11 m + H_inf 0.797 m > 2 m) is only told what it can do
    (_, short) = check_lines(case_a, references(case_a, s, per), length=2.0)
    assert "braid at least" not in short
    assert ("the 2 m mandrel cannot hold 3.11 m of braid and its convergence zone, so start nearer "
            "H_inf: [process] initial_position = 0.797 m") in short
    # started at H_inf, the transient has nothing to settle
    near = dataclasses.replace(case_a, process=dataclasses.replace(case_a.process, initial_position=0.797))
    assert len(check_lines(near, references(near, s, per))) == 1
