"""TOML config loading and validation (docs/guide/configuration.md): every error names the key
and what is expected."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest
import tomli_w

from preform.config import dump_config, load_config
from preform.errors import ConfigError, PreformError

DROP = object()  # override value that removes a key

BASE = {
    "mandrel": {"stl": "m.stl"},
    "machine": {"carriers": 96, "spool_radius": 0.85, "angular_speed": 18.0},
    "yarn": {"width": 4e-3, "thickness": 2.5e-4},
    "process": {"take_up_speed": 0.0263, "initial_position": 0.2, "braid_length": 1.3},
}


def write_toml(path: Path, doc: dict) -> Path:
    path.write_text(tomli_w.dumps(doc))
    return path


def make_case(tmp_path: Path, name="case", stl=True, **sections) -> Path:
    """Write BASE with per-section overrides (``yarn={"width": DROP}``) and an empty m.stl."""
    doc = copy.deepcopy(BASE)
    for section, changes in sections.items():
        if changes is DROP:
            doc.pop(section, None)
            continue
        table = doc.setdefault(section, {})
        for key, value in changes.items():
            if value is DROP:
                table.pop(key, None)
            else:
                table[key] = value
    if stl:
        (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    return write_toml(tmp_path / f"{name}.toml", doc)


def config_error(tmp_path, *words, **sections) -> str:
    """Load an overridden case, expect a ConfigError containing every word; return the message."""
    with pytest.raises(ConfigError) as info:
        load_config(make_case(tmp_path, **sections))
    message = str(info.value)
    for word in words:
        assert word in message, (word, message)
    return message


# ----- good configs ------------------------------------------------------------------------


def test_minimal_config_defaults(tmp_path):
    cfg = load_config(make_case(tmp_path))
    assert cfg.mandrel.stl == (tmp_path / "m.stl").resolve()
    assert cfg.mandrel.stl_unit == "m" and cfg.mandrel.centerline == "auto"
    assert cfg.mandrel.roll_reference is None
    assert cfg.machine.pattern == "regular" and cfg.machine.guide_ring is None
    assert (cfg.yarn.tension, cfg.yarn.friction, cfg.yarn.ring_friction) == (4.7, 0.0, 0.0)
    assert cfg.process.eccentricity == (0.0, 0.0) and cfg.process.pose_lead is None   # "auto"
    assert cfg.model.kind == "kinematic" and cfg.model.time_step is None
    assert (cfg.model.start, cfg.model.seed) == ("tip", 0)
    assert cfg.output.dir == (tmp_path / "results" / "case").resolve()
    assert cfg.output.field_edge_length is None and cfg.output.snapshots is None
    # unset: the interaction model's 20 snapshots, none for the kinematic model
    assert (cfg.output.snapshot_count("interaction"), cfg.output.snapshot_count("kinematic")) == (20, 0)
    assert cfg.source == (tmp_path / "case.toml").resolve()


def test_angular_speed_degrees_in_the_file_radians_inside(tmp_path):
    cfg = load_config(make_case(tmp_path, machine={"angular_speed": 18}))
    assert cfg.machine.angular_speed == pytest.approx(math.pi / 10, rel=1e-15)  # 18 deg = pi/10


def test_full_config_every_key(tmp_path):
    (tmp_path / "cl.csv").write_text("x,y,z\n0,0,0\n0,0,1\n")
    cfg = load_config(make_case(
        tmp_path,
        mandrel={"stl_unit": "mm", "centerline": "cl.csv", "roll_reference": [1, 0, 0]},
        machine={"pattern": "diamond", "guide_ring": {"radius": 0.17, "offset": 0.02}},
        yarn={"tension": 3, "friction": 0.25, "ring_friction": 0.17},
        process={"eccentricity": [0.025, -0.01], "pose_lead": 0.05},
        model={"kind": "interaction", "time_step": 0.01, "start": "random", "seed": 7},
        output={"dir": "out/here", "field_edge_length": 0.01, "snapshots": 0}))
    assert cfg.mandrel.centerline == (tmp_path / "cl.csv").resolve()
    assert cfg.mandrel.roll_reference == (1.0, 0.0, 0.0)
    assert cfg.machine.guide_ring.radius == 0.17 and cfg.machine.guide_ring.offset == 0.02
    assert cfg.machine.pattern_m == 1
    assert cfg.yarn.tension == 3.0 and isinstance(cfg.yarn.tension, float)
    assert cfg.process.eccentricity == (0.025, -0.01) and cfg.process.pose_lead == 0.05
    assert (cfg.model.kind, cfg.model.time_step, cfg.model.start, cfg.model.seed) == (
        "interaction", 0.01, "random", 7)
    assert cfg.output.dir == (tmp_path / "out" / "here").resolve()
    assert (cfg.output.field_edge_length, cfg.output.snapshots) == (0.01, 0)


def test_guide_ring_as_a_subtable(tmp_path):
    path = make_case(tmp_path)
    path.write_text(path.read_text() + "\n[machine.guide_ring]\nradius = 0.2\n")
    cfg = load_config(path)
    assert cfg.machine.guide_ring.radius == 0.2 and cfg.machine.guide_ring.offset == 0.0


def test_relative_paths_resolve_against_the_config_folder(tmp_path, monkeypatch):
    (tmp_path / "mandrels").mkdir()
    (tmp_path / "examples").mkdir()
    (tmp_path / "mandrels" / "b.stl").write_text("solid\nendsolid\n")
    (tmp_path / "mandrels" / "b.csv").write_text("0,0,0\n0,0,1\n")
    doc = copy.deepcopy(BASE)
    doc["mandrel"] = {"stl": "../mandrels/b.stl", "centerline": "../mandrels/b.csv"}
    path = write_toml(tmp_path / "examples" / "case_b.toml", doc)
    monkeypatch.chdir(tmp_path / "mandrels")  # the working folder must not matter
    cfg = load_config(Path("..") / "examples" / "case_b.toml")
    assert cfg.mandrel.stl == tmp_path.resolve() / "mandrels" / "b.stl"
    assert cfg.mandrel.centerline == tmp_path.resolve() / "mandrels" / "b.csv"
    assert cfg.output.dir == tmp_path.resolve() / "examples" / "results" / "case_b"
    assert cfg.source == path.resolve()
    assert all(p.is_absolute() for p in (cfg.mandrel.stl, cfg.mandrel.centerline, cfg.output.dir))


def test_absolute_paths_are_kept(tmp_path):
    stl = tmp_path / "abs.stl"
    stl.write_text("solid\nendsolid\n")
    sub = tmp_path / "sub"
    sub.mkdir()
    cfg = load_config(make_case(sub, mandrel={"stl": str(stl)}, output={"dir": str(tmp_path / "o")}))
    assert cfg.mandrel.stl == stl.resolve() and cfg.output.dir == (tmp_path / "o").resolve()


def test_constant_take_up_speed_is_a_one_row_table(tmp_path):
    cfg = load_config(make_case(tmp_path, process={"take_up_speed": 0.02}))
    assert cfg.process.take_up_speed == ((0.0, 0.02),)


def test_take_up_speed_table(tmp_path):
    table = [[0, 0.02], [0.5, 0.03], [1.0, 0.025]]
    cfg = load_config(make_case(tmp_path, process={"take_up_speed": table}))
    assert cfg.process.take_up_speed == ((0.0, 0.02), (0.5, 0.03), (1.0, 0.025))


def test_dump_config_is_json_with_file_units(tmp_path):
    table = [[0.0, 0.02], [0.5, 0.03]]
    cfg = load_config(make_case(tmp_path, process={"take_up_speed": table},
                                machine={"guide_ring": {"radius": 0.17}}))
    echo = json.loads(json.dumps(dump_config(cfg)))
    assert echo["machine"]["angular_speed"] == pytest.approx(18.0, rel=1e-14)
    assert echo["machine"]["guide_ring"] == {"radius": 0.17, "offset": 0.0}
    assert echo["process"]["take_up_speed"] == table
    assert echo["mandrel"]["stl"] == str((tmp_path / "m.stl").resolve())
    assert echo["mandrel"]["centerline"] == "auto"
    assert echo["model"]["time_step"] is None
    constant = dump_config(load_config(make_case(tmp_path)))
    assert constant["process"]["take_up_speed"] == 0.0263


# ----- bad configs: one test per message ---------------------------------------------------


def test_config_error_is_a_preform_error():
    assert issubclass(ConfigError, PreformError)


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.toml")


def test_unreadable_toml_names_the_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[mandrel]\nstl = "m.stl"\nstl_unit = \n')
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert "not valid TOML" in str(info.value) and "line 3" in str(info.value)


def test_unknown_section_suggests_the_closest(tmp_path):
    config_error(tmp_path, "unknown section [machin]", "did you mean 'machine'", machin={"x": 1})


def test_unknown_key_suggests_the_closest(tmp_path):
    config_error(tmp_path, "[yarn] widht = 0.004", "unknown key", "did you mean 'width'",
                 yarn={"widht": 0.004})


def test_key_in_the_wrong_section_says_where_it_belongs(tmp_path):
    config_error(tmp_path, "[yarn] carriers = 96", "belongs in [machine]", yarn={"carriers": 96})


def test_top_level_key_outside_any_section(tmp_path):
    path = make_case(tmp_path)
    path.write_text("carriers = 96\n" + path.read_text())
    with pytest.raises(ConfigError, match=r"carriers = 96 is outside any section: it belongs in \[machine\]"):
        load_config(path)


def test_unknown_guide_ring_key(tmp_path):
    config_error(tmp_path, "[machine] guide_ring.radios = 0.1", "did you mean 'radius'",
                 machine={"guide_ring": {"radios": 0.1}})


REQUIRED = [("mandrel", "stl"), ("machine", "carriers"), ("machine", "spool_radius"),
            ("machine", "angular_speed"), ("yarn", "width"), ("yarn", "thickness"),
            ("process", "take_up_speed"), ("process", "initial_position"), ("process", "braid_length")]


@pytest.mark.parametrize("section,key", REQUIRED)
def test_missing_required_key(tmp_path, section, key):
    config_error(tmp_path, f"[{section}] {key} is missing", "expected", **{section: {key: DROP}})


def test_missing_section(tmp_path):
    config_error(tmp_path, "section [yarn] is missing", "width", yarn=DROP)


@pytest.mark.parametrize("section,key,value,words", [
    ("yarn", "width", "4mm", ['[yarn] width = "4mm"', "expected a positive number (m)", "string"]),
    ("yarn", "tension", True, ["[yarn] tension = true", "number (N)", "boolean"]),
    ("machine", "spool_radius", [0.85], ["[machine] spool_radius = [0.85]", "number (m)", "list"]),
    ("process", "take_up_speed", "fast", ['[process] take_up_speed = "fast"', "m/s"]),
    ("machine", "carriers", 96.0, ["[machine] carriers = 96.0", "even integer", "float"]),
    ("machine", "carriers", True, ["[machine] carriers = true", "boolean"]),
    ("machine", "pattern", 2, ["[machine] pattern = 2", '"regular"']),
    ("model", "seed", 1.5, ["[model] seed = 1.5", "integer"]),
    ("model", "snapshots", 1, ["[model] snapshots = 1", "unknown key", "[output]"]),
    ("output", "snapshots", "all", ['[output] snapshots = "all"', "non-negative integer"]),
    ("output", "dir", 3, ["[output] dir = 3", "folder path"]),
    ("mandrel", "stl", 1, ["[mandrel] stl = 1", "file path", "integer"]),
    ("machine", "guide_ring", 0.17, ["[machine] guide_ring = 0.17", "radius"]),
])
def test_wrong_type(tmp_path, section, key, value, words):
    config_error(tmp_path, *words, **{section: {key: value}})


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_numbers(tmp_path, value):
    config_error(tmp_path, "[yarn] thickness =", "finite", yarn={"thickness": value})


POSITIVE = [("machine", "spool_radius"), ("machine", "angular_speed"), ("yarn", "width"),
            ("yarn", "thickness"), ("yarn", "tension"), ("process", "take_up_speed"),
            ("process", "braid_length"), ("model", "time_step"), ("output", "field_edge_length")]


@pytest.mark.parametrize("section,key", POSITIVE)
@pytest.mark.parametrize("value", [0, -0.5])
def test_zero_or_negative_where_positive_is_required(tmp_path, section, key, value):
    config_error(tmp_path, f"[{section}] {key} = {value!r}", "greater than zero",
                 **{section: {key: value}})


@pytest.mark.parametrize("section,key", [("process", "initial_position"), ("process", "pose_lead")])
def test_negative_lengths(tmp_path, section, key):
    config_error(tmp_path, f"[{section}] {key} = -0.1", "must not be negative", **{section: {key: -0.1}})


def test_guide_ring_radius_must_be_positive(tmp_path):
    config_error(tmp_path, "[machine] guide_ring.radius = 0", "greater than zero",
                 machine={"guide_ring": {"radius": 0}})


@pytest.mark.parametrize("key", ["friction", "ring_friction"])
def test_negative_friction(tmp_path, key):
    config_error(tmp_path, f"[yarn] {key} = -0.1", "coefficient of friction", "must not be negative",
                 yarn={key: -0.1})


@pytest.mark.parametrize("value", [2, 2.5])
def test_friction_too_large(tmp_path, value):
    config_error(tmp_path, f"[yarn] friction = {value!r}", "[0, 2)", yarn={"friction": value})


def test_howell_friction_law_is_read_and_echoed(tmp_path):
    cfg = load_config(make_case(tmp_path, yarn={"friction": 0.2, "friction_law": "howell",
                                                "howell_index": 0.85,
                                                "howell_reference_force": 0.5}))
    y = cfg.yarn
    assert (y.friction_law, y.howell_index, y.howell_reference_force) == ("howell", 0.85, 0.5)
    echo = dump_config(cfg)["yarn"]
    assert (echo["friction_law"], echo["howell_index"], echo["howell_reference_force"]) == (
        "howell", 0.85, 0.5)
    # the reference force defaults to 1 N, and Amontons stays the default law
    assert load_config(make_case(tmp_path, yarn={"friction_law": "howell", "howell_index": 0.9})
                       ).yarn.howell_reference_force == 1.0
    assert load_config(make_case(tmp_path)).yarn.friction_law == "amontons"


@pytest.mark.parametrize("law", [{}, {"friction_law": "howell", "howell_index": 0.85,
                                      "howell_reference_force": 0.5}])
def test_the_friction_law_echo_reads_back_as_the_same_yarn(tmp_path, law):
    """The echo written as a config (as ``preform design`` writes one, absent values left out)
    loads to the same [yarn]: Howell's keys are echoed under Howell's law only."""
    cfg = load_config(make_case(tmp_path, yarn={"friction": 0.2, **law}))
    echo = dump_config(cfg)["yarn"]
    again = load_config(make_case(tmp_path, name="again", yarn={
        k: (v if v is not None else DROP) for k, v in echo.items()}))
    assert again.yarn == cfg.yarn


def test_friction_law_choice_with_suggestion(tmp_path):
    config_error(tmp_path, '[yarn] friction_law = "howel"', "did you mean 'howell'",
                 '"amontons", "howell"', yarn={"friction_law": "howel"})


def test_howell_needs_its_index(tmp_path):
    config_error(tmp_path, '[yarn] friction_law = "howell"', "needs howell_index", "0 < n <= 1",
                 yarn={"friction_law": "howell"})


@pytest.mark.parametrize("value", [0, -0.5, 1.2])
def test_howell_index_outside_zero_to_one(tmp_path, value):
    config_error(tmp_path, f"[yarn] howell_index = {value!r}", "0 < n <= 1",
                 yarn={"friction_law": "howell", "howell_index": value})


@pytest.mark.parametrize("key, value", [("howell_index", 0.8), ("howell_reference_force", 1.0)])
def test_howell_keys_need_the_howell_law(tmp_path, key, value):
    config_error(tmp_path, f"[yarn] {key} = {value!r}", 'applies to friction_law = "howell" only',
                 '"amontons"', yarn={key: value})


@pytest.mark.parametrize("value", [0, -1.0, 5e-5, 2000.0])
def test_howell_reference_force_out_of_range(tmp_path, value):
    config_error(tmp_path, f"[yarn] howell_reference_force = {value!r}", "N",
                 yarn={"friction_law": "howell", "howell_index": 0.8,
                       "howell_reference_force": value})


def test_stl_unit_choice(tmp_path):
    config_error(tmp_path, '[mandrel] stl_unit = "cm"', 'expected one of "m", "mm"',
                 mandrel={"stl_unit": "cm"})


def test_pattern_choice_with_suggestion(tmp_path):
    config_error(tmp_path, '[machine] pattern = "regulr"', "did you mean 'regular'",
                 '"diamond", "regular", "hercules"', machine={"pattern": "regulr"})


def test_model_kind_choice(tmp_path):
    config_error(tmp_path, '[model] kind = "fem"', '"kinematic", "interaction"', model={"kind": "fem"})


def test_model_start_choice(tmp_path):
    config_error(tmp_path, '[model] start = "middle"', '"tip", "random"', model={"start": "middle"})


@pytest.mark.parametrize("value", [-1])
def test_negative_seed(tmp_path, value):
    config_error(tmp_path, "[model] seed = -1", "non-negative integer", model={"seed": value})


@pytest.mark.parametrize("carriers,pattern", [(95, "regular"), (94, "regular"), (4, "regular"),
                                              (16, "hercules"), (2, "diamond"), (0, "diamond")])
def test_carriers_not_runnable_by_the_pattern(tmp_path, carriers, pattern):
    config_error(tmp_path, f"[machine] carriers = {carriers}", "even", f'"{pattern}"',
                 machine={"carriers": carriers, "pattern": pattern})


@pytest.mark.parametrize("radius", [0.85, 0.9])
def test_guide_ring_not_inside_the_spool_circle(tmp_path, radius):
    config_error(tmp_path, f"[machine] guide_ring.radius = {radius}", "less than [machine] spool_radius",
                 machine={"guide_ring": {"radius": radius}})


def test_guide_ring_offset_negative(tmp_path):
    config_error(tmp_path, "[machine] guide_ring.offset = -0.01", "must not be negative",
                 machine={"guide_ring": {"radius": 0.17, "offset": -0.01}})


def test_missing_stl_names_the_resolved_path(tmp_path):
    msg = config_error(tmp_path, '[mandrel] stl = "../mandrels/x.stl"', "file not found",
                       mandrel={"stl": "../mandrels/x.stl"})
    assert str((tmp_path.parent / "mandrels" / "x.stl").resolve()) in msg


def test_stl_that_is_a_folder(tmp_path):
    (tmp_path / "d").mkdir()
    config_error(tmp_path, '[mandrel] stl = "d"', "folder", mandrel={"stl": "d"})


def test_missing_centerline_names_the_resolved_path(tmp_path):
    msg = config_error(tmp_path, '[mandrel] centerline = "cl.csv"', "file not found",
                       mandrel={"centerline": "cl.csv"})
    assert str((tmp_path / "cl.csv").resolve()) in msg


@pytest.mark.parametrize("value", [[0.1], [0.1, 0.2, 0.3], 0.1, ["a", 0.0], [True, 0.0]])
def test_eccentricity_not_two_numbers(tmp_path, value):
    config_error(tmp_path, "[process] eccentricity =", "2 numbers", process={"eccentricity": value})


@pytest.mark.parametrize("value", [[1, 0], [0, 0, 0]])
def test_roll_reference(tmp_path, value):
    config_error(tmp_path, "[mandrel] roll_reference =", "3 numbers" if len(value) != 3 else "non-zero",
                 mandrel={"roll_reference": value})


@pytest.mark.parametrize("table,words", [
    ([], ["empty"]),
    ([[0, 0.02], [0, 0.03]], ["strictly increasing"]),
    ([[0.5, 0.02], [0.2, 0.03]], ["strictly increasing"]),
    ([[0, 0.02, 1]], ["not a pair"]),
    ([0.02, 0.03], ["not a pair"]),
    ([[-0.1, 0.02]], ["must not be negative"]),
    ([[0, 0.02], [0.5, 0.0]], ["greater than zero"]),
])
def test_bad_take_up_speed_table(tmp_path, table, words):
    config_error(tmp_path, "[process] take_up_speed =", *words, process={"take_up_speed": table})


def test_take_up_speed_in_mm_per_s(tmp_path):
    config_error(tmp_path, "[process] take_up_speed = 26.3", "expected m/s", "mm/s",
                 process={"take_up_speed": 26.3})


def test_take_up_speed_table_in_mm_per_s(tmp_path):
    config_error(tmp_path, "[process] take_up_speed =", "mm/s",
                 process={"take_up_speed": [[0, 0.02], [0.5, 30.0]]})


def test_angular_speed_not_in_deg_per_s(tmp_path):
    config_error(tmp_path, "[machine] angular_speed = 5000", "expected deg/s",
                 machine={"angular_speed": 5000})


@pytest.mark.parametrize("section,key,value", [("machine", "spool_radius", 850),
                                               ("yarn", "width", 4), ("yarn", "thickness", 0.25)])
def test_lengths_in_mm(tmp_path, section, key, value):
    config_error(tmp_path, f"[{section}] {key} = {value}", "expected m", "mm?", **{section: {key: value}})


def test_section_that_is_not_a_table(tmp_path):
    path = make_case(tmp_path, yarn=DROP)
    path.write_text("yarn = 3\n" + path.read_text())
    with pytest.raises(ConfigError, match=r"\[yarn\] must be a table"):
        load_config(path)


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    path = make_case(tmp_path)
    plain = load_config(path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())   # what Notepad writes
    assert load_config(path).machine == plain.machine


def test_a_folder_given_as_config_is_said_so(tmp_path):
    with pytest.raises(ConfigError, match="is a folder: give the path of a .toml"):
        load_config(tmp_path)


def test_a_config_not_in_utf8_names_the_byte(tmp_path):
    path = make_case(tmp_path)
    path.write_bytes(path.read_bytes() + b"# caf\xe9\n")
    with pytest.raises(ConfigError, match="not UTF-8 text.*save the config as UTF-8"):
        load_config(path)


def test_pose_lead_auto_is_the_default_and_can_be_said(tmp_path):
    assert load_config(make_case(tmp_path, process={"pose_lead": "auto"})).process.pose_lead is None
    with pytest.raises(ConfigError, match=r'pose_lead.*or "auto"'):
        load_config(make_case(tmp_path, name="bad", process={"pose_lead": "far"}))


def test_mandrel_body_key(tmp_path):
    assert load_config(make_case(tmp_path, mandrel={"body": "largest"})).mandrel.body == "largest"
    assert load_config(make_case(tmp_path, name="one", mandrel={"body": 1})).mandrel.body == 1
    with pytest.raises(ConfigError, match=r'\[mandrel\] body.*expected "largest" or the index'):
        load_config(make_case(tmp_path, name="bad", mandrel={"body": -1}))


def test_yarn_min_width_defaults_to_half_the_width(tmp_path):
    cfg = load_config(make_case(tmp_path))
    assert cfg.yarn.min_width is None and cfg.yarn.least_width == 0.5 * cfg.yarn.width
    cfg = load_config(make_case(tmp_path, name="w", yarn={"min_width": 1e-3}))
    assert cfg.yarn.least_width == 1e-3
    with pytest.raises(ConfigError, match=r"min_width.*expected at most \[yarn\] width"):
        load_config(make_case(tmp_path, name="wide", yarn={"min_width": 1.0}))


def test_rtm_material_and_section(tmp_path):
    cfg = load_config(make_case(tmp_path, yarn={"linear_density_tex": 800.0, "fibre_density": 1780.0,
                                                "fibre_radius": 3.5e-6},
                                rtm={"cavity_thickness": 1.2e-3, "packing": "quadratic"}))
    assert cfg.yarn.has_material and cfg.yarn.fibre_density == 1780.0
    assert cfg.rtm.cavity_thickness == 1.2e-3 and cfg.rtm.permeability == "gebart"
    assert not load_config(make_case(tmp_path, name="plain")).yarn.has_material
    with pytest.raises(ConfigError, match="go together: give fibre_density, fibre_radius too"):
        load_config(make_case(tmp_path, name="half", yarn={"linear_density_tex": 800.0}))
    with pytest.raises(ConfigError, match=r"fibre_density = 1.78.*g/cm\^3\? multiply by 1000"):
        load_config(make_case(tmp_path, name="unit", yarn={"linear_density_tex": 800.0,
                                                           "fibre_density": 1.78, "fibre_radius": 3.5e-6}))
    with pytest.raises(ConfigError, match="needs k_ref"):
        load_config(make_case(tmp_path, name="kc", rtm={"permeability": "kozeny_carman"}))


def test_model_solver_key(tmp_path):
    """``[model] solver``: "relax" by default, "newton" (the reference) accepted and echoed,
    anything else refused with the key, the value and the choices named."""
    assert load_config(make_case(tmp_path)).model.solver == "relax"
    cfg = load_config(make_case(tmp_path, model={"kind": "interaction", "solver": "newton"}))
    assert cfg.model.solver == "newton" and dump_config(cfg)["model"]["solver"] == "newton"
    config_error(tmp_path, "solver", "cholesky", '"newton"', '"relax"',
                 model={"solver": "cholesky"})


def test_model_frontal_iterations_key(tmp_path):
    """``[model] frontal_iterations``: 1 by default (the bounds lag by a step), an integer from 1
    to 20 accepted and echoed (the checkpoint's inputs then differ), anything else refused with
    the key, the value and the range named."""
    assert load_config(make_case(tmp_path)).model.frontal_iterations == 1
    cfg = load_config(make_case(tmp_path, model={"kind": "interaction", "frontal_iterations": 3}))
    assert cfg.model.frontal_iterations == 3
    assert dump_config(cfg)["model"]["frontal_iterations"] == 3
    for bad in (0, 21, 2.5, "3", True):
        config_error(tmp_path, "frontal_iterations", "from 1 to 20",
                     model={"frontal_iterations": bad})
