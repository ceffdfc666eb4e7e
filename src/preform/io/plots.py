"""PNG plots of a run (docs/guide/results.md, ``plots/*.png``).

Drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas, never through pyplot, so
they work headless whatever ``MPLBACKEND`` says and leave no global figure state behind.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .atomic import atomic_path

GROUP_COLOURS = {0: "tab:blue", 1: "tab:red"}   # warp, weft
#: size (inches) and fixed margins (figure fractions) of the history figures: a fixed layout,
#: as matplotlib's constrained layout measured every tick label again (0.3 s a figure)
HISTORY_SIZE = (7.2, 4.4)
HISTORY_MARGINS = dict(left=0.105, right=0.975, bottom=0.115, top=0.865)
GROUP_NAMES = {0: "warp", 1: "weft"}
DPI = 150
#: the 3D picture draws at most this many points per yarn (every k-th point beyond that)
MAX_POINTS_PER_YARN = 2000


def _figure(**kwargs):
    """A matplotlib Figure (matplotlib imported here, not with the module: the picture worker
    renders with VTK and needs only this module's labels)."""
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def _save(fig: Figure, path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI)
    return Path(path)


def _column(result, name):
    return np.asarray(result.history[name], dtype=np.float64)


def run_label(result) -> str:
    """``case · model · status`` of a run (an unfinished run says so)."""
    config = result.config
    case = Path(config.source).stem if config is not None and config.source else "run"
    model = config.model.kind if config is not None else "?"
    status = result.status if result.status == "done" else f"{result.status.upper()}: partial results"
    return f"{case} · {model} model · {status}"


def run_title(result, what: str) -> str:
    """``what`` over the run's label (:func:`run_label`)."""
    return f"{what}\n{run_label(result)}"


#: the start-up rows left out of the axis range: while the yarns wind from their tie points to
#: tangency the fell points stay put and the laid angle climbs from 0 (a spike that squashes
#: the interesting range); the range starts where the braided length has grown by this fraction
START_FRACTION = 1e-3


def start_rows(length) -> int:
    """Rows of the wind-up at the start of a history (see START_FRACTION), at least one."""
    length = np.asarray(length, dtype=float)
    if len(length) < 2:
        return 0
    grown = np.nonzero(length > length[0] + START_FRACTION * (length.max() - length[0]))[0]
    return int(grown[0]) + 1 if len(grown) else 1


def _range(ax, skip, *columns):
    values = np.concatenate([np.asarray(c, dtype=float)[skip:] for c in columns])
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return
    lo, hi = float(values.min()), float(values.max())
    pad = max(0.08 * (hi - lo), 1e-3 * max(abs(hi), 1.0), 1e-6)
    ax.set_ylim(lo - pad, hi + pad)


def _steady_mark(ax, steady):
    """A dotted line where steady state starts, or a note that the run did not reach it."""
    if not steady:
        return
    if steady.get("reached"):
        ax.axvline(steady["braided_length_m"], color="0.3", linestyle=":", linewidth=1.0,
                   label=f"steady from {steady['braided_length_m']:.2f} m")
    else:
        ax.text(0.02, 0.03, "steady state not reached", transform=ax.transAxes, color="0.3",
                fontsize=9, ha="left", va="bottom")


def braid_angle_figure(result, refs=None, steady=None) -> Figure:
    """Warp and weft braid angle (deg) against braided length (m), with Ko's angle (``refs``, a
    :class:`preform.reference.References`) and the start of steady state (``steady``)."""
    fig = _figure(figsize=HISTORY_SIZE)
    fig.subplots_adjust(**HISTORY_MARGINS)
    ax = fig.add_subplot()
    length = _column(result, "braided_length_m")
    warp, weft = _column(result, "braid_angle_warp_deg"), _column(result, "braid_angle_weft_deg")
    ax.plot(length, warp, color=GROUP_COLOURS[0], label="warp")
    ax.plot(length, weft, color=GROUP_COLOURS[1], label="weft", linestyle="--")
    ko = None if refs is None else (refs.ko_deg, refs.s, "Ko (quasi-static)")
    _finish(ax, result, length, [warp, weft], ko, steady, "braid angle α (deg)",
            "Braid angle at the fell points")
    return fig


def _finish(ax, result, length, columns, reference, steady, ylabel, title):
    """The shared part of the history figures: the quasi-static reference curve (``reference`` =
    (values, s, label) or None), the steady-state mark, the range without the wind-up, labels."""
    if reference and len(length):
        values, s, label = reference
        ref = np.interp(length, s, values)
        ax.plot(length, ref, color="0.45", linewidth=1.0, label=label)
        columns = [*columns, ref]
    _steady_mark(ax, steady)
    _range(ax, start_rows(length), *columns)
    ax.set_xlabel("braided length L (m)")
    ax.set_ylabel(ylabel)
    ax.set_title(run_title(result, title))
    ax.grid(True, alpha=0.3)
    ax.legend()


def convergence_length_figure(result, refs=None, steady=None) -> Figure:
    """Mean convergence length (m) with its min-max band over yarns, against braided length (m),
    with the kinematic steady value H_inf (``refs``) and the start of steady state."""
    fig = _figure(figsize=HISTORY_SIZE)
    fig.subplots_adjust(**HISTORY_MARGINS)
    ax = fig.add_subplot()
    length = _column(result, "braided_length_m")
    lo, hi = _column(result, "convergence_length_min_m"), _column(result, "convergence_length_max_m")
    ax.fill_between(length, lo, hi, color="tab:green", alpha=0.25, label="min – max over yarns")
    ax.plot(length, _column(result, "convergence_length_mean_m"), color="tab:green", label="mean")
    h_inf = None if refs is None else (refs.h_inf, refs.s, "H∞ (kinematic, quasi-static)")
    _finish(ax, result, length, [lo, hi], h_inf, steady, "convergence length H (m)",
            "Convergence zone length")
    return fig


def history_references(result, n=60):
    """Ko and H_inf along the braided part (preform.reference), or None without geometry."""
    if result.mandrel is None or result.centerline is None or not result.steps:
        return None
    from ..geometry.centerline import section_perimeters
    from ..reference import references

    end = min(float(np.max(_column(result, "braided_length_m"))) * 1.05, result.centerline.length)
    s = np.linspace(0.0, max(end, 1e-6), n)
    perimeter = section_perimeters(result.mandrel, result.centerline, s)
    ok = perimeter > 0
    if np.count_nonzero(ok) < 2:
        return None
    return references(result.config, s[ok], perimeter[ok])


def plot_history(result, plots_dir, refs=None, steady_settings=None) -> list[Path]:
    """Write ``braid_angle.png`` and ``convergence_length.png`` in ``plots_dir``; return the paths.

    refs : preform.reference.References, or None to compute them from the result's geometry.
    steady_settings : the steady-state reading's (``steady.SteadySettings``; None: the defaults)
    """
    from ..steady import STEADY, steady_state

    plots_dir = Path(plots_dir)
    refs = refs if refs is not None else history_references(result)
    steady = steady_state(result.history, steady_settings or STEADY) if result.steps else None
    return [_save(braid_angle_figure(result, refs, steady), plots_dir / "braid_angle.png"),
            _save(convergence_length_figure(result, refs, steady), plots_dir / "convergence_length.png")]


def yarns_figure(result) -> Figure:
    """3D view of the deposited yarns (mandrel frame, m), warp blue, weft red."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    yarns = result.yarns
    fig = _figure(figsize=(6.4, 6.4), layout="constrained")
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
    """Write the 3D picture of the braided mandrel (``braided_mandrel.png``).

    The mandrel with its yarns rendered from two sides (``io.render3d``); where off-screen
    rendering fails (no OpenGL) or there is no mandrel, a matplotlib picture of the yarns alone
    with a warning saying why.
    """
    title = run_title(result, "Braided mandrel").replace("\n", " – ")
    if result.mandrel is not None:
        from .render3d import render_braided_mandrel

        try:
            with atomic_path(path) as tmp:
                render_braided_mandrel(result, tmp, title)
            return Path(path)
        except Exception as error:  # noqa: BLE001 - any VTK/GL failure: fall back to matplotlib
            warnings.warn(f"{path}: off-screen rendering failed ({type(error).__name__}: {error}); "
                          "drew the yarns without the mandrel", RuntimeWarning, stacklevel=2)
    fig = yarns_figure(result)
    fig.axes[0].set_title(title)
    return _save(fig, path)
