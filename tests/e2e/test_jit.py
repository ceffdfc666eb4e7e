"""The first run's compile worker (``preform._jit``): started at the command's first numba
compilation and only then, with a core idle, stopped without leaving a temporary file behind; its
jobs compile
the specialisations the run needs (after them the run compiles none of the stepper's, the braid
angles' or the map's kernels); its field mesh is the one the run would build, byte for byte."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from preform import _jit
from preform.config import load_config

ROOT = Path(__file__).resolve().parents[2]
CASE_A = ROOT / "examples" / "case_a.toml"
#: a worker whatever the machine's load (the suite runs on loaded machines too), and on a loaded
#: machine the time for its compilation in progress to return after SIGTERM
ANY_LOAD = _jit.WarmupSettings(idle_core=-1e9, stop_wait_s=120.0)


def _compile_something():
    """One numba compilation in this process (a new function, not cached)."""
    from numba import njit

    @njit(cache=False)
    def twice(x):
        return 2 * x

    assert twice(3) == 6


@pytest.fixture
def scratch_caches(tmp_path, monkeypatch):
    """Empty numba and preform caches for the worker this test starts."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(sys.path))
    return tmp_path


def test_no_compilation_no_worker(scratch_caches):
    with _jit.Warmup(load_config(CASE_A), CASE_A, settings=ANY_LOAD) as warmup:
        pass
    assert warmup.process is None


def test_no_worker_without_an_idle_core(scratch_caches):
    with _jit.Warmup(load_config(CASE_A), CASE_A, settings=_jit.WarmupSettings(idle_core=1e9)) as warmup:
        _compile_something()
    assert warmup.process is None


def test_no_worker_for_the_interaction_model(scratch_caches):
    cfg = load_config(CASE_A)
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"))
    with _jit.Warmup(cfg, CASE_A, settings=ANY_LOAD) as warmup:
        _compile_something()
    assert warmup.process is None


def test_the_worker_starts_at_the_first_compilation_and_is_stopped_cleanly(scratch_caches):
    """At the first compilation the worker starts; leaving the block stops it through SIGTERM,
    whose handler leaves by the ``finally`` blocks: no temporary file of numba's or of the
    preform cache stays."""
    import time

    with _jit.Warmup(load_config(CASE_A), CASE_A, settings=ANY_LOAD) as warmup:
        _compile_something()
        assert warmup.process is not None and warmup.process.poll() is None
        time.sleep(3.0)                    # importing and compiling by now
    assert warmup.process.returncode in (0, 143)       # done, or left by SIGTERM's handler
    assert [p.name for p in scratch_caches.rglob("*") if ".tmp" in p.name] == []


def test_the_worker_field_mesh_is_the_one_the_run_builds(tmp_path, monkeypatch):
    """The field-mesh job reads the mandrel the command stored in the cache and writes the field
    mesh the run's map would build itself, byte for byte, under the key the map looks up."""
    from types import SimpleNamespace

    from preform.analysis.fields import field_mesh
    from preform.geometry.mandrel import load_mandrel
    from preform.io.cache import cached_field_mesh, cached_mandrel

    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "cache"))
    config = load_config(CASE_A)
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


@pytest.mark.slow
def test_after_the_worker_jobs_the_run_compiles_none_of_their_kernels(tmp_path):
    """The worker's jobs run to the end on empty caches, then a short case A run with the
    compile log: the run compiles none of the kernels the jobs compiled (the checks', a
    mandrel's, the projector's, the map's, the braid angles'): the jobs compiled the
    specialisations the run calls, and the run loaded them."""
    # no pictures: they draw with VTK and matplotlib and call no numba kernel
    toml = CASE_A.read_text().replace("../mandrels/", str(ROOT / "mandrels") + "/").replace(
        "braid_length = 2.0", "braid_length = 0.05") + "pictures = false\n"
    config = tmp_path / "short.toml"
    config.write_text(toml)
    log = tmp_path / "jit.jsonl"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PREFORM_CACHE_DIR=str(tmp_path / "cache"),
               PREFORM_JIT_LOG=str(log), PYTHONPATH=os.pathsep.join(sys.path))
    worker = subprocess.run([sys.executable, "-m", "preform._jit", str(config)], env=env, capture_output=True,
                            text=True, timeout=900)
    assert worker.returncode == 0, worker.stderr
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert [d["job"] for d in events if d["event"] == "job"] == [name for name, _ in _jit.JOBS]
    # preform's kernels (numba compiles some of its own helpers in every process, uncached)
    by_worker = {d["kernel"] for d in events if d["event"] == "compile" and d["kernel"].startswith("preform.")}
    assert {"preform._kernels.mesh.project_to_polyline", "preform._kernels.mesh.corner_normals",
            "preform._kernels.mesh.project_sampled", "preform._kernels.fields.pool_sums",
            "preform._kernels.fields.clip_polylines", "preform._kernels.kinematic.laid_yarn_angles"} <= by_worker
    log.unlink()
    done = subprocess.run([sys.executable, "-m", "preform.cli", "run", str(config), "--out", str(tmp_path / "out"),
                           "--no-progress"], env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert "compiling the numba kernels" in done.stderr        # the repair's and the stepper's
    lines = [json.loads(line) for line in log.read_text().splitlines()]
    by_run = {d["kernel"] for d in lines
              if d["event"] == "compile" and d["role"] == "main" and d["kernel"].startswith("preform.")}
    assert "preform._kernels.kinematic.advance_fell_points" in by_run
    assert sorted(by_run & by_worker) == []
    assert [p.name for p in tmp_path.rglob("*") if ".tmp" in p.name] == []
