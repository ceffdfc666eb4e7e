"""``plots/surface_map.png``: the surface fields unrolled.

Each field face is drawn at its centerline arc length ``s`` (m, from the tip; horizontal) and its
circumferential position ``phi`` (deg, vertical): the angle about the centerline, measured in the
centerline's own frame ``(N, B)`` at the face's section, so the map is the same for any pose of
the part. Three panels: braid angle, cover factor and thickness, each coloured over the braided
faces only (faces no yarn reached are grey, so the colour range is that of the braid). One
picture shows the whole surface, all sides at once, which no 3D view does.

matplotlib is imported by the functions that draw, not with the module: ``write_results`` reads
:data:`MAP` before it forks the picture worker, which should not wait for matplotlib.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..drawing import PICTURES as PICTURE_SETTINGS
from .atomic import atomic_path

MAP = "surface_map.png"
#: (cell array, panel title, scale to the shown unit)
PANELS = (("braid_angle_deg", "braid angle (deg)", 1.0),
          ("cover_factor", "cover factor (-)", 1.0),
          ("thickness_m", "thickness (mm)", 1e3))
UNREACHED = "0.82"
#: arrays whose 0 means "undefined here" (end caps, no preform): drawn grey like unreached faces
POSITIVE_ONLY = ("braid_angle_deg", "permeability_k1_m2", "permeability_k2_m2", "fibre_volume_fraction")
#: the RTM hand-off's map (``examples/rtm_chain.py``)
RTM_PANELS = (("fibre_volume_fraction", "fibre volume fraction (-)", 1.0),
              ("permeability_k1_m2", "permeability K1 (1e-12 m^2, log scale)", 1e12),
              ("porosity", "porosity (-)", 1.0))
#: arrays that are >= 0 by their physics: their colour bars start at 0
NON_NEGATIVE = ("cover_factor", "thickness_m", "fibre_volume_fraction", "porosity", "areal_weight_kg_m2")


def rounded_limits(lo: float, hi: float, zero: bool = False,
                   ticks: int = PICTURE_SETTINGS.bar_ticks) -> tuple[float, float]:
    """Colour-bar limits holding [lo, hi] on round numbers (multiples of a 1-2-5 step giving about
    ``ticks`` ticks), from 0 when ``zero`` (a quantity >= 0); a uniform field gets a range of
    one step around its value."""
    if zero:
        lo = min(lo, 0.0)
    span = hi - lo
    if not span > 1e-9 * max(1.0, abs(hi)):
        span = max(0.02 * abs(hi), 1e-12)
        lo, hi = (0.0 if zero and lo - span < 0 else lo - span), hi + span
        span = hi - lo
    raw = span / ticks
    power = 10.0 ** np.floor(np.log10(raw))
    step = next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= raw * (1 - 1e-9))
    lo_r = np.floor(lo / step + 1e-9) * step
    hi_r = np.ceil(hi / step - 1e-9) * step
    if hi_r <= lo_r:
        hi_r = lo_r + step
    digits = max(0, -int(np.floor(np.log10(step))))     # round off the floating-point dust
    return float(np.round(lo_r, digits + 1)), float(np.round(hi_r, digits + 1))


def layer_panels(cell_data) -> tuple:
    """The map's panels: PANELS for one layer; for a stack, the braid angle of every layer (a
    panel each: ``layer<k>_braid_angle_deg``) and the stack's cover factor and thickness."""
    k, angles = 2, []
    while f"layer{k}_braid_angle_deg" in cell_data:
        angles.append((f"layer{k}_braid_angle_deg", f"braid angle of layer {k} (deg)", 1.0))
        k += 1
    if not angles:
        return PANELS
    return (("braid_angle_deg", "braid angle of layer 1 (deg)", 1.0), *angles,
            ("cover_factor", "cover factor of the stack (-)", 1.0),
            ("thickness_m", "thickness of the stack (mm)", 1e3))


def unrolled_coordinates(vertices, faces, centerline):
    """Per face, its three corners in the unrolled plane: (nf, 3, 2) (s in m, phi in deg).

    The corners' angles are taken in the frame of the face's own section (its centroid's
    projection) and unwrapped towards the centroid's angle, so a face on the seam at +-180 deg
    keeps its shape (it spills past the axis limit instead of spanning the map).
    """
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    corners = vertices[faces]                                   # (nf, 3, 3)
    centroid = corners.mean(axis=1)
    s_c, _ = centerline.project(centroid)
    p, _, N, B = centerline.frames_at(s_c)
    s_v = centerline.project(vertices)[0][faces]
    rel = corners - p[:, None, :]
    phi = np.degrees(np.arctan2(np.einsum("fkj,fj->fk", rel, B), np.einsum("fkj,fj->fk", rel, N)))
    phi_c = np.degrees(np.arctan2(np.einsum("fj,fj->f", centroid - p, B),
                                  np.einsum("fj,fj->f", centroid - p, N)))
    phi = phi_c[:, None] + (phi - phi_c[:, None] + 180.0) % 360.0 - 180.0
    return np.stack([s_v, phi], axis=2)


def face_raster(polys, extent, shape) -> np.ndarray:
    """(H, W) int64: the face whose triangle holds each pixel centre of a regular grid, -1 where
    none does (the highest face index where triangles overlap).

    polys : (nf, 3, 2) corners in the plane (:func:`unrolled_coordinates`);
    extent : (x0, x1, y0, y1) covered by the grid, row 0 at y1 (the top, as images are stored);
    shape : (H, W) pixels. Faces are grouped by the size of their pixel bounding box, and each
    group tests its candidate pixel centres at once with the three edge functions (both windings).
    """
    H, W = shape
    x0, x1, y0, y1 = extent
    out = np.full((H, W), -1, dtype=np.int64)
    if len(polys) == 0 or H <= 0 or W <= 0:
        return out
    u = (polys[..., 0] - x0) * (W / (x1 - x0)) - 0.5          # pixel column j has its centre at u = j
    v = (y1 - polys[..., 1]) * (H / (y1 - y0)) - 0.5          # pixel row i at v = i
    j0 = np.clip(np.ceil(u.min(axis=1)), 0, W).astype(np.int64)
    j1 = np.clip(np.floor(u.max(axis=1)), -1, W - 1).astype(np.int64)
    i0 = np.clip(np.ceil(v.min(axis=1)), 0, H).astype(np.int64)
    i1 = np.clip(np.floor(v.max(axis=1)), -1, H - 1).astype(np.int64)
    nj, ni = j1 - j0 + 1, i1 - i0 + 1
    area = (u[:, 1] - u[:, 0]) * (v[:, 2] - v[:, 0]) - (u[:, 2] - u[:, 0]) * (v[:, 1] - v[:, 0])
    live = (nj > 0) & (ni > 0) & (area != 0)
    size = ni * (W + 1) + nj
    for key in np.unique(size[live]):
        f = np.flatnonzero(live & (size == key))
        a, b = int(key // (W + 1)), int(key % (W + 1))
        di, dj = (g.ravel() for g in np.meshgrid(np.arange(a), np.arange(b), indexing="ij"))
        pi = i0[f, None] + di[None, :]                        # (g, a b) candidate pixels
        pj = j0[f, None] + dj[None, :]
        sign = np.sign(area[f])[:, None]
        inside = np.ones(pi.shape, dtype=bool)
        for k in range(3):                                    # edge k -> k+1, pixel on its inner side
            ua, va = u[f, k, None], v[f, k, None]
            ub, vb = u[f, (k + 1) % 3, None], v[f, (k + 1) % 3, None]
            inside &= sign * ((ub - ua) * (pi - va) - (vb - va) * (pj - ua)) >= 0
        np.maximum.at(out, (pi[inside], pj[inside]), np.broadcast_to(f[:, None], pi.shape)[inside])
    return out


#: the map's layout, inches: figure width, height per panel, and the margins around the panels
#: (fixed, so the picture needs no layout pass: the constrained layout of three panels with
#: their colour bars measured every tick label twice, half the time of drawing the map)
WIDTH_IN, PANEL_IN = 10.0, 3.0
LEFT_IN, RIGHT_IN, TOP_IN, BOTTOM_IN, TITLE_IN = 0.75, 1.25, 0.65, 0.75, 0.35
BAR_GAP_IN, BAR_IN = 0.15, 0.15


def _panel_rects(n):
    """Figure-fraction rectangles (left, bottom, width, height) of the n panels and their bars."""
    height = PANEL_IN * n
    slot = (height - TOP_IN - BOTTOM_IN) / n
    w = (WIDTH_IN - LEFT_IN - RIGHT_IN) / WIDTH_IN
    rects = []
    for k in range(n):
        bottom = BOTTOM_IN + (n - 1 - k) * slot
        ax = (LEFT_IN / WIDTH_IN, bottom / height, w, (slot - TITLE_IN) / height)
        bar = ((WIDTH_IN - RIGHT_IN + BAR_GAP_IN) / WIDTH_IN, bottom / height, BAR_IN / WIDTH_IN,
               (slot - TITLE_IN) / height)
        rects.append((ax, bar))
    return rects


def surface_map_figure(fields, centerline, title: str, panels=PANELS, pictures=PICTURE_SETTINGS) -> Figure:
    """The unrolled panels (see module docstring); ``panels``: (cell array, label, scale) each.

    Each panel is an image at the picture's resolution (:func:`face_raster`: the face under each
    pixel), coloured by the face's value where ``shown`` and grey where not, so the cost does not
    grow with the number of faces drawn as polygons; the face of each pixel of panel k is kept
    as ``fig.face_pixels[k]``, the faces coloured there as ``fig.shown[k]`` and the colour range
    as ``fig.colour_ranges[k]`` ((lo, hi) in the shown unit, None where nothing is coloured).
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LogNorm, Normalize, to_rgba
    from matplotlib.figure import Figure

    polys = unrolled_coordinates(fields.vertices, fields.faces, centerline)
    data = fields.cell_data
    if panels is PANELS:
        panels = layer_panels(data)
    reached = fields.reached()
    n = len(panels)
    dpi = pictures.map_dpi
    fig = Figure(figsize=(WIDTH_IN, PANEL_IN * n), dpi=dpi)
    fig.suptitle(title, y=1.0 - 0.12 / (PANEL_IN * n), va="top")
    s_all = polys[..., 0]
    extent = (float(s_all.min()), float(s_all.max()), -180.0, 180.0)
    # faces on the +-180 deg seam spill past one edge of the map: drawn once more, a turn
    # away, they fill the other edge too (no gaps of background along the seam)
    nf = len(polys)
    high, low = polys[..., 1].max(axis=1) > 180.0, polys[..., 1].min(axis=1) < -180.0
    turn = np.array([0.0, 360.0])
    wrapped = np.concatenate([polys, polys[high] - turn, polys[low] + turn])
    owner = np.concatenate([np.arange(nf), np.flatnonzero(high), np.flatnonzero(low)])
    zero = np.asarray(centerline.frames_at(np.array([0.0]))[2])[0]
    around = ("around (deg)" if n > 1 else "around the centerline (deg)")
    fig.zero_direction = zero
    grey = np.array(to_rgba(UNREACHED))
    fig.face_pixels, fig.shown, fig.colour_ranges = [], [], []
    axes, rasters = [], {}
    for k, ((name, label, scale), (rect, bar)) in enumerate(zip(panels, _panel_rects(n))):
        ax = fig.add_axes(rect, sharex=axes[0] if axes else None)
        axes.append(ax)
        values = np.asarray(data[name], dtype=float) * scale
        positive = name in POSITIVE_ONLY or name.endswith("_braid_angle_deg")
        shown = reached & (values > 0) if positive else reached
        shape = (max(1, round(rect[3] * PANEL_IN * n * dpi)), max(1, round(rect[2] * WIDTH_IN * dpi)))
        if shape not in rasters:                  # panels of one size share one raster
            raster = face_raster(wrapped, extent, shape)
            rasters[shape] = np.where(raster >= 0, owner[np.maximum(raster, 0)], -1)
        pixels = rasters[shape]
        rgba = np.zeros((*pixels.shape, 4))                 # transparent where no face lies
        on = pixels >= 0
        rgba[on] = grey
        colour_range = None
        if np.any(shown):
            lo, hi = float(values[shown].min()), float(values[shown].max())
            if not (name.startswith("permeability") and lo > 0):   # decades: log colours below
                lo, hi = rounded_limits(lo, hi, zero=name in NON_NEGATIVE, ticks=pictures.bar_ticks)
            # permeability spans decades: log colours
            norm = LogNorm(lo, hi) if name.startswith("permeability") and lo > 0 else Normalize(lo, hi)
            mappable = ScalarMappable(norm=norm, cmap="viridis")
            coloured = np.zeros(pixels.shape, dtype=bool)
            coloured[on] = shown[pixels[on]]
            rgba[coloured] = mappable.to_rgba(values[pixels[coloured]])
            fig.colorbar(mappable, cax=fig.add_axes(bar), label=label)
            colour_range = (lo, hi)
        ax.imshow(rgba, extent=extent, origin="upper", aspect="auto", interpolation="nearest",
                  resample=False)
        fig.face_pixels.append(pixels)
        fig.shown.append(shown)
        fig.colour_ranges.append(colour_range)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(-180.0, 180.0)
        ax.set_yticks([-180, -90, 0, 90, 180])
        ax.set_ylabel(around)
        ax.set_title(label + ("; grey: no yarn" if np.any(~shown) else ""), fontsize=10)
        if k < n - 1:
            ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("centerline arc length from the tip s (m)\naround: 0 deg is the direction "
                        f"({zero[0]:+.2f}, {zero[1]:+.2f}, {zero[2]:+.2f}) from the centerline at the "
                        "tip (mandrel frame), angles right-handed about the centerline", fontsize=9)
    return fig


def write_surface_map(fields, centerline, path, title: str, panels=PANELS,
                      pictures=PICTURE_SETTINGS) -> Path:
    """Write ``surface_map.png`` (or another map of ``panels``) atomically; return its path;
    ``pictures``: ``preform.settings.PictureSettings``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = surface_map_figure(fields, centerline, title, panels, pictures)
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=pictures.map_dpi)
    return Path(path)
