"""The mandrel: a closed, outward-wound triangle mesh in its own (STL) frame, in metres.

Besides the triangles it carries what the deposition kernels need: unit face normals, a smooth
normal at every face corner (angle-weighted over the faces around the vertex, split at creases so
that a flat end cap does not bend the side's normals) and the face across every edge.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import MandrelError
from ..tolerances import tol

UNITS = {"m": 1.0, "mm": 1e-3}


class EmbreeScene:
    """The triangles in an embree scene, in float32 (embree's precision), shifted by ``origin``
    (the vertices' low corner) and scaled by ``scale = 100 / d`` (d the diagonal of the bounding
    box of the vertices the faces use) to a box of diagonal 100: trimesh's embree wrapper with
    its ``scale_to_box``, built here from the arrays so that the ray queries of every step do
    not load trimesh. ``scene.run(origins, directions, dists=tfar)`` takes scaled float32 rays
    and returns the first face hit (-1 for none)."""

    def __init__(self, vertices, faces, rtcore_scene, triangle_mesh):
        vertices = np.array(vertices, dtype=np.float64)
        faces = np.asarray(faces)
        used = np.zeros(len(vertices), dtype=bool)
        used[faces.reshape(-1)] = True
        referenced = vertices[used]
        diagonal = float((np.ptp(np.array([referenced.min(axis=0), referenced.max(axis=0)]),
                                 axis=0) ** 2).sum() ** 0.5) if len(referenced) else 0.0
        self.origin = vertices.min(axis=0)
        self.scale = 100.0 / (diagonal if diagonal >= 1e-13 else 1.0)
        self.scene = rtcore_scene.EmbreeScene()
        triangle_mesh(scene=self.scene, vertices=((vertices - self.origin) * self.scale).astype(np.float32),
                      indices=faces.astype(np.int32))


@dataclass(frozen=True)
class Mandrel:
    """A watertight mandrel mesh, mandrel frame, SI.

    vertices : (nv, 3) float64, m
    faces : (nf, 3) int64, wound so that face normals point outwards
    face_normals : (nf, 3) float64, unit, outwards
    corner_normals : (nf, 3, 3) float64, unit smooth normal at corner k of face f
    neighbors : (nf, 3) int64, face across edge k (corners k, k+1) of face f; -1 on a boundary
    source : the file it came from ("" if built from arrays)
    repairs : sentences saying what the intake repaired (empty when nothing was needed)
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_normals: np.ndarray
    corner_normals: np.ndarray
    neighbors: np.ndarray
    source: str = ""
    repairs: tuple = field(default=())

    @cached_property
    def mesh(self):
        """A trimesh view (ray queries use embree when embreex is installed)."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    @cached_property
    def sections(self):
        """The faces indexed for plane sections (``sections.SectionIndex``), without trimesh."""
        from .sections import SectionIndex

        return SectionIndex(self.vertices, self.faces)

    @cached_property
    def bounds(self) -> np.ndarray:
        return np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @cached_property
    def diagonal(self) -> float:
        """Bounding-box diagonal, m."""
        b = self.bounds
        return float(np.linalg.norm(b[1] - b[0]))

    @cached_property
    def _embree(self):
        """The mandrel's embree scene (``EmbreeScene``), or None without embreex (then the ray
        queries go through trimesh's own ray tracer)."""
        try:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh
        except ImportError:
            return None
        return EmbreeScene(self.vertices, self.faces, rtcore_scene, TriangleMesh)

    def intersect_segments(self, starts, ends):
        """First hit of each segment start -> end with the mandrel.

        Hits closer than ``tol.ray_offset * diagonal`` to the start are ignored. Returns
        (hit (n,) bool, point (n, 3), face (n,) int64 (-1 if none), distance (n,) m (inf if none)).
        """
        starts = np.ascontiguousarray(np.asarray(starts, dtype=float).reshape(-1, 3))
        ends = np.ascontiguousarray(np.asarray(ends, dtype=float).reshape(-1, 3))
        n = len(starts)
        hit = np.zeros(n, dtype=bool)
        point = np.zeros((n, 3))
        face = np.full(n, -1, dtype=np.int64)
        dist = np.full(n, np.inf)
        if n == 0:
            return hit, point, face, dist
        if self._embree is not None:
            return self._first_hits_embree(self._embree, starts, ends, hit, point, face, dist)
        d = ends - starts
        length = np.linalg.norm(d, axis=1)
        ok = length > 0
        dirs = np.zeros_like(d)
        dirs[ok] = d[ok] / length[ok, None]
        idx = np.nonzero(ok)[0]
        loc, ray, tri = self.mesh.ray.intersects_location(starts[idx], dirs[idx], multiple_hits=True)
        if len(ray) == 0:
            return hit, point, face, dist
        ray = idx[ray]
        t = np.einsum("ij,ij->i", loc - starts[ray], dirs[ray])
        keep = (t > tol.ray_offset * self.diagonal) & (t <= length[ray])
        ray, t, loc, tri = ray[keep], t[keep], loc[keep], tri[keep]
        order = np.lexsort((t, ray))
        ray, t, loc, tri = ray[order], t[order], loc[order], tri[order]
        first = np.ones(len(ray), dtype=bool)
        first[1:] = ray[1:] != ray[:-1]
        r = ray[first]
        hit[r] = True
        point[r] = loc[first]
        face[r] = tri[first]
        dist[r] = t[first]
        return hit, point, face, dist

    def _first_hits_embree(self, scene, starts, ends, hit, point, face, dist):
        """intersect_segments with one embree query: rays from ``start + offset d`` limited to the
        segment (tfar a little past the end, ``_kernels.mesh.segment_rays``; the end is then
        enforced in float64), the hit point recomputed in float64 on the hit triangle's plane
        (embree works in float32). The same hits as trimesh's multiple-hit query, which sends
        every ray on through the mandrel and re-casts it after each hit."""
        from .._kernels.mesh import segment_rays

        offset = tol.ray_offset * self.diagonal
        n = len(starts)
        dirs = np.empty((n, 3))
        length = np.empty(n)
        live = np.empty(n, dtype=np.int64)
        origin32 = np.empty((n, 3), dtype=np.float32)
        dirs32 = np.empty((n, 3), dtype=np.float32)
        far32 = np.empty(n, dtype=np.float32)
        m = segment_rays(starts, ends, offset, self.diagonal, np.asarray(scene.origin, dtype=np.float64),
                         float(scene.scale), dirs, length, live, origin32, dirs32, far32)
        if m == 0:
            return hit, point, face, dist
        prim = np.asarray(scene.scene.run(origin32[:m], dirs32[:m], dists=far32[:m]), dtype=np.int64)
        got = prim >= 0
        if not got.any():
            return hit, point, face, dist
        rays, tris = live[:m][got], prim[got]
        n = self.face_normals[tris]
        a = self.vertices[self.faces[tris, 0]]
        den = np.einsum("ij,ij->i", n, dirs[rays])
        safe = np.abs(den) > 1e-300
        t = np.where(safe, np.einsum("ij,ij->i", n, a - starts[rays]) / np.where(safe, den, 1.0), 0.0)
        t = np.maximum(t, offset)                  # grazing hits: not before the ray's origin
        inside = t <= length[rays]
        rays, tris, t = rays[inside], tris[inside], t[inside]
        hit[rays] = True
        face[rays] = tris
        dist[rays] = t
        point[rays] = starts[rays] + t[:, None] * dirs[rays]
        return hit, point, face, dist

    @cached_property
    def _face_tree(self):
        """(KD-tree of sample points on the faces, the face of each sample, reach, m): each face
        is sampled on a barycentric grid fine enough that every point of it lies within
        ``reach`` (the median edge length) of one of its samples (a grid cell's edges are at
        most reach long, and a point of a triangle lies within its longest edge of a corner)."""
        from scipy.spatial import cKDTree

        tri = np.asarray(self.vertices, dtype=float)[np.asarray(self.faces, dtype=np.int64)]
        edges = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2)
        reach = float(np.median(edges))
        n = np.maximum(np.ceil(edges.max(axis=1) / reach), 1).astype(np.int64)
        samples, owner = [], []
        for k in np.unique(n):
            faces = np.nonzero(n == k)[0]
            i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
            keep = i + j <= k
            w = np.stack([1.0 - (i[keep] + j[keep]) / k, i[keep] / k, j[keep] / k], axis=1)
            samples.append(np.einsum("sj,fjk->fsk", w, tri[faces]).reshape(-1, 3))
            owner.append(np.repeat(faces, len(w)))
        return cKDTree(np.vstack(samples)), np.concatenate(owner), reach

    def closest_points(self, points):
        """Closest surface points and their faces: ((m, 3), (m,) int64), exact.

        The closest point over the faces of the 8 nearest face samples (``_face_tree``) gives a
        distance d; a face none of whose samples lies within d + reach of the point holds no
        closer point, so the closest point over the faces of the samples within that ball (a
        KD-tree query) is the closest point of the surface (point-triangle projection,
        ``_kernels.mesh.closest_on_candidates``; the lowest face index on a tie)."""
        from .._kernels.mesh import closest_on_candidates

        points = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
        m = len(points)
        V = np.ascontiguousarray(self.vertices, dtype=float)
        F = np.ascontiguousarray(self.faces, dtype=np.int64)
        out = np.empty((m, 3))
        face = np.empty(m, dtype=np.int64)
        d2 = np.empty(m)
        if m == 0:
            return out, face
        tree, owner, reach = self._face_tree
        k = min(8, len(owner))
        _, near = tree.query(points, k=k)
        near = owner[np.asarray(near, dtype=np.int64).reshape(m, k)]
        closest_on_candidates(points, V, F, np.arange(m + 1, dtype=np.int64) * k, near.ravel(),
                              out, face, d2)
        radius = np.sqrt(d2) * (1.0 + 1e-12) + reach
        # the samples within that ball: the nearest 256 (their faces, repeats harmless; a ball
        # of the median edge holds ~170 samples on case A), and the whole ball for a point whose
        # 256th nearest sample still lies inside it
        K = min(256, len(owner))
        dist, idx = tree.query(points, k=K, distance_upper_bound=float(radius.max()))
        dist, idx = dist.reshape(m, K), idx.reshape(m, K)
        inside = dist <= radius[:, None]
        cand = np.where(inside, owner[np.minimum(idx, len(owner) - 1)], face[:, None])
        ptr = np.arange(m + 1, dtype=np.int64) * K
        cand = cand.ravel().astype(np.int64)
        full = np.nonzero(inside[:, -1])[0] if K < len(owner) else np.zeros(0, np.int64)
        if len(full):
            parts = [cand.reshape(m, K)[i] for i in range(m)]
            for i in full:
                parts[i] = np.unique(owner[np.asarray(
                    tree.query_ball_point(points[i], radius[i]), dtype=np.int64)])
            ptr[1:] = np.cumsum([len(c) for c in parts])
            cand = np.concatenate(parts).astype(np.int64)
        closest_on_candidates(points, V, F, ptr, cand, out, face, d2)
        return out, face

    def smooth_normal(self, face, point):
        """Smooth unit normal at a point of a face (NumPy reference of the kernels' blend)."""
        p = self.vertices[self.faces[face]]
        A = np.stack([p[1] - p[0], p[2] - p[0]], axis=1)
        b12, *_ = np.linalg.lstsq(A, np.asarray(point, dtype=float) - p[0], rcond=None)
        b = np.array([1.0 - b12.sum(), b12[0], b12[1]])
        n = b @ self.corner_normals[face]
        return n / np.linalg.norm(n)


def face_neighbors(faces) -> np.ndarray:
    """(nf, 3) int64: the face across edge k (corners k, k+1) of each face, -1 if none or ambiguous."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    nf = len(faces)
    if nf == 0:
        return np.zeros((0, 3), dtype=np.int64)
    from .._kernels.edges import directed_neighbors, edge_table

    # the half-edges grouped by undirected edge (no sort), then within each group the lowest
    # half-edge running the other way; an edge used twice in the same direction is non-manifold
    # or mis-wound: no neighbour (the same arrays as a stable argsort of the directed keys
    # searched for each twin key, tests/unit/test_big_mesh_kernels.py)
    order = np.empty(3 * nf, dtype=np.int64)
    _, count = edge_table(faces, int(faces.max()) + 1, np.empty(3 * nf, dtype=np.int64), order)
    out = np.empty(3 * nf, dtype=np.int64)
    directed_neighbors(faces, order, count, out)
    return out.reshape(nf, 3)


def _corner_normals(vertices, faces, face_normals):
    """Crease-split smooth corner normals (``_kernels.mesh.corner_normals``): interior angles
    ``arccos(clip(cos, -1, 1))`` from ``corner_cosines`` (NumPy's arccos), the faces around each
    vertex from ``corners_by_vertex``."""
    from .._kernels.mesh import corner_cosines, corner_normals, corners_by_vertex

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    cos_crease = float(np.cos(np.radians(tol.crease_angle_deg)))

    c = np.empty((len(F), 3))
    corner_cosines(V, F, c)
    angles = np.arccos(np.clip(c, -1.0, 1.0))
    vert_ptr = np.empty(len(V) + 1, dtype=np.int64)
    vert_faces = np.empty(3 * len(F), dtype=np.int64)
    vert_corner = np.empty(3 * len(F), dtype=np.int64)
    corners_by_vertex(F, len(V), vert_ptr, vert_faces, vert_corner)
    return corner_normals(F, face_normals, angles, vert_ptr, vert_faces, vert_corner, cos_crease)


def mandrel_from_arrays(vertices, faces, source: str = "", repairs=(), check: bool = True) -> Mandrel:
    """Build a Mandrel from vertices (nv, 3) m and faces (nf, 3); checks closure and orientation."""
    from .._kernels.mesh import face_cross_normals

    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    name = source or "mandrel"
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MandrelError(f"{name}: expected a triangle mesh, got vertices {vertices.shape} and faces {faces.shape}")
    if not np.all(np.isfinite(vertices)):
        raise MandrelError(f"{name}: the STL has non-finite vertex coordinates")
    # cross = (p1 - p0) x (p2 - p0), normals = cross / |cross| (cross where |cross| = 0)
    cross = np.empty((len(faces), 3))
    normals = np.empty((len(faces), 3))
    face_cross_normals(vertices, faces, cross, normals)
    neighbors = face_neighbors(faces)
    if check:
        _check_closed(name, vertices, faces, neighbors, cross)
    return Mandrel(vertices=vertices, faces=faces, face_normals=normals,
                   corner_normals=_corner_normals(vertices, faces, normals), neighbors=neighbors,
                   source=str(source), repairs=tuple(repairs))


def edge_use(faces):
    """How the undirected edges of a face list are used: (open, miswound, non_manifold) masks.

    Returns three (nf, 3) bool arrays over the directed edges (corner k -> k+1 of each face):
    ``open``: the edge belongs to this face only (a hole's boundary); ``miswound``: exactly one
    other face has it, in the same direction (the two faces are wound against each other);
    ``non_manifold``: three or more faces share it.
    """
    faces = np.asarray(faces, dtype=np.int64)
    a = faces.reshape(-1)
    b = np.roll(faces, -1, axis=1).reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    _, inverse, counts = np.unique(np.stack([lo, hi], axis=1), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    uses = counts[inverse]
    forward = np.bincount(inverse, weights=(a < b).astype(float), minlength=len(counts))[inverse]
    miswound = (uses == 2) & (forward != 1)
    shape = faces.shape
    return (uses == 1).reshape(shape), miswound.reshape(shape), (uses > 2).reshape(shape)


def _near(vertices, faces, mask):
    """'(x, y, z) m': the mean of the first vertices of the flagged directed edges."""
    where = vertices[faces[mask]].mean(axis=0)
    return f"({where[0]:.4g}, {where[1]:.4g}, {where[2]:.4g}) m"


def _count_edges(faces, mask):
    """Number of distinct undirected edges among the flagged directed edges."""
    a = faces[mask]
    b = np.roll(faces, -1, axis=1)[mask]
    return len(np.unique(np.sort(np.stack([a, b], axis=1), axis=1), axis=0))


def _check_closed(name, vertices, faces, neighbors, cross):
    """Refuse open, non-manifold, inconsistently wound or inward-wound surfaces, saying which."""
    if np.any(neighbors < 0):
        open_, miswound, non_manifold = edge_use(faces)
        if np.any(open_):
            n_open = _count_edges(faces, open_)
            raise MandrelError(
                f"{name} is not watertight: {n_open} open edges (boundary loops near "
                f"{_near(vertices, faces, open_)}). A mandrel must be a closed surface; close the "
                "holes in your CAD tool or mesh editor")
        if np.any(non_manifold):
            raise MandrelError(
                f"{name} is not a manifold surface: {_count_edges(faces, non_manifold)} edges are shared "
                f"by three or more triangles (near {_near(vertices, faces, non_manifold)}). A mandrel "
                "must be one closed surface")
        if np.any(miswound):
            raise MandrelError(
                f"{name} is not consistently oriented: {_count_edges(faces, miswound)} edges join two "
                f"triangles wound against each other (near {_near(vertices, faces, miswound)}). "
                "Re-orient the normals consistently in your CAD tool or mesh editor")
    volume = float(np.einsum("ij,ij->", vertices[faces[:, 0]], cross)) / 6.0
    if volume <= 0:
        raise MandrelError(
            f"{name}: the triangles are wound inwards (enclosed volume {volume:.4g} m^3 is not "
            "positive): the normals point into the mandrel; flip the normals of the STL")


#: a binary STL: an 80-byte header, a uint32 triangle count, then 50 bytes per triangle
STL_HEADER, STL_RECORD = 84, 50


#: one triangle record of a binary STL: normal, three corners (float32), attribute bytes
_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def _check_binary_size(path: Path):
    """Refuse a binary STL whose size disagrees with its triangle count (cut short in a copy or a
    download, or not an STL at all), with the expected and actual sizes. Returns the triangle
    count of a binary STL of exactly the announced size, None for ASCII STL (or longer files)."""
    size = path.stat().st_size
    with path.open("rb") as fh:
        head = fh.read(1024)
    if head.lstrip().startswith(b"solid") and b"facet" in head:
        if not (size >= STL_HEADER and STL_HEADER + STL_RECORD * int.from_bytes(head[80:84], "little") == size):
            return None             # ASCII (a binary header may also start with "solid")
    if size < STL_HEADER:
        raise MandrelError(f"{path}: not a complete STL file: {size} bytes, shorter than the "
                           f"{STL_HEADER}-byte header of a binary STL, and not ASCII STL text")
    n = int.from_bytes(head[80:84], "little")
    expected = STL_HEADER + STL_RECORD * n
    if size < expected:
        raise MandrelError(
            f"{path}: truncated or corrupt binary STL: its header announces {n:,} triangles, which "
            f"take {expected:,} bytes, but the file has {size:,} bytes "
            f"({(size - STL_HEADER) // STL_RECORD:,} whole triangles); export or copy it again")
    if n == 0:
        raise MandrelError(f"{path}: binary STL with no triangles (its header announces 0, the file "
                           f"has {size:,} bytes)")
    return n if size == expected else None


def read_stl(path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of an STL in the file's unit: the soup as stored, three corners per
    triangle (``repair_mesh`` welds them). A binary STL is read directly, an ASCII one by trimesh."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise MandrelError(f"mandrel STL not found: {path}")
    n = _check_binary_size(path)
    if n is not None:   # binary: the records read directly (as trimesh reads them, 3x faster)
        with path.open("rb") as fh:
            fh.seek(STL_HEADER)
            corners = np.fromfile(fh, dtype=_STL_RECORD, count=n)["corners"]
        # one casting copy from the records into float64 (reshaping the strided float32 view
        # first copies it once more: 0.76 against 0.05 s on 1 M triangles)
        vertices = np.empty((n, 3, 3), dtype=np.float64)
        vertices[...] = corners
        return vertices.reshape(-1, 3), np.arange(3 * n, dtype=np.int64).reshape(-1, 3)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh = trimesh.load(str(path), file_type="stl", force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds for broken files
        raise MandrelError(f"{path}: not a readable STL file ({exc})") from None
    if len(mesh.faces) == 0:
        raise MandrelError(f"{path}: the STL has no triangles")
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def load_mandrel(path, unit: str = "m", body=None) -> Mandrel:
    """Read an STL mandrel; unit "m" or "mm" is the STL's length unit (converted to metres).

    body : which body of a multi-body STL is the mandrel (``[mandrel] body``): None (the STL must
    be one body), "largest", or an index into the bodies by decreasing size (``repair_mesh``).
    """
    if unit not in UNITS:
        raise MandrelError(f'[mandrel] stl_unit = "{unit}": expected "m" or "mm"')
    vertices, faces = read_stl(path)
    if UNITS[unit] != 1.0:          # x * 1.0 is x: no copy of the soup's 3 n corners for metres
        vertices = vertices * UNITS[unit]
    from .repair import repair_mesh   # repair imports this module: imported here, not at the top

    vertices, faces, report = repair_mesh(vertices, faces, source=str(path), unit_scale=UNITS[unit],
                                           body=body)
    mandrel = mandrel_from_arrays(vertices, faces, source=str(path), repairs=tuple(report.messages))
    if report.ray_mesh is not None:   # the same arrays: its embree scene serves the ray queries
        mandrel.__dict__["mesh"] = report.ray_mesh
    return mandrel
