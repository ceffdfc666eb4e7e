"""An isotropic field mesh of the mandrel surface, whatever the input triangulation.

CAD tools export cylinders, cones and extrusions as long slivers (a 1.6 m cylinder side of 1 mm
wide triangles) and fine exports as millions of tiny triangles. Fields averaged per face need
faces of about one size, near-equilateral, on the same surface: :func:`isotropic_remesh` makes
them with the remesher of Botsch and Kobbelt (2004, "A remeshing approach to multiresolution
modeling": split edges above 4/3 h, collapse below 4/5 h, flip towards valence 6, tangential
relaxation, projection back onto the input), as implemented by ``gpytoolbox.remesh_botsch``
(MIT), with the input's sharp edges (dihedral angle above ``RemeshSettings.feature_angle_deg``:
cap rims, the end of a shoulder) as feature lines that are split and collapsed only along
themselves, so the outline of the part is kept.

Fed long slivers directly, that remesher halves each long edge once per iteration and so passes
through meshes hundreds of times finer than its result (1.6 m slivers to 12 mm: 224 k faces after
five iterations, 21 s in all). :func:`subdivide_long_edges` first cuts every edge into pieces of
at most ``h`` and re-triangulates each face from those boundary points (a strip between its two
longest sides), which puts the remesher's input at the target scale at once (the points lie on
the input facets, so the surface is unchanged).

Over-fine input (exports at a fine tolerance, millions of faces) is first decimated with quadric
error metrics (:func:`decimate`) to a few times the field mesh's face count: the remesher's collapse
pass over a million faces costs half a minute, the decimation a few seconds.

:func:`locate_faces` finds the input face under each field face (its ``source_face``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PreformError


@dataclass(frozen=True)
class RemeshSettings:
    """Settings of :func:`isotropic_remesh` (the measurements behind them: docs/decisions.md)."""

    #: remeshing iterations: enough for a maximum aspect ratio of about 2 once long edges are pre-cut
    iterations: int = 10
    #: pre-cut input edges to at most this many target lengths: the remesher then starts at its scale
    precut_lengths: float = 2.0
    #: decimate input with more faces than this many times ``area / (sqrt(3)/4 h^2)`` to that many:
    #: the decimated surface stays within the field mesh's own chord sag, the remesh gets cheap
    decimate_above: float = 8.0
    #: pyfqmr's aggressiveness (its default 7): 5 keeps the decimation error below the chord sag
    decimate_aggressiveness: int = 5
    #: dihedral angle (deg) of feature lines: a cap rim is 90 deg, smooth facets at >= 16 sections <= 22.5
    feature_angle_deg: float = 45.0


def _edge_points(V, F, h):
    """Unique undirected edges (ne, 2), pieces per edge (ne,), and per-face edge ids (nf, 3)."""
    directed = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(directed, axis=1)
    edges, inverse = np.unique(key, axis=0, return_inverse=True)
    length = np.linalg.norm(V[edges[:, 1]] - V[edges[:, 0]], axis=1)
    pieces = np.maximum(1, np.ceil(length / h * (1.0 - 1e-12))).astype(np.int64)
    return edges, pieces, inverse.reshape(-1, 3)


def subdivide_long_edges(vertices, faces, h):
    """A conforming re-triangulation with every input edge cut into pieces of at most ``h``.

    Edge ``(a, b)`` gets ``ceil(|b - a| / h)`` equal pieces (shared by both faces on it). A face
    with a cut edge is triangulated as a strip between its two sides that meet at the corner
    opposite its shortest edge (advancing on the side whose next point is less far along, so the
    strip's rungs stay short), and the shortest edge's own points as a fan from the strip's last
    point. No interior points are added: the faces of a long sliver become slivers of length
    ``h``, which the remesher then equalises.

    vertices : (nv, 3) float64, m;  faces : (nf, 3) int64;  h : float, m (> 0)
    returns : vertices (nv', 3) (the first nv unchanged), faces (nf', 3) int64 (winding kept),
        source (nf',) int64: the input face each new face lies in.
    """
    from .._kernels.mesh import long_side_faces

    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    long_face = np.empty(len(F), dtype=bool)
    long_side_faces(np.ascontiguousarray(V), np.ascontiguousarray(F), float(h), long_face)
    if not long_face.any():
        return V, F, np.arange(len(F), dtype=np.int64)          # nothing to cut
    # only faces with a long edge change; a long edge's two faces are both among them, and their
    # short edges get no points, so the untouched faces stay conforming
    cut_ids = np.nonzero(long_face)[0]
    edges, pieces, face_edges = _edge_points(V, F[cut_ids], h)
    # interior points of edge e, from edges[e, 0] to edges[e, 1]: ids start[e] ... start[e] + pieces[e] - 2
    n_new = pieces - 1
    start = len(V) + np.concatenate([[0], np.cumsum(n_new)[:-1]])
    e_rep = np.repeat(np.arange(len(edges)), n_new)
    k = np.arange(len(e_rep)) - np.repeat(start - len(V), n_new) + 1
    t = (k / pieces[e_rep])[:, None]
    new_points = (1.0 - t) * V[edges[e_rep, 0]] + t * V[edges[e_rep, 1]]
    V_out = np.vstack([V, new_points])

    out_faces = [F[~long_face]]
    out_source = [np.nonzero(~long_face)[0]]

    def chain(u, v, e):
        """Vertex ids from u to v along edge e, both ends included."""
        inner = list(range(start[e], start[e] + n_new[e]))
        if edges[e, 0] != u:
            inner.reverse()
        return [u, *inner, v]

    F_cut = F[cut_ids]
    corner_len = np.linalg.norm(V[np.roll(F_cut, -1, axis=1)] - V[F_cut], axis=2)
    tris, src = [], []
    for i, f in enumerate(cut_ids):
        c = F[f]
        s = int(np.argmin(corner_len[i]))          # shortest edge: corners s -> s+1
        apex, ca, cb = c[(s + 2) % 3], c[s], c[(s + 1) % 3]
        A = chain(apex, ca, face_edges[i, (s + 2) % 3])   # edge s+2 runs from corner s+2 to s
        B = chain(apex, cb, face_edges[i, (s + 1) % 3])   # edge s+1 runs from corner s+1 to s+2
        base = chain(ca, cb, face_edges[i, s])
        m, n = len(A) - 1, len(B) - 1
        local = [(apex, A[1], B[1])]
        i = j = 1
        while i < m or j < n:
            if j >= n or (i < m and (i + 1) / m <= (j + 1) / n):
                local.append((A[i], A[i + 1], B[j]))
                i += 1
            else:
                local.append((A[i], B[j + 1], B[j]))
                j += 1
        if len(base) > 2:                          # fan the shortest edge's points from the strip
            x, y, q = local.pop()
            tri = (x, y, q)
            # rotate so that (x, y) is the base edge (ca, cb)
            for _ in range(3):
                if tri[0] == ca and tri[1] == cb:
                    break
                tri = (tri[1], tri[2], tri[0])
            q = tri[2]
            local.extend((base[r], base[r + 1], q) for r in range(len(base) - 1))
        tris.extend(local)
        src.extend([f] * len(local))
    if tris:
        out_faces.append(np.array(tris, dtype=np.int64))
        out_source.append(np.array(src, dtype=np.int64))
    return V_out, np.vstack(out_faces), np.concatenate(out_source).astype(np.int64)


def feature_edges(vertices, faces, angle_deg):
    """(k, 2) int64 vertex pairs of the edges whose dihedral angle exceeds ``angle_deg``."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
    directed = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, edge_id, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    edge_id = edge_id.reshape(-1)
    order = np.argsort(edge_id, kind="stable")
    face_of = order // 3
    first = np.concatenate([[True], edge_id[order[1:]] != edge_id[order[:-1]]])
    starts = np.nonzero(first)[0]
    two = counts[edge_id[order[starts]]] == 2
    fa, fb = face_of[starts[two]], face_of[starts[two] + 1]
    cos = np.einsum("ij,ij->i", n[fa], n[fb])
    sharp = cos < np.cos(np.radians(angle_deg))
    return key[order[starts[two][sharp]]]


def isotropic_remesh(vertices, faces, h, settings: RemeshSettings = RemeshSettings()):
    """An isotropic mesh of edge length about ``h`` on the surface of (vertices, faces).

    Feature lines (see :class:`RemeshSettings`) are kept; vertices are projected onto the input
    surface. vertices (nv, 3) float64 m; faces (nf, 3) int64 (closed, outward);
    h : float, m. Returns vertices (nv', 3) float64, faces (nf', 3) int64 (outward, like the input).
    """
    import warnings

    with warnings.catch_warnings():
        # gpytoolbox's own modules import deprecated scipy / numpy names; not the user's concern
        warnings.simplefilter("ignore", DeprecationWarning)
        import gpytoolbox

    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ideal = 0.5 * np.linalg.norm(cross, axis=1).sum() / (np.sqrt(3.0) / 4.0 * h * h)
    if len(F) > settings.decimate_above * ideal:
        V, F = decimate(V, F, int(settings.decimate_above * ideal), settings.decimate_aggressiveness)
    V, F, _ = subdivide_long_edges(V, F, settings.precut_lengths * h)
    feats = feature_edges(V, F, settings.feature_angle_deg)
    U, G = gpytoolbox.remesh_botsch(np.ascontiguousarray(V), np.ascontiguousarray(F, dtype=np.int32),
                                    settings.iterations, float(h), True,
                                    feature_edges=feats.astype(np.int32))
    U = np.asarray(U, dtype=np.float64)
    G = np.asarray(G, dtype=np.int64)
    used = np.zeros(len(U), dtype=bool)
    used[G.reshape(-1)] = True
    if not used.all():                        # drop vertices no face uses
        remap = np.cumsum(used) - 1
        U, G = U[used], remap[G]
    return U, G


def decimate(vertices, faces, target_faces, aggressiveness):
    """Quadric-error decimation (Garland-Heckbert, ``pyfqmr``, MIT) to about ``target_faces``.

    Quadrics keep sharp edges and the outline (a collapse across a crease costs its squared
    distance to both planes). Returns vertices (nv', 3) float64 and faces (nf', 3) int64.
    """
    import pyfqmr

    simplifier = pyfqmr.Simplify()
    simplifier.setMesh(np.ascontiguousarray(vertices, dtype=np.float64),
                       np.ascontiguousarray(faces, dtype=np.int32))
    simplifier.simplify_mesh(target_count=int(target_faces), aggressiveness=int(aggressiveness),
                             preserve_border=True, verbose=False)
    V, F, _ = simplifier.getMesh()
    return np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)


def locate_faces(vertices, faces, points, normals, reach, mesh=None):
    """The input face under each point: (m,) int64 (-1 where none was found).

    A ray from ``point + reach * normal`` along ``-normal`` (embree through trimesh when
    available) hits the input surface first at the face under the point, for points within
    ``reach`` of a surface whose normal is within 90 deg of ``normal``; where no ray hits
    (numerically grazing) the nearest surface point decides.
    points, normals : (m, 3) float64 (normals unit);  reach : float, m
    mesh : a trimesh.Trimesh of exactly (vertices, faces) to cast on (its ray scene is reused:
        a mandrel's), or None to build one
    """
    import trimesh

    if mesh is None:
        mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64),
                               np.asarray(faces, dtype=np.int64), process=False)
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    origins = points + reach * normals
    out = np.full(len(points), -1, dtype=np.int64)
    if len(points) == 0:
        return out
    tri = mesh.ray.intersects_first(origins, -normals)
    out[:] = tri
    missing = out < 0
    if missing.any():
        _, _, tri = trimesh.proximity.closest_point(mesh, points[missing])
        out[missing] = tri
    return out


#: refinement guard: at most this many edge-splitting passes (each halves the longest edges)
MAX_REFINE_PASSES = 60


def refine_to_edge_length(vertices, faces, max_edge):
    """A conforming refinement of a triangle mesh with no edge longer than ``max_edge``.

    Longest-edge bisection (Rivara): each pass bisects the longest edge of every face that has an
    edge above ``max_edge``, plus, for conformity, the longest edge of every face sharing a split
    edge (repeated until closed). Bisection keeps a face's shape (a needle of length L and width
    w becomes needles of L / 2 and w / 2), so it suits faces that are already about as wide as
    long: ``preform.analysis.fields.fields_on_input`` uses it after cutting long edges into pieces
    (:func:`subdivide_long_edges`); the field mesh itself is remeshed.

    vertices : (nv, 3) float64, m;  faces : (nf, 3) int64;  max_edge : float, m (> 0)
    returns : (vertices (nv', 3) float64, faces (nf', 3) int64, source_faces (nf',) int64), the
        first nv vertices unchanged, winding kept, each new face inside input face source_faces.
    Raises PreformError if ``max_edge`` is not positive and finite.
    """
    if not (np.isfinite(max_edge) and max_edge > 0):
        raise PreformError(f"[output] field_edge_length = {max_edge!r}: expected a positive length in m")
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    source = np.arange(len(F), dtype=np.int64)
    for _ in range(MAX_REFINE_PASSES):
        edges = np.sort(F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1, 3)
        edge_len = np.linalg.norm(V[unique[:, 0]] - V[unique[:, 1]], axis=1)
        face_len = edge_len[inverse]
        longest = inverse[np.arange(len(F)), np.argmax(face_len, axis=1)]
        marked = np.zeros(len(unique), bool)
        marked[longest[face_len.max(axis=1) > max_edge]] = True
        if not marked.any():
            break
        while True:  # closure: a face with a split edge also splits its longest edge
            need = marked[inverse].any(axis=1) & ~marked[longest]
            if not need.any():
                break
            marked[longest[need]] = True
        mid_index = np.full(len(unique), -1, dtype=np.int64)
        mid_index[marked] = len(V) + np.arange(marked.sum())
        V = np.vstack([V, 0.5 * (V[unique[marked, 0]] + V[unique[marked, 1]])])
        F, source = _bisect_faces(F, source, mid_index[inverse], np.argmax(face_len, axis=1))
    return V, F, source


def _bisect_faces(F, source, mids, longest_local):
    """Split faces whose edges are marked (mids (nf, 3): midpoint of edge j or -1); the longest
    edge (local index longest_local) of a split face is always marked and bisected first."""
    marked = mids >= 0
    untouched = ~marked.any(axis=1)
    out_f, out_s = [F[untouched]], [source[untouched]]
    for shift in range(3):  # rotate so the longest edge is (a, b), with midpoint m0
        rot = [(shift + i) % 3 for i in range(3)]
        sel = ~untouched & (longest_local == shift)
        a, b, c = (F[sel, r] for r in rot)
        m0, m1, m2 = (mids[sel, r] for r in rot)
        k1, k2 = marked[sel, rot[1]], marked[sel, rot[2]]
        src = source[sel]
        pieces = (  # (condition, triangles): left half (a, m0, c), right half (m0, b, c)
            (~k2, [a, m0, c]), (k2, [a, m0, m2]), (k2, [m2, m0, c]),
            (~k1, [m0, b, c]), (k1, [m0, b, m1]), (k1, [m0, m1, c]),
        )
        for cond, tri in pieces:
            out_f.append(np.column_stack(tri)[cond])
            out_s.append(src[cond])
    return np.vstack(out_f).astype(np.int64), np.concatenate(out_s).astype(np.int64)
