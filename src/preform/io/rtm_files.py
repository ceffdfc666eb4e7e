"""Solver-ready RTM files: ``rtm/lcmsim.h5`` and ``rtm/rtmsim.bdf``.

* ``lcmsim.h5`` (LCMsim v2 style): ``/mesh/vertices`` (nv, 3) float64 m, ``/mesh/cells`` (nf, 3)
  int64 (0-based), and per cell ``/properties/thickness`` (m), ``porosity`` (-),
  ``permeability`` (K1, m^2, along the reference direction), ``alpha`` (K2 / K1, the in-plane
  anisotropy) and ``reference_direction`` (nf, 3) unit tangent, global frame.
* ``rtmsim.bdf`` (RTMsim style, Nastran bulk data): ``GRID*`` nodes in large-field format (16
  characters a coordinate, so a metre-sized part keeps micrometres), ``CTRIA3`` cells whose
  property id is their set's id, and one ``SET1`` per property set, with that same id, listing
  its cells; the sets' values (thickness, porosity, K1, alpha, reference direction) are in
  ``rtmsim_sets.csv`` beside it, one row per set under the same id (column ``pid``), for
  RTMsim's patch table. The cells are binned into at most four sets by K1
  (``preform.analysis.rtm.solver_properties``), and the binning error is reported
  (docs/guide/results.md).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .atomic import atomic_path, atomic_write_text, safe_folder

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
    """The bulk data of the mesh with ``set_index`` (nf,) 0-based sets; the cards' ids are
    1-based: set ``k`` is ``SET1`` id and ``CTRIA3`` property id ``k + 1``, the ``pid`` of
    ``rtmsim_sets.csv``."""
    out = io.StringIO()
    out.write("$ preform: RTM mesh, metres; a CTRIA3's property id is the id of the SET1 that\n"
              "$ lists it and the pid of its row in rtmsim_sets.csv\nBEGIN BULK\n")
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


#: the columns of ``rtmsim_sets.csv``
SETS_COLUMNS = ("pid", "faces", "thickness_m", "porosity", "permeability_k1_m2", "alpha", "ref_x", "ref_y",
                "ref_z")


def write_rtmsim_bdf(path, vertices, cells, set_index, set_values) -> list[Path]:
    """Write ``rtmsim.bdf`` and ``rtmsim_sets.csv`` (one row per set: its pid, the bdf's property
    and SET1 id, its number of faces, thickness_m, porosity, k1_m2, alpha, reference direction x,
    y, z); return both paths. ``set_values[k]`` are set ``k``'s (0-based) values."""
    path = Path(path)
    set_index = np.asarray(set_index, dtype=np.int64)
    atomic_write_text(path, bdf_text(vertices, cells, set_index))
    counts = np.bincount(set_index, minlength=len(set_values))
    rows = [",".join(SETS_COLUMNS)]
    for k, (t, phi, k1, a, d) in enumerate(set_values):
        rows.append(",".join([str(k + 1), str(int(counts[k])), *(repr(float(v)) for v in (t, phi, k1, a, *d))]))
    sets = atomic_write_text(path.with_name("rtmsim_sets.csv"), "\n".join(rows) + "\n")
    return [path, sets]


RTM_DIR = "rtm"


def write_rtm(properties, out_dir) -> list[Path]:
    """``<out_dir>/rtm/lcmsim.h5``, ``rtmsim.bdf`` and ``rtmsim_sets.csv`` of ``properties``
    (``preform.analysis.rtm.SolverProperties``); returns the paths."""
    p = properties
    folder = safe_folder(out_dir, RTM_DIR)
    written = [write_lcmsim_h5(folder / "lcmsim.h5", p.vertices, p.cells, p.thickness, p.porosity,
                               p.k1, p.alpha, p.direction)]
    written += write_rtmsim_bdf(folder / "rtmsim.bdf", p.vertices, p.cells, p.set_index, p.set_values)
    return written
