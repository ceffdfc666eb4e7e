"""Mesh kernels against slow, obvious NumPy references (``support.naive_intake`` and forms
written here), bit for bit: long-side faces, triangle moments, the undirected edge table, the face
across each directed edge, first faces of each vertex set, the winding of each body; and the paths
that skip work
(the field mesh's weld of an already welded mandrel, the mandrel's ray scene reused)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from preform._kernels.edges import (INSERTION_MAX, directed_neighbors, edge_table, first_of_each_face,
                                    orient_bodies)
from preform._kernels.mesh import long_side_faces, triangle_moments
from support import naive_intake



def meshes():
    """A sliver cylinder, a jittered sphere with some faces flipped, random triangles (repeated
    vertices, duplicate faces, non-manifold edges), and a fan (one vertex on 100 edges, above
    INSERTION_MAX)."""
    rng = np.random.default_rng(7)
    yield trimesh.creation.cylinder(radius=0.04, height=1.6, sections=64)
    s = trimesh.creation.icosphere(subdivisions=3)
    F = s.faces.copy()
    flip = rng.random(len(F)) < 0.3
    F[flip] = F[flip, ::-1]
    yield trimesh.Trimesh(s.vertices + rng.normal(scale=0.01, size=s.vertices.shape), F, process=False)
    V = rng.normal(size=(40, 3))
    F = rng.integers(0, 40, size=(300, 3))
    F = np.vstack([F, F[:20, ::-1], F[20:30]])
    yield trimesh.Trimesh(np.vstack([V, [[9.0, 9.0, 9.0]]]), F, process=False)
    fan = trimesh.creation.cone(radius=1.0, height=1.0, sections=100)
    assert np.bincount(fan.faces.reshape(-1)).max() > INSERTION_MAX
    yield fan


def arrays(m):
    return np.asarray(m.vertices, dtype=np.float64), np.ascontiguousarray(m.faces, dtype=np.int64)


def test_long_side_faces_is_the_numpy_mask():
    for m in meshes():
        V, F = arrays(m)
        tri = V[F]
        sides = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
        for h in (0.5 * sides.max(), np.median(sides), np.nextafter(sides.max(), 0), sides.max()):
            got = np.empty(len(F), dtype=bool)
            long_side_faces(V, F, h, got)
            np.testing.assert_array_equal(got, (sides > h).any(axis=1))


def test_triangle_moments_are_the_numpy_form_bit_for_bit():
    rng = np.random.default_rng(3)
    cases = [arrays(m) for m in meshes()]
    cases.append((rng.normal(size=(5000, 3)) * 0.3 + 1.0, rng.integers(0, 5000, size=(20000, 3))))
    for V, F in cases:
        area, centroid, second = (np.empty(len(F)), np.empty((len(F), 3)), np.empty((len(F), 3, 3)))
        triangle_moments(V, F, area, centroid, second)
        p = V[F]
        ref_area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        s = p.sum(axis=1)
        ref = (np.einsum("fki,fkj->fij", p, p) + np.einsum("fi,fj->fij", s, s)) * (ref_area / 12.0)[:, None, None]
        np.testing.assert_array_equal(area, ref_area)
        np.testing.assert_array_equal(centroid, s / 3.0)
        np.testing.assert_array_equal(second, ref)


def test_surface_moments_of_the_masked_faces_are_the_full_arrays_rows():
    from preform.geometry.centerline import surface_moments

    V, F = arrays(trimesh.creation.icosphere(subdivisions=3))
    area, centroid, second = surface_moments(V, F)
    which = lambda c: c[:, 2] > 0.2                                  # noqa: E731
    a, c, s = surface_moments(V, F, which=which)
    keep = which(centroid)
    np.testing.assert_array_equal(a, area[keep])
    np.testing.assert_array_equal(c, centroid[keep])
    np.testing.assert_array_equal(s, second[keep])


def test_edge_table_is_numpy_unique_of_the_edge_keys():
    for m in meshes():
        V, F = arrays(m)
        for n in (int(F.max()) + 1, len(V) + 5):
            side = np.empty(3 * len(F), dtype=np.int64)
            order = np.empty(3 * len(F), dtype=np.int64)
            key, count = edge_table(F, n, side, order)
            ref_key, ref_count, ref_inverse, ref_order = naive_intake.edge_table(F, n)
            np.testing.assert_array_equal(key, ref_key)
            np.testing.assert_array_equal(count, ref_count)
            np.testing.assert_array_equal(side, ref_inverse)
            np.testing.assert_array_equal(order, ref_order)


def test_face_neighbors_equal_the_sort_based_form():
    from preform.geometry.mandrel import face_neighbors

    for m in meshes():
        _, F = arrays(m)
        collapsed = np.vstack([F, [[F[0, 0], F[0, 0], F[0, 1]]]])      # a repeated vertex too
        for faces in (F, collapsed):
            np.testing.assert_array_equal(face_neighbors(faces), naive_intake.face_neighbors(faces))
            side = np.empty(3 * len(faces), dtype=np.int64)
            order = np.empty(3 * len(faces), dtype=np.int64)
            _, count = edge_table(faces, int(faces.max()) + 1, side, order)
            out = np.empty(3 * len(faces), dtype=np.int64)
            directed_neighbors(faces, order, count, out)
            np.testing.assert_array_equal(out.reshape(-1, 3), naive_intake.face_neighbors(faces))


def test_first_of_each_face_is_numpy_unique_return_index():
    for m in meshes():
        _, F = arrays(m)
        keep = np.empty(len(F), dtype=bool)
        first_of_each_face(F, keep)
        _, first = np.unique(np.sort(F, axis=1), axis=0, return_index=True)
        np.testing.assert_array_equal(np.nonzero(keep)[0], np.sort(first))


def two_face_pairs(F):
    side = np.empty(3 * len(F), dtype=np.int64)
    order = np.empty(3 * len(F), dtype=np.int64)
    _, count = edge_table(F, int(F.max()) + 1, side, order)
    starts = np.concatenate([[0], np.cumsum(count)[:-1]])
    two = np.nonzero(count == 2)[0]
    return np.ascontiguousarray(np.stack([order[starts[two]], order[starts[two] + 1]], axis=1))


def moebius():
    """A triangulated Moebius strip: a one-sided surface."""
    n = 24
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = []
    for s in (-0.2, 0.2):
        V.append(np.column_stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t),
                                  s * np.sin(t / 2)]))
    V = np.vstack(V)
    F = []
    for i in range(n):
        j = (i + 1) % n
        a, b = i, n + i
        c, d = (j, n + j) if j else (n + j, j)            # the half twist joins the sides crosswise
        F += [(a, c, b), (b, c, d)]
    return V, np.array(F, dtype=np.int64)


@pytest.mark.parametrize("seed", range(6))
def test_orient_bodies_is_the_double_cover_components(seed):
    rng = np.random.default_rng(seed)
    parts = []
    offset = 0
    for m in list(meshes())[:2] + [trimesh.creation.box(), trimesh.creation.icosphere(subdivisions=1)]:
        V, F = arrays(m)
        F = F.copy()
        flip = rng.random(len(F)) < 0.4
        F[flip] = F[flip, ::-1]
        parts.append(F + offset)
        offset += len(V)
    if seed % 2:
        V, F = moebius()
        parts.append(F + offset)
    F = np.vstack(parts)
    F = F[rng.permutation(len(F))]                 # bodies interleaved in the face order
    pairs = two_face_pairs(F)
    flipped = np.empty(len(F), dtype=bool)
    component = np.empty(len(F), dtype=np.int64)
    bad = orient_bodies(F, pairs, flipped, component)
    ref_flipped, ref_component, ref_bad = naive_intake.orient_bodies(F, pairs)
    assert bad == ref_bad
    assert (bad >= 0) == bool(seed % 2)
    np.testing.assert_array_equal(component, ref_component)
    if bad < 0:   # the flips of a one-sided body are not defined
        np.testing.assert_array_equal(flipped, ref_flipped)


def test_field_mesh_weld_returns_welded_arrays_as_they_are():
    from preform.analysis.fields import _merge_exact_duplicates

    V, F = arrays(trimesh.creation.icosphere(subdivisions=2))
    U, G = _merge_exact_duplicates(V, F)
    assert U is V and G is F
    soup_V = V[F.reshape(-1)]
    soup_F = np.arange(3 * len(F)).reshape(-1, 3)
    U, G = _merge_exact_duplicates(soup_V, soup_F)
    ref, inverse = np.unique(soup_V, axis=0, return_inverse=True)
    np.testing.assert_array_equal(U, ref)
    np.testing.assert_array_equal(G, inverse.reshape(-1)[soup_F])


def test_locate_faces_on_a_given_mesh_is_the_same_as_on_a_new_one():
    from preform.geometry.remesh import locate_faces

    m = trimesh.creation.icosphere(subdivisions=3)
    V, F = arrays(m)
    rng = np.random.default_rng(1)
    p = rng.normal(size=(500, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    mesh = trimesh.Trimesh(V, F, process=False)
    np.testing.assert_array_equal(locate_faces(V, F, p, p, 0.05, mesh=mesh), locate_faces(V, F, p, p, 0.05))


def test_row_ids_are_numpy_unique_rows_inverse():
    from preform.geometry.centerline import _row_ids

    rng = np.random.default_rng(5)
    for span in (3, 1000, 10**6 + 1, 2**40):          # the last does not fit: the row-wise unique
        keys = rng.integers(-span // 2, span // 2 + 1, size=(2000, 3))
        keys[1000:1500] = keys[:500]                   # repeated rows
        ref = np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1)
        np.testing.assert_array_equal(_row_ids(keys), ref)


def test_vertex_bounds_are_numpy_min_and_max():
    from preform._kernels.mesh import vertex_bounds

    for m in meshes():
        V, F = arrays(m)
        for faces, used in ((np.zeros((0, 3), dtype=np.int64), V), (F[::3].copy(), V[np.unique(F[::3])])):
            lo, hi = np.empty(3), np.empty(3)
            vertex_bounds(V, faces, lo, hi)
            np.testing.assert_array_equal(lo, used.min(axis=0))
            np.testing.assert_array_equal(hi, used.max(axis=0))


def test_face_cross_normals_are_the_numpy_form():
    from preform._kernels.mesh import face_cross_normals

    for m in meshes():
        V, F = arrays(m)
        F = np.vstack([F, [[F[0, 0], F[0, 0], F[0, 1]]]])             # a zero-area face
        cross, normals = np.empty((len(F), 3)), np.empty((len(F), 3))
        face_cross_normals(V, F, cross, normals)
        ref_cross, ref_normals = naive_intake.face_cross_normals(V, F)
        np.testing.assert_array_equal(cross, ref_cross)
        np.testing.assert_array_equal(normals, ref_normals)


def test_edge_ray_geometry_is_the_numpy_form():
    from preform._kernels.mesh import edge_ray_geometry

    for m in meshes():
        V, F = arrays(m)
        e = np.unique(np.sort(np.vstack([F[:, :2], F[:, 1:], [[0, 0]]]), axis=1), axis=0)  # one of length 0
        k = len(e)
        ok = np.empty(k, dtype=bool)
        a, u, origin = np.empty((k, 3)), np.empty((k, 3)), np.empty((k, 3))
        length, eps = np.empty(k), np.empty(k)
        n = edge_ray_geometry(V, e, ok, a, u, length, eps, origin)
        keep, ra, ru, L, reps, rorigin = naive_intake.edge_ray_geometry(V, e)
        assert not keep.all() and n == keep.sum()
        np.testing.assert_array_equal(ok, keep)
        np.testing.assert_array_equal(a[:n], ra)
        np.testing.assert_array_equal(u[:n], ru)
        np.testing.assert_array_equal(length[:n], L)
        np.testing.assert_array_equal(eps[:n], reps)
        np.testing.assert_array_equal(origin[:n], rorigin)


@pytest.mark.parametrize("seed", range(4))
def test_merge_clusters_are_the_components_form(seed):
    from preform._kernels.edges import merge_clusters

    rng = np.random.default_rng(seed)
    n_exact = 300
    inverse = rng.integers(0, n_exact, size=900)
    inverse[:n_exact] = rng.permutation(n_exact)          # every exact vertex used
    pairs = rng.integers(0, n_exact, size=(40 * seed, 2)).reshape(-1, 2)
    survivors, new_index = np.empty(900, dtype=np.int64), np.empty(900, dtype=np.int64)
    n = merge_clusters(inverse, pairs, n_exact, survivors, new_index)
    # the NumPy form of geometry.repair._merge_vertices
    keeper, ref_index = naive_intake.merge_clusters(inverse, pairs, n_exact)
    assert n == len(keeper)
    np.testing.assert_array_equal(survivors[:n], keeper)
    np.testing.assert_array_equal(new_index, ref_index)


def test_near_pairs_are_the_kd_tree_pairs():
    """The grid shortcut gives the tree's pairs: none when the points are apart, and the tree's
    own where some lie within or near the radius (clusters at 0.5, 1 and 1.5 radii)."""
    from scipy.spatial import cKDTree

    from preform._kernels.mesh import grid_neighbours_exist
    from preform.geometry.repair import _near_pairs

    rng = np.random.default_rng(11)
    base = rng.uniform(-1, 1, size=(3000, 3)) * 1e3 + 5e3
    r = 1e-6
    assert not grid_neighbours_exist(base, 2 * r)
    assert len(_near_pairs(base, r)) == 0 and len(cKDTree(base).query_pairs(r)) == 0
    for gap in (0.5, 1.0, 1.5, 2.5):
        step = rng.normal(size=(50, 3))
        near = base[:50] + gap * r * step / np.linalg.norm(step, axis=1)[:, None]
        P = np.vstack([base, near])
        got = np.sort(_near_pairs(P, r), axis=0)
        ref = np.sort(cKDTree(P).query_pairs(r, output_type="ndarray"), axis=0)
        np.testing.assert_array_equal(got.reshape(-1, 2), ref.reshape(-1, 2))
        if gap <= 1.5:
            assert grid_neighbours_exist(P, 2 * r)


def test_binary_stl_corners_are_the_records_as_float64(tmp_path):
    from preform.geometry.mandrel import _STL_RECORD, read_stl

    m = trimesh.creation.icosphere(subdivisions=2)
    m.vertices = m.vertices * 0.1 + 0.3                  # values that are not float32-exact
    path = tmp_path / "s.stl"
    m.export(path)
    V, F = read_stl(path)
    rec = np.frombuffer(path.read_bytes()[84:], dtype=_STL_RECORD)
    ref = rec["corners"].reshape(-1, 3).astype(np.float64)
    assert V.dtype == np.float64 and V.flags.c_contiguous
    np.testing.assert_array_equal(V, ref)
    np.testing.assert_array_equal(F, np.arange(len(ref)).reshape(-1, 3))
