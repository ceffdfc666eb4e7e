"""PNG plots of a run (docs/guide/results.md, ``plots/*.png``).

Drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas, never through pyplot, so
they work headless whatever ``MPLBACKEND`` says and leave no global figure state behind.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..drawing import PICTURES as PICTURE_SETTINGS
from .atomic import atomic_path

GROUP_COLOURS = {0: "tab:blue", 1: "tab:red"}   # warp, weft
#: the history figures' fixed margins (figure fractions; their size and resolution are
#: ``PictureSettings.history_size_in`` and ``history_dpi``): a fixed layout, as matplotlib's
#: constrained layout measured every tick label again (0.3 s a figure).
#: The two panels of a history figure (left, bottom, width, height; figure fractions): the
#: quantity over the whole run, and below it its distance from the steady value (log scale)
HISTORY_MAIN = (0.115, 0.39, 0.86, 0.51)
HISTORY_DEV = (0.115, 0.075, 0.86, 0.22)
GROUP_NAMES = {0: "warp", 1: "weft"}


def _figure(**kwargs):
    """A matplotlib Figure (matplotlib imported here, not with the module: the picture worker
    renders with VTK and needs only this module's labels)."""
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def _save(fig: Figure, path, dpi) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
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


#: colours of the layers above the first in a layered run's history (one line per layer)
LAYER_COLOURS = ("tab:purple", "tab:brown", "tab:olive", "tab:cyan", "tab:pink")


def start_rows(length, fraction: float = PICTURE_SETTINGS.start_fraction) -> int:
    """Rows of the wind-up at the start of a history, at least one: while the yarns wind from
    their tie points to tangency the fell points stay put and the laid angle climbs from 0; the
    wind-up ends where the braided length has grown by ``fraction`` of the run."""
    length = np.asarray(length, dtype=float)
    if len(length) < 2:
        return 0
    grown = np.nonzero(length > length[0] + fraction * (length.max() - length[0]))[0]
    return int(grown[0]) + 1 if len(grown) else 1


def nice_step(span: float, ticks: int = 6) -> float:
    """A round tick step (1, 2 or 5 times a power of ten) giving about ``ticks`` ticks over ``span``."""
    if not span > 0:
        return 1.0
    raw = span / ticks
    power = 10.0 ** np.floor(np.log10(raw))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * power >= raw:
            return float(m * power)
    return float(10.0 * power)


def _range(ax, zero, *columns):
    """Y limits over the whole run (start-up included), on round ticks; from 0 when ``zero``
    (a quantity that is >= 0: an angle, a length)."""
    values = np.concatenate([np.atleast_1d(np.asarray(c, dtype=float)) for c in columns])
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return
    lo, hi = float(values.min()), float(values.max())
    if zero:
        lo = min(lo, 0.0)
    step = nice_step(max(hi - lo, 1e-6 * max(abs(hi), 1.0)))
    lo_t, hi_t = np.floor(lo / step) * step, np.ceil(hi / step) * step
    if hi_t - hi < 0.02 * (hi_t - lo_t):   # room above the highest curve
        hi_t += step
    ax.set_ylim(lo_t, hi_t)


def _pixel(ax, dpi) -> float:
    """One pixel of the axes' height in data units (the figure drawn at ``dpi``)."""
    lo, hi = ax.get_ylim()
    height = ax.get_position().height * ax.figure.get_size_inches()[1] * dpi
    return (hi - lo) / max(height, 1.0)


def flat_after(ax, length, columns, start, pictures=PICTURE_SETTINGS) -> bool:
    """Whether every curve of ``columns`` moves by at most ``pictures.flat_pixels`` pixels of
    ``ax`` (drawn at ``pictures.history_dpi``) from the braided length ``start`` on."""
    after = np.asarray(length) >= start
    if not np.any(after):
        return False
    spread = max(float(np.ptp(np.asarray(c, dtype=float)[after])) for c in columns)
    return spread <= pictures.flat_pixels * _pixel(ax, pictures.history_dpi)


def _steady_mark(ax, steady, length, columns, asymptotes, unit, pictures):
    """A dotted line where steady state starts and the asymptote the run approaches, if every
    curve is flat on this plot from there on; a note otherwise. ``asymptotes``: the steady values
    of this plot's quantity ({label: value})."""
    if not steady:
        return
    fits = steady.get("fits") or {}
    if steady.get("reached"):
        start = steady["braided_length_m"]
        for name, value in asymptotes.items():
            ax.axhline(value, color="0.2", linestyle="-.", linewidth=0.8,
                       label=f"steady {name}: {value:.{2 if unit == 'deg' else 3}f} {unit} (asymptote)")
        if flat_after(ax, length, columns, start, pictures):
            ax.axvline(start, color="0.3", linestyle=":", linewidth=1.2, label=f"steady from {start:.2f} m")
        else:
            _note(ax, f"within the steady tolerances from {start:.2f} m (still changing at this scale)")
    else:
        heading = ", ".join(f"{value:.{2 if unit == 'deg' else 3}f}" for value in asymptotes.values())
        _note(ax, "steady state not reached" + (f": heading for {heading} {unit}" if heading else
                                                 ": no value it approaches can be read yet"))


def _note(ax, text):
    ax.text(0.02, 0.97, text, transform=ax.transAxes, color="0.2", fontsize=9, ha="left", va="top",
            bbox=dict(facecolor="white", edgecolor="none", alpha=0.8))


def _credible(fit) -> bool:
    """Whether a steady-state fit names the value the run approaches: it describes the run and
    its transient decays inside the fit window (else the asymptote is an extrapolation)."""
    return bool(fit.get("describes_run", True) and fit.get("decays_in_window", True)
                and np.isfinite(fit.get("asymptote", np.nan)))


def _asymptotes(steady, names):
    """{label: asymptote} of the fitted quantities ``names`` ({fit name: label}) of ``steady``."""
    fits = (steady or {}).get("fits") or {}
    out = {label: float(fits[name]["asymptote"]) for name, label in names.items()
           if name in fits and _credible(fits[name])}
    if len(set(round(v, 2) for v in out.values())) == 1 and len(out) > 1:
        out = {"/".join(out): next(iter(out.values()))}   # warp and weft alike: one line
    return out


def _layer_label(k):
    return f"layer {k}"


def layer_length(layer):
    """(x (steps,) m, note): where a layer's fell points are, as arc length from the tip (layer
    1's braided length): a layer braided ``backward`` counts its braided length from the far
    end along its reversed centerline, so it is drawn at ``length - L``."""
    L = _column(layer, "braided_length_m")
    config = layer.config
    if (config is not None and getattr(config, "layers", ()) and config.layers[-1].direction == "backward"
            and layer.centerline is not None):
        return float(layer.centerline.length) - L, ", braided from the far end"
    return L, ""


def _layer_xlim(ax, layers):
    """Widen the x axis to the layers' extents (they may lie beyond layer 1's braid)."""
    ends = [float(np.max(layer_length(layer)[0])) for layer in layers if layer.steps]
    if ends:
        lo, hi = ax.get_xlim()
        ax.set_xlim(lo, max(hi, 1.02 * max(ends)))


def braid_angle_figure(result, refs=None, steady=None, layers=(), pictures=PICTURE_SETTINGS) -> Figure:
    """Warp and weft braid angle (deg) against braided length (m), the spread round the section
    (least to largest angle over the yarns, a band), Ko's angle (``refs``, a
    :class:`preform.reference.References`), the asymptote and start of steady state
    (``steady``), and the mean angle of each layer above the first (``layers``: their Results);
    ``pictures``: ``preform.settings.PictureSettings``."""
    fig = _figure(figsize=pictures.history_size_in)
    fig.layered = bool(layers)
    ax = fig.add_axes(HISTORY_MAIN)
    length = _column(result, "braided_length_m")
    warp, weft = _column(result, "braid_angle_warp_deg"), _column(result, "braid_angle_weft_deg")
    columns = [warp, weft]
    suffix = f", {_layer_label(1)}" if layers else ""
    if "braid_angle_min_deg" in result.history:
        lo, hi = _column(result, "braid_angle_min_deg"), _column(result, "braid_angle_max_deg")
        ax.fill_between(length, lo, hi, color="0.6", alpha=0.35, linewidth=0.6, edgecolor="0.5",
                        label=f"spread round the section, least – largest over the yarns "
                              f"(at the end {lo[-1]:.1f} – {hi[-1]:.1f} deg){suffix}")
        columns += [lo, hi]
    ax.plot(length, warp, color=GROUP_COLOURS[0], label="warp" + suffix)
    ax.plot(length, weft, color=GROUP_COLOURS[1], label="weft" + suffix, linestyle="--")
    for k, layer in enumerate(layers, start=2):
        if not layer.steps:
            continue
        L_k, note = layer_length(layer)
        mean = 0.5 * (_column(layer, "braid_angle_warp_deg") + _column(layer, "braid_angle_weft_deg"))
        ax.plot(L_k, mean, color=LAYER_COLOURS[(k - 2) % len(LAYER_COLOURS)],
                label=f"{_layer_label(k)} (warp and weft mean{note})")
        columns.append(mean)
    ko = None if refs is None else (refs.ko_deg, refs.s, "Ko (quasi-static)")
    _finish(ax, result, length, columns, [warp, weft], ko, steady,
            _asymptotes(steady, {"warp": "warp", "weft": "weft"}), "deg", "braid angle α (deg)",
            "Braid angle at the fell points", pictures)
    _deviation(fig, ax, length, {"warp": warp, "weft": weft}, steady, "deg", pictures)
    _layer_xlim(ax, layers)
    return fig


def _finish(ax, result, length, columns, judged, reference, steady, asymptotes, unit, ylabel, title,
            pictures):
    """The shared part of the history figures: the quasi-static reference curve (``reference`` =
    (values, s, label) or None), the whole run's range from 0, the steady-state mark (judged flat
    on ``judged``), labels."""
    if reference and len(length):
        values, s, label = reference
        ref = np.interp(length, s, values)
        ax.plot(length, ref, color="0.45", linewidth=1.0, label=label)
        columns = [*columns, ref]
    _range(ax, True, *columns, *asymptotes.values())
    if len(length):
        ax.set_xlim(0.0, float(np.max(length)) * 1.02 if np.max(length) > 0 else 1.0)
    _steady_mark(ax, steady, length, judged, asymptotes, unit, pictures)
    ax.set_ylabel(ylabel)
    ax.set_title(run_title(result, title))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)


#: the deviation panel's floor, as a fraction of the tolerance (exact agreement drawn there)
DEVIATION_FLOOR = 1e-3


def _deviation(fig, ax, length, series, steady, unit, pictures):
    """The lower panel: each series' distance from its fitted asymptote (log scale) with the
    steady tolerance as a line, so where the curve enters the tolerance band (steady state) and
    how fast it still approaches the steady value can be read; the run's own axis below."""
    dev = fig.add_axes(HISTORY_DEV, sharex=ax)
    fig.deviation_axes = dev
    ax.tick_params(labelbottom=False)
    dev.set_xlabel("braided length L (m)" if not fig.layered else
                   "arc length from the tip (m): layer 1's braided length L")
    fits = (steady or {}).get("fits") or {}
    shown = [name for name in series if name in fits and _credible(fits[name])]
    if not shown:
        why = ("the run is too short to fit" if not fits else
               "its later half shows no exponential approach to one value\n(still changing "
               "slowly, a changing section, a bend)")
        dev.text(0.5, 0.5, f"no steady value to compare with: {why}",
                 transform=dev.transAxes, ha="center", va="center", color="0.3", fontsize=9)
        dev.set_yticks([])
        return
    tol = float(fits[shown[0]]["tolerance"])
    floor = DEVIATION_FLOOR * tol
    skip = start_rows(length, pictures.start_fraction)
    for name in shown:
        d = np.abs(np.asarray(series[name], dtype=float) - float(fits[name]["asymptote"]))
        colour = {"warp": GROUP_COLOURS[0], "weft": GROUP_COLOURS[1]}.get(name, "tab:green")
        dev.semilogy(length[skip:], np.maximum(d[skip:], floor), color=colour,
                     linestyle="--" if name == "weft" else "-", linewidth=1.0)
    dev.axhline(tol, color="tab:orange", linewidth=1.0,
                label=f"steady tolerance {tol:.2g} {unit}" if unit == "deg" else f"steady tolerance {tol * 1e3:.1f} mm (1 %)")
    if steady.get("reached"):
        dev.axvline(steady["braided_length_m"], color="0.3", linestyle=":", linewidth=1.2)
    from matplotlib.ticker import FuncFormatter, NullFormatter

    lo, hi = dev.get_ylim()
    dev.set_ylim(min(lo, tol / 3.0), max(hi, 3.0 * tol))
    dev.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    dev.yaxis.set_minor_formatter(NullFormatter())
    dev.set_ylabel(f"|Δ| to steady ({unit})", fontsize=9)
    dev.grid(True, alpha=0.3, which="both")
    dev.legend(loc="upper right", fontsize=8)


def convergence_length_figure(result, refs=None, steady=None, layers=(), pictures=PICTURE_SETTINGS) -> Figure:
    """Mean convergence length (m) with its min-max band over yarns, against braided length (m),
    with the kinematic steady value H_inf (``refs``), the asymptote and start of steady state,
    and the mean of each layer above the first (``layers``); ``pictures``: as
    :func:`braid_angle_figure`'s."""
    fig = _figure(figsize=pictures.history_size_in)
    fig.layered = bool(layers)
    ax = fig.add_axes(HISTORY_MAIN)
    length = _column(result, "braided_length_m")
    lo, hi = _column(result, "convergence_length_min_m"), _column(result, "convergence_length_max_m")
    mean = _column(result, "convergence_length_mean_m")
    suffix = f", {_layer_label(1)}" if layers else ""
    skip = start_rows(length, pictures.start_fraction)
    width = float(np.max(hi[skip:] - lo[skip:])) if len(lo) > skip else 0.0
    # edged, so that a narrow band still shows; its width is in the legend
    apart = f"up to {width * 1e3:.1f} mm apart" if width >= 5e-5 else "under 0.1 mm apart: on the mean's line"
    ax.fill_between(length, lo, hi, color="tab:green", alpha=0.3, linewidth=0.6, edgecolor="tab:green",
                    label=f"min – max over yarns ({apart}){suffix}")
    ax.plot(length, mean, color="tab:green", label="mean" + suffix, linewidth=1.0)
    columns = [lo, hi]
    for k, layer in enumerate(layers, start=2):
        if not layer.steps:
            continue
        L_k, note = layer_length(layer)
        ax.plot(L_k, _column(layer, "convergence_length_mean_m"),
                color=LAYER_COLOURS[(k - 2) % len(LAYER_COLOURS)], label=f"{_layer_label(k)} mean{note}")
        columns.append(_column(layer, "convergence_length_mean_m"))
    h_inf = None if refs is None else (refs.h_inf, refs.s, "H∞ (kinematic, quasi-static)")
    _finish(ax, result, length, columns, [mean], h_inf, steady,
            _asymptotes(steady, {"convergence_length_m": "H"}), "m", "convergence length H (m)",
            "Convergence zone length", pictures)
    _deviation(fig, ax, length, {"convergence_length_m": mean}, steady, "m", pictures)
    _layer_xlim(ax, layers)
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


def plot_history(result, plots_dir, refs=None, steady=None, layers=(),
                 pictures=PICTURE_SETTINGS) -> list[Path]:
    """Write ``braid_angle.png`` and ``convergence_length.png`` in ``plots_dir``; return the paths.

    refs : preform.reference.References, or None to compute them from the result's geometry.
    steady : the run's steady state as the analysis read it (``Analysed.steady``: the dict of
        ``analysis.steady.steady_state``), marked on both plots; None: no mark
    layers : the Results of the layers above the first (a line each)
    pictures : ``preform.settings.PictureSettings``
    """
    plots_dir = Path(plots_dir)
    refs = refs if refs is not None else history_references(result)
    dpi = pictures.history_dpi
    return [_save(braid_angle_figure(result, refs, steady, layers, pictures),
                  plots_dir / "braid_angle.png", dpi),
            _save(convergence_length_figure(result, refs, steady, layers, pictures),
                  plots_dir / "convergence_length.png", dpi)]


def yarns_figure(result, pictures=PICTURE_SETTINGS) -> Figure:
    """3D view of the deposited yarns (mandrel frame, m), warp blue, weft red, at most
    ``pictures.fallback_points_per_yarn`` points a yarn."""
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
            stride = max(1, int(np.ceil(len(yarn) / pictures.fallback_points_per_yarn)))
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


def plot_yarns_3d(result, path, pictures=PICTURE_SETTINGS, layer=None, frame=None) -> Path:
    """Write the 3D picture of the braided mandrel (``braided_mandrel.png``, or a layer's).

    The mandrel with its yarns rendered from two sides (``io.render3d``); where off-screen
    rendering fails (no OpenGL) or there is no mandrel, a matplotlib picture of the yarns alone
    with a warning saying why. ``layer``: (k, direction) of a stack's layer, named in the title;
    ``frame``: the mandrel's centerline the views are oriented by (``render_braided_mandrel``).
    """
    what = "Braided mandrel"
    if layer is not None:
        k, direction = layer
        what += f", layer {k} ({direction}" + (", over the layers below)" if k > 1 else ")")
    title = run_title(result, what).replace("\n", " – ")
    if result.mandrel is not None:
        from .render3d import render_braided_mandrel

        try:
            with atomic_path(path) as tmp:
                render_braided_mandrel(result, tmp, title, pictures, frame)
            return Path(path)
        except Exception as error:  # noqa: BLE001 - any VTK/GL failure: fall back to matplotlib
            warnings.warn(f"{path}: off-screen rendering failed ({type(error).__name__}: {error}); "
                          "drew the yarns without the mandrel", RuntimeWarning, stacklevel=2)
    fig = yarns_figure(result, pictures)
    fig.axes[0].set_title(title)
    return _save(fig, path, pictures.history_dpi)
