"""Every picture answers its question at a glance: checked on the PNGs and figures of one small
kinematic run (a 20 mm tube, 0.3 m braided: a long part, as most are; one module fixture), and
on synthetic histories.

Each test fails on a defect users saw: a part drawn as a thin strip, a mirrored back view (the
tip on the other side), colour bars starting at 1.82e-07, background showing through the +-180
deg seam of the unrolled map, a steady marker on a still-rising curve, no spread round the
section, an invisible min-max band, a layered run showing only layer 1, a moire of yarns."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import preform as pf
from preform.pipeline import write_results
from preform.io.maps import face_raster, rounded_limits, surface_map_figure, unrolled_coordinates
from preform.io.plots import braid_angle_figure, convergence_length_figure
from preform.io.render3d import TIP_COLOUR, whole_stride
from preform.io.surface import PICTURES
from preform.settings import PICTURES as PICTURE_SETTINGS
from preform.analysis.steady import steady_state
from support.simcase import make_config, write_centerline, write_stl


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from preform.geometry import shapes

    folder = tmp_path_factory.mktemp("glance")
    v, f = shapes.cylinder(0.02, 0.4, n_around=48)
    stl = write_stl(folder / "tube.stl", v, f)
    csv = write_centerline(folder / "tube.csv", [[0, 0, 0], [0, 0, 0.4]])
    # Ko's 60 deg on r = 20 mm at 10 mm/s: omega = sqrt(3) v / r
    config = make_config(stl, centerline=csv, carriers=16, spool_radius=0.12,
                         angular_speed=np.sqrt(3.0) * 0.01 / 0.02, initial_position=0.05,
                         braid_length=0.3, out=folder / "results")
    result = pf.simulate(config, progress=False)
    fields = pf.map_to_surface(result)
    out = folder / "results"
    write_results(result, fields, out)
    return result, fields, out


def _image(path):
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def _tip_columns(image):
    """Columns of the pixels in the tip label's colour (TIP_COLOUR, within antialiasing)."""
    rgb = np.array([int(TIP_COLOUR[k:k + 2], 16) for k in (1, 3, 5)])
    near = np.abs(image - rgb).sum(axis=2) < 40
    return np.nonzero(near)[1]


def _drawn(image):
    return np.abs(image - image[0, 0]).sum(axis=2) > 30


def test_surface_pictures_fill_the_width_and_keep_the_tip_on_the_left_in_both_views(run):
    _, _, out = run
    for name, *_ in PICTURES:
        image = _image(out / "plots" / name)
        h = (image.shape[0] - PICTURE_SETTINGS.surface_bar_height_px) // 2
        width = image.shape[1]
        for view in (image[:h], image[h:2 * h]):
            # the part (not the title text in the top 30 px) spans most of the frame's width:
            # the camera is fitted to the braided part, not to a strip in 10 % of the image
            cols = np.nonzero(_drawn(view[30:]).any(axis=0))[0]
            assert cols.max() - cols.min() > 0.8 * width, name
            # the tip label lies on the left in the front and in the back view: a mirrored back
            # view (the camera turned round without turning the part over) puts it on the right
            tip = _tip_columns(view)
            assert len(tip) > 20, name
            assert np.median(tip) < 0.25 * width, name


@pytest.fixture(scope="module")
def short_thick(tmp_path_factory):
    """The surface pictures of a short, thick part: a cylinder 0.1 m long and 0.08 m across,
    braided over 0.05 m (a kinematic run of 16 carriers, Ko's 60 deg on r = 40 mm, spool radius
    80 mm: H_inf 0.04 m, so the mandrel holds the braid and its convergence zone)."""
    from preform.geometry import shapes
    from preform.io.surface import write_surface_pictures

    folder = tmp_path_factory.mktemp("short_thick")
    v, f = shapes.cylinder(0.04, 0.1, n_around=48)
    stl = write_stl(folder / "short.stl", v, f)
    csv = write_centerline(folder / "short.csv", [[0, 0, 0], [0, 0, 0.1]])
    config = make_config(stl, centerline=csv, carriers=16, spool_radius=0.08,
                         angular_speed=np.sqrt(3.0) * 0.01 / 0.04, initial_position=0.03,
                         braid_length=0.05, snapshots=0, out=folder / "results")
    result = pf.simulate(config, progress=False)
    assert result.status == "done", result.message
    fields = pf.map_to_surface(result)
    return write_surface_pictures(fields, folder / "plots", "short", centerline=result.centerline)


def _views(path):
    image = _image(path)
    h = (image.shape[0] - PICTURE_SETTINGS.surface_bar_height_px) // 2
    return image, (image[:h], image[h:2 * h])


def test_a_short_thick_part_fills_the_width_of_its_views(short_thick):
    """A braid 0.05 m long on a section 0.08 m across: the view as tall as the part at the
    width's scale (within the largest view height) or, beyond that, a narrower picture; the
    part spans more than 80 % of the width in both views, the tip on the left."""
    assert len(short_thick) == len(PICTURES)
    for path in short_thick:
        image, views = _views(path)
        width = image.shape[1]
        for view in views:
            cols = np.nonzero(_drawn(view[PICTURE_SETTINGS.surface_view_room_px[0]:]).any(axis=0))[0]
            assert cols.max() - cols.min() > 0.8 * width, path.name
            tip = _tip_columns(view)
            assert len(tip) > 20 and np.median(tip) < 0.25 * width, path.name


def test_the_braided_mandrel_keeps_the_tip_on_the_left_and_divides_its_panels(run):
    _, _, out = run
    image = _image(out / "plots" / "braided_mandrel.png")
    top = image[: image.shape[0] // 2]
    tip = _tip_columns(top)
    assert len(tip) > 20 and np.median(tip) < 0.25 * image.shape[1]
    # a dark divider between the two close-ups: a column of near-black pixels at the middle
    bottom = image[image.shape[0] // 2 + 10:-10]
    dark = (bottom.sum(axis=2) < 150).mean(axis=0)
    middle = image.shape[1] // 2
    assert dark[middle - 3:middle + 3].max() > 0.95


def test_the_whole_view_thins_the_yarns_on_a_long_mandrel_only():
    # case A: 144 yarns on 75 mm at 60 deg, 2 m across 1600 px: 3.3 mm apart = 2.4 px; every
    # 3rd yarn is 7 px apart, every 2nd only 4.9 px (below PictureSettings.min_yarn_spacing_px = 5)
    history = {"braid_angle_warp_deg": np.array([60.0]), "braid_angle_weft_deg": np.array([60.0])}
    yarns = type("Y", (), {"n_yarns": 144})()
    case_a = type("R", (), {"yarns": yarns, "history": history, "steps": 1})()
    assert whole_stride(case_a, 0.075, 1.0, 1600) == 3
    # a 6 cm braid across the same frame: every yarn shows
    assert whole_stride(case_a, 0.075, 0.04, 1600) == 1


def test_colour_limits_are_round_and_start_at_zero_where_the_quantity_cannot_be_negative(run):
    _, fields, _ = run
    result = run[0]
    fig = surface_map_figure(fields, result.centerline, "t")
    ranges = dict(zip(("braid_angle_deg", "cover_factor", "thickness_m"), fig.colour_ranges))
    assert ranges["cover_factor"][0] == 0.0 and ranges["thickness_m"][0] == 0.0
    for name, (lo, hi) in ranges.items():
        # round: a limit is its own 2-significant-digit rounding, never 1.82e-07
        for v in (lo, hi):
            assert v == float(f"{v:.2g}") or v == float(f"{v:.3g}"), (name, v)
        assert rounded_limits(lo, hi) == (lo, hi), name
    assert rounded_limits(1.82e-07, 0.93, zero=True) == (0.0, 1.0)
    assert rounded_limits(4.55e-08, 0.51, zero=True) == (0.0, 0.6)


def test_the_unrolled_map_has_no_background_along_its_seam(run):
    result, fields, _ = run
    # turn the part by half a face about its axis, so that faces straddle +-180 deg
    c, s = np.cos(np.radians(2.0)), np.sin(np.radians(2.0))
    turned = dataclasses.replace(fields, vertices=fields.vertices @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]))
    fig = surface_map_figure(turned, result.centerline, "t")
    pixels = fig.face_pixels[0]
    # the faces as unrolled, without their copies a turn away, leave gaps along the seam (the
    # test case has them) ...
    polys = unrolled_coordinates(turned.vertices, turned.faces, result.centerline)
    extent = (float(polys[..., 0].min()), float(polys[..., 0].max()), -180.0, 180.0)
    bare = face_raster(polys, extent, pixels.shape)
    inner = slice(3, pixels.shape[1] - 3)     # the columns of the side, not the end caps' edges
    assert (bare[[0, -1], inner] < 0).any()
    # ... the map's raster has none: every pixel of its top and bottom rows lies on a face
    assert (pixels[[0, -1], inner] >= 0).all()
    assert "0 deg is the direction" in fig.axes[-2 if len(fig.axes) % 2 == 0 else -1].get_xlabel() or \
        any("0 deg is the direction" in ax.get_xlabel() for ax in fig.axes)


def _with_history(result, L, H, angle, spread=0.0):
    history = {name: np.zeros(len(L)) for name in result.history}
    history.update(braided_length_m=L, convergence_length_mean_m=H, convergence_length_min_m=H - 0.01,
                   convergence_length_max_m=H + 0.01, braid_angle_warp_deg=angle,
                   braid_angle_weft_deg=angle, braid_angle_min_deg=angle - spread,
                   braid_angle_max_deg=angle + spread)
    return dataclasses.replace(result, history=history)


def _has_marker(ax):
    return any(line.get_label().startswith("steady from") for line in ax.get_lines())


def test_a_steady_marker_only_on_a_curve_flat_at_the_plots_scale(run):
    result = run[0]
    L = np.linspace(0.0, 2.0, 2001)
    # still rising towards 60 deg (lambda 1.2 m over 2 m): no marker, and the note says so
    rising = _with_history(result, L, 0.8 - 0.3 * np.exp(-L / 1.2), 60.0 - 12.0 * np.exp(-L / 1.2))
    ax = braid_angle_figure(rising, steady=steady_state(rising.history)).axes[0]
    assert not _has_marker(ax)
    assert any("not reached" in t.get_text() for t in ax.texts)
    # settled early (the angle over lambda 0.2 m, decides at 0.77 m; H over 0.1 m has moved 0.1 mm
    # = 0.05 px after): the marker on both, and the whole run on the axis from 0
    settled = _with_history(result, L, 0.8 - 0.3 * np.exp(-L / 0.1), 60.0 - 12.0 * np.exp(-L / 0.2))
    steady = steady_state(settled.history)
    assert steady["reached"]
    ax = braid_angle_figure(settled, steady=steady).axes[0]
    assert _has_marker(ax) and ax.get_ylim()[0] == 0.0
    ax = convergence_length_figure(settled, steady=steady).axes[0]
    assert _has_marker(ax) and ax.get_ylim()[0] == 0.0


def test_the_spread_round_the_section_is_a_band_and_the_min_max_band_has_an_edge(run):
    result = run[0]
    L = np.linspace(0.0, 1.0, 501)
    wide = _with_history(result, L, np.full_like(L, 0.3), np.full_like(L, 30.0), spread=15.0)
    ax = braid_angle_figure(wide).axes[0]
    (band,) = [c for c in ax.collections if c.get_label().startswith("spread round the section")]
    y = band.get_paths()[0].vertices[:, 1]
    assert y.min() == pytest.approx(15.0) and y.max() == pytest.approx(45.0)
    ax = convergence_length_figure(wide).axes[0]
    (band,) = [c for c in ax.collections if c.get_label().startswith("min – max")]
    assert band.get_linewidth()[0] > 0 and band.get_edgecolor()[0][3] > 0.2


def test_a_layered_history_has_a_line_per_layer(run):
    result = run[0]
    fig = braid_angle_figure(result, layers=[result, result])
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert sum(label.startswith("layer 2") for label in labels) == 1
    assert sum(label.startswith("layer 3") for label in labels) == 1
    assert any(label.endswith("layer 1") for label in labels)
    fig = convergence_length_figure(result, layers=[result])
    assert sum(line.get_label().startswith("layer 2") for line in fig.axes[0].get_lines()) == 1


def test_a_layered_map_has_a_panel_per_layer(run):
    result, fields, _ = run
    data = dict(fields.cell_data)
    data["layer2_braid_angle_deg"] = np.where(data["braid_angle_deg"] > 0, data["braid_angle_deg"] + 5.0, 0.0)
    fig = surface_map_figure(dataclasses.replace(fields, cell_data=data), result.centerline, "t")
    titles = [ax.get_title() for ax in fig.axes]
    assert any(t.startswith("braid angle of layer 1") for t in titles)
    assert any(t.startswith("braid angle of layer 2") for t in titles)
    assert len(fig.face_pixels) == 4
