"""The ``preform`` command, called in-process through ``main([...])`` (exit codes, messages)."""

from __future__ import annotations

import subprocess
import sys

import pytest

import preform
from preform.cli import default_centerline_csv, main, summary_lines


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


def test_default_centerline_csv_never_the_shipped_one(tmp_path):
    stl = tmp_path / "case_b.stl"
    assert default_centerline_csv(stl) == tmp_path / "case_b_centerline_auto.csv"


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
