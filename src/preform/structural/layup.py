"""The braid on each face as a stack of unidirectional plies, and the plies binned into groups.

Per face of the field mesh and per braided layer (from the mandrel outwards), one ply per yarn
family: warp, weft and, in a triaxial braid, axial. A ply's

* **direction** is the family's mean fibre direction on the face (``<family>_direction``), its
  **angle** measured in the face's plane from the local 1-axis, the surface projection of the
  mandrel's axis (the centerline tangent; ``fields.local_frames`` where that is undefined),
  positive about the outward normal (local 2-axis = normal x 1-axis): warp and weft come out at
  ``+alpha`` and ``-alpha`` or the other way round, as the machine turns, axial at 0;
* **thickness** is its share of the layer's thickness ``t_k`` in proportion to its fibre volume
  per area, ``L_g tex_g / sum_h L_h tex_h`` (``L`` the yarn length per area): the layer's
  thickness is the one its fibre volume fraction is computed over (``preform.analysis.rtm``: the preform's
  own, or its share of the mould's cavity), so the plies hold the layer's fibre and fill its
  thickness;
* **fibre volume fraction** is the layer's at the face (the plies of a layer share it, since
  their thicknesses follow their fibre volumes).

Faces that are no preform (``rtm_valid`` 0: no yarn, or a fibre fraction below ``rtm.MIN_VF``,
the fringe of the braid) are left out: the part is the braided region, and a matrix-only shell
there would have a thickness nobody knows. A ply absent from a face (a layer that does not reach
it) has thickness 0.

Solvers take few distinct sections and materials, so the faces are binned (:func:`bin_plies`):
ply angles to ``angle_step_deg``, thicknesses to relative steps of ``thickness_step``, fibre
fractions to ``vf_step``, each ply's values replaced by its bin's middle; faces with the same
binned plies form a group. The largest change binning makes is reported.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..analysis.fields import face_geometry, local_frames, surface_tangent
from ..analysis.rtm import missing_material

FAMILIES = ("warp", "weft", "axial")


@dataclass(frozen=True)
class BinSettings:
    """How finely the plies are binned into element groups."""

    #: deg; a +-45 laminate's axial modulus moves by ~5 % per degree of ply angle (measured on
    #: a braided tube): 1/8 deg at most, 0.6 %
    angle_step_deg: float = 0.25
    #: relative; a ply's stiffness is proportional to its thickness: +-1 % at most
    thickness_step: float = 0.02
    #: absolute; E2 and G12 change by ~2 % per 0.01 of fibre fraction near 0.55, E1 by ~1.7 %
    vf_step: float = 0.01


@dataclass(frozen=True)
class Plies:
    """The plies of the preform faces (ne faces, P plies, mandrel frame, SI).

    faces : (ne,) int64, the field-mesh faces (surface.vtu's cells) that are preform
    names : (P,) the plies, from the mandrel outwards: (layer from 1, family)
    angle_deg : (ne, P), from the local 1-axis about the outward normal, in (-90, 90]
    thickness_m : (ne, P), 0 where the ply is absent
    vf : (ne, P), the ply's fibre volume fraction (0 where absent)
    axis, normal : (ne, 3), the local 1-axis (in the face's plane) and the face's unit normal
    """

    faces: np.ndarray
    names: tuple[tuple[int, str], ...]
    angle_deg: np.ndarray
    thickness_m: np.ndarray
    vf: np.ndarray
    axis: np.ndarray
    normal: np.ndarray

    @property
    def present(self) -> np.ndarray:
        return self.thickness_m > 0


def layer_prefixes(cell_data, n_layers: int) -> list[str]:
    """The cell-data prefix of each layer: "" for one layer, ``layer{k}_`` for a stack."""
    return [""] if n_layers == 1 else [f"layer{k}_" for k in range(1, n_layers + 1)]


def face_plies(fields, configs, tangent) -> Plies:
    """The plies of every preform face (see module docstring).

    fields : preform.analysis.fields.SurfaceFields with the RTM arrays (``preform.analysis.rtm.rtm_fields`` or, for
        a stack, ``stacked_rtm_fields``)
    configs : each layer's Config, from the mandrel outwards (one for a single layer)
    tangent : (nf, 3), the surface projection of the centerline tangent (0 where undefined)
    """
    cd = fields.cell_data
    normals, _, _ = face_geometry(fields.vertices, fields.faces)
    keep = np.nonzero(cd["rtm_valid"] > 0)[0]
    n = normals[keep]
    t = tangent[keep] - np.einsum("ij,ij->i", tangent[keep], n)[:, None] * n
    norm = np.linalg.norm(t, axis=1)
    t = np.divide(t, norm[:, None], out=np.zeros_like(t), where=norm[:, None] > 1e-6)
    e1, e2 = local_frames(n, t)
    prefixes = layer_prefixes(cd, len(configs))
    thickness = _layer_thicknesses(cd, prefixes, configs)
    names, angles, thick, vfs = [], [], [], []
    for k, (prefix, config) in enumerate(zip(prefixes, configs), start=1):
        valid = cd[f"{prefix}rtm_valid"][keep] > 0
        vf = np.where(valid, cd[f"{prefix}fibre_volume_fraction"][keep], 0.0)
        braid = _braid_tex(config)
        tex = {"warp": braid, "weft": braid,
               "axial": config.axial()[3] or config.yarn.linear_density_tex}
        present = [f for f in FAMILIES if f"{prefix}yarn_length_{f}_m_per_m2" in cd]
        volume = np.column_stack([cd[f"{prefix}yarn_length_{f}_m_per_m2"][keep] * tex[f] for f in present])
        total = volume.sum(axis=1)
        share = np.divide(volume, total[:, None], out=np.zeros_like(volume), where=total[:, None] > 0)
        for j, family in enumerate(present):
            d = cd[f"{prefix}{family}_direction"][keep]
            angle = np.degrees(np.arctan2(np.einsum("ij,ij->i", d, e2), np.einsum("ij,ij->i", d, e1)))
            angle = np.where(angle > 90.0, angle - 180.0, np.where(angle <= -90.0, angle + 180.0, angle))
            ply_t = np.where(valid, share[:, j] * thickness[k - 1][keep], 0.0)
            names.append((k, family))
            angles.append(np.where(ply_t > 0, angle, 0.0))
            thick.append(ply_t)
            vfs.append(np.where(ply_t > 0, vf, 0.0))
    return Plies(faces=keep.astype(np.int64), names=tuple(names), angle_deg=np.column_stack(angles),
                 thickness_m=np.column_stack(thick), vf=np.column_stack(vfs), axis=e1, normal=n)


def _braid_tex(config) -> float:
    """The linear density (tex) of a group's mean yarn: [yarn]'s, or with mixed yarns the mean
    over a group's carriers (warp and weft alike carry the ``carrier_yarns`` pattern)."""
    if not getattr(config, "is_mixed", False):
        return config.yarn.linear_density_tex
    kinds = config.carrier_types()[: config.machine.carriers // 2]
    return float(np.mean([config.types[t].linear_density_tex for t in kinds]))


def _layer_thicknesses(cd, prefixes, configs) -> list[np.ndarray]:
    """Each layer's thickness (nf,) m that its fibre volume fraction is computed over: with a
    cavity, every layer compressed alike to fill it (``rtm.stacked_rtm_fields``)."""
    cavity = configs[0].rtm.cavity_thickness
    own = [np.asarray(cd[f"{p}thickness_m"], dtype=float) for p in prefixes]
    if cavity is None:
        return own
    total = np.sum(own, axis=0)
    squeeze = np.divide(cavity, total, out=np.zeros_like(total), where=total > 0)
    return [t * squeeze for t in own]


@dataclass(frozen=True)
class Groups:
    """Plies binned into element groups.

    index : (ne,) int64, each face's group (0-based)
    angle_deg, thickness_m, vf : (G, P), the groups' ply values (thickness 0: the ply is absent)
    errors : the largest change binning makes to a present ply: ``angle_deg`` (deg),
        ``thickness_rel`` (relative) and ``vf`` (absolute)
    """

    index: np.ndarray
    angle_deg: np.ndarray
    thickness_m: np.ndarray
    vf: np.ndarray
    errors: dict


def bin_plies(plies: Plies, settings: BinSettings = BinSettings()) -> Groups:
    """Group the faces whose plies fall into the same bins (see module docstring)."""
    present = plies.present
    half_turn = round(180.0 / settings.angle_step_deg)
    angle = np.round(plies.angle_deg / settings.angle_step_deg)
    angle = np.where(present, np.where(angle * settings.angle_step_deg <= -90.0, angle + half_turn, angle), 0.0)
    step = np.log1p(settings.thickness_step)
    log_t = np.log(np.where(present, plies.thickness_m, 1.0))
    thick = np.where(present, np.round(log_t / step), -1e300)   # -1e300: the ply is absent
    vf = np.where(present, np.round(plies.vf / settings.vf_step), -1.0)
    keys = np.column_stack([angle, thick, vf])
    rows, index = np.unique(keys, axis=0, return_inverse=True)
    P = plies.angle_deg.shape[1]
    g_present = rows[:, P:2 * P] > -1e300
    g_angle = np.where(g_present, rows[:, :P] * settings.angle_step_deg, 0.0)
    g_thick = np.where(g_present, np.exp(np.where(g_present, rows[:, P:2 * P], 0.0) * step), 0.0)
    g_vf = np.where(g_present, rows[:, 2 * P:] * settings.vf_step, 0.0)
    index = index.ravel().astype(np.int64)
    errors = {"angle_deg": 0.0, "thickness_rel": 0.0, "vf": 0.0}
    if present.any():
        turn = (plies.angle_deg - g_angle[index] + 90.0) % 180.0 - 90.0   # a ply at -90 is one at 90
        errors = {"angle_deg": float(np.max(np.abs(turn)[present])),
                  "thickness_rel": float(np.max(np.abs(plies.thickness_m / np.where(present, g_thick[index], 1.0)
                                                       - 1.0)[present])),
                  "vf": float(np.max(np.abs(plies.vf - g_vf[index])[present]))}
    return Groups(index=index, angle_deg=g_angle, thickness_m=g_thick, vf=g_vf, errors=errors)


def largest_component(faces) -> np.ndarray:
    """(nf,) bool: the faces of the largest edge-connected piece of the triangles ``faces``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(faces, dtype=np.int64)
    if len(F) == 0:
        return np.zeros(0, dtype=bool)
    edges = np.sort(F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, edge_id = np.unique(edges, axis=0, return_inverse=True)
    owner = np.repeat(np.arange(len(F)), 3)
    graph = coo_matrix((np.ones(len(owner)), (owner, edge_id.ravel() + len(F))),
                       shape=(len(F) + edge_id.max() + 1,) * 2)
    _, label = connected_components(graph, directed=False)
    biggest = np.bincount(label[:len(F)]).argmax()
    return label[:len(F)] == biggest


# ------------------------------------------------------------------------------ a run's layup

@dataclass(frozen=True)
class StructuralLayup:
    """What ``fe/preform.inp`` and ``fe/layup.csv`` hold (``io.fe_files.write_structural``
    writes them): the fields, the plies of the preform faces of the braided part and their
    groups, the fibre and matrix, the centerline the deck's tip and end are found along, the
    deck's title and how many faces were left out."""

    fields: object
    plies: Plies
    groups: Groups
    constituents: object
    centerline: object
    title: str
    left_out_faces: int


def missing_inputs(result, fields) -> str:
    """Why the structural files cannot be written for this run ("" if they can)."""
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


def structural_layup(result, fields, layer_results=(), settings: BinSettings = BinSettings()
                     ) -> tuple[StructuralLayup | None, str]:
    """(the layup of a run's structural deck, "") or (None, why there is none).

    result : the Result of the (first) layer; layer_results : those of layers 2, 3, ...
    fields : its SurfaceFields with the RTM arrays (``preform.analysis.rtm``), stacked for
        several layers. The plies are those of the largest connected piece of preform faces.
    """
    reason = missing_inputs(result, fields)
    if reason:
        return None, reason
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
    source = getattr(result.config, "source", None)
    title = f"preform: {source.stem if source is not None else 'run'}"
    return StructuralLayup(fields=fields, plies=plies, groups=bin_plies(plies, settings),
                           constituents=result.config.material.constituents,
                           centerline=result.centerline, title=title,
                           left_out_faces=int(len(fields.faces) - len(plies.faces))), ""
