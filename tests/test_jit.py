"""The first run's compile worker (``preform._jit``): each job runs once, in one of the two
processes; a failing job does not stop the run; and on a real first run the main process
compiles none of the stepper's or the field kernels (the worker's small jobs compile the same
specialisations the run needs)."""

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


def test_a_failing_job_is_marked_done_and_does_not_raise(tmp_path):
    def broken(config):
        raise RuntimeError("no compiler today")

    folder = tmp_path / "claims"
    folder.mkdir()
    _jit._run(folder, "x", None, {"x": broken})
    assert (folder / "x.done").exists()


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
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PREFORM_CACHE_DIR=str(tmp_path / "cache"),
               PREFORM_JIT_LOG=str(log), PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, "-m", "preform.cli", "run", str(config), "--out", str(tmp_path / "out"),
                           "--no-progress"], env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert "compiling the numba kernels" in done.stderr        # the run says that it compiles
    lines = [json.loads(line) for line in log.read_text().splitlines()]
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
    # the next run is not a first run: no worker
    code = ("import sys; from preform import _jit; from preform.config import load_config; "
            "sys.exit(1 if _jit.needed(load_config(sys.argv[1])) else 0)")
    again = subprocess.run([sys.executable, "-c", code, str(config)], env=env, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
