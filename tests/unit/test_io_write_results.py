"""io.write_results: the full set of files of an analysed run, summary.json last and listing
them."""

from __future__ import annotations

import json
from pathlib import Path

from preform.analysis.derived import Analysed, analyse_run, summary_dict
from preform.io import write_results

EXPECTED = ["history.csv", "yarns.vtp", "convergence.pvd", "convergence/step_0000.vtp",
            "convergence/step_0001.vtp", "plots/braid_angle.png", "plots/convergence_length.png",
            "plots/braided_mandrel.png", "summary.json"]


def test_all_files_written_summary_last(small_result, tmp_path):
    out = tmp_path / "results" / "case"
    written = write_results(analyse_run(small_result, None), out)
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

    write_results(analyse_run(small_result, None), tmp_path)
    history = dict(small_result.history, residual=np.full(small_result.steps, np.nan))
    with pytest.raises(SimulationError):
        write_results(analyse_run(dataclasses.replace(small_result, history=history), None), tmp_path)
    assert not (tmp_path / "summary.json").exists()


def test_fields_go_to_the_surface_writer(small_result, tmp_path, monkeypatch):
    """With fields, write_results hands them to ``io.surface.write_surface`` (stubbed here)
    before summary.json, and lists what it wrote; the surface pictures get them after."""
    import preform.io
    import preform.io.surface

    calls = []

    def write_surface(fields, out_dir, title="", pictures=True):
        calls.append((fields, out_dir, pictures))
        path = out_dir / "surface.vtu"
        path.write_text("stub")
        return [path]

    def write_surface_pictures(fields, plots_dir, title="", centerline=None, pictures=None):
        calls.append((fields, plots_dir, title))
        assert "kinematic model" in title
        return []

    monkeypatch.setattr(preform.io, "write_surface", write_surface)
    monkeypatch.setattr(preform.io.surface, "write_surface_pictures", write_surface_pictures)
    fields = object()
    analysed = Analysed(result=small_result, fields=fields, summary=summary_dict(small_result),
                        rtm_reason="no tow data", structural_reason="no [material] section")
    written = write_results(analysed, tmp_path)
    assert calls[0] == (fields, tmp_path, False)   # the data files, then the pictures
    assert calls[1][:2] == (fields, tmp_path / "plots")
    names = [p.relative_to(tmp_path).as_posix() for p in written]
    assert "surface.vtu" in names and names[-1] == "summary.json"
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert "surface.vtu" in summary["files"]
    assert summary["rtm"] == {"written": False, "reason": "no tow data"}
    assert summary["structural"] == {"written": False, "reason": "no [material] section"}


def test_the_writer_imports_no_analysis():
    """``io`` writes what it is given: its package imports neither the verdict, the steady state,
    the RTM properties nor the structural plies (a fresh interpreter), reads no steady state
    of its own (the history plots mark ``Analysed.steady``), nor does it time anything."""
    import subprocess
    import sys

    code = ("import sys, preform.io\n"
            "print([m for m in ('preform.analysis.quality', 'preform.analysis.steady', "
            "'preform.analysis.rtm', 'preform.structural.layup', 'preform.analysis.derived') "
            "if m in sys.modules])\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    import preform.io

    source = "".join(p.read_text() for p in Path(preform.io.__file__).parent.glob("*.py"))
    assert "perf_counter" not in source and "time.time(" not in source
    assert "steady import" not in source and "steady_state(" not in source
