"""A first run's numba compilations shared with a second process.

numba compiles a kernel the first time it is called with new argument types; the kernels are
``cache=True``, so a compiled kernel is written to numba's on-disk cache, and any later call
with those types, in any process, loads it from there. A first run of ``preform run`` in an
environment compiles, one kernel after another, in the order the run needs them: the mesh intake
and the checks, the stepper, the braid angles, the field map. At the command's first compilation
(numba's ``numba:compile`` event, raised for a compilation, not for a cache load) and when a
core is idle, :class:`Warmup` starts a worker process (``python -m preform._jit``) that runs the
same code on a small cylinder with the run's settings (the same argument types, so the same
compiled specialisations): while the command compiles the repair's and then the stepper's
kernels, the worker compiles the checks', a mandrel's and the projector's, then the braid
angles' and the map's (:data:`JOBS`), and builds the run's field mesh into the preform cache;
what one compiled, the other loads. Nothing is coordinated beyond that: a job that fails, or a
worker that is slow or dies, only means that the command compiles or builds that part itself.
The worker is a fresh interpreter, not a fork: embree's thread pool and numba's state are not
fork-safe once started.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from .zone import zone_class

#: environment variable naming a file to which the command and the worker append one JSON line per
#: numba compilation and per worker job (``benchmarks/bench_pipeline.py --jit``, the tests)
LOG_ENV = "PREFORM_JIT_LOG"


# ------------------------------------------------------------------------------------- jobs
def _cylinder(config):
    """(config, vertices, faces, centerline): ``config`` braiding 1 cm on a cylinder of 5 cm
    radius long enough for its start, with the run's machine, yarn, model and step settings."""
    from .geometry import centerline_from_points, shapes

    length = config.process.initial_position + 0.5
    V, F = shapes.cylinder(0.05, length, n_around=32)
    centerline = centerline_from_points(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]]))
    process = dataclasses.replace(config.process, braid_length=0.01)
    return dataclasses.replace(config, process=process, layers=()), V, F, centerline


def small_case(config):
    """(config, mandrel, centerline) of :func:`_cylinder`."""
    from .geometry.mandrel import mandrel_from_arrays

    small, V, F, centerline = _cylinder(config)
    return small, mandrel_from_arrays(V, F, source="warm-up cylinder"), centerline


def job_checks(config):
    """The checks' kernels on :func:`_cylinder`'s arrays (not the mandrel's own arrays, whose
    kernels the command is compiling meanwhile): the centerline projection, the winding numbers
    of the centerline-inside check, the section loops of the perimeters."""
    from .checks import _check_centerline_inside
    from .geometry.centerline import section_perimeters
    from .geometry.sections import SectionIndex

    small, V, F, centerline = _cylinder(config)
    centerline.project(np.ascontiguousarray(V, dtype=np.float64))
    surface = SimpleNamespace(vertices=V, faces=F, sections=SectionIndex(V, F))
    _check_centerline_inside(small, surface, centerline)
    section_perimeters(surface, centerline, np.array([0.1, 0.2]))


def job_arrays(config):
    """A mandrel's own arrays (``mandrel_from_arrays``: face normals, neighbours, corner normals)
    on :func:`_cylinder`'s arrays."""
    small_case(config)


def small_map_case(config):
    """(result, (V, F, source faces, edge length)) for ``fields.map_to_surface(result, mesh=...)``:
    two helices on a cylinder of 5 cm radius with ``config``'s yarn, the cylinder's own triangles
    as the field mesh (the array types of a run's map)."""
    from .geometry import centerline_from_points, shapes
    from .geometry.mandrel import mandrel_from_arrays
    from .result import YarnPaths

    r, length = 0.05, 0.1
    mandrel = mandrel_from_arrays(*shapes.cylinder(r, length, n_around=24))
    centerline = centerline_from_points(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]]))
    z = np.linspace(0.0, length, 41)
    points = [np.column_stack([r * np.cos(sign * 10 * z), r * np.sin(sign * 10 * z), z]) for sign in (-1, 1)]
    m = 2 * len(z)
    yarns = YarnPaths(points=np.vstack(points), offsets=np.array([0, len(z), m], dtype=np.int64),
                      time_s=np.zeros(m), braid_angle_deg=np.zeros(m), face=np.full(m, -1, np.int64),
                      flags=np.zeros(m, np.uint8), group=np.array([0, 1], np.int8))
    result = SimpleNamespace(config=config, mandrel=mandrel, centerline=centerline, yarns=yarns)
    V = np.ascontiguousarray(mandrel.vertices, dtype=np.float64)
    F = np.ascontiguousarray(mandrel.faces, dtype=np.int64)
    return result, (V, F, np.arange(len(F), dtype=np.int64), 0.02)


def job_projector(config):
    """The stepper's arc-length projector (``laid.CenterlineProjector``: its sample tree and
    the projection on it) on :func:`_cylinder`'s centerline."""
    from .laid import CenterlineProjector
    from .tolerances import tol

    _, V, _, centerline = _cylinder(config)
    CenterlineProjector(centerline, spacing=tol.projector_spacing)(V)


def job_pool(config):
    """The neighbourhood sums of the map (``fields.pool``) on :func:`small_map_case`'s faces."""
    from .analysis.fields import face_geometry, pool

    _, (V, F, _, h) = small_map_case(config)
    normals, areas, centroids = face_geometry(V, F)
    pool(centroids, normals, 2.0 * h, areas[:, None])


def job_clip(config):
    """The yarns clipped to the faces (``fields.clip_yarns`` as the map calls it)."""
    from .analysis.fields import clip_yarns, face_geometry

    result, (V, F, _, _) = small_map_case(config)
    normals, _, centroids = face_geometry(V, F)
    clip_yarns(result.yarns, V, F, normals, centroids, with_first=True)


def _analysis_case(config):
    """(config, surface arrays, centerline, points on faces 0 and 1, those faces, their arc
    lengths, a direction each) on :func:`small_case`'s cylinder, as a result passes them."""
    from .kinematic import SurfaceArrays

    small, cylinder, centerline = small_case(config)
    arrays = SurfaceArrays.from_mandrel(cylinder)
    faces = np.array([0, 1], dtype=np.int64)
    points = np.ascontiguousarray(np.asarray(cylinder.vertices)[np.asarray(cylinder.faces)[faces]].mean(axis=1))
    s, _ = centerline.project(points)
    return small, arrays, centerline, points, faces, s, np.ascontiguousarray(points[::-1] - points)


def job_laid(config):
    """The laid yarn's braid angles (``laid.laid_braid_angles``) on two points."""
    from .laid import laid_braid_angles, mandrel_friction
    from .tolerances import tol

    small, arrays, centerline, points, faces, s, _ = _analysis_case(config)
    laid_braid_angles(arrays, None, centerline, points, faces, np.array([0, 2], dtype=np.int64),
                      mandrel_friction(small), tol.slip_curvature, s=s)


def job_angles(config):
    """The history's braid angles (``laid.braid_angles_at``) on two points."""
    from .laid import braid_angles_at

    _, arrays, centerline, points, faces, s, directions = _analysis_case(config)
    braid_angles_at(arrays, centerline, points, faces, s, directions)


def job_field_mesh(config):
    """The run's field mesh into the preform cache (``io.cache.cached_field_mesh``), from the
    mandrel the command stored there on loading it; nothing when it is not there (yet), without
    the cache, or with ``[[layer]]`` tables (the layers build theirs on the way)."""
    from .io.cache import cache_dir, cached_field_mesh, cached_mandrel

    folder = cache_dir()
    if folder is None or config.layers or not (folder.is_dir() and os.access(folder, os.W_OK)):
        return
    mc = config.mandrel
    mandrel = cached_mandrel(mc.stl, unit=mc.stl_unit, body=mc.body, build=False)
    if mandrel is not None:
        cached_field_mesh(SimpleNamespace(config=config, mandrel=mandrel))


#: the worker's jobs, in the order the command needs what they compile while it compiles the
#: repair's and then the stepper's kernels itself: the checks', a mandrel's and the stepper's
#: projector kernels (right after the repair), the braid angles' (after the simulation), the map's
#: and the field mesh (from the mandrel the command stored in the cache when it loaded it)
JOBS = (("checks", job_checks), ("arrays", job_arrays), ("projector", job_projector), ("laid", job_laid),
        ("angles", job_angles), ("pool", job_pool), ("clip", job_clip), ("field_mesh", job_field_mesh))


# ------------------------------------------------------------------------------ compile log
def _log(line: dict) -> None:
    """Append ``line`` (with this process's pid) to ``$PREFORM_JIT_LOG``, if set."""
    path = os.environ.get(LOG_ENV, "")
    if path:
        import json

        with open(path, "a") as f:
            f.write(json.dumps({"pid": os.getpid(), **line}) + "\n")


class _Listener:
    """numba ``numba:compile`` listener: ``first()`` at the first compilation; with the log set,
    one line per compilation (``event`` "compile", ``role``, ``job`` running or "", ``kernel``,
    ``depth`` 0 for a kernel called from Python, ``start_s``, ``wall_s``, ``cpu_s``)."""

    def __init__(self, role, first=None):
        from numba.core import event

        self.role, self.first, self.job, self.stack, self.event = role, first, "", [], event
        outer = self

        class Listener(event.Listener):
            def on_start(self, ev):
                if outer.first is not None:
                    first, outer.first = outer.first, None
                    first()
                outer.stack.append((time.time(), time.perf_counter(), time.process_time()))

            def on_end(self, ev):
                start, t0, c0 = outer.stack.pop()
                fn = ev.data["dispatcher"].py_func
                _log({"event": "compile", "role": outer.role, "job": outer.job,
                      "kernel": f"{fn.__module__}.{fn.__qualname__}", "depth": len(outer.stack),
                      "start_s": start, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0})

        self.listener = Listener()

    def __enter__(self):
        self.event.register("numba:compile", self.listener)
        return self

    def __exit__(self, *exc):
        self.event.unregister("numba:compile", self.listener)
        return False


@dataclass(frozen=True)
class WarmupSettings:
    """When a first run starts the compile worker."""

    #: the worker only gains on a core nobody else uses: it is started while the 1-minute load
    #: average is below the number of cores minus this
    idle_core: float = 0.5
    #: seconds the command waits, at its end, for a worker still running to leave after SIGTERM
    #: (it leaves once the compilation in progress returns) before killing it
    stop_wait_s: float = 5.0


#: the defaults
WARMUP = WarmupSettings()


def _idle_core(settings) -> bool:
    """Whether the machine has a core to spare (``settings.idle_core``); True where the load
    average is not known."""
    try:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        return os.getloadavg()[0] < cores - settings.idle_core
    except (AttributeError, OSError):
        return True


class Warmup:
    """While entered: at the command's first numba compilation, the worker for ``config`` (read
    from ``config_path``, ``[model] kind`` replaced by ``model`` when given), for a model whose
    zone asks for it (``Zone.first_run_worker``: the kinematic one) and when a core is idle
    then (``settings``); on exit it is stopped if still running
    (SIGTERM, then killed after ``settings.stop_wait_s``)."""

    def __init__(self, config, config_path, model: str = "", settings: WarmupSettings = WARMUP):
        self.argv = [sys.executable, "-m", "preform._jit", str(config_path), model]
        self.settings = settings
        self.process = None
        worker = zone_class(config.model.kind).first_run_worker
        self.compiles = _Listener("main", self.start if worker else None)

    def start(self):
        if not _idle_core(self.settings):
            return
        try:
            self.process = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL, close_fds=True)
        except OSError:   # no worker: the command compiles everything itself
            self.process = None

    def __enter__(self):
        self.compiles.__enter__()
        return self

    def __exit__(self, *exc):
        self.compiles.__exit__(*exc)
        self.stop()
        return False

    def stop(self):
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=self.settings.stop_wait_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


class _Stopped(Exception):
    """SIGTERM in the worker. An Exception, so that numba's and the preform cache's writes remove
    their temporary files on the way out (they clean up on Exception)."""


def _on_sigterm(signum, frame):
    raise _Stopped(signum)


def main(argv=None) -> int:
    """The worker: ``python -m preform._jit CONFIG [MODEL]``; exit code 0, or 143 when stopped."""
    import signal

    config_path, *rest = sys.argv[1:] if argv is None else argv
    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        from .config import load_config

        config = load_config(config_path)
        if rest and rest[0]:
            config = dataclasses.replace(config, model=dataclasses.replace(config.model, kind=rest[0]))
        with _Listener("worker") as log:
            for name, job in JOBS:
                log.job = name
                start, t0, c0 = time.time(), time.perf_counter(), time.process_time()
                try:
                    job(config)
                except _Stopped:
                    raise
                except Exception:   # noqa: BLE001 - a failed job: the command does that work itself
                    pass
                _log({"event": "job", "role": "worker", "job": name, "start_s": start,
                      "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0})
    except _Stopped:
        return 128 + signal.SIGTERM
    return 0


if __name__ == "__main__":
    sys.exit(main())
