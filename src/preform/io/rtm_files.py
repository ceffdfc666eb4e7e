"""Solver-ready RTM files: ``rtm/lcmsim.h5`` and ``rtm/rtmsim.bdf``.

* ``lcmsim.h5`` (LCMsim v2 style): ``/mesh/vertices`` (nv, 3) float64 m, ``/mesh/cells`` (nf, 3)
  int64 (0-based), and per cell ``/properties/thickness`` (m), ``porosity`` (-),
  ``permeability`` (K1, m^2, along the reference direction), ``alpha`` (K2 / K1, the in-plane
  anisotropy) and ``reference_direction`` (nf, 3) unit tangent, global frame.
* ``rtmsim.bdf`` (RTMsim style, Nastran bulk data): ``GRID*`` nodes in large-field format (16
  characters a coordinate, so a metre-sized part keeps micrometres), ``CTRIA3`` cells with the
  set as their property id, and one ``SET1`` per property set listing its cells; the sets'
  values (thickness, porosity, K1, alpha, reference direction) are in ``rtmsim_sets.csv`` beside
  it, for RTMsim's patch table. The cells are binned into at most four sets
  (:func:`preform.analysis.rtm.bin_cells`), and the binning error is reported.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .atomic import atomic_path, atomic_write_text

#: Nastran small-field width and large-field width (characters)
SMALL, LARGE = 8, 16


def write_lcmsim_h5(path, vertices, cells, thickness, porosity, k1, alpha, reference_direction) -> Path:
    import h5py

    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            mesh = f.create_group("mesh")
            mesh.create_dataset("vertices", data=np.asarray(vertices, dtype=np.float64))
            mesh.create_dataset("cells", data=np.asarray(cells, dtype=np.int64))
            props = f.create_group("properties")
            for name, values in (("thickness", thickness), ("porosity", porosity), ("permeability", k1),
                                 ("alpha", alpha), ("reference_direction", reference_direction)):
                props.create_dataset(name, data=np.asarray(values, dtype=np.float64))
            f.attrs["units"] = "SI: m, m^2"
            f.attrs["written_by"] = "preform"
    return Path(path)


def _large(value) -> str:
    text = f"{value:.9E}" if isinstance(value, float) else str(value)
    if len(text) > LARGE:
        raise ValueError(f"{value!r} does not fit a {LARGE}-character Nastran field")
    return text.rjust(LARGE)


def _small(value) -> str:
    text = str(value)
    if len(text) > SMALL:
        raise ValueError(f"{value!r} does not fit an {SMALL}-character Nastran field")
    return text.rjust(SMALL)


def bdf_text(vertices, cells, set_index) -> str:
    """The bulk data of the mesh with ``set_index`` (nf,) 0-based sets; ids are 1-based."""
    out = io.StringIO()
    out.write("$ preform: RTM mesh, metres; property id = set + 1\nBEGIN BULK\n")
    for i, (x, y, z) in enumerate(np.asarray(vertices, dtype=float), start=1):
        out.write(f"{'GRID*':<8}{_large(i)}{_large('')}{_large(float(x))}{_large(float(y))}*\n")
        out.write(f"{'*':<8}{_large(float(z))}\n")
    for e, (a, b, c) in enumerate(np.asarray(cells, dtype=np.int64), start=1):
        pid = int(set_index[e - 1]) + 1
        out.write(f"{'CTRIA3':<8}{_small(e)}{_small(pid)}{_small(a + 1)}{_small(b + 1)}{_small(c + 1)}\n")
    for k in np.unique(set_index):
        ids = [str(e + 1) for e in np.nonzero(set_index == k)[0]]
        fields = [str(int(k) + 1), *ids]
        first, rest = fields[:8], fields[8:]
        line = f"{'SET1':<8}" + "".join(_small(v) for v in first)
        while rest:
            out.write(line + "+\n")
            chunk, rest = rest[:8], rest[8:]
            line = f"{'+':<8}" + "".join(_small(v) for v in chunk)
        out.write(line + "\n")
    out.write("ENDDATA\n")
    return out.getvalue()


def write_rtmsim_bdf(path, vertices, cells, set_index, set_values) -> list[Path]:
    """Write ``rtmsim.bdf`` and ``rtmsim_sets.csv`` (one row per set: set, thickness_m, porosity,
    k1_m2, alpha, reference direction x, y, z); return both paths."""
    path = Path(path)
    atomic_write_text(path, bdf_text(vertices, cells, np.asarray(set_index, dtype=np.int64)))
    rows = ["set,thickness_m,porosity,permeability_k1_m2,alpha,ref_x,ref_y,ref_z"]
    for k, (t, phi, k1, a, d) in enumerate(set_values, start=1):
        rows.append(",".join([str(k), *(repr(float(v)) for v in (t, phi, k1, a, *d))]))
    sets = atomic_write_text(path.with_name("rtmsim_sets.csv"), "\n".join(rows) + "\n")
    return [path, sets]


RTM_DIR = "rtm"


def write_rtm(fields, out_dir, n_sets=4, cavity_thickness=None) -> tuple[list[Path], dict]:
    """The solver files of the RTM fields in ``<out_dir>/rtm/`` and what the summary says of them.

    Cells with no preform (``rtm_valid`` 0: no yarn, or a resin channel) are an open gap: the
    Hele-Shaw permeability ``h^2 / 12`` of the cavity ``h`` (or, without a cavity thickness, the
    largest K1 of the preform), isotropic. For RTMsim's few property sets they form a set of their
    own and the preform's cells the other ``n_sets - 1`` (or all ``n_sets`` where every cell is
    preform).
    """
    from ..analysis.rtm import bin_cells
    from .atomic import safe_folder

    folder = safe_folder(out_dir, RTM_DIR)
    cd = fields.cell_data
    valid = cd["rtm_valid"] > 0
    if not np.any(valid):
        return [], {"written": False, "reason": "no face carries preform (no yarn reached the mandrel)"}
    thickness = np.full(len(valid), cavity_thickness) if cavity_thickness else cd["thickness_m"]
    channel = cavity_thickness ** 2 / 12.0 if cavity_thickness else float(np.max(cd["permeability_k1_m2"][valid]))
    k1 = np.where(valid, cd["permeability_k1_m2"], channel)
    alpha = np.where(valid, np.divide(cd["permeability_k2_m2"], k1, out=np.ones_like(k1), where=k1 > 0), 1.0)
    direction = cd["permeability_direction"]
    written = [write_lcmsim_h5(folder / "lcmsim.h5", fields.vertices, fields.faces, thickness,
                               cd["porosity"], k1, alpha, direction)]
    sets = n_sets - 1 if np.any(~valid) else n_sets
    index_valid, rep, error = bin_cells(k1[valid], sets)
    index = np.full(len(k1), len(rep), dtype=np.int64)
    index[valid] = index_valid
    values = []
    for k in range(len(rep)):
        members = index == k
        values.append((float(np.mean(thickness[members])), float(np.mean(cd["porosity"][members])),
                       float(rep[k]), float(np.mean(alpha[members])),
                       _mean_direction(direction[members])))
    if np.any(~valid):
        values.append((float(np.mean(thickness[~valid])), float(np.mean(cd["porosity"][~valid])),
                       channel, 1.0, (1.0, 0.0, 0.0)))
    written += write_rtmsim_bdf(folder / "rtmsim.bdf", fields.vertices, fields.faces, index, values)
    return written, {"written": True, "sets": len(values), "binning_error_k1": error,
                     "preform_faces": int(np.count_nonzero(valid)), "faces": int(len(k1))}


def _mean_direction(d):
    """A sign-free mean of unit directions (principal axis of sum d d^T)."""
    if len(d) == 0:
        return (1.0, 0.0, 0.0)
    w, v = np.linalg.eigh(d.T @ d)
    return tuple(float(x) for x in v[:, -1])
