"""The on-disk cache (``io.cache``): the same bytes with and without it, and an entry that is
damaged, foreign, planted or pickled is ignored and rebuilt, never trusted."""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from preform.io import cache
from support.simcase import write_cylinder_case
from support.field_standins import cylinder, helices, make_result


@pytest.fixture
def folder(tmp_path, monkeypatch):
    where = tmp_path / "cache"
    monkeypatch.setenv("PREFORM_CACHE_DIR", str(where))
    monkeypatch.delenv("PREFORM_CACHE", raising=False)
    return where


def _only_entry(folder, kind):
    (entry,) = folder.glob(f"{kind}-*.npz")
    return entry


def test_where_the_cache_lives(tmp_path, monkeypatch):
    monkeypatch.delenv("PREFORM_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "xdg" / "preform"
    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "mine"))
    assert cache.cache_dir() == tmp_path / "mine"
    monkeypatch.setenv("PREFORM_CACHE", "0")
    assert cache.cache_dir() is None
    assert cache.store("x", "k" * 64, {"a": np.arange(3)}) is None and cache.load("x", "k" * 64) is None


def test_round_trip_and_keys(folder):
    key = cache.make_key("field_mesh", np.arange(4.0), 0.012)
    assert key != cache.make_key("field_mesh", np.arange(4), 0.012)      # dtype is part of the key
    assert key != cache.make_key("field_mesh", np.arange(4.0), 0.0121)
    arrays = {"a": np.arange(6.0).reshape(2, 3), "b": np.array([1, -1], dtype=np.int64)}
    path = cache.store("t", key, arrays)
    assert path.parent == folder and (path.stat().st_mode & 0o777) == 0o600
    got = cache.load("t", key)
    assert set(got) == {"a", "b"} and all(np.array_equal(got[k], arrays[k]) for k in arrays)
    assert cache.load("t", cache.make_key("other")) is None
    assert cache.load("t", key, check=lambda a: False) is None
    assert not [p for p in folder.iterdir() if p.name.startswith(".tmp-")]


def test_a_damaged_entry_is_ignored(folder):
    key = cache.make_key("damaged")
    path = cache.store("t", key, {"a": np.arange(1000.0)})
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF                  # one flipped byte inside the array
    path.write_bytes(bytes(data))
    assert cache.load("t", key) is None
    path.write_bytes(b"not a zip file")
    assert cache.load("t", key) is None


def test_an_entry_with_another_key_inside_is_ignored(folder):
    key, other = cache.make_key("mine"), cache.make_key("theirs")
    cache.store("t", other, {"a": np.arange(3.0)})
    os.replace(cache._entry("t", other, folder), cache._entry("t", key, folder))
    assert cache.load("t", key) is None


def test_a_pickle_in_an_entry_never_runs(folder, tmp_path):
    """An entry whose array is a pickled object (a payload that would create a file) is refused:
    np.load with allow_pickle=False raises, the entry is ignored, the payload never runs."""
    key = cache.make_key("pickled")
    marker = tmp_path / "pwned"

    class Payload:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    path = cache._entry("t", key, folder)
    folder.mkdir(parents=True, exist_ok=True)
    np.savez(path, a=np.array([Payload()], dtype=object), _meta=np.frombuffer(b"{}", dtype=np.uint8))
    assert cache.load("t", key) is None
    assert not marker.exists()


def test_a_planted_symlink_is_not_followed(folder, tmp_path):
    key = cache.make_key("planted")
    folder.mkdir(parents=True)
    target = tmp_path / "elsewhere.npz"
    cache.store("t", key, {"a": np.arange(3.0)})
    os.replace(cache._entry("t", key, folder), target)          # a valid entry, moved away
    cache._entry("t", key, folder).symlink_to(target)
    assert cache.load("t", key) is None                        # not read through the link
    before = target.read_bytes()
    path = cache.store("t", key, {"a": np.arange(4.0)})
    assert not path.is_symlink() and target.read_bytes() == before   # replaced, target untouched
    assert np.array_equal(cache.load("t", key)["a"], np.arange(4.0))


def _result():
    return make_result(cylinder(height=0.2), helices(np.radians(30.0), 8, z1=0.14))


def test_field_mesh_the_same_bytes_from_the_cache(folder):
    from preform.analysis.fields import field_mesh, map_to_surface

    result = _result()
    fresh = field_mesh(result, 0.015)
    first = cache.cached_field_mesh(result, 0.015)          # computed and stored
    entry = _only_entry(folder, "field_mesh")
    second = cache.cached_field_mesh(result, 0.015)         # read back
    for a, b, c in zip(fresh, first, second):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes() == np.asarray(c).tobytes()
    f0 = map_to_surface(result, 0.015)
    f1 = map_to_surface(result, mesh=second)
    assert f0.cell_data.keys() == f1.cell_data.keys()
    for name in f0.cell_data:
        assert f0.cell_data[name].tobytes() == f1.cell_data[name].tobytes(), name
    # another edge length is another entry; a damaged entry is rebuilt with the same bytes
    cache.cached_field_mesh(result, 0.02)
    assert len(list(folder.glob("field_mesh-*.npz"))) == 2
    entry.write_bytes(entry.read_bytes()[:-100])
    again = cache.cached_field_mesh(result, 0.015)
    assert all(np.asarray(a).tobytes() == np.asarray(b).tobytes() for a, b in zip(fresh, again))


def test_field_mesh_with_out_of_range_faces_is_rebuilt(folder):
    """An entry with a valid digest but faces pointing past the vertices (a foreign writer that
    knew the format) fails the shape checks and is rebuilt."""
    result = _result()
    good = cache.cached_field_mesh(result, 0.015)
    key = cache._field_mesh_key(result.mandrel, 0.015, __import__(
        "preform.geometry.remesh", fromlist=["RemeshSettings"]).RemeshSettings())
    bad_faces = good[1].copy()
    bad_faces[0, 0] = len(good[0]) + 5
    cache.store("field_mesh", key, {"vertices": good[0], "faces": bad_faces, "source_faces": good[2],
                                    "edge_length": np.array([0.015])})
    again = cache.cached_field_mesh(result, 0.015)
    assert np.array_equal(again[1], good[1])


def test_mandrel_from_the_cache_is_the_loaded_one(folder, tmp_path):
    from preform.geometry import load_mandrel

    config = write_cylinder_case(tmp_path, length=0.6, braid=0.06, carriers=16, friction=0.0)
    stl = next(Path(config).parent.glob("*.stl"))
    fresh = load_mandrel(stl, unit="m")
    first, second = cache.cached_mandrel(stl), cache.cached_mandrel(stl)
    for m in (first, second):
        for name in ("vertices", "faces", "face_normals", "corner_normals", "neighbors"):
            assert getattr(m, name).tobytes() == getattr(fresh, name).tobytes(), name
        assert m.repairs == fresh.repairs and m.source == fresh.source
    assert len(list(folder.glob("mandrel-*.npz"))) == 1
    # another unit is another entry; an STL that changes gets a new key
    cache.cached_mandrel(stl, unit="mm")
    assert len(list(folder.glob("mandrel-*.npz"))) == 2


def test_a_run_writes_the_same_bytes_with_and_without_the_cache(tmp_path, monkeypatch):
    from preform.cli import main

    config = write_cylinder_case(tmp_path, length=0.6, braid=0.06, carriers=16, friction=0.0)
    monkeypatch.setenv("PREFORM_CACHE_DIR", str(tmp_path / "cache"))
    outs = {}
    for name, setting in (("off", "0"), ("cold", "1"), ("warm", "1")):
        monkeypatch.setenv("PREFORM_CACHE", setting)
        outs[name] = tmp_path / name
        assert main(["run", str(config), "--out", str(outs[name]), "--no-progress"]) == 0
    assert {p.name.split("-")[0] for p in (tmp_path / "cache").iterdir()} == {"mandrel", "field_mesh"}
    for file in ("history.csv", "yarns.vtp", "surface.vtu", "surface.h5", "convergence/step_0000.vtp"):
        off = (outs["off"] / file).read_bytes()
        assert off == (outs["cold"] / file).read_bytes() == (outs["warm"] / file).read_bytes(), file
