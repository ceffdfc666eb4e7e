"""The numba kernels of a first run compiled on the second core while this process loads the mandrel.

On a first run in an environment (numba's on-disk cache lacks the kinematic kernels), ``preform
run`` compiles kernels for most of its first 20-30 s: the intake and check kernels
(``_kernels.mesh``, ``edges``, ``sections``) while it loads and checks the mandrel, then the
stepper's (``_kernels.kinematic`` and the centerline projection) and the field kernels
(``_kernels.fields``). The first group is needed at once, the others only after it, so
:func:`start` launches a worker process that compiles the others meanwhile by running small
representative jobs (:data:`JOBS`, in the order the run needs them). The kernels are
``cache=True``: the worker writes them to the cache and this process loads them when it gets
there instead of compiling them.

The jobs are claimed through files created exclusively in a folder of the two processes: the
worker claims them from the front; :meth:`Warmup.finish` (called once the mandrel is loaded and
checked) claims what the worker has not reached and runs it here, then waits for the jobs the
worker holds. A job is the run's own code on a small cylinder (the same calls, so the same
argument types and the same compiled specialisations), so nothing here knows the kernels' types;
a job that fails only means that the run compiles what it needs itself.

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


def job_kinematic(config):
    """A few steps of the kinematic stepper and the result's analysis (braid angles of the laid
    yarn) on :func:`small_case`: the stepper's, the projection's and the analysis kernels."""
    from .simulation import make_stepper

    small, mandrel, centerline = small_case(config)
    stepper = make_stepper(small, mandrel, centerline)
    stepper.run(progress=False, max_steps=3)
    stepper.result("done", "", 0.0)


def job_fields(config):
    """Two helices mapped onto a small cylinder (``pipeline._compile_map_kernels``): the field
    kernels."""
    from .pipeline import _compile_map_kernels

    _compile_map_kernels(config)


#: each job's function of the run's config, in the order the run needs their kernels
RUNNERS = {"kinematic": job_kinematic, "fields": job_fields}
#: the jobs, in that order
JOBS = tuple(RUNNERS)


# ------------------------------------------------------------------------------ compile log
#: the job this process is running (for the compile log), if any
_RUNNING: list = []

#: environment variable naming a file to which every process of the run appends one JSON line per
#: numba compilation (``benchmarks/bench_pipeline.py --jit``, ``tests/test_jit.py``)
LOG_ENV = "PREFORM_JIT_LOG"


class CompileLog:
    """While entered and ``$PREFORM_JIT_LOG`` is set: numba's ``numba:compile`` events (raised for
    a compilation, not for a cache load) appended to that file, one JSON line each: ``pid``,
    ``role`` (``main`` or ``worker``), ``job`` (the warm-up job running, "" for the run's own
    work), ``kernel`` (module and name), ``depth`` (0 for a kernel
    called from Python, 1 and more for one compiled inside another's compilation), ``start_s``
    (``time.time()``), ``wall_s`` and ``cpu_s`` (this process's CPU time over the compilation,
    the nested ones included)."""

    def __init__(self, role: str):
        self.role = role
        self.path = os.environ.get(LOG_ENV, "")
        self.listener = None

    def __enter__(self):
        if not self.path:
            return self
        import json

        from numba.core import event

        log = self

        class Listener(event.Listener):
            stack: list = []

            def on_start(self, ev):
                self.stack.append((time.time(), time.perf_counter(), time.process_time()))

            def on_end(self, ev):
                t_wall, t0, c0 = self.stack.pop()
                fn = ev.data["dispatcher"].py_func
                line = {"pid": os.getpid(), "role": log.role, "job": _RUNNING[-1] if _RUNNING else "", "kernel": f"{fn.__module__}.{fn.__qualname__}",
                        "depth": len(self.stack), "start_s": t_wall, "wall_s": time.perf_counter() - t0,
                        "cpu_s": time.process_time() - c0}
                with open(log.path, "a") as f:
                    f.write(json.dumps(line) + "\n")

        self.event, self.listener = event, Listener()
        event.register("numba:compile", self.listener)
        return self

    def __exit__(self, *exc):
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


def _run(folder: Path, job: str, config, runners=None) -> None:
    """Run ``job`` (``runners[job](config)``, :data:`RUNNERS` by default) and mark it done (also
    when it fails: the run then compiles what it needs)."""
    _RUNNING.append(job)
    try:
        (RUNNERS if runners is None else runners)[job](config)
    except Exception:   # noqa: BLE001 - a warm-up's failure must not stop the run
        pass
    finally:
        _RUNNING.pop()
        (folder / f"{job}.done").touch()


class Warmup:
    """The worker of a first run (see module docstring); :meth:`finish` before simulating."""

    def __init__(self, folder: Path, process: subprocess.Popen, config, runners=None):
        self.folder = folder
        self.process = process
        self.config = config
        self.runners = RUNNERS if runners is None else runners

    def finish(self) -> None:
        """Run here the jobs the worker has not claimed yet (the last ones first), wait for the
        ones it holds (at most :data:`WAIT_LIMIT_S`), and clean up."""
        try:
            for job in reversed(list(self.runners)):
                if _claim(self.folder, job):
                    _run(self.folder, job, self.config, self.runners)
            deadline = time.monotonic() + WAIT_LIMIT_S
            while not all((self.folder / f"{job}.done").exists() for job in self.runners):
                if self.process.poll() is not None or time.monotonic() > deadline:
                    break
                time.sleep(0.02)
        finally:
            self.stop()

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
    """The worker compiling :data:`JOBS` for ``config`` (read from ``config_path``, with
    ``[model] kind`` replaced by ``model`` when given), or None when not :func:`needed`."""
    if not needed(config):
        return None
    folder = Path(tempfile.mkdtemp(prefix="preform-jit-"))
    argv = [sys.executable, "-m", "preform._jit", str(folder), str(config_path), model]
    try:
        process = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, close_fds=True)
    except OSError:
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return Warmup(folder, process, config)


def main(argv=None) -> int:
    """The worker: ``python -m preform._jit FOLDER CONFIG [MODEL]``."""
    folder, config_path, *rest = sys.argv[1:] if argv is None else argv
    from .config import load_config

    config = load_config(config_path)
    model = rest[0] if rest else ""
    if model:
        config = dataclasses.replace(config, model=dataclasses.replace(config.model, kind=model))
    with CompileLog("worker"):
        for job in JOBS:
            if _claim(Path(folder), job):
                _run(Path(folder), job, config)
    return 0


if __name__ == "__main__":
    sys.exit(main())
