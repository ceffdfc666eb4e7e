"""The unrolled surface map: coordinates, colour ranges, the picture."""

from __future__ import annotations

import numpy as np
import trimesh

from preform.analysis.fields import SurfaceFields
from preform.geometry import centerline_from_points
from preform.io.maps import rounded_limits, surface_map_figure, unrolled_coordinates, write_surface_map

R = 0.05


def tube(sections=48):
    mesh = trimesh.creation.cylinder(radius=R, height=0.4, sections=sections)
    mesh.apply_translation([0, 0, 0.2])
    side = np.abs(mesh.face_normals[:, 2]) < 0.5
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces[side], max_edge=0.03)
    return V, F


def test_unrolled_coordinates_are_arc_length_and_angle():
    V, F = tube()
    cl = centerline_from_points(np.array([[0, 0, z] for z in np.linspace(0, 0.4, 9)]))
    polys = unrolled_coordinates(V, F, cl)
    np.testing.assert_allclose(polys[..., 0], V[F][..., 2], atol=1e-12)     # s is z on this axis
    # no face spans the map: each keeps its width of at most 360 / 48 deg, also on the seam
    width = np.ptp(polys[..., 1], axis=1)
    assert width.max() <= 360.0 / 48 * (1 + 1e-9)
    # the angle is the azimuth about the axis, measured from the frame's N
    p, _, N, B = cl.frames_at(np.array([0.1]))
    v = V[F[0, 0]]
    expected = np.degrees(np.arctan2(v @ B[0], v @ N[0]))
    assert abs((polys[0, 0, 1] - expected + 180) % 360 - 180) < 1e-9


def fields_on(V, F, braided_up_to=0.25):
    centroid_z = V[F].mean(axis=1)[:, 2]
    reached = (centroid_z < braided_up_to).astype(np.uint8)
    angle = np.where(reached, 40.0 + 20.0 * centroid_z, 0.0)
    data = {"reached_warp": reached, "reached_weft": reached, "braid_angle_deg": angle,
            "cover_factor": 0.9 * reached, "thickness_m": 4e-4 * reached}
    return SurfaceFields(vertices=V, faces=F, source_faces=np.arange(len(F)), cell_data=data)


def test_colour_ranges_cover_the_braided_faces_only(tmp_path):
    V, F = tube()
    cl = centerline_from_points(np.array([[0, 0, z] for z in np.linspace(0, 0.4, 9)]))
    fig = surface_map_figure(fields_on(V, F), cl, "tube")
    lo, hi = fig.colour_ranges[0]
    centroid_z = V[F].mean(axis=1)[:, 2]
    braided = centroid_z < 0.25
    # the braided faces' range (40.17 to 44.33 deg), held by round limits
    first, last = 40.0 + 20.0 * centroid_z[braided].min(), 40.0 + 20.0 * centroid_z[braided].max()
    assert (lo, hi) == rounded_limits(first, last) == (40.0, 45.0)
    # every pixel of the map lies on a face (the tube's side covers s x [-180, 180] deg), and the
    # faces drawn in colour are the braided ones
    pixels = fig.face_pixels[0]
    assert (pixels >= 0).mean() > 0.99
    assert np.array_equal(fig.shown[0], braided)
    path = write_surface_map(fields_on(V, F), cl, tmp_path / "surface_map.png", "tube")
    from PIL import Image

    img = np.asarray(Image.open(path).convert("RGB"))
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 50   # not blank


def test_a_layered_run_colours_the_stack_where_any_layer_reached():
    """Layer 1 braided z < 0.15, layer 2 (prefixed arrays) 0.1 < z < 0.35: the stacked thickness
    is coloured on every face either reached, grey only where neither did; the braid angle (the
    first layer's) only where layer 1 has one."""
    V, F = tube()
    cl = centerline_from_points(np.array([[0, 0, z] for z in np.linspace(0, 0.4, 9)]))
    z = V[F].mean(axis=1)[:, 2]
    one, two = (z < 0.15).astype(np.uint8), ((z > 0.1) & (z < 0.35)).astype(np.uint8)
    data = {"reached_warp": one, "reached_weft": one, "layer1_reached_warp": one,
            "layer1_reached_weft": one, "layer2_reached_warp": two, "layer2_reached_weft": two,
            "braid_angle_deg": np.where(one, 45.0, 0.0), "layer2_braid_angle_deg": 60.0 * two,
            "cover_factor": 0.9 * (one | two),
            "thickness_m": 4e-4 * one + 5e-4 * two}
    fields = SurfaceFields(vertices=V, faces=F, source_faces=np.arange(len(F)), cell_data=data)
    assert np.array_equal(fields.reached(), (one | two) > 0)
    fig = surface_map_figure(fields, cl, "two layers")
    from matplotlib.colors import to_rgba

    from preform.io.maps import UNREACHED

    panels = [ax for ax in fig.axes if ax.images]
    for k, shown in ((0, one > 0), (2, (one | two) > 0)):
        assert np.array_equal(fig.shown[k], shown)
        # the picture itself: grey exactly on the pixels of faces not shown, colours elsewhere
        rgba = np.asarray(panels[k].images[0].get_array())
        face = fig.face_pixels[k]
        grey = np.all(rgba == to_rgba(UNREACHED), axis=-1)
        assert np.array_equal(grey[face >= 0], ~shown[face[face >= 0]])
        assert shown[face[face >= 0]].any() and (~shown[face[face >= 0]]).any()
    assert fig.axes[0].get_title().startswith("braid angle of layer 1")


def naive_face_raster(polys, extent, shape):
    """Slow reference of ``face_raster``: every pixel centre against every triangle (barycentric
    coordinates by a 2x2 solve), the highest face index holding it."""
    H, W = shape
    x0, x1, y0, y1 = extent
    out = np.full((H, W), -1)
    for i in range(H):
        for j in range(W):
            p = np.array([x0 + (j + 0.5) * (x1 - x0) / W, y1 - (i + 0.5) * (y1 - y0) / H])
            for f, (a, b, c) in enumerate(polys):
                m = np.column_stack([b - a, c - a])
                if abs(np.linalg.det(m)) < 1e-300:
                    continue
                u, v = np.linalg.solve(m, p - a)
                if u >= -1e-12 and v >= -1e-12 and u + v <= 1 + 1e-12:
                    out[i, j] = f
    return out


def test_face_raster_matches_the_point_in_triangle_reference():
    """Random triangles of both windings, some larger than the grid, some smaller than a pixel:
    the same face under every pixel centre as the brute-force test, away from edges (a centre on
    a shared edge may go to either face)."""
    from preform.io.maps import face_raster

    rng = np.random.default_rng(3)
    centres = rng.uniform(-0.2, 1.2, size=(40, 1, 2))
    polys = centres + rng.normal(scale=rng.choice([0.01, 0.1, 0.4], size=(40, 1, 1)), size=(40, 3, 2))
    extent, shape = (0.0, 1.0, 0.0, 1.0), (23, 31)
    fast = face_raster(polys, extent, shape)
    slow = naive_face_raster(polys, extent, shape)
    # pixels whose centre is within 1e-9 of some triangle edge are ambiguous: left out
    i, j = np.mgrid[0:shape[0], 0:shape[1]]
    pts = np.stack([(j + 0.5) / shape[1], 1.0 - (i + 0.5) / shape[0]], axis=-1).reshape(-1, 1, 2)
    a, b = polys, np.roll(polys, -1, axis=1)
    t = np.clip(np.einsum("pfkd,fkd->pfk", pts[:, None] - a[None], b - a) / np.einsum("fkd,fkd->fk", b - a, b - a), 0, 1)
    d = np.linalg.norm(pts[:, None] - (a[None] + t[..., None] * (b - a)[None]), axis=-1).min(axis=(1, 2))
    clear = (d > 1e-9).reshape(shape)
    assert clear.mean() > 0.95
    np.testing.assert_array_equal(fast[clear], slow[clear])
    assert (fast >= 0).any() and (fast < 0).any()
