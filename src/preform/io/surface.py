"""Surface fields to files: ``surface.vtu``, ``surface.xdmf`` + ``surface.h5``, and two pictures
(docs/guide/results.md).

Writes are atomic: everything is first written into a temporary folder inside ``out_dir`` and
then moved into place with :func:`os.replace`, the ``.h5`` before the ``.xdmf`` that references it
(by its bare file name, so the pair stays valid wherever the folder goes). meshio's static XDMF
writer puts the ``.h5`` beside the ``.xdmf`` (``Path.with_suffix``), never in the working directory.

Pictures are off-screen pyvista renders (EGL, no display needed). If rendering fails (no OpenGL),
no PNG is written and a :class:`RuntimeWarning` says why; the data files are still written.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..drawing import PICTURES as PICTURE_SETTINGS
from .atomic import atomic_path

VTU = "surface.vtu"
#: the fields on the mandrel's own triangles (``[output] input_mesh_fields``)
INPUT_VTU = "surface_input.vtu"
XDMF = "surface.xdmf"
H5 = "surface.h5"
PLOTS = "plots"
#: (file name, cell array, scalar-bar title with units, scale to the shown unit); the sizes and
#: the framing are ``preform.settings.PictureSettings``
PICTURES = (
    ("surface_braid_angle.png", "braid_angle_deg", "braid angle (deg)", 1.0),
    ("surface_cover_factor.png", "cover_factor", "cover factor (-)", 1.0),
    ("surface_thickness.png", "thickness_m", "thickness (mm)", 1e3),
)
BACKGROUND = "white"
UNREACHED_COLOR = "lightgray"


def layer_pictures(n_layers: int) -> tuple:
    """The surface pictures of a run of ``n_layers`` (0 or 1: a single layer): PICTURES; for a
    stack, the braid angle of every layer (``surface_braid_angle_layer<k>.png`` of
    ``layer<k>_braid_angle_deg``, layer 1's the unprefixed array) and the stack's cover factor
    and thickness under the single-layer names, as the unrolled map's panels
    (``maps.layer_panels``)."""
    if n_layers < 2:
        return PICTURES
    angles = tuple((f"surface_braid_angle_layer{k}.png", "braid_angle_deg" if k == 1 else f"layer{k}_braid_angle_deg",
                    f"braid angle of layer {k} (deg)", 1.0) for k in range(1, n_layers + 1))
    return (*angles, ("surface_cover_factor.png", "cover_factor", "cover factor of the stack (-)", 1.0),
            ("surface_thickness.png", "thickness_m", "thickness of the stack (mm)", 1e3))


def fields_layers(fields) -> int:
    """The layers whose arrays ``fields`` holds (``layer<k>_braid_angle_deg``; 1 for none)."""
    k = 1
    while f"layer{k + 1}_braid_angle_deg" in fields.cell_data:
        k += 1
    return k


def surface_mesh(fields):
    """The fields as a ``meshio.Mesh`` of triangles with every cell array (float64 or int)."""
    import meshio

    cell_data = {name: [np.ascontiguousarray(values)] for name, values in fields.cell_data.items()}
    return meshio.Mesh(np.asarray(fields.vertices, dtype=np.float64),
                       [("triangle", np.asarray(fields.faces, dtype=np.int64))], cell_data=cell_data)


def write_surface(fields, out_dir, title: str = "", pictures: bool = True) -> list[Path]:
    """Write ``surface.vtu``, ``surface.xdmf`` + ``surface.h5`` and the pictures into ``out_dir``.

    fields : preform.analysis.fields.SurfaceFields
    out_dir : str or Path, created if missing
    pictures : also render the pictures (:func:`write_surface_pictures`) into ``out_dir/plots``
    returns : the paths written (pictures only if rendering worked)
    """
    import meshio

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh = surface_mesh(fields)
    tmp = Path(tempfile.mkdtemp(prefix=".surface-", dir=out_dir))
    try:
        # uncompressed: meshio's zlib (.vtu) and gzip (.h5) took 0.3-0.5 s each on case A's 24 k
        # faces for 2.4x smaller files (6.4 + 4.4 MB against 2.5 + 1.9 MB of about 75 MB)
        meshio.write(tmp / VTU, mesh, file_format="vtu", compression=None)
        meshio.write(tmp / XDMF, mesh, file_format="xdmf", compression=None)
        written = []
        for name in (VTU, H5, XDMF):  # the .h5 before the .xdmf that points to it
            os.replace(tmp / name, out_dir / name)
            written.append(out_dir / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written + (write_surface_pictures(fields, out_dir / PLOTS, title) if pictures else [])


def write_input_mesh_fields(input_fields, out_dir) -> Path:
    """``surface_input.vtu``: the fields on the mandrel's own triangles (the STL's, after repair;
    ``analysis.fields.fields_on_input``, area-weighted), written atomically."""
    import meshio

    path = Path(out_dir) / INPUT_VTU
    with atomic_path(path) as tmp:
        meshio.write(tmp, surface_mesh(input_fields), file_format="vtu", compression=None)
    return path


def write_surface_pictures(fields, plots_dir, title: str = "", centerline=None,
                           pictures=PICTURE_SETTINGS) -> list[Path]:
    """Off-screen renders of the braid angle, the cover factor and the thickness on the mandrel
    (:func:`layer_pictures`: for a stack, the braid angle of each layer and the stack's cover
    factor and thickness); ``pictures``: ``preform.settings.PictureSettings``.

    Each picture shows the braided part from the front and, turned over about its axis, from
    the back (all four sides of a square section), tip on the left in both (and in the unrolled
    map), filling the frame's width, with a ruler of arc length from the tip under each view
    (``centerline``: preform.geometry.Centerline, else no ruler); titled with ``title`` (case,
    model, status); faces no yarn reached are grey and the colour range is that of the braided
    faces only, on round limits. The three pictures are drawn by one plotter whose surface only
    changes its colours (a new plotter or actor compiles its shaders again: about 0.5 s a
    picture). Returns the PNG paths written; on a rendering failure returns [] and warns.
    """
    plots_dir = Path(plots_dir)
    plots_dir.mkdir(parents=True, exist_ok=True)
    written = []
    scene = None
    try:
        scene = _SurfaceScene(fields, centerline, pictures)
        for file_name, array, label, scale in layer_pictures(fields_layers(fields)):
            path = plots_dir / file_name
            # atomic_path leaves the temporary name free, so the renderer creates the file with
            # the user's umask (mkstemp's own file is 0600, and writing into it kept that mode)
            with atomic_path(path) as tmp:
                _render(scene, array, label, tmp, title, scale)
            written.append(path)
    except Exception as error:  # noqa: BLE001 - any VTK/GL failure: pictures are optional
        warnings.warn(f"surface pictures not written to {plots_dir}: off-screen rendering failed "
                      f"({type(error).__name__}: {error})", RuntimeWarning, stacklevel=2)
    finally:
        if scene is not None:
            scene.close()
    return written


#: the cell array the scene colours by (the shown field, NaN where drawn grey)
SHOWN = "shown"


class _SurfaceScene:
    """One off-screen plotter of the field mesh in two views (front on top, back below, then a
    row for the colour bar), each with one actor of the whole surface: faces with a NaN value
    are drawn in the grey ``UNREACHED_COLOR``, the others through the colour map. The cameras
    frame the braided faces (``fields.reached()``), the same for every picture."""

    def __init__(self, fields, centerline=None, pictures=PICTURE_SETTINGS):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        import pyvista as pv

        from .render3d import add_ruler, part_axes, tip_left

        self.fields = fields
        self.pictures = pictures
        self.vertices = np.asarray(fields.vertices, dtype=np.float64)
        self.faces = np.asarray(fields.faces, dtype=np.int64)
        reached = fields.reached()
        focus = self.vertices[np.unique(self.faces[reached])] if reached.any() else self.vertices
        centre, _, across, third = part_axes(focus, centerline)
        front = (across + third) / np.sqrt(2.0)
        tip = np.asarray(centerline.frames_at(np.array([0.0]))[0])[0] if centerline is not None else None
        up = tip_left(centre, front, (third - across) / np.sqrt(2.0), tip)
        right = np.cross(up, front)
        # the middle of the part's extents on the screen (its vertices' mean lies towards the
        # wide end of a cone), and its half extents from there
        rel = focus - centre
        x, y = rel @ right, rel @ up
        centre = centre + 0.5 * (x.max() + x.min()) * right + 0.5 * (y.max() + y.min()) * up
        half_w = max(0.5 * float(x.max() - x.min()), 1e-9)
        half_h = max(0.5 * float(y.max() - y.min()), 1e-9)
        # the part spans fill_width of the width; the view is as tall as the part at that scale
        # plus the rows of pixels its title and its ruler take, within the height's bounds. A
        # part too short for that (a short braid on a thick part) gets a narrower picture, down
        # to the least width, so that it still fills the width rather than a band in the middle
        least_w, width = (int(v) for v in pictures.surface_width_px)
        above, below = pictures.surface_view_room_px
        lo_h, hi_h = pictures.surface_view_height_px
        part_h = hi_h - above - below                                 # the tallest a part is drawn
        if 2.0 * half_h * pictures.fill_width * width / (2.0 * half_w) > part_h:
            width = int(np.clip(round(part_h * 2.0 * half_w / (2.0 * half_h * pictures.fill_width)),
                                least_w, width))
        per_px = 2.0 * half_w / (pictures.fill_width * width)        # metres a pixel
        h = int(np.clip(round(2.0 * half_h / per_px) + above + below, lo_h, hi_h))
        per_px = max(per_px, 2.0 * half_h / max(h - above - below, 1))   # the height caps it
        bar = int(pictures.surface_bar_height_px)
        self.window_size = (width, 2 * h + bar)
        cells = np.column_stack([np.full(len(self.faces), 3), self.faces]).ravel()
        self.surface = pv.PolyData(self.vertices, cells)
        self.surface.cell_data[SHOWN] = np.zeros(len(self.faces))
        self.plotter = pv.Plotter(off_screen=True, window_size=self.window_size, shape=(3, 1),
                                  row_weights=[h, h, bar], border=False)
        self.plotter.render_window.SetMultiSamples(pictures.multi_samples)
        self.actors, self.texts = [], [None, None]
        # the back view is the part turned over about its axis: view and up both reversed, so
        # the screen's right (up x view) and with it the tip's side stay
        self.views = [(front, up), (-front, -up)]
        for row, (view, view_up) in enumerate(self.views):
            self.plotter.subplot(row, 0)
            self.plotter.set_background(BACKGROUND)
            self.actors.append(self.plotter.add_mesh(
                self.surface, scalars=SHOWN, cmap="viridis", nan_color=UNREACHED_COLOR,
                show_scalar_bar=False, ambient=0.5, diffuse=0.5))   # colours readable on shaded faces
            if centerline is not None:
                # marks over the part's extent only: the frame's margin is too narrow for a label
                add_ruler(self.plotter, centerline, centre, view, view_up, half_w, half_h,
                          pixel=per_px, margin=1.0)
            # the view's middle: the title's rows above the part, the ruler's below
            look_at = centre + 0.5 * (above - below) * per_px * view_up
            self.plotter.camera_position = [tuple(look_at + 10.0 * max(half_w, half_h) * view),
                                            tuple(look_at), tuple(view_up)]
            self.plotter.enable_parallel_projection()
            self.plotter.camera.parallel_scale = 0.5 * h * per_px
            self.plotter.reset_camera_clipping_range()
        self.plotter.subplot(2, 0)
        self.plotter.set_background(BACKGROUND)
        self.bar = self.bar_title = None

    def close(self):
        self.plotter.close()


def _render(scene, array, label, path, title="", scale=1.0):
    """One picture: reached faces coloured by ``array`` (times ``scale``), the rest grey, the
    braided part from the front (top) and the back (below, turned over about its axis).

    Grey: no yarn reached the face (or, for the braid angle, the angle is undefined there).
    """
    fields, plotter = scene.fields, scene.plotter
    values = np.asarray(fields.cell_data[array], dtype=np.float64) * scale
    reached = fields.reached()
    if array.endswith("braid_angle_deg"):  # 0 there means "undefined" (end caps): grey, not a colour
        reached &= values > 0
    scene.surface.cell_data[SHOWN] = np.where(reached, values, np.nan)
    if reached.any():
        from .maps import NON_NEGATIVE, rounded_limits

        lo, hi = rounded_limits(float(values[reached].min()), float(values[reached].max()),
                                zero=array in NON_NEGATIVE, ticks=scene.pictures.bar_ticks)
    else:
        lo, hi = 0.0, 1.0
    for actor in scene.actors:
        actor.mapper.scalar_range = (lo, hi)
    from .render3d import nice_length

    ticks = int(round((hi - lo) / nice_length(hi - lo, scene.pictures.bar_ticks))) + 1
    for row in range(2):
        plotter.subplot(row, 0)
        side = "front" if row == 0 else "back (turned over about its axis); grey: no yarn"
        text = f"{title}: {label}, {side}" if row == 0 and title else side if row else f"{label}, {side}"
        if scene.texts[row] is not None:
            plotter.remove_actor(scene.texts[row], render=False)
        scene.texts[row] = plotter.add_text(text, font_size=10, color="black", position="upper_left",
                                            render=False)
    plotter.subplot(2, 0)
    if scene.bar is None:        # one colour bar in its own row; its title a text above it
        scene.bar = plotter.add_scalar_bar(title=" ", mapper=scene.actors[1].mapper, color="black",
                                           vertical=False, position_x=0.3, position_y=0.05, width=0.4,
                                           height=0.55, label_font_size=14, n_labels=ticks, fmt="%g")
        scene.bar.SetTextPositionToPrecedeScalarBar()   # tick labels under the bar
    scene.bar.SetNumberOfLabels(ticks)
    scene.bar.SetVisibility(bool(reached.any()))
    if scene.bar_title is not None:
        plotter.remove_actor(scene.bar_title, render=False)
    scene.bar_title = plotter.add_text(label, font_size=11, color="black", position="upper_edge",
                                       render=False)
    plotter.render()             # a screenshot alone may return the last frame drawn
    plotter.screenshot(str(path))
