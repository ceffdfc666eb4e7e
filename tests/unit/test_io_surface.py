"""surface.vtu / surface.xdmf + .h5 / PNG writers: round trips through VTK's own readers."""

from __future__ import annotations

import os

import numpy as np
import pytest
from vtkmodules.util.numpy_support import vtk_to_numpy

from preform.analysis.fields import map_to_surface
from preform.io.surface import H5, PICTURES, VTU, XDMF, write_surface
from preform.settings import PICTURES as PICTURE_SETTINGS
from support.field_standins import cylinder, helices, make_result


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    fields = map_to_surface(make_result(cylinder(height=0.2), helices(np.radians(30.0), 16, z1=0.14)),
                            edge_length=0.015)
    cwd = tmp_path_factory.mktemp("cwd")
    out = tmp_path_factory.mktemp("out") / "results"
    old = os.getcwd()
    os.chdir(cwd)  # the .h5 must not land in the working directory
    try:
        paths = write_surface(fields, out)
    finally:
        os.chdir(old)
    return fields, out, paths, cwd


def _cell_arrays(dataset):
    cd = dataset.GetCellData()
    return {cd.GetArrayName(i): vtk_to_numpy(cd.GetArray(i)) for i in range(cd.GetNumberOfArrays())}


def _check_round_trip(fields, dataset):
    assert dataset.GetNumberOfCells() == len(fields.faces)
    points = vtk_to_numpy(dataset.GetPoints().GetData())
    assert np.allclose(points, fields.vertices, rtol=0, atol=1e-15)
    arrays = _cell_arrays(dataset)
    for name, values in fields.cell_data.items():
        got = arrays[name].reshape(values.shape)
        assert np.allclose(got, values, rtol=0, atol=1e-15), name  # float64 and ints: exact


def test_files_are_where_they_belong(written):
    _, out, paths, cwd = written
    names = {p.relative_to(out).as_posix() for p in paths}
    assert {VTU, XDMF, H5} <= names
    assert (out / H5).exists() and not list(cwd.iterdir())
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary left
    text = (out / XDMF).read_text()
    assert f"{H5}:/" in text and str(out) not in text  # relative reference


def test_vtu_round_trip(written):
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    fields, out, _, _ = written
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(out / VTU))
    reader.Update()
    _check_round_trip(fields, reader.GetOutput())


def test_xdmf_round_trip_from_another_directory(written, tmp_path):
    from vtkmodules.vtkIOXdmf2 import vtkXdmfReader

    fields, out, _, _ = written
    moved = tmp_path / "moved"
    moved.mkdir()
    for name in (XDMF, H5):  # the pair stays valid when the folder moves
        (moved / name).write_bytes((out / name).read_bytes())
    reader = vtkXdmfReader()
    reader.SetFileName(str(moved / XDMF))
    reader.Update()
    dataset = reader.GetOutputDataObject(0)
    if dataset.IsA("vtkMultiBlockDataSet"):
        dataset = dataset.GetBlock(0)
    _check_round_trip(fields, dataset)


def test_pictures_show_the_mandrel(written):
    from PIL import Image

    _, out, paths, _ = written
    for file_name, *_ in PICTURES:
        path = out / "plots" / file_name
        assert path in paths and path.exists()
        image = np.asarray(Image.open(path).convert("RGB")).astype(int)
        assert image.shape[1] == PICTURE_SETTINGS.surface_width_px[1]
        background = image[0, 0]
        drawn = np.abs(image - background).sum(axis=2) > 30
        assert drawn.mean() > 0.05, file_name  # not a blank frame
        # colours, not only grey: the braided part is coloured by the field
        rgb_spread = image.max(axis=2) - image.min(axis=2)
        assert (rgb_spread > 60).mean() > 0.02, file_name
        # two views above the colour bar's row: each shows the mandrel
        half = (image.shape[0] - PICTURE_SETTINGS.surface_bar_height_px) // 2
        assert drawn[:half].mean() > 0.02 and drawn[half:2 * half].mean() > 0.02, file_name


def test_rendering_failure_warns_and_writes_data(monkeypatch, tmp_path):
    import preform.io.surface as S

    def broken(*args, **kwargs):
        raise RuntimeError("no OpenGL here")

    monkeypatch.setattr(S, "_render", broken)
    fields = map_to_surface(make_result(cylinder(), helices(np.radians(30.0), 4)), edge_length=0.03)
    with pytest.warns(RuntimeWarning, match="rendering failed"):
        paths = write_surface(fields, tmp_path)
    assert {p.name for p in paths} == {VTU, XDMF, H5}
    assert not list((tmp_path / "plots").glob("*.png"))


def test_every_file_keeps_the_users_umask(tmp_path):
    # pyvista's pictures once kept mkstemp's 0600 while the data files followed the umask
    fields = map_to_surface(make_result(cylinder(), helices(np.radians(30.0), 8)), edge_length=0.02)
    old = os.umask(0o022)
    try:
        paths = write_surface(fields, tmp_path / "out")
    finally:
        os.umask(old)
    assert any(p.suffix == ".png" for p in paths)
    for p in paths:
        assert (p.stat().st_mode & 0o777) == 0o644, p
