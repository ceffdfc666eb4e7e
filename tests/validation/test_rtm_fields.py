"""RTM fields on a steady braided cylinder: areal weight, Vf and porosity against the
closed forms, permeability against Gebart at the face's Vf along the right directions; and the
files written into rtm/ when the config has tow data."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from preform.analysis import rtm
from preform.analysis.fields import face_geometry, map_to_surface
from support.field_standins import cylinder, helices, make_result, side_faces

R, N_GROUP, TEX, RHO, FIBRE_R, CAVITY = 0.05, 24, 800.0, 1780.0, 3.5e-6, 1.0e-3


@pytest.fixture(scope="module", params=[30.0, 60.0])
def braided(request):
    alpha = math.radians(request.param)
    fields = map_to_surface(make_result(cylinder(), helices(alpha, N_GROUP)), edge_length=0.012)
    config = NS(yarn=NS(linear_density_tex=TEX, fibre_density=RHO, fibre_radius=FIBRE_R, has_material=True),
                rtm=NS(cavity_thickness=CAVITY, permeability="gebart", packing="hexagonal"))
    V, F = fields.vertices, fields.faces
    tangents = np.tile([0.0, 0.0, 1.0], (len(F), 1))
    return alpha, fields, rtm.rtm_fields(fields, config, tangents)


def test_areal_weight_vf_and_porosity_match_the_closed_forms(braided):
    alpha, fields, out = braided
    inner, _ = side_faces(fields, margin=2 * fields.pool_radius_m)
    N = 2 * N_GROUP
    aw = N * TEX * 1e-6 / (2 * math.pi * R * math.cos(alpha))     # the closed form
    # 3 %: the pooling's flicker over discrete yarns, as for the cover factor
    assert np.allclose(out["areal_weight_kg_m2"][inner], aw, rtol=0.03)
    assert np.allclose(out["fibre_volume_fraction"][inner], aw / (RHO * CAVITY), rtol=0.03)
    np.testing.assert_allclose(out["porosity"][inner], 1.0 - out["fibre_volume_fraction"][inner])


def test_permeability_is_gebarts_along_the_axis_or_around_it(braided):
    alpha, fields, out = braided
    inner, _ = side_faces(fields, margin=2 * fields.pool_radius_m)
    vf = out["fibre_volume_fraction"][inner]
    k_par, k_perp = rtm.gebart(vf, FIBRE_R, "hexagonal")
    # the face's directions are the fields' (within 0.5 deg of alpha): compare at their angle
    a = np.radians(fields.cell_data["braid_angle_deg"][inner])
    along = k_par * np.cos(a) ** 2 + k_perp * np.sin(a) ** 2
    around = k_par * np.sin(a) ** 2 + k_perp * np.cos(a) ** 2
    # 2e-3: a face's warp and weft angles differ by hundredths of a degree (pooled separately),
    # which the mean angle used here hides; K rotates with them by ~1e-3 (measured 4.6e-4)
    np.testing.assert_allclose(out["permeability_k1_m2"][inner], np.maximum(along, around), rtol=2e-3)
    np.testing.assert_allclose(out["permeability_k2_m2"][inner], np.minimum(along, around), rtol=2e-3)
    np.testing.assert_allclose(out["permeability_k3_m2"][inner], k_perp, rtol=1e-9)
    d = out["permeability_direction"][inner]
    axial = np.abs(d[:, 2])
    # within 5 deg of the axis below a 45 deg braid angle, of the hoop above: the two families'
    # yarn lengths on a face differ by a few % (discrete yarns, pooled), which turns the principal
    # axes of their sum (seen: median 1.3 deg, largest 3.0 deg at 30 deg)
    if alpha < math.radians(45):
        assert np.all(axial > math.cos(math.radians(5))) and np.median(axial) > math.cos(math.radians(2))
    else:
        assert np.all(axial < math.sin(math.radians(5))) and np.median(axial) < math.sin(math.radians(2))
    K = out["permeability_m2"][inner].reshape(-1, 3, 3)
    np.testing.assert_allclose(K, np.transpose(K, (0, 2, 1)), rtol=1e-14, atol=0)   # round-off
    assert np.all(np.linalg.eigvalsh(K) > 0)
    assert np.all(out["rtm_valid"][inner] == 1)


def test_faces_without_yarn_are_no_preform(braided):
    _, fields, out = braided
    bare = (fields.cell_data["reached_warp"] == 0) & (fields.cell_data["reached_weft"] == 0)
    assert np.any(bare)
    assert np.all(out["porosity"][bare] == 1.0) and np.all(out["rtm_valid"][bare] == 0)
    assert np.all(out["permeability_m2"][bare] == 0.0)


def _case(folder, material):
    from support.simcase import write_cylinder_case

    tow = "linear_density_tex = 800.0\nfibre_density = 1780.0\nfibre_radius = 3.5e-6" if material else ""
    return write_cylinder_case(folder, length=0.4, braid=0.08, snapshots=0, friction=0.0,
                               yarn_extra=tow, extra="[rtm]\ncavity_thickness = 1e-4",
                               output_extra="pictures = false")   # the RTM files, not pictures


def test_preform_run_writes_the_rtm_files_with_tow_data_and_says_why_not_without(tmp_path, capsys):
    import json

    import h5py
    import meshio

    from preform.cli import main

    out = tmp_path / "out"
    assert main(["run", str(_case(tmp_path / "a", True)), "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rtm"]["written"] and summary["rtm"]["sets"] <= 4
    with h5py.File(out / "rtm" / "lcmsim.h5") as f:
        porosity = f["/properties/porosity"][...]
        assert len(porosity) == len(f["/mesh/cells"]) and np.all((porosity > 0) & (porosity <= 1))
    assert (out / "rtm" / "rtmsim.bdf").stat().st_size > 1000
    mesh = meshio.read(out / "surface.vtu")
    assert mesh.cell_data["permeability_m2"][0].shape[1] == 9
    plain = tmp_path / "plain"
    assert main(["run", str(_case(tmp_path / "b", False)), "--out", str(plain), "--no-progress"]) == 0
    summary = json.loads((plain / "summary.json").read_text())
    assert not summary["rtm"]["written"] and "linear_density_tex" in summary["rtm"]["reason"]
    assert not (plain / "rtm").exists()


def test_triaxial_areal_weight_adds_the_axial_yarns():
    from support.field_standins import coverage_closed_form  # noqa: F401 - same stand-ins

    alpha, n_axial = math.radians(30.0), 16
    result = make_result(cylinder(), helices(alpha, N_GROUP))
    result.config.axial = lambda: (n_axial, 3e-3, 3e-4, None)
    fields = map_to_surface(result, edge_length=0.012)
    config = NS(yarn=NS(linear_density_tex=TEX, fibre_density=RHO, fibre_radius=FIBRE_R, has_material=True),
                rtm=NS(cavity_thickness=CAVITY, permeability="gebart", packing="hexagonal"),
                axial=lambda: (n_axial, 3e-3, 3e-4, None))
    out = rtm.rtm_fields(fields, config, np.tile([0.0, 0.0, 1.0], (len(fields.faces), 1)))
    inner, _ = side_faces(fields, margin=2 * fields.pool_radius_m)
    aw = (2 * N_GROUP / math.cos(alpha) + n_axial) * TEX * 1e-6 / (2 * math.pi * R)
    assert np.allclose(out["areal_weight_kg_m2"][inner], aw, rtol=0.03)   # as the biaxial one
    K = out["permeability_m2"][inner].reshape(-1, 3, 3)
    assert np.all(np.linalg.eigvalsh(K) > 0)
