"""Mesh intake for real-world CAD STLs: repair what can be repaired, refuse the rest.

``repair_mesh`` works on plain arrays and, in this order:

1. merges duplicate and near-duplicate vertices (closer than ``tol.merge_vertices`` times the
   bounding-box diagonal; the first vertex of a cluster keeps its coordinates);
2. drops degenerate faces: collapsed ones (a repeated vertex) and zero-area "caps" (one vertex within
   the merge distance of the opposite edge). A cap's neighbour across the long edge is split at the
   cap's middle vertex, so no crack is left behind;
3. drops exact duplicate faces (same three vertices, either winding);
4. refuses non-manifold edges (three or more faces on one edge), and triangles that do not connect
   at all (more than ``IntakeSettings.unwelded`` of the edges open);
5. makes the winding consistent by propagating orientation across every two-face edge (one
   connected-components call on the orientation double cover; a non-orientable surface is refused);
6. finds the disjoint bodies and refuses several of them unless ``body`` chooses one;
7. fills small holes by ear clipping the loop in its mean plane, and refuses large ones (an open
   surface). Small: the loop spans at most ``small_hole`` of the bounding-box diagonal, or it has
   at most ``few_edges`` edges (one or two missing triangles, which on a coarse CAD mesh may run the
   whole length of the part). No patch may cover more than ``max_fill_share`` of the surface,
   whatever its span. The report names the largest fill: its triangles, its span and its share
   of the surface;
8. turns the winding outwards (signed volume > 0) and refuses a surface that encloses no volume;
9. refuses self-intersections: an edge that pierces a triangle it does not belong to (one batched
   ray query, embree when installed). Coplanar overlaps are not detected.

The passes are numba kernels (``_kernels.mesh``, ``_kernels.edges``) on plain arrays; their slow
NumPy references are in ``tests/support/naive_intake.py``. The thresholds are
:class:`IntakeSettings`.

Every change is said in ``RepairReport.messages``, which the run log and ``summary.json`` repeat.
Merging the corners of an STL triangle soup (``3 * n_faces`` vertices, as every STL file is) is the
format, not a repair, and is not said.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..errors import MandrelError
from ..tolerances import tol


@dataclass(frozen=True)
class IntakeSettings:
    """The mesh intake's thresholds: which holes are filled, and which meshes are refused."""

    #: holes whose boundary loop spans at most this fraction of the bounding-box diagonal are filled
    small_hole: float = 0.05
    #: so are one or two missing triangles (a loop of at most this many edges): on a coarse CAD
    #: mesh one triangle can span the whole part
    few_edges: int = 4
    #: no fill may cover more than this share of the surface (the open mesh's area), whatever its
    #: span: 5 % is the end cap of a cylinder 4.5 diameters long (r / (2 L + 2 r)); more would
    #: invent the shape
    max_fill_share: float = 0.05
    #: a closed surface enclosing less than this times diagonal**3 encloses no volume (flat, folded)
    min_volume: float = 1e-9
    #: more than this fraction of open edges means the triangles were never connected (not holes)
    unwelded: float = 0.5


#: the defaults
INTAKE = IntakeSettings()

_UNIT_NAMES = {1.0: "m", 1e-3: "mm"}


@dataclass(frozen=True)
class RepairReport:
    """What ``repair_mesh`` did. Counts refer to the input; lengths in metres.

    merged_vertices : vertices merged into others (the shared corners of an STL soup not counted)
    degenerate_faces : zero-area faces dropped
    duplicate_faces : repeated faces dropped (same vertices, either winding)
    flipped_faces : faces whose winding was reversed (consistent and outward)
    bodies : disjoint bodies found (one kept)
    holes_filled, largest_hole : small holes filled, and the largest one's span (m)
    messages : one sentence per change, for people
    ray_mesh : the trimesh.Trimesh of the returned arrays that the self-intersection test cast on,
        with its embree scene, for ``Mandrel`` to reuse (building it takes 1 s on 1 M faces)
    """

    input_vertices: int = 0
    input_faces: int = 0
    merged_vertices: int = 0
    degenerate_faces: int = 0
    duplicate_faces: int = 0
    flipped_faces: int = 0
    bodies: int = 1
    holes_filled: int = 0
    largest_hole: float = 0.0
    messages: tuple[str, ...] = ()
    ray_mesh: object = field(default=None, compare=False, repr=False)

    @property
    def changed(self) -> bool:
        """True when anything beyond welding an STL soup was repaired."""
        return bool(self.messages)


def repair_mesh(vertices, faces, *, source="mandrel", unit_scale=1.0, body=None, settings=INTAKE):
    """Repair a triangle mesh (or soup) into one closed, outward-wound body; see the module docstring.

    vertices : (n, 3) float64, m, the STL's frame (already converted with ``unit_scale``)
    faces : (m, 3) int64, indices into ``vertices``
    source : the file name, quoted in messages
    unit_scale : metres per unit of the source file (1e-3 for an STL in mm); locations in messages
        are given in the file's own coordinates so they can be found in the CAD tool
    body : None (exactly one body required), "largest", or an index into the bodies ordered by
        decreasing bounding-box diagonal (0 is the largest)
    settings : IntakeSettings, the thresholds of hole filling and of the refusals

    Returns ``(vertices (k, 3) float64 m, faces (l, 3) int64, RepairReport)``; unused vertices are
    dropped. The inputs are not modified. Raises MandrelError, naming ``source``, what is wrong and
    what to do, for meshes that cannot be a mandrel.
    """
    say = _Messages(source, unit_scale)
    V, F = _validated(vertices, faces, say)
    counts = {"input_vertices": len(V), "input_faces": len(F)}
    radius = tol.merge_vertices * _diagonal(V)

    V, F, counts["merged_vertices"] = _merge_vertices(V, F, radius)
    if counts["merged_vertices"]:
        say.change(f"merged {counts['merged_vertices']:,} duplicate vertices")
    F, counts["degenerate_faces"] = _drop_degenerate(V, F, radius)
    if counts["degenerate_faces"]:
        say.change(f"dropped {counts['degenerate_faces']:,} degenerate faces")
    F, counts["duplicate_faces"] = _drop_duplicate_faces(F)
    if counts["duplicate_faces"]:
        say.change(f"dropped {counts['duplicate_faces']:,} duplicated faces")
    if len(F) == 0:
        say.refuse(f"no usable triangles (all {counts['input_faces']:,} are degenerate)",
                   "export the mandrel again as a closed solid")

    edges = _EdgeTable(F)
    _refuse_non_manifold(V, edges, say)
    _refuse_unwelded(V, edges, radius, say, settings)
    flipped, component = _orientation(F, edges, V, say)
    if flipped.any():
        F = np.where(flipped[:, None], F[:, ::-1], F)
    keep, counts["bodies"] = _choose_body(V, F, component, body, say)
    if not keep.all():
        F, flipped = F[keep], flipped[keep]

    # every edge of a body lies in that body's faces only (two-face edges join faces of one body,
    # and no edge has more), so with no open edge now no kept body has a hole
    closed = not np.any(edges.count == 1)
    F, counts["holes_filled"], counts["largest_hole"] = _fill_small_holes(V, F, say, closed, settings)
    volume = _signed_volume(V, F)
    if volume < 0:
        F = F[:, ::-1]
        flipped = ~flipped
    _refuse_flat(V, F, say, abs(volume), settings)
    n_flipped = int(flipped.sum())
    counts["flipped_faces"] = n_flipped
    if n_flipped == len(flipped):
        say.change(f"turned the normals outwards (all {n_flipped:,} faces were wound inwards)", first=True)
    elif n_flipped:
        say.change(f"flipped {n_flipped:,} faces to consistent outward winding", first=True)
    V, F = _compact(V, F)
    import trimesh

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    mesh = trimesh.Trimesh(V, F, process=False)
    _refuse_self_intersections(V, F, say, mesh)
    return V, F, RepairReport(**counts, messages=tuple(say.changes), ray_mesh=mesh)


class _Messages:
    """Collects repair sentences (orientation ones before hole filling) and raises refusals."""

    def __init__(self, source, unit_scale):
        self.source = str(source)
        self.unit_scale = float(unit_scale)
        self.changes: list[str] = []
        self._before_holes = 0

    def change(self, text, first=False):
        if first:   # said in pipeline order, although decided after the hole filling
            self.changes.insert(self._before_holes, text)
        else:
            self.changes.append(text)

    def mark_holes(self):
        self._before_holes = len(self.changes)

    def refuse(self, what, todo):
        raise MandrelError(f"{self.source}: {what}. {todo[0].upper()}{todo[1:]}")

    def where(self, point):
        """A location in the source file's own coordinates and unit."""
        unit = _UNIT_NAMES.get(self.unit_scale, "file units")
        p = np.asarray(point, dtype=float) / self.unit_scale
        return f"near ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) {unit}"


def _mm(length):
    return f"{1e3 * length:.3g} mm" if length < 1.0 else f"{1e3 * length:,.0f} mm"


def _validated(vertices, faces, say):
    """Copies as (n, 3) float64 and (m, 3) int64, or a refusal naming what is wrong."""
    V = np.array(vertices, dtype=np.float64)
    F = np.array(faces)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        say.refuse(f"expected a triangle mesh, got vertices of shape {V.shape} and faces of shape {F.shape}",
                   "export the mandrel as a triangulated STL")
    if not np.issubdtype(F.dtype, np.integer):
        say.refuse(f"face indices of type {F.dtype} are not integers", "pass faces as int64 indices")
    F = F.astype(np.int64, copy=False)          # F is a copy already (np.array above)
    if F.min() < 0 or F.max() >= len(V):
        say.refuse(f"face indices run from {F.min()} to {F.max()} but there are {len(V)} vertices",
                   "check the mesh export")
    if not np.all(np.isfinite(V)) and not np.all(np.isfinite(V[_unique(F)])):
        say.refuse("some vertex coordinates are not finite (NaN or infinite)", "export the STL again")
    V, F = _compact(V, F)
    return V, F


def _diagonal(V, F=None):
    """Bounding-box diagonal (m) of finite vertices (n, 3), or of those faces F (m, 3) use; 1 for a
    single point. One pass (``_kernels.mesh.vertex_bounds``): ``V.max(axis=0) - V.min(axis=0)``
    exactly, without gathering ``V[np.unique(F)]``."""
    from .._kernels.mesh import vertex_bounds

    F = np.zeros((0, 3), dtype=np.int64) if F is None else np.ascontiguousarray(F, dtype=np.int64)
    V = np.ascontiguousarray(V, dtype=np.float64)
    lo, hi = np.empty(3), np.empty(3)
    vertex_bounds(V, F, lo, hi)
    return float(np.linalg.norm(hi - lo)) or 1.0


def _edge_keys(F, n_vertices):
    """Undirected edge key per face side: (m, 3) int64, side k runs F[:, k] -> F[:, k + 1]."""
    a, b = F, np.roll(F, -1, axis=1)
    return np.minimum(a, b) * np.int64(n_vertices) + np.maximum(a, b)


def _compact(V, F):
    """Drop unused vertices, keeping the order of the used ones."""
    used = np.zeros(len(V), dtype=bool)
    used[F.reshape(-1)] = True
    if used.all():
        return V, F
    remap = np.cumsum(used) - 1
    return V[used], remap[F]


def _merge_vertices(V, F, radius):
    """Merge vertices closer than ``radius`` (m): the lowest index of each cluster survives.

    Returns (vertices, faces, merged) where ``merged`` leaves out the corners shared by an STL
    soup's triangles when the input is a soup (exact copies, ``3 * len(F)`` vertices).
    """
    first, inverse = _weld_exact(V)
    exact = V[first]
    pairs = _near_pairs(exact, radius)
    n_exact = len(exact)
    # clusters: connected components of the pairs on the exact vertices; survivors: the lowest
    # input vertex of each, ascending; new_index: each input vertex's survivor's rank (one
    # union-find pass, _kernels.edges.merge_clusters). Without pairs the clusters are the exact
    # vertices: their first appearances survive, in order, and new_index is the weld's inverse
    if len(pairs) == 0:
        survivors, new_index = first, inverse
    else:
        from .._kernels.edges import merge_clusters

        survivors = np.empty(len(V), dtype=np.int64)
        new_index = np.empty(len(V), dtype=np.int64)
        n = merge_clusters(inverse, np.ascontiguousarray(pairs.reshape(-1, 2), dtype=np.int64), n_exact,
                           survivors, new_index)
        survivors = survivors[:n]
    n_clusters = len(survivors)
    merged = len(V) - n_clusters
    if len(V) == 3 * len(F):
        merged = n_exact - n_clusters                      # a soup: only near-duplicates are repairs
    return V[survivors], new_index[F], merged


#: _near_pairs's grid test applies while coordinates stay below this many grid cubes (the
#: division x / cube then rounds by less than 1e-4 of a cube)
GRID_REACH = 1e12


def _near_pairs(P, radius):
    """``cKDTree(P).query_pairs(radius, output_type="ndarray")``: the pairs of rows of P (n, 3)
    within ``radius`` (m). A grid of cubes of edge ``2 radius`` comes first
    (``_kernels.mesh.grid_neighbours_exist``): when no two points share a cube or touch cubes,
    no pair is that close and the tree (0.45 s on 500 k points) is not built; else the tree."""
    cube = 2.0 * radius
    P = np.ascontiguousarray(P, dtype=np.float64)
    if len(P) and cube > 0 and np.isfinite(cube) and float(np.abs(P).max()) < GRID_REACH * cube:
        from .._kernels.mesh import grid_neighbours_exist

        if not grid_neighbours_exist(P, cube):
            return np.zeros((0, 2), dtype=np.int64)
    return cKDTree(P).query_pairs(radius, output_type="ndarray")


def _weld_exact(V):
    """The distinct rows of V (n, 3) in order of first appearance: (first (k,) the index of each
    one's first appearance, ascending; inverse (n,) the distinct row of each vertex). A hash
    table (``_kernels.mesh.weld_exact``)."""
    from .._kernels.mesh import weld_exact

    V = np.ascontiguousarray(V, dtype=np.float64)

    inverse = np.empty(len(V), dtype=np.int64)
    return weld_exact(V, inverse), inverse


def _drop_degenerate(V, F, radius):
    """Drop zero-area faces (height below ``radius`` m); split the neighbour across a cap's long edge.

    In NumPy (kernel ``_kernels.mesh.degenerate_faces``)::

        collapsed = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
        p = V[F]
        side = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
        length = np.linalg.norm(side, axis=2)
        area2 = np.linalg.norm(np.cross(side[:, 0], side[:, 1]), axis=1)
        longest = length.argmax(axis=1)
        caps = ~collapsed & (area2 <= radius * length.max(axis=1))

    Returns (faces, dropped).
    """
    from .._kernels.mesh import degenerate_faces

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    collapsed = np.empty(len(F), dtype=bool)
    caps = np.empty(len(F), dtype=bool)
    longest = np.empty(len(F), dtype=np.int64)
    degenerate_faces(V, F, float(radius), collapsed, caps, longest)
    if caps.any():
        F = _split_across_caps(F, np.nonzero(caps)[0], longest, collapsed | caps)
    keep = ~(collapsed | caps)
    keep = np.concatenate([keep, np.ones(len(F) - len(keep), dtype=bool)])
    return F[keep], int(np.sum(collapsed | caps))


def _split_across_caps(F, caps, longest, dropped):
    """For each cap (a, b, c) with long edge a-b, split the other face on a-b at c.

    F (m, 3) int64 is not modified; dropped (m,) bool marks the faces about to go; returns faces (m + k, 3): split faces are rewritten in place
    (first half) and their second halves appended. A cap whose long edge has not exactly one other
    face, or whose neighbour is a cap or already split, is only dropped (hole filling then sees it).
    """
    F = F.copy()
    key = _edge_keys(F, int(F.max()) + 1)
    order = np.argsort(key.reshape(-1), kind="stable")
    sorted_keys = key.reshape(-1)[order]
    busy = dropped.copy()
    extra = []
    for f in caps:
        k = longest[f]
        a, b, c = F[f, k], F[f, (k + 1) % 3], F[f, (k + 2) % 3]
        lo, hi = np.searchsorted(sorted_keys, [key[f, k], key[f, k] + 1])
        others = [h for h in order[lo:hi] // 3 if h != f]
        if len(others) != 1 or busy[others[0]]:
            continue
        g = others[0]
        busy[g] = True
        j = int(np.nonzero((F[g] != a) & (F[g] != b))[0][0])      # g = (r, p, q) rolled so r first
        r, p, q = F[g, j], F[g, (j + 1) % 3], F[g, (j + 2) % 3]
        F[g] = (r, p, c)
        extra.append((r, c, q))
    return np.vstack([F, np.array(extra, dtype=np.int64).reshape(-1, 3)])


def _drop_duplicate_faces(F):
    """Keep the first of faces with the same vertex set (either winding): (faces, dropped).

    The faces ``np.unique(np.sort(F, axis=1), axis=0, return_index=True)`` keeps, by a hash
    table (``_kernels.edges.first_of_each_face``) instead of a lexicographic sort."""
    from .._kernels.edges import first_of_each_face

    keep = np.empty(len(F), dtype=bool)
    first_of_each_face(np.ascontiguousarray(F, dtype=np.int64), keep)
    n_kept = int(keep.sum())
    return (F if n_kept == len(F) else F[keep]), len(F) - n_kept


class _EdgeTable:
    """Undirected edges of faces F (m, 3): ``side_edge`` (m, 3) edge id of each face side,
    ``count`` faces per edge, ``pairs`` (k, 2) the two half-edge ids (3 * face + side) of every
    two-face edge."""

    def __init__(self, F):
        from .._kernels.edges import edge_table

        F = np.ascontiguousarray(F, dtype=np.int64)
        # np.unique of the edge keys (_edge_keys) with its inverse and counts, and the stable
        # argsort of the inverse, in O(m) passes instead of sorts
        inverse = np.empty(3 * len(F), dtype=np.int64)
        order = np.empty(3 * len(F), dtype=np.int64)
        self.key, self.count = edge_table(F, int(F.max()) + 1, inverse, order)
        self.side_edge = inverse.reshape(-1, 3)
        starts = np.concatenate([[0], np.cumsum(self.count)[:-1]])
        two = np.nonzero(self.count == 2)[0]
        self.pairs = np.stack([order[starts[two]], order[starts[two] + 1]], axis=1)
        self.n_vertices = int(F.max()) + 1

    def ends(self, edge):
        return divmod(int(self.key[edge]), self.n_vertices)


def _refuse_non_manifold(V, edges, say):
    bad = np.nonzero(edges.count > 2)[0]
    if len(bad):
        a, b = edges.ends(bad[0])
        say.refuse(
            f"{len(bad):,} non-manifold edges (more than two triangles share one edge), e.g. "
            f"{say.where((V[a] + V[b]) / 2)}, so inside and outside are ambiguous",
            "export the mandrel as one closed solid: union touching parts and remove internal faces")


def _refuse_unwelded(V, edges, radius, say, settings=INTAKE):
    """Most edges open: the triangles' corners do not meet, holes would be everywhere."""
    n_open = int(np.sum(edges.count == 1))
    if n_open > settings.unwelded * len(edges.count):
        say.refuse(f"{n_open:,} of {len(edges.count):,} triangle edges have no neighbouring triangle: the "
                   f"corners of neighbouring triangles do not coincide to within {_mm(radius)} (the merge "
                   f"tolerance, {tol.merge_vertices:g} of the mesh size)",
                   "export the STL as one watertight mesh (binary STL, fine tessellation)")


def _orientation(F, edges, V, say):
    """Flips for a consistent winding, and a component label per face (both (m,)).

    Orientation double cover: node f is face f as given, node f + m is face f reversed. Across a
    two-face edge the faces agree when the edge runs in opposite directions in them; the cover links
    the node pairs that agree. A face whose two nodes end up connected lies on a non-orientable
    surface. Otherwise each body's faces split into two classes; the class holding the lower node
    label is kept as given and the other flipped (the outward choice comes later, from the volume).

    The components are found by a union-find over the faces that keeps each face's parity
    against its root (``_kernels.edges.orient_bodies``): the same flips and body numbers (in
    order of the bodies' lowest faces) as connected components of the 2 m-node cover, 10x faster.
    """
    from .._kernels.edges import orient_bodies

    F = np.ascontiguousarray(F, dtype=np.int64)
    pairs = np.ascontiguousarray(edges.pairs, dtype=np.int64).reshape(-1, 2)
    flipped = np.empty(len(F), dtype=bool)
    component = np.empty(len(F), dtype=np.int64)
    f = orient_bodies(F, pairs, flipped, component)
    if f >= 0:
        say.refuse(f"the surface cannot be oriented (one-sided like a Moebius strip), e.g. "
                   f"{say.where(V[F[f]].mean(axis=0))}", "export the mandrel as one closed solid")
    return flipped, component


def _choose_body(V, F, component, body, say):
    """Faces to keep (m,) bool and the number of bodies; several bodies need ``body``."""
    n = int(component.max()) + 1
    if n == 1:
        return np.ones(len(F), dtype=bool), 1
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    corner_body = np.repeat(component, 3)
    corners = V[F.reshape(-1)]
    for k in range(3):
        np.minimum.at(lo[:, k], corner_body, corners[:, k])
        np.maximum.at(hi[:, k], corner_body, corners[:, k])
    ranking = np.argsort(-np.linalg.norm(hi - lo, axis=1), kind="stable")
    n_faces = np.bincount(component, minlength=n)
    listing = "; ".join(
        f"{i}: {' x '.join(_mm(x)[:-3] for x in hi[c] - lo[c])} mm, {n_faces[c]:,} triangles"
        for i, c in enumerate(ranking[:5])) + ("; ..." if n > 5 else "")
    if body is None:
        say.refuse(f'{n} disjoint bodies ({listing}), but a mandrel is one body',
                   'remove the others in your CAD tool, or choose one in the config with '
                   '[mandrel] body = "largest" (or body = <index> in this list)')
    index = 0 if body == "largest" else body
    if not isinstance(index, (int, np.integer)) or isinstance(index, bool) or not 0 <= index < n:
        say.refuse(f"[mandrel] body = {body!r} does not choose one of the {n} disjoint bodies ({listing})",
                   f'use body = "largest" or an index from 0 to {n - 1}')
    chosen = ranking[index]
    what = f"the largest of {n} bodies" if index == 0 else f"body {index} of {n}"
    say.change(f"kept {what} ({n_faces[chosen]:,} triangles; bodies by size: {listing})")
    return component == chosen, n


def _boundary_loops(F):
    """Boundary loops of a consistently wound mesh: lists of vertex ids in the faces' direction
    (each boundary edge runs loop[i] -> loop[i + 1] in its face). A vertex where two holes touch is
    split into simple loops; an unclosed chain comes back as None."""
    edges = _EdgeTable(F)
    sides = np.nonzero(edges.count[edges.side_edge] == 1)
    tails = F[sides]
    heads = F[sides[0], (sides[1] + 1) % 3]
    following: dict[int, list[int]] = {}
    for t, h in zip(tails.tolist(), heads.tolist()):
        following.setdefault(t, []).append(h)
    loops = []
    while following:
        start = next(iter(following))
        walk = [start]
        while True:
            outs = following.get(walk[-1])
            if not outs:
                loops.append(None)
                break
            nxt = outs.pop()
            if not outs:
                del following[walk[-1]]
            if nxt == start:
                loops.extend(_simple_loops(walk))
                break
            walk.append(nxt)
    return loops


def _simple_loops(walk):
    """Split a closed walk that passes a vertex twice (two holes touching) into simple loops."""
    out, stack, where = [], [], {}
    for v in walk:
        if v in where:
            i = where[v]
            out.append(stack[i:])
            for u in stack[i + 1:]:
                del where[u]
            stack = stack[:i + 1]
        else:
            where[v] = len(stack)
            stack.append(v)
    out.append(stack)
    return [loop for loop in out if len(loop) >= 3]


def _fill_small_holes(V, F, say, closed=False, settings=INTAKE):
    """Fill the small boundary loops (module docstring, step 7); refuse if any is large.

    closed : True when F is known to have no open edge (the loops are not searched for).
    settings : which holes are small (``small_hole``, ``few_edges``, ``max_fill_share``).
    Returns (faces, holes filled, largest span m).
    """
    say.mark_holes()
    loops = [] if closed else _boundary_loops(F)
    if not loops:
        return F, 0, 0.0
    spans = np.array([np.inf if loop is None else _diagonal(V[loop]) for loop in loops])
    limit = settings.small_hole * _diagonal(V, F)
    patches = [None if loop is None else _triangulate_loop(V, loop[::-1]) for loop in loops]  # fills run against the loop
    surface = _area(V, F).sum()
    patch_area = np.array([np.inf if patch is None else _area(V, patch).sum() for patch in patches])
    share = patch_area / surface
    small = [patch is not None and (span <= limit or len(patch) <= settings.few_edges - 2)
             for patch, span in zip(patches, spans)]
    too_much = [ok and sh > settings.max_fill_share for ok, sh in zip(small, share)]
    if any(too_much):
        worst = int(np.argmax(np.where(too_much, share, -1.0)))
        k = len(patches[worst])
        say.refuse(
            f"the mesh is an open surface: a hole {_mm(spans[worst])} across, "
            f"{say.where(V[loops[worst]].mean(axis=0))}, would need a patch of {k} triangle"
            f"{'s' if k > 1 else ''} covering {100 * share[worst]:.1f} % of the surface (holes are "
            f"filled up to {settings.max_fill_share:.0%} of the surface)",
            "a mandrel must be one closed solid: close (cap) it in your CAD tool and export it again")
    if not all(small):
        worst = int(np.argmax(np.where(small, -1.0, spans)))
        size = "an unclosed chain" if loops[worst] is None else _mm(spans[worst]) + " across"
        place = "" if loops[worst] is None else ", " + say.where(V[loops[worst]].mean(axis=0))
        say.refuse(
            f"the mesh is an open surface: {len(loops)} boundary loop(s), {len(small) - sum(small)} too "
            f"large to fill, the largest {size}{place} (holes up to {settings.small_hole:.0%} of the mandrel's "
            f"size, {_mm(limit)}, and single missing triangles are filled automatically)",
            "a mandrel must be one closed solid: close (cap) it in your CAD tool and export it again")
    big = int(np.argmax(patch_area))
    k = len(patches[big])
    what = "the hole" if len(loops) == 1 else "the largest"
    wider = f"; the widest {_mm(spans.max())} across" if spans.max() > spans[big] else ""
    say.change(f"filled {len(loops)} small hole{'s' if len(loops) > 1 else ''}: {what} with a patch of "
               f"{k} triangle{'s' if k > 1 else ''} {_mm(spans[big])} across, covering "
               f"{100 * share[big]:.2g} % of the surface{wider}")
    return np.vstack([F, *patches]), len(loops), float(spans.max())


def _unique(a):
    """``np.unique(a)`` (sorted distinct values, flattened) of an integer array by one sort:
    NumPy 2's hash-based unique takes 5.9 s on 6 M int64 keys where sorting takes 0.04 s."""
    s = np.sort(np.asarray(a).reshape(-1))
    if len(s) == 0:
        return s
    keep = np.empty(len(s), dtype=bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def _area(V, F):
    """Triangle areas (m,) m^2."""
    p = V[F]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def _triangulate_loop(V, loop):
    """Ear-clip a closed loop of vertex ids (k,) projected on its Newell plane: (k - 2, 3) int64,
    wound like the loop. Falls back to a fan from the first vertex if the projection is not simple."""
    p = V[loop]
    normal = np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
    normal /= np.linalg.norm(normal) or 1.0
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)
    xy = np.column_stack([(p - p.mean(axis=0)) @ u, (p - p.mean(axis=0)) @ w])   # CCW about normal
    idx = list(range(len(loop)))
    out = []
    while len(idx) > 3:
        ear = _find_ear(xy, idx)
        if ear is None:
            break
        out.append((idx[ear - 1], idx[ear], idx[(ear + 1) % len(idx)]))
        del idx[ear]
    out.extend((idx[0], idx[i], idx[i + 1]) for i in range(1, len(idx) - 1))
    return np.asarray(loop, dtype=np.int64)[np.array(out, dtype=np.int64)]


def _find_ear(xy, idx):
    """Position in ``idx`` of a convex polygon corner with no other corner inside its triangle."""
    pts = xy[idx]
    prev, nxt = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0)
    turn = _cross2(pts - prev, nxt - pts)
    for i in np.argsort(-turn):            # widest convex corners first: fewer slivers
        if turn[i] <= 0:
            return None
        a, b, c = prev[i], pts[i], nxt[i]
        others = np.delete(pts, [(i - 1) % len(pts), i, (i + 1) % len(pts)], axis=0)
        inside = ((_cross2(b - a, others - a) >= 0) & (_cross2(c - b, others - b) >= 0)
                  & (_cross2(a - c, others - c) >= 0))
        if not inside.any():
            return int(i)
    return None


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _signed_volume(V, F):
    """Enclosed volume (m^3) of a closed mesh, positive when wound outwards (about its centre)."""
    p = V[F]
    p -= p.reshape(-1, 3).mean(axis=0)
    return float(np.einsum("ij,ij->", p[:, 0], np.cross(p[:, 1], p[:, 2]))) / 6.0


def _refuse_flat(V, F, say, volume, settings=INTAKE):
    """volume: the outward-wound mesh's enclosed volume (m^3, ``_signed_volume``)."""
    diag = _diagonal(V, F)
    if volume <= settings.min_volume * diag**3:
        say.refuse(f"the closed surface encloses no volume ({volume:.3g} m^3 for a {_mm(diag)} wide mesh: "
                   "flat or folded onto itself)", "export the mandrel as a solid body")


#: ray advance past each hit in self_intersections, in bounding-box diagonals (trimesh's own
#: multiple-hit offset); doubled while a ray keeps hitting the same triangle
RAY_ADVANCE = 1e-6


def self_intersections(vertices, faces, mesh=None):
    """Edges that pierce a triangle they do not belong to: (k, 2) int64 vertex-index pairs.

    vertices : (n, 3) float64, m; faces : (m, 3) int64; mesh : a trimesh.Trimesh of exactly
    these arrays to cast on (its embree scene is built on first use and kept by it), or None.
    Every pair of crossing, non-coplanar triangles has such an edge. Each edge, shortened by a
    hair at both ends, is cast along itself (embree when installed, which works in float32 on
    the mesh shifted to its bounding box's corner and scaled to a 100-unit box) and every
    triangle it meets before its end is collected: the hit is recomputed in float64 on the
    triangle's plane and the ray restarted just past it (trimesh's multiple-hit scheme), with the
    ray's far limit set to what is left of the edge, so no ray travels on through the mandrel
    (kernels ``_kernels.mesh.edge_ray_batch`` / ``edge_ray_hits``). Coplanar overlaps are not found.
    """
    import trimesh

    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if mesh is None:
        mesh = trimesh.Trimesh(vertices, faces, process=False)
    n = np.int64(len(vertices))
    from .._kernels.edges import edge_table
    from .._kernels.mesh import edge_ray_geometry, face_cross_normals

    # the distinct edges in increasing key, _unique(_edge_keys(faces, n)), without a sort
    key, _ = edge_table(faces, int(n), np.empty(3 * len(faces), dtype=np.int64),
                        np.empty(3 * len(faces), dtype=np.int64))
    e = np.stack([key // n, key % n], axis=1)
    k = len(e)
    ok = np.empty(k, dtype=bool)
    a, u, origin = np.empty((k, 3)), np.empty((k, 3)), np.empty((k, 3))
    length, eps = np.empty(k), np.empty(k)
    k = edge_ray_geometry(vertices, e, ok, a, u, length, eps, origin)   # origin = a + eps u
    e, a, u, length, eps, origin = e[ok], a[:k], u[:k], length[:k], eps[:k], origin[:k]
    intersector = mesh.ray
    scene = getattr(intersector, "_scene", None)
    if scene is None or not hasattr(scene, "scene"):        # no embree: trimesh's own rays
        loc, ray, tri = intersector.intersects_location(a + u * eps[:, None], u, multiple_hits=True)
        t = np.einsum("ij,ij->i", loc - a[ray], u[ray])
        inside = t < length[ray] - 2 * eps[ray]
        own = np.any(faces[tri] == e[ray, 0:1], axis=1) | np.any(faces[tri] == e[ray, 1:2], axis=1)
        return e[_unique(ray[inside & ~own])]
    base = max(1e-8, RAY_ADVANCE * float(np.linalg.norm(np.ptp(vertices, axis=0))))
    normals = np.empty((len(faces), 3))
    face_cross_normals(vertices, faces, np.empty((len(faces), 3)), normals)
    scene_origin = np.asarray(scene.origin, dtype=np.float64)
    offset = np.full(k, base)
    last = np.full(k, -1, dtype=np.int64)
    bad = np.zeros(k, dtype=bool)
    live = np.arange(k, dtype=np.int64)
    batch, hits = _edge_ray_passes(k)
    for _ in range(100):
        live, origin32, dirs32, far32 = batch(live, origin, a, u, length, eps, scene_origin, float(scene.scale))
        if len(live) == 0:
            break
        prim = np.asarray(scene.scene.run(origin32, dirs32, dists=far32), dtype=np.int64)
        live = hits(live, prim, vertices, faces, normals, e, origin, a, u, length, eps, base, offset, last, bad)
        if len(live) == 0:
            break
    return e[np.nonzero(bad)[0]]


def _edge_ray_passes(k):
    """``_kernels.mesh.edge_ray_batch`` and ``edge_ray_hits`` for at most ``k`` rays, as functions
    that return the rays still going, and the batch's float32 origins, directions and far
    distances (views of buffers kept here)."""
    from .._kernels.mesh import edge_ray_batch, edge_ray_hits

    rays = np.empty(k, dtype=np.int64)
    origin32 = np.empty((k, 3), dtype=np.float32)
    dirs32 = np.empty((k, 3), dtype=np.float32)
    far32 = np.empty(k, dtype=np.float32)

    def batch(live, origin, a, u, length, eps, scene_origin, scale):
        m = edge_ray_batch(live, origin, a, u, length, eps, scene_origin, scale, rays, origin32, dirs32, far32)
        return rays[:m].copy(), origin32[:m], dirs32[:m], far32[:m]

    def hits(live, prim, V, F, FN, e, origin, a, u, length, eps, base, offset, last, bad):
        m = edge_ray_hits(live, prim, V, F, FN, e, origin, a, u, length, eps, base, offset, last, bad, rays)
        return rays[:m].copy()

    return batch, hits


def _refuse_self_intersections(V, F, say, mesh=None):
    bad = self_intersections(V, F, mesh)
    if len(bad):
        say.refuse(f"the surface intersects itself ({len(bad):,} edges pierce other triangles, e.g. "
                   f"{say.where(V[bad[0, 0]])}), so inside and outside are ambiguous",
                   "export the mandrel as one clean solid (a boolean union of its parts)")
