"""The pictures drawn beside the data files (``io.pictures``): a failing or dying picture never
costs a data file and is reported; the background run writes the same files as the inline one."""

from __future__ import annotations

import json
import os
import signal

import pytest

from preform.io import write_results
from preform.io.pictures import PictureJob, PictureWorker, can_fork, run_jobs

needs_fork = pytest.mark.skipif(not can_fork(), reason="the picture worker forks (Linux)")


def _touch(path):
    path.write_bytes(b"png")
    return [path]


def test_run_jobs_reports_a_failure_and_draws_the_rest(tmp_path):
    def broken():
        raise RuntimeError("no OpenGL here")

    jobs = [PictureJob(("a.png",), broken), PictureJob(("b.png",), lambda: _touch(tmp_path / "b.png"))]
    written, failed = run_jobs(jobs)
    assert written == [tmp_path / "b.png"]
    assert failed == ["a.png not drawn (RuntimeError: no OpenGL here)"]


@needs_fork
def test_worker_draws_in_another_process_and_reports(tmp_path):
    parent = os.getpid()

    def where():
        (tmp_path / "pid").write_text(str(os.getpid()))
        return _touch(tmp_path / "c.png")

    def broken():
        raise ValueError("bad field")

    written, failed = PictureWorker([PictureJob(("c.png",), where), PictureJob(("d.png",), broken)]).finish()
    assert written == [tmp_path / "c.png"] and (tmp_path / "c.png").is_file()
    assert int((tmp_path / "pid").read_text()) != parent
    assert failed == ["d.png not drawn (ValueError: bad field)"]


@needs_fork
def test_worker_that_dies_is_reported(tmp_path):
    def crash():
        os.kill(os.getpid(), signal.SIGKILL)   # as a segfaulting renderer would end

    written, failed = PictureWorker([PictureJob(("e.png", "f.png"), crash)]).finish()
    assert written == []
    assert failed == [f"e.png, f.png not drawn (the picture worker stopped by signal {int(signal.SIGKILL)})"]


@needs_fork
def test_worker_past_its_time_is_stopped(tmp_path):
    import time

    def hang():
        time.sleep(60)

    t0 = time.monotonic()
    written, failed = PictureWorker([PictureJob(("g.png",), hang)], timeout_s=0.5).finish()
    assert time.monotonic() - t0 < 30
    assert written == [] and failed == ["g.png not drawn (the picture worker took longer than 0.5 s)"]


@needs_fork
def test_worker_warnings_come_back_to_the_parent(tmp_path):
    import warnings

    def warn():
        warnings.warn("drew the yarns without the mandrel", RuntimeWarning)
        return _touch(tmp_path / "h.png")

    with pytest.warns(RuntimeWarning, match="without the mandrel"):
        written, failed = PictureWorker([PictureJob(("h.png",), warn)]).finish()
    assert written == [tmp_path / "h.png"] and failed == []


def _names(paths, out):
    return [p.relative_to(out).as_posix() for p in paths]


@needs_fork
def test_background_writes_the_same_files_as_inline(small_result, tmp_path):
    inline = write_results(small_result, None, tmp_path / "inline")
    background = write_results(small_result, None, tmp_path / "background", background=True)
    assert _names(background, tmp_path / "background") == _names(inline, tmp_path / "inline")
    for p in background:
        assert p.is_file() and p.stat().st_size > 0
    summary = json.loads((tmp_path / "background" / "summary.json").read_text())
    assert summary["pictures"] == {"failed": []}


@needs_fork
def test_a_failing_render_in_the_worker_keeps_the_data_files(small_result, tmp_path, monkeypatch):
    """The 3-D render raises inside the worker (and so does its matplotlib fallback): the data
    files and the other pictures are written, the failure is a warning and in the summary."""
    import preform.io.plots as plots

    def broken(*args, **kwargs):
        raise RuntimeError("renderer exploded")

    monkeypatch.setattr(plots, "plot_yarns_3d", broken)
    out = tmp_path / "out"
    with pytest.warns(RuntimeWarning, match="braided_mandrel.png not drawn"):
        written = write_results(small_result, None, out, background=True, stages={"simulate": 1.0})
    names = _names(written, out)
    assert names[:3] == ["history.csv", "yarns.vtp", "convergence.pvd"]
    assert "plots/braid_angle.png" in names and "plots/braided_mandrel.png" not in names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["pictures"]["failed"] == [
        "plots/braided_mandrel.png not drawn (RuntimeError: renderer exploded)"]
    assert set(summary["stages_s"]) == {"simulate", "write", "pictures"}
    assert summary["wall_time_s"] == pytest.approx(sum(summary["stages_s"].values()))


def test_the_first_run_kernel_warmup_maps_a_small_cylinder(tmp_path):
    """The warm-up a first run forks (``pipeline.start_kernel_warmup``) runs the field kernels
    with the run's settings; once they are in numba's cache it is not started."""
    from preform import pipeline
    from preform._kernels import fields as field_kernels
    from preform.config import load_config
    from simcase import write_cylinder_case

    config = load_config(write_cylinder_case(tmp_path, length=0.6, braid=0.06, carriers=16, friction=0.0))
    assert pipeline._compile_map_kernels(config) == []
    assert pipeline._kernels_cached(field_kernels)
    assert pipeline.start_kernel_warmup(config) is None
