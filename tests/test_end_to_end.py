"""End to end through the ``preform`` command: a real (short) run, checks, bad set-ups, examples."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import preform as pf
from preform.cli import main
from preform.result import HISTORY_COLUMNS

ROOT = Path(__file__).resolve().parents[1]

CASE = """
[mandrel]
stl = "{stl}"
stl_unit = "m"
centerline = "{csv}"

[machine]
carriers = 16
spool_radius = 0.3
angular_speed = 13.232
{ring}

[yarn]
width = 4e-3
thickness = 2.5e-4

[process]
take_up_speed = 0.01
initial_position = 0.05
braid_length = 0.15

[output]
dir = "out"
field_edge_length = 0.01
"""


def write_case(tmp_path, name="cone", ring=""):
    cfg = tmp_path / "case.toml"
    cfg.write_text(CASE.format(stl=ROOT / "mandrels" / f"{name}.stl", csv=ROOT / "mandrels" / f"{name}_centerline.csv",
                               ring=ring))
    return cfg


def test_run_writes_every_result_file(tmp_path, capsys):
    assert main(["run", str(write_case(tmp_path)), "--no-progress"]) == 0
    out = tmp_path / "out"
    for name in ("summary.json", "history.csv", "yarns.vtp", "surface.vtu", "surface.xdmf", "surface.h5",
                 "convergence.pvd", "plots/braid_angle.png", "plots/convergence_length.png",
                 "plots/surface_braid_angle.png", "plots/surface_cover_factor.png"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "done"
    rows = list(csv.reader((out / "history.csv").open()))
    assert tuple(rows[0]) == HISTORY_COLUMNS
    values = np.array(rows[1:], dtype=float)
    assert np.all(np.isfinite(values))
    assert values[-1, 1] >= 0.15          # braided the configured length
    assert "results:" in capsys.readouterr().out


def test_check_runs_every_check_without_simulating(tmp_path, capsys):
    assert main(["check", str(write_case(tmp_path))]) == 0
    assert not (tmp_path / "out").exists()


def test_mandrel_wider_than_the_guide_ring_is_refused(tmp_path, capsys):
    cfg = write_case(tmp_path, name="case_a", ring="guide_ring = { radius = 0.07, offset = 0.0 }")
    assert main(["run", str(cfg), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "guide ring" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["case_a", "case_b", "bent_tube"])
def test_examples_run(name):
    """Every shipped example loads, passes the checks and braids (a short stretch of it)."""
    cfg = pf.load_config(ROOT / "examples" / f"{name}.toml")
    short = dataclasses.replace(cfg, process=dataclasses.replace(cfg.process, braid_length=0.03))
    result = pf.simulate(short, progress=False)
    assert result.status == "done"
    assert result.history["braided_length_m"][-1] >= 0.03
