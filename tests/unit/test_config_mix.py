"""Mixed yarns in the config (docs/guide/configuration.md, "Mixed yarns"): ``[[yarn_type]]``,
``[machine] carrier_yarns`` and ``[[friction_pair]]``, their checks, echo and check lines."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import tomli_w

from preform.config import dump_config, load_config, mix_lines
from preform.errors import ConfigError

BASE = {
    "mandrel": {"stl": "m.stl"},
    "machine": {"carriers": 16, "spool_radius": 0.85, "angular_speed": 18.0},
    "yarn": {"width": 4e-3, "thickness": 2.5e-4, "friction": 0.2, "tension": 4.7},
    "process": {"take_up_speed": 0.0263, "initial_position": 0.2, "braid_length": 1.3},
}
POLYESTER = {"name": "polyester", "width": 2e-3, "thickness": 1.5e-4, "friction": 0.1,
             "tension": 3.0}


def case(tmp_path, types=(POLYESTER,), pairs=(), carrier_yarns=("yarn", "yarn", "yarn",
                                                                "polyester"), **sections):
    doc = copy.deepcopy(BASE)
    for sec, changes in sections.items():
        doc.setdefault(sec, {}).update(changes)
    if carrier_yarns is not None:
        doc["machine"]["carrier_yarns"] = (list(carrier_yarns) if isinstance(carrier_yarns, tuple)
                                           else carrier_yarns)
    if types:
        doc["yarn_type"] = [dict(t) for t in types]
    if pairs:
        doc["friction_pair"] = [dict(p) for p in pairs]
    (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    path = tmp_path / "case.toml"
    path.write_text(tomli_w.dumps(doc))
    return path


def error(tmp_path, *words, **kw) -> str:
    with pytest.raises(ConfigError) as info:
        load_config(case(tmp_path, **kw))
    message = str(info.value)
    for word in words:
        assert word in message, (word, message)
    return message


def test_types_inherit_yarn_and_carriers_repeat_round_each_group(tmp_path):
    cfg = load_config(case(tmp_path, pairs=[{"types": ["yarn", "polyester"], "friction": 0.15}]))
    assert cfg.type_names == ("yarn", "polyester")
    poly = cfg.yarn_type("polyester")
    assert (poly.width, poly.thickness, poly.friction, poly.tension) == (2e-3, 1.5e-4, 0.1, 3.0)
    assert poly.ring_friction == cfg.yarn.ring_friction       # not given: [yarn]'s
    assert poly.least_width == 1e-3                            # half its own width
    assert cfg.is_mixed
    # 8 carriers a group, the pattern twice round each, from its first carrier
    assert cfg.carrier_types().tolist() == [0, 0, 0, 1] * 4
    mu, source = cfg.pair_friction()
    np.testing.assert_array_equal(mu, [[0.2, 0.15], [0.15, 0.1]])
    assert source.tolist() == [["own", "pair"], ["pair", "own"]]


def test_one_name_puts_a_type_on_every_carrier(tmp_path):
    cfg = load_config(case(tmp_path, carrier_yarns="polyester"))
    assert cfg.carrier_types().tolist() == [1] * 16
    assert cfg.used_types() == (1,)


def test_a_pair_not_listed_takes_the_mean_and_check_says_so(tmp_path):
    cfg = load_config(case(tmp_path))
    mu, source = cfg.pair_friction()
    assert mu[0, 1] == mu[1, 0] == pytest.approx(0.15)   # (0.2 + 0.1) / 2
    assert source[0, 1] == "mean"
    lines = mix_lines(cfg)
    assert lines[0].startswith("yarns: yarn 6, polyester 2 carriers per group")
    assert "friction yarn-polyester: 0.15 (not listed: the mean of the two types' own friction)" in lines
    assert "friction yarn-yarn: 0.2 (the type's own friction)" in lines
    assert "friction polyester-polyester: 0.1 (the type's own friction)" in lines


def test_check_says_the_interaction_zone_takes_yarns_shape(tmp_path):
    cfg = load_config(case(tmp_path, model={"kind": "interaction"}))
    assert mix_lines(cfg)[-1].startswith("the interaction model's crossings take [yarn]'s width")
    same = {**POLYESTER, "width": 4e-3, "thickness": 2.5e-4}
    assert "crossings" not in " ".join(mix_lines(load_config(case(
        tmp_path, types=(same,), model={"kind": "interaction"}))))


def test_uniform_config_echoes_and_checks_as_before(tmp_path):
    cfg = load_config(case(tmp_path, types=(), carrier_yarns=None))
    assert not cfg.is_mixed and mix_lines(cfg) == []
    echo = dump_config(cfg)
    assert "carrier_yarns" not in echo["machine"] and "yarn_types" not in echo
    assert "friction_pairs" not in echo


def test_echo_names_the_types_and_pairs(tmp_path):
    cfg = load_config(case(tmp_path, pairs=[{"types": ["polyester", "yarn"], "friction": 0.3}]))
    echo = json.loads(json.dumps(dump_config(cfg)))
    assert echo["machine"]["carrier_yarns"] == ["yarn", "yarn", "yarn", "polyester"]
    assert echo["yarn_types"]["polyester"]["width"] == 2e-3
    assert echo["friction_pairs"] == {"1": {"types": ["polyester", "yarn"], "friction": 0.3}}
    # the checkpoint's record of the inputs takes every echoed table
    from preform.checkpoint import input_record

    (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    record = input_record(cfg)
    assert record["[friction_pairs] 1"] == {"types": ["polyester", "yarn"], "friction": 0.3}
    assert record["[yarn_types] polyester"]["width"] == 2e-3


def test_unknown_type_on_the_carriers(tmp_path):
    error(tmp_path, "[machine] carrier_yarns", 'unknown yarn type "polyster"', "polyester",
          carrier_yarns=["yarn", "polyster"])


def test_pattern_that_does_not_divide_the_group(tmp_path):
    error(tmp_path, "[machine] carrier_yarns", "a pattern of 3 does not divide the 8 carriers",
          carrier_yarns=["yarn", "yarn", "polyester"])


@pytest.mark.parametrize("value", [[], 3, ["yarn", 2]])
def test_carrier_yarns_of_the_wrong_shape(tmp_path, value):
    error(tmp_path, "[machine] carrier_yarns", "expected a yarn type name", carrier_yarns=value)


def test_a_pair_listed_twice_in_either_order(tmp_path):
    pairs = [{"types": ["yarn", "polyester"], "friction": 0.15},
             {"types": ["polyester", "yarn"], "friction": 0.2}]
    error(tmp_path, "[[friction_pair]] 2 types", "listed twice", "[[friction_pair]] 1", pairs=pairs)


def test_a_pair_of_an_unknown_type_or_a_type_with_itself(tmp_path):
    error(tmp_path, "[[friction_pair]] 1 types", 'unknown yarn type "nylon"',
          pairs=[{"types": ["yarn", "nylon"], "friction": 0.15}])
    error(tmp_path, "a type with itself", pairs=[{"types": ["yarn", "yarn"], "friction": 0.15}])


def test_a_pair_needs_its_friction_in_range(tmp_path):
    error(tmp_path, "[[friction_pair]] 1 friction is missing",
          pairs=[{"types": ["yarn", "polyester"]}])
    error(tmp_path, "[[friction_pair]] 1 friction = -0.1", "must not be negative",
          pairs=[{"types": ["yarn", "polyester"], "friction": -0.1}])


def test_a_type_named_twice_or_named_yarn(tmp_path):
    error(tmp_path, '[[yarn_type]] 2 name = "polyester"', "named twice", "[[yarn_type]] 1",
          types=(POLYESTER, POLYESTER))
    error(tmp_path, 'name = "yarn"', "the type [yarn] describes",
          types=({**POLYESTER, "name": "yarn"},))


@pytest.mark.parametrize("name", ["warp", "2ply", "poly ester", ""])
def test_type_names_that_cannot_name_fields(tmp_path, name):
    error(tmp_path, "[[yarn_type]] 1 name", types=({**POLYESTER, "name": name},),
          carrier_yarns=None)


def test_a_type_value_is_checked_with_its_name(tmp_path):
    error(tmp_path, '[[yarn_type]] "polyester" width = 2.0', "mm? divide by 1000",
          types=({**POLYESTER, "width": 2.0},))
    error(tmp_path, '[[yarn_type]] "polyester" widht', "did you mean 'width'",
          types=({**POLYESTER, "widht": 1e-3},))
    error(tmp_path, '[[yarn_type]] "polyester" min_width', 'at most [[yarn_type]] "polyester" width',
          types=({**POLYESTER, "min_width": 3e-3},))


def test_tow_data_for_every_type_on_the_carriers_or_none(tmp_path):
    tow = {"linear_density_tex": 300.0, "fibre_density": 2550.0, "fibre_radius": 8e-6}
    # [yarn] without tow data beside a type with them, both on the carriers
    error(tmp_path, 'the yarn type "yarn" has no tow material data', types=({**POLYESTER, **tow},))
    # a type without tow data of its own takes [yarn]'s
    assert load_config(case(tmp_path, yarn=tow)).yarn_type("polyester").fibre_density == 2550.0
    # a type's own tow data replace [yarn]'s as a whole, and go together
    error(tmp_path, "the RTM material data go together",
          types=({**POLYESTER, "linear_density_tex": 110.0},), yarn=tow)
    cfg = load_config(case(tmp_path, yarn=tow, types=({**POLYESTER, "linear_density_tex": 110.0,
                                                       "fibre_density": 1380.0,
                                                       "fibre_radius": 1e-5},)))
    assert cfg.yarn_type("polyester").fibre_density == 1380.0


def test_yarn_type_as_a_single_table_is_said_so(tmp_path):
    path = case(tmp_path, types=(), carrier_yarns=None)
    path.write_text(path.read_text() + '\n[yarn_type]\nname = "x"\n')
    with pytest.raises(ConfigError, match=r"write \[\[yarn_type\]\]"):
        load_config(path)


def test_a_layer_keeps_the_pattern_dividing_its_group(tmp_path):
    path = case(tmp_path, carrier_yarns=["yarn", "polyester"])
    path.write_text(path.read_text() + "\n[[layer]]\n[layer.machine]\ncarriers = 12\n"
                    'carrier_yarns = ["yarn", "yarn", "yarn", "polyester"]\n')
    with pytest.raises(ConfigError, match=r"\[\[layer\]\] 1 \[machine\] carrier_yarns .* a pattern "
                                          r"of 4 does not divide the 6 carriers"):
        load_config(path)
