"""The mandrel: intake checks, smooth corner normals, adjacency and queries.

Small meshes from ``preform.geometry.shapes`` with known geometry: a regular 128-gon prism (its
vertices sit at angles 2 pi k / n from +x, so every hit and normal has a closed form), an
icosphere, and a bent rounded-square tube for the kernels.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from preform._kernels.kinematic import smooth_normals_batch
from preform.errors import MandrelError
from preform.geometry import load_mandrel, mandrel_from_arrays, shapes
from preform.geometry.mandrel import face_neighbors
from preform.tolerances import tol

N_AROUND = 128
RADIUS = 0.05
LENGTH = 0.2


@pytest.fixture(scope="module")
def cylinder_arrays():
    return shapes.cylinder(RADIUS, LENGTH, n_around=N_AROUND, n_along=4)


@pytest.fixture(scope="module")
def cylinder(cylinder_arrays):
    return mandrel_from_arrays(*cylinder_arrays)


@pytest.fixture(scope="module")
def bent():
    return mandrel_from_arrays(*shapes.bent_tube(n_around=24, spacing=0.05))


def _polygon_radius(theta, r=RADIUS, n=N_AROUND):
    """Distance from the axis to the regular n-gon (vertices at 2 pi k / n) in direction theta.

    Each side is at distance r cos(pi/n) from the axis, along its mid-angle; theta is phi off
    that mid-angle, so the side is hit at r cos(pi/n) / cos(phi)."""
    w = 2 * np.pi / n
    phi = np.mod(theta, w) - w / 2
    return r * np.cos(np.pi / n) / np.cos(phi)


def _angle(a, b):
    """Angles (n,) rad between rows; atan2 keeps small angles accurate (arccos does not)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


# ------------------------------------------------------------------ smooth corner normals

def test_side_corner_normals_are_radial(cylinder):
    V, F, FN, CN = cylinder.vertices, cylinder.faces, cylinder.face_normals, cylinder.corner_normals
    side = np.abs(FN[:, 2]) < 1e-9
    assert side.sum() == 2 * N_AROUND * 4
    corners = V[F[side]].reshape(-1, 3)
    radial = corners * [1.0, 1.0, 0.0]
    normals = CN[side].reshape(-1, 3)
    # A side face normal is pi/n off the radial direction of its corners: that is all the facets
    # allow. Around a vertex the side quads are planar rectangles, each giving a right angle, so the
    # angle-weighted average of the two columns is exactly the bisector: radial to rounding.
    face_off = _angle(np.repeat(FN[side], 3, axis=0), radial)
    assert np.allclose(face_off, np.pi / N_AROUND, atol=1e-9)
    assert np.max(_angle(normals, radial)) < 1e-9
    assert np.allclose(np.linalg.norm(CN, axis=2), 1.0, atol=1e-12)


def test_caps_do_not_bend_side_normals(cylinder):
    """Crease split: the cap ring's side corners stay horizontal, the cap corners stay axial."""
    V, F, FN, CN = cylinder.vertices, cylinder.faces, cylinder.face_normals, cylinder.corner_normals
    side = np.abs(FN[:, 2]) < 1e-9
    on_cap_ring = np.isclose(V[F][..., 2], 0.0) | np.isclose(V[F][..., 2], LENGTH)    # (nf, 3)
    ring_side = CN[side][on_cap_ring[side]]
    assert len(ring_side) == 2 * N_AROUND * 3          # 3 corners per column on each cap ring
    # without the crease split these would tilt by about 45 deg * (cap angle weight)
    assert np.max(np.abs(ring_side[:, 2])) < 1e-12
    tip_cap = FN[:, 2] < -0.5
    back_cap = FN[:, 2] > 0.5
    assert tip_cap.sum() == back_cap.sum() == N_AROUND
    assert np.allclose(CN[tip_cap], [0.0, 0.0, -1.0], atol=1e-12)
    assert np.allclose(CN[back_cap], [0.0, 0.0, 1.0], atol=1e-12)


def _naive_corner_normals(V, F, FN, crease_deg):
    """Slow reference: for every corner, angle-weighted mean of the normals of the faces that share
    its vertex and whose normal is within the crease angle of the corner's face."""
    out = np.empty((len(F), 3, 3))
    cos_crease = np.cos(np.radians(crease_deg))
    around = [[] for _ in range(len(V))]
    for g, face in enumerate(F):
        for k, v in enumerate(face):
            u = V[face[(k + 1) % 3]] - V[v]
            w = V[face[(k + 2) % 3]] - V[v]
            angle = np.arccos(np.clip(u @ w / np.linalg.norm(u) / np.linalg.norm(w), -1, 1))
            around[v].append((g, angle))
    for f, face in enumerate(F):
        for k, v in enumerate(face):
            n = sum(a * FN[g] for g, a in around[v] if FN[g] @ FN[f] >= cos_crease)
            out[f, k] = n / np.linalg.norm(n)
    return out


@pytest.mark.parametrize("which", ["bent", "box"])
def test_corner_normals_kernel_matches_naive_reference(which, bent):
    if which == "bent":
        m = bent
    else:  # a box: every vertex has three creases of 90 deg, the normals must not mix
        box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
        m = mandrel_from_arrays(box.vertices, box.faces)
        assert np.allclose(m.corner_normals, m.face_normals[:, None, :], atol=1e-12)
    ref = _naive_corner_normals(m.vertices, m.faces, m.face_normals, tol.crease_angle_deg)
    assert np.allclose(m.corner_normals, ref, atol=1e-12)


# ------------------------------------------------------------------ adjacency

def _naive_neighbors(F):
    """Reference: the face holding the reversed directed edge, through a dict."""
    owner = {}
    for f, face in enumerate(F):
        for k in range(3):
            owner[(face[k], face[(k + 1) % 3])] = f
    return np.array([[owner.get((face[(k + 1) % 3], face[k]), -1) for k in range(3)] for face in F])


@pytest.mark.parametrize("make", [
    lambda: shapes.cylinder(RADIUS, LENGTH, n_around=N_AROUND, n_along=4),
    lambda: shapes.cone(0.02, 0.04, 0.1, n_around=16, n_along=3),
    lambda: shapes.bent_tube(n_around=16, spacing=0.1),
    lambda: shapes.case_b(n_around=16, spacing=0.2),
], ids=["cylinder", "cone", "bent_tube", "case_b"])
def test_neighbors_symmetric_and_complete(make):
    V, F = make()
    m = mandrel_from_arrays(V, F)
    nb = m.neighbors
    assert np.all(nb >= 0)
    assert np.array_equal(nb, _naive_neighbors(m.faces))
    for f in range(len(F)):
        for k in range(3):
            a, b = m.faces[f, k], m.faces[f, (k + 1) % 3]
            g = nb[f, k]
            kk = [j for j in range(3) if m.faces[g, j] == b and m.faces[g, (j + 1) % 3] == a]
            assert len(kk) == 1 and nb[g, kk[0]] == f


def test_neighbors_minus_one_on_open_edges(cylinder_arrays):
    V, F = cylinder_arrays
    nb = face_neighbors(np.delete(F, 7, axis=0))
    assert np.sum(nb < 0) == 3                  # the three faces around the hole lose one neighbour


# ------------------------------------------------------------------ intake errors

def test_open_mesh_is_not_watertight(cylinder_arrays):
    V, F = cylinder_arrays
    with pytest.raises(MandrelError, match="not watertight"):
        mandrel_from_arrays(V, np.delete(F, 100, axis=0))


def test_inward_mesh_is_refused(cylinder_arrays):
    V, F = cylinder_arrays
    with pytest.raises(MandrelError, match="inwards"):
        mandrel_from_arrays(V, F[:, ::-1])


def test_missing_file_names_the_path(tmp_path):
    path = tmp_path / "no_such_mandrel.stl"
    with pytest.raises(MandrelError, match="no_such_mandrel.stl") as err:
        load_mandrel(path)
    assert str(path) in str(err.value)


def test_bad_unit_names_stl_unit(tmp_path, cylinder_arrays):
    path = tmp_path / "c.stl"
    trimesh.Trimesh(*cylinder_arrays, process=False).export(path)
    with pytest.raises(MandrelError, match="stl_unit") as err:
        load_mandrel(path, unit="inch")
    assert "inch" in str(err.value)


def test_mm_and_m_give_the_same_metres(tmp_path, cylinder_arrays):
    V, F = cylinder_arrays
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "m.stl")
    trimesh.Trimesh(V * 1e3, F, process=False).export(tmp_path / "mm.stl")
    a = load_mandrel(tmp_path / "m.stl", unit="m")
    b = load_mandrel(tmp_path / "mm.stl", unit="mm")
    assert a.faces.shape == b.faces.shape == F.shape
    # binary STL stores float32: each file rounds by at most half an ulp, 2**-24 relative
    atol = 2 * 2.0**-24 * LENGTH
    assert np.allclose(a.vertices[a.faces], b.vertices[b.faces], rtol=0, atol=atol)
    assert np.allclose(a.vertices[a.faces], V[F], rtol=0, atol=atol)
    assert a.repairs == b.repairs == ()


def test_ascii_stl_loads_without_warnings(tmp_path, cylinder_arrays):
    V, F = cylinder_arrays
    path = tmp_path / "ascii.stl"
    path.write_text(trimesh.exchange.stl.export_stl_ascii(trimesh.Trimesh(V, F, process=False)))
    assert path.read_text().startswith("solid")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = load_mandrel(path)
    # ASCII keeps full float64 repr: the same triangles as the arrays
    assert np.allclose(m.vertices[m.faces], V[F], rtol=0, atol=1e-15)


# ------------------------------------------------------------------ queries

def test_segments_to_the_axis_hit_the_polygon(cylinder):
    rng = np.random.default_rng(0)
    theta = rng.uniform(0.0, 2 * np.pi, 400)
    z = rng.uniform(0.01, LENGTH - 0.01, 400)
    outer = 2 * RADIUS
    starts = np.column_stack([outer * np.cos(theta), outer * np.sin(theta), z])
    ends = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
    hit, point, face, dist = cylinder.intersect_segments(starts, ends)
    assert hit.all() and np.all(face >= 0)
    rho = np.hypot(point[:, 0], point[:, 1])
    assert np.all(rho >= RADIUS * np.cos(np.pi / N_AROUND) - 1e-12) and np.all(rho <= RADIUS + 1e-12)
    exact = _polygon_radius(theta)
    assert np.allclose(rho, exact, rtol=0, atol=1e-12)
    assert np.allclose(dist, outer - exact, rtol=0, atol=1e-12)
    assert np.allclose(point[:, 2], z, atol=1e-12)
    # the face hit is a side face whose outward normal points back at the start
    assert np.all(np.einsum("ij,ij->i", cylinder.face_normals[face], starts - ends) > 0)


def test_segments_miss_when_parallel_outside_or_too_short(cylinder):
    starts = np.array([[2 * RADIUS, 0.0, -0.1],          # parallel to the axis, outside
                       [0.0, 3 * RADIUS, 0.05],           # towards the axis, ends before the wall
                       [0.0, 0.0, 0.0]])                  # zero length
    ends = np.array([[2 * RADIUS, 0.0, LENGTH + 0.1],
                     [0.0, 1.5 * RADIUS, 0.05],
                     [0.0, 0.0, 0.0]])
    hit, point, face, dist = cylinder.intersect_segments(starts, ends)
    assert not hit.any()
    assert np.all(face == -1) and np.all(np.isinf(dist))
    # the end is respected, not ignored: the same segment ending just past the wall hits
    rho = _polygon_radius(np.pi / 2)
    hit, _, _, dist = cylinder.intersect_segments([[0.0, 3 * RADIUS, 0.05]], [[0.0, rho - 1e-9, 0.05]])
    assert hit[0] and dist[0] == pytest.approx(3 * RADIUS - rho, abs=1e-12)


def test_hit_at_the_start_is_ignored(cylinder):
    """A segment starting on the wall finds the opposite wall, not its own start."""
    side = np.nonzero(np.abs(cylinder.face_normals[:, 2]) < 1e-9)[0][:20]
    starts = cylinder.vertices[cylinder.faces[side]].mean(axis=1)
    inward = -cylinder.face_normals[side]
    hit, point, face, dist = cylinder.intersect_segments(starts, starts + 3 * RADIUS * inward)
    assert hit.all()
    # n is even: the opposite side is parallel, 2 r cos(pi/n) away
    assert np.allclose(dist, 2 * RADIUS * np.cos(np.pi / N_AROUND), rtol=0, atol=1e-12)
    assert np.allclose(cylinder.face_normals[face], -cylinder.face_normals[side], atol=1e-12)
    # outwards from the wall there is nothing else
    hit, *_ = cylinder.intersect_segments(starts, starts - 3 * RADIUS * inward)
    assert not hit.any()


def _points_on_faces(m, n, seed):
    rng = np.random.default_rng(seed)
    faces = rng.integers(0, len(m.faces), n)
    b = rng.dirichlet([1.0, 1.0, 1.0], n)
    points = np.einsum("ik,ikj->ij", b, m.vertices[m.faces[faces]])
    return faces, b, points


def test_smooth_normal_matches_kernel(bent):
    faces, b, points = _points_on_faces(bent, 300, seed=1)
    out = np.empty((len(points), 3))
    smooth_normals_batch(bent.vertices, bent.faces, bent.corner_normals, faces.astype(np.int64), points, out)
    ref = np.array([bent.smooth_normal(f, p) for f, p in zip(faces, points)])
    assert np.allclose(out, ref, rtol=0, atol=1e-12)
    # and both are the normalised barycentric blend of the corner normals
    blend = np.einsum("ik,ikj->ij", b, bent.corner_normals[faces])
    assert np.allclose(ref, blend / np.linalg.norm(blend, axis=1)[:, None], atol=1e-9)


def test_smooth_normal_at_corners_is_the_corner_normal(cylinder):
    for f in (0, 300, len(cylinder.faces) - 1):
        for k in range(3):
            n = cylinder.smooth_normal(f, cylinder.vertices[cylinder.faces[f, k]])
            assert np.allclose(n, cylinder.corner_normals[f, k], atol=1e-12)


def test_closest_points_on_an_icosphere():
    r = 0.1
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=r)
    m = mandrel_from_arrays(sphere.vertices, sphere.faces)
    rng = np.random.default_rng(2)
    d = rng.normal(size=(40, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    queries = d * rng.uniform(0.3 * r, 2.0 * r, 40)[:, None]
    closest, faces = m.closest_points(queries)
    # the point lies on its face: in its plane, non-negative barycentrics
    tri = m.vertices[m.faces[faces]]
    assert np.allclose(np.einsum("ij,ij->i", closest - tri[:, 0], m.face_normals[faces]), 0.0, atol=1e-12)
    for p, t in zip(closest, tri):
        b, *_ = np.linalg.lstsq(np.stack([t[1] - t[0], t[2] - t[0]], axis=1), p - t[0], rcond=None)
        assert b.min() >= -1e-9 and b.sum() <= 1 + 1e-9
    # brute force: a barycentric grid of k steps on every face is within h = max edge / k of any
    # surface point, so the true distance lies in [grid min - h, grid min]
    k = 12
    i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    keep = i + j <= k
    w = np.column_stack([1 - (i[keep] + j[keep]) / k, i[keep] / k, j[keep] / k])
    samples = np.einsum("sk,fkj->fsj", w, m.vertices[m.faces]).reshape(-1, 3)
    edges = np.linalg.norm(m.vertices[m.faces] - m.vertices[np.roll(m.faces, 1, axis=1)], axis=2)
    h = edges.max() / k
    dist = np.linalg.norm(closest - queries, axis=1)
    brute = np.array([np.linalg.norm(samples - q, axis=1).min() for q in queries])
    assert np.all(dist <= brute + 1e-12)
    assert np.all(dist >= brute - h)
    # and the sphere bounds it: the mesh lies between the inscribed sphere of its flattest face and r
    inner = np.min(np.abs(np.einsum("ij,ij->i", m.vertices[m.faces[:, 0]], m.face_normals)))
    rho = np.linalg.norm(queries, axis=1)
    outside = rho > r
    assert np.all(dist[outside] >= rho[outside] - r - 1e-12)
    assert np.all(dist[outside] <= rho[outside] - inner + 1e-12)


# ------------------------------------------------------------------ what the refusals say

def _open_tube(n=16):
    return shapes.sweep(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, LENGTH]]), lambda s: shapes.circle(RADIUS, n), n,
                        np.linspace(0.0, LENGTH, 5), caps=False)


def test_open_tube_message_counts_the_open_edges():
    V, F = _open_tube(16)
    assert not trimesh.Trimesh(V, F, process=False).is_watertight          # independent judge
    with pytest.raises(MandrelError) as err:
        mandrel_from_arrays(V, F, source="mandrels/x.stl")
    msg = str(err.value)
    # two boundary loops (the ends) of 16 edges each
    assert msg.startswith("mandrels/x.stl is not watertight: 32 open edges (boundary loops near")
    assert "must be a closed surface" in msg


def test_one_missing_triangle_is_three_open_edges(cylinder_arrays):
    V, F = cylinder_arrays
    with pytest.raises(MandrelError, match="not watertight: 3 open edges"):
        mandrel_from_arrays(V, np.delete(F, 7, axis=0), source="holed.stl")


def test_one_flipped_triangle_is_not_consistently_oriented(cylinder_arrays):
    V, F = cylinder_arrays
    F = F.copy()
    F[7] = F[7, ::-1]
    assert not trimesh.Trimesh(V, F, process=False).is_winding_consistent
    with pytest.raises(MandrelError, match=r"mixed.stl is not consistently oriented: 3 edges join two "
                                           r"triangles wound against each other"):
        mandrel_from_arrays(V, F, source="mixed.stl")


def test_non_manifold_edge_is_named():
    """Two tetrahedra sharing one edge: that edge has four triangles."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 0.3, 1], [0.5, -1, 0], [0.5, -0.3, -1]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3],       # tetra 0,1,2,3 (outward)
                  [0, 1, 4], [0, 5, 1], [1, 5, 4], [4, 5, 0]])      # tetra 0,1,4,5 shares edge 0-1
    with pytest.raises(MandrelError, match="not a manifold surface: 1 edges are shared by three or more"):
        mandrel_from_arrays(V, F, source="pinched.stl")


def test_inward_message_says_what_to_do(cylinder_arrays):
    V, F = cylinder_arrays
    with pytest.raises(MandrelError) as err:
        mandrel_from_arrays(V, F[:, ::-1], source="flipped.stl")
    assert "flipped.stl" in str(err.value) and "flip the normals" in str(err.value)


# ------------------------------------------------------------------ facet independence

def _radial_unit(points):
    r = points * [1.0, 1.0, 0.0]
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def _jittered_cylinder_errors(n_around, jitter=0.25, seed=4):
    """Max angle (rad) off radial of the corner normals and of the face normals of a cylinder
    whose side vertices are moved around and along the exact surface by up to ``jitter`` cells."""
    V, F = shapes.cylinder(RADIUS, LENGTH, n_around=n_around, aspect=1.0)
    side = (V[:, 2] > 1e-9) & (V[:, 2] < LENGTH - 1e-9)
    n_rings = len(np.unique(np.round(V[:, 2], 12)))
    dz = LENGTH / (n_rings - 1)
    dphi = 2 * np.pi / n_around
    rng = np.random.default_rng(seed)
    phi = np.arctan2(V[side, 1], V[side, 0]) + rng.uniform(-jitter, jitter, side.sum()) * dphi
    V = V.copy()
    V[side] = np.column_stack([RADIUS * np.cos(phi), RADIUS * np.sin(phi),
                               V[side, 2] + rng.uniform(-jitter, jitter, side.sum()) * dz])
    m = mandrel_from_arrays(V, F)
    s = np.abs(m.face_normals[:, 2]) < 0.5
    corners = m.vertices[m.faces[s]].reshape(-1, 3)
    err = _angle(m.corner_normals[s].reshape(-1, 3), _radial_unit(corners))
    face_err = _angle(m.face_normals[s], _radial_unit(m.vertices[m.faces[s]].mean(axis=1)))
    return err.max(), face_err.max()


def test_corner_normals_radial_on_a_jittered_cylinder():
    """Irregular faces (asymmetric fans): the corner normals stay close to radial and converge.

    On a regular prism they are exact (test above); on an irregular mesh angle-weighted vertex
    normals are first order in h, like the faces, but with a smaller constant. Measured at a
    quarter-cell jitter: corner/face error ratio 0.34 at every n, errors halving with each
    doubling of n (0.073 rad at n = 32, 0.017 at 128)."""
    err32, face32 = _jittered_cylinder_errors(32)
    err128, face128 = _jittered_cylinder_errors(128)
    assert err32 < 0.45 * face32 and err128 < 0.45 * face128
    # first order: 4x finer -> 4x smaller (3x leaves room for the random fans)
    assert err128 < err32 / 3.0
    assert err128 < 0.5 * (2 * np.pi / 128)


def test_corner_normals_follow_the_sphere():
    r = 0.1
    ico = trimesh.creation.icosphere(subdivisions=3, radius=r)
    m = mandrel_from_arrays(ico.vertices, ico.faces)
    corners = m.vertices[m.faces].reshape(-1, 3)
    exact = corners / np.linalg.norm(corners, axis=1)[:, None]
    edge = np.linalg.norm(m.vertices[m.faces[:, 1]] - m.vertices[m.faces[:, 0]], axis=1).max()
    # a face normal is off by up to ~edge / (sqrt(3) r); the smooth normal is second order:
    # a tenth of the first-order bound is ample (measured ~1e-3 rad vs edge / r ~ 0.1)
    assert np.max(_angle(m.corner_normals.reshape(-1, 3), exact)) < 0.1 * edge / r


def test_segment_hits_match_the_multiple_hit_reference(bent):
    """The one-query embree path against trimesh's every-hit query filtered by hand."""
    rng = np.random.default_rng(7)
    lo, hi = bent.bounds
    starts = rng.uniform(lo - 0.05, hi + 0.05, (400, 3))
    ends = rng.uniform(lo - 0.05, hi + 0.05, (400, 3))
    hit, point, face, dist = bent.intersect_segments(starts, ends)
    d = ends - starts
    length = np.linalg.norm(d, axis=1)
    u = d / length[:, None]
    loc, ray, tri = bent.mesh.ray.intersects_location(starts, u, multiple_hits=True)
    t = np.einsum("ij,ij->i", loc - starts[ray], u[ray])
    keep = (t > tol.ray_offset * bent.diagonal) & (t <= length[ray])
    ref = np.full(len(starts), np.inf)
    np.minimum.at(ref, ray[keep], t[keep])
    assert np.array_equal(hit, np.isfinite(ref))
    assert hit.sum() > 50
    # 1e-9 m: both recompute the hit on the triangle's plane in float64
    assert np.allclose(dist[hit], ref[hit], rtol=0, atol=1e-9)
    assert np.allclose(point[hit], starts[hit] + dist[hit, None] * u[hit], atol=1e-12)


def test_embree_scene_is_trimeshs_wrapper(bent):
    """``EmbreeScene`` (built from the arrays, no trimesh) has trimesh's embree wrapper's origin and
    scale bit for bit and returns the same first faces for the same float32 rays."""
    pytest.importorskip("embreex")
    ours = bent._embree
    theirs = bent.mesh.ray._scene
    np.testing.assert_array_equal(ours.origin, theirs.origin)
    assert ours.scale == theirs.scale
    rng = np.random.default_rng(11)
    lo, hi = bent.bounds
    origins = ((rng.uniform(lo - 0.05, hi + 0.05, (500, 3)) - ours.origin) * ours.scale).astype(np.float32)
    aim = (bent.vertices[rng.integers(len(bent.vertices), size=500)] - ours.origin) * ours.scale
    dirs = aim - origins + rng.normal(scale=5.0, size=(500, 3))      # towards the mandrel, or past it
    dirs = (dirs / np.linalg.norm(dirs, axis=1)[:, None]).astype(np.float32)
    got = np.asarray(ours.scene.run(origins, dirs))
    np.testing.assert_array_equal(got, np.asarray(theirs.scene.run(origins, dirs)))
    assert 100 < (got >= 0).sum() < 500               # hits and misses
