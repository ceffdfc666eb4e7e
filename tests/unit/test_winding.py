"""The winding-number kernel (``_kernels.mesh.winding_numbers``, the centerline-inside check of
``preform check``) against its NumPy reference (``support.naive_intake``, solid angles summed in
face order) and
against known answers on well-shaped and sliver triangulations."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from preform._kernels.mesh import winding_numbers
from support.naive_intake import winding_numbers as numpy_winding

MESHES = {
    "icosphere": lambda: trimesh.creation.icosphere(3, radius=0.05),
    # trimesh's CAD-style cylinder: 64 pairs of side slivers 1.6 m long, 4 mm wide
    "sliver cylinder": lambda: trimesh.creation.cylinder(radius=0.04, height=1.6, sections=64),
    "box": lambda: trimesh.creation.box((0.1, 0.2, 0.3)),
}


@pytest.mark.parametrize("name", MESHES)
def test_winding_numbers_match_numpy_and_know_inside_from_outside(name):
    mesh = MESHES[name]()
    V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    rng = np.random.default_rng(3)
    lo, hi = mesh.bounds
    P = lo - 0.2 * (hi - lo) + rng.random((200, 3)) * 1.4 * (hi - lo)
    w = np.empty(len(P))
    winding_numbers(V, F, P, w)
    # the NumPy form (small meshes' path): the same terms summed in the same order, but NumPy's
    # arctan2 is not libm's (the last bit differs for 7 % of random arguments): measured 4e-17
    np.testing.assert_allclose(w, numpy_winding(V, F, P), rtol=0, atol=1e-14)
    # 1 inside, 0 outside, to round-off, for points off the surface (trimesh's ray test agrees)
    d = np.abs(trimesh.proximity.signed_distance(mesh, P))
    far = d > 1e-3
    inside = mesh.contains(P)
    assert np.all(np.abs(w[far] - inside[far]) < 1e-9)
    assert 20 < inside[far].sum() < far.sum() - 20


def test_an_inside_out_surface_winds_minus_one():
    mesh = trimesh.creation.icosphere(2)
    F = np.ascontiguousarray(mesh.faces[:, ::-1], dtype=np.int64)
    w = np.empty(1)
    winding_numbers(np.ascontiguousarray(mesh.vertices), F, np.zeros((1, 3)), w)
    assert w[0] == pytest.approx(-1.0, abs=1e-12)
