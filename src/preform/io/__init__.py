"""Result files of a run (DESIGN.md §1): tables, VTK/PVD, plots, and the surface fields.

:func:`write_results` writes everything into one folder; ``summary.json`` comes last, so its
presence marks a complete set of results. Every file is written atomically (``io.atomic``).
"""

from __future__ import annotations

from pathlib import Path

from .atomic import atomic_path, atomic_write_bytes, atomic_write_text, safe_folder
from .plots import plot_history, plot_yarns_3d
from .tables import write_history, write_summary
from .vtk_yarns import write_convergence, write_yarns_vtp

SUMMARY = "summary.json"
HISTORY = "history.csv"
YARNS = "yarns.vtp"
PLOTS = "plots"
YARNS_PNG = "braided_mandrel.png"


def _write_surface(fields, out_dir, title="") -> list[Path]:
    """``preform.io.surface.write_surface`` when that module exists (surface.vtu/.xdmf/.h5, PNGs)."""
    try:
        from .surface import write_surface
    except ModuleNotFoundError as err:  # tolerated only while io/surface.py does not exist yet
        if err.name != f"{__name__}.surface":
            raise
        return []

    written = write_surface(fields, out_dir, title)
    return [Path(p) for p in (written or [])]


def _relative(path, out_dir) -> str:
    path, out_dir = Path(path).resolve(), Path(out_dir).resolve()
    return path.relative_to(out_dir).as_posix() if path.is_relative_to(out_dir) else str(path)


def write_results(result, fields, out_dir, stages=None, layers=None, layer_results=()) -> list[Path]:
    """Write all result files of ``result`` (and of ``fields`` if not None) into ``out_dir``.

    result : preform.result.Result
    fields : preform.fields.SurfaceFields or None (no surface files then)
    out_dir : str or Path, created if missing
    stages : dict stage -> seconds of wall time so far (``preform run``'s), or None; the summary's
        ``wall_time_s`` is then the whole command's, these stages and this writing included
    layers : summary.json's ``layers`` entries of a run with [[layer]] tables, or None
    layer_results : the Results of layers 2, 3, ...: their ``history.csv`` and ``yarns.vtp`` go
        to ``layer2/``, ``layer3/``, ... (``result`` is the first layer's)
    returns : the paths written, summary.json last
    """
    import time

    t_write = time.perf_counter()
    out_dir = safe_folder(out_dir)
    safe_folder(out_dir, PLOTS)   # a symlink planted as plots/ is replaced, never followed
    summary = out_dir / SUMMARY
    summary.unlink(missing_ok=True)  # a summary from an earlier run would mark this one complete
    written = [write_history(result, out_dir / HISTORY),
               write_yarns_vtp(result.yarns, out_dir / YARNS),
               *write_convergence(result.snapshots, out_dir)]
    for k, layer in enumerate(layer_results, start=2):
        folder = safe_folder(out_dir, f"layer{k}")
        written += [write_history(layer, folder / HISTORY), write_yarns_vtp(layer.yarns, folder / YARNS)]
    if fields is not None:
        from .plots import run_label

        written += _write_surface(fields, out_dir, run_label(result))
        if result.centerline is not None:
            from .maps import MAP, write_surface_map
            from .plots import run_title

            written.append(write_surface_map(fields, result.centerline, out_dir / PLOTS / MAP,
                                             run_title(result, "Surface fields, unrolled")))
    rtm = _write_rtm(result, fields, out_dir, written)
    if result.steps:
        written += plot_history(result, out_dir / PLOTS)
    written.append(plot_yarns_3d(result, out_dir / PLOTS / YARNS_PNG))
    files = [_relative(p, out_dir) for p in [*written, summary]]
    from ..quality import surface_reasons

    extra = {"files": files, "rtm": rtm, "quality_reasons": surface_reasons(result, fields)}
    if layers is not None:   # the run is suspect when a layer above the first is
        extra["layers"] = layers
        extra["quality_reasons"] += [f"layer {e['layer']}: {reason}" for e in layers[1:]
                                     for reason in e["quality"]["reasons"]]
    if stages is not None:
        stages = {**stages, "write": time.perf_counter() - t_write}
        extra.update(wall_time_s=sum(stages.values()), stages_s=stages,
                     simulation_wall_time_s=float(result.wall_time_s))
    written.append(write_summary(result, summary, extra=extra))
    return written


def _write_rtm(result, fields, out_dir, written) -> dict:
    """``rtm/`` when the fields carry fibre content (tow data given); what the summary says."""
    from ..rtm import missing_material

    reason = missing_material(result.config) if result.config is not None else "no config"
    if reason:
        return {"written": False, "reason": reason}
    if fields is None or "fibre_volume_fraction" not in fields.cell_data:
        return {"written": False, "reason": "no surface fields"}
    from .rtm_files import write_rtm

    paths, said = write_rtm(fields, out_dir, cavity_thickness=result.config.rtm.cavity_thickness)
    written += paths
    return said


__all__ = [
    "write_results",
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
