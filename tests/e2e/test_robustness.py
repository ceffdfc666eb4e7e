"""Bad input never ends in a traceback: CLI messages, and property-based tests over
config values and damaged mandrels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tomli_w
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from preform.cli import main
from preform.errors import PreformError

ROOT = Path(__file__).resolve().parents[2]

BASE = {
    "mandrel": {"stl": str(ROOT / "mandrels" / "cone.stl"), "centerline": str(ROOT / "mandrels" / "cone_centerline.csv")},
    "machine": {"carriers": 16, "spool_radius": 0.3, "angular_speed": 13.232},
    "yarn": {"width": 4e-3, "thickness": 2.5e-4},
    "process": {"take_up_speed": 0.01, "initial_position": 0.05, "braid_length": 0.1},
}


def write_toml(path, data):
    path.write_text(tomli_w.dumps(data))
    return path


def _check(tmp_path, data, capsys):
    cfg = write_toml(tmp_path / "case.toml", data)
    code = main(["check", str(cfg)])
    captured = capsys.readouterr()
    return code, captured.err


def _with(section, key, value):
    data = {s: dict(t) for s, t in BASE.items()}
    data.setdefault(section, {})[key] = value
    return data


def test_base_case_passes(tmp_path, capsys):
    assert _check(tmp_path, BASE, capsys)[0] == 0


@pytest.mark.parametrize("section,key,value,words", [
    ("machine", "carriers", 18, ["[machine] carriers", "regular"]),
    ("machine", "spool_radus", 0.3, ["spool_radus", "spool_radius"]),           # did you mean
    ("process", "take_up_speed", -0.01, ["[process] take_up_speed"]),
    ("process", "take_up_speed", 10.0, ["[process] take_up_speed", "m/s"]),     # mm/s typed as m/s
    ("yarn", "width", "4 mm", ["[yarn] width"]),
    ("yarn", "friction", float("nan"), ["[yarn] friction"]),
    ("machine", "guide_ring", {"radius": 0.03}, ["guide ring"]),                 # mandrel does not fit
    ("machine", "spool_radius", 0.03, ["spool"]),                                # nor the spool ring
    ("mandrel", "stl_unit", "mm", ["stl_unit"]),                                  # 150 m read as ... too small
    ("mandrel", "stl", "nowhere.stl", ["nowhere.stl"]),
    ("process", "braid_length", 5.0, ["braid_length"]),                          # longer than the mandrel
])
def test_bad_input_names_key_and_expectation(tmp_path, capsys, section, key, value, words):
    code, err = _check(tmp_path, _with(section, key, value), capsys)
    assert code == 2
    assert "Traceback" not in err
    for w in words:
        assert w in err, (w, err)


def test_centerline_outside_the_mandrel(tmp_path, capsys):
    csv = tmp_path / "off.csv"
    csv.write_text("x,y,z\n0.5,0,0\n0.5,0,1.0\n")
    code, err = _check(tmp_path, _with("mandrel", "centerline", str(csv)), capsys)
    assert code == 2 and "leaves the mandrel" in err


def test_mandrel_in_mm_read_as_metres_suggests_stl_unit(tmp_path, capsys):
    mesh = trimesh.load(ROOT / "mandrels" / "cone.stl")
    mesh.apply_scale(1000.0)
    mesh.export(tmp_path / "cone_mm.stl")
    csv = tmp_path / "cl.csv"
    csv.write_text("x,y,z\n0,0,0\n0,0,1000\n")
    data = _with("mandrel", "stl", str(tmp_path / "cone_mm.stl"))
    data["mandrel"]["centerline"] = str(csv)
    code, err = _check(tmp_path, data, capsys)
    assert code == 2 and 'stl_unit = "mm"' in err


NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                    st.integers(min_value=-10**6, max_value=10**6),
                  st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=5), st.booleans())
KEYS = [("machine", "carriers"), ("machine", "spool_radius"), ("machine", "angular_speed"),
        ("yarn", "width"), ("yarn", "thickness"), ("yarn", "tension"), ("yarn", "friction"),
        ("process", "take_up_speed"), ("process", "initial_position"), ("process", "braid_length"),
        ("process", "eccentricity"), ("model", "time_step"), ("output", "snapshots")]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.lists(st.tuples(st.sampled_from(KEYS), NUMBERS), min_size=1, max_size=3))
def test_any_config_values_are_accepted_or_refused_cleanly(tmp_path, capsys, changes):
    data = {s: dict(t) for s, t in BASE.items()}
    for (section, key), value in changes:
        data.setdefault(section, {})[key] = value
    code, err = _check(tmp_path, data, capsys)
    assert code in (0, 2), err
    assert "Traceback" not in err
    if code == 2:
        assert "error: " in err and "[" in err


def _damage(mesh, rng, kind):
    v = mesh.vertices.copy()
    f = mesh.faces.copy()
    if kind == "flip":
        pick = rng.random(len(f)) < 0.2
        f[pick] = f[pick][:, ::-1]
    elif kind == "duplicate":
        f = np.vstack([f, f[rng.random(len(f)) < 0.05]])
    elif kind == "jitter":
        v = v + rng.normal(scale=1e-9 * np.ptp(v), size=v.shape)
    elif kind == "soup":
        v = v[f].reshape(-1, 3)
        f = np.arange(len(v)).reshape(-1, 3)
    elif kind == "hole":
        f = f[1:]
    return trimesh.Trimesh(v, f, process=False)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["flip", "duplicate", "jitter", "soup", "hole"]), seed=st.integers(0, 2**16),
       scale=st.sampled_from([1.0, 1000.0]))
def test_damaged_mandrels_load_or_fail_cleanly(tmp_path, kind, seed, scale):
    from preform.geometry import load_mandrel

    mesh = trimesh.load(ROOT / "mandrels" / "cone.stl")
    bad = _damage(mesh, np.random.default_rng(seed), kind)
    bad.apply_scale(scale)
    path = tmp_path / f"bad_{kind}.stl"
    bad.export(path)
    try:
        m = load_mandrel(path, unit="m" if scale == 1.0 else "mm")
    except PreformError as exc:
        assert str(exc)
        return
    assert np.all(np.isfinite(m.corner_normals))
    assert m.mesh.is_watertight and m.mesh.volume > 0
