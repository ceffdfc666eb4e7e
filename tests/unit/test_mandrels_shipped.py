"""The mandrels shipped in ``mandrels/``: loadable, closed, what their docstring says, and reproducible
by ``mandrels/make_mandrels.py`` (regenerated into a temporary folder, never over the committed files).
"""

from __future__ import annotations

import hashlib
import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from preform.cli import main
from preform.geometry import load_mandrel, read_centerline_csv, shapes

MANDRELS = Path(__file__).resolve().parents[2] / "mandrels"
SHIPPED = sorted(p.stem for p in MANDRELS.glob("*.stl"))


def _stl_triangles(path):
    """(n, 3, 3) float64 corners of a binary STL, read with NumPy alone (80-byte header, uint32
    count, then 50 bytes per triangle: normal, three corners, attribute)."""
    raw = Path(path).read_bytes()
    n = int(np.frombuffer(raw, dtype="<u4", count=1, offset=80)[0])
    assert len(raw) == 84 + 50 * n, f"{path} is not a binary STL"
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    return np.frombuffer(raw, dtype=record, count=n, offset=84)["corners"].astype(np.float64)


def _make_mandrels_module():
    spec = importlib.util.spec_from_file_location("make_mandrels", MANDRELS / "make_mandrels.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def loaded():
    return {name: load_mandrel(MANDRELS / f"{name}.stl") for name in SHIPPED}


def test_the_six_mandrels_are_there():
    assert SHIPPED == sorted(["case_a", "case_b", "bent_tube", "cone", "waist", "bulge"])
    for name in SHIPPED:
        assert (MANDRELS / f"{name}_centerline.csv").is_file()


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_mandrel_loads_closed_with_its_centerline(loaded, name):
    m = loaded[name]
    assert m.repairs == ()                                  # clean as shipped: nothing to repair
    assert np.all(m.neighbors >= 0)
    assert m.mesh.is_watertight and m.mesh.is_winding_consistent and m.mesh.volume > 0
    cl = read_centerline_csv(MANDRELS / f"{name}_centerline.csv")
    # the CSV starts at the tip: its first point is the origin, the centre of the tip cap, and no
    # part of the mandrel lies behind it; likewise nothing lies beyond its last point.
    # (1e-7 m: float32 corners of coordinates up to 2 m round by at most 2**-24 * 2)
    assert np.allclose(cl.points[0], 0.0, atol=1e-15)
    V = m.vertices
    assert np.min((V - cl.points[0]) @ cl.tangents[0]) == pytest.approx(0.0, abs=1e-7)
    assert np.max((V - cl.points[-1]) @ cl.tangents[-1]) == pytest.approx(0.0, abs=1e-7)
    tip_cap = V[np.abs((V - cl.points[0]) @ cl.tangents[0]) < 1e-7]
    assert np.allclose(tip_cap.mean(axis=0), cl.points[0], atol=1e-6)
    # and it runs inside the mandrel
    inner = cl.frames_at(np.linspace(0.01, cl.length - 0.01, 25))[0]
    assert np.all(m.mesh.contains(inner))


@pytest.mark.parametrize("name, r_min, r_max, length", [
    ("case_a", 0.075, 0.075, 3.0),            # Ko: r = v tan 60 / omega = 75 mm
    ("cone", 0.04, 0.08, 1.0),
    ("waist", 0.045, 0.075, 1.2),
    ("bulge", 0.05, 0.09, 1.2),
])
def test_shipped_solids_of_revolution_have_the_documented_size(loaded, name, r_min, r_max, length):
    V = loaded[name].vertices
    r = np.hypot(V[:, 0], V[:, 1])
    r = r[r > 1e-3]                                         # the rings, not the two cap centres
    # vertices sit on the smooth radius (float32: 1e-7 m); rings are 5 mm apart on the waist and
    # bulge, so the extreme ring is within (5 mm)^2 r'' / 8 of the extreme radius (< 0.2 mm here)
    assert r.min() == pytest.approx(r_min, abs=2e-4) and r.max() == pytest.approx(r_max, abs=2e-4)
    assert V[:, 2].min() == pytest.approx(0.0, abs=1e-7) and V[:, 2].max() == pytest.approx(length, abs=1e-6)


def test_mandrel_info_on_case_b(tmp_path, capsys):
    out = tmp_path / "case_b_auto.csv"
    code = main(["mandrel", "info", str(MANDRELS / "case_b.stl"), "--csv", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    match = re.search(r"perimeter\s+min ([\d.]+) m, max ([\d.]+) m", printed)
    assert match, printed
    low, high = float(match.group(1)) * 1e3, float(match.group(2)) * 1e3     # mm
    # the ends are the rounded square and the circle of the same perimeter (0.3342 m, sampled by
    # 128-gons); the linear blend of their points between 0.9 and 1.1 m dips about 1.3 % below
    exact = shapes.rounded_square_perimeter(0.09, 0.015) * 1e3
    assert high == pytest.approx(exact, rel=1e-3)
    assert exact * 0.97 < low < high
    assert "watertight" in printed and str(out) in printed
    cl = read_centerline_csv(out)
    assert np.allclose(cl.points[[0, -1]], [[0, 0, 0], [0, 0, 1.5]], atol=1e-3)
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert table.shape == (len(cl.points), 5)
    assert np.allclose(table[:, 3], cl.s, atol=1e-8)                       # the s column is arc length
    assert np.all(table[1:-1, 4] * 1e3 >= low - 0.01) and np.all(table[:, 4] * 1e3 <= high + 0.01)


def _digest(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def test_make_mandrels_is_deterministic(tmp_path, monkeypatch, capsys):
    module = _make_mandrels_module()
    before = _digest(MANDRELS)
    # the builders give the committed triangles: float32 (as stored) of the regenerated corners
    for name, (make, path) in module.MANDRELS.items():
        V, F = make()
        stored = _stl_triangles(MANDRELS / f"{name}.stl")
        assert stored.shape == (len(F), 3, 3), name
        assert np.allclose(V[F].astype(np.float32).astype(np.float64), stored, rtol=0, atol=1e-9), name
        committed = np.loadtxt(MANDRELS / f"{name}_centerline.csv", delimiter=",", skiprows=1)
        assert np.allclose(committed, path, rtol=0, atol=1e-9), name
    # and the script itself, run into a temporary copy, writes the same files
    monkeypatch.setattr(module, "HERE", tmp_path)
    module.main()
    assert "case_a:" in capsys.readouterr().out
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == sorted([f"{n}.stl" for n in SHIPPED] + [f"{n}_centerline.csv" for n in SHIPPED])
    for name in SHIPPED:
        assert np.allclose(_stl_triangles(tmp_path / f"{name}.stl"), _stl_triangles(MANDRELS / f"{name}.stl"),
                           rtol=0, atol=1e-9), name
        assert (tmp_path / f"{name}_centerline.csv").read_text() == \
            (MANDRELS / f"{name}_centerline.csv").read_text(), name
    assert _digest(MANDRELS) == before                      # the committed files are untouched


def test_shipped_stl_reads_the_same_through_trimesh():
    """Our NumPy reader and trimesh agree on the stored triangles (so the checks above are fair)."""
    mesh = trimesh.load(MANDRELS / "cone.stl", process=False)
    assert np.array_equal(mesh.vertices[mesh.faces], _stl_triangles(MANDRELS / "cone.stl"))
