"""repair_mesh on damaged trimesh.creation meshes.

The repaired meshes are judged by trimesh (``is_watertight``, ``is_winding_consistent``,
``volume``), which shares no code with ``preform.geometry.repair``.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from preform.errors import MandrelError
from preform.geometry.repair import INTAKE, RepairReport, repair_mesh, self_intersections
from preform.tolerances import tol

# Volumes of meshes made of the very same vertices and faces agree to round-off; 1e-9 leaves room
# for summing a few hundred triple products in another order (trimesh vs the original).
SAME = 1e-9


def _mesh(kind):
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=0.05, height=0.3, sections=24)
    if kind == "icosphere":
        return trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    return trimesh.creation.box(extents=(0.1, 0.2, 0.4))


@pytest.fixture(scope="module", params=["cylinder", "icosphere", "box"])
def mesh(request):
    return _mesh(request.param)


@pytest.fixture(scope="module")
def sphere():
    return _mesh("icosphere")


def _soup(v, f):
    """An STL as read: 3 vertices per triangle, arange faces."""
    return v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3)


def _assert_closed_outward(v, f, volume, rel=SAME):
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0                       # outward: positive signed volume
    assert m.volume == pytest.approx(volume, rel=rel)


def test_clean_mesh_is_returned_unchanged(mesh):
    v, f, report = repair_mesh(mesh.vertices, mesh.faces)
    assert isinstance(report, RepairReport) and not report.changed and report.messages == ()
    np.testing.assert_array_equal(v, mesh.vertices)
    np.testing.assert_array_equal(f, mesh.faces)
    assert v.dtype == np.float64 and f.dtype == np.int64


def test_inputs_are_not_modified(sphere):
    v = sphere.vertices.copy()
    f = sphere.faces.copy()
    f[::3] = f[::3, ::-1]
    v_in, f_in = v.copy(), f.copy()
    repair_mesh(v, f)
    np.testing.assert_array_equal(v, v_in)
    np.testing.assert_array_equal(f, f_in)


def test_stl_soup_is_welded_to_the_original_vertices(mesh):
    v, f, report = repair_mesh(*_soup(mesh.vertices, mesh.faces))
    assert len(v) == len(mesh.vertices) and len(f) == len(mesh.faces)
    assert not report.changed                 # every STL is a soup: welding it is no repair
    _assert_closed_outward(v, f, mesh.volume)


def test_near_duplicates_are_merged_and_said(sphere):
    v, f = _soup(sphere.vertices, sphere.faces)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    rng = np.random.default_rng(1)
    # each copy moves at most 0.45 merge radii, so copies of a corner stay within one radius
    step = rng.normal(size=v.shape)
    v = v + 0.45 * tol.merge_vertices * diag * step / np.linalg.norm(step, axis=1)[:, None]
    v2, f2, report = repair_mesh(v, f)
    assert len(v2) == len(sphere.vertices)
    n_near = len(np.unique(v, axis=0)) - len(sphere.vertices)
    assert report.merged_vertices == n_near
    assert f"merged {n_near:,} duplicate vertices" in report.messages
    _assert_closed_outward(v2, f2, sphere.volume, rel=1e-6)


def test_duplicate_vertices_of_an_indexed_mesh(sphere):
    n = len(sphere.vertices)
    v = np.vstack([sphere.vertices, sphere.vertices[:12]])
    f = sphere.faces.copy()
    f[1::2] = np.where(f[1::2] < 12, f[1::2] + n, f[1::2])     # odd faces use the copies
    v2, f2, report = repair_mesh(v, f)
    copies = np.unique(f[f >= n])
    both_used = np.isin(copies - n, f).sum()          # copies whose original is used too
    assert both_used > 0
    assert report.merged_vertices == both_used
    assert report.messages == (f"merged {both_used} duplicate vertices",)
    _assert_closed_outward(v2, f2, sphere.volume)


def test_some_faces_flipped_become_consistent_and_outward(mesh):
    rng = np.random.default_rng(2)
    pick = rng.random(len(mesh.faces)) < 0.3
    pick[0] = True
    f = mesh.faces.copy()
    f[pick] = f[pick][:, ::-1]
    v2, f2, report = repair_mesh(mesh.vertices, f)
    assert report.flipped_faces == pick.sum()
    assert f"flipped {pick.sum():,} faces to consistent outward winding" in report.messages
    np.testing.assert_array_equal(f2, mesh.faces)   # the original winding, face for face
    _assert_closed_outward(v2, f2, mesh.volume)


def test_mostly_flipped_faces_still_end_outward(sphere):
    f = sphere.faces[:, ::-1].copy()
    f[:10] = sphere.faces[:10]                  # 10 right, the rest inward
    v2, f2, report = repair_mesh(sphere.vertices, f)
    assert report.flipped_faces == len(f) - 10
    np.testing.assert_array_equal(f2, sphere.faces)


def test_all_faces_inward_are_turned_outward(mesh):
    v2, f2, report = repair_mesh(mesh.vertices, mesh.faces[:, ::-1])
    assert report.flipped_faces == len(mesh.faces)
    assert "outwards" in report.messages[-1]
    _assert_closed_outward(v2, f2, mesh.volume)


def test_duplicated_faces_are_removed(mesh):
    f = np.vstack([mesh.faces, mesh.faces[:5], mesh.faces[5:8, ::-1]])   # either winding
    v2, f2, report = repair_mesh(mesh.vertices, f)
    assert report.duplicate_faces == 8 and "dropped 8 duplicated faces" in report.messages
    assert len(f2) == len(mesh.faces)
    _assert_closed_outward(v2, f2, mesh.volume)


def test_collapsed_faces_are_dropped(mesh):
    f = np.vstack([mesh.faces, [[0, 0, 1], [2, 2, 2], [3, 4, 3]]])
    v2, f2, report = repair_mesh(mesh.vertices, f)
    assert report.degenerate_faces == 3 and "dropped 3 degenerate faces" in report.messages
    _assert_closed_outward(v2, f2, mesh.volume)


def test_zero_area_cap_is_dropped_and_its_neighbour_split(sphere):
    # insert the midpoint c of an edge a-b as a cap (a, b, c) and split the face on one side at c:
    # the other side's face then spans a-b while the split faces meet c (a T-junction) and the cap
    # (zero area) closes the crack. Repair must drop the cap without leaving a hole.
    v = np.vstack([sphere.vertices, sphere.vertices[sphere.faces[0, :2]].mean(axis=0)])
    c = len(v) - 1
    a, b, r = sphere.faces[0]
    f = np.vstack([sphere.faces[1:], [[a, c, r], [c, b, r], [a, c, b]]])   # cap wound like face 0
    v2, f2, report = repair_mesh(v, f)
    assert report.degenerate_faces == 1
    m = trimesh.Trimesh(v2, f2, process=False)
    assert np.all(m.area_faces > 1e-6 * m.area)                 # no sliver left
    _assert_closed_outward(v2, f2, sphere.volume)


def test_a_small_hole_is_filled(mesh):
    # two neighbouring faces; on the box one triangle of its smallest side (a triangle of a larger
    # side covers more than INTAKE.max_fill_share of the surface)
    gone = mesh.face_adjacency[0] if len(mesh.faces) > 12 else [np.argmin(mesh.area_faces)]
    f = np.delete(mesh.faces, gone, axis=0)
    v2, f2, report = repair_mesh(mesh.vertices, f)
    assert report.holes_filled == 1 and "filled 1 small hole" in report.messages[-1]
    assert "mm across" in report.messages[-1]
    _assert_closed_outward(v2, f2, mesh.volume, rel=0.01)   # the brief's 1 %


def test_two_small_holes_on_the_sphere_are_filled_with_the_removed_volume(sphere):
    # one face removed: the ear clipping puts the same triangle back, so the volume is exact
    f = np.delete(sphere.faces, [0, 200], axis=0)
    v2, f2, report = repair_mesh(sphere.vertices, f)
    assert report.holes_filled == 2 and "filled 2 small holes" in report.messages[-1]
    _assert_closed_outward(v2, f2, sphere.volume)


def test_a_hole_of_a_few_faces_is_filled_within_one_percent():
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.1)   # hole 9 mm, limit 17 mm
    around = np.nonzero(np.any(sphere.faces == 0, axis=1))[0]          # the fan around vertex 0
    f = np.delete(sphere.faces, around, axis=0)
    v2, f2, report = repair_mesh(sphere.vertices, f)
    assert report.holes_filled == 1 and len(around) == 5
    _assert_closed_outward(v2, f2, sphere.volume, rel=0.01)
    assert len(v2) == len(sphere.vertices) - 1                         # vertex 0 left unused


def test_one_long_missing_triangle_of_a_coarse_mesh_is_filled():
    # a CAD cylinder's side triangles run its whole length: far above INTAKE.small_hole of the diagonal
    mesh = _mesh("cylinder")
    side = np.nonzero(np.abs(mesh.face_normals[:, 2]) < 0.5)[0]
    gone = side[np.argmin(mesh.area_faces[side])]
    f = np.delete(mesh.faces, gone, axis=0)
    v2, f2, report = repair_mesh(mesh.vertices, f)
    assert report.largest_hole > INTAKE.small_hole * np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    _assert_closed_outward(v2, f2, mesh.volume)     # the same triangle is put back: exact


def test_a_missing_large_triangle_is_refused():
    box = _mesh("box")                            # one triangle is 14 % of the surface
    f = np.delete(box.faces, np.argmax(box.area_faces), axis=0)
    with pytest.raises(MandrelError, match="open surface.*447 mm across"):   # hypot(200, 400) mm
        repair_mesh(box.vertices, f)


def test_a_large_hole_is_refused_with_its_size(mesh):
    m = mesh
    top = m.face_normals[:, 2] > 0.5
    f = m.faces[~top]
    with pytest.raises(MandrelError, match=r"^part\.stl: .*open surface: .*mm across") as exc:
        repair_mesh(m.vertices, f, source="part.stl")
    assert "CAD" in str(exc.value)
    assert len(mesh.faces[top]) > 0


def test_large_hole_threshold_is_the_small_hole_fraction(sphere):
    # a hole just above INTAKE.small_hole of the diagonal is refused, the span quoted in mm
    centre = sphere.vertices[0]
    d = np.linalg.norm(sphere.vertices[sphere.faces].mean(axis=1) - centre, axis=1)
    diag = np.linalg.norm(np.ptp(sphere.vertices, axis=0))
    f = sphere.faces[d > INTAKE.small_hole * diag]
    with pytest.raises(MandrelError, match="open surface"):
        repair_mesh(sphere.vertices, f)


def test_two_bodies_are_refused_unless_one_is_chosen(sphere):
    v = np.vstack([sphere.vertices, sphere.vertices * 0.5 + [1.0, 0.0, 0.0]])
    f = np.vstack([sphere.faces + len(sphere.vertices), sphere.faces])   # the small one first
    with pytest.raises(MandrelError, match=r'two\.stl: 2 disjoint bodies \(0: 200 x 200 x 200 mm.*'
                                           r'1: 100 x 100 x 100 mm.*\[mandrel\] body = "largest"'):
        repair_mesh(v, f, source="two.stl")
    v2, f2, report = repair_mesh(v, f, body="largest")
    assert report.bodies == 2 and "largest of 2 bodies" in report.messages[-1]
    _assert_closed_outward(v2, f2, sphere.volume)
    v3, f3, _ = repair_mesh(v, f, body=1)
    _assert_closed_outward(v3, f3, sphere.volume / 8)
    with pytest.raises(MandrelError, match=r"\[mandrel\] body = 2 does not choose"):
        repair_mesh(v, f, body=2)


def test_unconnected_triangles_are_refused(sphere):
    v, f = _soup(sphere.vertices, sphere.faces)
    v = v + np.random.default_rng(4).normal(scale=1e-6, size=v.shape)    # 1e-6 m >> 3.5e-10 m radius
    for body in (None, "largest"):
        with pytest.raises(MandrelError, match="960 of 960 triangle edges have no neighbouring triangle"):
            repair_mesh(v, f, body=body)


def test_non_manifold_edge_is_refused(sphere):
    v = np.vstack([sphere.vertices, [[0.5, 0.5, 0.5]]])
    a, b = sphere.faces[0, :2]
    f = np.vstack([sphere.faces, [[a, b, len(v) - 1]]])          # a fin on edge a-b
    with pytest.raises(MandrelError, match="1 non-manifold edges.*more than two triangles") as exc:
        repair_mesh(v, f, source="fin.stl", unit_scale=1e-3)
    assert str(exc.value).startswith("fin.stl: ") and " mm" in str(exc.value)   # location in file unit


def test_self_intersection_is_refused(sphere):
    v = sphere.vertices.copy()
    v[v[:, 0] > 0.09, 0] -= 0.25                 # a cap pushed through the opposite wall
    assert len(self_intersections(v, sphere.faces)) > 0
    with pytest.raises(MandrelError, match="intersects itself"):
        repair_mesh(v, sphere.faces)


def test_self_intersection_check_is_quiet_far_from_the_origin(sphere):
    v = sphere.vertices + [1e3, -2e3, 5e2]       # embree works in float32: centred first
    assert len(self_intersections(v, sphere.faces)) == 0


@pytest.mark.parametrize("vertices, faces, words", [
    (np.zeros((3, 2)), [[0, 1, 2]], "expected a triangle mesh"),
    (np.zeros((3, 3)), np.zeros((0, 3), int), "expected a triangle mesh"),
    (np.eye(3), [[0, 1, 3]], "face indices run from 0 to 3 but there are 3 vertices"),
    (np.eye(3), [[0.0, 1.0, 2.0]], "not integers"),
    (np.array([[np.nan, 0, 0], [0, 1, 0], [0, 0, 1]]), [[0, 1, 2]], "not finite"),
    (np.eye(3), [[0, 0, 1]], "no usable triangles"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.25, 0.25, 0]],                # a flat tetrahedron
     [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], "encloses no volume"),
])
def test_bad_arrays_are_refused_with_a_message(vertices, faces, words):
    with pytest.raises(MandrelError, match=words):
        repair_mesh(vertices, np.asarray(faces), source="x.stl")


def test_large_mesh_is_repaired_in_a_few_seconds():
    import time

    m = trimesh.creation.icosphere(subdivisions=6)          # 81,920 faces
    f = m.faces.copy()
    f[::5] = f[::5, ::-1]
    v, f = _soup(m.vertices, f)
    start = time.perf_counter()
    v2, f2, report = repair_mesh(v, f)
    elapsed = time.perf_counter() - start
    assert report.flipped_faces == len(m.faces[::5])
    assert elapsed < 3.0, elapsed    # brief: ~200k faces in a few seconds; this is 82k on 2 cores


_DAMAGE = dict(
    kind=st.sampled_from(["cylinder", "icosphere", "box"]),
    seed=st.integers(0, 2**32 - 1),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
    shift=st.floats(-10, 10),
    flip=st.floats(0, 1),
    dup=st.floats(0, 0.3),
    soup=st.booleans(),
    jitter=st.booleans(),
)


@settings(max_examples=40, deadline=None)
@given(**_DAMAGE)
def test_random_damage_is_repaired_or_refused(kind, seed, scale, shift, flip, dup, soup, jitter):
    base = _mesh(kind)
    rng = np.random.default_rng(seed)
    rotation = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]
    size = scale * np.linalg.norm(np.ptp(base.vertices, axis=0))
    v = base.vertices @ rotation.T * scale + shift * size
    f = base.faces.copy()
    pick = rng.random(len(f)) < flip
    f[pick] = f[pick][:, ::-1]
    f = np.vstack([f, f[rng.random(len(f)) < dup][:, ::rng.choice([1, -1])]])
    f = f[rng.permutation(len(f))]
    if soup:
        v, f = _soup(v, f)
    if jitter:   # each corner copy moves at most 0.45 merge radii (1e-9 of the diagonal)
        step = rng.normal(size=v.shape)
        v = v + 0.45 * tol.merge_vertices * size * step / np.linalg.norm(step, axis=1)[:, None]
    try:
        v2, f2, report = repair_mesh(v, f)
    except MandrelError as exc:              # allowed, but then with a message; never another error
        assert str(exc)
        return
    # jitter of 1e-9 of the size moves the volume by ~1e-9 relative: 1e-6 is the brief's bound
    _assert_closed_outward(v2, f2, base.volume * scale**3, rel=1e-6)
    assert report.holes_filled == 0 and len(f2) == len(base.faces)


def _pierced(seed):
    """Icosphere with a cap pushed through the opposite wall, shifted and turned at random."""
    rng = np.random.default_rng(seed)
    s = _mesh("icosphere")
    v = s.vertices.copy()
    v[v[:, 0] > rng.uniform(0.06, 0.095), 0] -= rng.uniform(0.18, 0.3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return v @ q + rng.normal(scale=0.5, size=3), s.faces


@pytest.mark.parametrize("seed", range(4))
def test_self_intersection_kernels_find_the_edges_of_the_numpy_reference(seed):
    """The edge-ray kernels flag the same edges as the whole-array NumPy reference on pierced
    spheres, and none on clean meshes (the reference also none)."""
    from support import naive_repair

    v, f = _pierced(seed)
    got = self_intersections(v, f)
    ref = naive_repair.self_intersections(v, f)
    assert len(ref) > 0
    np.testing.assert_array_equal(np.unique(got, axis=0), np.unique(ref, axis=0))
    for kind in ("cylinder", "icosphere", "box"):
        m = _mesh(kind)
        assert len(self_intersections(m.vertices, m.faces)) == 0
        assert len(naive_repair.self_intersections(m.vertices, m.faces)) == 0


def test_exact_weld_kernel_matches_numpy_unique():
    """weld_exact: the distinct rows (first appearances) and the inverse of np.unique(axis=0),
    -0.0 and 0.0 one value; on a soup with repeated corners and signed zeros."""
    from preform._kernels.mesh import weld_exact

    rng = np.random.default_rng(5)
    base = np.round(rng.normal(size=(400, 3)), 2)
    base[:40, 0] = 0.0
    V = base[rng.integers(0, len(base), 5000)].copy()
    V[rng.random(len(V)) < 0.2, 0] *= -1.0                  # some 0.0 become -0.0
    inverse = np.empty(len(V), dtype=np.int64)
    first = weld_exact(V, inverse)
    np.testing.assert_array_equal(V[first][inverse], V)      # every row maps to an equal row
    ref_rows, ref_first = np.unique(V + 0.0, axis=0, return_index=True)
    assert len(first) == len(ref_rows)                       # as many distinct rows as NumPy's
    np.testing.assert_array_equal(np.sort(first), np.sort(ref_first))


def test_degenerate_face_kernel_matches_numpy():
    """degenerate_faces against the NumPy form in _drop_degenerate's docstring
    (``support.naive_intake.degenerate_faces``), on random faces with repeated vertices, near-caps and
    equal sides."""
    from preform._kernels.mesh import degenerate_faces
    from support import naive_intake

    rng = np.random.default_rng(11)
    V = rng.normal(size=(300, 3))
    V[200:] = V[:100] * 0.5 + V[100:200] * 0.5 + rng.normal(scale=1e-10, size=(100, 3))  # near midpoints
    F = rng.integers(0, 300, size=(4000, 3))
    F[:100] = np.stack([np.arange(100), np.arange(100, 200), np.arange(200, 300)], axis=1)  # caps
    F[100:150, 1] = F[100:150, 0]                                                          # collapsed
    radius = 1e-8
    collapsed, caps, longest = (np.empty(len(F), bool), np.empty(len(F), bool), np.empty(len(F), np.int64))
    degenerate_faces(V, F, radius, collapsed, caps, longest)
    ref_collapsed, ref_caps, ref_longest = naive_intake.degenerate_faces(V, F, radius)
    np.testing.assert_array_equal(collapsed, ref_collapsed)
    np.testing.assert_array_equal(caps, ref_caps)
    np.testing.assert_array_equal(longest, ref_longest)
    assert caps[:100].sum() > 50
