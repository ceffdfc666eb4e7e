"""The mesh intake's kernels on the meshes the intake meets (clean, soups, damaged, refused):
every kernel ``geometry.repair`` and ``geometry.mandrel`` call against its slow NumPy reference
(``support.naive_intake``), bit for bit, on the arrays of each case; the repair's outcome (a
report or the refusal that names the fault); and the centerline-inside check on case A."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from preform._kernels import edges as EK
from preform._kernels import mesh as MK
from preform.errors import MandrelError
from preform.geometry.mandrel import read_stl
from preform.geometry.repair import repair_mesh
from preform.tolerances import tol
from support import naive_intake as naive

ROOT = Path(__file__).resolve().parents[2]


def _soup(v, f):
    return v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3)


def _sphere():
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    return np.asarray(s.vertices), np.asarray(s.faces)


def _sliver():
    m = trimesh.creation.cylinder(radius=0.04, height=1.6, sections=256)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _moebius():
    n = 24
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.vstack([np.column_stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t),
                                    s * np.sin(t / 2)]) for s in (-0.2, 0.2)])
    F = []
    for i in range(n):
        j = (i + 1) % n
        c, d = (j, n + j) if j else (n + j, j)            # the half twist joins the sides crosswise
        F += [(i, c, n + i), (n + i, c, d)]
    return V, np.array(F, dtype=np.int64)


def _damaged(kind, seed):
    """A sphere or the sliver cylinder: some faces flipped, some duplicated (either winding),
    shuffled, as a soup with every corner copy jittered within the merge radius."""
    v, f = _sphere() if kind == "sphere" else _sliver()
    rng = np.random.default_rng(seed)
    f = f.copy()
    pick = rng.random(len(f)) < 0.3
    f[pick] = f[pick, ::-1]
    f = np.vstack([f, f[rng.random(len(f)) < 0.1][:, ::-1], f[:3]])
    f = f[rng.permutation(len(f))]
    v, f = _soup(v, f)
    step = rng.normal(size=v.shape)
    size = np.linalg.norm(np.ptp(v, axis=0))
    return v + 0.45 * tol.merge_vertices * size * step / np.linalg.norm(step, axis=1)[:, None], f


def _cases():
    for stl in sorted((ROOT / "mandrels").glob("*.stl")):
        yield f"shipped {stl.name}", read_stl(stl), {}
    v, f = _sphere()
    n = len(v)
    yield "sliver cylinder", _sliver(), {}
    yield "sliver soup", _soup(*_sliver()), {}
    for seed in range(3):
        yield f"damaged sphere {seed}", _damaged("sphere", seed), {}
        yield f"damaged sliver {seed}", _damaged("sliver", seed), {}
    copies = np.vstack([v, v[:12]])
    g = f.copy()
    g[1::2] = np.where(g[1::2] < 12, g[1::2] + n, g[1::2])
    yield "duplicate vertices", (copies, g), {}
    yield "collapsed faces", (v, np.vstack([f, [[0, 0, 1], [2, 2, 2], [3, 4, 3]]])), {}
    mid = np.vstack([v, v[f[0, :2]].mean(axis=0)])
    a, b, r = f[0]
    yield "cap", (mid, np.vstack([f[1:], [[a, n, r], [n, b, r], [a, n, b]]])), {}
    yield "duplicate faces", (v, np.vstack([f, f[:5], f[5:8, ::-1]])), {}
    yield "all inverted", (v, f[:, ::-1]), {}
    yield "small hole", (v, f[1:]), {}                     # one missing triangle: filled
    two = (np.vstack([v, v * 0.5 + [1.0, 0.0, 0.0]]), np.vstack([f + n, f]))
    yield "two bodies", two, {}
    yield "two bodies, largest", two, {"body": "largest"}
    yield "two bodies, second", two, {"body": 1}
    yield "moebius", _moebius(), {}
    pierced = v.copy()
    pierced[pierced[:, 0] > 0.09, 0] -= 0.25
    yield "self-intersection", (pierced, f), {}
    fin = np.vstack([v, [[0.5, 0.5, 0.5]]])
    yield "non-manifold", (fin, np.vstack([f, [[f[0, 0], f[0, 1], n]]])), {}


CASES = {name: (arrays, kw) for name, arrays, kw in _cases()}



def _welded(v, f):
    """The case's arrays with exact copies welded (as ``repair_mesh`` first does), int64 faces."""
    V = np.ascontiguousarray(v, dtype=np.float64)
    first, inverse = naive.weld_exact(V)
    return np.ascontiguousarray(V[first]), np.ascontiguousarray(inverse[np.asarray(f, dtype=np.int64)])


def _same(got, ref, what):
    got, ref = np.asarray(got), np.asarray(ref)
    assert got.shape == ref.shape and np.array_equal(got, ref), what


@pytest.mark.parametrize("name", CASES)
def test_each_intake_kernel_is_its_numpy_reference(name):
    """vertex_bounds, weld_exact, degenerate_faces, first_of_each_face, edge_table,
    orient_bodies, merge_clusters and the mandrel's arrays (face normals, corner cosines, the
    corners around each vertex, crease-split corner normals, neighbours) on the case's arrays."""
    (v, f), _ = CASES[name]
    V0 = np.ascontiguousarray(v, dtype=np.float64)
    F0 = np.ascontiguousarray(f, dtype=np.int64)
    lo, hi = np.empty(3), np.empty(3)
    MK.vertex_bounds(V0, F0, lo, hi)
    ref_lo, ref_hi = naive.vertex_bounds(V0, F0)
    _same(lo, ref_lo, "vertex_bounds lo")
    _same(hi, ref_hi, "vertex_bounds hi")
    inverse = np.empty(len(V0), dtype=np.int64)
    first = MK.weld_exact(V0, inverse)
    ref_first, ref_inverse = naive.weld_exact(V0)
    _same(first, ref_first, "weld_exact first")
    _same(inverse, ref_inverse, "weld_exact inverse")

    V, F = _welded(v, f)
    m = len(F)
    radius = tol.merge_vertices * float(np.linalg.norm(ref_hi - ref_lo))
    collapsed, caps, longest = np.empty(m, bool), np.empty(m, bool), np.empty(m, np.int64)
    MK.degenerate_faces(V, F, radius, collapsed, caps, longest)
    for got, ref, what in zip((collapsed, caps, longest), naive.degenerate_faces(V, F, radius),
                              ("collapsed", "caps", "longest")):
        _same(got, ref, what)
    keep = np.empty(m, dtype=bool)
    EK.first_of_each_face(F, keep)
    _same(keep, naive.first_of_each_face(F), "first_of_each_face")

    F = F[keep & ~collapsed]
    n = int(F.max()) + 1
    inv, order = np.empty(3 * len(F), np.int64), np.empty(3 * len(F), np.int64)
    key, count = EK.edge_table(F, n, inv, order)
    for got, ref, what in zip((key, count, inv, order), naive.edge_table(F, n), ("key", "count", "inverse", "order")):
        _same(got, ref, what)
    starts = np.concatenate([[0], np.cumsum(count)[:-1]])
    two = np.nonzero(count == 2)[0]
    pairs = np.ascontiguousarray(np.stack([order[starts[two]], order[starts[two] + 1]], axis=1))
    flipped, component = np.empty(len(F), bool), np.empty(len(F), np.int64)
    bad = EK.orient_bodies(F, pairs, flipped, component)
    ref_flipped, ref_component, ref_bad = naive.orient_bodies(F, pairs)
    assert bad == ref_bad
    _same(component, ref_component, "orient_bodies component")
    if bad < 0:      # the flips of a one-sided body are not defined
        _same(flipped, ref_flipped, "orient_bodies flipped")

    # the merge of near vertices: vertices 3 k and 3 k + 1 paired, so clusters of one and two
    n_exact = len(V)
    near = np.ascontiguousarray(np.stack([np.arange(0, n_exact - 1, 3), np.arange(1, n_exact, 3)], axis=1),
                                dtype=np.int64)
    survivors, new_index = np.empty(len(inverse), np.int64), np.empty(len(inverse), np.int64)
    k = EK.merge_clusters(ref_inverse, near, n_exact, survivors, new_index)
    ref_survivors, ref_index = naive.merge_clusters(ref_inverse, near, n_exact)
    _same(survivors[:k], ref_survivors, "merge_clusters survivors")
    _same(new_index, ref_index, "merge_clusters index")

    cross, normals = np.empty((len(F), 3)), np.empty((len(F), 3))
    MK.face_cross_normals(V, F, cross, normals)
    ref_cross, ref_normals = naive.face_cross_normals(V, F)
    _same(cross, ref_cross, "face cross")
    _same(normals, ref_normals, "face normals")
    cosines = np.empty((len(F), 3))
    MK.corner_cosines(V, F, cosines)
    _same(cosines, naive.corner_cosines(V, F), "corner cosines")
    ptr, around, corner = np.empty(len(V) + 1, np.int64), np.empty(3 * len(F), np.int64), np.empty(3 * len(F), np.int64)
    MK.corners_by_vertex(F, len(V), ptr, around, corner)
    for got, ref, what in zip((ptr, around, corner), naive.corners_by_vertex(F, len(V)), ("ptr", "faces", "corner")):
        _same(got, ref, what)
    angles = np.arccos(np.clip(cosines, -1.0, 1.0))
    cos_crease = float(np.cos(np.radians(tol.crease_angle_deg)))
    _same(MK.corner_normals(F, normals, angles, ptr, around, corner, cos_crease),
          naive.corner_normals(F, normals, angles, ptr, around, corner, cos_crease), "corner normals")
    from preform.geometry.mandrel import face_neighbors

    _same(face_neighbors(F), naive.face_neighbors(F), "neighbours")


def _repaired(v, f, **kw):
    try:
        return repair_mesh(v, f, **kw)
    except MandrelError as exc:
        return str(exc)


@pytest.mark.parametrize("name", CASES)
def test_the_intake_repairs_or_refuses_naming_the_fault(name):
    """Meshes with a fault the intake cannot repair are refused with it named; the others
    come back closed and outward (trimesh's own checks, which share no code with the intake)."""
    (v, f), kw = CASES[name]
    out = _repaired(v, f, **kw)
    refused = {"two bodies": "2 disjoint bodies", "moebius": "cannot be oriented",
               "self-intersection": "intersects itself", "non-manifold": "non-manifold"}
    if name in refused:
        assert isinstance(out, str) and refused[name] in out
        return
    assert not isinstance(out, str), out
    mesh = trimesh.Trimesh(out[0], out[1], process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


def test_the_centerline_inside_check_passes_case_a_and_refuses_a_moved_centerline():
    """preflight's winding numbers: case A's centerline runs inside its mandrel; the same
    centerline moved 0.5 m sideways is refused with the place it leaves the mandrel."""
    import dataclasses

    from preform.checks import _check_centerline_inside
    from preform.config import load_config
    from preform.geometry import load_mandrel
    from preform.geometry.centerline import read_centerline_csv

    config = load_config(ROOT / "examples" / "case_a.toml")
    mandrel = load_mandrel(config.mandrel.stl)
    centerline = read_centerline_csv(config.mandrel.centerline)
    _check_centerline_inside(config, mandrel, centerline)
    moved = dataclasses.replace(centerline, points=centerline.points + [0.0, 0.5, 0.0])
    with pytest.raises(Exception, match="leaves the mandrel"):
        _check_centerline_inside(config, mandrel, moved)
