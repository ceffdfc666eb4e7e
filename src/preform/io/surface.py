"""Surface fields to files: ``surface.vtu``, ``surface.xdmf`` + ``surface.h5``, and two pictures
(DESIGN.md §1; issue 3).

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
UNREACHED_COLOR = "lightgray"


def surface_mesh(fields):
    """The fields as a ``meshio.Mesh`` of triangles with every cell array (float64 or int)."""
    import meshio

    cell_data = {name: [np.ascontiguousarray(values)] for name, values in fields.cell_data.items()}
    return meshio.Mesh(np.asarray(fields.vertices, dtype=np.float64),
                       [("triangle", np.asarray(fields.faces, dtype=np.int64))], cell_data=cell_data)


def write_surface(fields, out_dir, title: str = "") -> list[Path]:
    """Write ``surface.vtu``, ``surface.xdmf`` + ``surface.h5`` and the pictures into ``out_dir``.

    fields : preform.fields.SurfaceFields
    out_dir : str or Path, created if missing
    returns : the paths written (pictures only if rendering worked)
    """
    import meshio

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh = surface_mesh(fields)
    tmp = Path(tempfile.mkdtemp(prefix=".surface-", dir=out_dir))
    try:
        meshio.write(tmp / VTU, mesh, file_format="vtu")
        meshio.write(tmp / XDMF, mesh, file_format="xdmf")
        written = []
        for name in (VTU, H5, XDMF):  # the .h5 before the .xdmf that points to it
            os.replace(tmp / name, out_dir / name)
            written.append(out_dir / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written + write_surface_pictures(fields, out_dir / PLOTS, title)


def write_surface_pictures(fields, plots_dir, title: str = "") -> list[Path]:
    """Off-screen renders of the braid angle, the cover factor and the thickness on the mandrel.

    Each picture shows the braided part from two opposite sides (all four sides of a square
    section), titled with ``title`` (case, model, status); faces no yarn reached are drawn grey
    and the colour range is that of the braided faces only. Returns the PNG paths written; on a
    rendering failure returns [] and warns.
    """
    plots_dir = Path(plots_dir)
    plots_dir.mkdir(parents=True, exist_ok=True)
    written = []
    try:
        for file_name, array, label, scale in PICTURES:
            path = plots_dir / file_name
            # atomic_path leaves the temporary name free, so the renderer creates the file with
            # the user's umask (mkstemp's own file is 0600, and writing into it kept that mode)
            with atomic_path(path) as tmp:
                _render(fields, array, label, tmp, title, scale)
            written.append(path)
    except Exception as error:  # noqa: BLE001 - any VTK/GL failure: pictures are optional
        warnings.warn(f"surface pictures not written to {plots_dir}: off-screen rendering failed "
                      f"({type(error).__name__}: {error})", RuntimeWarning, stacklevel=2)
    return written


def _render(fields, array, label, path, title="", scale=1.0):
    """One picture: reached faces coloured by ``array`` (times ``scale``), the rest grey, the
    braided part from the front (top) and the back (bottom).

    Grey: no yarn reached the face (or, for the braid angle, the angle is undefined there).
    """
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    from .render3d import frame_parallel, view_axes

    faces = np.asarray(fields.faces, dtype=np.int64)
    vertices = np.asarray(fields.vertices, dtype=np.float64)
    cells = np.column_stack([np.full(len(faces), 3), faces]).ravel()
    surface = pv.PolyData(vertices, cells)
    values = np.asarray(fields.cell_data[array], dtype=np.float64) * scale
    reached = fields.reached()
    if array == "braid_angle_deg":  # 0 there means "undefined" (end caps): grey, not a colour
        reached &= values > 0
        if "layer2_braid_angle_deg" in fields.cell_data:
            label = "braid angle of layer 1 (deg)"
    surface.cell_data[label] = values
    focus = vertices[np.unique(faces[reached])] if reached.any() else vertices
    centre, _, across, third = view_axes(focus)
    w, h = WINDOW_SIZE
    plotter = pv.Plotter(off_screen=True, window_size=WINDOW_SIZE, shape=(2, 1), border=False)
    try:
        for row, sign in enumerate((1.0, -1.0)):
            plotter.subplot(row, 0)
            plotter.set_background(BACKGROUND)
            if (~reached).any():
                plotter.add_mesh(surface.extract_cells(np.flatnonzero(~reached)), color=UNREACHED_COLOR,
                                 ambient=0.5, diffuse=0.5)
            if reached.any():
                lo, hi = float(values[reached].min()), float(values[reached].max())
                if hi - lo < 1e-9 * max(1.0, abs(hi)):
                    lo, hi = lo - 0.5 * max(1e-3, abs(lo) * 1e-2), hi + 0.5 * max(1e-3, abs(hi) * 1e-2)
                plotter.add_mesh(surface.extract_cells(np.flatnonzero(reached)), scalars=label,
                                 cmap="viridis", clim=(lo, hi), show_scalar_bar=row == 1,
                                 ambient=0.5, diffuse=0.5,   # colours readable on shaded faces
                                 scalar_bar_args=dict(title=label, color="black", vertical=False,
                                                      position_x=0.3, position_y=0.02, width=0.4,
                                                      height=0.1, title_font_size=18,
                                                      label_font_size=14))
            side = "front" if sign > 0 else "back; grey: no yarn"
            text = f"{title}: {label} ({side})" if row == 0 and title else side if row else label
            plotter.add_text(text, font_size=11, color="black", position="upper_left")
            frame_parallel(plotter, focus, centre, sign * (across + third) / np.sqrt(2.0),
                           (third - across) / np.sqrt(2.0), w / (h / 2))
        plotter.screenshot(str(path))
    finally:
        plotter.close()
