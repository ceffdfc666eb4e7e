"""preform compare: measurements sampled from a run give zero difference; bad files are refused
with what is wrong; points the run cannot be sampled at are reported, not dropped."""

from __future__ import annotations

import json

import numpy as np
import pytest

from preform.cli import main
from preform.studies.compare import read_measurements
from support.simcase import write_cylinder_case


@pytest.fixture(scope="module", params=[64, 41], ids=["64-around", "41-around"])
def run(request, tmp_path_factory):
    """A small interaction run on a cylinder of two triangulations (64 and 41 facets round),
    with three snapshots and no pictures."""
    d = tmp_path_factory.mktemp("cmp")
    case = write_cylinder_case(d, kind="interaction", carriers=8, braid=0.06, snapshots=3,
                               out=d / "res", n_around=request.param, output_extra="pictures = false")
    assert main(["run", str(case), "--no-progress"]) == 0
    return d / "res"


def test_a_run_without_pictures_writes_its_data_files_alone(run):
    """``[output] pictures = false``: no PNG, the data files all there, none listed missing."""
    assert not list(run.rglob("*.png"))
    summary = json.loads((run / "summary.json").read_text())
    assert summary["inputs"]["output"]["pictures"] is False
    for name in ("surface.vtu", "history.csv", "convergence.pvd", "yarns.vtp"):
        assert name in summary["files"] and (run / name).is_file()
    assert summary["pictures"]["failed"] == []


def test_every_braided_face_is_found_at_its_own_centroid(run):
    """locate_faces: the centroid of each face's unrolled triangle lies in that face, also on
    the seam at +-180 deg where the azimuth wraps."""
    from preform.studies.compare import load_run, locate_faces

    r = load_run(run, {"angle"})
    polys = r.unrolled()
    a, b, c = polys[:, 0], polys[:, 1], polys[:, 2]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
    faces = np.flatnonzero(area > 1e-9)           # the end caps are edges in this plane
    centre = polys[faces].mean(axis=1)
    phi = (centre[:, 1] + 180.0) % 360.0 - 180.0  # as a user gives them, -180..180
    assert np.array_equal(locate_faces(polys, centre[:, 0], phi), faces)
    seam = faces[np.abs(np.abs(centre[:, 1]) - 180.0) < 10.0]
    assert len(seam) > 0


def _write(path, header, rows):
    np.savetxt(path, np.asarray(rows, dtype=float), delimiter=",", header=header, comments="")
    return path


def _sampled(run, d):
    """Measurements taken from the run's own files, independently of preform.studies.compare: angles at
    the braided faces' centroids (arc length and azimuth from the centerline's frame), H at
    the history rows of a braided length met once, every point of the first and last
    snapshots with their times."""
    import meshio
    import pyvista as pv

    from preform.geometry import read_centerline_csv

    mesh = meshio.read(run / "surface.vtu")
    V, F = mesh.points, mesh.cells_dict["triangle"]
    angle = mesh.cell_data["braid_angle_deg"][0]
    warp = mesh.cell_data["braid_angle_warp_deg"][0]
    reached_warp = mesh.cell_data["reached_warp"][0] > 0
    cl = read_centerline_csv(run.parent / "c.csv")
    c = V[F].mean(axis=1)
    s, _ = cl.project(c)
    p, _, N, B = cl.frames_at(s)
    phi = np.degrees(np.arctan2(np.einsum("ij,ij->i", c - p, B), np.einsum("ij,ij->i", c - p, N)))
    faces = np.flatnonzero(angle > 0)[::7]
    angles = _write(d / "angles.csv", "arc_length_m,azimuth_deg,braid_angle_deg",
                    np.column_stack([s[faces], phi[faces], angle[faces]]))
    wf = np.flatnonzero(reached_warp & (warp > 0))[::11]
    with open(d / "warp.csv", "w") as f:
        f.write("arc_length_m,azimuth_deg,braid_angle_deg,group\n")
        for k in wf:
            f.write(f"{float(s[k])!r},{float(phi[k])!r},{float(warp[k])!r},warp\n")
    h = np.genfromtxt(run / "history.csv", delimiter=",", names=True)
    L, H = h["braided_length_m"], h["convergence_length_mean_m"]
    once = np.array([np.sum(L == x) == 1 for x in L])
    conv = _write(d / "H.csv", "braided_length_m,convergence_length_m", np.column_stack([L[once], H[once]]))
    reader = pv.get_reader(run / "convergence.pvd")
    rows = []
    for t in (reader.time_values[0], reader.time_values[-1]):
        reader.set_active_time_value(t)
        pts = np.asarray(reader.read()[0].points)
        rows += [[*x, t] for x in pts]
    yarns = _write(d / "yarns.csv", "x_m,y_m,z_m,time_s", rows)
    return angles, d / "warp.csv", conv, yarns


def test_measurements_sampled_from_the_run_give_zero_difference(run, tmp_path, capsys):
    files = _sampled(run, tmp_path)
    out = tmp_path / "cmp"
    assert main(["compare", str(run), *map(str, files), "--out", str(out)]) == 0
    stats = json.loads((out / "compare.json").read_text())
    # the face values and the history rows are sampled where they are: exactly; the snapshot
    # points are read back from the same binary file, their distance to a segment of their
    # own yarn is round-off of the projection (a 0.1 m zone: 1e-15 m)
    assert stats["angle"]["count"] == sum(len(read_measurements(f)) for f in files[:2])
    assert stats["angle"]["max"] == 0.0 and stats["angle"]["off"] == 0
    assert stats["convergence"]["max"] == 0.0 and stats["convergence"]["count"] > 5
    assert stats["yarn"]["max"] < 1e-12 and stats["yarn"]["off"] == 0
    assert (out / "compare.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "braid angle:" in printed and "convergence length:" in printed


def test_a_point_off_the_braid_is_reported_and_kept(run, tmp_path, capsys):
    angles = _write(tmp_path / "a.csv", "arc_length_m,azimuth_deg,braid_angle_deg",
                    [[0.02, 10.0, 40.0], [0.29, 10.0, 40.0], [0.5, 0.0, 40.0]])
    conv = _write(tmp_path / "h.csv", "braided_length_m,convergence_length_m", [[0.03, 0.07], [0.5, 0.07]])
    assert main(["compare", str(run), str(angles), str(conv), "--out", str(tmp_path)]) == 0
    text = (tmp_path / "compare.csv").read_text().splitlines()
    assert len(text) == 1 + 5                       # every point has its row
    status = [line.rsplit(",", 1)[1] for line in text[1:]]
    assert status[0] == "ok"
    assert status[1].startswith("off the braid")   # beyond the braided 0.1 m: no yarn there
    assert status[2].startswith("off the part")    # beyond the 0.3 m cylinder
    assert status[4].startswith("off the run")
    stats = json.loads((tmp_path / "compare.json").read_text())
    assert stats["angle"]["off"] == 2 and stats["angle"]["count"] == 1
    assert "off the run" in capsys.readouterr().err


@pytest.mark.parametrize("header, rows, says", [
    ("arc_length_m,braid_angle_deg", [[0.1, 40]], "azimuth_deg missing"),
    ("s,phi,alpha", [[0.1, 0, 40]], "names no kind of measurement"),
    ("arc_length_m,azimuth_deg,braid_angle_deg", [[50.0, 0, 40], [80.0, 0, 41]], "look like mm"),
    ("braided_length_m,convergence_length_m", [[30.0, 70.0], [40.0, 72.0]], "look like mm"),
    ("x_m,y_m,z_m", [[60.0, 0.0, 20.0]], "look like mm"),
    ("arc_length_m,azimuth_deg,braid_angle_deg", [[0.1, 0, 0.7], [0.1, 9, 0.8], [0.1, 20, 0.7]],
     "look like radians"),
    ("arc_length_m,azimuth_deg,braid_angle_deg", [[0.1, 0, 95]], "between 0 and 90"),
])
def test_bad_measurement_files_are_refused_with_the_reason(run, tmp_path, capsys, header, rows, says):
    f = _write(tmp_path / "m.csv", header, rows)
    assert main(["compare", str(run), str(f), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and says in err and "Traceback" not in err
    assert not (tmp_path / "compare.csv").exists()


def test_a_bad_value_names_its_line_and_column(tmp_path):
    f = tmp_path / "m.csv"
    f.write_text("# measured 2026-12-01\nbraided_length_m,convergence_length_m\n0.01,0.07\n0.02,abc\n")
    with pytest.raises(Exception, match=r"line 4: convergence_length_m = 'abc'"):
        read_measurements(f)


@pytest.fixture(scope="module")
def layered(tmp_path_factory):
    """Two kinematic layers on the cylinder, the second shorter."""
    d = tmp_path_factory.mktemp("layers")
    case = write_cylinder_case(d, carriers=8, braid=0.06, snapshots=2, out=d / "res",
                               output_extra="pictures = false",
                               extra="[[layer]]\n\n[[layer]]\n[layer.process]\nbraid_length = 0.04\n")
    assert main(["run", str(case), "--no-progress"]) == 0
    return d / "res"


def test_a_layer_is_compared_with_its_own_fields_and_history(layered, tmp_path):
    """Without a ``layer`` column the outermost layer's angles (what a picture of the part
    sees), with it the layer named; H of layer 2 from ``layer2/history.csv``."""
    import meshio

    from preform.studies.compare import compare_run, load_run

    r = load_run(layered, {"angle"})
    assert r.n_layers == 2
    mesh = meshio.read(layered / "surface.vtu")
    polys = r.unrolled()
    centre = polys.mean(axis=1)
    rows = {}
    for k in (1, 2):
        a = mesh.cell_data[f"layer{k}_braid_angle_deg"][0]
        faces = np.flatnonzero(a > 0)[::9]
        rows[k] = (faces, a)
    outer = _write(tmp_path / "outer.csv", "arc_length_m,azimuth_deg,braid_angle_deg",
                   [[centre[f, 0], (centre[f, 1] + 180) % 360 - 180, rows[2][1][f]] for f in rows[2][0]])
    inner = _write(tmp_path / "inner.csv", "arc_length_m,azimuth_deg,braid_angle_deg,layer",
                   [[centre[f, 0], (centre[f, 1] + 180) % 360 - 180, rows[1][1][f], 1] for f in rows[1][0]])
    h = np.genfromtxt(layered / "layer2" / "history.csv", delimiter=",", names=True)
    L, H = h["braided_length_m"], h["convergence_length_mean_m"]
    once = np.array([np.sum(L == x) == 1 for x in L])
    conv = _write(tmp_path / "H2.csv", "braided_length_m,convergence_length_m,layer",
                  np.column_stack([L[once], H[once], np.full(once.sum(), 2)]))
    out = compare_run(layered, [outer, inner, conv])
    for c in out:
        assert c.ok.all() and np.abs(c.difference).max() == 0.0
    # the outer layer's angles against the inner layer's fields differ (the second layer is
    # braided on a thicker part): the layer taken matters, so the zeros above can fail
    as_inner = _write(tmp_path / "as_inner.csv", "arc_length_m,azimuth_deg,braid_angle_deg,layer",
                      [[centre[f, 0], (centre[f, 1] + 180) % 360 - 180, rows[2][1][f], 1.0]
                       for f in rows[2][0]])
    (c,) = compare_run(layered, [as_inner])
    assert np.nanmax(np.abs(c.difference)) > 0.01
    bad = _write(tmp_path / "bad.csv", "braided_length_m,convergence_length_m,layer", [[0.01, 0.07, 3]])
    with pytest.raises(Exception, match="layer = 3: the run braided 2 layers"):
        compare_run(layered, [bad])
