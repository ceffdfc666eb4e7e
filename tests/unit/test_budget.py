"""Bounds on work: estimates and refusals with their reasons."""

from __future__ import annotations

import dataclasses
import math

import pytest

from preform.budget import LIMITS, braiding_time, check_work, estimate_work
from preform.config import load_config
from preform.errors import ConfigError

CASE_A = "examples/case_a.toml"
#: case A's mandrel: a 150 mm cylinder (radius 0.075 m)
RADIUS = 0.075


@pytest.fixture(scope="module")
def case_a():
    return load_config(CASE_A)


def _with(config, section, **values):
    return dataclasses.replace(config, **{section: dataclasses.replace(getattr(config, section), **values)})


def test_braiding_time_of_a_constant_speed_and_of_a_table(case_a):
    assert braiding_time(case_a) == pytest.approx(case_a.process.braid_length / 0.01)
    table = _with(case_a, "process", take_up_speed=((0.0, 0.01), (1.0, 0.02)), braid_length=1.0)
    # closed form of int_0^1 dL / (0.01 + 0.01 L) = 100 ln 2; trapezoids on 2000 intervals: 1e-6
    assert braiding_time(table) == pytest.approx(100.0 * math.log(2.0), rel=1e-6)


def test_estimate_counts_faces_from_area_and_edge(case_a):
    cfg = _with(case_a, "output", field_edge_length=2e-3)
    area = 2 * math.pi * RADIUS * 2.0
    est = estimate_work(cfg, area, time_step=0.05)
    assert est.field_faces == int(area / (math.sqrt(3) / 4 * 4e-6))
    assert est.steps == int(case_a.process.braid_length / 0.01 / 0.05)
    check_work(cfg, est, RADIUS)   # a normal case passes


def test_a_tiny_field_edge_is_refused_unless_forced(case_a):
    cfg = _with(case_a, "output", field_edge_length=1e-9)
    est = estimate_work(cfg, 1.0, time_step=0.05)
    with pytest.raises(ConfigError, match=r"field_edge_length = 1e-09 m asks for about .* --force"):
        check_work(cfg, est, RADIUS)
    check_work(cfg, est, RADIUS, force=True)


def test_a_tiny_time_step_is_refused_unless_forced(case_a):
    cfg = _with(case_a, "model", time_step=1e-300)
    est = estimate_work(cfg, 1.0, time_step=1e-300)
    assert est.steps > LIMITS.max_steps
    with pytest.raises(ConfigError, match=r"time_step = 1e-300 s makes about"):
        check_work(cfg, est, RADIUS)
    check_work(cfg, est, RADIUS, force=True)


def test_more_yarns_than_fit_the_perimeter_are_refused_even_when_forced(case_a):
    cfg = _with(case_a, "machine", carriers=10_000)
    est = estimate_work(cfg, 1.0, time_step=0.05)
    least = cfg.yarn.least_width
    # 5000 yarns narrowed to their least width against a perimeter of 0.47 m: at most
    # floor(4 pi r / w) carriers
    with pytest.raises(ConfigError, match=rf"carriers = 10000: .* at most {int(4 * math.pi * RADIUS / least)} "
                                          r"carriers.*min_width"):
        check_work(cfg, est, RADIUS, force=True)


def test_the_carriers_fit_at_the_least_width_the_model_narrows_to(case_a):
    """96 yarns of 4 mm on a 0.189 m perimeter do not fit side by side at their width
    (0.192 m a group) but do at the 2 mm the model narrows them to (0.096 m); 200 of 2 mm
    (0.2 m a group) do not."""
    radius = 0.189 / (2 * math.pi)
    cfg = _with(_with(case_a, "machine", carriers=96), "yarn", width=4e-3, min_width=2e-3)
    est = estimate_work(cfg, 1.0, time_step=0.05)
    check_work(cfg, est, radius)
    with pytest.raises(ConfigError, match=r"carriers = 200: 100 yarns per group, each narrowed to its "
                                          r"least width 0.002 m \(\[yarn\] min_width\), need 0.2 m"):
        check_work(_with(cfg, "machine", carriers=200), est, radius)


@pytest.mark.parametrize("width", [1e-9, 1e-170, 5e-324])
def test_a_tiny_yarn_width_is_refused_by_the_faces_it_asks_for(case_a, width):
    """With no field_edge_length the edge comes from the yarn width; a width whose square
    underflows to 0 counts as unbounded work, and the message names the width (the edge is
    not in the config)."""
    cfg = _with(case_a, "yarn", width=width)
    est = estimate_work(cfg, 1.0, time_step=0.05)
    assert est.field_faces > LIMITS.max_field_faces
    with pytest.raises(ConfigError, match=r"field edge length .* \(from \[yarn\] width = .*\) asks for"):
        check_work(cfg, est, RADIUS)


def test_a_take_up_speed_that_makes_unbounded_steps_names_the_automatic_step(case_a):
    cfg = _with(case_a, "process", take_up_speed=((0.0, 1e-320),))
    est = estimate_work(cfg, 1.0, time_step=0.05)
    assert est.steps > LIMITS.max_steps
    with pytest.raises(ConfigError, match=r"the automatic time step 0.05 s makes about .* take_up_speed .* expected a take-up speed"):
        check_work(cfg, est, RADIUS)
    assert estimate_work(cfg, 1.0, time_step=0.0).steps >= LIMITS.max_steps   # no ZeroDivisionError
