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
  (:func:`preform.rtm.bin_cells`), and the binning error is reported (docs/guide/results.md).
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


def write_rtm(fields, out_dir, n_sets=None, cavity_thickness=None,
              settings=None) -> tuple[list[Path], dict]:
    """The solver files of the RTM fields in ``<out_dir>/rtm/`` and what the summary says of them.

    Cells with no preform (``rtm_valid`` 0: no yarn, or a resin channel) are an open gap: the
    Hele-Shaw permeability ``h^2 / 12`` of the cavity ``h`` (or, without a cavity thickness, the
    largest K1 of the preform), isotropic. For RTMsim's few property sets they form a set of their
    own and the preform's cells the other ``n_sets - 1`` (or all ``n_sets`` where every cell is
    preform), grouped by K1 so that the area-weighted binning error is small
    (:func:`preform.rtm.bin_cells`). The summary gives that error (``k1_binning``), the preform's
    fibre volume fraction and, with a cavity, its compression (:func:`preform.rtm.compression`);
    a cavity that packs fibres beyond :data:`preform.rtm.MAX_COMPACTED_VF` is warned about.
    ``settings``: the binning's (``preform.rtm.BinningSettings``; None: ``rtm.BINNING``), whose
    ``sets`` ``n_sets`` overrides where given.
    """
    import warnings

    from ..rtm import BINNING, MAX_COMPACTED_VF, bin_cells, compression
    from .atomic import safe_folder

    folder = safe_folder(out_dir, RTM_DIR)
    cd = fields.cell_data
    valid = cd["rtm_valid"] > 0
    if not np.any(valid):
        return [], {"written": False, "reason": "no face carries preform (no yarn reached the mandrel)"}
    V, F = np.asarray(fields.vertices, dtype=float), np.asarray(fields.faces)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    thickness = np.full(len(valid), cavity_thickness) if cavity_thickness else cd["thickness_m"]
    channel = cavity_thickness ** 2 / 12.0 if cavity_thickness else float(np.max(cd["permeability_k1_m2"][valid]))
    k1 = np.where(valid, cd["permeability_k1_m2"], channel)
    alpha = np.where(valid, np.divide(cd["permeability_k2_m2"], k1, out=np.ones_like(k1), where=k1 > 0), 1.0)
    direction = cd["permeability_direction"]
    written = [write_lcmsim_h5(folder / "lcmsim.h5", fields.vertices, fields.faces, thickness,
                               cd["porosity"], k1, alpha, direction)]
    settings = BINNING if settings is None else settings
    n_sets = settings.sets if n_sets is None else int(n_sets)
    sets = n_sets - 1 if np.any(~valid) else n_sets
    binning = bin_cells(k1[valid], sets, weights=area[valid], settings=settings)
    index = np.full(len(k1), len(binning.values), dtype=np.int64)
    index[valid] = binning.index
    values = []
    for k in range(len(binning.values)):
        members = index == k
        values.append((float(np.mean(thickness[members])), float(np.mean(cd["porosity"][members])),
                       float(binning.values[k]), float(np.mean(alpha[members])),
                       _mean_direction(direction[members])))
    if np.any(~valid):
        values.append((float(np.mean(thickness[~valid])), float(np.mean(cd["porosity"][~valid])),
                       channel, 1.0, (1.0, 0.0, 0.0)))
    written += write_rtmsim_bdf(folder / "rtmsim.bdf", fields.vertices, fields.faces, index, values)
    # faces packed to V_f 1 or more are no preform to the fields (rtm_valid 0), but the most
    # compressed: they count here
    packed = valid | (cd["fibre_volume_fraction"] >= MAX_COMPACTED_VF)
    squeeze = compression(cd["fibre_volume_fraction"][packed], cd["thickness_m"][packed], area[packed],
                          cavity_thickness)
    for text in squeeze.pop("warnings"):
        warnings.warn(text, UserWarning, stacklevel=3)
    said = {"written": True, "sets": len(values), "preform_faces": int(np.count_nonzero(valid)),
            "faces": int(len(k1)),
            "faces_per_set": [int(n) for n in np.bincount(index, minlength=len(values))],
            "k1_binning": {"rms_factor": binning.rms_factor, "max_factor": binning.max_factor,
                           "sets_k1_m2": [float(v) for v in binning.values]},
            **squeeze}
    return written, said


def _mean_direction(d):
    """A sign-free mean of unit directions (principal axis of sum d d^T)."""
    if len(d) == 0:
        return (1.0, 0.0, 0.0)
    w, v = np.linalg.eigh(d.T @ d)
    return tuple(float(x) for x in v[:, -1])
