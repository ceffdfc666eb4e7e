"""Result files of a run (docs/guide/results.md): tables, VTK/PVD, plots, and the surface fields.

:func:`write_results` writes everything into one folder; ``summary.json`` comes last, so its
presence marks a complete set of results. Every file is written atomically (``io.atomic``).
The plotting modules (matplotlib, pyvista) are imported only when a picture is drawn.
"""

from __future__ import annotations

from pathlib import Path

from .atomic import atomic_path, atomic_write_bytes, atomic_write_text, safe_folder
from .tables import write_history, write_summary
from .vtk_yarns import write_convergence, write_yarns_vtp

SUMMARY = "summary.json"
HISTORY = "history.csv"
YARNS = "yarns.vtp"
PLOTS = "plots"
YARNS_PNG = "braided_mandrel.png"


def plot_history(result, plots_dir, refs=None, steady_settings=None, layers=()):
    """``preform.io.plots.plot_history`` (matplotlib imported on the first call)."""
    from .plots import plot_history as plot

    return plot(result, plots_dir, refs, steady_settings, layers)


def plot_yarns_3d(result, path):
    """``preform.io.plots.plot_yarns_3d`` (pyvista or matplotlib imported on the first call)."""
    from .plots import plot_yarns_3d as plot

    return plot(result, path)


def _picture_jobs(result, fields, out_dir, settings=None, layer_results=()):
    """(matplotlib jobs, 3-D render jobs, the 3-D render jobs of the fields as
    ``io.pictures.LaterJob`` s) of the pictures of a run (``io.pictures``). The render jobs
    include those of ``fields`` (None: the result's alone); the later jobs take the fields as
    the arrays of :func:`fields_arrays`, for a worker started before the fields were mapped.
    ``settings``: ``preform.Settings`` (None: the defaults), the steady state the history
    plots mark."""
    from .pictures import LaterJob, PictureJob
    from .surface import PICTURES

    plots = out_dir / PLOTS
    steady = None if settings is None else settings.steady
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
                                      run_title(result, "Surface fields, unrolled"))]

        drawn.append(PictureJob((f"{PLOTS}/{MAP}",), surface_map))
    if result.steps:
        drawn.append(PictureJob((f"{PLOTS}/braid_angle.png", f"{PLOTS}/convergence_length.png"),
                                lambda: plot_history(result, plots, steady_settings=steady,
                                                     layers=layer_results)))

    def surface_pictures(shown):
        from .plots import run_label
        from .surface import write_surface_pictures

        return write_surface_pictures(shown, plots, run_label(result), centerline=result.centerline)

    names = tuple(f"{PLOTS}/{name}" for name, *_ in PICTURES)
    if fields is not None:
        rendered.append(PictureJob(names, lambda: surface_pictures(fields)))
    rendered.append(PictureJob((f"{PLOTS}/{YARNS_PNG}",), lambda: [plot_yarns_3d(result, plots / YARNS_PNG)]))
    later = [LaterJob(names, lambda arrays: surface_pictures(fields_from_arrays(arrays)))]
    return drawn, rendered, later


#: the SurfaceFields attributes that are plain numbers, sent as 0-d arrays
_FIELD_NUMBERS = ("unmapped_length_m", "edge_length_m", "pool_radius_m")


def fields_arrays(fields) -> dict:
    """``fields`` (preform.fields.SurfaceFields) as a dict name -> numpy array, to hand to a
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
    from ..fields import SurfaceFields

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


def start_pictures(result, out_dir):
    """Start the 3-D pictures of ``result`` in a worker process before its fields are mapped
    (``preform run`` calls it right after the simulation): the worker imports pyvista and renders
    the braided mandrel while this process maps the fields and writes the data files, then draws
    the surface pictures from the fields :func:`write_results` hands it (``pictures=``).
    Returns the ``io.pictures.PictureWorker`` (without fork it draws them in ``write_results``),
    or None when the folder cannot be prepared (``write_results`` then says why)."""
    from .pictures import PictureWorker

    try:
        out_dir = _prepare_folder(out_dir)
    except OSError:
        return None
    _, rendered, later = _picture_jobs(result, None, out_dir)
    return PictureWorker(rendered, later=later)


def _relative(path, out_dir) -> str:
    path, out_dir = Path(path).resolve(), Path(out_dir).resolve()
    return path.relative_to(out_dir).as_posix() if path.is_relative_to(out_dir) else str(path)


def write_results(result, fields, out_dir, stages=None, layers=None, layer_results=(),
                  background=False, pictures=None, settings=None) -> list[Path]:
    """Write all result files of ``result`` (and of ``fields`` if not None) into ``out_dir``.

    result : preform.result.Result
    fields : preform.fields.SurfaceFields or None (no surface files then)
    out_dir : str or Path, created if missing
    stages : dict stage -> seconds of wall time so far (``preform run``'s), or None; the summary's
        ``wall_time_s`` is then the whole command's, these stages, the writing of the data files
        (``write``) and what the pictures take after it (``pictures``: the matplotlib pictures
        drawn here, then the wait for the worker's renders) included. The stages follow each
        other in this process; a picture worker renders beside the stages since it started.
    layers : summary.json's ``layers`` entries of a run with [[layer]] tables, or None
    layer_results : the Results of layers 2, 3, ...: their ``history.csv`` and ``yarns.vtp`` go
        to ``layer2/``, ``layer3/``, ... (``result`` is the first layer's)
    background : render the 3-D pictures in a worker process while the data files are written
        (``io.pictures.PictureWorker``), else one after the other here
    pictures : the worker :func:`start_pictures` started for ``result`` (then ``background`` is
        not looked at): it gets ``fields`` before the data files are written, and is waited for
        after them; stopped if writing fails
    settings : the numerical settings of the run (``preform.Settings``; None: the defaults),
        for the verdict, the steady state and the interlacing in summary.json and the plots,
        and the binning of the RTM files and of the shell deck
    returns : the paths written, summary.json last (then report.html, io.report, from the finished folder)

    The data files come first; a picture that cannot be drawn is reported (a RuntimeWarning and
    the summary's ``pictures.failed``) and never stops the rest.
    """
    import time
    import warnings

    from .pictures import PictureWorker, run_jobs

    t_write = time.perf_counter()
    try:
        out_dir = _prepare_folder(out_dir)
        summary = out_dir / SUMMARY
        drawn, rendered, _ = _picture_jobs(result, fields, out_dir, settings, layer_results)
        if pictures is not None:       # the early worker renders the fields too
            rendered = []
            pictures.send(fields_arrays(fields) if fields is not None else None)
        else:
            pictures = PictureWorker(rendered if background else [])
            if background:             # the worker's (drawn by its finish() where it cannot fork)
                rendered = []
        written = [write_history(result, out_dir / HISTORY),
                   write_yarns_vtp(result.yarns, out_dir / YARNS),
                   *write_convergence(result.snapshots, out_dir)]
        for k, layer in enumerate(layer_results, start=2):
            folder = safe_folder(out_dir, f"layer{k}")
            written += [write_history(layer, folder / HISTORY), write_yarns_vtp(layer.yarns, folder / YARNS)]
        if fields is not None:
            from .surface import write_surface

            written += [Path(p) for p in write_surface(fields, out_dir, pictures=False)]
            from .surface import INPUT_VTU, write_input_mesh_fields

            output = result.config.output
            if output is not None and output.input_mesh_fields and result.mandrel is not None:
                written.append(write_input_mesh_fields(fields, result.mandrel, out_dir))
            else:   # not left over from an earlier run into this folder
                (out_dir / INPUT_VTU).unlink(missing_ok=True)
        rtm = _write_rtm(result, fields, out_dir, written,
                         None if settings is None else settings.rtm)
        structural = _write_structural(result, fields, out_dir, written, layer_results,
                                       None if settings is None else settings.binning)
    except BaseException:
        if pictures is not None:
            pictures.stop()
        raise
    t_pictures = time.perf_counter()
    try:
        drawn_here, failed = run_jobs(drawn + rendered)
    except BaseException:
        pictures.stop()
        raise
    more, more_failed = pictures.finish()
    drawn_here, failed = drawn_here + more, failed + more_failed
    for text in failed:
        warnings.warn(f"{text}; the data files are written", RuntimeWarning, stacklevel=2)
    written += [p for p in drawn_here if Path(p).is_file()]
    files = [_relative(p, out_dir) for p in [*written, summary]]
    from ..quality import QUALITY, surface_reasons

    quality = QUALITY if settings is None else settings.quality
    extra = {"files": files, "rtm": rtm, "structural": structural,
             "quality_reasons": surface_reasons(result, fields, quality),
             "pictures": {"failed": failed}}
    if layers is not None:   # the run is suspect when a layer above the first is
        extra["layers"] = layers
        extra["quality_reasons"] += [f"layer {e['layer']}: {reason}" for e in layers[1:]
                                     for reason in e["quality"]["reasons"]]
    if stages is not None:
        now = time.perf_counter()
        stages = {**stages, "write": t_pictures - t_write, "pictures": now - t_pictures}
        extra.update(wall_time_s=sum(stages.values()), stages_s=stages,
                     simulation_wall_time_s=float(result.wall_time_s))
    written.append(write_summary(result, summary, extra=extra, settings=settings))
    from .report import report_hook; report_hook(out_dir)  # noqa: E702 - the page of the finished folder
    return written


def _write_rtm(result, fields, out_dir, written, settings=None) -> dict:
    """``rtm/`` when the fields carry fibre content (tow data given); what the summary says
    (``settings``: ``rtm.BinningSettings``, None: the defaults)."""
    from ..rtm import missing_material

    reason = missing_material(result.config) if result.config is not None else "no config"
    if reason:
        return {"written": False, "reason": reason}
    if fields is None or "fibre_volume_fraction" not in fields.cell_data:
        return {"written": False, "reason": "no surface fields"}
    from .rtm_files import write_rtm

    paths, said = write_rtm(fields, out_dir, cavity_thickness=result.config.rtm.cavity_thickness,
                            settings=settings)
    written += paths
    return said


def _write_structural(result, fields, out_dir, written, layer_results, binning=None) -> dict:
    """``fe/`` when the config has a [material] section and the fields fibre content; what the
    summary says (``preform.structural``; ``binning``: its ``layup.BinSettings``, None: the
    defaults)."""
    from ..structural import write_structural

    paths, said = write_structural(result, fields, out_dir, layer_results, binning)
    written += paths
    return said


__all__ = [
    "write_results",
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
