"""``yarns.vtp`` and ``convergence.pvd`` + ``convergence/*.vtp`` (DESIGN.md §1, result files).

- ``yarns.vtp``: deposited yarn centerlines, mandrel frame, one polyline cell per yarn.
- ``convergence/step_NNNN.vtp``: the convergence zone at one time, machine frame, one line cell per
  yarn segment (fell point, contacts, ring point, supply point).
- ``convergence.pvd``: ParaView collection of those files with their times (relative paths, so the
  results folder can be moved).
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pyvista as pv

from ..errors import SimulationError
from .atomic import atomic_path, atomic_write_text, safe_folder

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


def yarns_polydata(yarns) -> pv.PolyData:
    """One polyline cell per yarn that has points; point data ``braid_angle_deg``, ``time_s``,
    ``flags``; cell data ``yarn_id``, ``group`` (0 warp, 1 weft). Mandrel frame, m."""
    points = np.asarray(yarns.points, dtype=np.float64).reshape(-1, 3)
    m = len(points)
    offsets = np.asarray(yarns.offsets, dtype=np.int64)
    _cell_index(offsets, m)
    for name in ("braid_angle_deg", "time_s", "flags"):
        _check_length(f"yarns.{name}", getattr(yarns, name), m)
    _check_length("yarns.group", yarns.group, len(offsets) - 1)
    counts = np.diff(offsets)
    ids = np.flatnonzero(counts > 0)
    # VTK connectivity: [n0, i..., n1, i..., ...]; every point belongs to exactly one yarn
    lines = np.insert(np.arange(m, dtype=np.int64), offsets[ids], counts[ids])
    poly = pv.PolyData(points, lines=lines) if len(ids) else pv.PolyData(points)
    poly.point_data["braid_angle_deg"] = np.asarray(yarns.braid_angle_deg, dtype=np.float64)
    poly.point_data["time_s"] = np.asarray(yarns.time_s, dtype=np.float64)
    poly.point_data["flags"] = np.asarray(yarns.flags, dtype=np.uint8)
    if len(ids):
        poly.cell_data["yarn_id"] = ids.astype(np.int64)
        poly.cell_data["group"] = np.asarray(yarns.group, dtype=np.int8)[ids]
    return poly


def write_yarns_vtp(yarns, path) -> Path:
    """Write ``yarns.vtp`` (binary XML PolyData) atomically."""
    poly = yarns_polydata(yarns)
    with atomic_path(path) as tmp:
        poly.save(tmp, binary=True)
    return Path(path)


def snapshot_polydata(snapshot) -> pv.PolyData:
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
    lines = np.column_stack([np.full(len(start), 2), start, start + 1]).astype(np.int64).ravel()
    poly = pv.PolyData(points, lines=lines) if len(start) else pv.PolyData(points)
    poly.point_data["contact_id"] = np.asarray(snapshot.contact_id, dtype=np.int64)
    poly.point_data["slip"] = np.asarray(snapshot.slip, dtype=np.int8)
    poly.point_data["external_force_N"] = external
    if len(start):
        yarn_id = yarn_of_point[start]
        poly.cell_data["tension_N"] = np.asarray(snapshot.tension_N, dtype=np.float64)
        poly.cell_data["yarn_id"] = yarn_id.astype(np.int64)
        poly.cell_data["group"] = np.asarray(snapshot.group, dtype=np.int8)[yarn_id]
    poly.field_data["TimeValue"] = np.array([float(snapshot.time_s)])
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
        poly = snapshot_polydata(snapshot)
        with atomic_path(out_dir / relative) as tmp:
            poly.save(tmp, binary=True)
        entries.append((snapshot.time_s, relative))
        written.append(out_dir / relative)
    keep = {p.name for p in written}
    for stale in folder.glob("step_*.vtp"):
        if stale.name not in keep:
            stale.unlink()
    pvd = atomic_write_text(out_dir / CONVERGENCE_PVD, pvd_text(entries))
    return [pvd, *written]
