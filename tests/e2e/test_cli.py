"""The ``preform`` command, called in-process through ``main([...])`` (exit codes, messages)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

import preform
from preform.cli import main, summary_lines


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"preform {preform.__version__}"


def test_no_command_is_bad_input(capsys):
    assert main([]) == 2
    assert "usage: preform" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["run", "check"])
def test_missing_config_file(command, tmp_path, capsys):
    missing = tmp_path / "nope.toml"
    assert main([command, str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "nope.toml" in err and "not found" in err
    assert "Traceback" not in err


CASE = """
[mandrel]
stl = "mandrel.stl"

[machine]
carriers = 16
spool_radius = 0.3
angular_speed = 12.0
{machine_extra}

[yarn]
width = 4e-3
thickness = 2.5e-4

[process]
take_up_speed = 0.01
initial_position = 0.1
braid_length = 0.2
"""


@pytest.mark.parametrize("command", ["run", "check"])
def test_unknown_key_is_bad_input(command, tmp_path, capsys):
    (tmp_path / "mandrel.stl").write_text("solid empty\nendsolid empty\n")
    config = tmp_path / "case.toml"
    config.write_text(CASE.format(machine_extra="carrierz = 16"))
    assert main([command, str(config)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "carrierz" in err
    assert "Traceback" not in err


def test_mandrel_info_missing_stl(tmp_path, capsys):
    assert main(["mandrel", "info", str(tmp_path / "gone.stl")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "gone.stl" in err and "not found" in err


def test_mandrel_info_bad_unit_is_usage_error(tmp_path, capsys):
    assert main(["mandrel", "info", str(tmp_path / "x.stl"), "--unit", "inch"]) == 2
    assert "invalid choice: 'inch'" in capsys.readouterr().err


def test_interrupt_exit_code(monkeypatch, tmp_path, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr("preform.cli.cmd_check", interrupted)
    assert main(["check", str(tmp_path / "a.toml")]) == 130
    assert "interrupted" in capsys.readouterr().err


def test_simulation_error_exit_code(monkeypatch, tmp_path, capsys):
    def failing(args):
        raise preform.SimulationError("no convergence at step 12")

    monkeypatch.setattr("preform.cli.cmd_check", failing)
    assert main(["check", str(tmp_path / "a.toml")]) == 1
    assert capsys.readouterr().err == "error: no convergence at step 12\n"


def test_summary_lines(small_result, tmp_path):
    lines = summary_lines(small_result, tmp_path, 9)
    assert len(lines) == 3
    assert lines[0] == f"results: {tmp_path} (9 files)"
    assert "done" in lines[1] and "6 steps" in lines[1] and "0.025 m" in lines[1]
    assert "warp" in lines[2] and "weft" in lines[2] and "convergence length" in lines[2]


def test_console_script_entry_point():
    """``python -m preform.cli --version`` works as a process (the installed ``preform`` calls the
    same ``main``)."""
    done = subprocess.run([sys.executable, "-m", "preform.cli", "--version"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0
    assert done.stdout.strip() == f"preform {preform.__version__}"


# ---------------------------------------------------------------- shipped examples

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

#: the paper's Table 1: carriers, spool radius m, deg/s, guide ring m, take-up m/s
TABLE_1 = {
    "case_a": (144, 1.382, 13.232, None, 0.01),
    "case_b": (96, 0.85, 18.0, 0.17, 0.0263),
    "bent_tube": (96, 0.85, 18.0, 0.17, 0.0263),
}


def _load_example(name, tmp_path):
    """load_config on a copy of the example whose mandrel files are placeholders, so the test
    does not depend on the mandrels being built; checks the files it names are the shipped ones."""
    from preform.config import load_config

    config_dir = tmp_path / "examples"
    config_dir.mkdir()
    text = (EXAMPLES / f"{name}.toml").read_text()
    (config_dir / f"{name}.toml").write_text(text)
    (tmp_path / "mandrels").mkdir()
    for line in text.splitlines():
        if line.split("=")[0].strip() in ("stl", "centerline") and "../mandrels/" in line:
            target = line.split('"')[1]
            (config_dir / target).resolve().write_text("placeholder")
    return load_config(config_dir / f"{name}.toml"), config_dir


@pytest.mark.parametrize("name", sorted(TABLE_1))
def test_example_matches_table_1(name, tmp_path):
    config, config_dir = _load_example(name, tmp_path)
    carriers, spool, speed_deg, ring, take_up = TABLE_1[name]
    assert config.machine.carriers == carriers
    assert config.machine.spool_radius == spool
    assert math.degrees(config.machine.angular_speed) == pytest.approx(speed_deg, rel=1e-12)
    assert config.machine.pattern == "regular"
    assert (config.machine.guide_ring and config.machine.guide_ring.radius) == ring
    assert [speed for _, speed in config.process.take_up_speed] == [take_up]  # constant
    assert (config.yarn.width, config.yarn.thickness, config.yarn.tension) == (4e-3, 2.5e-4, 4.7)
    assert config.model.kind == "kinematic"
    assert config.mandrel.stl == (tmp_path / "mandrels" / f"{name}.stl").resolve()
    assert config.output.dir == (config_dir / "results" / name).resolve()


def test_example_mandrel_files_exist_or_are_being_built():
    """Every mandrel file the examples name exists once mandrels/ is populated."""
    mandrels = EXAMPLES.parent / "mandrels"
    if not any(mandrels.glob("*.stl")):
        pytest.skip("mandrels/ not built yet")
    for name in TABLE_1:
        for line in (EXAMPLES / f"{name}.toml").read_text().splitlines():
            if "../mandrels/" in line:
                assert (EXAMPLES / line.split('"')[1]).resolve().is_file(), line


# ---------------------------------------------------------------- preform run, simulation stubbed

@pytest.fixture
def stubbed_run(small_result, tmp_path, monkeypatch):
    """A valid case file, with the pipeline's geometry, checks, simulation and map replaced by
    stubs that return the synthetic Result: tests the command's plumbing, not the physics."""
    import dataclasses
    import types

    (tmp_path / "mandrel.stl").write_text("solid placeholder\nendsolid placeholder\n")
    config = tmp_path / "case.toml"
    config.write_text(CASE.format(machine_extra=""))
    state = {"status": "done", "preflight": [],
             "mandrel": types.SimpleNamespace(repairs=("filled 1 small hole",))}

    def simulate(cfg, progress=True, mandrel=None, centerline=None, checkpoint=None, resume=False,
                 keep_checkpoint=False, settings=None):
        state["progress"] = progress
        return dataclasses.replace(small_result, config=cfg, status=state["status"],
                                   message="" if state["status"] == "done" else "stopped")

    def preflight(cfg, mandrel, centerline):
        state["preflight"].append((mandrel, centerline))
        return ["guide ring is tight"]

    import preform.pipeline
    from preform.budget import WorkEstimate

    # the pipeline's stages call these through its own names: the geometry and the field mesh
    # (through the cache), the checks, the simulation and the map
    monkeypatch.setattr(preform.pipeline, "load_geometry", lambda cfg: (state["mandrel"], "centerline"))
    monkeypatch.setattr(preform.pipeline, "cached_field_mesh", lambda result, remesh=None: None)
    monkeypatch.setattr(preform.pipeline, "preflight", preflight)
    monkeypatch.setattr(preform.pipeline, "_simulate", simulate)
    monkeypatch.setattr(preform.pipeline, "map_to_surface", lambda r, mesh=None: None)

    # the placeholder mandrel has no geometry to estimate the work or the references from
    monkeypatch.setattr(preform.pipeline, "estimate", lambda *a, **k: WorkEstimate(1, 1, 1))
    monkeypatch.setattr(preform.pipeline, "reference_lines", lambda *a: [])
    return config, state


def test_run_writes_results_and_prints_summary(stubbed_run, tmp_path, capsys):
    config, state = stubbed_run
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), "--no-progress"]) == 0
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()
    assert len(lines) == 4 and lines[0].startswith(f"results: {out}") and lines[3].startswith("quality: ")
    assert "warning: guide ring is tight" in captured.err
    assert "mandrel: filled 1 small hole" in captured.err
    assert state["preflight"] == [(state["mandrel"], "centerline")] and state["progress"] is False
    summary = json.loads((out / "summary.json").read_text())
    assert summary["inputs"]["machine"]["carriers"] == 16
    assert (out / "history.csv").is_file() and (out / "convergence.pvd").is_file()


def test_run_default_out_dir_is_next_to_config(stubbed_run, tmp_path):
    config, _ = stubbed_run
    assert main(["run", str(config), "--no-progress"]) == 0
    assert (tmp_path / "results" / "case" / "summary.json").is_file()


def test_run_model_flag_replaces_the_config_model(stubbed_run, tmp_path):
    config, _ = stubbed_run
    for model in ("interaction", "kinematic"):
        out = tmp_path / model
        assert main(["run", str(config), "--out", str(out), "--no-progress", "--model", model]) == 0
        assert json.loads((out / "summary.json").read_text())["inputs"]["model"]["kind"] == model


def test_run_unknown_model_is_usage_error(stubbed_run, capsys):
    config, _ = stubbed_run
    assert main(["run", str(config), "--model", "frontal"]) == 2
    assert "interaction" in capsys.readouterr().err


@pytest.mark.parametrize("status, code", [("interrupted", 130), ("failed", 1)])
def test_run_partial_results_and_exit_code(stubbed_run, tmp_path, capsys, status, code):
    config, state = stubbed_run
    state["status"] = status
    assert main(["run", str(config), "--out", str(tmp_path / "out"), "--no-progress"]) == code
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == status
    captured = capsys.readouterr()
    assert status in captured.err
    # a run that did not finish is never ok (the status printed beside the verdict)
    assert summary["quality"]["verdict"] == "suspect"
    assert f"quality: suspect: the run did not finish: status {status}" in captured.out


# ---------------------------------------------------------------- preform mandrel info, geometry stubbed

@pytest.fixture
def stubbed_geometry(tmp_path, monkeypatch):
    """preform.geometry.info / io.centerline_csv.write_centerline_csv replaced by stubs recording their calls."""
    import types

    import preform.io.centerline_csv

    calls = {}

    def mandrel_info(stl, unit, centerline):
        calls["info"] = (stl, unit, centerline)
        return types.SimpleNamespace(centerline="the centerline")

    def write_centerline_csv(centerline, path, unit):
        calls["csv"] = (centerline, path, unit)
        Path(path).write_text("x,y,z\n")

    monkeypatch.setitem(sys.modules, "preform.geometry.info", types.SimpleNamespace(
        mandrel_info=mandrel_info, format_mandrel_info=lambda info: "watertight: yes"))
    monkeypatch.setattr(preform.io.centerline_csv, "write_centerline_csv", write_centerline_csv)
    stl = tmp_path / "case_b.stl"
    stl.write_text("solid placeholder\nendsolid placeholder\n")
    shipped = tmp_path / "case_b_centerline.csv"
    shipped.write_text("shipped\n")
    return stl, shipped, calls


def test_mandrel_info_writes_no_csv_unless_asked(stubbed_geometry, tmp_path, capsys):
    stl, shipped, calls = stubbed_geometry
    before = sorted(tmp_path.iterdir())
    assert main(["mandrel", "info", str(stl), "--unit", "mm"]) == 0
    assert "watertight: yes" in capsys.readouterr().out
    assert calls["info"] == (stl, "mm", "auto") and "csv" not in calls
    assert sorted(tmp_path.iterdir()) == before                 # nothing beside the STL
    out = tmp_path / "sub" / "cl.csv"
    (tmp_path / "sub").mkdir()
    assert main(["mandrel", "info", str(stl), "--unit", "mm", "--csv", str(out)]) == 0
    assert calls["csv"] == ("the centerline", out, "mm") and out.is_file()
    assert shipped.read_text() == "shipped\n"


def test_mandrel_info_csv_into_a_missing_folder_is_an_error_line(stubbed_geometry, tmp_path, capsys):
    stl, _, calls = stubbed_geometry
    assert main(["mandrel", "info", str(stl), "--csv", str(tmp_path / "nowhere" / "cl.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --csv") and "nowhere" in err and "does not exist" in err
    assert "info" not in calls                                  # refused before the work


def test_mandrel_info_given_centerline_writes_no_csv(stubbed_geometry, capsys):
    stl, shipped, calls = stubbed_geometry
    assert main(["mandrel", "info", str(stl), "--centerline", str(shipped)]) == 0
    assert calls["info"] == (stl, "m", shipped) and "csv" not in calls


def test_mandrel_info_missing_centerline_csv(stubbed_geometry, tmp_path, capsys):
    stl, _, _ = stubbed_geometry
    assert main(["mandrel", "info", str(stl), "--centerline", str(tmp_path / "no.csv")]) == 2
    assert "no.csv" in capsys.readouterr().err


def test_the_run_says_when_numba_compiles(capsys, tmp_path, monkeypatch):
    """The note comes once, at numba's first compilation (not for a call of compiled code), and
    once per environment: a later compilation (a new config's kernels) says nothing."""
    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "cache"))
    import numba
    import numpy as np

    from preform.cli import COMPILING, _CompileNote

    @numba.njit
    def twice(x):
        return 2 * x

    twice(1)                            # compiled outside: no note
    with _CompileNote():
        twice(2)                        # already compiled: no note
        assert COMPILING not in capsys.readouterr().err
        twice(2.5)                      # a new signature compiles: the note, once
        twice(np.float32(1.5))
    err = capsys.readouterr().err
    assert err.count(COMPILING) == 1
    with _CompileNote():
        twice(np.int8(3))               # compiles again, in an environment that was told
    assert COMPILING not in capsys.readouterr().err
