"""The process over the run on the command line: ``preform check`` reports each setting's range
(take-up speed, angular speed, eccentricity) or the trajectory's spans, and ``preform run``
writes ``process.csv``, which a config's ``[process] trajectory`` runs again.

The cheap cylinder case of ``simcase.write_cylinder_case`` (16 carriers, 75 mm radius).
"""

from __future__ import annotations

import json

import numpy as np
from support.simcase import write_cylinder_case

from preform.cli import main
from preform.trajectory import COLUMNS


def test_check_reports_every_setting_constant(tmp_path, capsys):
    assert main(["check", str(write_cylinder_case(tmp_path, braid=0.1, snapshots=0))]) == 0
    out = capsys.readouterr().out
    assert "process: take-up speed 10 mm/s throughout" in out
    assert "process: angular speed 13.2 deg/s throughout" in out
    assert "process: eccentricity [0, 0] m throughout" in out


def test_check_reports_the_range_of_every_table_and_where(tmp_path, capsys):
    path = write_cylinder_case(tmp_path, braid=0.1, snapshots=0)
    text = (path.read_text()
            .replace("angular_speed = 13.232", "angular_speed = [[0.0, 13.232], [0.05, 15.0]]")
            .replace("take_up_speed = 0.01", "take_up_speed = [[0.0, 0.012], [0.08, 0.01]]\n"
                     "eccentricity = [[0.02, 0.0, 0.0], [0.06, 0.003, -0.004]]"))
    path.write_text(text)
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    # the tables' extremes on [0, braid_length]: linear between rows, constant beyond them
    assert ("process: take-up speed 10-12 mm/s over the run: least at 0.08 m braided, most at "
            "0 m (where first reached)") in out
    assert ("process: angular speed 13.2-15 deg/s over the run: least at 0 m braided, most at "
            "0.05 m (where first reached)") in out
    assert ("process: eccentricity |[x, y]| 0-5 mm over the run: least at 0 m braided, most at "
            "0.06 m (where first reached)") in out


def test_a_run_writes_process_csv_and_its_path_runs_again(tmp_path, capsys):
    first = write_cylinder_case(tmp_path / "a", braid=0.05, snapshots=0, out=tmp_path / "a_out",
                                output_extra="pictures = false")
    assert main(["run", str(first)]) == 0
    process = tmp_path / "a_out" / "process.csv"
    summary = json.loads((tmp_path / "a_out" / "summary.json").read_text())
    assert "process.csv" in summary["files"] and "transients" not in summary
    table = np.genfromtxt(process, delimiter=",", names=True)
    assert tuple(table.dtype.names) == COLUMNS
    # a straight cylinder fed along the axis: the origin on the axis, z = initial_position + v t
    np.testing.assert_allclose(table["z_m"], 0.08 + 0.01 * table["time_s"], atol=1e-12)
    text = first.read_text()
    for key in ("angular_speed = 13.232", "take_up_speed = 0.01", "initial_position = 0.08"):
        text = text.replace(key + "\n", "")
    text = text.replace(str(tmp_path / "a_out"), str(tmp_path / "b_out"))
    text = text.replace("[process]\n", f'[process]\ntrajectory = "{process}"\n')
    second = tmp_path / "a" / "replay.toml"
    second.write_text(text)
    capsys.readouterr()
    assert main(["check", str(second)]) == 0
    assert f"process: trajectory {process}: {len(table)} rows" in capsys.readouterr().out
    assert main(["run", str(second)]) == 0
    a = np.genfromtxt(tmp_path / "a_out" / "history.csv", delimiter=",", names=True)
    b = np.genfromtxt(tmp_path / "b_out" / "history.csv", delimiter=",", names=True)
    # a straight feed: the interpolated poses are the first run's to rounding (PCHIP of a linear
    # series is linear, the orientation constant)
    np.testing.assert_allclose(b["convergence_length_mean_m"], a["convergence_length_mean_m"],
                               atol=1e-9)
    np.testing.assert_allclose(b["braid_angle_warp_deg"], a["braid_angle_warp_deg"], atol=1e-7)
