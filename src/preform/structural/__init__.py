"""The structural hand-off: the braided part as composite shells for CalculiX and Abaqus.

``materials`` (fibre and matrix constants, presets), ``micromechanics`` (a ply's constants at its
fibre volume fraction), ``layup`` (the plies of each face and their binning into groups), ``deck``
(``fe/preform.inp`` and ``fe/layup.csv``), ``frd`` (reading CalculiX results back). The user's
guide is ``docs/structural.md``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

FE_DIR = "fe"


def missing_inputs(result, fields) -> str:
    """Why the structural files cannot be written for this run ("" if they can)."""
    from ..analysis.rtm import missing_material

    config = result.config
    if config is None or getattr(config, "material", None) is None:
        return ("no [material] section: give preset = \"AS4/3501-6\" (or another preset) or the fibre's "
                "and matrix's elastic constants for the composite shell deck")
    reason = missing_material(config)
    if reason:
        return reason + " (the plies' fibre volume fraction)"
    if fields is None or "rtm_valid" not in fields.cell_data:
        return "no surface fields"
    if result.centerline is None:
        return "no centerline (the plies' angles are measured from the mandrel's axis)"
    if not np.any(fields.cell_data["rtm_valid"] > 0):
        return "no face carries preform (no yarn reached the mandrel)"
    return ""


def write_structural(result, fields, out_dir, layer_results=(), settings=None) -> tuple[list, dict]:
    """``<out_dir>/fe/preform.inp`` and ``layup.csv`` of a run; (paths, what the summary says).

    result : the Result of the (first) layer; layer_results : those of layers 2, 3, ...
    fields : its SurfaceFields with the RTM arrays (``preform.analysis.rtm``), stacked for several layers
    settings : layup.BinSettings (None: the defaults)
    """
    reason = missing_inputs(result, fields)
    if reason:
        _remove_earlier(out_dir)
        return [], {"written": False, "reason": reason}
    from ..analysis.fields import face_geometry, surface_tangent
    from ..io.atomic import safe_folder
    from .deck import largest_component, write_deck
    from .layup import BinSettings, bin_plies, face_plies

    cd = fields.cell_data
    configs = [result.config, *(r.config for r in layer_results)]
    stacked = sum(1 for k in range(1, len(configs) + 1) if f"layer{k}_thickness_m" in cd)
    configs = configs[:stacked] if stacked > 1 else configs[:1]
    normals, _, centroids = face_geometry(fields.vertices, fields.faces)
    tangent = surface_tangent(result, centroids, normals)
    plies = face_plies(fields, configs, tangent)
    connected = largest_component(np.asarray(fields.faces)[plies.faces])
    plies = dataclasses.replace(plies, **{name: getattr(plies, name)[connected] for name in
                                          ("faces", "angle_deg", "thickness_m", "vf", "axis", "normal")})
    groups = bin_plies(plies, settings or BinSettings())
    centerline = result.centerline

    def arc_length(points):
        return np.asarray(centerline.project(np.asarray(points, dtype=float))[0], dtype=float)

    def axis_at(s):
        return np.asarray(centerline.frames_at(np.array([float(s)]))[1], dtype=float)[0]

    folder = safe_folder(out_dir, FE_DIR)
    paths, said = write_deck(folder, fields, plies, groups, result.config.material.constituents,
                             arc_length, axis_at, title=f"preform: {_run_name(result)}")
    said["left_out_faces"] = int(len(fields.faces) - len(plies.faces))
    said["left_out"] = ("faces that are no preform (no yarn, or a fibre fraction below "
                        "preform.analysis.rtm.MIN_VF at the braid's fringe) and pieces apart from the braided part")
    return paths, said


def _remove_earlier(out_dir) -> None:
    """An earlier run's deck in this folder is not this run's: removed (a symlinked ``fe`` is
    left alone, as is anything else in it)."""
    from pathlib import Path

    folder = Path(out_dir) / FE_DIR
    if folder.is_dir() and not folder.is_symlink():
        for name in ("preform.inp", "layup.csv"):
            (folder / name).unlink(missing_ok=True)


def _run_name(result) -> str:
    source = getattr(result.config, "source", None)
    return source.stem if source is not None else "run"
