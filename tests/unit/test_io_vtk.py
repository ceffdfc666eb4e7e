"""yarns.vtp and convergence.pvd: read back with VTK's own readers, every array compared."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import pyvista as pv
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from preform.errors import SimulationError
from preform.io.vtk_yarns import write_convergence, write_yarns_vtp

# binary XML stores float64 and integers as they are: anything above 0 would be a writer bug
ATOL = 0.0


def _read_vtp(path):
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def _point(poly, name):
    return vtk_to_numpy(poly.GetPointData().GetArray(name))


def _cell(poly, name):
    return vtk_to_numpy(poly.GetCellData().GetArray(name))


def _lines(poly):
    """Cells as lists of point ids."""
    cells = []
    for i in range(poly.GetNumberOfCells()):
        ids = poly.GetCell(i).GetPointIds()
        cells.append([ids.GetId(j) for j in range(ids.GetNumberOfIds())])
    return cells


def test_yarns_round_trip(small_result, tmp_path):
    yarns = small_result.yarns
    poly = _read_vtp(write_yarns_vtp(yarns, tmp_path / "yarns.vtp"))
    np.testing.assert_allclose(vtk_to_numpy(poly.GetPoints().GetData()), yarns.points, rtol=0, atol=ATOL)
    assert _lines(poly) == [list(range(yarns.offsets[k], yarns.offsets[k + 1]))
                            for k in range(yarns.n_yarns)]
    np.testing.assert_allclose(_point(poly, "braid_angle_deg"), yarns.braid_angle_deg, rtol=0, atol=ATOL)
    np.testing.assert_allclose(_point(poly, "time_s"), yarns.time_s, rtol=0, atol=ATOL)
    np.testing.assert_array_equal(_point(poly, "flags"), yarns.flags)
    np.testing.assert_array_equal(_cell(poly, "yarn_id"), np.arange(4))
    np.testing.assert_array_equal(_cell(poly, "group"), [0, 0, 1, 1])


def test_yarns_empty_yarn_gets_no_cell(small_result, tmp_path):
    import dataclasses

    y = small_result.yarns
    keep = np.r_[0:5, 10:20]  # drop yarn 1's points
    yarns = dataclasses.replace(
        y, points=y.points[keep], time_s=y.time_s[keep], braid_angle_deg=y.braid_angle_deg[keep],
        face=y.face[keep], flags=y.flags[keep], offsets=np.array([0, 5, 5, 10, 15]))
    poly = _read_vtp(write_yarns_vtp(yarns, tmp_path / "yarns.vtp"))
    np.testing.assert_array_equal(_cell(poly, "yarn_id"), [0, 2, 3])
    np.testing.assert_array_equal(_cell(poly, "group"), [0, 1, 1])
    assert _lines(poly)[1] == list(range(5, 10))


def test_yarns_bad_offsets_refused(small_result, tmp_path):
    import dataclasses

    broken = dataclasses.replace(small_result.yarns, offsets=np.array([0, 5, 10, 15, 19]))
    with pytest.raises(SimulationError, match="offsets"):
        write_yarns_vtp(broken, tmp_path / "yarns.vtp")
    assert not (tmp_path / "yarns.vtp").exists()


def _segments(snapshot):
    """Expected line cells: consecutive point pairs of each yarn, yarn-major, and their yarn."""
    pairs, yarn_ids = [], []
    for k in range(len(snapshot.offsets) - 1):
        for i in range(snapshot.offsets[k], snapshot.offsets[k + 1] - 1):
            pairs.append([i, i + 1])
            yarn_ids.append(k)
    return pairs, np.array(yarn_ids)


def test_convergence_files_round_trip(small_result, tmp_path):
    written = write_convergence(small_result.snapshots, tmp_path)
    assert [p.relative_to(tmp_path).as_posix() for p in written] == [
        "convergence.pvd", "convergence/step_0000.vtp", "convergence/step_0001.vtp"]
    for snapshot, path in zip(small_result.snapshots, written[1:]):
        poly = _read_vtp(path)
        pairs, yarn_ids = _segments(snapshot)
        np.testing.assert_allclose(vtk_to_numpy(poly.GetPoints().GetData()), snapshot.points,
                                   rtol=0, atol=ATOL)
        assert _lines(poly) == pairs
        np.testing.assert_allclose(_cell(poly, "tension_N"), snapshot.tension_N, rtol=0, atol=ATOL)
        np.testing.assert_array_equal(_cell(poly, "yarn_id"), yarn_ids)
        np.testing.assert_array_equal(_cell(poly, "group"), snapshot.group[yarn_ids])
        np.testing.assert_array_equal(_point(poly, "contact_id"), snapshot.contact_id)
        np.testing.assert_array_equal(_point(poly, "slip"), snapshot.slip)


def test_pvd_lists_relative_files_with_times(small_result, tmp_path):
    write_convergence(small_result.snapshots, tmp_path)
    root = ET.parse(tmp_path / "convergence.pvd").getroot()
    assert root.get("type") == "Collection"
    sets = root.find("Collection").findall("DataSet")
    assert [d.get("file") for d in sets] == ["convergence/step_0000.vtp", "convergence/step_0001.vtp"]
    np.testing.assert_allclose([float(d.get("timestep")) for d in sets], [0.25, 0.5], rtol=0, atol=0)


def test_pvd_reader_sees_every_time(small_result, tmp_path):
    """pyvista's PVDReader (the vtk wheel has no vtkPVDReader) finds the steps and their times."""
    write_convergence(small_result.snapshots, tmp_path)
    reader = pv.get_reader(tmp_path / "convergence.pvd")
    assert isinstance(reader, pv.PVDReader)
    assert reader.number_time_points == 2
    np.testing.assert_allclose(reader.time_values, [0.25, 0.5], rtol=0, atol=0)
    reader.set_active_time_value(0.5)
    block = reader.read()[0]
    np.testing.assert_allclose(block.cell_data["tension_N"], small_result.snapshots[1].tension_N,
                               rtol=0, atol=ATOL)
    np.testing.assert_array_equal(block.point_data["contact_id"], small_result.snapshots[1].contact_id)


def test_stale_steps_removed(small_result, tmp_path):
    write_convergence(small_result.snapshots, tmp_path)
    write_convergence(small_result.snapshots[:1], tmp_path)
    assert sorted(p.name for p in (tmp_path / "convergence").iterdir()) == ["step_0000.vtp"]


def test_tension_count_checked(small_result, tmp_path):
    import dataclasses

    s = small_result.snapshots[0]
    broken = dataclasses.replace(s, tension_N=s.tension_N[:-1])
    with pytest.raises(SimulationError, match="tension_N"):
        write_convergence([broken], tmp_path)
    assert not (tmp_path / "convergence.pvd").exists()


def test_vtp_without_cells_and_field_data_reads_back(tmp_path):
    """A piece with points but no cells, and field data, read back by VTK's reader."""
    from preform.io.vtk_yarns import PolyLines, write_vtp

    points = np.arange(12, dtype=float).reshape(4, 3) / 7.0
    poly = PolyLines(points, np.zeros(0, np.int64), np.zeros(0, np.int64),
                     point_data={"flags": np.array([0, 1, 2, 255], np.uint8),
                                 "force": np.arange(12, dtype=float).reshape(4, 3)},
                     field_data={"TimeValue": np.array([2.5])})
    read = _read_vtp(write_vtp(poly, tmp_path / "p.vtp"))
    assert read.GetNumberOfCells() == 0
    np.testing.assert_array_equal(vtk_to_numpy(read.GetPoints().GetData()), points)
    np.testing.assert_array_equal(_point(read, "flags"), [0, 1, 2, 255])
    np.testing.assert_array_equal(_point(read, "force"), poly.point_data["force"])
    np.testing.assert_array_equal(vtk_to_numpy(read.GetFieldData().GetArray("TimeValue")), [2.5])


def test_vtp_mode_follows_umask(small_result, tmp_path):
    import os

    old = os.umask(0o022)
    try:
        path = write_yarns_vtp(small_result.yarns, tmp_path / "yarns.vtp")
    finally:
        os.umask(old)
    assert (path.stat().st_mode & 0o777) == 0o644
