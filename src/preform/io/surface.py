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

from .atomic import atomic_path

VTU = "surface.vtu"
#: the fields on the mandrel's own triangles (``[output] input_mesh_fields``)
INPUT_VTU = "surface_input.vtu"
XDMF = "surface.xdmf"
H5 = "surface.h5"
PLOTS = "plots"
#: picture size, pixels (width, height): two views stacked, each wide like a long part
WINDOW_SIZE = (1400, 1000)
#: (file name, cell array, scalar-bar title with units, scale to the shown unit)
PICTURES = (
    ("surface_braid_angle.png", "braid_angle_deg", "braid angle (deg)", 1.0),
    ("surface_cover_factor.png", "cover_factor", "cover factor (-)", 1.0),
    ("surface_thickness.png", "thickness_m", "thickness (mm)", 1e3),
)
BACKGROUND = "white"
#: multisampling of the render window: none. With 2 or 4 samples Mesa's software rasteriser
#: (llvmpipe, the usual off-screen EGL) takes about 0.19 s a frame against 0.02 s; without, the
#: part's outline is not smoothed (one-pixel notches where the faces' corners fall inside it)
MULTI_SAMPLES = 0
UNREACHED_COLOR = "lightgray"


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


def write_surface_pictures(fields, plots_dir, title: str = "") -> list[Path]:
    """Off-screen renders of the braid angle, the cover factor and the thickness on the mandrel.

    Each picture shows the braided part from two opposite sides (all four sides of a square
    section), titled with ``title`` (case, model, status); faces no yarn reached are drawn grey
    and the colour range is that of the braided faces only. The three pictures are drawn by one
    plotter whose surface only changes its colours (a new plotter or actor compiles its shaders
    again: about 0.5 s a picture). Returns the PNG paths written; on a rendering failure returns
    [] and warns.
    """
    plots_dir = Path(plots_dir)
    plots_dir.mkdir(parents=True, exist_ok=True)
    written = []
    scene = None
    try:
        scene = _SurfaceScene(fields)
        for file_name, array, label, scale in PICTURES:
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
    """One off-screen plotter of the field mesh in two views (front on top, back below), each
    with one actor of the whole surface: faces with a NaN value are drawn in the grey
    ``UNREACHED_COLOR``, the others through the colour map."""

    def __init__(self, fields):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        import pyvista as pv

        self.fields = fields
        self.vertices = np.asarray(fields.vertices, dtype=np.float64)
        self.faces = np.asarray(fields.faces, dtype=np.int64)
        cells = np.column_stack([np.full(len(self.faces), 3), self.faces]).ravel()
        self.surface = pv.PolyData(self.vertices, cells)
        self.surface.cell_data[SHOWN] = np.zeros(len(self.faces))
        self.plotter = pv.Plotter(off_screen=True, window_size=WINDOW_SIZE, shape=(2, 1), border=False)
        self.plotter.render_window.SetMultiSamples(MULTI_SAMPLES)
        self.actors, self.texts = [], [None, None]
        for row in range(2):
            self.plotter.subplot(row, 0)
            self.plotter.set_background(BACKGROUND)
            self.actors.append(self.plotter.add_mesh(
                self.surface, scalars=SHOWN, cmap="viridis", nan_color=UNREACHED_COLOR,
                show_scalar_bar=False, ambient=0.5, diffuse=0.5))   # colours readable on shaded faces
        self.bar = None

    def close(self):
        self.plotter.close()


def _render(scene, array, label, path, title="", scale=1.0):
    """One picture: reached faces coloured by ``array`` (times ``scale``), the rest grey, the
    braided part from the front (top) and the back (bottom).

    Grey: no yarn reached the face (or, for the braid angle, the angle is undefined there).
    """
    from .render3d import frame_parallel, view_axes

    fields, plotter = scene.fields, scene.plotter
    values = np.asarray(fields.cell_data[array], dtype=np.float64) * scale
    reached = fields.reached()
    if array == "braid_angle_deg":  # 0 there means "undefined" (end caps): grey, not a colour
        reached &= values > 0
        if "layer2_braid_angle_deg" in fields.cell_data:
            label = "braid angle of layer 1 (deg)"
    scene.surface.cell_data[SHOWN] = np.where(reached, values, np.nan)
    if reached.any():
        lo, hi = float(values[reached].min()), float(values[reached].max())
        if hi - lo < 1e-9 * max(1.0, abs(hi)):
            lo, hi = lo - 0.5 * max(1e-3, abs(lo) * 1e-2), hi + 0.5 * max(1e-3, abs(hi) * 1e-2)
    else:
        lo, hi = 0.0, 1.0
    for actor in scene.actors:
        actor.mapper.scalar_range = (lo, hi)
    focus = scene.vertices[np.unique(scene.faces[reached])] if reached.any() else scene.vertices
    centre, _, across, third = view_axes(focus)
    w, h = WINDOW_SIZE
    for row, sign in enumerate((1.0, -1.0)):
        plotter.subplot(row, 0)
        side = "front" if sign > 0 else "back; grey: no yarn"
        text = f"{title}: {label} ({side})" if row == 0 and title else side if row else label
        if scene.texts[row] is not None:
            plotter.remove_actor(scene.texts[row], render=False)
        scene.texts[row] = plotter.add_text(text, font_size=11, color="black", position="upper_left",
                                            render=False)
        frame_parallel(plotter, focus, centre, sign * (across + third) / np.sqrt(2.0),
                       (third - across) / np.sqrt(2.0), w / (h / 2))
    if scene.bar is None:        # one colour bar under the back view, retitled for each field
        plotter.subplot(1, 0)
        scene.bar = plotter.add_scalar_bar(title=label, mapper=scene.actors[1].mapper, color="black",
                                           vertical=False, position_x=0.3, position_y=0.02, width=0.4,
                                           height=0.1, title_font_size=18, label_font_size=14)
    scene.bar.SetTitle(label)
    scene.bar.SetVisibility(bool(reached.any()))
    plotter.render()             # a screenshot alone may return the last frame drawn
    plotter.screenshot(str(path))
