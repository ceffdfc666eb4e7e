"""``plots/surface_map.png``: the surface fields unrolled (issue 16 item 4).

Each field face is drawn at its centerline arc length ``s`` (m, from the tip; horizontal) and its
circumferential position ``phi`` (deg, vertical): the angle about the centerline, measured in the
centerline's own frame ``(N, B)`` at the face's section, so the map is the same for any pose of
the part. Three panels: braid angle, cover factor and thickness, each coloured over the braided
faces only (faces no yarn reached are grey, so the colour range is that of the braid). One
picture shows the whole surface, all sides at once, which no 3D view does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

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
DPI = 130


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


def surface_map_figure(fields, centerline, title: str, panels=PANELS) -> Figure:
    """The unrolled panels (see module docstring); ``panels``: (cell array, label, scale) each."""
    polys = unrolled_coordinates(fields.vertices, fields.faces, centerline)
    data = fields.cell_data
    reached = fields.reached()
    fig = Figure(figsize=(10.0, 3.0 * len(panels)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True))
    fig.suptitle(title)
    for ax, (name, label, scale) in zip(axes, panels):
        values = np.asarray(data[name], dtype=float) * scale
        shown = reached & (values > 0) if name in POSITIVE_ONLY else reached
        if name == "braid_angle_deg" and "layer2_braid_angle_deg" in data:
            label = "braid angle of layer 1 (deg)"     # the stack's totals in the other panels
        if np.any(~shown):
            ax.add_collection(PolyCollection(polys[~shown], facecolors=UNREACHED, edgecolors=UNREACHED,
                                          linewidths=0.1))
        if np.any(shown):
            lo, hi = float(values[shown].min()), float(values[shown].max())
            if hi - lo < 1e-9 * max(1.0, abs(hi)):   # a uniform field: a range around its value
                pad = 0.5 if name == "braid_angle_deg" else max(0.01 * abs(hi), 1e-12)
                lo, hi = lo - pad, hi + pad
            coll = PolyCollection(polys[shown], array=values[shown], cmap="viridis", edgecolors="face",
                                  linewidths=0.1)
            if name.startswith("permeability") and lo > 0:
                from matplotlib.colors import LogNorm   # permeability spans decades: log colours

                coll.set_norm(LogNorm(lo, hi))
            else:
                coll.set_clim(lo, hi)
            ax.add_collection(coll)
            fig.colorbar(coll, ax=ax, label=label, pad=0.01)
        ax.set_ylim(-180.0, 180.0)
        ax.set_yticks([-180, -90, 0, 90, 180])
        ax.set_ylabel("around (deg)")
        ax.set_title(label + ("; grey: no yarn" if np.any(~shown) else ""), fontsize=10)
    s_all = polys[..., 0]
    axes[-1].set_xlim(float(s_all.min()), float(s_all.max()))
    axes[-1].set_xlabel("centerline arc length from the tip s (m)")
    return fig


def write_surface_map(fields, centerline, path, title: str, panels=PANELS) -> Path:
    """Write ``surface_map.png`` (or another map of ``panels``) atomically; return its path."""
    fig = surface_map_figure(fields, centerline, title, panels)
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI)
    return Path(path)
