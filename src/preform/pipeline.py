"""One run from config to result files: what ``preform run`` does, callable from a sweep worker.

A run is five stages, one after the other, each a function from plain inputs to a plain output:

1. :func:`load` -> :class:`Loaded`: the mandrel (repaired, through the disk cache ``io.cache``)
   and its centerline, checked against the set-up (:func:`checked_geometry`: impossible set-ups
   raise before anything runs; repairs, doubtful points and the quasi-static references come
   back as notes);
2. :func:`check` -> :class:`Checked`: the layers to braid, each with its config, the centerline
   it travels along and its checkpoint; every layer's set-up and work estimate (field faces,
   steps, result size: ``preform.budget``, refused beyond its limits unless ``force``); the
   results folder proved writable with room (``io.folder``);
3. :func:`simulate` -> :class:`Simulated`: the layers in turn, from the mandrel outwards, each
   braided on the mandrel offset by the thickness of the layers below (``geometry.offset``; the
   fields of a layer are mapped when the next one needs them), each keeping its state in its
   checkpoint in the results folder; a layer that stops, or whose surface folds or makes its
   set-up impossible, ends the run;
4. :func:`analyse` -> ``analysis.derived.Analysed``: the surface fields of the last layer, the
   RTM arrays or a stack's totals, the verdict, steady state, interlacing, the RTM solver
   properties, the structural plies and the summary's figures;
5. :func:`write` -> the paths written (``io``: data files, pictures, ``summary.json`` last,
   with the stage timings); only then are the checkpoints removed. If writing fails, the
   checkpoints stay and the error says how to finish: ``--resume`` on finished checkpoints
   writes the results without simulating again.

:func:`run_case` composes them inside the results folder's lock. A config without ``[[layer]]``
tables is a stack of one layer; with them the top-level ``history.csv``, ``yarns.vtp`` and
``convergence`` are the first layer's, ``layer{k}/`` holds those of layer k >= 2, the surface
files every layer's fields (``layer{k}_*``) and the stacked totals, and ``summary.json``
``layers`` one entry per layer. It returns a :class:`CaseOutcome` instead of printing, so the CLI
and a sweep's workers run exactly the same path.

Stage timings are taken here, and only here; the writers (``io``) only write.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import io
from .analysis.derived import Analysed, analyse_run, layer_summary
from .analysis.fields import LOCATE_REACH_EDGES, map_to_surface, stack_layers
from .analysis.rtm import missing_material, rtm_fields, stacked_rtm_fields
from .budget import check_work, estimate_work
from .checkpoint import CHECKPOINT, LAYER_CHECKPOINT, Checkpoint
from .checks import preflight
from .config import mix_lines
from .errors import PreformError
from .geometry import centerline_from_points, section_perimeters
from .geometry.mandrel import mandrel_from_arrays
from .geometry.offset import interpolate, offset_surface, refined_surface, vertex_means, vertex_normals
from .io.cache import cached_field_mesh, cached_mandrel
from .io.folder import RunLock, check_results_folder
from .machine import Machine
from .reference import check_lines, end_convergence_length, references, resolve_pose_lead
from .result import Result
from .settings import resolved
from .simulation import load_geometry as _load_geometry
from .simulation import simulate as _simulate
from .stepping import default_time_step
from .zone import zone_class

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


# ------------------------------------------------------------------------------ 1. load

@dataclass(frozen=True)
class Loaded:
    """The run's config, its mandrel and centerline (mandrel frame), and the notes of the
    geometry check."""

    config: object
    mandrel: object
    centerline: object
    notes: tuple = ()


def load(config, geometry=None, settings=None) -> Loaded:
    """The geometry of ``config`` after :func:`checked_geometry`, or ``geometry`` (mandrel,
    centerline, notes) that a caller already checked; ``settings``: ``preform.Settings`` (None:
    the defaults), for the work estimate's time step."""
    first = config.layer_config(0) if config.layers else config
    mandrel, centerline, notes = geometry if geometry is not None else checked_geometry(first, settings)
    return Loaded(config=config, mandrel=mandrel, centerline=centerline, notes=tuple(notes))


def checked_geometry(config, settings=None):
    """(mandrel, centerline, notes): the geometry of ``config`` after the pre-flight checks.

    Impossible set-ups raise PreformError; the mandrel's repairs, the doubtful points and the
    quasi-static references (Ko, H_inf, whether the braid can settle) come back as notes.
    settings : ``preform.Settings`` (None: the defaults), for the work estimate's time step
    """
    mandrel, centerline = load_geometry(config)
    notes = [f"mandrel: {repair}" for repair in mandrel.repairs]
    notes += [f"note: {line}" for line in mix_lines(config)]
    notes += [f"warning: {w}" for w in preflight(config, mandrel, centerline)]
    notes += [f"note: {line}" for line in reference_lines(config, mandrel, centerline)]
    cost = zone_class(config.model.kind).cost_note
    if cost and not config.layers:
        # the model's cost for this run (the work estimate's steps), before it starts; the
        # estimate's limits are checked in the check stage
        steps = estimate(config, mandrel, centerline, force=True, settings=settings).steps
        notes.append(f"note: {cost.format(steps=steps)}")
    return mandrel, centerline, notes


def load_geometry(config):
    """(Mandrel, Centerline) of a config (``preform.simulation.load_geometry``), the repaired
    mandrel through the on-disk cache (``io.cache``)."""
    return _load_geometry(config, load_mandrel=cached_mandrel)


def reference_lines(config, mandrel, centerline) -> list[str]:
    """``preform.reference.check_lines`` over the part to braid (sections every ~2 cm)."""
    end = min(float(config.process.braid_length), float(centerline.length))
    s = np.linspace(0.0, end, 25)
    perimeter = section_perimeters(mandrel, centerline, s)
    ok = perimeter > 0
    if np.count_nonzero(ok) < 2:
        return []
    return check_lines(config, references(config, s[ok], perimeter[ok]), float(centerline.length))


# ------------------------------------------------------------------------------ 2. check

@dataclass(frozen=True)
class Layer:
    """One layer to braid: k (from 1), its config, the centerline it travels along and the file
    that keeps its state."""

    k: int
    config: object
    centerline: object
    checkpoint: Path | None


@dataclass(frozen=True)
class Checked:
    """The loaded geometry, the layers to braid (one for a config without [[layer]] tables), the
    notes so far and the estimated size of the results (bytes)."""

    loaded: Loaded
    layers: tuple
    notes: tuple
    result_bytes: int

    @property
    def stacked(self) -> bool:
        """Whether the run has [[layer]] tables (its files then name the layers)."""
        return bool(self.loaded.config.layers)


def estimate(config, mandrel, centerline, *, force=False, settings=None):
    """The work estimate of a run (``preform.budget``), refused beyond its limits
    (``settings.limits``; None: the defaults) unless ``force``."""
    settings = resolved(settings)
    config = resolve_pose_lead(config, mandrel, centerline)
    dt = config.model.time_step or default_time_step(config, Machine.from_config(config.machine),
                                                     mandrel, centerline, settings.tolerances)
    tri = np.asarray(mandrel.vertices)[np.asarray(mandrel.faces)]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    distance = centerline.project(mandrel.vertices)[1]
    h_end = end_convergence_length(config, float(np.median(distance)))
    if h_end is not None and config.model.kind == "interaction":
        # the interaction model's zone, shortened by its friction, stays near where it started
        # instead of growing to the kinematic H (docs/decisions.md, "The interaction model's
        # step estimate"): its fell travel is braid_length plus at most initial_position
        h_end = min(h_end, float(config.process.initial_position))
    work = estimate_work(config, area, dt, h_end)
    max_radius = float(np.max(distance))
    check_work(config, work, max_radius, force=force, limits=settings.limits)
    return work


def layer_centerline(centerline, direction: str, roll_reference=None):
    """The centerline a layer travels along: the mandrel's, or reversed for ``"backward"`` (its
    tip is then the far end, and arc lengths count from there)."""
    if direction == "forward":
        return centerline
    perimeter = None if centerline.perimeter is None else np.asarray(centerline.perimeter)[::-1]
    return centerline_from_points(np.asarray(centerline.points)[::-1], roll_reference=roll_reference,
                                  perimeter=perimeter)


def check(loaded: Loaded, out_dir, *, force=False, settings=None) -> Checked:
    """Every layer's set-up against the mandrel and its work estimate, before any runs, then the
    results folder ``out_dir`` (writable, with room for the estimated results; None: no folder,
    as ``preform check``); ``settings``: ``preform.Settings`` (None: the defaults) for the work
    estimates.

    Impossible set-ups raise (PreformError), work beyond the limits is refused unless ``force``.
    The layers of a stack are checked on the mandrel: their warnings not already in the
    geometry check's notes, the Ko / H_inf notes of layers above the first (which lie further
    out by the layers below them) and their estimates come as notes naming the layer.
    """
    config, mandrel, centerline = loaded.config, loaded.mandrel, loaded.centerline
    out_dir = Path(out_dir) if out_dir is not None else None
    notes, result_bytes, layers = list(loaded.notes), 0, []
    stacked = bool(config.layers)
    for k in range(1, max(len(config.layers), 1) + 1):
        if stacked:
            cfg = config.layer_config(k - 1)
            cl = layer_centerline(centerline, config.layers[k - 1].direction, config.mandrel.roll_reference)
            notes += [line for w in preflight(cfg, mandrel, cl)
                      if (line := f"warning: layer {k}: {w}") not in notes and f"warning: {w}" not in notes]
            if k > 1:
                notes += [f"note: layer {k}: {line}" for line in reference_lines(cfg, mandrel, cl)]
            name = LAYER_CHECKPOINT.format(k=k)
        else:
            cfg, cl, name = config, centerline, CHECKPOINT
        work = estimate(cfg, mandrel, cl, force=force, settings=settings)
        prefix = f"layer {k}: " if stacked else ""
        notes += [f"note: {prefix}{line}" for line in work.lines()]
        result_bytes += work.result_bytes
        layers.append(Layer(k=k, config=cfg, centerline=cl,
                            checkpoint=None if out_dir is None else out_dir / name))
    if out_dir is not None:
        check_results_folder(out_dir, result_bytes)
    return Checked(loaded=loaded, layers=tuple(layers), notes=tuple(notes), result_bytes=result_bytes)


# ------------------------------------------------------------------------------ 3. simulate

@dataclass
class LayerStack:
    """The geometry shared by the layers of a stack: the base surface (the mandrel refined to
    the field edge, ``offset.refined_surface``) and the field mesh of the first layer, which
    every layer maps onto an offset copy of. ``displacement`` (nv, 3) m: the base vertices'
    offset under the layers mapped so far."""

    mandrel: object
    base_vertices: np.ndarray
    base_faces: np.ndarray
    field_mesh: tuple
    displacement: np.ndarray
    settings: object

    @classmethod
    def start(cls, mandrel, field_mesh, settings):
        V, F = refined_surface(mandrel.vertices, mandrel.faces, field_mesh[3])
        return cls(mandrel, V, F, field_mesh, np.zeros_like(V), settings)

    @property
    def reach(self) -> float:
        return LOCATE_REACH_EDGES * float(self.field_mesh[3])

    def layer_mesh(self):
        """The field mesh moved by the current displacement (same faces, same source faces)."""
        V, F, source, h = self.field_mesh
        moved = interpolate(self.base_vertices, self.base_faces, self.displacement, V,
                            vertex_normals(V, F), self.reach)
        return V + moved, F, source, h

    def offset_for(self, layer_fields, name: str):
        """(Mandrel, OffsetReport) of the surface on the stacked thickness of ``layer_fields``."""
        V, F, _, _ = self.field_mesh
        total = np.sum([f.cell_data["thickness_m"] for f in layer_fields], axis=0)
        at_base = interpolate(V, F, vertex_means(V, F, total), self.base_vertices,
                              vertex_normals(self.base_vertices, self.base_faces), self.reach)
        moved, self.displacement, report = offset_surface(self.base_vertices, self.base_faces,
                                                          at_base, self.settings)
        source = f"{self.mandrel.source or 'mandrel'} offset for {name}"
        return mandrel_from_arrays(moved, self.base_faces, source=source), report


@dataclass(frozen=True)
class Simulated:
    """The layers braided: their Results in order (fewer than the layers when one stopped or was
    refused), the SurfaceFields of those mapped for the layers above them, the OffsetReport of
    the surface each was braided on (None: the mandrel), why the next layer could not start ("":
    none was refused), the stack's geometry (None until a layer of a stack was mapped), the
    Result the top-level files describe (:func:`top_result`), the run's ``preform.Settings``, the
    notes of the offset surfaces' checks and the stage timings (s)."""

    results: tuple
    layer_fields: tuple
    offsets: tuple
    refused: str
    stack: LayerStack | None
    result: Result
    settings: object = None
    notes: tuple = ()
    stages: dict = field(default_factory=dict)


def _on_mandrel(result, centerline):
    """``result`` located on the mandrel's centerline, forwards: every layer's angles and fields
    are measured against it."""
    return dataclasses.replace(result, centerline=centerline)


def _mapped(checked: Checked, stack, result, settings):
    """(SurfaceFields, stack) of a layer's Result, located on the mandrel's centerline: a single
    layer on its field mesh (kept in the disk cache: it depends only on the mandrel and the
    settings), a stack's layer on the field mesh of the first layer moved by the layers below
    (the stack's geometry started on first use); ``settings``: the run's ``preform.Settings``
    (its ``remesh`` and ``offset``)."""
    on_mandrel = _on_mandrel(result, checked.loaded.centerline)
    if not checked.stacked:
        return map_to_surface(on_mandrel, mesh=cached_field_mesh(on_mandrel, remesh=settings.remesh)), stack
    if stack is None:
        stack = LayerStack.start(checked.loaded.mandrel, cached_field_mesh(on_mandrel, remesh=settings.remesh),
                                 settings.offset)
    return map_to_surface(on_mandrel, mesh=stack.layer_mesh()), stack


def simulate(checked: Checked, *, progress=False, resume=False, settings=None) -> Simulated:
    """Braid the layers of ``checked`` in turn (module docstring, stage 3).

    resume : continue each layer from its checkpoint (a stack's layers without one start anew)
    settings : ``preform.Settings`` (None: the defaults): passed to ``simulation.simulate``; its
        ``remesh`` and ``offset`` for the fields and surfaces of a stack
    """
    settings = resolved(settings)
    loaded = checked.loaded
    stacked = checked.stacked
    stages, notes = {}, []
    results, layer_fields, offsets, stack, refused = [], [], [], None, ""
    surface = loaded.mandrel
    for layer in checked.layers:
        name = f"_layer{layer.k}" if stacked else ""
        report = None
        if layer.k > 1:   # the layer below lies under this one: map it, offset the surface by it
            t = time.perf_counter()
            mapped, stack = _mapped(checked, stack, results[-1], settings)
            layer_fields.append(mapped)
            stages[f"map_layer{layer.k - 1}"] = time.perf_counter() - t
            try:   # a surface that folds, or a set-up the stack makes impossible, ends the run
                surface, report = stack.offset_for(layer_fields, f"layer {layer.k}")
                notes += [f"warning: layer {layer.k}: {w}" for w in preflight(layer.config, surface, layer.centerline)]
            except PreformError as err:
                refused = f"layer {layer.k} cannot be braided on the layers below: {err}"
                break
        offsets.append(report)
        t = time.perf_counter()
        result = _simulate(layer.config, progress=progress, mandrel=surface, centerline=layer.centerline,
                           checkpoint=layer.checkpoint,
                           resume=resume and (not stacked or layer.checkpoint.exists()),
                           keep_checkpoint=True, settings=settings)
        stages[f"simulate{name}"] = time.perf_counter() - t
        results.append(result)
        if result.status != "done" or not len(result.yarns.points):
            break
    return Simulated(results=tuple(results), layer_fields=tuple(layer_fields), offsets=tuple(offsets),
                     refused=refused, stack=stack, result=top_result(checked, results, refused),
                     settings=settings, notes=tuple(notes), stages=stages)


def top_result(checked: Checked, results, refused=""):
    """The Result the top-level files describe: a single layer's own; a stack's first layer's,
    with the whole run's config (all layers echoed) and the status of the last layer run (a
    stopped layer stops the run); ``refused``: why the next layer could not start ("" if it was
    not refused)."""
    if not checked.stacked:
        return results[0]
    config = checked.loaded.config
    last = results[-1]
    status, message = last.status, last.message
    if refused:
        status, message = "failed", refused
    elif status == "done" and len(results) < len(checked.layers):
        status, message = "failed", f"layer {len(results)} deposited no yarn; the layers above it were not braided"
    elif status != "done" and len(results) > 1:
        message = f"layer {len(results)}: {message}"
    whole = dataclasses.replace(checked.layers[0].config, layers=config.layers)
    wall = float(sum(r.wall_time_s for r in results))
    return dataclasses.replace(results[0], config=whole, status=status, message=message, wall_time_s=wall,
                               stop_signal=last.stop_signal)


# ------------------------------------------------------------------------------ 4. analyse

def analyse(checked: Checked, simulated: Simulated) -> tuple[Analysed, dict]:
    """(everything the result files need, the stage timings): the last layer's fields (a single
    layer's whenever it deposited yarn; a stack's layer only when it is done, its thickness
    would be partial otherwise), with the RTM arrays or, for a stack, the stacked totals; then
    ``analysis.derived.analyse_run``: the verdict, steady state, interlacing, the RTM solver
    properties, the structural plies, the summary's figures and a stack's layer entries, with
    the run's settings (``Simulated.settings``)."""
    settings = resolved(simulated.settings)
    t = time.perf_counter()
    results, layer_fields = simulated.results, list(simulated.layer_fields)
    last = results[-1]
    if len(layer_fields) < len(results) and len(last.yarns.points) and (not checked.stacked
                                                                       or last.status == "done"):
        layer_fields.append(_mapped(checked, simulated.stack, last, settings)[0])
    if not checked.stacked:
        fields = with_rtm_fields(last, layer_fields[0]) if layer_fields else None
        analysed = analyse_run(simulated.result, fields, settings=settings)
        return analysed, {"analyse": time.perf_counter() - t}
    stages = {}
    if len(layer_fields) > len(simulated.layer_fields):
        stages[f"map_layer{len(layer_fields)}"] = time.perf_counter() - t
    t = time.perf_counter()
    configs = [layer.config for layer in checked.layers]
    fields = _stacked_fields(configs, layer_fields, checked.loaded.centerline,
                             checked.loaded.config.rtm.cavity_thickness)
    entries = [layer_summary(layer.k, layer.config.layers[-1], r, f, o, settings) for layer, r, f, o
               in zip(checked.layers, results, [*layer_fields, None], simulated.offsets)]
    analysed = analyse_run(simulated.result, fields, results[1:], layers=entries, settings=settings)
    stages["analyse"] = time.perf_counter() - t
    return analysed, stages


def with_rtm_fields(result, fields):
    """``fields`` with the RTM arrays (``preform.analysis.rtm``) when the config has tow material data."""
    if fields is None or missing_material(result.config):
        return fields
    V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
    s, _ = result.centerline.project(V[F].mean(axis=1))
    tangents = result.centerline.frames_at(s)[1]
    fields.cell_data.update(rtm_fields(fields, result.config, tangents))
    return fields


def _stacked_fields(configs, layer_fields, centerline, cavity_thickness):
    """The stacked SurfaceFields of the layers mapped (with the stacked RTM arrays when every
    layer has tow data), or None when no layer was."""
    if not layer_fields:
        return None
    fields = stack_layers(layer_fields)
    if not any(missing_material(cfg) for cfg in configs[:len(layer_fields)]):
        V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
        s, _ = centerline.project(V[F].mean(axis=1))
        tangents = centerline.frames_at(s)[1]
        fields.cell_data.update(stacked_rtm_fields(layer_fields, configs, tangents, cavity_thickness))
    return fields


# ------------------------------------------------------------------------------ 5. write

def write(analysed: Analysed, out_dir, *, stages=None, pictures=None, background=False) -> list[Path]:
    """Write every result file of ``analysed`` (``io.write_data``, ``io.draw_pictures``,
    ``io.write_summary_last``), timing the data files (``write``) and what the pictures add
    after them (``pictures``: those drawn here, then the wait for the worker's renders).

    stages : the timings (s) of the stages before, or None: then summary.json's ``wall_time_s``
        is the simulation's; else the whole command's (the sum of the stages), with the stages
    pictures, background : as ``io.write_data``
    """
    t = time.perf_counter()
    writing = io.write_data(analysed, out_dir, background=background, pictures=pictures)
    t_pictures = time.perf_counter()
    writing = io.draw_pictures(writing)
    extra = None
    if stages is not None:
        stages = {**stages, "write": t_pictures - t, "pictures": time.perf_counter() - t_pictures}
        extra = {"wall_time_s": sum(stages.values()), "stages_s": stages,
                 "simulation_wall_time_s": float(analysed.result.wall_time_s)}
    return io.write_summary_last(analysed, writing, extra)


def write_results(result, fields, out_dir, *, background=False, settings=None) -> list[Path]:
    """Analyse a simulated Result and its SurfaceFields (``analysis.derived.analyse_run``) and
    write all its result files into ``out_dir`` (:func:`write`): the Python API's way to files
    from ``preform.simulate`` and ``preform.map_to_surface``; ``settings``: ``preform.Settings``
    (None: the defaults). Returns the paths, summary.json last."""
    return write(analyse_run(result, fields, settings=settings), out_dir, background=background)


# ------------------------------------------------------------------------------ the run

def run_case(config, out_dir, *, progress=False, resume=False, force=False, geometry=None,
             started=None, background_pictures=False, startup_s=None, settings=None,
             say=None) -> CaseOutcome:
    """Simulate ``config`` and write its results into ``out_dir``: the five stages of the module
    docstring, for one layer or a stack.

    geometry : (mandrel, centerline, notes) already checked, or None to load and check here.
    started : ``time.perf_counter()`` when the command began (before loading the geometry), so
        the summary's wall time is the command's; None: from this call.
    background_pictures : render the 3-D pictures in a worker process forked right after the
        simulation (``io.start_pictures``; ``preform run`` does): it imports pyvista and renders
        the braided mandrel while this process analyses and writes the data files, then
        renders the surface pictures from the fields it is handed. Embree is not used in the
        workers.
    startup_s : seconds from the process's start to ``started`` (the interpreter and the imports),
        listed as the stage ``start`` when given
    settings : the numerical settings of every stage (``preform.Settings``; None: the defaults);
        its ``offset`` for the surfaces of a stack
    say : called with each note as it arises (the check stage's work estimate before the
        simulation starts), or None; the notes are in the outcome either way
    Raises PreformError for bad input or an unusable folder (before simulating) and
    ResultsWriteError when writing fails after the simulation (the checkpoints are kept).
    """
    t0 = time.perf_counter() if started is None else started
    settings = resolved(settings)
    out_dir = Path(out_dir)
    checked = check(load(config, geometry, settings), out_dir, force=force, settings=settings)
    _said(say, checked.notes)
    with RunLock(out_dir):
        stages = {} if startup_s is None else {"start": float(startup_s)}
        stages["load_and_check"] = time.perf_counter() - t0
        simulated = simulate(checked, progress=progress, resume=resume, settings=settings)
        stages.update(simulated.stages)
        # the 3-D pictures start now, on the second core, beside the analysis and the data files
        pictures = (io.start_pictures(simulated.result, out_dir, settings, simulated.results[1:])
                    if background_pictures else None)
        try:
            analysed, analysis_stages = analyse(checked, simulated)
        except BaseException:
            if pictures is not None:
                pictures.stop()
            raise
        stages.update(analysis_stages)
        try:
            written = write(analysed, out_dir, stages=stages, pictures=pictures)
        except OSError as err:
            kept = checked.layers[0].checkpoint if not checked.stacked else f"{out_dir}/checkpoint_layer*.npz"
            raise ResultsWriteError(
                f"cannot write the results to {out_dir} ({err.strerror or err}); the "
                f"{'simulations are' if checked.stacked else 'simulation is'} kept in {kept}: once "
                "the folder is writable, `preform run CONFIG --resume` writes the results without "
                "simulating again") from None
        if simulated.result.status == "done":
            for layer in checked.layers:
                Checkpoint(layer.checkpoint, layer.config).remove()
    notes = [*checked.notes, *_said(say, simulated.notes)]
    return CaseOutcome(result=simulated.result, out_dir=out_dir, written=written, notes=notes)


def _said(say, notes):
    """``notes``, each passed to ``say`` first (when given): the caller shows them now."""
    if say is not None:
        for note in notes:
            say(note)
    return notes


def run_layers(config, out_dir, **kwargs) -> CaseOutcome:
    """:func:`run_case` of a config with ``[[layer]]`` tables (the same flow: kept for callers
    that name it)."""
    return run_case(config, out_dir, **kwargs)
