"""Deposited yarns -> per-face fields on the mandrel surface (docs/theory.md §5).

:func:`map_to_surface` clips every deposited yarn to the faces of a *field mesh*, sums per face and
group (warp 0, weft 1) the yarn length ``L`` and the direction moment ``sum l d d^T``, pools those
sums over a small neighbourhood (see :func:`map_to_surface`), and turns them into fields: mean
fibre direction, braid angle, coverage, cover factor, thickness.

The field mesh is an isotropic remesh of the mandrel surface to the field edge length
(:func:`preform.geometry.remesh.isotropic_remesh`: near-equilateral faces of about that edge,
sharp feature edges kept, vertices on the input surface), so the fields do not depend on how the
STL happens to be triangulated: CAD slivers, coarse facets and over-fine exports all give faces of
one size. The input mesh is never modified; ``source_face`` says which input triangle each field
face lies on, and :func:`fields_on_input` carries the fields over to the input triangles
(area-weighted) for tools that need the user's own mesh.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .._kernels import fields as _k
from ..errors import PreformError
from ..geometry.remesh import (RemeshSettings, isotropic_remesh, locate_faces, refine_to_edge_length,
                               subdivide_long_edges)
from ..tolerances import tol

#: default field-mesh edge length, in yarn widths ("a few yarn widths")
DEFAULT_EDGE_WIDTHS = 3.0
#: default pooling radius, in field-mesh edge lengths (6 yarn widths with the default mesh): wide
#: enough to hold a few yarns of a group at usual cover factors, so coverage stops flickering
#: between "on a yarn" and "between yarns" from face to face
POOL_EDGES = 2.0
#: relative margin by which the yarn width must exceed the available width to flag a face jammed
JAM_RTOL = 1e-6
#: below this norm the surface projection of the centerline tangent is undefined (end caps)
TANGENT_MIN = 1e-6
#: walk guard: at most this many face hops per yarn segment
MAX_HOPS = 100_000
#: fields_on_input samples each input face with pieces of at most this many field edge lengths:
#: the midpoint rule over pieces of h / 2 puts a piece in the wrong field face only along field
#: face edges, within h / 4 of them
TRANSFER_PIECE_EDGES = 0.5
#: locate_faces casts its rays from this many field edge lengths outside the surface: beyond the
#: chord sag of the field mesh (h^2 / (8 r), 0.05 h at r = 2.5 h) and well inside a yarn width of
#: wall thickness for the usual h
LOCATE_REACH_EDGES = 0.5

GROUPS = ("warp", "weft")


@dataclass(frozen=True)
class SurfaceFields:
    """Per-face fields on the field mesh (mandrel frame, SI; docs/guide/results.md, ``surface.vtu``).

    vertices : (nv, 3) float64, m, mandrel frame
    faces : (nf, 3) int64, outward wound like the mandrel
    source_faces : (nf,) int64, the input (STL) face each field face lies in
    cell_data : dict name -> (nf,) or (nf, 3) array, see :func:`map_to_surface`
    jammed : (nf,) bool, a group's yarn width exceeds its available width here
    unmapped_length_m : float, m, deposited yarn length that could not be put on any face
    edge_length_m : float, m, the field mesh's target edge length (inf: the input mesh as is)
    pool_radius_m : float, m, radius of the neighbourhood each face borrows from
    """

    vertices: np.ndarray
    faces: np.ndarray
    source_faces: np.ndarray
    cell_data: dict = field(default_factory=dict)
    jammed: np.ndarray | None = None
    unmapped_length_m: float = 0.0
    edge_length_m: float = float("inf")
    pool_radius_m: float = 0.0

    def reached(self) -> np.ndarray:
        """(nf,) bool: faces some yarn reached, of any layer (``reached_*`` and, on a layered
        run, ``layer{k}_reached_*``: the unprefixed arrays are the first layer's)."""
        keys = [k for k in self.cell_data if k.endswith(("reached_warp", "reached_weft"))]
        out = np.zeros(len(self.faces), dtype=bool)
        for k in keys:
            out |= np.asarray(self.cell_data[k]) > 0
        return out


# ---------------------------------------------------------------------------------------- mesh

def _merge_exact_duplicates(vertices, faces):
    """Weld vertices with identical coordinates (an STL triangle soup) so faces share edges.

    A mandrel's vertices are welded already: the hash-table test (``_kernels.mesh.weld_exact``,
    0.05 s on 500 k vertices) returns them as they are; only when it finds equal rows does
    ``np.unique`` (a lexicographic sort, 1.2 s there) weld and reorder them."""
    from .._kernels.mesh import weld_exact

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    distinct = len(weld_exact(V, np.empty(len(V), dtype=np.int64)))
    if distinct == len(V):
        return vertices, faces
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    if len(unique) == len(vertices):
        return vertices, faces
    return unique, inverse.reshape(-1)[faces]


def face_geometry(vertices, faces):
    """Unit normals (nf, 3), areas (nf,) m^2 and centroids (nf, 3) m; zero normal if degenerate."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, norm[:, None], out=np.zeros_like(cross), where=norm[:, None] > 0)
    return normals, 0.5 * norm, tri.mean(axis=1)


def edge_planes(vertices, faces, normals):
    """Edge planes and neighbours for the clipping walk (see ``preform._kernels.fields``).

    returns : plane_normal (nf, 3, 3) float64, plane_offset (nf, 3) float64 m,
        neighbour (nf, 3) int64 (face across edge j = corners j, j + 1, or -1)
    """
    nf = len(faces)
    corner_a = faces.reshape(-1)
    corner_b = faces[:, [1, 2, 0]].reshape(-1)
    keys = np.sort(np.column_stack([corner_a, corner_b]), axis=1)
    _, edge_id = np.unique(keys, axis=0, return_inverse=True)
    edge_id = edge_id.reshape(-1)
    order = np.argsort(edge_id, kind="stable")
    # half-edges with the same edge id are consecutive in `order`; pair the first two of each run
    same_next = edge_id[order[:-1]] == edge_id[order[1:]]
    first_of_run = np.concatenate([[True], ~same_next])
    pair = same_next & first_of_run[:-1]
    h0, h1 = order[:-1][pair], order[1:][pair]
    neighbour = np.full(3 * nf, -1, dtype=np.int64)
    neighbour[h0], neighbour[h1] = h1 // 3, h0 // 3
    face_of = np.arange(3 * nf) // 3
    other = np.where(neighbour >= 0, neighbour, face_of)
    mean_normal = normals[face_of] + normals[other]
    length = np.linalg.norm(mean_normal, axis=1)
    mean_normal = np.where(length[:, None] > 1e-12, mean_normal, normals[face_of])
    # one plane per edge: build it from the canonical (sorted) direction so both sides agree
    pa, pb = vertices[keys[:, 0]], vertices[keys[:, 1]]
    m = np.cross(mean_normal, pb - pa)
    m_norm = np.linalg.norm(m, axis=1)
    m = np.divide(m, m_norm[:, None], out=np.zeros_like(m), where=m_norm[:, None] > 0)
    if len(h0):  # the mean normal is symmetric, so h0's plane is h1's: copy to be bit-identical
        m[h1] = m[h0]
    opposite = vertices[faces[:, [2, 0, 1]].reshape(-1)]
    inward = np.einsum("ij,ij->i", m, opposite - pa) >= 0
    m = np.where(inward[:, None], m, -m)
    offset = np.einsum("ij,ij->i", m, pa)
    return m.reshape(nf, 3, 3), offset.reshape(nf, 3), neighbour.reshape(nf, 3)


def field_mesh(result, edge_length=None, remesh: RemeshSettings = RemeshSettings()):
    """The mesh the fields live on: the mandrel remeshed isotropically to ``edge_length``.

    returns : vertices (nv, 3), faces (nf, 3), source_faces (nf,) (the input face under each
    field face's centroid), edge length used (m; inf: the input mesh itself, welded).
    Vertices with identical coordinates (an STL triangle soup) are welded first.
    """
    V = np.asarray(result.mandrel.vertices, dtype=np.float64)
    F = np.asarray(result.mandrel.faces, dtype=np.int64)
    V, F = _merge_exact_duplicates(V, F)
    h = default_edge_length(result) if edge_length is None else float(edge_length)
    if np.isinf(h):
        return V.copy(), F.copy(), np.arange(len(F), dtype=np.int64), h
    if not (np.isfinite(h) and h > 0):
        raise PreformError(f"[output] field_edge_length = {h!r}: expected a positive length in m")
    U, G = isotropic_remesh(V, F, h, remesh)
    normals, _, centroids = face_geometry(U, G)
    from ..geometry.mandrel import Mandrel

    mandrel = result.mandrel
    # a Mandrel's own trimesh (and its embree scene, 1 s to build on 1 M faces) when the arrays
    # are its own, as they are unless a soup was welded above
    same = isinstance(mandrel, Mandrel) and V is mandrel.vertices and F is mandrel.faces
    source = locate_faces(V, F, centroids, normals, LOCATE_REACH_EDGES * h,
                          mesh=mandrel.mesh if same else None)
    return U, G, source, h


def default_edge_length(result) -> float:
    """``[output] field_edge_length`` if set, else DEFAULT_EDGE_WIDTHS yarn widths, m."""
    output = getattr(result.config, "output", None)
    h = getattr(output, "field_edge_length", None) if output is not None else None
    return float(h) if h is not None else DEFAULT_EDGE_WIDTHS * float(result.config.yarn.width)


# ------------------------------------------------------------------------------------ clipping

def clip_yarns(yarns, vertices, faces, normals, centroids, with_first=False):
    """Per-face, per-group yarn length (nf, 2) m, direction moment (nf, 2, 3, 3) m, unmapped m;
    with ``with_first`` also the first moment ``sum l x_mid`` (nf, 2, 3) m^2 (before unmapped).

    Every segment of every deposited yarn (including bridges over concave stretches, which lie
    over the faces below them) is clipped exactly to the edge-plane wedges of the faces.
    """
    points = np.ascontiguousarray(yarns.points, dtype=np.float64)
    if len(points) == 0 or len(faces) == 0:
        empty = np.zeros((len(faces), 2)), np.zeros((len(faces), 2, 3, 3))
        return (*empty, np.zeros((len(faces), 2, 3)), 0.0) if with_first else (*empty, 0.0)
    plane_normal, plane_offset, neighbour = edge_planes(vertices, faces, normals)
    _, seed = cKDTree(centroids).query(points)
    length, m6, first, unmapped = _k.clip_polylines(
        points, np.asarray(yarns.offsets, dtype=np.int64), np.asarray(yarns.group, dtype=np.int64),
        np.asarray(seed, dtype=np.int64), np.ascontiguousarray(centroids), plane_normal,
        plane_offset, neighbour, len(faces), MAX_HOPS)
    xx, yy, zz, xy, xz, yz = np.moveaxis(m6, -1, 0)
    moment = np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1),
                       np.stack([xz, yz, zz], -1)], -2)
    if with_first:
        return length, moment, first, float(unmapped)
    return length, moment, float(unmapped)


# ------------------------------------------------------------------------------------- pooling

def default_pool_radius(edge_length, width) -> float:
    """POOL_EDGES field edge lengths (on the unrefined mesh: of the default edge length), m."""
    h = edge_length if np.isfinite(edge_length) else DEFAULT_EDGE_WIDTHS * width
    return POOL_EDGES * h


def pool(centroids, normals, radius, values, sources=None):
    """Biweight-kernel sums of per-face values over neighbourhoods (see map_to_surface).

    centroids, normals : (nf, 3) float64;  radius : float or (nf,) float64, m
    values : (nf, c) float64;  sources : (nf, 3) float64, where each face's values sit (default
    its centroid);  returns (nf, c) float64
    """
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(centroids),))
    cos_crease = float(np.cos(np.radians(tol.crease_angle_deg)))
    sources = centroids if sources is None else sources
    return _k.pool_sums(np.ascontiguousarray(centroids), np.ascontiguousarray(sources),
                        np.ascontiguousarray(normals),
                        np.ascontiguousarray(radius), np.ascontiguousarray(values), cos_crease)


# ------------------------------------------------------------------------------------- fields

def centroid_normals(vertices, faces, normals):
    """Smooth unit normal at each face centroid (nf, 3): the mean of the face's crease-split,
    angle-weighted corner normals (as the mandrel's, tolerances.crease_angle_deg).

    A chord face of a curved surface is tilted against the surface under its centroid by up to
    ``h / (2 r)`` (on a prism the tilt can be about any axis, as the corners sit at different
    heights), so the centerline tangent projected onto the facet is not its projection onto the
    surface; the smooth normal is the surface's to second order in ``h``. The braid angle is
    measured in the frame of this normal (docs/architecture.md §2: the angle to the projection of the
    tangent onto the surface's tangent plane).
    """
    from ..geometry.mandrel import _corner_normals

    cn = _corner_normals(vertices, faces, normals).sum(axis=1)
    norm = np.linalg.norm(cn, axis=1)
    return np.divide(cn, norm[:, None], out=normals.copy(), where=norm[:, None] > 0)


def surface_tangent(result, centroids, normals):
    """Unit surface projection of the centerline tangent at each centroid (nf, 3); 0 on end caps."""
    s, _ = result.centerline.project(centroids)
    _, T, _, _ = result.centerline.frames_at(np.asarray(s, dtype=np.float64))
    T = np.asarray(T, dtype=np.float64)
    Ts = T - np.einsum("ij,ij->i", T, normals)[:, None] * normals
    norm = np.linalg.norm(Ts, axis=1)
    return np.divide(Ts, norm[:, None], out=np.zeros_like(Ts), where=norm[:, None] > TANGENT_MIN)


def local_frames(normals, tangent):
    """Per-face tangent-plane frame: e1 (nf, 3), e2 = n x e1 (nf, 3), unit.

    e1 is the surface projection of the centerline tangent; where that is undefined (end caps) it
    is the projection of the global axis least aligned with the normal, so the frame still varies
    smoothly across a cap. Zero for degenerate (zero-area) faces.
    """
    e1 = tangent.copy()
    missing = np.linalg.norm(e1, axis=1) == 0
    if missing.any():
        n = normals[missing]
        axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
        t = axis - np.einsum("ij,ij->i", axis, n)[:, None] * n
        norm = np.linalg.norm(t, axis=1)
        e1[missing] = np.divide(t, norm[:, None], out=np.zeros_like(t), where=norm[:, None] > 0.5)
    return e1, np.cross(normals, e1)


def planar_moments(moment, e1, e2):
    """3D direction moments (nf, 2, 3, 3) in each face's frame: (nf, 2, 3) = (aa, ab, bb), m.

    e1, e2 span the plane normal to ``n = e1 x e2`` (the smooth normal, :func:`centroid_normals`).
    A yarn direction ``d = a e1 + b e2 + c n`` with ``c != 0`` (the yarn, on the mandrel, is not
    quite tangent to the smooth plane of a chord face) is unfolded into the plane keeping its
    angle to e1: ``b' = sign(b) sqrt(b^2 + c^2)``, so ``bb' = bb + cc`` exactly and
    ``ab' = ab sqrt(bb' / bb)`` (exact when the pieces of a group in a face share one ``c / b``,
    as neighbouring pieces of a yarn on a smooth surface do); projecting instead would shorten
    ``b`` and the braid angle with it (``tan alpha' = tan alpha cos(tilt)``).
    """
    n = np.cross(e1, e2)
    ma = np.einsum("fgij,fj->fgi", moment, e1)
    mb = np.einsum("fgij,fj->fgi", moment, e2)
    aa = np.einsum("fgi,fi->fg", ma, e1)
    ab = np.einsum("fgi,fi->fg", ma, e2)
    bb = np.einsum("fgi,fi->fg", mb, e2)
    cc = np.einsum("fgij,fi,fj->fg", moment, n, n)
    bb_unfolded = bb + cc
    scale = np.sqrt(np.divide(bb_unfolded, bb, out=np.ones_like(bb), where=bb > 0))
    return np.stack([aa, ab * scale, bb_unfolded], axis=-1)


def principal_direction_2d(aa, ab, bb):
    """Unit principal axis (a, b) of the 2x2 moments [[aa, ab], [ab, bb]], with a >= 0."""
    phi = 0.5 * np.arctan2(2.0 * ab, aa - bb)  # in [-90, 90] deg, so a = cos(phi) >= 0
    return np.cos(phi), np.sin(phi)


def map_to_surface(result, edge_length=None, pool_radius_m=None,
                   remesh: RemeshSettings = RemeshSettings(), mesh=None) -> SurfaceFields:
    """Map the deposited yarns of ``result`` onto the mandrel surface (docs/theory.md §5).

    result : preform.result.Result (uses yarns, mandrel, centerline, config.yarn, config.output)
    edge_length : float, m, target edge of the isotropic field mesh (edges between 4/5 and 4/3
        of it); None: ``[output] field_edge_length``, else DEFAULT_EDGE_WIDTHS yarn widths;
        ``float("inf")``: map onto the input mesh as it is
    remesh : settings of the isotropic remesher (preform.geometry.remesh.RemeshSettings)
    pool_radius_m : float, m, radius of the neighbourhood a face borrows from; None:
        POOL_EDGES field edge lengths; 0: no pooling (raw per-face values)
    mesh : (vertices (nv, 3), faces (nf, 3), source_faces (nf,), edge length m) of the field
        mesh to map onto, or None to remesh the mandrel (:func:`field_mesh`); several layers
        map onto offset copies of one field mesh, so that their fields share the faces
    returns : SurfaceFields on the field mesh

    Per face and group (warp, weft), from the clipped yarn pieces (lengths ``l_i``, unit
    directions ``d_i``), pooled over the neighbourhood (below) into a length ``L``, an area ``A``
    and a moment ``M = sum l_i d_i d_i^T``:

    - ``{group}_direction`` (nf, 3): length-weighted mean fibre direction, unit, in the face
      plane, oriented towards increasing centerline arc length: the principal axis of ``M``
      (sign-free, so yarns walked either way average correctly). ``M`` is kept in each face's
      tangent frame (e1 = surface projection of the centerline tangent, e2 = n x e1) before
      pooling, so pooling round a curved surface does not tilt the mean direction;
    - ``braid_angle_{group}_deg``: angle between that direction and the surface projection of
      the centerline tangent at the face centroid, 0..90 deg;
    - ``yarn_width_{group}_m`` = ``w_eff = max(min(w, p), w_min)``: the yarn width narrowed to
      the available width ``p = A / L``, the perpendicular spacing of neighbouring yarns of the
      group (paper §2.4.2; on a cylinder ``p = 2 pi r cos(alpha) / n``), but not below the least
      width ``w_min`` (``[yarn] min_width``); where ``p < w_min`` the yarns cannot lie side by side
      and the face is ``jammed``;
    - ``coverage_{group}`` = min(1, L w_eff / A);
    - ``cover_factor`` = 1 - (1 - k_warp)(1 - k_weft); ``thickness_m`` = t_n w (L_warp + L_weft)
      / A, the yarns' volume per area: a narrowed yarn keeps its cross-section ``w t_n`` and gets
      thicker, ``t_n w / w_eff`` (where the yarns leave gaps this is ``t_n (k_warp + k_weft)``);
    - ``braid_angle_deg``: mean of the braid angles of the groups present;
    - ``reached_warp``, ``reached_weft``, ``jammed``: 0/1 (uint8); ``source_face`` (int64): the
      input STL face each field face lies in.

    Sentinels (never NaN): where no yarn of a group reached (its pooled length is 0) the group's
    coverage is 0, its direction (0, 0, 0), its braid angle 0 and ``reached_{group}`` 0 (threshold
    on it in ParaView); a face reached by neither group has ``braid_angle_deg`` 0. Where the
    surface normal is parallel to the centerline tangent (end caps) the braid angle is undefined
    and reported as 0.

    Pooling (how small faces borrow from their neighbours): below the yarn spacing coverage is
    binary (a point lies on a yarn or between two), so per-face sums flicker on faces smaller than
    a few spacings. Each face therefore adds to its own sums those of the faces near it, weighted
    by the biweight kernel ``(1 - (d / rho)^2)^2`` of the distance ``d`` from its centroid to
    where a neighbour's sum sits, up to ``rho = pool_radius_m``: a neighbour's area at its
    centroid, its yarn sums of a group at the length-weighted centre of its yarn pieces of that
    group (placing them at the face centroid would move each yarn by up to half a face and make
    the window's count of yarns depend on how the faces fall);
    facets turned by more than the crease angle (``tolerances.crease_angle_deg``) are left out, so
    the far side of a thin part or an end cap never leaks in. A uniform field stays exactly
    uniform, and the area-weighted means change only by the smoothing near the edges of the
    braided zone. The field mesh's faces are near-equilateral whatever the input, so no face
    averages along a long stretch; ``yarn_length_{group}_m_per_m2`` = L / A is the pooled yarn
    length per area (its integral over the surface is the deposited length, up to the pooling's
    smoothing at the ends of the braided zone).
    """
    V, F, source, h = field_mesh(result, edge_length, remesh) if mesh is None else mesh
    normals, areas, centroids = face_geometry(V, F)
    if getattr(result.config, "is_mixed", False):
        return _map_mixed(result, V, F, source, h, normals, areas, centroids, pool_radius_m)
    length, moment, first, unmapped = clip_yarns(result.yarns, V, F, normals, centroids, with_first=True)
    width = float(result.config.yarn.width)
    thickness = float(result.config.yarn.thickness)
    smooth = centroid_normals(V, F, normals)
    tangent = surface_tangent(result, centroids, smooth)
    e1, e2 = local_frames(smooth, tangent)
    rho = default_pool_radius(h, width) if pool_radius_m is None else float(pool_radius_m)
    planar = planar_moments(moment, e1, e2)
    if rho > 0:
        A = pool(centroids, normals, rho, areas[:, None])[:, 0]
        L = np.empty((len(F), 2))
        M = np.empty((len(F), 2, 3))
        for g in range(2):
            at = np.where(length[:, g, None] > 0, first[:, g]
                          / np.where(length[:, g, None] > 0, length[:, g, None], 1.0), centroids)
            s = pool(centroids, normals, rho, np.column_stack([length[:, g], planar[:, g]]), at)
            L[:, g], M[:, g] = s[:, 0], s[:, 1:]
    else:
        A, L, M = areas, length, planar
    data = _group_fields(A, L, M, e1, e2, np.linalg.norm(tangent, axis=1) > 0, width,
                         float(result.config.yarn.least_width))
    for name in GROUPS:  # directions shown in the facet's plane (the angle is the smooth frame's)
        d = data[f"{name}_direction"]
        d = d - np.einsum("ij,ij->i", d, normals)[:, None] * normals
        norm = np.linalg.norm(d, axis=1)
        data[f"{name}_direction"] = np.divide(d, norm[:, None], out=np.zeros_like(d),
                                              where=norm[:, None] > 0)
    jammed = (data.pop("_jammed_warp") | data.pop("_jammed_weft")).astype(bool)
    k_warp, k_weft = data["coverage_warp"], data["coverage_weft"]
    hit_warp, hit_weft = data["reached_warp"] > 0, data["reached_weft"] > 0
    n_present = hit_warp.astype(float) + hit_weft
    data["braid_angle_deg"] = np.divide(
        data["braid_angle_warp_deg"] * hit_warp + data["braid_angle_weft_deg"] * hit_weft,
        n_present, out=np.zeros(len(F)), where=n_present > 0)
    # a narrowed yarn keeps its cross-section w t, so it gets thicker: the thickness is the yarn
    # volume per area, t w L / A per group (= t k where the yarns leave gaps, t k w / w_eff where
    # they narrowed side by side)
    data["thickness_m"] = thickness * width * np.divide(L[:, 0] + L[:, 1], A, out=np.zeros(len(F)), where=A > 0)
    k_axial = _add_axial_yarns(data, result, V[F], centroids, areas, normals, tangent, hit_warp | hit_weft, h)
    data["cover_factor"] = 1.0 - (1.0 - k_warp) * (1.0 - k_weft) * (1.0 - k_axial)
    data["jammed"] = jammed.astype(np.uint8)
    for g, name in enumerate(GROUPS):
        data[f"yarn_length_{name}_m_per_m2"] = np.divide(L[:, g], A, out=np.zeros(len(F)), where=A > 0)
    data["source_face"] = source.copy()
    for name, values in data.items():
        if not np.all(np.isfinite(values)):  # a bug, not a user error
            raise AssertionError(f"non-finite values in surface field {name}")
    return SurfaceFields(vertices=V, faces=F, source_faces=source, cell_data=data, jammed=jammed,
                         unmapped_length_m=unmapped, edge_length_m=h, pool_radius_m=rho)


# ------------------------------------------------------------------------------- mixed yarns

@dataclass(frozen=True)
class _Subset:
    """The polylines of some yarns of a YarnPaths (points, offsets, group), for clip_yarns."""

    points: np.ndarray
    offsets: np.ndarray
    group: np.ndarray


def yarns_of_type(yarns, kinds, t) -> _Subset:
    """The deposited yarns whose type ``kinds[k]`` is ``t``: yarns (YarnPaths), kinds (ny,) int."""
    offsets = np.asarray(yarns.offsets, dtype=np.int64)
    keep = np.nonzero(np.asarray(kinds) == t)[0]
    counts = offsets[keep + 1] - offsets[keep]
    index = np.concatenate([np.arange(offsets[k], offsets[k + 1]) for k in keep]) if len(keep) \
        else np.zeros(0, dtype=np.int64)
    return _Subset(points=np.asarray(yarns.points)[index],
                   offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
                   group=np.asarray(yarns.group)[keep])


def _map_mixed(result, V, F, source, h, normals, areas, centroids, pool_radius_m):
    """:func:`map_to_surface` for mixed yarns (``[[yarn_type]]``, docs/theory.md §5, "Mixed
    yarns"): the yarns of every type are clipped and pooled apart, and per face and group

    - the yarns narrow together, each to its share of the available width: with the demand
      ``D = sum_t L_t w_t / A`` (the coverage the yarns would have at their own widths), each
      type's width is ``w_eff,t = max(w_t min(1, 1 / D), w_min,t)`` (one type: ``max(min(w, A / L),
      w_min)``, the uniform rule); jammed where some type would narrow below its least width;
    - ``coverage_{group}`` = min(1, sum_t L_t w_eff,t / A), ``yarn_width_{group}_m`` the
      length-weighted mean of ``w_eff,t``; ``thickness_m`` = sum_t t_t w_t (L_t,warp + L_t,weft) / A;
    - per type ``coverage_<type>`` = 1 - (1 - k_t,warp)(1 - k_t,weft) (k_t,g = min(1, L_t,g
      w_eff,t / A)) and ``yarn_length_<type>_m_per_m2`` = (L_t,warp + L_t,weft) / A, which the RTM
      fields weigh with each type's tow data.

    Directions and braid angles are of all the yarns of a group, as for one type."""
    config = result.config
    kinds = config.carrier_types()
    used = config.used_types()
    yarns = [config.types[t] for t in used]
    names = [config.type_names[t] for t in used]
    parts = [clip_yarns(yarns_of_type(result.yarns, kinds, t), V, F, normals, centroids,
                        with_first=True) for t in used]
    moment = np.sum([p[1] for p in parts], axis=0)
    unmapped = float(sum(p[3] for p in parts))
    smooth = centroid_normals(V, F, normals)
    tangent = surface_tangent(result, centroids, smooth)
    e1, e2 = local_frames(smooth, tangent)
    width = float(config.yarn.width)
    rho = default_pool_radius(h, width) if pool_radius_m is None else float(pool_radius_m)
    planar = planar_moments(moment, e1, e2)
    nf, nt = len(F), len(used)
    Lt = np.empty((nt, nf, 2))           # pooled length of every type and group
    if rho > 0:
        A = pool(centroids, normals, rho, areas[:, None])[:, 0]
        M = np.empty((nf, 2, 3))
        length = np.sum([p[0] for p in parts], axis=0)
        first = np.sum([p[2] for p in parts], axis=0)
        for g in range(2):
            at = np.where(length[:, g, None] > 0, first[:, g]
                          / np.where(length[:, g, None] > 0, length[:, g, None], 1.0), centroids)
            # every type's sums sit where the group's do, so that the types' pooled lengths add
            # up to the group's (the pooling is linear in the values at fixed places)
            s = pool(centroids, normals, rho,
                     np.column_stack([*(p[0][:, g] for p in parts), planar[:, g]]), at)
            Lt[:, :, g], M[:, g] = s[:, :nt].T, s[:, nt:]
    else:
        A, M = areas, planar
        for i, p in enumerate(parts):
            Lt[i] = p[0]
    L = Lt.sum(axis=0)
    w = np.array([y.width for y in yarns])
    w_min = np.array([y.least_width for y in yarns])
    data = _group_fields(A, L, M, e1, e2, np.linalg.norm(tangent, axis=1) > 0, width,
                         float(config.yarn.least_width))
    k_type = np.zeros((nt, nf, 2))
    for g, name in enumerate(GROUPS):
        hit = L[:, g] > 0
        demand = np.divide(np.einsum("t,tf->f", w, Lt[:, :, g]), A, out=np.zeros(nf), where=A > 0)
        share = np.minimum(1.0, np.divide(1.0, demand, out=np.ones(nf), where=demand > 0))
        w_eff = np.maximum(w[:, None] * share[None, :], w_min[:, None])       # (nt, nf)
        covered = np.einsum("tf,tf->f", w_eff, Lt[:, :, g])
        data[f"coverage_{name}"] = np.minimum(1.0, np.divide(covered, A, out=np.zeros(nf), where=A > 0))
        data[f"yarn_width_{name}_m"] = np.divide(covered, L[:, g], out=np.zeros(nf), where=hit)
        data[f"_jammed_{name}"] = hit & np.any((Lt[:, :, g] > 0) & (
            w_min[:, None] > w[:, None] * share[None, :] * (1.0 + JAM_RTOL)), axis=0)
        k_type[:, :, g] = np.minimum(1.0, np.divide(w_eff * Lt[:, :, g], A, out=np.zeros((nt, nf)),
                                                    where=A > 0))
    for name in GROUPS:
        d = data[f"{name}_direction"]
        d = d - np.einsum("ij,ij->i", d, normals)[:, None] * normals
        norm = np.linalg.norm(d, axis=1)
        data[f"{name}_direction"] = np.divide(d, norm[:, None], out=np.zeros_like(d),
                                              where=norm[:, None] > 0)
    jammed = (data.pop("_jammed_warp") | data.pop("_jammed_weft")).astype(bool)
    k_warp, k_weft = data["coverage_warp"], data["coverage_weft"]
    hit_warp, hit_weft = data["reached_warp"] > 0, data["reached_weft"] > 0
    n_present = hit_warp.astype(float) + hit_weft
    data["braid_angle_deg"] = np.divide(
        data["braid_angle_warp_deg"] * hit_warp + data["braid_angle_weft_deg"] * hit_weft,
        n_present, out=np.zeros(nf), where=n_present > 0)
    section = np.array([y.thickness * y.width for y in yarns])   # every type's cross-section
    data["thickness_m"] = np.divide(np.einsum("t,tf->f", section, Lt.sum(axis=2)), A,
                                    out=np.zeros(nf), where=A > 0)
    k_axial = _add_axial_yarns(data, result, V[F], centroids, areas, normals, tangent, hit_warp | hit_weft, h)
    data["cover_factor"] = 1.0 - (1.0 - k_warp) * (1.0 - k_weft) * (1.0 - k_axial)
    data["jammed"] = jammed.astype(np.uint8)
    for g, name in enumerate(GROUPS):
        data[f"yarn_length_{name}_m_per_m2"] = np.divide(L[:, g], A, out=np.zeros(nf), where=A > 0)
    for i, name in enumerate(names):
        data[f"coverage_{name}"] = 1.0 - (1.0 - k_type[i, :, 0]) * (1.0 - k_type[i, :, 1])
        data[f"yarn_length_{name}_m_per_m2"] = np.divide(Lt[i].sum(axis=1), A, out=np.zeros(nf),
                                                         where=A > 0)
    data["source_face"] = source.copy()
    for name, values in data.items():
        if not np.all(np.isfinite(values)):  # a bug, not a user error
            raise AssertionError(f"non-finite values in surface field {name}")
    return SurfaceFields(vertices=V, faces=F, source_faces=source, cell_data=data, jammed=jammed,
                         unmapped_length_m=unmapped, edge_length_m=h, pool_radius_m=rho)


def section_perimeter(face_s, areas, side, window, face_range=None):
    """Perimeter (m) of the section at each face's arc length ``face_s`` (nf,), read off the mesh:
    P = dA/ds, the side faces' (``side``, not end caps) area between the two ends of a window
    ``2 window`` long round s, over its length. Each face's area is spread evenly over its extent
    in s (``face_range`` (nf, 2): the least and greatest s of its corners; default its centroid's)
    before it is binned, so a ring of faces that share a centroid's s does not make a step; the
    window is shifted inside the side at its ends."""
    if face_range is None:
        face_range = np.column_stack([face_s, face_s])
    k = (np.arange(SPREAD_SAMPLES) + 0.5) / SPREAD_SAMPLES
    lo_f, hi_f = face_range[side, 0], face_range[side, 1]
    samples = (lo_f[:, None] + (hi_f - lo_f)[:, None] * k[None, :]).ravel()
    weights = np.repeat(areas[side] / SPREAD_SAMPLES, SPREAD_SAMPLES)
    lo_s, hi_s = float(samples.min()), float(samples.max())
    n = max(int(np.ceil(8.0 * (hi_s - lo_s) / window)), 1)
    edges = np.linspace(lo_s, hi_s, n + 1)
    binned, _ = np.histogram(samples, bins=edges, weights=weights)
    cumulative = np.concatenate([[0.0], np.cumsum(binned)])
    width = min(2.0 * window, hi_s - lo_s)
    lo = np.clip(face_s - 0.5 * width, lo_s, hi_s - width)
    area = np.interp(lo + width, edges, cumulative) - np.interp(lo, edges, cumulative)
    return area / max(width, 1e-12)


#: points along a face's extent in s its area is spread over (section_perimeter)
SPREAD_SAMPLES = 8


def _add_axial_yarns(data, result, vertices, centroids, areas, normals, tangent, braided, h):
    """Triaxial braiding: the ``[machine] axial_yarns`` lie along the mandrel (the surface
    projection of the centerline tangent), evenly round each section of perimeter P, wherever
    the braid is. Adds ``coverage_axial`` = min(1, n w_a / P), ``yarn_length_axial_m_per_m2`` =
    n / P and ``axial_direction`` (3), adds the axial yarns' volume per area t_a w_a n / P to
    ``thickness_m``, and returns k_axial for the cover factor 1 - (1 - k)^2 (1 - k_a)."""
    count, width, thick, _ = result.config.axial()
    if count == 0:
        return np.zeros(len(centroids))
    s, _ = result.centerline.project(centroids)
    s = np.asarray(s, dtype=float)
    corners = np.asarray(result.centerline.project(vertices.reshape(-1, 3))[0]).reshape(-1, 3)
    side = np.linalg.norm(tangent, axis=1) > 0
    perimeter = section_perimeter(s, areas, side, 3.0 * h, np.column_stack([corners.min(1), corners.max(1)]))
    per_area = np.where(braided & side, count / perimeter, 0.0)
    k = np.minimum(1.0, width * per_area)
    data["coverage_axial"] = k
    data["yarn_length_axial_m_per_m2"] = per_area
    data["axial_direction"] = tangent * (per_area > 0)[:, None]
    data["thickness_m"] = data["thickness_m"] + thick * width * per_area
    return k


def _group_fields(A, L, M, e1, e2, has_tangent, width, least_width=0.0):
    """Direction, braid angle, coverage, width, reached and jammed of each group from pooled sums.

    A : (nf,) m^2;  L : (nf, 2) m;  M : (nf, 2, 3) m, planar moments (aa, ab, bb) in (e1, e2);
    e1, e2 : (nf, 3) face frames;  has_tangent : (nf,) bool, e1 is the centerline direction;
    width, least_width : m, the yarn's width and the least it narrows to
    """
    data = {}
    for g, name in enumerate(GROUPS):
        hit = L[:, g] > 0
        spacing = np.divide(A, L[:, g], out=np.full_like(A, np.inf), where=hit)
        # paper §2.4.2: the width narrows to the available width, down to the least width
        w_eff = np.maximum(np.minimum(width, spacing), least_width)
        k = np.minimum(1.0, np.divide(L[:, g] * w_eff, A, out=np.zeros_like(A), where=A > 0))
        data[f"yarn_width_{name}_m"] = np.where(hit, w_eff, 0.0)
        a, b = principal_direction_2d(M[:, g, 0], M[:, g, 1], M[:, g, 2])
        d = (a[:, None] * e1 + b[:, None] * e2) * hit[:, None]
        angle = np.degrees(np.arctan2(np.abs(b), a))
        data[f"braid_angle_{name}_deg"] = np.where(hit & has_tangent, angle, 0.0)
        data[f"coverage_{name}"] = k
        data[f"{name}_direction"] = d
        data[f"reached_{name}"] = hit.astype(np.uint8)
        # jammed: the yarns would have to narrow below their least width to lie side by side
        data[f"_jammed_{name}"] = hit & (least_width > spacing * (1.0 + JAM_RTOL))
    return data


# ------------------------------------------------------------------- fields on the input mesh

def fields_on_input(fields: SurfaceFields, mandrel) -> SurfaceFields:
    """The fields carried over to the input (STL) triangles, area-weighted.

    Each input face is cut into pieces no longer than ``TRANSFER_PIECE_EDGES`` field edge lengths
    (:func:`preform.geometry.remesh.subdivide_long_edges`, then bisection of what is still too
    long); each piece takes the values of the field face under its centroid
    (:func:`preform.geometry.remesh.locate_faces`); an input face gets the area-weighted mean of
    its pieces, ``v_i = sum_p a_p v_f(p) / A_i`` (the pieces partition it, so ``sum_p a_p = A_i``).
    So ``sum_i A_i v_i`` is the midpoint-rule integral of the field over the surface, the same
    as on the field mesh up to the pieces that straddle field-face edges.

    Intensive values (coverage, cover factor, thickness, yarn length per area) are averaged over
    the whole face; a group's braid angle and direction over the part of the face that group
    reached (and the direction normalised), so a face half reached keeps the angle of its yarns;
    ``reached_{group}`` is 1 where any piece was reached, ``jammed`` where at least half the area
    is; ``braid_angle_deg`` is recombined from the groups as in :func:`map_to_surface`.

    mandrel : anything with ``vertices`` (nv, 3) m and ``faces`` (nf, 3); returns SurfaceFields
    on those triangles (``source_faces`` = 0 .. nf - 1).
    """
    V = np.asarray(mandrel.vertices, dtype=np.float64)
    F = np.asarray(mandrel.faces, dtype=np.int64)
    nf = len(F)
    h = fields.edge_length_m
    if np.isinf(h):
        h = float(np.median(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1)))
    piece = TRANSFER_PIECE_EDGES * h
    Vp, Fp, src = subdivide_long_edges(V, F, piece)
    Vp, Fp, src2 = refine_to_edge_length(Vp, Fp, piece)
    src = src[src2]
    normals, areas, centroids = face_geometry(Vp, Fp)
    on = locate_faces(fields.vertices, fields.faces, centroids, normals, LOCATE_REACH_EDGES * h)
    ok = on >= 0
    src, areas, on = src[ok], areas[ok], on[ok]
    A = np.bincount(src, areas, nf)

    def mean(values, weights):
        num = np.bincount(src, weights * values, nf)
        den = np.bincount(src, weights, nf)
        return np.divide(num, den, out=np.zeros(nf), where=den > 0), den

    cd = fields.cell_data
    out = {}
    reached = {}
    for name in GROUPS:
        hit = cd[f"reached_{name}"][on].astype(float)
        angle, den = mean(cd[f"braid_angle_{name}_deg"][on], areas * hit)
        out[f"braid_angle_{name}_deg"] = angle
        reached[name] = den > 0
        out[f"reached_{name}"] = reached[name].astype(np.uint8)
        d = np.column_stack([mean(cd[f"{name}_direction"][on, c], areas * hit)[0] for c in range(3)])
        norm = np.linalg.norm(d, axis=1)
        out[f"{name}_direction"] = np.divide(d, norm[:, None], out=np.zeros_like(d),
                                             where=norm[:, None] > 0)
    for key, values in cd.items():
        if key in out or key in ("source_face", "jammed", "braid_angle_deg") or values.ndim != 1:
            continue
        out[key] = mean(values[on].astype(float), areas)[0]
    jammed = mean(cd["jammed"][on].astype(float), areas)[0] >= 0.5
    out["jammed"] = jammed.astype(np.uint8)
    hw, hf = reached["warp"], reached["weft"]
    n_present = hw.astype(float) + hf
    out["braid_angle_deg"] = np.divide(out["braid_angle_warp_deg"] * hw + out["braid_angle_weft_deg"] * hf,
                                       n_present, out=np.zeros(nf), where=n_present > 0)
    out["source_face"] = np.arange(nf, dtype=np.int64)
    out = {k: out[k] for k in cd if k in out}
    return SurfaceFields(vertices=V.copy(), faces=F.copy(), source_faces=np.arange(nf, dtype=np.int64),
                         cell_data=out, jammed=jammed, unmapped_length_m=fields.unmapped_length_m,
                         edge_length_m=fields.edge_length_m, pool_radius_m=fields.pool_radius_m)


# ------------------------------------------------------------------------- a stack of layers

def stack_layers(layer_fields) -> SurfaceFields:
    """The fields of several braided layers on one set of faces (docs/theory.md, "Several layers").

    layer_fields : SurfaceFields of each layer, from the mandrel outwards, mapped onto offset
    copies of one field mesh (``map_to_surface(mesh=...)``), so face ``i`` of every layer lies
    over face ``i`` of the first. The result lies on the first layer's faces (on the mandrel) and
    holds

    - every array of layer ``k`` (from 1) as ``layer{k}_<name>``;
    - the stack's totals under the single-layer names: ``thickness_m = sum_k t_k``,
      ``cover_factor = 1 - prod_k (1 - CF_k)`` (the share of the surface that some layer covers,
      the layers' yarns lying independently of each other), ``jammed`` where any layer jammed;
    - the first layer's braid angles, directions, coverages, yarn lengths and ``reached_*``
      under their single-layer names (the layer on the mandrel, which the top-level history and
      quality checks describe; each layer's own are prefixed).
    """
    base = layer_fields[0]
    data = dict(base.cell_data)
    for k, fields in enumerate(layer_fields, start=1):
        for name, values in fields.cell_data.items():
            if name != "source_face":
                data[f"layer{k}_{name}"] = values
    cd = [f.cell_data for f in layer_fields]
    data["thickness_m"] = np.sum([c["thickness_m"] for c in cd], axis=0)
    data["cover_factor"] = 1.0 - np.prod([1.0 - c["cover_factor"] for c in cd], axis=0)
    data["jammed"] = np.max([c["jammed"] for c in cd], axis=0).astype(np.uint8)
    jammed = data["jammed"].astype(bool)
    return SurfaceFields(vertices=base.vertices, faces=base.faces, source_faces=base.source_faces,
                         cell_data=data, jammed=jammed,
                         unmapped_length_m=float(sum(f.unmapped_length_m for f in layer_fields)),
                         edge_length_m=base.edge_length_m, pool_radius_m=base.pool_radius_m)
