"""The process settings over the run (docs/guide/configuration.md): ``[machine] angular_speed``
and ``[process] eccentricity`` as tables over the braided length, read and refused as
``take_up_speed`` is; ``[process] trajectory``, the path's file checked row by row."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from preform.config import dump_config, load_config
from preform.errors import ConfigError
from preform.stepping import setting_at
from preform.trajectory import (COLUMNS, PathInterpolant, Trajectory, quaternion_to_rotation,
                                read_trajectory, rotation_to_quaternion)

BASE = {
    "mandrel": {"stl": "m.stl"},
    "machine": {"carriers": 96, "spool_radius": 0.85, "angular_speed": 18.0},
    "yarn": {"width": 4e-3, "thickness": 2.5e-4},
    "process": {"take_up_speed": 0.0263, "initial_position": 0.2, "braid_length": 1.3},
}


def make_case(tmp_path: Path, machine=None, process=None, drop=()) -> Path:
    """BASE with keys replaced (``machine=``, ``process=``) and ``drop``ped: (section, key)."""
    doc = copy.deepcopy(BASE)
    doc["machine"].update(machine or {})
    doc["process"].update(process or {})
    for section, key in drop:
        doc[section].pop(key, None)
    (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    path = tmp_path / "case.toml"
    path.write_text(tomli_w.dumps(doc))
    return path


def config_error(path, *words) -> str:
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    for word in words:
        assert word in message, (word, message)
    return message


# ----- tables over the braided length -------------------------------------------------------

def test_a_constant_angular_speed_has_no_table_and_echoes_a_number(tmp_path):
    cfg = load_config(make_case(tmp_path))
    assert cfg.machine.angular_speed_table == ()
    assert cfg.machine.angular_speeds == ((0.0, math.radians(18.0)),)
    assert dump_config(cfg)["machine"]["angular_speed"] == pytest.approx(18.0, rel=1e-14)
    assert "trajectory" not in dump_config(cfg)["process"]


def test_angular_speed_table(tmp_path):
    table = [[0.0, 18.0], [0.4, 18.0], [0.45, 24.0]]
    cfg = load_config(make_case(tmp_path, machine={"angular_speed": table}))
    assert cfg.machine.angular_speed == pytest.approx(math.radians(18.0), rel=1e-15)
    assert cfg.machine.angular_speed_table == tuple((a, math.radians(b)) for a, b in table)
    echo = json.loads(json.dumps(dump_config(cfg)))
    np.testing.assert_allclose(echo["machine"]["angular_speed"], table, rtol=1e-14)


def test_eccentricity_table(tmp_path):
    table = [[0.0, 0.0, 0.0], [0.5, 0.01, -0.002]]
    cfg = load_config(make_case(tmp_path, process={"eccentricity": table}))
    assert cfg.process.eccentricity == (0.0, 0.0)
    assert cfg.process.eccentricity_table == ((0.0, 0.0, 0.0), (0.5, 0.01, -0.002))
    assert cfg.process.largest_eccentricity == pytest.approx(math.hypot(0.01, 0.002), rel=1e-15)
    assert dump_config(cfg)["process"]["eccentricity"] == table
    constant = load_config(make_case(tmp_path, process={"eccentricity": [0.01, 0.0]}))
    assert constant.process.eccentricity_table == ()
    assert dump_config(constant)["process"]["eccentricity"] == [0.01, 0.0]


def test_setting_at_interpolates_as_the_take_up_speed_does():
    table = ((0.0, 1.0, -1.0), (0.5, 3.0, 0.0))
    # linear between rows (numpy's interp, by hand here), the end rows beyond them
    np.testing.assert_allclose(setting_at(table, 0.25), [2.0, -0.5], rtol=1e-15)
    np.testing.assert_array_equal(setting_at(table, 2.0), [3.0, 0.0])
    np.testing.assert_array_equal(setting_at(((0.0, 7.0),), 5.0), [7.0])


@pytest.mark.parametrize("table,words", [
    ([], ["empty"]),
    ([[0, 18.0], [0, 20.0]], ["strictly increasing"]),
    ([[0, 18.0, 1]], ["not a pair"]),
    ([[-0.1, 18.0]], ["must not be negative"]),
    ([[0, 18.0], [0.5, 0.0]], ["greater than zero"]),
    ([[0, 18.0], [0.5, 5000.0]], ["expected deg/s", "1 rpm = 6 deg/s"]),
])
def test_bad_angular_speed_table(tmp_path, table, words):
    config_error(make_case(tmp_path, machine={"angular_speed": table}),
                 "[machine] angular_speed =", *words)


@pytest.mark.parametrize("table,words", [
    ([[0, 0.0, 0.0], [0, 0.01, 0.0]], ["strictly increasing"]),
    ([[0, 0.0]], ["not a list of 3 numbers"]),
    ([[0, 0.0, "x"]], ["[braided_length_m, x_m, y_m]", "not a string"]),
    ([[-1, 0.0, 0.0]], ["must not be negative"]),
])
def test_bad_eccentricity_table(tmp_path, table, words):
    config_error(make_case(tmp_path, process={"eccentricity": table}),
                 "[process] eccentricity =", *words)


def test_a_layer_sets_an_angular_speed_table(tmp_path):
    doc = copy.deepcopy(BASE)
    doc["layer"] = [{}, {"machine": {"angular_speed": [[0.0, 18.0], [0.5, 20.0]]}}]
    (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    path = tmp_path / "layers.toml"
    path.write_text(tomli_w.dumps(doc))
    cfg = load_config(path)
    assert cfg.layer_config(0).machine.angular_speed_table == ()
    second = cfg.layer_config(1).machine
    assert second.angular_speed_table == ((0.0, math.radians(18.0)), (0.5, math.radians(20.0)))
    echo = dump_config(cfg)["layers"]["2"]["machine"]
    assert list(echo) == ["angular_speed"]
    np.testing.assert_allclose(echo["angular_speed"], [[0.0, 18.0], [0.5, 20.0]], rtol=1e-14)


# ----- trajectories -------------------------------------------------------------------------

def rows(n=5, dt=0.5):
    """A straight feed along +z at 10 mm/s, 18 deg/s, the mandrel turned 180 deg about x (its
    tangent towards -z, as the pose puts a straight centerline)."""
    out = []
    for k in range(n):
        t = k * dt
        out.append([t, 0.01 * t, 0.01, 18.0, 0.0, 0.0, 0.2 + 0.01 * t, 0.0, 1.0, 0.0, 0.0])
    return out


def write_path(folder: Path, table, header=COLUMNS, name="path.csv") -> Path:
    text = ",".join(header) + "\n" + "".join(",".join(repr(v) for v in row) + "\n" for row in table)
    path = folder / name
    path.write_text(text)
    return path


def path_case(tmp_path, table=None, header=COLUMNS):
    write_path(tmp_path, rows() if table is None else table, header)
    return make_case(tmp_path, process={"trajectory": "path.csv"},
                     drop=[("process", k) for k in ("take_up_speed", "initial_position")]
                     + [("machine", "angular_speed")])


def test_a_trajectory_gives_the_speeds_of_the_run(tmp_path):
    cfg = load_config(path_case(tmp_path))
    assert cfg.process.trajectory == (tmp_path / "path.csv").resolve()
    assert cfg.process.take_up_speed == tuple((0.01 * 0.5 * k, 0.01) for k in range(5))
    assert cfg.machine.angular_speed == pytest.approx(math.radians(18.0), rel=1e-15)
    echo = dump_config(cfg)["process"]
    assert echo["trajectory"] == str(cfg.process.trajectory) and len(echo["trajectory_sha256"]) == 64


@pytest.mark.parametrize("change,words", [
    (lambda t: t.__setitem__(2, [0.5] + t[2][1:]), ["row 3 (line 4)", "time_s = 0.5 after 0.5",
                                                     "strictly increasing"]),
    (lambda t: t[1].__setitem__(7, 0.9), ["row 2 (line 3)", "has length 1.34", "unit quaternion"]),
    (lambda t: t[3].__setitem__(2, 0.0), ["row 4", "take_up_speed_m_s = 0.0", "greater than zero"]),
    (lambda t: t[0].__setitem__(2, 26.3), ["row 1", "take_up_speed_m_s = 26.3", "mm/s"]),
    (lambda t: t[4].__setitem__(3, 5000.0), ["row 5", "angular_speed_deg_s = 5000.0", "1 rpm"]),
    (lambda t: t[1].__setitem__(1, -0.1), ["row 2", "braided_length_m = -0.1", ">= 0"]),
    (lambda t: t[1].__setitem__(4, math.nan), ["row 2", "x_m = 'nan'", "finite number"]),
    (lambda t: t.__delitem__(slice(1, None)), ["1 row(s)", "at least two"]),
])
def test_bad_trajectory_rows(tmp_path, change, words):
    table = rows()
    change(table)
    message = config_error(path_case(tmp_path, table), "[process] trajectory", "path.csv", *words)
    assert str(tmp_path) in message


def test_a_trajectory_needs_every_column(tmp_path):
    header = tuple(c for c in COLUMNS if c != "qz")
    table = [row[:-1] for row in rows()]
    config_error(path_case(tmp_path, table, header), "path.csv", "missing qz", "process.csv")


def test_a_trajectory_refuses_the_keys_it_replaces_and_layers(tmp_path):
    case = path_case(tmp_path)
    text = case.read_text().replace("[process]\n", "[process]\npose_lead = 0.1\n")
    case.write_text(text)
    config_error(case, "[process] pose_lead = 0.1", 'not with [process] trajectory = "path.csv"')
    case.write_text(case.read_text().replace("pose_lead = 0.1\n", "") + "\n[[layer]]\n")
    config_error(case, "[process] trajectory", "[[layer]] tables")


def test_a_trajectory_file_must_exist(tmp_path):
    case = make_case(tmp_path, process={"trajectory": "nowhere.csv"},
                     drop=[("process", "take_up_speed"), ("process", "initial_position"),
                           ("machine", "angular_speed")])
    config_error(case, "[process] trajectory", "file not found", "nowhere.csv")


# ----- quaternions and the interpolation, against scipy's rotations -------------------------

def test_quaternions_round_trip_and_agree_with_scipy():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    for q_xyzw in Rotation.random(50, random_state=rng).as_quat():
        R = Rotation.from_quat(q_xyzw).as_matrix()
        q = rotation_to_quaternion(R)
        assert q[0] >= 0.0
        expected = np.roll(q_xyzw, 1) * (1 if q_xyzw[3] >= 0 else -1)   # scalar first, w >= 0
        np.testing.assert_allclose(q, expected, atol=1e-14)
        np.testing.assert_allclose(quaternion_to_rotation(q), R, atol=1e-14)


def test_the_orientation_turns_at_a_constant_rate_along_the_shorter_arc():
    """Two rows 2 s apart, the second turned 120 deg about z and given with the sign that makes
    the long way round (w < 0): in between the pose is the rotation about z by 120 deg x the
    fraction of the time (SLERP on the shorter arc, closed form)."""
    half = np.radians(60.0)
    q = np.array([[1.0, 0.0, 0.0, 0.0], [-np.cos(half), 0.0, 0.0, -np.sin(half)]])
    zeros = np.zeros(2)
    path = PathInterpolant(Trajectory(path=Path("p.csv"), time=np.array([1.0, 3.0]), braided=zeros,
                                      take_up=np.ones(2), angular=np.ones(2),
                                      position=np.zeros((2, 3)), quaternion=q))
    for u in (0.0, 0.25, 0.5, 1.0):
        R, _ = path.pose(2.0 * u)
        a = np.radians(120.0) * u
        expected = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1]])
        np.testing.assert_allclose(R, expected, atol=1e-13)


def test_the_interpolant_passes_through_the_rows_and_integrates_the_turn(tmp_path):
    table = rows(n=6)
    for k, row in enumerate(table):           # the angular speed ramps from 18 to 28 deg/s
        row[3] = 18.0 + 2.0 * k
    path = read_trajectory(write_path(tmp_path, table), max_take_up_speed=1.0,
                           max_angular_speed_deg=3600.0)
    f = PathInterpolant(path)
    for row in table:
        R, origin = f.pose(row[0])
        np.testing.assert_array_equal(origin, row[4:7])
        np.testing.assert_allclose(R, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    # a linear ramp is its own monotone cubic: the turn is its integral, 18 t + 2 t^2 deg (s)
    for t in (0.3, 1.7, 2.5):
        assert f.turn(t) == pytest.approx(math.radians(18.0 * t + 2.0 * t * t), rel=1e-12)
    # between rows the straight feed stays straight (PCHIP of a linear series is linear)
    assert f.pose(0.75)[1][2] == pytest.approx(0.2075, rel=1e-14)


def test_the_references_before_the_run_read_the_angular_speed_table(tmp_path):
    from preform.reference import references

    table = [[0.0, 18.0], [0.4, 18.0], [0.6, 24.0]]
    cfg = load_config(make_case(tmp_path, machine={"angular_speed": table}))
    s = np.array([0.2, 0.5, 1.0])
    r = 0.075
    refs = references(cfg, s, np.full(3, 2 * math.pi * r))
    # Ko's angle atan(omega r / v) with the table's speed at each arc length (braided length ~ s)
    omega = np.radians([18.0, 21.0, 24.0])
    np.testing.assert_allclose(refs.ko_deg, np.degrees(np.arctan(omega * r / 0.0263)), rtol=1e-12)
