"""The mandrel's centerline: arc length from the tip, rotation-minimising frames, sections.

A centerline is a polyline in the mandrel frame, tip first. Frames are rotation-minimising
(double reflection, Wang et al. 2008), so a curved mandrel does not twist as it is fed; the first
normal comes from ``roll_reference`` (projected normal to the tip tangent) or, without one, from
the world axis least aligned with the tip tangent.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import MandrelError
from .mandrel import UNITS
from .sections import plane_segments

#: the tip region counts as elongated (its own principal axis is trusted) when its largest
#: principal variance exceeds the second by this factor
ELONGATED = 2.0


@dataclass(frozen=True)
class Centerline:
    """points (n, 3) m, mandrel frame, tip first; s (n,) arc length from the tip, m;
    tangents, normals, binormals (n, 3) unit (T towards increasing s, B = T x N);
    perimeter (n,) m of the cross-section at each point, or None."""

    points: np.ndarray
    s: np.ndarray
    tangents: np.ndarray
    normals: np.ndarray
    binormals: np.ndarray
    perimeter: np.ndarray | None = None

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def frames_at(self, s):
        """(points, T, N, B), each (m, 3), at arc lengths s (m,); straight beyond the ends."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        S = self.s
        i = np.clip(np.searchsorted(S, s, side="right") - 1, 0, len(S) - 2)
        u = (s - S[i]) / (S[i + 1] - S[i])
        inside = np.clip(u, 0.0, 1.0)[:, None]
        T = (1 - inside) * self.tangents[i] + inside * self.tangents[i + 1]
        T /= np.linalg.norm(T, axis=1)[:, None]
        N = (1 - inside) * self.normals[i] + inside * self.normals[i + 1]
        N -= np.einsum("ij,ij->i", N, T)[:, None] * T
        N /= np.linalg.norm(N, axis=1)[:, None]
        B = np.cross(T, N)
        p = self.points[i] + u[:, None] * (self.points[i + 1] - self.points[i])
        before = s < S[0]
        after = s > S[-1]
        if np.any(before):
            p[before] = self.points[0] + (s[before] - S[0])[:, None] * self.tangents[0]
        if np.any(after):
            p[after] = self.points[-1] + (s[after] - S[-1])[:, None] * self.tangents[-1]
        return p, T, N, B

    @cached_property
    def _rows(self):
        """The polyline as Python lists (s, then (x, y, z) tuples of points, tangents, normals)
        for ``frame_values``, which runs twice per time step."""
        rows = lambda a: [tuple(r) for r in np.asarray(a, dtype=float).tolist()]
        return ([float(v) for v in self.s], rows(self.points), rows(self.tangents), rows(self.normals))

    def frame_values(self, s: float):
        """(point, T, N, B), each an (x, y, z) tuple of floats, at one arc length: frames_at for
        one value in plain float arithmetic, without its array set-up (the pose is taken twice
        per time step). T and N are the blends of the vertex frames, normalised (N made normal
        to T first), B = T x N; the point is interpolated, extrapolated along the end tangent
        beyond the ends."""
        S, P, TT, NN = self._rows
        s = float(s)
        i = min(max(bisect.bisect_right(S, s) - 1, 0), len(S) - 2)
        u = (s - S[i]) / (S[i + 1] - S[i])
        w = min(max(u, 0.0), 1.0)
        v = 1 - w
        t0, t1 = TT[i], TT[i + 1]
        tx, ty, tz = v * t0[0] + w * t1[0], v * t0[1] + w * t1[1], v * t0[2] + w * t1[2]
        tn = math.sqrt((tx * tx + ty * ty) + tz * tz)
        tx, ty, tz = tx / tn, ty / tn, tz / tn
        n0, n1 = NN[i], NN[i + 1]
        nx, ny, nz = v * n0[0] + w * n1[0], v * n0[1] + w * n1[1], v * n0[2] + w * n1[2]
        d = (nx * tx + ny * ty) + nz * tz
        nx, ny, nz = nx - d * tx, ny - d * ty, nz - d * tz
        nn = math.sqrt((nx * nx + ny * ny) + nz * nz)
        nx, ny, nz = nx / nn, ny / nn, nz / nn
        B = (ty * nz - tz * ny, tz * nx - tx * nz, tx * ny - ty * nx)
        if s < S[0]:
            a, e, h = P[0], TT[0], s - S[0]
            p = (a[0] + h * e[0], a[1] + h * e[1], a[2] + h * e[2])
        elif s > S[-1]:
            a, e, h = P[-1], TT[-1], s - S[-1]
            p = (a[0] + h * e[0], a[1] + h * e[1], a[2] + h * e[2])
        else:
            a, b = P[i], P[i + 1]
            p = (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]))
        return p, (tx, ty, tz), (nx, ny, nz), B

    def frame_at(self, s: float):
        """(point, T, N, B), each (3,), at one arc length (``frame_values`` as arrays)."""
        return tuple(np.array(v) for v in self.frame_values(s))

    def project(self, points):
        """Arc length of the closest polyline point and the distance to it: ((m,), (m,)) m.

        Every segment is tried for every point (``_kernels.mesh.project_to_polyline``, exact;
        0.5 M mandrel vertices against 200 segments in well under a second).
        """
        from .._kernels.mesh import project_to_polyline

        points = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
        out_s = np.empty(len(points))
        out_d = np.empty(len(points))
        project_to_polyline(points, np.ascontiguousarray(self.points, dtype=float),
                            np.ascontiguousarray(self.s, dtype=float), out_s, out_d)
        return out_s, out_d


def _check_unit(unit, name):
    if unit not in UNITS:
        raise MandrelError(f'{name} = "{unit}": expected "m" or "mm"')


def _initial_normal(T0, roll_reference):
    if roll_reference is not None:
        r = np.asarray(roll_reference, dtype=float)
        n = r - (r @ T0) * T0
        if np.linalg.norm(n) > 1e-9 * max(np.linalg.norm(r), 1e-300):
            return n / np.linalg.norm(n)
    axis = np.eye(3)[int(np.argmin(np.abs(T0)))]
    n = axis - (axis @ T0) * T0
    return n / np.linalg.norm(n)


def rotation_minimising_frames(points, tangents, roll_reference=None):
    """Normals (n, 3) by the double reflection method (Wang et al. 2008)."""
    N = np.empty_like(points)
    N[0] = _initial_normal(tangents[0], roll_reference)
    for i in range(len(points) - 1):
        v1 = points[i + 1] - points[i]
        c1 = v1 @ v1
        rL = N[i] - (2.0 / c1) * (v1 @ N[i]) * v1
        tL = tangents[i] - (2.0 / c1) * (v1 @ tangents[i]) * v1
        v2 = tangents[i + 1] - tL
        c2 = v2 @ v2
        n = rL - (2.0 / c2) * (v2 @ rL) * v2 if c2 > 1e-30 else rL
        n -= (n @ tangents[i + 1]) * tangents[i + 1]
        N[i + 1] = n / np.linalg.norm(n)
    return N


def centerline_from_points(points, roll_reference=None, perimeter=None) -> Centerline:
    """A Centerline through points (n, 3) m, tip first (consecutive duplicates removed)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-12
    points = points[keep]
    if perimeter is not None:
        perimeter = np.asarray(perimeter, dtype=float)[keep]
    if len(points) < 2:
        raise MandrelError("a centerline needs at least two distinct points")
    seg = np.diff(points, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg_len)])
    d = seg / seg_len[:, None]
    T = np.empty_like(points)
    T[0] = d[0]
    T[-1] = d[-1]
    if len(points) > 2:
        t = d[:-1] + d[1:]
        T[1:-1] = t / np.linalg.norm(t, axis=1)[:, None]
    N = rotation_minimising_frames(points, T, roll_reference)
    return Centerline(points=points, s=s, tangents=T, normals=N, binormals=np.cross(T, N),
                      perimeter=perimeter)


def read_centerline_csv(path, unit: str = "m", roll_reference=None) -> Centerline:
    """Centerline from a CSV of x,y,z per line in the STL's unit, tip first.

    Blank lines and ``#`` comments are skipped. The first other line may be a header naming the
    columns; if it names ``x``, ``y`` and ``z`` those columns are read (so the ``x,y,z,s,perimeter``
    files of ``write_centerline_csv`` and ``s,x,y,z`` tables both work), otherwise the first three.
    A bad row raises MandrelError naming the file and the line.
    """
    _check_unit(unit, "[mandrel] stl_unit")
    path = Path(path)
    if not path.is_file():
        raise MandrelError(f"centerline CSV not found: {path}")
    rows = []
    columns = [0, 1, 2]
    first = True
    raw = path.read_bytes()
    try:
        text_all = raw.decode("utf-8-sig")      # a byte-order mark (Excel's "CSV UTF-8") is accepted
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise MandrelError(f"{path}: not a UTF-8 text CSV: byte 0x{raw[exc.start]:02x} at offset "
                           f"{exc.start} (line {line}) is not UTF-8; expected a text file of x,y,z "
                           "numbers (save it as CSV UTF-8 or plain text)") from None
    for lineno, line in enumerate(text_all.splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        parts = [p.strip() for p in text.replace(";", ",").split(",")]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            if first:
                columns = _header_columns(parts, columns)
                first = False
                continue
            raise MandrelError(f"{path}, line {lineno}: expected numbers x,y,z, got {text!r}") from None
        first = False
        if len(values) <= max(columns):
            raise MandrelError(f"{path}, line {lineno}: expected {max(columns) + 1} numbers "
                               f"(x,y,z), got {text!r}")
        point = [values[c] for c in columns]
        if not np.all(np.isfinite(point)):
            raise MandrelError(f"{path}, line {lineno}: x,y,z must be finite numbers, got {text!r}")
        rows.append(point)
    if len(rows) < 2:
        raise MandrelError(f"{path}: a centerline needs at least two points, found {len(rows)}")
    return centerline_from_points(np.array(rows) * UNITS[unit], roll_reference=roll_reference)


def _header_columns(names, default):
    """Column indices of x, y, z in a header row (names lower-cased), else ``default``."""
    names = [n.lower().strip('"') for n in names]
    if all(c in names for c in "xyz"):
        return [names.index(c) for c in "xyz"]
    return default


def _slab_index(mesh):
    """Face centroids (nf, 3) and each face's largest centroid-to-corner distance (nf,) m, cached
    in the mesh's ``metadata``: a plane farther than that from a centroid cannot cut the face
    (``_kernels.mesh.centroids_and_reach``)."""
    cached = mesh.metadata.get("_preform_slab")
    if cached is None:
        from .._kernels.mesh import centroids_and_reach

        F = np.ascontiguousarray(mesh.faces.view(np.ndarray), dtype=np.int64)
        V = np.ascontiguousarray(mesh.vertices.view(np.ndarray), dtype=np.float64)
        centroids = np.empty((len(F), 3))
        reach = np.empty(len(F))
        centroids_and_reach(V, F, centroids, reach)
        cached = mesh.metadata["_preform_slab"] = (centroids, reach)
    return cached


def _axis_order(mesh, axis):
    """Faces sorted by centroid coordinate ``axis`` (cached): (order (nf,), sorted coordinates
    (nf,), centre (3,), largest centroid distance from the centre across the axis, m)."""
    key = f"_preform_axis{axis}"
    cached = mesh.metadata.get(key)
    if cached is None:
        centroids, _ = _slab_index(mesh)
        order = np.argsort(centroids[:, axis], kind="stable")
        centre = 0.5 * (centroids.min(axis=0) + centroids.max(axis=0))
        across = np.delete(centroids - centre, axis, axis=1)
        radius = float(np.sqrt((across ** 2).sum(axis=1).max()))
        cached = mesh.metadata[key] = (order, centroids[order, axis], centre, radius)
    return cached


#: a plane whose normal is within 60 deg of a coordinate axis searches a window of the faces
#: sorted along that axis instead of testing every face
WINDOW_MIN_COS = 0.5


def _faces_near_plane(mesh, normal, level):
    """Indices (ascending) of the faces whose centroid lies within their reach of the plane
    ``x . normal = level``: ``|c . n - level| <= reach (1 + 1e-9)``.

    With ``n_a`` the normal's largest coordinate (axis a, ``|n_a| >= WINDOW_MIN_COS``) and the
    centroids within R of the centre m across a: ``|(c - m) . n - (c_a - m_a) n_a| <= R sqrt(1 -
    n_a^2)``, so only centroids with ``|(c_a - m_a) n_a - (level - m . n)| <= reach_max (1 + 1e-9)
    + R sqrt(1 - n_a^2)`` can pass; those (a binary search in the sorted coordinates) are tested.
    """
    centroids, reach = _slab_index(mesh)
    axis = int(np.argmax(np.abs(normal)))
    na = float(normal[axis])
    if abs(na) < WINDOW_MIN_COS or len(centroids) < 10000:
        return np.nonzero(np.abs(centroids @ normal - level) <= reach * (1.0 + 1e-9))[0]
    order, coord, centre, radius = _axis_order(mesh, axis)
    rmax = mesh.metadata.get("_preform_reach_max")
    if rmax is None:
        rmax = mesh.metadata["_preform_reach_max"] = float(reach.max())
    mid = centre[axis] + (level - float(centre @ normal)) / na
    half = (rmax * (1.0 + 1e-9) + radius * np.sqrt(max(0.0, 1.0 - na * na))) / abs(na)
    half = half * (1.0 + 1e-6) + 1e-9 * (abs(mid) + radius)          # rounding of the bound itself
    lo, hi = np.searchsorted(coord, [mid - half, mid + half])
    candidates = np.sort(order[lo:hi])
    near = np.abs(centroids[candidates] @ normal - level) <= reach[candidates] * (1.0 + 1e-9)
    return candidates[near]


def _section_loops(mesh, origin, normal):
    """Closed section loops (list of (k, 3) arrays, first point repeated last) of a mesh with a plane.

    ``mesh``: anything with ``vertices``, ``faces`` and a ``metadata`` dict for the face index
    (``Mandrel.sections``, a ``SectionIndex``; a trimesh object works too). Only the faces whose
    centroid lies within their own centroid-to-corner distance of the plane are cut, found by
    ``_faces_near_plane``: on a 2 M-face mandrel a section then costs about a millisecond instead
    of 77 ms for the whole mesh. The cut is ``plane_segments`` on those faces' corners.
    """
    normal = np.asarray(normal, dtype=float)
    origin = np.asarray(origin, dtype=float)
    level = float(origin @ normal)
    local = _faces_near_plane(mesh, normal, level)
    if len(local) == 0:
        return []
    V = np.asarray(mesh.vertices).view(np.ndarray)
    corners = V[np.asarray(mesh.faces).view(np.ndarray)[local].reshape(-1)]
    segments = plane_segments(corners, corners @ normal - level, normal, origin)
    if segments is None:
        return []
    return chain_segments(segments)


def chain_segments(segments, rel_tol=1e-9):
    """Join segments (n, 2, 3) that share end points into closed loops; open chains are dropped.

    End points closer than ``rel_tol * 1e3`` of the segments' extent are one node (rounded
    coordinates); the walk over the nodes is ``_kernels.sections.chain_loops``. Each loop is
    (k + 1, 3), its first point repeated last.
    """
    from .._kernels.sections import chain_loops

    if len(segments) == 0:
        return []
    segments = np.asarray(segments, dtype=float)
    scale = float(np.ptp(segments.reshape(-1, 3), axis=0).max()) or 1.0
    keys = np.round(segments.reshape(-1, 3) / (rel_tol * 1e3 * scale)).astype(np.int64)
    ids = np.ascontiguousarray(_row_ids(keys).reshape(-1, 2), dtype=np.int64)
    nodes, offsets, src = chain_loops(ids, int(ids.max()) + 1)
    ends = segments.reshape(-1, 3)
    loops = []
    for a, b in zip(offsets[:-1], offsets[1:]):
        loop = nodes[a:b]
        loops.append(ends[src[np.append(loop, loop[0])]])
    return loops


def _row_ids(keys):
    """``np.unique(keys, axis=0, return_inverse=True)[1]`` of integer rows (n, 3): each row's rank
    among the distinct rows in lexicographic order. The rows are read as one mixed-radix integer
    ``((x - x0) R_y + (y - y0)) R_z + (z - z0)`` (R the ranges), which orders them the same way,
    when that fits in 62 bits, as it does for ``chain_segments``'s keys (at most 1e6 + 1 values per
    axis): a 1-D unique is 10x faster than the row-wise one on a section's few thousand points."""
    lo = keys.min(axis=0)
    span = keys.max(axis=0) - lo + 1
    if float(span[0]) * float(span[1]) * float(span[2]) >= 2.0 ** 62:
        return np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1)
    k = keys - lo
    flat = (k[:, 0] * span[1] + k[:, 1]) * span[2] + k[:, 2]
    return np.unique(flat, return_inverse=True)[1].reshape(-1)


def _loop_properties(loop, normal):
    """Area centroid (3,), area and perimeter of a planar loop."""
    u = np.cross(normal, [1.0, 0.0, 0.0])
    if np.linalg.norm(u) < 0.5:
        u = np.cross(normal, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)
    o = loop[0]
    x = (loop - o) @ u
    y = (loop - o) @ w
    cross = x[:-1] * y[1:] - x[1:] * y[:-1]
    area = 0.5 * cross.sum()
    if abs(area) < 1e-300:
        c = loop.mean(axis=0)
    else:
        cx = ((x[:-1] + x[1:]) * cross).sum() / (6 * area)
        cy = ((y[:-1] + y[1:]) * cross).sum() / (6 * area)
        c = o + cx * u + cy * w
    perimeter = float(np.linalg.norm(np.diff(loop, axis=0), axis=1).sum())
    return c, abs(area), perimeter


def _nearest_loop(loops, normal, predicted):
    best = None
    for loop in loops:
        c, area, per = _loop_properties(loop, normal)
        d = np.linalg.norm(c - predicted)
        if best is None or d < best[0]:
            best = (d, c, area, per)
    return best


def section_perimeters(mandrel, centerline: Centerline, s_values) -> np.ndarray:
    """Perimeter (m) of the section loop around the centerline at each s (plane normal to T)."""
    s_values = np.atleast_1d(np.asarray(s_values, dtype=float))
    p, T, _, _ = centerline.frames_at(s_values)
    out = np.zeros(len(s_values))
    for k in range(len(s_values)):
        best = _nearest_loop(_section_loops(mandrel.sections, p[k], T[k]), T[k], p[k])
        out[k] = 0.0 if best is None else best[3]
    return out


def with_perimeter(centerline: Centerline, mandrel) -> Centerline:
    """A copy with ``perimeter`` filled from the mandrel's sections."""
    return replace(centerline, perimeter=section_perimeters(mandrel, centerline, centerline.s))


#: ``auto_centerline`` cuts faces into pieces no longer than this fraction of the mandrel's
#: extent before selecting the surface near the tip by piece centroid (a 1.6 m CAD sliver of a
#: cylinder's side has its centroid mid-length, so no whole side face is near either end)
PIECE_FRACTION = 0.02


def surface_moments(vertices, faces, which=None):
    """Areas (nf,) m^2, centroids (nf, 3) m and second moments (nf, 3, 3) m^4 of triangles.

    Second moment of triangle (a, b, c) over its area: ``A / 12 (a a^T + b b^T + c c^T + s s^T)``
    with ``s = a + b + c`` (exact for a uniform density), so principal axes computed from them
    are properties of the surface, not of how it was triangulated. ``which``: a callable taking
    the centroids and returning a bool mask (nf,); then only the masked triangles' moments are
    formed and returned (each triangle's values are its own, so they equal the full arrays'
    masked rows).

    One pass per face (``_kernels.mesh.triangle_moments``, 5x faster than NumPy on 1 M faces),
    bit-identical to the NumPy form::

        p = vertices[faces]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        s = p.sum(axis=1)
        second = (np.einsum("fki,fkj->fij", p, p) + np.einsum("fi,fj->fij", s, s)) * (area / 12.0)[:, None, None]
        centroid = s / 3.0
    """
    from .._kernels.mesh import centroids_and_reach, triangle_moments

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    if which is not None:
        centroid = np.empty((len(F), 3))
        centroids_and_reach(V, F, centroid, np.empty(len(F)))     # centroid: (a + b + c) / 3
        F = np.ascontiguousarray(F[which(centroid)])
    area = np.empty(len(F))
    centroid = np.empty((len(F), 3))
    second = np.empty((len(F), 3, 3))
    triangle_moments(V, F, area, centroid, second)
    return area, centroid, second


def _principal_axes(area, centroid, second):
    """Eigenvalues (3,) ascending, eigenvectors (3, 3) (columns) and centre (3,) of the surface
    pieces' covariance ``sum M_i / A - c c^T``."""
    A = area.sum()
    centre = (area @ centroid) / A
    cov = second.sum(axis=0) / A - np.outer(centre, centre)
    vals, vecs = np.linalg.eigh(cov)
    return vals, vecs, centre


def _tip_axis(area, centroid, second, global_axis):
    """Axis (3,) of the surface near the tip, pointing away from the tip, and its centre (3,).

    The local principal axis where the tip region is elongated (a bent part's global axis is
    oblique there); the global axis where it is not (a fat tip region is mostly end cap, whose
    principal axis lies across the mandrel). An eigenvector's sign is arbitrary: it is turned to
    point along ``global_axis`` (tip towards the far end), which a local axis within 90 deg of the
    global one always can be. The trace corrects the tangent from the centroids.
    """
    vals, vecs, centre = _principal_axes(area, centroid, second)
    T = vecs[:, -1] if vals[-1] > ELONGATED * vals[-2] else global_axis
    return (T if T @ global_axis >= 0 else -T), centre


def auto_centerline(mandrel, n_sections: int | None = None, roll_reference=None) -> Centerline:
    """Slice centroids traced along the mandrel (``centerline = "auto"``).

    The two ends come from the principal axis of the surface (exact second moments of its
    triangles, :func:`surface_moments`, so the result does not depend on the triangulation); the
    tip is the
    end (on that axis) nearer the STL frame's origin, so a mandrel modelled from its tip at the
    origin, as the shipped ones are, is fed tip first. To feed the other end first, move the STL's
    origin or give a centerline CSV.

    From the tip the trace steps ``h = extent / n_sections`` (default 200 sections), slices the
    mesh normal to the current tangent and takes the area centroid of the section loop nearest
    the predicted point; the tangent follows consecutive centroids, so bends are followed. The ends
    are extended to the mesh's extremes along the end tangents. ``perimeter`` is filled from the
    same sections.
    """
    from .._kernels.mesh import any_side_longer
    from .remesh import subdivide_long_edges

    V = mandrel.vertices
    area, C, M = surface_moments(V, mandrel.faces)
    _, vecs, centre = _principal_axes(area, C, M)
    axis = vecs[:, -1]
    proj = (V - centre) @ axis
    # the two ends, on the principal axis; the tip is the one nearer the STL origin
    if np.linalg.norm(centre + proj.max() * axis) < np.linalg.norm(centre + proj.min() * axis):
        axis = -axis
        proj = -proj
    extent = float(proj.max() - proj.min())
    tip = V[np.argmin(proj)]
    # local axis at the tip: principal axis of the surface near the tip end (a bent part's global
    # axis is oblique there)
    F = np.ascontiguousarray(mandrel.faces, dtype=np.int64)
    if any_side_longer(np.ascontiguousarray(V, dtype=np.float64), F, PIECE_FRACTION * extent):
        Vp, Fp, _ = subdivide_long_edges(V, F, PIECE_FRACTION * extent)
    else:                                     # nothing to cut: the pieces are the faces
        Vp, Fp = V, F
    area, C, M = surface_moments(Vp, Fp, which=lambda c: np.linalg.norm(c - tip, axis=1) < 0.25 * extent)
    T, local_centre = _tip_axis(area, C, M, axis)
    near = V[np.linalg.norm(V - tip, axis=1) < 0.25 * extent]
    n = n_sections or 200
    h = extent / n
    tip_depth = float(np.min((near - tip) @ T))
    start = tip + (0.5 * h - tip_depth) * T
    start = start + (local_centre - start) - ((local_centre - start) @ T) * T
    name = mandrel.source or "mandrel"
    pts, pers = _trace(mandrel.sections, start, T, h, 8 * n, name)
    pts, pers = _extend_ends(V, pts, pers, h)
    return centerline_from_points(pts, roll_reference=roll_reference, perimeter=pers)


def _section(mesh, origin, normal, predicted):
    """(distance to predicted, centroid (3,), area, perimeter) of the loop nearest ``predicted``."""
    return _nearest_loop(_section_loops(mesh, origin, normal), normal, predicted)


def _trace(mesh, start, T, h, max_steps, name):
    """March from the tip: slice normal to T, step to the nearest loop's centroid.

    Returns centroids (m, 3) and section perimeters (m,). T follows the chord over the last
    ``sqrt(area)`` of the trace, not the last step: a tangent from consecutive centroids is unstable
    where the radius changes (a cut of a cone tilted by theta has its centroid about r r' theta off
    the axis, which the next one-step chord turns into a tilt r r' / h times larger). Over a
    baseline of sqrt(area) ~ 1.8 r the gain is about r' / 1.8, below 1 up to 60 deg slopes. The
    chord's direction lags the tangent by baseline / (2 bend radius) in a bend; a section tilted
    that little moves its centroid by much less than a step (0.07 mm on the shipped bent tube).
    """
    best = _section(mesh, start, T, start)
    if best is None:
        raise MandrelError(f"{name}: no cross-section near the tip: cannot derive a centerline")
    pts = [best[1]]
    pers = [best[3]]
    for _ in range(max_steps):
        predicted = pts[-1] + h * T
        best = _section(mesh, predicted, T, predicted)
        if best is None or best[0] > 2.0 * h + 0.5 * np.sqrt(best[2]):
            break                                   # past the far end
        c = best[1]
        k = max(1, int(np.ceil(np.sqrt(best[2]) / h)))
        chord = c - pts[max(0, len(pts) - k)]
        if np.linalg.norm(c - pts[-1]) < 1e-12 or np.linalg.norm(chord) < 1e-12:
            break
        new_T = chord / np.linalg.norm(chord)
        if new_T @ T < 0.5:
            break                                   # turned back: the far end cap
        T = new_T
        pts.append(c)
        pers.append(best[3])
    if len(pts) < 2:
        raise MandrelError(f"{name}: the centerline trace found fewer than two sections")
    return np.array(pts), np.array(pers)


def _extend_ends(V, pts, pers, h):
    """Extend the trace to the mesh's extremes along the end tangents (caps and tips)."""
    t0 = pts[1] - pts[0]
    t0 /= np.linalg.norm(t0)
    t1 = pts[-1] - pts[-2]
    t1 /= np.linalg.norm(t1)
    near0 = np.linalg.norm(V - pts[0], axis=1) < 4 * h + np.sqrt(max(pers[0], 1e-12))
    near1 = np.linalg.norm(V - pts[-1], axis=1) < 4 * h + np.sqrt(max(pers[-1], 1e-12))
    back = max(0.0, float(-((V[near0] - pts[0]) @ t0).min())) if np.any(near0) else 0.0
    ahead = max(0.0, float(((V[near1] - pts[-1]) @ t1).max())) if np.any(near1) else 0.0
    pts = np.vstack([pts[0] - back * t0, pts, pts[-1] + ahead * t1])
    pers = np.array([pers[0], *pers, pers[-1]])
    return pts, pers
