"""One case from config to result files: what ``preform run`` does, callable from a sweep worker.

:func:`run_case` does, in this order, so that nothing is lost and nothing is written elsewhere:

1. load and check the geometry (impossible set-ups raise before anything runs);
2. estimate the work (field faces, steps, result size: ``preform.budget``) and refuse what is
   beyond its limits unless ``force``;
3. check that the results folder can be created and written and has room (``io.folder``), and
   take its lock (one run per folder);
4. simulate, with the checkpoint in the results folder; when the run is done its final state is
   saved there too;
5. map the fields and write every result file; only then is the checkpoint removed. If writing
   fails, the checkpoint stays and the error says how to finish: ``--resume`` on a finished
   checkpoint writes the results without simulating again.

With ``[[layer]]`` tables :func:`run_layers` does the same once per layer, from the mandrel
outwards, each layer braided on the mandrel offset by the thickness of the layers below
(``preform.geometry.offset``), and writes the layers' fields and their stacked totals.

It returns a :class:`CaseOutcome` instead of printing, so the CLI and a sweep's workers run
exactly the same path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import PreformError
from .settings import resolved

#: the state of a running simulation, saved periodically and on a stop, removed once the results
#: are written
CHECKPOINT = "checkpoint.npz"


class ResultsWriteError(PreformError):
    """The results could not be written; the simulation is kept in the checkpoint."""

    exit_code = 1


@dataclass
class CaseOutcome:
    """result: preform.result.Result; written: paths written (summary.json last); notes: the
    repairs, pre-flight warnings and estimates, in order, for the caller to show."""

    result: object
    out_dir: Path
    written: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def status(self) -> str:
        return self.result.status


def checked_geometry(config, settings=None):
    """(mandrel, centerline, notes): the geometry of ``config`` after the pre-flight checks.

    Impossible set-ups raise PreformError; the mandrel's repairs, the doubtful points and the
    quasi-static references (Ko, H_inf, whether the braid can settle) come back as notes.
    settings : ``preform.Settings`` (None: the defaults), for the work estimate's time step
    """
    from .checks import preflight

    mandrel, centerline = load_geometry(config)
    notes = [f"mandrel: {repair}" for repair in mandrel.repairs]
    notes += [f"warning: {w}" for w in preflight(config, mandrel, centerline)]
    notes += [f"note: {line}" for line in reference_lines(config, mandrel, centerline)]
    if config.model.kind == "interaction" and not config.layers:
        # the model's cost for this run (the work estimate's steps), before it starts; the
        # estimate's limits are checked where the run is set up (``run_case``)
        line = estimate(config, mandrel, centerline, force=True, settings=settings).model_line()
        notes += [f"note: {line}"] if line else []
    return mandrel, centerline, notes


def load_geometry(config):
    """(Mandrel, Centerline) of a config (``preform.simulation.load_geometry``), the repaired
    mandrel through the on-disk cache (``io.cache``)."""
    from .io.cache import cached_mandrel
    from .simulation import load_geometry as load

    return load(config, load_mandrel=cached_mandrel)


def reference_lines(config, mandrel, centerline) -> list[str]:
    """``preform.reference.check_lines`` over the part to braid (sections every ~2 cm)."""
    from .geometry.centerline import section_perimeters
    from .reference import check_lines, references

    end = min(float(config.process.braid_length), float(centerline.length))
    s = np.linspace(0.0, end, 25)
    perimeter = section_perimeters(mandrel, centerline, s)
    ok = perimeter > 0
    if np.count_nonzero(ok) < 2:
        return []
    return check_lines(config, references(config, s[ok], perimeter[ok]))


def estimate(config, mandrel, centerline, *, force=False, settings=None):
    """The work estimate of a run (``preform.budget``), refused beyond its limits
    (``settings.limits``; None: the defaults) unless ``force``."""
    from .budget import check_work, estimate_work
    from .machine import Machine
    from .reference import end_convergence_length, resolve_pose_lead
    from .stepping import default_time_step

    settings = resolved(settings)
    config = resolve_pose_lead(config, mandrel, centerline)
    dt = config.model.time_step or default_time_step(config, Machine.from_config(config.machine),
                                                     mandrel, centerline, settings.tolerances)
    tri = np.asarray(mandrel.vertices)[np.asarray(mandrel.faces)]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    distance = centerline.project(mandrel.vertices)[1]
    work = estimate_work(config, area, dt, end_convergence_length(config, float(np.median(distance))))
    max_radius = float(np.max(distance))
    check_work(config, work, max_radius, force=force, limits=settings.limits)
    return work


def with_rtm_fields(result, fields):
    """``fields`` with the RTM arrays (``preform.rtm``) when the config has tow material data."""
    from .rtm import missing_material, rtm_fields

    if fields is None or missing_material(result.config):
        return fields
    V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
    s, _ = result.centerline.project(V[F].mean(axis=1))
    tangents = result.centerline.frames_at(s)[1]
    fields.cell_data.update(rtm_fields(fields, result.config, tangents))
    return fields


def run_case(config, out_dir, *, progress=False, resume=False, force=False, geometry=None,
             started=None, background_pictures=False, startup_s=None,
             settings=None) -> CaseOutcome:
    """Simulate ``config`` and write its results into ``out_dir`` (see module docstring).

    geometry : (mandrel, centerline, notes) already checked, or None to load and check here.
    started : ``time.perf_counter()`` when the command began (before loading the geometry), so
        the summary's wall time is the command's; None: from this call.
    background_pictures : render the 3-D pictures in a worker process forked right after the
        simulation (``io.start_pictures``; ``preform run`` does): it imports pyvista and renders
        the braided mandrel while this process maps the fields and writes the data files, then
        renders the surface pictures from the fields ``write_results`` hands it. The stages
        (``simulate``, ``map``, ``write``, ``pictures``) are this process's, one after the other;
        ``pictures`` is what the pictures add after the data files (the matplotlib pictures, then
        the wait for the worker). Embree is not used in the worker (it only renders).
    startup_s : seconds from the process's start to ``started`` (the interpreter and the imports),
        listed as the stage ``start`` when given
    settings : the numerical settings of every stage (``preform.Settings``; None: the defaults)
    Raises PreformError for bad input or an unusable folder (before simulating) and
    ResultsWriteError when writing fails after the simulation (the checkpoint is kept).
    """
    from .checkpoint import Checkpoint
    from .fields import map_to_surface
    from .io import start_pictures, write_results
    from .io.cache import cached_field_mesh
    from .io.folder import RunLock, check_results_folder
    from .simulation import simulate

    import time

    t0 = time.perf_counter() if started is None else started
    settings = resolved(settings)
    if config.layers:
        return run_layers(config, out_dir, progress=progress, resume=resume, force=force,
                          geometry=geometry, started=t0, background_pictures=background_pictures,
                          startup_s=startup_s, settings=settings)
    out_dir = Path(out_dir)
    mandrel, centerline, notes = geometry if geometry is not None else checked_geometry(config,
                                                                                         settings)
    work = estimate(config, mandrel, centerline, force=force, settings=settings)
    notes = [*notes, *(f"note: {line}" for line in work.lines())]
    check_results_folder(out_dir, work.result_bytes)
    checkpoint = out_dir / CHECKPOINT
    with RunLock(out_dir):
        stages = {} if startup_s is None else {"start": float(startup_s)}
        stages["load_and_check"] = time.perf_counter() - t0
        t = time.perf_counter()
        result = simulate(config, progress=progress, mandrel=mandrel, centerline=centerline,
                          checkpoint=checkpoint, resume=resume, keep_checkpoint=True,
                          settings=settings)
        stages["simulate"], t = time.perf_counter() - t, time.perf_counter()
        # the 3-D pictures start now, on the second core, beside the map and the data files
        pictures = start_pictures(result, out_dir) if background_pictures else None
        try:
            # the field mesh depends only on the mandrel and the settings: kept in the cache
            fields = map_to_surface(result, mesh=cached_field_mesh(result, remesh=settings.remesh)) \
                if len(result.yarns.points) else None
            fields = with_rtm_fields(result, fields)
        except BaseException:
            if pictures is not None:
                pictures.stop()
            raise
        stages["map"] = time.perf_counter() - t
        try:
            written = write_results(result, fields, out_dir, stages=stages, background=background_pictures,
                                    pictures=pictures, settings=settings)
        except OSError as err:
            raise ResultsWriteError(
                f"cannot write the results to {out_dir} ({err.strerror or err}); the simulation "
                f"is kept in {checkpoint}: once the folder is writable, `preform run CONFIG "
                "--resume` writes the results without simulating again") from None
        if result.status == "done":
            Checkpoint(checkpoint, result.config).remove()
    return CaseOutcome(result=result, out_dir=out_dir, written=written, notes=notes)


# ------------------------------------------------------------------------------ several layers

#: the checkpoint of layer k (from 1) of a run with [[layer]] tables
LAYER_CHECKPOINT = "checkpoint_layer{k}.npz"


def layer_centerline(centerline, direction: str, roll_reference=None):
    """The centerline a layer travels along: the mandrel's, or reversed for ``"backward"`` (its
    tip is then the far end, and arc lengths count from there)."""
    if direction == "forward":
        return centerline
    from .geometry.centerline import centerline_from_points

    perimeter = None if centerline.perimeter is None else np.asarray(centerline.perimeter)[::-1]
    return centerline_from_points(np.asarray(centerline.points)[::-1], roll_reference=roll_reference,
                                  perimeter=perimeter)


@dataclass
class LayerStack:
    """The geometry shared by the layers of a run: the base surface (the mandrel refined to the
    field edge, ``offset.refined_surface``) and the field mesh of the first layer, which every
    layer maps onto an offset copy of. ``displacement`` (nv, 3) m: the base vertices' offset
    under the layers mapped so far."""

    mandrel: object
    base_vertices: np.ndarray
    base_faces: np.ndarray
    field_mesh: tuple
    displacement: np.ndarray
    settings: object

    @classmethod
    def start(cls, mandrel, field_mesh, settings):
        from .geometry.offset import refined_surface

        V, F = refined_surface(mandrel.vertices, mandrel.faces, field_mesh[3])
        return cls(mandrel, V, F, field_mesh, np.zeros_like(V), settings)

    @property
    def reach(self) -> float:
        from .fields import LOCATE_REACH_EDGES

        return LOCATE_REACH_EDGES * float(self.field_mesh[3])

    def layer_mesh(self):
        """The field mesh moved by the current displacement (same faces, same source faces)."""
        from .geometry.offset import interpolate, vertex_normals

        V, F, source, h = self.field_mesh
        moved = interpolate(self.base_vertices, self.base_faces, self.displacement, V,
                            vertex_normals(V, F), self.reach)
        return V + moved, F, source, h

    def offset_for(self, layer_fields, name: str):
        """(Mandrel, OffsetReport) of the surface on the stacked thickness of ``layer_fields``."""
        from .geometry.mandrel import mandrel_from_arrays
        from .geometry.offset import interpolate, offset_surface, vertex_means, vertex_normals

        V, F, _, _ = self.field_mesh
        total = np.sum([f.cell_data["thickness_m"] for f in layer_fields], axis=0)
        at_base = interpolate(V, F, vertex_means(V, F, total), self.base_vertices,
                              vertex_normals(self.base_vertices, self.base_faces), self.reach)
        moved, self.displacement, report = offset_surface(self.base_vertices, self.base_faces,
                                                          at_base, self.settings)
        source = f"{self.mandrel.source or 'mandrel'} offset for {name}"
        return mandrel_from_arrays(moved, self.base_faces, source=source), report


def check_layers(config, mandrel, centerline, notes=(), *, force=False, settings=None):
    """(notes, estimated result bytes) of every layer of ``config`` against the mandrel, before
    any runs: impossible set-ups raise (PreformError), work beyond the limits is refused unless
    ``force``; ``notes`` are the geometry check's, whose warnings are not repeated. Each layer's
    Ko / H_inf notes are the mandrel's (the layer lies further out by the layers below it).
    ``settings``: ``preform.Settings`` (None: the defaults) for the work estimates."""
    from .checks import preflight

    notes = list(notes)
    result_bytes = 0
    for k in range(1, len(config.layers) + 1):
        cfg = config.layer_config(k - 1)
        cl = layer_centerline(centerline, config.layers[k - 1].direction, config.mandrel.roll_reference)
        notes += [line for w in preflight(cfg, mandrel, cl)
                  if (line := f"warning: layer {k}: {w}") not in notes and f"warning: {w}" not in notes]
        if k > 1:
            notes += [f"note: layer {k}: {line}" for line in reference_lines(cfg, mandrel, cl)]
        work = estimate(cfg, mandrel, cl, force=force, settings=settings)
        notes += [f"note: layer {k}: {line}" for line in work.lines()]
        result_bytes += work.result_bytes
    return notes, result_bytes


def run_layers(config, out_dir, *, progress=False, resume=False, force=False, geometry=None,
               started=None, background_pictures=False, startup_s=None,
               settings=None) -> CaseOutcome:
    """:func:`run_case` for a config with ``[[layer]]`` tables: each layer is braided in turn,
    from the mandrel outwards, on the mandrel offset by the thickness of the layers below.

    Every layer's set-up is checked and its work estimated against the mandrel before the first
    runs; layer k (from 1) keeps its state in ``checkpoint_layer{k}.npz`` until all results are
    written (``--resume`` continues at the first unfinished layer). A layer that stops
    (interrupted, failed), or whose surface folds or makes its set-up impossible, ends the run
    (status "failed" for the latter, naming the layer); the layers done so far are written. The top-level
    ``history.csv``, ``yarns.vtp`` and ``convergence`` are the first layer's, ``layer{k}/`` holds
    those of layer k >= 2; the surface files hold every layer's fields (``layer{k}_*``) and the
    stacked totals (``preform.fields.stack_layers``, ``preform.rtm.stacked_rtm_fields``);
    ``summary.json`` ``layers`` has one entry per layer.
    settings : ``preform.Settings`` (None: the defaults); its ``offset`` for the layers' surfaces
    """
    import dataclasses
    import time

    from .checks import preflight
    from .checkpoint import Checkpoint
    from .fields import map_to_surface
    from .io import write_results
    from .io.cache import cached_field_mesh
    from .io.folder import RunLock, check_results_folder
    from .simulation import simulate

    t0 = time.perf_counter() if started is None else started
    settings = resolved(settings)
    out_dir = Path(out_dir)
    configs = [config.layer_config(k) for k in range(len(config.layers))]
    mandrel, centerline, notes = geometry if geometry is not None else checked_geometry(configs[0],
                                                                                         settings)
    lines = [layer_centerline(centerline, layer.direction, config.mandrel.roll_reference)
             for layer in config.layers]
    notes, result_bytes = check_layers(config, mandrel, centerline, notes, force=force,
                                       settings=settings)
    check_results_folder(out_dir, result_bytes)
    stages = {} if startup_s is None else {"start": float(startup_s)}
    stages["load_and_check"] = time.perf_counter() - t0
    with RunLock(out_dir):
        results, layer_fields, offsets, stack, refused = [], [], [None], None, ""
        surface = mandrel
        for k, (cfg, cl) in enumerate(zip(configs, lines), start=1):
            if k > 1:   # a surface that folds, or a set-up the stack makes impossible, ends the run
                try:
                    surface, report = stack.offset_for(layer_fields, f"layer {k}")
                    notes += [f"warning: layer {k}: {w}" for w in preflight(cfg, surface, cl)]
                except PreformError as err:
                    refused = f"layer {k} cannot be braided on the layers below: {err}"
                    break
                offsets.append(report)
            t = time.perf_counter()
            ckpt = out_dir / LAYER_CHECKPOINT.format(k=k)
            result = simulate(cfg, progress=progress, mandrel=surface, centerline=cl, checkpoint=ckpt,
                              resume=resume and ckpt.exists(), keep_checkpoint=True,
                              settings=settings)
            stages[f"simulate_layer{k}"], t = time.perf_counter() - t, time.perf_counter()
            results.append(result)
            if result.status != "done" or not len(result.yarns.points):
                break
            # every layer's angles are measured against the mandrel's centerline, forwards
            on_mandrel = dataclasses.replace(result, centerline=centerline)
            if stack is None:
                stack = LayerStack.start(mandrel, cached_field_mesh(on_mandrel, remesh=settings.remesh),
                                         settings.offset)
            layer_fields.append(map_to_surface(on_mandrel, mesh=stack.layer_mesh()))
            stages[f"map_layer{k}"] = time.perf_counter() - t
        fields = _stacked_fields(configs, layer_fields, centerline, config.rtm.cavity_thickness)
        top = _top_result(config, configs, results, refused)
        entries = [layer_summary(k, cfg.layers[-1], r, f, o, settings) for k, (cfg, r, f, o)
                   in enumerate(zip(configs, results, [*layer_fields, None], offsets), start=1)]
        try:
            written = write_results(top, fields, out_dir, stages=stages, layers=entries, settings=settings,
                                    layer_results=results[1:], background=background_pictures)
        except OSError as err:
            raise ResultsWriteError(
                f"cannot write the results to {out_dir} ({err.strerror or err}); the simulations "
                f"are kept in {out_dir}/checkpoint_layer*.npz: once the folder is writable, "
                "`preform run CONFIG --resume` writes the results without simulating again") from None
        if top.status == "done":
            for k, cfg in enumerate(configs, start=1):
                Checkpoint(out_dir / LAYER_CHECKPOINT.format(k=k), cfg).remove()
    return CaseOutcome(result=top, out_dir=out_dir, written=written, notes=notes)


def _stacked_fields(configs, layer_fields, centerline, cavity_thickness):
    """The stacked SurfaceFields of the layers mapped (with the stacked RTM arrays when every
    layer has tow data), or None when no layer was."""
    from .fields import stack_layers
    from .rtm import missing_material, stacked_rtm_fields

    if not layer_fields:
        return None
    fields = stack_layers(layer_fields)
    if not any(missing_material(cfg) for cfg in configs[:len(layer_fields)]):
        V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
        s, _ = centerline.project(V[F].mean(axis=1))
        tangents = centerline.frames_at(s)[1]
        fields.cell_data.update(stacked_rtm_fields(layer_fields, configs, tangents, cavity_thickness))
    return fields


def _top_result(config, configs, results, refused=""):
    """The Result the top-level files describe: the first layer's, with the whole run's config
    (all layers echoed) and the status of the last layer run (a stopped layer stops the run);
    ``refused``: why the next layer could not start ("" if it was not refused)."""
    import dataclasses

    last = results[-1]
    status, message = last.status, last.message
    if refused:
        status, message = "failed", refused
    elif status == "done" and len(results) < len(configs):
        status, message = "failed", f"layer {len(results)} deposited no yarn; the layers above it were not braided"
    elif status != "done" and len(results) > 1:
        message = f"layer {len(results)}: {message}"
    whole = dataclasses.replace(configs[0], layers=config.layers)
    wall = float(sum(r.wall_time_s for r in results))
    return dataclasses.replace(results[0], config=whole, status=status, message=message, wall_time_s=wall,
                               stop_signal=last.stop_signal)


def layer_summary(k, layer, result, fields, offset, settings=None) -> dict:
    """summary.json's entry for layer k (from 1): its process figures and quality verdict (its
    history, yarns and fields, located on its own centerline; ``settings``: ``preform.Settings``,
    None: the defaults), its fields' means over the faces it reached, and for k >= 2 the offset
    surface it was braided on."""
    from .io.tables import summary_dict
    from .quality import surface_reasons

    settings = resolved(settings)
    s = summary_dict(result, {"quality_reasons": surface_reasons(result, fields, settings.quality)},
                     settings=settings)
    entry = {"layer": k, "direction": layer.direction, "model": s["model"], "status": s["status"],
             "message": s["message"], "steps": s["steps"], "wall_time_s": s["wall_time_s"],
             "braided_length_m": s["braided_length_m"], "braid_angle_deg": s["braid_angle_deg"],
             "convergence_length_m": s["convergence_length_m"], "quality": s["quality"],
             "offset": None if offset is None else offset.as_dict(), "fields": None}
    if fields is not None:
        cd = fields.cell_data
        V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
        area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
        on = (cd["reached_warp"] > 0) | (cd["reached_weft"] > 0)
        if on.any():
            entry["fields"] = {f"mean_{name}": float(np.average(cd[name][on], weights=area[on]))
                               for name in ("thickness_m", "cover_factor", "braid_angle_deg")}
    return entry
