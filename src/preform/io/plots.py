"""PNG plots of a run (DESIGN.md §1 ``plots/*.png``).

Drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas, never through pyplot, so
they work headless whatever ``MPLBACKEND`` says and leave no global figure state behind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .atomic import atomic_path

GROUP_COLOURS = {0: "tab:blue", 1: "tab:red"}   # warp, weft
GROUP_NAMES = {0: "warp", 1: "weft"}
DPI = 150
#: the 3D picture draws at most this many points per yarn (every k-th point beyond that)
MAX_POINTS_PER_YARN = 2000


def _save(fig: Figure, path) -> Path:
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI)
    return Path(path)


def _column(result, name):
    return np.asarray(result.history[name], dtype=np.float64)


def braid_angle_figure(result) -> Figure:
    """Warp and weft braid angle (deg) against braided length (m)."""
    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    length = _column(result, "braided_length_m")
    ax.plot(length, _column(result, "braid_angle_warp_deg"), color=GROUP_COLOURS[0], label="warp")
    ax.plot(length, _column(result, "braid_angle_weft_deg"), color=GROUP_COLOURS[1], label="weft",
            linestyle="--")
    ax.set_xlabel("braided length L (m)")
    ax.set_ylabel("braid angle α (deg)")
    ax.set_title("Braid angle at the fell points")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return fig


def convergence_length_figure(result) -> Figure:
    """Mean convergence length (m) with its min-max band over yarns, against braided length (m)."""
    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    length = _column(result, "braided_length_m")
    ax.fill_between(length, _column(result, "convergence_length_min_m"),
                    _column(result, "convergence_length_max_m"), color="tab:green", alpha=0.25,
                    label="min – max over yarns")
    ax.plot(length, _column(result, "convergence_length_mean_m"), color="tab:green", label="mean")
    ax.set_xlabel("braided length L (m)")
    ax.set_ylabel("convergence length H (m)")
    ax.set_title("Convergence zone length")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return fig


def plot_history(result, plots_dir) -> list[Path]:
    """Write ``braid_angle.png`` and ``convergence_length.png`` in ``plots_dir``; return the paths."""
    plots_dir = Path(plots_dir)
    return [_save(braid_angle_figure(result), plots_dir / "braid_angle.png"),
            _save(convergence_length_figure(result), plots_dir / "convergence_length.png")]


def yarns_figure(result) -> Figure:
    """3D view of the deposited yarns (mandrel frame, m), warp blue, weft red."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    yarns = result.yarns
    fig = Figure(figsize=(6.4, 6.4), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    points = np.asarray(yarns.points, dtype=np.float64).reshape(-1, 3)
    drawn = False
    for group in (0, 1):
        paths = []
        for k in np.flatnonzero(np.asarray(yarns.group) == group):
            yarn = yarns.yarn(k)
            stride = max(1, int(np.ceil(len(yarn) / MAX_POINTS_PER_YARN)))
            if len(yarn) >= 2:
                paths.append(np.vstack([yarn[::stride], yarn[-1:]]))
        if paths:
            ax.add_collection3d(Line3DCollection(paths, colors=GROUP_COLOURS[group], linewidths=0.6,
                                                 label=GROUP_NAMES[group]))
            drawn = True
    if len(points):
        lo, hi = points.min(axis=0), points.max(axis=0)
        centre, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-9)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title("Deposited yarns (mandrel frame)")
    if drawn:
        ax.legend(loc="upper left")
    return fig


def plot_yarns_3d(result, path) -> Path:
    """Write the 3D picture of the braided mandrel (``braided_mandrel.png``)."""
    return _save(yarns_figure(result), path)
