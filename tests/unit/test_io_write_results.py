"""write_results: the full set of files, summary.json last and listing them."""

from __future__ import annotations

import json

from preform.io import write_results

EXPECTED = ["history.csv", "yarns.vtp", "convergence.pvd", "convergence/step_0000.vtp",
            "convergence/step_0001.vtp", "plots/braid_angle.png", "plots/convergence_length.png",
            "plots/braided_mandrel.png", "summary.json"]


def test_all_files_written_summary_last(small_result, tmp_path):
    out = tmp_path / "results" / "case"
    written = write_results(small_result, None, out)
    assert [p.relative_to(out).as_posix() for p in written] == EXPECTED
    for p in written:
        assert p.is_file() and p.stat().st_size > 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["files"] == EXPECTED
    on_disk = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    # no temporary files left behind; report.html is made from the finished folder, after summary.json
    assert on_disk == sorted([*EXPECTED, "report.html"])


def test_stale_summary_removed_when_a_later_write_fails(small_result, tmp_path):
    import dataclasses

    import numpy as np
    import pytest

    from preform.errors import SimulationError

    write_results(small_result, None, tmp_path)
    history = dict(small_result.history, residual=np.full(small_result.steps, np.nan))
    with pytest.raises(SimulationError):
        write_results(dataclasses.replace(small_result, history=history), None, tmp_path)
    assert not (tmp_path / "summary.json").exists()


def test_fields_go_to_the_surface_writer(small_result, tmp_path, monkeypatch):
    """With fields, write_results hands them to preform.io.surface.write_surface (stubbed here)
    before summary.json, and lists what it wrote."""
    import sys
    import types

    calls = []

    def write_surface(fields, out_dir, title="", pictures=True):
        calls.append((fields, out_dir, pictures))
        path = out_dir / "surface.vtu"
        path.write_text("stub")
        return [path]

    def write_surface_pictures(fields, plots_dir, title="", centerline=None):
        calls.append((fields, plots_dir, title))
        assert "kinematic model" in title
        return []

    monkeypatch.setitem(sys.modules, "preform.io.surface",
                        types.SimpleNamespace(write_surface=write_surface, PICTURES=(),
                                              write_surface_pictures=write_surface_pictures,
                                              INPUT_VTU="surface_input.vtu",
                                              write_input_mesh_fields=None))
    fields = object()
    written = write_results(small_result, fields, tmp_path)
    assert calls[0] == (fields, tmp_path, False)   # the data files, then the pictures
    assert calls[1][:2] == (fields, tmp_path / "plots")
    names = [p.relative_to(tmp_path).as_posix() for p in written]
    assert "surface.vtu" in names and names[-1] == "summary.json"
    assert "surface.vtu" in json.loads((tmp_path / "summary.json").read_text())["files"]
