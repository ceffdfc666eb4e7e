"""Surface fields from a real kinematic run on a cylinder in steady state (docs/theory.md §5)."""

from __future__ import annotations

import numpy as np
import pytest

import preform as pf
from preform import analytic
from preform.geometry import shapes
from support.simcase import make_config, write_centerline, write_stl

OMEGA = 0.2309401     # Ko angle 60 deg at r = 75 mm, v = 10 mm/s
CARRIERS = 48


@pytest.fixture(scope="module")
def mapped(tmp_path_factory):
    d = tmp_path_factory.mktemp("fields")
    verts, faces = shapes.cylinder(0.075, 1.2, n_around=128)
    cfg = make_config(write_stl(d / "c.stl", verts, faces), write_centerline(d / "c.csv", [[0, 0, 0], [0, 0, 1.2]]),
                      carriers=CARRIERS, spool_radius=0.3, initial_position=0.02, braid_length=0.9)
    result = pf.simulate(cfg, progress=False)
    return result, pf.map_to_surface(result, edge_length=0.01)


def _steady_side(fields):
    c = fields.vertices[fields.faces].mean(axis=1)
    # laid more than 5 time constants after the yarns started wrapping, and not on the end caps
    return (c[:, 2] > 0.72) & (c[:, 2] < 0.82) & (np.hypot(c[:, 0], c[:, 1]) > 0.07)


def _area(fields):
    p = fields.vertices[fields.faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def test_mapped_cover_factor_and_thickness_match_closed_forms(mapped):
    result, fields = mapped
    side = _steady_side(fields)
    area = _area(fields)[side]
    cf = np.average(fields.cell_data["cover_factor"][side], weights=area)
    alpha = analytic.ko_braid_angle(OMEGA, 0.075, 0.01)
    expected = analytic.cover_factor(CARRIERS, 4e-3, 0.075, alpha)
    assert cf == pytest.approx(expected, rel=0.05)          # required: within 5 %
    k = analytic.yarn_coverage(CARRIERS / 2, 4e-3, 0.075, alpha)
    t = np.average(fields.cell_data["thickness_m"][side], weights=area)
    assert t == pytest.approx(2.5e-4 * 2 * k, rel=0.10)    # required: within 10 %


def test_mapped_braid_angle_is_ko_and_directions_are_tangent(mapped):
    result, fields = mapped
    side = _steady_side(fields)
    ko = np.degrees(analytic.ko_braid_angle(OMEGA, 0.075, 0.01))
    for name in ("braid_angle_warp_deg", "braid_angle_weft_deg", "braid_angle_deg"):
        assert np.abs(fields.cell_data[name][side] - ko).max() < 0.5      # required: 0.5 deg
    p = fields.vertices[fields.faces]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    for name in ("warp_direction", "weft_direction"):
        d = fields.cell_data[name][side]
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-9)
        assert np.abs(np.einsum("ij,ij->i", d, n[side])).max() < 1e-6


def test_no_nan_anywhere(mapped):
    _, fields = mapped
    for name, values in fields.cell_data.items():
        assert np.all(np.isfinite(values)), name
