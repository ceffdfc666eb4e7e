"""A run driven by a trajectory (``[process] trajectory``, ``preform.trajectory``).

The robot program a run writes (``process.csv``) is a valid trajectory, and a run driven by its
own ``process.csv`` reproduces its ``history.csv``: kinematic model, a small bent tube of round
section (the pose turns by about 55 deg in the bend, the automatic pose lead), 16 carriers. Every config key the path
replaces is refused beside it, and the mandrel's tip behind the supply plane is refused naming
the row.
"""

from __future__ import annotations

import numpy as np
import pytest

from preform.config import config_from_dict
from preform.errors import ConfigError
from preform.geometry import shapes
from preform.geometry.centerline import centerline_from_points
from preform.io.tables import write_process
from preform.reference import resolve_pose_lead
from preform.result import HISTORY_COLUMNS
from preform.simulation import load_geometry, simulate
from preform.trajectory import COLUMNS
from support.simcase import write_centerline, write_stl


def _document(folder, process):
    return {"mandrel": {"stl": str(folder / "bent.stl"), "centerline": str(folder / "bent.csv")},
            "machine": {"carriers": 16, "spool_radius": 0.3,
                        **({} if "trajectory" in process else {"angular_speed": 12.0})},
            "yarn": {"width": 4e-3, "thickness": 2.5e-4},
            "process": process, "output": {"snapshots": 0}}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """(the run from its tables, its process.csv, the run driven by that file)."""
    folder = tmp_path_factory.mktemp("replay")
    path = shapes.bent_tube_path(straight=0.1, bend_radius=0.2, n_bend=24)
    rings = np.linspace(0.0, centerline_from_points(path).length, 60)
    verts, faces = shapes.sweep(path, lambda s: shapes.circle(0.03, 32), 32, rings)
    write_stl(folder / "bent.stl", verts, faces)
    write_centerline(folder / "bent.csv", path)
    given = config_from_dict(_document(folder, {
        "take_up_speed": 0.01, "initial_position": 0.1, "braid_length": 0.3}), base_dir=folder)
    first = simulate(given, progress=False)
    path = write_process(first, folder / "process.csv")
    driven = config_from_dict(_document(folder, {"trajectory": "process.csv", "braid_length": 0.3}),
                              base_dir=folder)
    return first, path, simulate(driven, progress=False)


def test_the_run_braids_through_the_bend(runs):
    first, _, _ = runs
    assert first.status == "done"
    q = first.process[:, 6:10]
    # the mandrel turned as it went through the bend (the orientation's angle, 2 acos(w), about
    # its start): a pose that changes, not a straight feed
    turn = 2 * np.degrees(np.arccos(np.clip(np.abs(q @ q[0]), 0, 1)))
    assert turn.max() > 45.0


def test_process_csv_reads_back_as_the_run_wrote_it(runs):
    first, path, _ = runs
    table = np.genfromtxt(path, delimiter=",", names=True)
    assert tuple(table.dtype.names) == COLUMNS
    np.testing.assert_array_equal(table["time_s"], first.history["time_s"])
    np.testing.assert_array_equal(table["braided_length_m"], first.history["braided_length_m"])
    np.testing.assert_array_equal(table["angular_speed_deg_s"], np.degrees(first.process[:, 2]))
    q = np.column_stack([table[c] for c in ("qw", "qx", "qy", "qz")])
    # unit quaternions to rounding (a rotation matrix's own orthogonality, ~1e-15)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)


def test_a_run_driven_by_its_own_process_csv_reproduces_its_history(runs):
    first, _, driven = runs
    assert driven.status == "done"
    assert driven.steps == first.steps
    a, b = first.history, driven.history
    # the same time steps (the path gives the same step control: its take-up and angular
    # speeds), to the last bits: the angular speed is written in deg/s and read back in rad/s
    np.testing.assert_allclose(b["time_s"], a["time_s"], rtol=1e-13, atol=0)
    # at the rows the poses agree to rounding (the quaternion of the pose's rotation matrix, and
    # back); inside a step the midpoint pose is interpolated (PCHIP, SLERP) where the first run
    # posed it from the centerline, a difference of third order in the step that the fell
    # points' walk carries on: measured at most 1.8e-7 m on the lengths and 3.1e-5 deg on the
    # angles. Allowed: 1 um, a four-thousandth of the yarn's width, and 1e-3 deg, a 250th of
    # the steady-state tolerance on an angle
    for name in HISTORY_COLUMNS:
        tol = 1e-3 if name.endswith("_deg") else 1e-6
        np.testing.assert_allclose(b[name], a[name], rtol=0, atol=tol, err_msg=name)


def test_the_replay_starts_where_the_first_run_did(runs, tmp_path):
    first, _, driven = runs
    mandrel, cl = load_geometry(driven.config)
    resolved = resolve_pose_lead(driven.config, mandrel, cl)
    # the tip's distance ahead of the supply plane at the first row: the given initial_position
    assert resolved.process.initial_position == pytest.approx(0.1, abs=1e-12)
    np.testing.assert_allclose(driven.process[:, 3:], first.process[:, 3:], atol=1e-12)


@pytest.mark.parametrize("key, section", [("take_up_speed", "process"),
                                          ("initial_position", "process"),
                                          ("eccentricity", "process"), ("pose_lead", "process"),
                                          ("angular_speed", "machine")])
def test_keys_the_path_replaces_are_refused(runs, key, section):
    _, path, _ = runs
    doc = _document(path.parent, {"trajectory": "process.csv", "braid_length": 0.3})
    doc[section][key] = [0.0, 0.0] if key == "eccentricity" else 0.01
    with pytest.raises(ConfigError, match=rf"\[{section}\] {key} = .*not with \[process\] "
                                          r"trajectory = \"process.csv\""):
        config_from_dict(doc, base_dir=path.parent)


def test_a_tip_behind_the_supply_plane_is_refused_naming_the_row(runs, tmp_path):
    _, path, _ = runs
    lines = path.read_text().splitlines()
    row = lines[3].split(",")
    row[COLUMNS.index("z_m")] = repr(float(row[COLUMNS.index("z_m")]) - 0.2)   # 0.1 m behind
    lines[3] = ",".join(row)
    bad = tmp_path / "behind.csv"
    bad.write_text("\n".join(lines) + "\n")
    for name in ("bent.stl", "bent.csv"):
        (tmp_path / name).write_bytes((path.parent / name).read_bytes())
    cfg = config_from_dict(_document(tmp_path, {"trajectory": "behind.csv", "braid_length": 0.3}),
                           base_dir=tmp_path)
    mandrel, cl = load_geometry(cfg)
    with pytest.raises(ConfigError, match=r"behind.csv: row 3 \(line 4\): the mandrel's tip is at "
                                          r"z = -0.0\d+ m, behind the supply plane z = 0 m"):
        resolve_pose_lead(cfg, mandrel, cl)
