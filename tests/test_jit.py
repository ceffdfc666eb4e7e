"""The first run's compile worker (``preform._jit``): each job runs once, in one of the two
processes; a failing job does not stop the run; and on a real first run the main process
compiles none of the stepper's or the field kernels (the worker's small jobs compile the same
specialisations the run needs), and neither process the intake kernels (a small mandrel takes
their NumPy forms)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from preform import _jit

ROOT = Path(__file__).resolve().parents[1]


def finished_process():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p


def test_finish_runs_the_unclaimed_jobs_here_and_waits_for_the_claimed_ones(tmp_path):
    ran = []
    runners = {name: (lambda config, name=name: ran.append(name)) for name in ("a", "b", "c")}
    # the worker holds "a" and has finished it; "b" and "c" are left for this process
    assert _jit._claim(tmp_path, "a") and not _jit._claim(tmp_path, "a")
    (tmp_path / "a.done").touch()
    _jit.Warmup(tmp_path, finished_process(), config=None, runners=runners).finish()
    assert ran == ["c", "b"]              # the last-needed first
    assert not tmp_path.exists()           # the claims folder is removed


def test_lead_runs_a_job_here_then_waits_for_the_workers_first(tmp_path):
    """Before the mandrel is loaded: the command runs the lead jobs while the worker holds its
    first job, then waits for that one; nothing once it is done."""
    import threading

    ran = []
    runners = {name: (lambda config, name=name: ran.append(name)) for name in ("first", "b", "c")}
    assert _jit._claim(tmp_path, "first")                       # the worker holds it
    worker = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        done = threading.Timer(0.5, (tmp_path / "first.done").touch)
        done.start()
        warmup = _jit.Warmup(tmp_path, worker, config=None, runners=runners)
        warmup.lead(jobs=("c",))
        assert ran == ["c"] and (tmp_path / "first.done").exists()
        warmup.lead(jobs=("b",))                                 # the first job is done: nothing
        assert ran == ["c"]
        warmup.finish()
        assert ran == ["c", "b"]
    finally:
        worker.kill()
        worker.wait()


def test_a_failing_job_is_marked_done_and_does_not_raise(tmp_path):
    def broken(config):
        raise RuntimeError("no compiler today")

    folder = tmp_path / "claims"
    folder.mkdir()
    _jit._run(folder, "x", None, {"x": broken})
    assert (folder / "x.done").exists()


def test_a_dead_worker_costs_nothing_but_time(tmp_path):
    ran = []
    runners = {name: (lambda config, name=name: ran.append(name)) for name in ("a", "b")}
    assert _jit._claim(tmp_path, "a")      # the worker took "a" and died before finishing it
    _jit.Warmup(tmp_path, finished_process(), config=None, runners=runners).finish()
    assert ran == ["b"]                    # no wait for "a": the run compiles it itself
    assert not tmp_path.exists()


def test_a_stopped_worker_leaves_nothing_behind(tmp_path, monkeypatch):
    """``Warmup.stop`` (the command failed, e.g. a broken STL) ends a compiling worker through
    SIGTERM: it leaves by its ``finally`` blocks, so neither its claims folder nor a temporary
    file of numba's or the preform cache stays."""
    import time

    from preform.config import load_config

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(sys.path))
    toml = ROOT / "examples" / "case_a.toml"
    warmup = _jit.launch(load_config(toml), toml)
    deadline = time.monotonic() + 120
    while not (warmup.folder / "projection.claim").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)                        # compiling by now
    assert warmup.process.poll() is None
    warmup.stop()
    assert warmup.process.returncode == 143    # left by SIGTERM's handler, not killed
    assert not warmup.folder.exists()
    left = [p.name for p in tmp_path.rglob("*") if ".tmp" in p.name]
    assert left == []


def test_the_worker_field_mesh_is_the_one_the_run_builds(tmp_path, monkeypatch):
    """The field-mesh job in the worker reads the mandrel the command stored in the cache and
    writes the field mesh the run's map would build itself, byte for byte, under the key the
    map looks up."""
    from types import SimpleNamespace

    from preform.config import load_config
    from preform.analysis.fields import field_mesh
    from preform.geometry.mandrel import load_mandrel
    from preform.io.cache import cached_field_mesh, cached_mandrel

    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "cache"))
    config = load_config(ROOT / "examples" / "case_a.toml")
    mc = config.mandrel
    assert cached_mandrel(mc.stl, unit=mc.stl_unit, body=mc.body, build=False) is None
    _jit.job_field_mesh(config)            # no mandrel in the cache yet: nothing done
    assert not list((tmp_path / "cache").glob("field_mesh-*"))
    cached_mandrel(mc.stl, unit=mc.stl_unit, body=mc.body)      # the command loads it (stored)
    _jit.job_field_mesh(config)            # the worker's way
    (entry,) = (tmp_path / "cache").glob("field_mesh-*.npz")
    stamp = entry.stat().st_mtime_ns
    mandrel = load_mandrel(mc.stl, unit=mc.stl_unit, body=mc.body)
    run = SimpleNamespace(config=config, mandrel=mandrel)
    built = field_mesh(run)                # what the map would build without the cache
    got = cached_field_mesh(run)           # what the map reads
    assert entry.stat().st_mtime_ns == stamp                    # read, not built again
    for a, b in zip(got[:3], built[:3]):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    assert got[3] == built[3]


def test_no_worker_for_the_interaction_model():
    from preform.config import load_config
    import dataclasses

    cfg = load_config(ROOT / "examples" / "case_a.toml")
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"))
    assert not _jit.needed(cfg) and _jit.start(cfg, ROOT / "examples" / "case_a.toml") is None


@pytest.mark.slow
def test_first_run_main_process_compiles_no_stepper_or_field_kernel(tmp_path):
    toml = (ROOT / "examples" / "case_a.toml").read_text()
    toml = toml.replace("../mandrels/", str(ROOT / "mandrels") + "/").replace(
        "braid_length = 2.0", "braid_length = 0.05")
    config = tmp_path / "short.toml"
    config.write_text(toml)
    log = tmp_path / "jit.jsonl"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PREFORM_CACHE_DIR=str(tmp_path / "cache"),
               PREFORM_JIT_LOG=str(log), PYTHONPATH=os.pathsep.join(sys.path), TMPDIR=str(scratch))
    done = subprocess.run([sys.executable, "-m", "preform.cli", "run", str(config), "--out", str(tmp_path / "out"),
                           "--no-progress"], env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert "compiling the numba kernels" in done.stderr        # the run says that it compiles
    events = [json.loads(line) for line in log.read_text().splitlines()]
    lines = [d for d in events if d["event"] == "compile"]
    compiled = {d["kernel"] for d in lines}
    assert "preform._kernels.kinematic.advance_fell_points" in compiled
    assert "preform._kernels.fields.pool_sums" in compiled
    assert {d["role"] for d in lines} == {"main", "worker"}
    # the run's own work (outside the warm-up jobs, in either process) compiled none of the
    # stepper's or the field kernels: the jobs' small cases compile the specialisations the run
    # needs, and the run loaded them from the cache
    late = ("preform._kernels.kinematic.", "preform._kernels.fields.")
    run_compiled = sorted(d["kernel"] for d in lines if not d["job"] and d["kernel"].startswith(late))
    assert run_compiled == []
    # every job ran once, in one of the two processes; the command compiled the centerline
    # projection (needed by its checks and by the stepper) only through the worker
    jobs = sorted(d["job"] for d in events if d["event"] == "job")
    assert jobs == sorted(_jit.JOBS)
    assert not [d for d in lines if d["role"] == "main" and d["kernel"].endswith(".project_to_polyline")]
    # a small mandrel's intake, arrays, sections and checks, and the field mesh's weld test,
    # take their NumPy forms (geometry.small_mesh): neither process compiles those kernels
    from test_small_mesh_intake import INTAKE_KERNELS

    intake = {f"preform._kernels.{m}.{k}" for m, names in INTAKE_KERNELS.items() for k in names}
    assert sorted({(d["kernel"], d["job"]) for d in lines if d["kernel"] in intake}) == []
    # the field mesh in the cache was built by a job before the simulation, and the map used it
    # (it would have written the entry again after the simulation had it been missing)
    finished = [d["start_s"] for d in events if d["event"] == "finished"]
    entries = list((tmp_path / "cache").glob("field_mesh-*.npz"))
    assert len(finished) == 1 and len(entries) == 1
    assert entries[0].stat().st_mtime <= finished[0]
    # nothing left in the temporary folder (the claims folder) or as a temporary cache entry
    assert list(scratch.iterdir()) == []
    assert [p.name for p in tmp_path.rglob("*") if ".tmp" in p.name] == []
    # the next run is not a first run: no worker
    code = ("import sys; from preform import _jit; from preform.config import load_config; "
            "sys.exit(1 if _jit.needed(load_config(sys.argv[1])) else 0)")
    again = subprocess.run([sys.executable, "-c", code, str(config)], env=env, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
