"""The pictures drawn beside the data files (``io.pictures``): a failing or dying picture never
costs a data file and is reported; the background run writes the same files as the inline one,
and so does the early worker ``preform run`` forks after the simulation (``io.start_pictures``),
which gets the fields later as plain arrays."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

from preform import pipeline
from preform.analysis.derived import analyse_run
from preform.io import fields_arrays, fields_from_arrays, start_pictures
from preform.io.pictures import LaterJob, PictureJob, PictureWorker, can_fork, run_jobs

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


def write_results(result, fields, out, **kwargs):
    """The pipeline's write stage (``pipeline.write``) of ``result`` and ``fields`` analysed."""
    return pipeline.write(analyse_run(result, fields), out, **kwargs)


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


# ------------------------------------------------------------------ the worker started early


@pytest.fixture(scope="module")
def fields():
    from preform.analysis.fields import map_to_surface
    from support.field_standins import cylinder, helices, make_result

    return map_to_surface(make_result(cylinder(height=0.2), helices(np.radians(30.0), 16, z1=0.14)),
                          edge_length=0.015)


def _wait_for(path, seconds=30.0):
    import time

    deadline = time.monotonic() + seconds
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    return path.exists()


def test_fields_travel_as_plain_arrays(fields):
    arrays = fields_arrays(fields)
    assert all(isinstance(a, np.ndarray) and a.dtype != object for a in arrays.values())
    back = fields_from_arrays(arrays)
    for name in ("vertices", "faces", "source_faces", "jammed"):
        assert np.array_equal(getattr(back, name), getattr(fields, name)), name
    for name in ("unmapped_length_m", "edge_length_m", "pool_radius_m"):
        assert getattr(back, name) == getattr(fields, name), name
    assert list(back.cell_data) == list(fields.cell_data)
    for name, values in fields.cell_data.items():
        assert back.cell_data[name].dtype == values.dtype and np.array_equal(back.cell_data[name], values)


@needs_fork
def test_later_jobs_get_arrays_sent_after_the_fork_without_blocking_the_parent(tmp_path):
    """send() returns while the child is still busy with its first job (the arrays, 8 MB, are
    more than a pipe holds); the child then draws the later job from exactly those arrays."""
    go = tmp_path / "go"

    def first():
        assert _wait_for(go), "the parent was blocked"
        return _touch(tmp_path / "first.png")

    def later(arrays):
        (tmp_path / "later.json").write_text(json.dumps({"pid": os.getpid(),
                                                         "sum": float(arrays["x"].sum())}))
        return [tmp_path / "later.json"]

    worker = PictureWorker([PictureJob(("first.png",), first)], later=[LaterJob(("later.json",), later)])
    x = np.arange(1_000_000, dtype=np.float64)   # made after the fork: the child cannot see it
    worker.send({"x": x})
    go.touch()
    written, failed = worker.finish()
    assert failed == [] and written == [tmp_path / "first.png", tmp_path / "later.json"]
    got = json.loads((tmp_path / "later.json").read_text())
    assert got["pid"] != os.getpid() and got["sum"] == float(x.sum())


@needs_fork
@pytest.mark.parametrize("send", [True, False])
def test_later_jobs_are_skipped_when_nothing_is_sent(tmp_path, send):
    def later(arrays):
        raise AssertionError("drawn without arrays")

    worker = PictureWorker([], later=[LaterJob(("later.png",), later)])
    if send:
        worker.send(None)
    assert worker.finish() == ([], [])


def _pixels(path):
    from PIL import Image

    return np.asarray(Image.open(path))


@needs_fork
def test_early_worker_draws_the_same_pictures_as_inline(small_result, fields, tmp_path):
    inline = write_results(small_result, fields, tmp_path / "inline")
    early = tmp_path / "early"
    written = write_results(small_result, fields, early, pictures=start_pictures(small_result, early))
    # the same files (the worker renders the braided mandrel first, so it is listed earlier)
    assert sorted(_names(written, early)) == sorted(_names(inline, tmp_path / "inline"))
    assert _names(written, early)[-1] == "summary.json"
    pngs = [p for p in _names(written, early) if p.endswith(".png")]
    assert {"plots/surface_thickness.png", "plots/braided_mandrel.png"} <= set(pngs)
    for name in pngs:
        assert np.array_equal(_pixels(early / name), _pixels(tmp_path / "inline" / name)), name
    assert json.loads((early / "summary.json").read_text())["pictures"] == {"failed": []}


@needs_fork
def test_an_early_worker_that_dies_keeps_the_data_files(small_result, fields, tmp_path, monkeypatch):
    import preform.io.plots as plots

    monkeypatch.setattr(plots, "plot_yarns_3d", lambda *a: os.kill(os.getpid(), signal.SIGKILL))
    out = tmp_path / "out"
    worker = start_pictures(small_result, out)
    with pytest.warns(RuntimeWarning, match="stopped by signal"):
        written = write_results(small_result, fields, out, stages={"simulate": 1.0}, pictures=worker)
    names = _names(written, out)
    assert {"history.csv", "yarns.vtp", "surface.vtu", "surface.xdmf", "plots/braid_angle.png"} <= set(names)
    assert not any(n.startswith("plots/surface_") or n.endswith("braided_mandrel.png") for n in names)
    failed = json.loads((out / "summary.json").read_text())["pictures"]["failed"]
    assert len(failed) == 1 and "plots/braided_mandrel.png" in failed[0]
    assert "plots/surface_thickness.png" in failed[0] and f"signal {int(signal.SIGKILL)}" in failed[0]


@needs_fork
def test_a_failing_surface_render_in_the_early_worker_is_reported(small_result, fields, tmp_path,
                                                                   monkeypatch):
    import preform.io.surface as surface

    def broken(*args, **kwargs):
        raise RuntimeError("no OpenGL here")

    monkeypatch.setattr(surface, "write_surface_pictures", broken)
    out = tmp_path / "out"
    worker = start_pictures(small_result, out)
    with pytest.warns(RuntimeWarning, match="surface_braid_angle.png"):
        written = write_results(small_result, fields, out, pictures=worker)
    assert "plots/braided_mandrel.png" in _names(written, out)
    failed = json.loads((out / "summary.json").read_text())["pictures"]["failed"]
    assert failed == ["plots/surface_braid_angle.png, plots/surface_cover_factor.png, "
                      "plots/surface_thickness.png not drawn (RuntimeError: no OpenGL here)"]


@needs_fork
def test_the_data_files_do_not_wait_for_the_early_worker(small_result, fields, tmp_path, monkeypatch):
    """The worker's first picture waits for the last data file: were the data files written
    only after the worker, it would wait in vain (and say so)."""
    import preform.io.plots as plots

    out = tmp_path / "out"

    def after_the_data(result, path, *drawing):
        (out / "seen").write_text(str(_wait_for(out / "surface.vtu")))
        return _touch(path)[0]

    monkeypatch.setattr(plots, "plot_yarns_3d", after_the_data)
    worker = start_pictures(small_result, out)
    write_results(small_result, fields, out, pictures=worker)
    assert (out / "seen").read_text() == "True"
    assert json.loads((out / "summary.json").read_text())["pictures"] == {"failed": []}


def test_without_fork_the_early_worker_draws_in_the_write_stage(small_result, fields, tmp_path, monkeypatch):
    import preform.io.pictures as pictures

    monkeypatch.setattr(pictures, "can_fork", lambda: False)
    out = tmp_path / "out"
    worker = start_pictures(small_result, out)
    assert worker.pid is None
    names = _names(write_results(small_result, fields, out, pictures=worker), out)
    assert {"plots/braided_mandrel.png", "plots/surface_thickness.png", "surface.vtu"} <= set(names)
    assert json.loads((out / "summary.json").read_text())["pictures"] == {"failed": []}


@needs_fork
def test_arrays_that_cannot_be_sent_cost_only_their_pictures(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    def later(arrays):
        raise AssertionError("drawn without its arrays")

    worker = PictureWorker([PictureJob(("first.png",), lambda: _touch(tmp_path / "first.png"))],
                           later=[LaterJob(("later.png",), later)])
    monkeypatch.setattr(np, "savez", broken)
    worker.send({"x": np.arange(3)})
    written, failed = worker.finish()
    assert written == [tmp_path / "first.png"]
    assert failed == ["later.png not drawn (could not hand their arrays to the picture worker: "
                      "OSError: [Errno 28] No space left on device)"]


@needs_fork
def test_the_worker_never_unpickles_what_it_receives(tmp_path):
    """An object array would need unpickling: the worker refuses it and reports the pictures."""
    def later(arrays):
        raise AssertionError("drawn from unpickled arrays")

    worker = PictureWorker([], later=[LaterJob(("later.png",), later)])
    worker.send({"x": np.array([{"a": 1}], dtype=object)})
    written, failed = worker.finish()
    assert written == [] and len(failed) == 1
    assert failed[0].startswith("later.png not drawn (RuntimeError: their arrays could not be received")
    assert "pickle" in failed[0]


def test_without_fork_background_draws_each_picture_once(small_result, tmp_path, monkeypatch):
    """``background=True`` where the worker cannot fork: its jobs are drawn once, by
    ``PictureWorker.finish`` in this process, not a second time beside the matplotlib ones."""
    import preform.io.pictures as pictures
    import preform.io.plots as plots

    calls = []

    def counted(result, path, *drawing):
        calls.append(path)
        return _touch(path)[0]

    monkeypatch.setattr(pictures, "can_fork", lambda: False)
    monkeypatch.setattr(plots, "plot_yarns_3d", counted)
    out = tmp_path / "out"
    names = _names(write_results(small_result, None, out, background=True), out)
    assert calls == [out / "plots" / "braided_mandrel.png"]
    assert names.count("plots/braided_mandrel.png") == 1
