"""Mesh intake of damaged CAD STLs: repaired and said, or refused clearly."""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from preform.cli import main
from preform.errors import MandrelError
from preform.geometry import load_mandrel
from preform.geometry.repair import repair_mesh


@pytest.fixture(scope="module")
def cone():
    verts, faces = __import__("preform.geometry.shapes", fromlist=["cone"]).cone(0.04, 0.08, 1.0, n_around=64, n_along=40)
    return trimesh.Trimesh(verts, faces, process=False)


def _check_closed(v, f, volume):
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume == pytest.approx(volume, rel=1e-6)


def test_clean_mesh_is_untouched(cone):
    v, f, report = repair_mesh(cone.vertices, cone.faces)
    assert not report.changed
    _check_closed(v, f, cone.volume)


def test_triangle_soup_is_merged(cone):
    soup = cone.vertices[cone.faces].reshape(-1, 3)
    v, f, report = repair_mesh(soup, np.arange(len(soup)).reshape(-1, 3))
    assert len(v) == len(cone.vertices)
    assert not report.changed          # a soup is what every STL is: merging it is not a repair
    _check_closed(v, f, cone.volume)


def test_duplicate_vertices_in_an_indexed_mesh_are_merged_and_said(cone):
    v = np.vstack([cone.vertices, cone.vertices[:10]])
    f = cone.faces.copy()
    f[f < 10] += len(cone.vertices)            # half the faces use the copies
    f[::2] = np.where(f[::2] >= len(cone.vertices), f[::2] - len(cone.vertices), f[::2])
    v2, f2, report = repair_mesh(v, f)
    assert "merged 10 duplicate vertices" in report.messages[0]
    _check_closed(v2, f2, cone.volume)


def test_flipped_duplicated_and_degenerate_faces(cone):
    rng = np.random.default_rng(3)
    f = cone.faces.copy()
    pick = rng.random(len(f)) < 0.25
    f[pick] = f[pick][:, ::-1]
    f = np.vstack([f, cone.faces[:20], [[0, 0, 1], [1, 1, 1]]])
    v, f2, report = repair_mesh(cone.vertices, f)
    text = " ".join(report.messages)
    assert "flipped" in text or "outwards" in text
    assert "20 duplicated faces" in text and "2 degenerate faces" in text
    _check_closed(v, f2, cone.volume)


def test_inward_mesh_is_turned_outwards(cone):
    v, f, report = repair_mesh(cone.vertices, cone.faces[:, ::-1])
    assert "outwards" in report.messages[-1]
    _check_closed(v, f, cone.volume)


def test_small_holes_are_filled(cone):
    f = np.delete(cone.faces, [5, 300, 301], axis=0)
    v, f2, report = repair_mesh(cone.vertices, f)
    assert "filled" in report.messages[-1]
    m = trimesh.Trimesh(v, f2, process=False)
    assert m.is_watertight
    assert m.volume == pytest.approx(cone.volume, rel=0.01)   # a few facets' worth of volume


def test_open_surface_is_refused(cone):
    sides = cone.faces[np.abs(cone.face_normals[:, 2]) < 0.9]    # caps removed: a tube
    with pytest.raises(MandrelError, match="open surface.*mm across"):
        repair_mesh(cone.vertices, sides, source="tube.stl")


def test_two_bodies_refused_unless_largest_is_asked_for(cone):
    v = np.vstack([cone.vertices, cone.vertices * 0.5 + [1, 0, 0]])
    f = np.vstack([cone.faces, cone.faces + len(cone.vertices)])
    with pytest.raises(MandrelError, match=r'2 disjoint bodies.*\[mandrel\] body = "largest"'):
        repair_mesh(v, f, source="two.stl")
    v2, f2, report = repair_mesh(v, f, body="largest")
    assert "largest of 2 bodies" in report.messages[-1]
    _check_closed(v2, f2, cone.volume)


def test_config_body_chooses_a_body_through_load_geometry(tmp_path, cone):
    import dataclasses

    from support.simcase import make_config, write_stl

    from preform.simulation import load_geometry

    v = np.vstack([cone.vertices, cone.vertices * 0.5 + [1, 0, 0]])
    f = np.vstack([cone.faces + len(cone.vertices), cone.faces])     # the small body first
    stl = write_stl(tmp_path / "two.stl", v, f)
    cfg = make_config(stl)
    with pytest.raises(MandrelError, match=r'2 disjoint bodies.*\[mandrel\] body = "largest" '
                                           r'\(or body = <index>'):
        load_geometry(cfg)
    for body, volume in (("largest", cone.volume), (0, cone.volume), (1, cone.volume / 8)):
        mc = dataclasses.replace(cfg.mandrel, body=body)
        mandrel, centerline = load_geometry(dataclasses.replace(cfg, mandrel=mc))
        assert mandrel.mesh.volume == pytest.approx(volume, rel=1e-6)   # the chosen body, exactly
        assert mandrel.mesh.bounds[0, 0] > 0.5 if body == 1 else mandrel.mesh.bounds[1, 0] < 0.5
    mc = dataclasses.replace(cfg.mandrel, body=2)
    with pytest.raises(MandrelError, match=r"\[mandrel\] body = 2 does not choose.*from 0 to 1"):
        load_geometry(dataclasses.replace(cfg, mandrel=mc))


def test_non_manifold_is_refused(cone):
    v = np.vstack([cone.vertices, [[5.0, 5.0, 5.0]]])
    f = np.vstack([cone.faces, [[cone.faces[0, 0], cone.faces[0, 1], len(cone.vertices)]]])
    with pytest.raises(MandrelError, match="non-manifold"):
        repair_mesh(v, f)


def test_repairs_are_reported_by_mandrel_info(tmp_path, cone, capsys):
    f = cone.faces.copy()
    f[::7] = f[::7, ::-1]
    trimesh.Trimesh(cone.vertices, f, process=False).export(tmp_path / "damaged.stl")
    m = load_mandrel(tmp_path / "damaged.stl")
    assert m.repairs
    assert main(["mandrel", "info", str(tmp_path / "damaged.stl"), "--csv", str(tmp_path / "c.csv")]) == 0
    assert "repaired" in capsys.readouterr().out


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([1e-3, 1.0, 1e3]),
       flip=st.floats(0, 1), dup=st.floats(0, 0.2), jitter=st.booleans())
def test_random_damage_is_repaired_exactly_or_refused(cone, seed, scale, flip, dup, jitter):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    R = trimesh.transformations.quaternion_matrix(q)[:3, :3]
    v = (cone.vertices @ R.T) * scale + rng.normal(size=3)
    if jitter:
        v = v + rng.normal(scale=1e-12 * scale, size=v.shape)
    f = cone.faces.copy()
    pick = rng.random(len(f)) < flip
    f[pick] = f[pick][:, ::-1]
    f = np.vstack([f, f[rng.random(len(f)) < dup]])
    try:
        v2, f2, _ = repair_mesh(v, f)
    except MandrelError as exc:
        assert str(exc)
        return
    m = trimesh.Trimesh(v2, f2, process=False)
    assert m.is_watertight and m.volume > 0
    assert m.volume == pytest.approx(cone.volume * scale**3, rel=1e-6)


def test_self_intersecting_mesh_is_refused(cone):
    # two overlapping copies of the cone joined into one connected surface would be non-manifold;
    # instead push a band of vertices through the opposite wall
    v = cone.vertices.copy()
    z = v[:, 2]
    band = (z > 0.45) & (z < 0.55) & (v[:, 0] > 0.02)
    v[band, 0] -= 0.2            # the band's side pokes out through the other side
    with pytest.raises(MandrelError, match="intersects itself"):
        repair_mesh(v, cone.faces, source="folded.stl")


def test_shipped_mandrels_do_not_self_intersect():
    from pathlib import Path

    from preform.geometry.repair import self_intersections

    for stl in sorted((Path(__file__).resolve().parents[2] / "mandrels").glob("*.stl")):
        m = trimesh.load(stl)
        assert len(self_intersections(np.asarray(m.vertices), np.asarray(m.faces))) == 0, stl.name


# ---------------------------------------------------------------- messages through `preform mandrel info`

def test_truncated_binary_stl_is_said_with_both_sizes(tmp_path, cone, capsys):
    stl = tmp_path / "cut.stl"
    cone.export(stl)
    data = stl.read_bytes()
    n = len(cone.faces)
    assert len(data) == 84 + 50 * n                            # binary STL as trimesh writes it
    stl.write_bytes(data[:84 + 50 * (n // 2) + 17])             # cut inside a triangle record
    assert main(["mandrel", "info", str(stl)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err
    assert "truncated or corrupt binary STL" in err
    assert f"{n:,} triangles" in err and f"{84 + 50 * n:,} bytes" in err
    assert f"has {84 + 50 * (n // 2) + 17:,} bytes" in err and f"({n // 2:,} whole triangles)" in err
    stl.write_bytes(data[:40])                                  # shorter than the header
    assert main(["mandrel", "info", str(stl)]) == 2
    assert "40 bytes, shorter than the 84-byte header" in capsys.readouterr().err


def test_hole_fill_is_reported_with_its_triangles_and_share(tmp_path, cone, capsys):
    f = np.delete(cone.faces, [10], axis=0)
    stl = tmp_path / "holed.stl"
    trimesh.Trimesh(cone.vertices, f, process=False).export(stl)
    share = 100 * cone.area_faces[10] / (cone.area - cone.area_faces[10])
    assert main(["mandrel", "info", str(stl)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"repaired +filled 1 small hole: the hole with a patch of 1 triangle [\d.]+ mm "
                     rf"across, covering {share:.2g} % of the surface", out), out


def test_hole_fill_above_the_share_is_refused(tmp_path, capsys):
    from preform.geometry.repair import INTAKE

    box = trimesh.creation.box(extents=(0.1, 0.2, 0.4))        # largest triangle: 14 % of the surface
    big = int(np.argmax(box.area_faces))
    stl = tmp_path / "open_box.stl"
    trimesh.Trimesh(box.vertices, np.delete(box.faces, big, axis=0), process=False).export(stl)
    share = 100 * box.area_faces[big] / (box.area - box.area_faces[big])
    assert share > 100 * INTAKE.max_fill_share
    assert main(["mandrel", "info", str(stl)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "open surface" in err
    assert f"a patch of 1 triangle covering {share:.1f} % of the surface" in err
    assert f"filled up to {INTAKE.max_fill_share:.0%} of the surface" in err


def test_non_utf8_centerline_csv_is_an_error_line(tmp_path, cone, capsys):
    stl = tmp_path / "cone.stl"
    cone.export(stl)
    csv = tmp_path / "cl.csv"
    csv.write_bytes("x,y,z\n0,0,0\n0,0,0.5\n# m\xb2\n".encode("latin-1"))   # latin-1 superscript two
    assert main(["mandrel", "info", str(stl), "--centerline", str(csv)]) == 2
    err = capsys.readouterr().err
    offset = len(b"x,y,z\n0,0,0\n0,0,0.5\n# m")
    assert err.startswith(f"error: {csv}: not a UTF-8 text CSV: byte 0xb2 at offset {offset} (line 4)")
    assert "Traceback" not in err
    csv.write_bytes(b"\xef\xbb\xbfx,y,z\n0,0,0\n0,0,0.5\n")     # a byte-order mark is accepted
    assert main(["mandrel", "info", str(stl), "--centerline", str(csv)]) == 0


@pytest.mark.parametrize("scale, unit, hint", [(1e3, "m", "--unit mm"), (1.0, "mm", "--unit m")])
def test_mandrel_info_warns_on_an_implausible_unit(tmp_path, cone, capsys, scale, unit, hint):
    stl = tmp_path / "cone.stl"
    trimesh.Trimesh(cone.vertices * scale, cone.faces, process=False).export(stl)
    assert main(["mandrel", "info", str(stl), "--unit", unit]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith(f"warning: read with unit '{unit}', the mandrel is ")
    assert hint in captured.err
    assert main(["mandrel", "info", str(stl), "--unit", {"m": "mm", "mm": "m"}[unit]]) == 0
    assert "warning" not in capsys.readouterr().err             # the right unit: no warning


def test_mandrel_info_writes_nothing_beside_a_read_only_stl(tmp_path, cone, capsys):
    folder = tmp_path / "ro"
    folder.mkdir()
    stl = folder / "cone.stl"
    cone.export(stl)
    folder.chmod(0o555)
    try:
        assert main(["mandrel", "info", str(stl)]) == 0
        assert sorted(p.name for p in folder.iterdir()) == ["cone.stl"]
        # a CSV that cannot be written (here: a folder of that name; or a read-only folder for
        # users who are not root) is an error line
        code = main(["mandrel", "info", str(stl), "--csv", str(tmp_path)])
        err = capsys.readouterr().err
        assert code == 2 and err.startswith(f"error: --csv {tmp_path}: cannot write the centerline there")
        if os.geteuid() != 0:                                   # root writes into read-only folders
            assert main(["mandrel", "info", str(stl), "--csv", str(folder / "cl.csv")]) == 2
            assert "cannot write the centerline there" in capsys.readouterr().err
    finally:
        folder.chmod(0o755)
