"""The work of a first run that a warm run does not do, done on the second core while this
process loads the mandrel: compiling numba kernels, and building the field mesh.

On a first run in an environment (numba's on-disk cache lacks the kinematic kernels), ``preform
run`` compiles kernels for most of its first 10-30 s: the intake and check kernels
(``_kernels.mesh``, ``edges``, ``sections``) while it loads and checks a mandrel of
``IntakeSettings.kernel_faces`` faces or more (smaller ones take their NumPy forms,
``geometry.small_mesh``, and compile nothing), then the
stepper's (``_kernels.kinematic`` and the centerline projection) and the field kernels
(``_kernels.fields``); its map then builds the field mesh, which later runs read from the preform
cache. The first group is needed at once, the rest only after it, so :func:`start` launches a
worker process that runs small representative jobs meanwhile (:data:`JOBS`, in the order the run
needs what they make): ``projection`` (the centerline projection, which the checks need too:
compiled first, the command loads it), ``stepper``, ``laid`` and ``angles`` (the laid yarn's and the
history's braid angles: two jobs, so the process free first takes one), then
what the map needs: ``clip`` and ``pool`` (the field kernels) and ``field_mesh`` (the run's own
field mesh, into the preform cache). The kernels are
``cache=True``: the worker writes them to the cache and this process loads them when it gets
there instead of compiling them.

The jobs are claimed through files created exclusively in a folder of the two processes: the
worker claims them from the front; :meth:`Warmup.finish` (called once the mandrel is loaded and
checked) claims what the worker has not reached, from the back, and runs it here, then waits for
the jobs the worker holds: whichever process is free takes the next job. Before loading the
mandrel, :meth:`Warmup.lead` runs a map job here while the worker does its first job (on a
small mandrel the command would otherwise reach the projection first and compile it too). A compile job is the
run's own code on a small cylinder (the same calls, so the same argument types and the same
compiled specialisations), so nothing here knows the kernels' types; a job that fails, or a
worker that dies, only means that the run does that work itself.

The worker is a fresh interpreter (``python -m preform._jit``), not a fork: embree's thread pool
and numba's state in this process are not fork-safe once started.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: longest wait (s) for the worker's jobs before this process compiles what it needs itself
WAIT_LIMIT_S = 300.0


def kernels_cached(kernels) -> bool:
    """Whether numba's on-disk cache holds each of the ``cache=True`` kernels (their index files
    exist: numba then loads them instead of compiling)."""
    for kernel in kernels:
        cache = getattr(kernel, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
        if index is None or not os.path.exists(index):
            return False
    return True


def entry_kernels():
    """The kernels the jobs' code calls from Python last (each compiles the helpers it calls):
    when they are cached, so is what the jobs would compile. Not a whole module's kernels: some
    (``tangency_gap``, ``smooth_normals_batch``, ...) a kinematic run never calls."""
    from ._kernels import fields, kinematic

    return (kinematic.advance_fell_points, kinematic.lifted_points, kinematic.braid_cosines_batch,
            kinematic.laid_yarn_angles, fields.clip_polylines, fields.pool_sums)


def needed(config) -> bool:
    """Whether a run of ``config`` is a first run worth a worker: a kinematic model and numba's
    cache without the stepper's or the field kernels (later runs load them)."""
    if config.model.kind != "kinematic" or os.environ.get("NUMBA_DISABLE_JIT", "0") != "0":
        return False
    return not kernels_cached(entry_kernels())


# ------------------------------------------------------------------------------------- jobs
def small_case(config):
    """(config, mandrel, centerline): ``config`` on a cylinder of 5 cm radius long enough for its
    start (the machine, yarn, model and step settings of the run, so the same code paths run)."""
    from .geometry import centerline_from_points, shapes
    from .geometry.mandrel import mandrel_from_arrays

    radius = 0.05
    length = config.process.initial_position + 0.5
    mandrel = mandrel_from_arrays(*shapes.cylinder(radius, length, n_around=32), source="warm-up cylinder")
    centerline = centerline_from_points(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]]))
    process = dataclasses.replace(config.process, braid_length=0.01)
    return dataclasses.replace(config, process=process, layers=()), mandrel, centerline


def job_projection(config, mandrel=None):
    """The centerline projection of points (``Centerline.project``): the first kernel that both the
    command's checks and the stepper need, so the worker compiles it first and the command loads
    it instead of compiling it a second time at the same moment."""
    _, cylinder, centerline = small_case(config)
    centerline.project(cylinder.vertices)


def job_stepper(config, mandrel=None):
    """Three steps of the kinematic stepper on :func:`small_case`: the mandrel's arrays, the
    projection, ray and walk kernels."""
    from .simulation import make_stepper

    small, cylinder, centerline = small_case(config)
    make_stepper(small, cylinder, centerline).run(progress=False, max_steps=3)


def _analysis_case(config):
    """(small config, surface arrays, centerline, two points on faces 0 and 1, those faces, their
    centerline coordinates, a direction each) on :func:`small_case`'s cylinder, the arguments
    the analysis jobs pass as a result does."""
    from .kinematic import SurfaceArrays

    small, cylinder, centerline = small_case(config)
    arrays = SurfaceArrays.from_mandrel(cylinder)
    faces = np.array([0, 1], dtype=np.int64)
    points = np.ascontiguousarray(np.asarray(cylinder.vertices)[np.asarray(cylinder.faces)[faces]].mean(axis=1))
    s, _ = centerline.project(points)
    directions = np.ascontiguousarray(points[::-1] - points)
    return small, arrays, centerline, points, faces, s, directions


def job_angles(config, mandrel=None):
    """The braid angles of the history (``analysis.braid_angles_at``), as a result computes
    them, on two points of :func:`small_case`'s surface."""
    from .laid import braid_angles_at

    _, arrays, centerline, points, faces, s, directions = _analysis_case(config)
    braid_angles_at(arrays, centerline, points, faces, s, directions)


def job_laid(config, mandrel=None):
    """The laid yarn's braid angles of the yarn paths (``analysis.laid_braid_angles``), as a
    result computes them, on the same two points."""
    from .laid import laid_braid_angles, mandrel_friction
    from .tolerances import tol

    small, arrays, centerline, points, faces, s, _ = _analysis_case(config)
    laid_braid_angles(arrays, None, centerline, points, faces, np.array([0, 2], dtype=np.int64),
                      mandrel_friction(small), tol.slip_curvature, s=s)


def job_clip(config, mandrel=None):
    """Two helices clipped to the faces of a small cylinder (``fields.clip_yarns`` as
    ``fields.map_to_surface`` calls it, on ``pipeline.small_map_case``): the clipping kernels."""
    from .analysis.fields import clip_yarns, face_geometry
    from .pipeline import small_map_case

    result, (V, F, _, _) = small_map_case(config)
    normals, _, centroids = face_geometry(V, F)
    clip_yarns(result.yarns, V, F, normals, centroids, with_first=True)


def job_pool(config, mandrel=None):
    """The neighbourhood sums of the same small cylinder's faces (``fields.pool`` as
    ``fields.map_to_surface`` calls it): the pooling kernels."""
    from .analysis.fields import face_geometry, pool
    from .pipeline import small_map_case

    _, (V, F, _, h) = small_map_case(config)
    normals, areas, centroids = face_geometry(V, F)
    pool(centroids, normals, 2.0 * h, areas[:, None])


def job_field_mesh(config, mandrel=None):
    """The run's field mesh (the mandrel remeshed to the field edge length, a second or more)
    built into the preform cache (``io.cache.cached_field_mesh``), so that the run's map reads it
    instead of building it after the simulation. ``mandrel``: the run's (in the command); the
    worker reads it from the cache, where the command stored it on loading, and leaves the job
    to the run when it is not there yet. Nothing to do without the cache or with ``[[layer]]``
    tables (the layers' field mesh is built on the way), nor where the cache cannot be written
    (the map would build it a second time)."""
    from types import SimpleNamespace

    from .io.cache import cache_dir, cached_field_mesh, cached_mandrel

    folder = cache_dir()
    if folder is None or config.layers or not (folder.is_dir() and os.access(folder, os.W_OK)):
        return
    if mandrel is None:
        mc = config.mandrel
        mandrel = cached_mandrel(mc.stl, unit=mc.stl_unit, body=mc.body, build=False)
        if mandrel is None:
            return
    cached_field_mesh(SimpleNamespace(config=config, mandrel=mandrel))


#: each job's function of the run's config (and the run's mandrel, when the command runs it), in
#: the order the run needs what they make; the last three are the map's, each 1-2 s of CPU, the
#: two angle jobs 0.5 s each: the worker (from the front) and the command (from the back) meet
#: among them, and small jobs there keep the two processes' finishing times within about one job
#: of each other
RUNNERS = {"projection": job_projection, "stepper": job_stepper, "laid": job_laid, "angles": job_angles,
           "clip": job_clip, "field_mesh": job_field_mesh, "pool": job_pool}
#: the jobs, in that order
JOBS = tuple(RUNNERS)
#: what the command runs before it loads the mandrel while the worker does its first job
#: (:meth:`Warmup.lead`): the shortest of the map's compile jobs, which need none of its kernels
LEAD_JOBS = ("clip",)


# ------------------------------------------------------------------------------ compile log
#: the job this process is running (for the compile log), if any
_RUNNING: list = []
#: this process's role in the log (``main`` or ``worker``), set by :class:`CompileLog`
_ROLE: list = []

#: environment variable naming a file to which every process of the run appends one JSON line per
#: numba compilation and per warm-up job (``benchmarks/bench_pipeline.py --jit``,
#: ``tests/test_jit.py``)
LOG_ENV = "PREFORM_JIT_LOG"


def _log(line: dict) -> None:
    """Append ``line`` (with this process's pid and role) to ``$PREFORM_JIT_LOG``, if set."""
    path = os.environ.get(LOG_ENV, "")
    if path:
        import json

        line = {"pid": os.getpid(), "role": _ROLE[-1] if _ROLE else "", **line}
        with open(path, "a") as f:
            f.write(json.dumps(line) + "\n")


class CompileLog:
    """While entered and ``$PREFORM_JIT_LOG`` is set: numba's ``numba:compile`` events (raised for
    a compilation, not for a cache load) appended to that file, one JSON line each: ``pid``,
    ``role`` (``main`` or ``worker``), ``event`` ("compile"), ``job`` (the warm-up job running,
    "" for the run's own work), ``kernel`` (module and name), ``depth`` (0 for a kernel
    called from Python, 1 and more for one compiled inside another's compilation), ``start_s``
    (``time.time()``), ``wall_s`` and ``cpu_s`` (this process's CPU time over the compilation,
    the nested ones included). The warm-up jobs add their own lines (``event`` "job": ``job``,
    ``start_s``, ``wall_s``, ``cpu_s``) and :meth:`Warmup.finish` one when it returns
    (``event`` "finished", ``start_s``)."""

    def __init__(self, role: str):
        self.role = role
        self.path = os.environ.get(LOG_ENV, "")
        self.listener = None

    def __enter__(self):
        _ROLE.append(self.role)
        if not self.path:
            return self
        from numba.core import event

        class Listener(event.Listener):
            stack: list = []

            def on_start(self, ev):
                self.stack.append((time.time(), time.perf_counter(), time.process_time()))

            def on_end(self, ev):
                t_wall, t0, c0 = self.stack.pop()
                fn = ev.data["dispatcher"].py_func
                _log({"event": "compile", "job": _RUNNING[-1] if _RUNNING else "",
                      "kernel": f"{fn.__module__}.{fn.__qualname__}", "depth": len(self.stack),
                      "start_s": t_wall, "wall_s": time.perf_counter() - t0,
                      "cpu_s": time.process_time() - c0})

        self.event, self.listener = event, Listener()
        event.register("numba:compile", self.listener)
        return self

    def __exit__(self, *exc):
        _ROLE.pop()
        if self.listener is not None:
            self.event.unregister("numba:compile", self.listener)
        return False


# ------------------------------------------------------------------------------ coordination
def _claim(folder: Path, job: str) -> bool:
    """True for the one process that creates ``job``'s claim file first."""
    try:
        os.close(os.open(folder / f"{job}.claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
    except FileExistsError:
        return False
    return True


def _run(folder: Path, job: str, config, runners=None, mandrel=None) -> None:
    """Run ``job`` (``runners[job](config)``, :data:`RUNNERS` by default; ``mandrel=`` too when
    given) and mark it done (also when it fails: the run then does the work itself)."""
    _RUNNING.append(job)
    start, t0, c0 = time.time(), time.perf_counter(), time.process_time()
    try:
        runner = (RUNNERS if runners is None else runners)[job]
        runner(config) if mandrel is None else runner(config, mandrel=mandrel)
    except Exception:   # noqa: BLE001 - a warm-up's failure must not stop the run
        pass
    finally:
        _RUNNING.pop()
        (folder / f"{job}.done").touch()
        _log({"event": "job", "job": job, "start_s": start, "wall_s": time.perf_counter() - t0,
              "cpu_s": time.process_time() - c0})


class Warmup:
    """The worker of a first run (see module docstring); :meth:`finish` before simulating."""

    def __init__(self, folder: Path, process: subprocess.Popen, config, runners=None):
        self.folder = folder
        self.process = process
        self.config = config
        self.runners = RUNNERS if runners is None else runners

    def lead(self, jobs=LEAD_JOBS) -> None:
        """Before the command loads and checks the mandrel: unless the worker has done its first
        job (the centerline projection, which the checks call), run ``jobs`` here, then wait for
        that job (while the worker runs, at most :data:`WAIT_LIMIT_S`). A small mandrel loads
        without compiling (``geometry.small_mesh``), so the command would otherwise reach the
        projection first and compile it a second time at the same moment; waiting for the
        worker, which started on it earlier, ends sooner."""
        first = self.folder / f"{next(iter(self.runners))}.done"
        for job in jobs:
            if first.exists() or self.process.poll() is not None:
                return
            if job in self.runners and _claim(self.folder, job):
                _run(self.folder, job, self.config, self.runners)
        deadline = time.monotonic() + WAIT_LIMIT_S
        while not first.exists() and self.process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)

    def finish(self, mandrel=None) -> None:
        """Run here the jobs the worker has not claimed yet (the last ones first; ``mandrel``: the
        run's, for the field mesh), wait for the ones it holds (at most :data:`WAIT_LIMIT_S`, and
        only while it runs), and clean up."""
        try:
            for job in reversed(list(self.runners)):
                if _claim(self.folder, job):
                    _run(self.folder, job, self.config, self.runners, mandrel)
            deadline = time.monotonic() + WAIT_LIMIT_S
            while not all((self.folder / f"{job}.done").exists() for job in self.runners):
                if self.process.poll() is not None or time.monotonic() > deadline:
                    break
                time.sleep(0.02)
        finally:
            self.stop()
            _log({"event": "finished", "start_s": time.time()})

    def stop(self) -> None:
        """End the worker (if still running) and remove the claims folder."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        shutil.rmtree(self.folder, ignore_errors=True)


def start(config, config_path, model: str = ""):
    """The worker running :data:`JOBS` for ``config`` (read from ``config_path``, with
    ``[model] kind`` replaced by ``model`` when given), or None when not :func:`needed`."""
    return launch(config, config_path, model) if needed(config) else None


def launch(config, config_path, model: str = ""):
    """The worker (:func:`main`, a fresh interpreter) and its claims folder, as a :class:`Warmup`;
    None when it cannot be started."""
    folder = Path(tempfile.mkdtemp(prefix="preform-jit-"))
    argv = [sys.executable, "-m", "preform._jit", str(folder), str(config_path), model]
    try:
        process = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, close_fds=True)
    except OSError:
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return Warmup(folder, process, config)


class _Stopped(Exception):
    """SIGTERM in the worker. An Exception, so that numba's and the preform cache's writes remove
    their temporary files on the way out (they clean up on Exception); the worker then claims
    no further job."""


def _on_sigterm(signum, frame):
    _STOPPED.append(signum)
    raise _Stopped("stopped")


#: the signal that stopped the worker, once it has
_STOPPED: list = []


def main(argv=None) -> int:
    """The worker: ``python -m preform._jit FOLDER CONFIG [MODEL]``; exit code 0, or 128 + the
    signal's number when stopped."""
    folder, config_path, *rest = sys.argv[1:] if argv is None else argv
    import signal

    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        from .config import load_config

        config = load_config(config_path)
        model = rest[0] if rest else ""
        if model:
            config = dataclasses.replace(config, model=dataclasses.replace(config.model, kind=model))
        with CompileLog("worker"):
            for job in JOBS:
                if _STOPPED:
                    break
                if _claim(Path(folder), job):
                    _run(Path(folder), job, config)
    except _Stopped:
        pass
    return 128 + _STOPPED[0] if _STOPPED else 0


if __name__ == "__main__":
    sys.exit(main())
