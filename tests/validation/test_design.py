"""Take-up speed design for a target braid angle, kinematic forward model."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

import preform as pf
from preform import analytic
from preform.cli import main
from preform.studies.design import DESIGN, design_speed

ROOT = Path(__file__).resolve().parents[2]


def case(tmp_path, name, stl, spool, braid, ring="", eccentricity="[0.0, 0.0]", omega=20.0,
         initial_position=0.15):
    path = tmp_path / f"{name}.toml"
    path.write_text(f"""
[mandrel]
stl = "{ROOT / 'mandrels' / (stl + '.stl')}"
centerline = "{ROOT / 'mandrels' / (stl + '_centerline.csv')}"
[machine]
carriers = 16
spool_radius = {spool}
angular_speed = {omega}
{ring}
[yarn]
width = 4e-3
thickness = 2.5e-4
[process]
take_up_speed = 0.01
initial_position = {initial_position}
eccentricity = {eccentricity}
braid_length = {braid}
[output]
snapshots = 0
""")
    return pf.load_config(path)


def judged_error(design):
    # required: beyond the first two convergence lengths of braid
    sel = design.length >= DESIGN.judged_after * design.h_inf
    assert np.count_nonzero(sel) >= 5
    return float(np.max(np.abs(design.achieved_deg[sel] - design.target_deg[sel])))


@pytest.fixture(scope="module")
def cone(tmp_path_factory):
    return case(tmp_path_factory.mktemp("cone"), "cone", "cone", spool=0.25, braid=0.6)


def test_a_constant_angle_on_a_cone(cone):
    design = design_speed(cone, 45.0)
    assert judged_error(design) < 1.0       # required: within 1 deg of a constant target
    # the cone widens: the speed for a constant angle grows with the radius (v ~ omega r)
    assert design.speed[-1] > 1.5 * design.speed[0]


def test_a_rising_target_table_on_a_cone(cone):
    design = design_speed(cone, np.array([[0.0, 45.0], [0.6, 55.0]]))
    assert judged_error(design) < 1.5       # required: within 1.5 deg of a target table


def test_a_constant_angle_on_the_case_b_like_mandrel(tmp_path):
    cfg = case(tmp_path, "b", "case_b", spool=0.85, braid=1.2, omega=18.0,
               ring="guide_ring = { radius = 0.17, offset = 0.0 }", eccentricity="[0.025, 0.0]")
    design = design_speed(cfg, 35.0)
    assert judged_error(design) < 1.0


def test_the_design_on_a_cylinder_is_kos_speed(tmp_path, capsys):
    cfg = case(tmp_path, "cyl", "case_a", spool=0.3, braid=1.6, initial_position=0.168)
    out = tmp_path / "designed.toml"
    # the tail of the start-up transient leaves about 0.3 deg just past where judging starts
    # (test_design_promise.py: below 0.2 deg is not met, and says so); this test is about the
    # steady speed, so it asks for 0.5 deg and expects the design to be met
    assert main(["design", str(cfg.source), "--target-angle", "60", "--tolerance", "0.5",
                 "--out", str(out)]) == 0
    written = tomllib.loads(out.read_text())
    table = np.array(written["process"]["take_up_speed"])
    ko = analytic.ko_braid_angle  # tan(alpha) = omega r / v  ->  v = omega r / tan(60 deg)
    v_ko = math.radians(20.0) * 0.075 / math.tan(math.radians(60.0))
    assert np.isclose(math.degrees(ko(math.radians(20.0), 0.075, v_ko)), 60.0)
    h_inf = analytic.steady_convergence_length(math.radians(20.0), 0.075, v_ko, 0.3)
    # the design leans on the speed while the start-up transient decays (over H_inf = 0.17 m);
    # six convergence lengths on, what is left of it (exp(-6) of ~1 deg) is below 0.01 deg and
    # the designed speed is Ko's; 0.3 %: the 128-gon's perimeter is 0.02 % short of the circle's,
    # and the corrections made upstream still reach exp(-6) = 0.25 % of their size here
    steady = table[:, 0] >= 6 * h_inf
    assert np.count_nonzero(steady) >= 10
    np.testing.assert_allclose(table[steady, 1], v_ko, rtol=3e-3)
    assert (tmp_path / "designed_design.png").stat().st_size > 10_000
    # the written config runs as it is
    assert pf.load_config(out).process.take_up_speed[0] == tuple(table[0])
