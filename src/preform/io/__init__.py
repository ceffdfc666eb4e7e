"""Result files of a run (docs/guide/results.md): tables, VTK/PVD, plots, and the surface fields.

:func:`write_results` writes everything into one folder; ``summary.json`` comes last, so its
presence marks a complete set of results. Every file is written atomically (``io.atomic``).
The plotting modules (matplotlib, pyvista) are imported only when a picture is drawn.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

from . import report
from .atomic import atomic_path, atomic_write_bytes, atomic_write_text, safe_folder
from .fe_files import write_structural
from .pictures import LaterJob, PictureJob, PictureWorker, run_jobs
from .rtm_files import write_rtm
from ..drawing import PICTURES as PICTURE_SETTINGS
from .surface import INPUT_VTU, layer_pictures, write_input_mesh_fields, write_surface
from .tables import write_history, write_summary
from .vtk_yarns import write_convergence, write_yarns_vtp, yarn_types_of

SUMMARY = "summary.json"
HISTORY = "history.csv"
YARNS = "yarns.vtp"
PLOTS = "plots"
YARNS_PNG = "braided_mandrel.png"


def plot_history(result, plots_dir, refs=None, steady=None, layers=(), pictures=None):
    """``preform.io.plots.plot_history`` (matplotlib imported on the first call); ``pictures``:
    ``preform.settings.PictureSettings`` (None: the defaults)."""
    from .plots import plot_history as plot

    return plot(result, plots_dir, refs, steady, layers, pictures or PICTURE_SETTINGS)


def plot_yarns_3d(result, path, pictures=None, layer=None, frame=None):
    """``preform.io.plots.plot_yarns_3d`` (pyvista or matplotlib imported on the first call)."""
    from .plots import plot_yarns_3d as plot

    return plot(result, path, pictures or PICTURE_SETTINGS, layer, frame)


def _drawing(settings):
    """The pictures' branch of ``settings`` (``preform.Settings``; None: the defaults)."""
    return PICTURE_SETTINGS if settings is None else settings.pictures


def mandrel_pictures(result, layer_results=()) -> list[tuple]:
    """(file name, Result, (k, direction) or None) of each braided-mandrel picture of a run:
    ``braided_mandrel.png`` for a single layer; for a stack (``layer_results``: the layers above
    the first) ``braided_mandrel_layer<k>.png`` per layer braided, each on its own surface."""
    layers = getattr(result.config, "layers", ()) if result.config is not None else ()
    if not layers:
        return [(YARNS_PNG, result, None)]
    runs = [result, *layer_results]
    return [(f"braided_mandrel_layer{k}.png", run, (k, layers[k - 1].direction))
            for k, run in enumerate(runs, start=1)]


def _picture_jobs(result, fields, out_dir, steady=None, layer_results=(), pictures=None):
    """(matplotlib jobs, 3-D render jobs, the 3-D render jobs of the fields as
    ``io.pictures.LaterJob`` s) of the pictures of a run (``io.pictures``). The render jobs
    include those of ``fields`` (None: the result's alone); the later jobs take the fields as
    the arrays of :func:`fields_arrays`, for a worker started before the fields were mapped.
    ``steady``: the run's steady state (``Analysed.steady``), which the history plots mark
    (None: no mark); ``layer_results``: a stack's layers above the first (their lines, their
    braided-mandrel pictures); ``pictures``: how every picture is drawn
    (``preform.settings.PictureSettings``; None: the defaults)."""
    plots = out_dir / PLOTS
    pictures = pictures or PICTURE_SETTINGS
    drawn, rendered = [], []
    output = getattr(result.config, "output", None)
    if output is not None and not output.pictures:    # [output] pictures = false
        return drawn, rendered, []
    if fields is not None and result.centerline is not None:
        from .maps import MAP

        def surface_map():
            from .maps import write_surface_map
            from .plots import run_title

            return [write_surface_map(fields, result.centerline, plots / MAP,
                                      run_title(result, "Surface fields, unrolled"), pictures=pictures)]

        drawn.append(PictureJob((f"{PLOTS}/{MAP}",), surface_map))
    if result.steps:
        drawn.append(PictureJob((f"{PLOTS}/braid_angle.png", f"{PLOTS}/convergence_length.png"),
                                lambda: plot_history(result, plots, steady=steady,
                                                     layers=layer_results, pictures=pictures)))

    def surface_pictures(shown):
        from .plots import run_label
        from .surface import write_surface_pictures

        return write_surface_pictures(shown, plots, run_label(result), centerline=result.centerline,
                                      pictures=pictures)

    layers = getattr(result.config, "layers", ()) if result.config is not None else ()
    names = tuple(f"{PLOTS}/{name}" for name, *_ in layer_pictures(len(layers)))
    if fields is not None:
        rendered.append(PictureJob(names, lambda: surface_pictures(fields)))
    for name, run, layer in mandrel_pictures(result, layer_results):
        rendered.append(PictureJob((f"{PLOTS}/{name}",), lambda name=name, run=run, layer=layer: [
            plot_yarns_3d(run, plots / name, pictures, layer, result.centerline)]))
    later = [LaterJob(names, lambda arrays: surface_pictures(fields_from_arrays(arrays)))]
    return drawn, rendered, later


#: the SurfaceFields attributes that are plain numbers, sent as 0-d arrays
_FIELD_NUMBERS = ("unmapped_length_m", "edge_length_m", "pool_radius_m")


def fields_arrays(fields) -> dict:
    """``fields`` (preform.analysis.fields.SurfaceFields) as a dict name -> numpy array, to hand to a
    picture worker without pickling (:func:`fields_from_arrays` makes it back)."""
    import numpy as np

    arrays = {"vertices": fields.vertices, "faces": fields.faces, "source_faces": fields.source_faces}
    if fields.jammed is not None:
        arrays["jammed"] = fields.jammed
    arrays.update({name: np.asarray(float(getattr(fields, name))) for name in _FIELD_NUMBERS})
    arrays.update({f"cell_data/{name}": values for name, values in fields.cell_data.items()})
    return {name: np.asarray(values) for name, values in arrays.items()}


def fields_from_arrays(arrays):
    """The SurfaceFields of :func:`fields_arrays`' dict."""
    from ..analysis.fields import SurfaceFields

    cell_data = {name[len("cell_data/"):]: values for name, values in arrays.items()
                 if name.startswith("cell_data/")}
    return SurfaceFields(vertices=arrays["vertices"], faces=arrays["faces"],
                         source_faces=arrays["source_faces"], cell_data=cell_data,
                         jammed=arrays.get("jammed"),
                         **{name: float(arrays[name]) for name in _FIELD_NUMBERS})


def _prepare_folder(out_dir) -> Path:
    """``out_dir`` and its ``plots/`` made safe to write into, without an earlier summary (which
    would mark a set of files being replaced as complete)."""
    out_dir = safe_folder(out_dir)
    safe_folder(out_dir, PLOTS)   # a symlink planted as plots/ is replaced, never followed
    (out_dir / SUMMARY).unlink(missing_ok=True)
    return out_dir


def start_pictures(result, out_dir, settings=None, layer_results=()):
    """Start the 3-D pictures of ``result`` in a worker process before its fields are mapped
    (``preform run`` calls it right after the simulation): the worker imports pyvista and renders
    the braided mandrel while this process maps the fields and writes the data files, then draws
    the surface pictures from the fields :func:`write_results` hands it (``pictures=``).
    Returns the ``io.pictures.PictureWorker`` (without fork it draws them in ``write_results``),
    or None when the folder cannot be prepared (``write_results`` then says why).
    ``settings``: the run's ``preform.Settings`` (None: the defaults; its ``pictures``);
    ``layer_results``: as :func:`write_data` has them."""
    try:
        out_dir = _prepare_folder(out_dir)
    except OSError:
        return None
    _, rendered, later = _picture_jobs(result, None, out_dir, None, layer_results, _drawing(settings))
    return PictureWorker(rendered, later=later, timeout_s=_drawing(settings).worker_timeout_s)


def _relative(path, out_dir) -> str:
    path, out_dir = Path(path).resolve(), Path(out_dir).resolve()
    return path.relative_to(out_dir).as_posix() if path.is_relative_to(out_dir) else str(path)


@dataclass
class Writing:
    """The files of one run as they are written (:func:`write_data`, :func:`draw_pictures`,
    :func:`write_summary_last`): the folder, the paths written so far, what the summary says of
    the RTM and structural files, the pictures still to draw here and the picture worker."""

    out_dir: Path
    written: list
    rtm: dict
    structural: dict
    to_draw: list
    worker: object
    failed: list = field(default_factory=list)


def write_data(analysed, out_dir, *, background=False, pictures=None) -> Writing:
    """Write the data files of ``analysed`` (``preform.analysis.derived.Analysed``) into
    ``out_dir``: ``history.csv``, ``yarns.vtp``, ``convergence.pvd``, a stack's ``layer{k}/``,
    the surface files, ``rtm/`` and ``fe/`` where they were analysed; an earlier summary is
    removed first. The pictures are set up, not drawn (:func:`draw_pictures`).

    background : render the 3-D pictures in a worker process (``io.pictures.PictureWorker``),
        else one after the other in :func:`draw_pictures`
    pictures : the worker :func:`start_pictures` started for ``analysed.result`` (then
        ``background`` is not looked at): it gets the fields now; stopped if writing fails
    """
    result, fields = analysed.result, analysed.fields
    try:
        out_dir = _prepare_folder(out_dir)
        drawn, rendered, _ = _picture_jobs(result, fields, out_dir, analysed.steady,
                                           analysed.layer_results, analysed.pictures)
        if pictures is not None:       # the early worker renders the fields too
            rendered = []
            pictures.send(fields_arrays(fields) if fields is not None else None)
        else:
            pictures = PictureWorker(rendered if background else [],
                                     timeout_s=(analysed.pictures or PICTURE_SETTINGS).worker_timeout_s)
            if background:             # the worker's (drawn by its finish() where it cannot fork)
                rendered = []
        written = [write_history(result, out_dir / HISTORY),
                   write_yarns_vtp(result.yarns, out_dir / YARNS, yarn_types_of(result.config)),
                   *write_convergence(result.snapshots, out_dir)]
        for k, layer in enumerate(analysed.layer_results, start=2):
            folder = safe_folder(out_dir, f"layer{k}")
            written += [write_history(layer, folder / HISTORY),
                        write_yarns_vtp(layer.yarns, folder / YARNS, yarn_types_of(layer.config))]
        if fields is not None:
            written += [Path(p) for p in write_surface(fields, out_dir, pictures=False)]
            if analysed.input_mesh_fields is not None:
                written.append(write_input_mesh_fields(analysed.input_mesh_fields, out_dir))
            else:   # not left over from an earlier run into this folder
                (out_dir / INPUT_VTU).unlink(missing_ok=True)
        if analysed.rtm is not None:
            written += write_rtm(analysed.rtm, out_dir)
            rtm = analysed.rtm.said()
        else:
            rtm = {"written": False, "reason": analysed.rtm_reason}
        paths, structural = write_structural(analysed.structural, out_dir)
        written += paths
        if analysed.structural is None:
            structural = {"written": False, "reason": analysed.structural_reason}
    except BaseException:
        if pictures is not None:
            pictures.stop()
        raise
    return Writing(out_dir=out_dir, written=written, rtm=rtm, structural=structural,
                   to_draw=drawn + rendered, worker=pictures)


def draw_pictures(writing: Writing) -> Writing:
    """Draw the pictures left to this process, then wait for the worker's; a picture that cannot
    be drawn is reported (a RuntimeWarning, and the summary's ``pictures.failed``) and never
    stops the rest."""
    try:
        drawn_here, failed = run_jobs(writing.to_draw)
    except BaseException:
        writing.worker.stop()
        raise
    more, more_failed = writing.worker.finish()
    drawn_here, failed = drawn_here + more, failed + more_failed
    for text in failed:
        warnings.warn(f"{text}; the data files are written", RuntimeWarning, stacklevel=3)
    writing.written += [p for p in drawn_here if Path(p).is_file()]
    writing.to_draw, writing.failed = [], failed
    return writing


def write_summary_last(analysed, writing: Writing, extra=None) -> list[Path]:
    """Write ``summary.json``: ``analysed.summary`` with the files written, what was said of the
    RTM and structural files, the pictures not drawn, a stack's ``layers`` and ``extra`` (a
    caller's, e.g. the stage timings) merged in. Returns every path written, summary.json last."""
    summary = writing.out_dir / SUMMARY
    files = [_relative(p, writing.out_dir) for p in [*writing.written, summary]]
    said = {"files": files, "rtm": writing.rtm, "structural": writing.structural,
            "pictures": {"failed": writing.failed}}
    if analysed.layers is not None:
        said["layers"] = analysed.layers
    said.update(extra or {})
    written = [*writing.written, write_summary({**analysed.summary, **said}, summary)]
    report.report_hook(writing.out_dir)   # report.html, the page of the finished folder
    return written


def write_results(analysed, out_dir, *, background=False, pictures=None, extra=None) -> list[Path]:
    """Write all result files of ``analysed`` (``preform.analysis.derived.Analysed``: a run with
    everything derived from it) into ``out_dir``, created if missing: :func:`write_data`, then
    :func:`draw_pictures`, then :func:`write_summary_last`. Returns the paths written,
    summary.json last. ``preform.pipeline.write_results`` analyses a Result and its fields and
    calls this."""
    writing = draw_pictures(write_data(analysed, out_dir, background=background, pictures=pictures))
    return write_summary_last(analysed, writing, extra)


__all__ = [
    "write_results",
    "write_data",
    "draw_pictures",
    "write_summary_last",
    "start_pictures",
    "write_summary",
    "write_history",
    "write_yarns_vtp",
    "write_convergence",
    "plot_history",
    "plot_yarns_3d",
    "atomic_path",
    "atomic_write_text",
    "atomic_write_bytes",
    "safe_folder",
]
