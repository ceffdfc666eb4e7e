"""``yarns.vtp`` and ``convergence.pvd`` + ``convergence/*.vtp`` (docs/guide/results.md, result files).

- ``yarns.vtp``: deposited yarn centerlines, mandrel frame, one polyline cell per yarn.
- ``convergence/step_NNNN.vtp``: the convergence zone at one time, machine frame, one line cell per
  yarn segment (fell point, contacts, ring point, supply point).
- ``convergence.pvd``: ParaView collection of those files with their times (relative paths, so the
  results folder can be moved).

The ``.vtp`` files are VTK XML PolyData with the arrays in one raw appended block (every array's
bytes as they are in memory, each after a UInt64 byte count; :func:`vtp_bytes`), which every VTK
XML reader (ParaView, VTK, pyvista, meshio) reads. They are written from NumPy directly: no VTK is
imported to write results, and no compression or base64 pass is spent on float data that hardly
compresses (case A's 645 k yarn points: 31.6 MB raw against 31.8 MB zlib-compressed base64).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import SimulationError
from .atomic import atomic_write_bytes, atomic_write_text, safe_folder

CONVERGENCE_DIR = "convergence"
CONVERGENCE_PVD = "convergence.pvd"


def _check_length(what, array, n):
    if len(array) != n:
        raise SimulationError(f"{what} has {len(array)} entries; expected {n}")


def _cell_index(offsets, n_points):
    """Yarn index of each point, from offsets (n_yarns + 1,)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    if offsets[0] != 0 or offsets[-1] != n_points or np.any(np.diff(offsets) < 0):
        raise SimulationError(f"yarn offsets {offsets[:3]}...{offsets[-1:]} do not split "
                              f"{n_points} points into yarns")
    return np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))


#: VTK XML type names of the NumPy dtypes written
VTK_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.float32): "Float32", np.dtype(np.int64): "Int64",
             np.dtype(np.int32): "Int32", np.dtype(np.int8): "Int8", np.dtype(np.uint8): "UInt8"}


@dataclass
class PolyLines:
    """A VTK PolyData of points and polyline cells, as plain arrays (mandrel or machine frame, m).

    points : (m, 3) float64;  connectivity : (k,) int64 point ids of the cells, cell after cell;
    cell_ends : (n_cells,) int64, where each cell's ids end in ``connectivity`` (VTK's offsets);
    point_data / cell_data / field_data : name -> array (point: (m,) or (m, c); cell: (n_cells,))
    """

    points: np.ndarray
    connectivity: np.ndarray
    cell_ends: np.ndarray
    point_data: dict = field(default_factory=dict)
    cell_data: dict = field(default_factory=dict)
    field_data: dict = field(default_factory=dict)


def vtp_bytes(poly: PolyLines) -> bytes:
    """The VTK XML PolyData file of ``poly``: little-endian, UInt64 block headers, one raw
    appended block holding every array in the order the XML lists them."""
    blocks, offset = [], 0

    def array(name, values, tuples=False):
        nonlocal offset
        values = np.ascontiguousarray(values)
        dtype = values.dtype.newbyteorder("<")
        if dtype not in VTK_TYPES:
            raise TypeError(f"{name}: no VTK type for {values.dtype}")
        data = values.astype(dtype, copy=False).tobytes()
        comps = 1 if values.ndim == 1 else int(np.prod(values.shape[1:]))
        extra = f' NumberOfTuples="{len(values)}"' if tuples else ""
        tag = (f'<DataArray type="{VTK_TYPES[dtype]}" Name={quoteattr(name)} NumberOfComponents="{comps}"'
               f'{extra} format="appended" offset="{offset}"/>')
        blocks.append(np.uint64(len(data)).astype("<u8").tobytes() + data)
        offset += 8 + len(data)
        return tag

    points = np.asarray(poly.points, dtype=np.float64).reshape(-1, 3)
    n_cells = len(poly.cell_ends)
    xml = ['<?xml version="1.0"?>',
           '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
           "<PolyData>"]
    if poly.field_data:
        xml += ["<FieldData>", *(array(k, v, tuples=True) for k, v in poly.field_data.items()), "</FieldData>"]
    xml.append(f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" NumberOfLines="{n_cells}" '
               'NumberOfStrips="0" NumberOfPolys="0">')
    xml += ["<PointData>", *(array(k, v) for k, v in poly.point_data.items()), "</PointData>"]
    xml += ["<CellData>", *(array(k, v) for k, v in poly.cell_data.items()), "</CellData>"]
    xml += ["<Points>", array("Points", points), "</Points>"]
    if n_cells:
        xml += ["<Lines>", array("connectivity", np.asarray(poly.connectivity, dtype=np.int64)),
                array("offsets", np.asarray(poly.cell_ends, dtype=np.int64)), "</Lines>"]
    xml += ["</Piece>", "</PolyData>", '<AppendedData encoding="raw">']
    head = ("\n".join(xml) + "\n_").encode("ascii")
    return b"".join([head, *blocks, b"\n</AppendedData>\n</VTKFile>\n"])


def write_vtp(poly: PolyLines, path) -> Path:
    """Write ``poly`` as a ``.vtp`` file (:func:`vtp_bytes`) atomically; return its path."""
    return atomic_write_bytes(path, vtp_bytes(poly), sync=False)


def yarns_polydata(yarns, types=None) -> PolyLines:
    """One polyline cell per yarn that has points; point data ``braid_angle_deg``, ``time_s``,
    ``flags``; cell data ``yarn_id``, ``group`` (0 warp, 1 weft). Mandrel frame, m.

    types : mixed yarns, (kinds (n_yarns,) int, names): cell data ``yarn_type`` (the index of
    each yarn's type) and, per type, field data ``yarn_type_<name>`` holding its index, so that a
    threshold on ``yarn_type`` in ParaView can be read off the names; None: neither."""
    points = np.asarray(yarns.points, dtype=np.float64).reshape(-1, 3)
    m = len(points)
    offsets = np.asarray(yarns.offsets, dtype=np.int64)
    _cell_index(offsets, m)
    for name in ("braid_angle_deg", "time_s", "flags"):
        _check_length(f"yarns.{name}", getattr(yarns, name), m)
    _check_length("yarns.group", yarns.group, len(offsets) - 1)
    ids = np.flatnonzero(np.diff(offsets) > 0)
    # every point belongs to exactly one yarn, in yarn order: the cells' ids are 0..m-1
    poly = PolyLines(points, np.arange(m, dtype=np.int64), offsets[ids + 1],
                     point_data={"braid_angle_deg": np.asarray(yarns.braid_angle_deg, dtype=np.float64),
                                 "time_s": np.asarray(yarns.time_s, dtype=np.float64),
                                 "flags": np.asarray(yarns.flags, dtype=np.uint8)})
    if len(ids):
        poly.cell_data = {"yarn_id": ids.astype(np.int64),
                          "group": np.asarray(yarns.group, dtype=np.int8)[ids]}
    if types is not None:
        kinds, names = types
        _check_length("yarn types", kinds, len(offsets) - 1)
        if len(ids):
            poly.cell_data["yarn_type"] = np.asarray(kinds, dtype=np.int8)[ids]
        poly.field_data = {f"yarn_type_{name}": np.array([i], dtype=np.int8)
                           for i, name in enumerate(names)}
    return poly


def yarn_types_of(config):
    """(kinds, names) of a mixed config's yarns for :func:`yarns_polydata`; None if uniform."""
    if not getattr(config, "is_mixed", False):
        return None
    return config.carrier_types(), config.type_names


def write_yarns_vtp(yarns, path, types=None) -> Path:
    """Write ``yarns.vtp`` (binary XML PolyData) atomically; types: see :func:`yarns_polydata`."""
    return write_vtp(yarns_polydata(yarns, types), path)


def snapshot_polydata(snapshot) -> PolyLines:
    """One line cell per segment between consecutive points of a yarn, yarn-major order.

    cell data ``tension_N`` (N), ``yarn_id``, ``group``; point data ``contact_id`` (-1: no yarn-yarn
    contact), ``slip`` (0 stick, 1 slip), ``external_force_N`` (3, N: every force at the point other
    than the yarns' tensions, ``result.Snapshot``); field data ``TimeValue`` (s). Machine frame, m.
    """
    points = np.asarray(snapshot.points, dtype=np.float64).reshape(-1, 3)
    m = len(points)
    yarn_of_point = _cell_index(snapshot.offsets, m)
    offsets = np.asarray(snapshot.offsets, dtype=np.int64)
    # a segment starts at every point that is not the last of its yarn
    last = np.zeros(m, dtype=bool)
    last[offsets[1:][np.diff(offsets) > 0] - 1] = True
    start = np.flatnonzero(~last)
    _check_length("snapshot.tension_N (one per segment)", snapshot.tension_N, len(start))
    _check_length("snapshot.contact_id", snapshot.contact_id, m)
    _check_length("snapshot.slip", snapshot.slip, m)
    external = snapshot.external_forces()
    _check_length("snapshot.external_force_N", external, m)
    _check_length("snapshot.group", snapshot.group, len(offsets) - 1)
    poly = PolyLines(points, np.column_stack([start, start + 1]).astype(np.int64).ravel(),
                     2 * np.arange(1, len(start) + 1, dtype=np.int64),
                     point_data={"contact_id": np.asarray(snapshot.contact_id, dtype=np.int64),
                                 "slip": np.asarray(snapshot.slip, dtype=np.int8),
                                 "external_force_N": np.asarray(external, dtype=np.float64)},
                     field_data={"TimeValue": np.array([float(snapshot.time_s)])})
    if len(start):
        yarn_id = yarn_of_point[start]
        poly.cell_data = {"tension_N": np.asarray(snapshot.tension_N, dtype=np.float64),
                          "yarn_id": yarn_id.astype(np.int64),
                          "group": np.asarray(snapshot.group, dtype=np.int8)[yarn_id]}
    return poly


def pvd_text(entries) -> str:
    """ParaView collection XML; entries: iterable of (time_s, relative file path)."""
    rows = "".join(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file={quoteattr(str(f))}/>\n'
                   for t, f in entries)
    return ('<?xml version="1.0"?>\n'
            '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
            "  <Collection>\n" + rows + "  </Collection>\n</VTKFile>\n")


def write_convergence(snapshots, out_dir) -> list[Path]:
    """Write ``convergence/step_0000.vtp``... and then ``convergence.pvd`` in ``out_dir``.

    Step files left over from an earlier run with more snapshots are removed. Returns the paths
    written, the .pvd first.
    """
    out_dir = Path(out_dir)
    folder = safe_folder(out_dir, CONVERGENCE_DIR)
    entries, written = [], []
    for i, snapshot in enumerate(snapshots):
        relative = f"{CONVERGENCE_DIR}/step_{i:04d}.vtp"
        write_vtp(snapshot_polydata(snapshot), out_dir / relative)
        entries.append((snapshot.time_s, relative))
        written.append(out_dir / relative)
    keep = {p.name for p in written}
    for stale in folder.glob("step_*.vtp"):
        if stale.name not in keep:
            stale.unlink()
    pvd = atomic_write_text(out_dir / CONVERGENCE_PVD, pvd_text(entries))
    return [pvd, *written]
