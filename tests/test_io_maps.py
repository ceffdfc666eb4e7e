"""The unrolled surface map (issue 16 item 4): coordinates, colour ranges, the picture."""

from __future__ import annotations

import numpy as np
import trimesh

from preform.fields import SurfaceFields
from preform.geometry import centerline_from_points
from preform.io.maps import surface_map_figure, unrolled_coordinates, write_surface_map

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
    angle_ax = fig.axes[0]
    coloured = [c for c in angle_ax.collections if c.get_array() is not None]
    lo, hi = coloured[0].get_clim()
    centroid_z = V[F].mean(axis=1)[:, 2]
    braided = centroid_z < 0.25
    assert lo == 40.0 + 20.0 * centroid_z[braided].min() and hi == 40.0 + 20.0 * centroid_z[braided].max()
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
    for ax, shown in ((fig.axes[0], one > 0), (fig.axes[2], (one | two) > 0)):
        coloured = [c for c in ax.collections if c.get_array() is not None]
        assert len(coloured[0].get_array()) == shown.sum()
    assert fig.axes[0].get_title().startswith("braid angle of layer 1")
