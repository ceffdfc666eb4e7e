"""The numbers summary.json gives every run beside its history: the quasi-static references
where the braid ends and the statistics of its surface fields (docs/guide/results.md).

* ``ko_braid_angle_deg``, ``h_inf_m``: Ko's braid angle and the kinematic steady convergence
  length (``preform.reference``) on the section where the braid ends (``braid_length``, or the
  end of the centerline), its perimeter read as the perimeter-equivalent radius: the values the
  final braid angle and convergence length approach there;
* ``fields``: ``{name: {"mean", "min", "max"}}`` of the braid angle (deg), cover factor and
  thickness (m) over the field faces a yarn reached, the mean weighted by face area (a fine
  face counts as much as its share of the surface), null where no face was reached.
"""

from __future__ import annotations

import math

import numpy as np

#: the surface fields summarised, as the field mesh's cell arrays name them
FIELD_NAMES = ("braid_angle_deg", "cover_factor", "thickness_m")


def references_at_end(config, mandrel, centerline) -> dict:
    """``{"ko_braid_angle_deg", "h_inf_m"}`` on the section where the braid ends; None where
    that section has no loop around the centerline or lies outside the supply radius."""
    from ..geometry.centerline import section_perimeters
    from ..reference import references

    none = {"ko_braid_angle_deg": None, "h_inf_m": None}
    if config is None or mandrel is None or centerline is None:
        return none
    end = min(float(config.process.braid_length), float(centerline.length))
    perimeter = section_perimeters(mandrel, centerline, [end])
    if not perimeter[0] > 0:
        return none
    refs = references(config, np.array([end]), perimeter)
    ko, h = float(refs.ko_deg[0]), float(refs.h_inf[0])
    return {"ko_braid_angle_deg": ko if math.isfinite(ko) else None,
            "h_inf_m": h if math.isfinite(h) else None}


def field_statistics(fields) -> dict | None:
    """``{name: {"mean", "min", "max"}}`` of :data:`FIELD_NAMES` over the reached faces (see the
    module docstring); None without fields."""
    if fields is None:
        return None
    cd = fields.cell_data
    V, F = np.asarray(fields.vertices, dtype=float), np.asarray(fields.faces)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    on = (np.asarray(cd["reached_warp"]) > 0) | (np.asarray(cd["reached_weft"]) > 0)
    on &= area > 0
    out = {}
    for name in FIELD_NAMES:
        if name not in cd:
            continue
        values = np.asarray(cd[name], dtype=float)
        keep = on & np.isfinite(values)
        if not keep.any():
            out[name] = {"mean": None, "min": None, "max": None}
            continue
        v = values[keep]
        out[name] = {"mean": float(np.average(v, weights=area[keep])), "min": float(v.min()),
                     "max": float(v.max())}
    return out


def key_numbers(result, fields) -> dict:
    """summary.json's references and field statistics of a run (the module docstring)."""
    numbers = references_at_end(result.config, result.mandrel, result.centerline)
    numbers["fields"] = field_statistics(fields)
    return numbers
