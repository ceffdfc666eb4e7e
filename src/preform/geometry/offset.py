"""The surface a braided layer lies on: the mandrel offset by the thickness of the layers below.

Offset law (docs/theory.md, "Several layers"): every vertex of the base surface moves along its
smooth normal by the stacked thickness ``T`` there,

    x' = x + T(x) c(x) n(x),    n = angle-weighted mean of the face normals round the vertex,
    c = 1 / min_f (n . n_f) at a crease (some face round the vertex turned from n by more than
        OffsetSettings.crease_deg), clamped to OffsetSettings.max_crease_scale; else c = 1,

so that on a smooth surface a vertex moves by ``T`` along the normal (its facets are chords of
the surface: a cylinder of radius r becomes one of r + T exactly at the vertices), and at a
crease the vertex moves so that every face round it is pushed out along its own normal by at
least ``T``, the least pushed by exactly ``T`` (the sharp offset; ``T`` along ``n`` alone would
push the faces of a right-angled crease by ``T cos 45``).

``T`` comes from the mapped thickness fields, which flicker from face to face by a few percent
(discrete yarns, pooled), and steps down to 0 where the layer ends. Before it moves anything the
thickness is smoothed on the vertex graph by Taubin's lambda|mu passes (Taubin 1995: a pair of
umbrella-operator steps ``T <- T + lambda L T`` then ``T <- T + mu L T`` with ``mu < -lambda``
damps the short wavelengths and leaves the long ones, so a uniform thickness stays exactly
uniform and the mean is not shrunk). Then every face is checked against its base face: a face
that turned by more than ``max_turn_deg`` or shrank below ``min_area_ratio`` of its area is
folded (a concave radius smaller than the thickness, or a step too steep); the displacements of
the vertices round folded faces are smoothed further (Laplacian, up to ``repair_passes``), and if
faces stay folded :class:`OffsetError` names the layer, how many and where.

Everything here works on plain arrays: ``vertices (nv, 3) float64 m, faces (nf, 3) int64`` in the
mandrel frame. The base surface is the mandrel itself, refined so that no edge is longer than the
field mesh's (:func:`refined_surface`); refining adds points on the facets, so the surface is the
one the first layer was braided on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import PreformError
from .remesh import locate_faces, refine_to_edge_length, subdivide_long_edges


class OffsetError(PreformError):
    """The offset surface of a layer folds where the thickness cannot be laid."""


@dataclass(frozen=True)
class OffsetSettings:
    """How the offset surface of a layer is built (module docstring)."""

    #: Taubin lambda|mu pairs on the thickness: the pooled fields flicker over a few faces, which
    #: 3 pairs damp by ~(1 - lambda k)(1 - mu k) per pair at the umbrella eigenvalue k of that scale
    smoothing_passes: int = 3
    #: Taubin's lambda (0 < lambda < 1) and mu (< -lambda), Taubin (1995)'s usual pair
    taubin_lambda: float = 0.5
    taubin_mu: float = -0.53
    #: cap of the crease scale 1 / min(n . n_f): a right-angled crease needs sqrt 2; sharper than
    #: about 120 deg the sharp offset runs off and the vertex keeps at most twice the thickness
    max_crease_scale: float = 2.0
    #: a vertex whose smooth normal is turned from a face round it by more than this sits on a
    #: crease: half the mandrel's crease angle (tolerances.crease_angle_deg, 60 deg), as the
    #: normal bisects a crease; the chords of a smooth surface turn by pi / n_around (3 deg at 64)
    crease_deg: float = 30.0
    #: a face turned by more than this from its base face counts as folded (the offset of a smooth
    #: surface by a thickness far below its radii turns faces by hundredths of a degree)
    max_turn_deg: float = 45.0
    #: ... and so does one whose area falls below this share of its base face's
    min_area_ratio: float = 0.05
    #: Laplacian passes of the displacement round folded faces before giving up
    repair_passes: int = 50


@dataclass(frozen=True)
class OffsetReport:
    """What building an offset surface did (for summary.json).

    max_offset_m, mean_offset_m : of the vertex displacements; max_turn_deg : largest turn of a
    face against its base face; repair_passes : Laplacian passes spent on folded faces;
    repaired_vertices : vertices those passes moved
    """

    max_offset_m: float
    mean_offset_m: float
    max_turn_deg: float
    repair_passes: int
    repaired_vertices: int

    def as_dict(self) -> dict:
        return dict(self.__dict__)


# --------------------------------------------------------------------------------- mesh basics

def face_normals_areas(vertices, faces):
    """Unit face normals (nf, 3) (zero where degenerate) and areas (nf,) m^2."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, norm[:, None], out=np.zeros_like(cross), where=norm[:, None] > 0)
    return normals, 0.5 * norm


def corner_angles(vertices, faces):
    """Interior angle (rad) at each corner: (nf, 3)."""
    p = vertices[faces]
    out = np.empty((len(faces), 3))
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        w = p[:, (k + 2) % 3] - p[:, k]
        den = np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
        out[:, k] = np.arccos(np.clip(np.einsum("ij,ij->i", u, w) / den, -1.0, 1.0))
    return out


def vertex_normals(vertices, faces):
    """Angle-weighted mean of the face normals round each vertex, unit: (nv, 3).

    One normal per vertex (not split at creases, unlike the mandrel's corner normals), so the
    offset surface stays closed."""
    normals, _ = face_normals_areas(vertices, faces)
    weights = corner_angles(vertices, faces)
    out = np.zeros((len(vertices), 3))
    for k in range(3):
        np.add.at(out, faces[:, k], weights[:, k, None] * normals)
    norm = np.linalg.norm(out, axis=1)
    return np.divide(out, norm[:, None], out=np.zeros_like(out), where=norm[:, None] > 0)


def crease_scale(vertices, faces, normals, cap, crease_deg):
    """c = 1 / min_f (n . n_f) over the faces round each vertex where that minimum is below
    cos(crease_deg) (a crease), clamped to [1, cap]; 1 elsewhere: (nv,)."""
    fn, _ = face_normals_areas(vertices, faces)
    least = np.ones(len(vertices))
    for k in range(3):
        np.minimum.at(least, faces[:, k], np.einsum("ij,ij->i", normals[faces[:, k]], fn))
    sharp = np.clip(np.divide(1.0, least, out=np.full_like(least, cap), where=least > 0), 1.0, cap)
    return np.where(least < np.cos(np.radians(crease_deg)), sharp, 1.0)


def umbrella(faces, n_vertices):
    """The umbrella operator ``L x = mean of the neighbours - x`` as a sparse (nv, nv) matrix."""
    i = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1)
    j = faces[:, [1, 0, 2, 1, 0, 2]].reshape(-1)
    A = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    A.data[:] = 1.0                       # each edge once, however many faces share it
    degree = np.asarray(A.sum(axis=1)).reshape(-1)
    inv = sp.diags(np.divide(1.0, degree, out=np.zeros_like(degree), where=degree > 0))
    return (inv @ A - sp.diags((degree > 0).astype(float))).tocsr()


def taubin(values, faces, settings: OffsetSettings = OffsetSettings()):
    """``values`` (nv,) or (nv, c) after ``smoothing_passes`` Taubin lambda|mu pairs."""
    L = umbrella(np.asarray(faces, dtype=np.int64), len(values))
    x = np.asarray(values, dtype=np.float64).copy()
    for _ in range(settings.smoothing_passes):
        x = x + settings.taubin_lambda * (L @ x)
        x = x + settings.taubin_mu * (L @ x)
    return x


# ------------------------------------------------------------------------------------ offset

def offset_surface(vertices, faces, thickness, settings: OffsetSettings = OffsetSettings()):
    """(offset vertices (nv, 3), displacement (nv, 3), OffsetReport) of a closed surface.

    thickness : (nv,) float64 m, the stacked thickness at each vertex (before smoothing), >= 0.
    Raises OffsetError where faces stay folded after the repair passes (module docstring).
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    t = np.maximum(taubin(np.maximum(np.asarray(thickness, dtype=np.float64), 0.0), F, settings), 0.0)
    n = vertex_normals(V, F)
    D = (t * crease_scale(V, F, n, settings.max_crease_scale, settings.crease_deg))[:, None] * n
    base_normals, base_areas = face_normals_areas(V, F)
    cos_turn = np.cos(np.radians(settings.max_turn_deg))
    L = umbrella(F, len(V))
    repaired = np.zeros(len(V), dtype=bool)
    passes = 0
    while True:
        normals, areas = face_normals_areas(V + D, F)
        turn = np.einsum("ij,ij->i", normals, base_normals)
        folded = (turn < cos_turn) | (areas < settings.min_area_ratio * base_areas)
        if not folded.any() or passes == settings.repair_passes:
            break
        ring = np.zeros(len(V), dtype=bool)
        ring[F[folded].reshape(-1)] = True
        ring |= np.asarray((abs(L) @ ring.astype(float)) > 0).reshape(-1)   # and their neighbours
        D[ring] += 0.5 * (L @ D)[ring]
        repaired |= ring
        passes += 1
    if folded.any():
        raise OffsetError(f"{np.count_nonzero(folded)} face(s) of the offset surface fold (turned "
                          f"more than {settings.max_turn_deg:g} deg or collapsed) after "
                          f"{passes} smoothing passes, near {_where(V, F, folded)}: the stacked "
                          f"thickness there (up to {np.max(t):.3g} m) is too large for the "
                          "curvature of the surface below")
    offset = np.linalg.norm(D, axis=1)
    report = OffsetReport(max_offset_m=float(offset.max()), mean_offset_m=float(offset.mean()),
                          max_turn_deg=float(np.degrees(np.arccos(np.clip(turn.min(), -1, 1)))),
                          repair_passes=passes, repaired_vertices=int(np.count_nonzero(repaired)))
    return V + D, D, report


def _where(V, F, folded) -> str:
    c = V[F[folded]].mean(axis=1)
    return "(" + ", ".join(f"{x:.4g}" for x in c.mean(axis=0)) + ") m in the mandrel frame"


# ------------------------------------------------------------------- fields between surfaces

def refined_surface(vertices, faces, max_edge):
    """The same piecewise-flat surface with no edge longer than ``max_edge`` (m): long edges cut
    into pieces, then longest-edge bisection (as ``preform.analysis.fields.fields_on_input``)."""
    V, F, _ = subdivide_long_edges(np.asarray(vertices, dtype=np.float64),
                                   np.asarray(faces, dtype=np.int64), max_edge)
    V, F, _ = refine_to_edge_length(V, F, max_edge)
    return V, F


def vertex_means(vertices, faces, face_values):
    """Area-weighted mean of the face values round each vertex: (nv,) or (nv, c)."""
    _, areas = face_normals_areas(vertices, faces)
    values = np.asarray(face_values, dtype=np.float64)
    w = areas.reshape((-1,) + (1,) * (values.ndim - 1))
    num = np.zeros((len(vertices),) + values.shape[1:])
    den = np.zeros(len(vertices))
    for k in range(3):
        np.add.at(num, faces[:, k], w * values)
        np.add.at(den, faces[:, k], areas)
    den = den.reshape((-1,) + (1,) * (values.ndim - 1))
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0)


def interpolate(vertices, faces, vertex_values, points, normals, reach):
    """Linear interpolation of vertex values at points on (or within ``reach`` of) the surface.

    Each point is located on the face under it (``preform.geometry.remesh.locate_faces``) and
    the values of that face's corners are weighted by the point's barycentric coordinates (of
    its projection onto the face's plane, clipped into the face).
    vertex_values : (nv,) or (nv, c);  points, normals : (m, 3);  returns (m,) or (m, c)
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    face = locate_faces(V, F, points, normals, reach)
    a, b, c = (V[F[face, k]] for k in range(3))
    w = barycentric(np.asarray(points, dtype=np.float64), a, b, c)
    values = np.asarray(vertex_values, dtype=np.float64)
    corner = [values[F[face, k]] for k in range(3)]
    shape = (-1,) + (1,) * (values.ndim - 1)
    return sum(w[:, k].reshape(shape) * corner[k] for k in range(3))


def barycentric(p, a, b, c):
    """Barycentric coordinates (m, 3) of the projections of p onto triangles (a, b, c), clipped
    to the triangle (negative weights set to 0 and the rest renormalised)."""
    e0, e1, d = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", e0, e0)
    d01 = np.einsum("ij,ij->i", e0, e1)
    d11 = np.einsum("ij,ij->i", e1, e1)
    d20 = np.einsum("ij,ij->i", d, e0)
    d21 = np.einsum("ij,ij->i", d, e1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) > 0, den, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    out = np.maximum(np.column_stack([1.0 - v - w, v, w]), 0.0)
    total = out.sum(axis=1)
    return np.divide(out, total[:, None], out=np.full_like(out, 1.0 / 3.0), where=total[:, None] > 0)
