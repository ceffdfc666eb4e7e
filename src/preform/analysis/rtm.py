"""From braid to resin flow: fibre content and permeability per face (docs/guide/results.md, ``rtm/``).

Per face, from the yarn length the fields put on it (``L_g / A``, metres of yarn of group ``g``
per square metre), the yarn's linear density ``tex`` (g/km) and the fibre density ``rho_f``:

* areal weight ``A_w = sum_g tex 1e-6 L_g / A`` (kg/m^2);
* fibre volume fraction ``V_f = A_w / (rho_f t)`` with ``t`` the local preform thickness, or the
  mould's cavity thickness (the usual RTM case: the preform is compressed to it); porosity
  ``1 - V_f``;
* permeability of the aligned fibres of each yarn, along (``K_par``) and across (``K_perp``) them,
  from one of the models below; the braid's in-plane tensor is the mean of its two yarn families',
  ``K = sum_g w_g [K_par d_g d_g^T + K_perp (P - d_g d_g^T)]`` (``P`` the tangent-plane projector,
  ``w_g`` the groups' shares of the yarn length), plus ``K3 = K_perp`` through the thickness along
  the normal. For a braid the principal in-plane direction follows the yarns: along the mandrel
  axis below a 45 deg braid angle, around it above, not a fixed axis.

Models (``PermeabilityModel``):

* **Gebart (1992)**, fibres of radius ``R`` in quadratic or hexagonal packing:
  ``K_par = 8 R^2 (1 - V_f)^3 / (c V_f^2)`` with ``c = 57`` (quadratic) or ``53`` (hexagonal);
  ``K_perp = C_1 (sqrt(V_fmax / V_f) - 1)^(5/2) R^2`` with ``C_1 = 16 / (9 pi sqrt(2))``,
  ``V_fmax = pi / 4`` (quadratic) or ``C_1 = 16 / (9 pi sqrt(6))``, ``V_fmax = pi / (2 sqrt(3))``
  (hexagonal).
* **Kozeny-Carman rescaling** of a measured pair ``K_ref = (K_par, K_perp)`` at ``V_f_ref``:
  ``K(V_f) = K_ref (1 - V_f)^3 / V_f^2 * V_f_ref^2 / (1 - V_f_ref)^3``.
* **User table** of the braid's principal values ``K1, K2`` against braid angle and ``V_f``
  (bilinear interpolation, clamped at the table's edges), for measured preforms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Gebart's constants per packing: (c, C_1, V_f max)
GEBART = {
    "quadratic": (57.0, 16.0 / (9.0 * math.pi * math.sqrt(2.0)), math.pi / 4.0),
    "hexagonal": (53.0, 16.0 / (9.0 * math.pi * math.sqrt(6.0)), math.pi / (2.0 * math.sqrt(3.0))),
}


def areal_weight(length_per_area, tex):
    """kg/m^2 from metres of yarn per square metre (any shape) and the linear density (g/km)."""
    return np.asarray(length_per_area, dtype=float) * (float(tex) * 1e-6)


def fibre_volume_fraction(areal_weight_kg_m2, fibre_density, thickness):
    """``V_f = A_w / (rho_f t)``; 0 where the thickness is 0 (no yarn)."""
    aw = np.asarray(areal_weight_kg_m2, dtype=float)
    t = np.broadcast_to(np.asarray(thickness, dtype=float), aw.shape)
    return np.divide(aw, fibre_density * t, out=np.zeros_like(aw), where=t > 0)


def gebart(vf, fibre_radius, packing="hexagonal"):
    """(K_par, K_perp) in m^2 at fibre volume fractions ``vf`` (Gebart 1992; see module docstring).

    K_perp is 0 at and above the packing's V_f max (the channels between fibres close)."""
    c, c1, vf_max = GEBART[packing]
    vf = np.asarray(vf, dtype=float)
    # one radius, or per face (mixed yarns: the types' surface-equivalent mean, ``_type_tow``)
    r2 = float(fibre_radius) ** 2 if np.ndim(fibre_radius) == 0 else np.asarray(fibre_radius, float) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        k_par = np.where(vf > 0, 8.0 * r2 * (1.0 - vf) ** 3 / (c * vf * vf), np.inf)
        gap = np.sqrt(np.divide(vf_max, vf, out=np.full_like(vf, np.inf), where=vf > 0)) - 1.0
        k_perp = c1 * np.maximum(gap, 0.0) ** 2.5 * r2
    return k_par, k_perp


def kozeny_carman(vf, k_ref, vf_ref):
    """``K_ref`` (a scalar or a pair) rescaled from ``vf_ref`` to ``vf`` by Kozeny-Carman."""
    vf = np.asarray(vf, dtype=float)
    shape = (1.0 - vf) ** 3 / np.where(vf > 0, vf * vf, np.nan)
    ref = (1.0 - vf_ref) ** 3 / (vf_ref * vf_ref)
    return tuple(np.asarray(k, dtype=float) * shape / ref for k in np.atleast_1d(k_ref))


@dataclass(frozen=True)
class PermeabilityTable:
    """K1, K2 (m^2) of a braid on a grid: angles (na,) deg increasing, vf (nv,) increasing,
    k1, k2 (na, nv)."""

    angles_deg: np.ndarray
    vf: np.ndarray
    k1: np.ndarray
    k2: np.ndarray

    def __call__(self, angle_deg, vf):
        from scipy.interpolate import RegularGridInterpolator

        pts = np.column_stack([np.clip(angle_deg, self.angles_deg[0], self.angles_deg[-1]),
                               np.clip(vf, self.vf[0], self.vf[-1])])
        out = []
        for k in (self.k1, self.k2):
            out.append(RegularGridInterpolator((self.angles_deg, self.vf), k)(pts))
        return tuple(out)


def tensor_from_yarns(k_par, k_perp, k3, directions, shares, normals):
    """The 3x3 permeability tensor per face (global frame) from its yarn families.

    k_par, k_perp, k3 : (f,) m^2;  directions : (f, G, 3) unit yarn directions (zero rows for a
    group absent from the face);  shares : (f, G), the groups' shares of the yarn on the face (sum
    1 where there is yarn);  normals : (f, 3) unit. Returns (f, 3, 3).
    """
    n = np.asarray(normals, dtype=float)
    P = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    K = np.zeros((len(n), 3, 3))
    for g in range(directions.shape[1]):
        d = directions[:, g]
        dd = d[:, :, None] * d[:, None, :]
        K += shares[:, g, None, None] * (k_par[:, None, None] * dd + k_perp[:, None, None] * (P - dd))
    return K + k3[:, None, None] * n[:, :, None] * n[:, None, :]


def principal_in_plane(K, normals, reference):
    """(k1, k2, direction): the in-plane principal values (k1 >= k2) and the unit tangent of k1.

    K : (f, 3, 3);  normals : (f, 3);  reference : (f, 3), a tangent direction (e.g. the centerline
    tangent) that fixes the in-plane basis and the sign of the direction.
    """
    n = np.asarray(normals, dtype=float)
    e1 = reference - np.einsum("ij,ij->i", reference, n)[:, None] * n
    e1 /= np.maximum(np.linalg.norm(e1, axis=1), 1e-300)[:, None]
    e2 = np.cross(n, e1)
    a = np.einsum("fi,fij,fj->f", e1, K, e1)
    b = np.einsum("fi,fij,fj->f", e1, K, e2)
    c = np.einsum("fi,fij,fj->f", e2, K, e2)
    mean, half = 0.5 * (a + c), np.sqrt(0.25 * (a - c) ** 2 + b * b)
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    direction = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
    return mean + half, mean - half, direction


@dataclass(frozen=True)
class BinningSettings:
    """How the faces' K1 are grouped into the few property sets of RTMsim's patch table."""

    #: property sets at most: RTMsim reads four cell sets (patches) with their own thickness,
    #: porosity and permeability from the mesh file (its ``read_nastran_mesh``, patches 1-4)
    sets: int = 4
    #: Lloyd iterations at most; each lowers the binning error and they stop when no face
    #: changes set, which takes a few tens on a field mesh
    max_iterations: int = 200


BINNING = BinningSettings()


@dataclass(frozen=True)
class Binning:
    """Faces grouped into property sets by K1 (see :func:`bin_cells`).

    index : (f,) int, each face's set (0-based, sets ordered by K1);  values : (k,) m^2, each
    set's K1, the area-weighted geometric mean of its faces';  rms_factor : the binning error,
    ``exp(sqrt(sum_f a_f ln(K_f / K_set)^2 / sum_f a_f))``, the typical factor between a face's
    K1 and the K1 its set gives it (1 = none);  max_factor : the largest such factor of any face.
    """

    index: np.ndarray
    values: np.ndarray
    rms_factor: float
    max_factor: float


def _lloyd(logs, weights, centres, max_iterations):
    """Area-weighted 1-D k-means of ``logs`` from sorted ``centres``: (index, centres)."""
    index = None
    for _ in range(max_iterations):
        cuts = 0.5 * (centres[1:] + centres[:-1])
        new = np.searchsorted(cuts, logs, side="right")
        used = np.unique(new)
        remap = np.full(len(centres), -1)
        remap[used] = np.arange(len(used))
        new = remap[new]
        centres = (np.bincount(new, weights * logs, len(used)) / np.bincount(new, weights, len(used)))
        if index is not None and np.array_equal(new, index):
            break
        index = new
    return index, centres


def bin_cells(values, n_sets=None, weights=None, settings: BinningSettings = BINNING) -> Binning:
    """Group positive ``values`` (K1 per face) into at most ``n_sets`` sets for a solver that takes
    few property sets, so that the area-weighted mean square of ``ln(K / K_set)`` is as small as
    1-D k-means (Lloyd's iteration) makes it.

    ``weights`` are the faces' areas (default equal). It starts from equal widths in ``ln K``;
    every step lowers the error, so it ends at most at that start's, ``ln(K_max / K_min) / (2 n)``
    in root mean square (each face within half a width of its bin's middle). Each set's value is
    the area-weighted geometric mean of its faces' K1 (the mean of ``ln K``, which the mean square
    of the log error asks for). A start from area quantiles reaches the same mean square on braids
    (their K1 is a narrow band with a tail of edge faces) but leaves tail faces 18 times off, not 4.
    """
    n_sets = settings.sets if n_sets is None else int(n_sets)
    values = np.asarray(values, dtype=float)
    weights = np.ones_like(values) if weights is None else np.asarray(weights, dtype=float)
    logs = np.log(values)
    lo, hi = float(logs.min()), float(logs.max())
    if hi - lo <= 0 or n_sets <= 1:
        centre = np.array([float(np.sum(weights * logs) / np.sum(weights))])
        index = np.zeros(len(values), dtype=np.int64)
    else:
        width = (hi - lo) / n_sets
        index, centre = _lloyd(logs, weights, lo + width * (np.arange(n_sets) + 0.5), settings.max_iterations)
    dev = np.abs(logs - centre[index])
    rms = math.sqrt(float(np.sum(weights * dev ** 2) / np.sum(weights)))
    return Binning(index=index.astype(np.int64), values=np.exp(centre), rms_factor=math.exp(rms),
                   max_factor=math.exp(float(dev.max())))


#: the fibre volume fraction beyond which a cavity cannot be closed on a dry preform: fibres in a
#: square array touch at pi / 4, where Gutowski's compaction law (Gutowski, Morigaki and Cai
#: 1987, "The consolidation of laminate composites", J. Compos. Mater. 21) needs an unbounded
#: pressure (its available fibre volume fraction V_a) and Gebart's quadratic packing lets no
#: resin across the fibres (K_perp = 0)
MAX_COMPACTED_VF = math.pi / 4.0


def compression(vf, thickness, area, cavity_thickness=None) -> dict:
    """What the cavity does to the preform, for the summary: the fibre volume fraction of the
    preform faces (area-weighted mean, min, max), with a cavity the compression (the preform's
    area-weighted mean thickness as braided over the cavity's), and ``warnings`` (lines for
    people) where faces are packed beyond :data:`MAX_COMPACTED_VF`.

    vf, thickness, area : (f,) of the preform faces (rtm_valid), -, m, m^2."""
    vf, thickness, area = (np.asarray(x, dtype=float) for x in (vf, thickness, area))
    total = float(np.sum(area))
    out = {"fibre_volume_fraction": {"mean": float(np.sum(area * vf) / total), "min": float(vf.min()),
                                     "max": float(vf.max())},
           "compression": None, "warnings": []}
    mean_t = float(np.sum(area * thickness) / total)
    if cavity_thickness:
        out["compression"] = mean_t / float(cavity_thickness)
    over = vf > MAX_COMPACTED_VF
    if np.any(over):
        share = float(np.sum(area[over]) / total)
        where = (f"[rtm] cavity_thickness = {cavity_thickness:g} m compresses the preform "
                 f"{out['compression']:.1f} times (from {mean_t * 1e3:.2f} mm as braided)"
                 if cavity_thickness else f"the preform's own thickness ({mean_t * 1e3:.2f} mm)")
        out["warnings"].append(
            f"{where} to a fibre volume fraction up to {vf.max():.2f}, above {MAX_COMPACTED_VF:.3f} "
            f"(fibres touching: no pressure closes the cavity, no resin flows across them) on "
            f"{100 * share:.1f} % of the preform's area: give a thicker cavity (docs/guide/results.md, rtm/)")
    return out


# ------------------------------------------------------------------------------ solver cells

@dataclass(frozen=True)
class SolverProperties:
    """The per-cell properties of the RTM solver files (``io.rtm_files.write_rtm`` writes them).

    vertices (nv, 3) float64 m, cells (nf, 3) int64: the field mesh; per cell thickness (m),
    porosity, k1 (m^2, along ``direction``), alpha (K2 / K1) and direction (nf, 3); set_index
    (nf,) int64 and set_values (one (thickness, porosity, K1, alpha, direction) per set): the
    binning for RTMsim; summary: what summary.json says of the files.
    """

    vertices: np.ndarray
    cells: np.ndarray
    thickness: np.ndarray
    porosity: np.ndarray
    k1: np.ndarray
    alpha: np.ndarray
    direction: np.ndarray
    set_index: np.ndarray
    set_values: tuple
    summary: dict

    def said(self) -> dict:
        """What summary.json says of the files."""
        return dict(self.summary)


def solver_properties(config, fields, settings: BinningSettings | None = None,
                      n_sets=None) -> tuple[SolverProperties | None, str]:
    """(the solver files' properties, "") of fields with the RTM arrays, or (None, why not).

    Cells with no preform (``rtm_valid`` 0: no yarn, or a resin channel) are an open gap: the
    Hele-Shaw permeability ``h^2 / 12`` of the cavity ``h`` (``[rtm] cavity_thickness``; without
    it, the largest K1 of the preform), isotropic. For RTMsim's few property sets they form a set
    of their own and the preform's cells the other ``n_sets - 1`` (or all ``n_sets`` where every
    cell is preform), grouped by K1 so that the area-weighted binning error is small
    (:func:`bin_cells`). The summary gives that error (``k1_binning``), the preform's fibre
    volume fraction and, with a cavity, its compression (:func:`compression`); a cavity that
    packs fibres beyond :data:`MAX_COMPACTED_VF` is warned about. ``settings``: the binning's
    (None: :data:`BINNING`), whose ``sets`` ``n_sets`` overrides where given.
    """
    import warnings

    reason = missing_material(config)
    if reason:
        return None, reason
    if fields is None or "fibre_volume_fraction" not in fields.cell_data:
        return None, "no surface fields"
    cd = fields.cell_data
    valid = cd["rtm_valid"] > 0
    if not np.any(valid):
        return None, "no face carries preform (no yarn reached the mandrel)"
    cavity_thickness = config.rtm.cavity_thickness
    V, F = np.asarray(fields.vertices, dtype=float), np.asarray(fields.faces)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    thickness = np.full(len(valid), cavity_thickness) if cavity_thickness else cd["thickness_m"]
    channel = cavity_thickness ** 2 / 12.0 if cavity_thickness else float(np.max(cd["permeability_k1_m2"][valid]))
    k1 = np.where(valid, cd["permeability_k1_m2"], channel)
    alpha = np.where(valid, np.divide(cd["permeability_k2_m2"], k1, out=np.ones_like(k1), where=k1 > 0), 1.0)
    direction = cd["permeability_direction"]
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
    return SolverProperties(vertices=fields.vertices, cells=fields.faces, thickness=thickness,
                            porosity=cd["porosity"], k1=k1, alpha=alpha, direction=direction,
                            set_index=index, set_values=tuple(values), summary=said), ""


def _mean_direction(d):
    """A sign-free mean of unit directions (principal axis of sum d d^T)."""
    if len(d) == 0:
        return (1.0, 0.0, 0.0)
    w, v = np.linalg.eigh(d.T @ d)
    return tuple(float(x) for x in v[:, -1])


# ------------------------------------------------------------------------------ per face

#: where no yarn lies, or so little that the face is a resin channel rather than preform (fibre
#: volume fraction below MIN_VF: Gebart's and Kozeny-Carman's laws hold for packed fibres, and
#: their K grows as 1 / V_f^2 towards an empty cavity), the face is no preform: its permeability
#: arrays are 0 and ``rtm_valid`` = 0 (the solver files give such cells the cavity's own)
MIN_VF = 0.05
RTM_ARRAYS = ("areal_weight_kg_m2", "fibre_volume_fraction", "porosity", "permeability_m2",
              "permeability_k1_m2", "permeability_k2_m2", "permeability_k3_m2",
              "permeability_direction", "rtm_valid")


def missing_material(config) -> str:
    """Why the RTM fields cannot be made for ``config`` ("" if they can)."""
    if getattr(config, "is_mixed", False):
        lacking = [config.type_names[t] for t in config.used_types()
                   if not config.types[t].has_material]
        if lacking:
            return (f"no tow material data for the yarn type {lacking[0]}: give linear_density_tex, "
                    "fibre_density and fibre_radius of every type on the carriers for fibre "
                    "volume fraction and permeability")
        return ""
    if not config.yarn.has_material:
        return ("no tow material data: give [yarn] linear_density_tex, fibre_density and fibre_radius "
                "for fibre volume fraction and permeability")
    return ""


def _principal_values(config, vf, angle_deg, fibre_radius=None):
    """(K_par, K_perp) of the fibres, or (K1, K2) of the braid for a table model; fibre_radius
    (m, one or per face): None, ``[yarn] fibre_radius``."""
    model = config.rtm
    if model.permeability == "gebart":
        r = config.yarn.fibre_radius if fibre_radius is None else fibre_radius
        return gebart(vf, r, model.packing)
    if model.permeability == "kozeny_carman":
        return kozeny_carman(vf, model.k_ref, model.vf_ref)
    table = read_permeability_table(model.table)
    return table(angle_deg, vf)


def _type_tow(cd, config):
    """Mixed yarns: (areal weight kg/m^2, fibre volume per area m, fibre radius m) per face from
    every type's yarn length per area (``yarn_length_<type>_m_per_m2``) and tow data:
    ``A_w = sum_t A_w,t``, ``v = sum_t A_w,t / rho_t``, and the radius of equal specific surface
    ``r = v / sum_t (v_t / r_t)`` (the volume-weighted harmonic mean: the fibres' wetted surface
    per volume, ``2 / r``, which Gebart's and Kozeny's laws scale with, is the mix's), [yarn]'s
    where no yarn lies."""
    nf = len(cd["thickness_m"])
    aw, solid, surface = np.zeros(nf), np.zeros(nf), np.zeros(nf)
    for t in config.used_types():
        name, y = config.type_names[t], config.types[t]
        own = areal_weight(cd[f"yarn_length_{name}_m_per_m2"], y.linear_density_tex)
        aw += own
        solid += own / y.fibre_density
        surface += own / y.fibre_density / y.fibre_radius
    radius = np.divide(solid, surface, out=np.full(nf, float(config.yarn.fibre_radius)),
                       where=surface > 0)
    return aw, solid, radius


def read_permeability_table(path) -> PermeabilityTable:
    """A CSV of braid_angle_deg, fibre_volume_fraction, k1_m2, k2_m2 rows on a full grid."""
    from ..errors import ConfigError

    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as err:
        raise ConfigError(f"[rtm] table = {path}: cannot be read as braid_angle_deg, "
                          f"fibre_volume_fraction, k1_m2, k2_m2 rows ({err})") from None
    angles, vfs = np.unique(data[:, 0]), np.unique(data[:, 1])
    if len(data) != len(angles) * len(vfs) or len(angles) < 2 or len(vfs) < 2:
        raise ConfigError(f"[rtm] table = {path}: expected a full grid of at least 2 braid angles x 2 "
                          f"fibre volume fractions, found {len(data)} rows for {len(angles)} x {len(vfs)}")
    order = np.lexsort((data[:, 1], data[:, 0]))
    grid = data[order].reshape(len(angles), len(vfs), 4)
    return PermeabilityTable(angles_deg=angles, vf=vfs, k1=grid[..., 2], k2=grid[..., 3])


def rtm_fields(fields, config, tangents, thickness=None) -> dict:
    """The RTM cell arrays of :data:`RTM_ARRAYS` on the field mesh (see module docstring).

    fields : preform.analysis.fields.SurfaceFields (with ``yarn_length_{group}_m_per_m2``)
    tangents : (nf, 3), the centerline tangent at each face (fixes the in-plane reference)
    thickness : (nf,) m, the thickness the fibres fill, or None: ``[rtm] cavity_thickness``,
        else the preform's own ``thickness_m`` (a layer of a stack: its share of the cavity)
    """
    cd = fields.cell_data
    V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    normals = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
    per_area = np.column_stack([cd["yarn_length_warp_m_per_m2"], cd["yarn_length_weft_m_per_m2"]])
    mixed = _type_tow(cd, config) if getattr(config, "is_mixed", False) else None
    if mixed is None:
        aw = areal_weight(per_area.sum(axis=1), config.yarn.linear_density_tex)
    else:
        aw, solid, radius = mixed
    families = ["warp_direction", "weft_direction"]
    if "yarn_length_axial_m_per_m2" in cd:   # triaxial: the axial yarns are a third family
        axial = cd["yarn_length_axial_m_per_m2"]
        axial_aw = areal_weight(axial, config.axial()[3] or config.yarn.linear_density_tex)
        aw = aw + axial_aw
        if mixed is not None:   # the axial yarns are [yarn]'s fibre
            solid = solid + axial_aw / config.yarn.fibre_density
        per_area = np.column_stack([per_area, axial])
        families.append("axial_direction")
    total = per_area.sum(axis=1)
    if thickness is None:
        thickness = cd["thickness_m"] if config.rtm.cavity_thickness is None else \
            np.full(len(F), config.rtm.cavity_thickness)
    if mixed is None:
        vf = fibre_volume_fraction(aw, config.yarn.fibre_density, thickness)
    else:
        t = np.broadcast_to(np.asarray(thickness, dtype=float), aw.shape)
        vf = np.divide(solid, t, out=np.zeros_like(aw), where=t > 0)
    valid = (total > 0) & (vf >= MIN_VF) & (vf < 1)
    angle = cd["braid_angle_deg"]
    k1 = np.zeros(len(F))
    k2 = np.zeros(len(F))
    k3 = np.zeros(len(F))
    K = np.zeros((len(F), 3, 3))
    direction = np.zeros((len(F), 3))
    if np.any(valid):
        shares = per_area[valid] / total[valid, None]
        d = np.stack([cd[name][valid] for name in families], axis=1)
        a, b = _principal_values(config, vf[valid], angle[valid],
                                 None if mixed is None else radius[valid])
        if config.rtm.permeability == "table":
            # the braid's own principal values: K1 along the axis below 45 deg, around it above
            n = normals[valid]
            t = tangents[valid] - np.einsum("ij,ij->i", tangents[valid], n)[:, None] * n
            t /= np.maximum(np.linalg.norm(t, axis=1), 1e-300)[:, None]
            hoop = np.cross(n, t)
            first = np.where((angle[valid] < 45.0)[:, None], t, hoop)
            second = np.cross(n, first)
            Kv = (a[:, None, None] * first[:, :, None] * first[:, None, :]
                  + b[:, None, None] * second[:, :, None] * second[:, None, :]
                  + np.minimum(a, b)[:, None, None] * n[:, :, None] * n[:, None, :])
        else:
            Kv = tensor_from_yarns(a, b, b, d, shares, normals[valid])
        K[valid] = Kv
        p1, p2, dirv = principal_in_plane(Kv, normals[valid], tangents[valid])
        k1[valid], k2[valid], direction[valid] = p1, p2, dirv
        k3[valid] = np.einsum("fi,fij,fj->f", normals[valid], Kv, normals[valid])
    ok = valid & (k2 > 0)
    vf = np.minimum(vf, 1.0)
    return {"areal_weight_kg_m2": aw, "fibre_volume_fraction": vf, "porosity": 1.0 - vf, "permeability_m2": K.reshape(len(F), 9),
            "permeability_k1_m2": k1, "permeability_k2_m2": k2, "permeability_k3_m2": k3,
            "permeability_direction": direction, "rtm_valid": ok.astype(np.uint8)}


# ------------------------------------------------------------------------------ a stack of layers

#: per-layer RTM arrays kept with a ``layer{k}_`` prefix next to the stack's
LAYER_RTM_ARRAYS = ("areal_weight_kg_m2", "fibre_volume_fraction", "permeability_k1_m2",
                    "permeability_k2_m2", "rtm_valid")


def stacked_rtm_fields(layer_fields, layer_configs, tangents, cavity_thickness=None) -> dict:
    """The RTM arrays of a stack of layers on one set of faces (docs/theory.md, "Several layers").

    layer_fields : SurfaceFields of each layer, from the mandrel outwards, on copies of one field
    mesh (the same faces); layer_configs : each layer's Config (its tow data); tangents : (nf, 3).

    With ``t_k`` the layers' thicknesses and ``t = sum t_k`` (or the cavity ``c``, which
    compresses every layer alike, to ``t_k c / t``):

    * areal weight ``A_w = sum_k A_w,k``; fibre volume fraction ``V_f = sum_k (A_w,k / rho_f,k) / t``
      (or ``/ c``), so a stack of one tow is ``A_w / (rho_f t)`` as for one layer;
    * each layer's permeability at its own (compressed) ``V_f,k``, then the layered-medium rule:
      in the plane the layers conduct side by side under one pressure gradient,
      ``K_in = sum_k (t_k / t) K_in,k``; through the thickness in series,
      ``K3 = t / sum_k (t_k / K3_k)`` (over the layers that are preform there).

    Returns the stack's arrays under :data:`RTM_ARRAYS` names and each layer's
    :data:`LAYER_RTM_ARRAYS` as ``layer{k}_<name>`` (k from 1).
    """
    base = layer_fields[0]
    V, F = np.asarray(base.vertices), np.asarray(base.faces)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    normals = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
    nn = normals[:, :, None] * normals[:, None, :]
    t_layers = np.array([f.cell_data["thickness_m"] for f in layer_fields])
    t = t_layers.sum(axis=0)
    fill = t if cavity_thickness is None else np.full(len(F), float(cavity_thickness))
    squeeze = np.divide(fill, t, out=np.ones_like(t), where=t > 0)
    out, aw, solid = {}, np.zeros(len(F)), np.zeros(len(F))
    K_in, resist, share = np.zeros((len(F), 3, 3)), np.zeros(len(F)), np.zeros(len(F))
    for k, (fields, config) in enumerate(zip(layer_fields, layer_configs), start=1):
        own = rtm_fields(fields, config, tangents, thickness=t_layers[k - 1] * squeeze)
        aw += own["areal_weight_kg_m2"]
        if getattr(config, "is_mixed", False):   # the types' fibre volume, at the layer's fill
            solid += own["fibre_volume_fraction"] * t_layers[k - 1] * squeeze
        else:
            solid += own["areal_weight_kg_m2"] / config.yarn.fibre_density
        ok = own["rtm_valid"] > 0
        w = np.where(ok, t_layers[k - 1], 0.0)
        Kk = own["permeability_m2"].reshape(-1, 3, 3)
        k3k = np.einsum("fi,fij,fj->f", normals, Kk, normals)
        K_in += w[:, None, None] * (Kk - k3k[:, None, None] * nn)
        resist += np.divide(w, k3k, out=np.zeros_like(w), where=ok & (k3k > 0))
        share += w
        for name in LAYER_RTM_ARRAYS:
            out[f"layer{k}_{name}"] = own[name]
    vf = np.divide(solid, fill, out=np.zeros_like(solid), where=fill > 0)
    valid = (share > 0) & (vf >= MIN_VF) & (vf < 1) & (resist > 0)
    K = np.zeros((len(F), 3, 3))
    k3 = np.divide(share, resist, out=np.zeros_like(share), where=valid)
    K[valid] = (K_in[valid] / share[valid, None, None] + k3[valid, None, None] * nn[valid])
    k1, k2, direction = np.zeros(len(F)), np.zeros(len(F)), np.zeros((len(F), 3))
    if np.any(valid):
        k1[valid], k2[valid], direction[valid] = principal_in_plane(K[valid], normals[valid], tangents[valid])
    vf = np.minimum(vf, 1.0)
    ok = valid & (k2 > 0)
    out.update({"areal_weight_kg_m2": aw, "fibre_volume_fraction": vf, "porosity": 1.0 - vf,
                "permeability_m2": K.reshape(len(F), 9), "permeability_k1_m2": k1,
                "permeability_k2_m2": k2, "permeability_k3_m2": k3,
                "permeability_direction": direction, "rtm_valid": ok.astype(np.uint8)})
    return out
