"""Fibre content and permeability: closed forms, tensor invariants, binning."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from preform.analysis import rtm


def test_areal_weight_and_vf_on_a_cylinder_closed_form():
    N, tex, r, alpha = 144, 800.0, 0.075, math.radians(60.0)
    length_per_area = N / (2 * math.pi * r * math.cos(alpha))    # both groups
    aw = rtm.areal_weight(length_per_area, tex)
    assert aw == pytest.approx(N * tex * 1e-6 / (2 * math.pi * r * math.cos(alpha)), rel=1e-15)
    vf = rtm.fibre_volume_fraction(aw, 1780.0, 1.0e-3)
    assert vf == pytest.approx(aw / (1780.0 * 1e-3), rel=1e-15)
    assert rtm.fibre_volume_fraction(np.array([0.5]), 1780.0, np.array([0.0]))[0] == 0.0


@pytest.mark.parametrize("packing,c,c1,vf_max", [
    ("quadratic", 57.0, 16 / (9 * math.pi * math.sqrt(2)), math.pi / 4),
    ("hexagonal", 53.0, 16 / (9 * math.pi * math.sqrt(6)), math.pi / (2 * math.sqrt(3))),
])
def test_gebart_formulas(packing, c, c1, vf_max):
    R, vf = 3.5e-6, np.array([0.45, 0.55, 0.6])
    k_par, k_perp = rtm.gebart(vf, R, packing)
    np.testing.assert_allclose(k_par, 8 * R**2 * (1 - vf) ** 3 / (c * vf**2), rtol=1e-14)
    np.testing.assert_allclose(k_perp, c1 * (np.sqrt(vf_max / vf) - 1) ** 2.5 * R**2, rtol=1e-14)
    assert np.all(np.diff(k_par) < 0) and np.all(np.diff(k_perp) < 0)   # denser, tighter
    assert rtm.gebart(np.array([0.95]), R, packing)[1][0] == 0.0         # channels closed


def test_kozeny_carman_is_exact_at_the_reference_and_scales_by_its_law():
    (k,) = rtm.kozeny_carman(np.array([0.5, 0.6]), 2e-11, 0.5)
    assert k[0] == pytest.approx(2e-11, rel=1e-15)
    assert k[1] / k[0] == pytest.approx((0.4**3 / 0.36) / (0.5**3 / 0.25), rel=1e-14)


def braid_faces(alpha_deg, n=5, frame=None):
    """Faces of a cylinder around z with yarns at +-alpha to the axis."""
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    normals = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(n)])
    axis = np.tile([0.0, 0.0, 1.0], (n, 1))
    hoop = np.cross(axis, normals)
    a = math.radians(alpha_deg)
    d = np.stack([math.cos(a) * axis + math.sin(a) * hoop, math.cos(a) * axis - math.sin(a) * hoop], axis=1)
    if frame is not None:
        normals, axis, d = normals @ frame.T, axis @ frame.T, d @ frame.T
    return normals, axis, d


@pytest.mark.parametrize("alpha_deg", [30.0, 60.0])
def test_tensor_is_spd_with_principal_axes_along_axis_or_hoop(alpha_deg):
    normals, axis, d = braid_faces(alpha_deg)
    n = len(normals)
    k_par, k_perp = rtm.gebart(np.full(n, 0.55), 3.5e-6)
    K = rtm.tensor_from_yarns(k_par, k_perp, k_perp, d, np.full((n, 2), 0.5), normals)
    np.testing.assert_allclose(K, np.transpose(K, (0, 2, 1)), atol=1e-30)   # symmetric
    assert np.all(np.linalg.eigvalsh(K) > 0)                                 # positive definite
    k1, k2, direction = rtm.principal_in_plane(K, normals, axis)
    a = math.radians(alpha_deg)
    # in the axis-hoop basis: K_aa = Kpar cos^2 + Kperp sin^2, K_hh = Kpar sin^2 + Kperp cos^2
    along = k_par * math.cos(a) ** 2 + k_perp * math.sin(a) ** 2
    around = k_par * math.sin(a) ** 2 + k_perp * math.cos(a) ** 2
    np.testing.assert_allclose(k1, np.maximum(along, around), rtol=1e-12)
    np.testing.assert_allclose(k2, np.minimum(along, around), rtol=1e-12)
    expected = axis if alpha_deg < 45 else np.cross(axis, normals)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", direction, expected)), 1.0, atol=1e-12)
    assert np.allclose(np.einsum("ij,ij->i", direction, normals), 0.0, atol=1e-12)   # tangent
    assert np.allclose(np.linalg.norm(direction, axis=1), 1.0)


def test_rotating_the_mandrel_rotates_the_tensor():
    frame = Rotation.from_euler("zyx", [31, -17, 55], degrees=True).as_matrix()
    k_par, k_perp = np.full(5, 2e-12), np.full(5, 4e-13)
    K = rtm.tensor_from_yarns(k_par, k_perp, k_perp, braid_faces(40.0)[2], np.full((5, 2), 0.5),
                              braid_faces(40.0)[0])
    normals, axis, d = braid_faces(40.0, frame=frame)
    K_rot = rtm.tensor_from_yarns(k_par, k_perp, k_perp, d, np.full((5, 2), 0.5), normals)
    np.testing.assert_allclose(K_rot, frame @ K @ frame.T, atol=1e-27)


def test_binning_keeps_each_cell_within_the_reported_error():
    values = np.exp(np.random.default_rng(3).normal(-25.0, 0.4, 500))
    binning = rtm.bin_cells(values, 4)
    index, rep = binning.index, binning.values
    assert len(rep) == 4 and set(index) == {0, 1, 2, 3}
    ratio = np.abs(np.log(values / rep[index]))
    assert np.all(ratio <= np.log(binning.max_factor) + 1e-12)
    assert np.sqrt(np.mean(ratio ** 2)) == pytest.approx(np.log(binning.rms_factor), rel=1e-12)
