"""Small meshes' intake: below ``IntakeSettings.kernel_faces`` the repair, the mandrel's
arrays, the section index and the centerline-inside check take the NumPy forms of the numba kernels (``geometry.small_mesh``).
Both paths give the same arrays, bit for bit, the same report or the same refusal, on clean,
damaged and refused meshes; and a first load and check of a shipped mandrel compiles none of
those kernels."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from preform.errors import MandrelError
from preform.geometry.mandrel import read_stl
from preform.geometry.repair import repair_mesh, self_intersections
from preform.geometry.small_mesh import IntakeSettings
from preform.tolerances import tol
from support.intake import INTAKE_KERNELS

ROOT = Path(__file__).resolve().parents[2]
NUMPY = IntakeSettings(kernel_faces=10**12)
KERNELS = IntakeSettings(kernel_faces=0)


def _repaired(v, f, settings, **kw):
    try:
        return repair_mesh(v, f, settings=settings, **kw)
    except MandrelError as exc:
        return str(exc)


def assert_same_intake(v, f, **kw):
    """repair_mesh on both paths: the same vertices and faces (bytes), report, or refusal."""
    a, b = _repaired(v, f, NUMPY, **kw), _repaired(v, f, KERNELS, **kw)
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return a
    for x, y in zip(a[:2], b[:2]):
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
    assert a[2] == b[2]
    return a


def _soup(v, f):
    return v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3)


def _sphere():
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    return np.asarray(s.vertices), np.asarray(s.faces)


def _sliver():
    m = trimesh.creation.cylinder(radius=0.04, height=1.6, sections=256)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _moebius():
    n = 24
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.vstack([np.column_stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t),
                                    s * np.sin(t / 2)]) for s in (-0.2, 0.2)])
    F = []
    for i in range(n):
        j = (i + 1) % n
        c, d = (j, n + j) if j else (n + j, j)            # the half twist joins the sides crosswise
        F += [(i, c, n + i), (n + i, c, d)]
    return V, np.array(F, dtype=np.int64)


def _damaged(kind, seed):
    """A sphere or the sliver cylinder: some faces flipped, some duplicated (either winding),
    shuffled, as a soup with every corner copy jittered within the merge radius."""
    v, f = _sphere() if kind == "sphere" else _sliver()
    rng = np.random.default_rng(seed)
    f = f.copy()
    pick = rng.random(len(f)) < 0.3
    f[pick] = f[pick, ::-1]
    f = np.vstack([f, f[rng.random(len(f)) < 0.1][:, ::-1], f[:3]])
    f = f[rng.permutation(len(f))]
    v, f = _soup(v, f)
    step = rng.normal(size=v.shape)
    size = np.linalg.norm(np.ptp(v, axis=0))
    return v + 0.45 * tol.merge_vertices * size * step / np.linalg.norm(step, axis=1)[:, None], f


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "mandrels").glob("*.stl")))
def test_shipped_mandrels_take_both_paths_alike(name):
    v, f, report = assert_same_intake(*read_stl(ROOT / "mandrels" / name))
    assert len(f) < IntakeSettings().kernel_faces            # the default path is the NumPy one


def _cases():
    v, f = _sphere()
    n = len(v)
    yield "sliver cylinder", _sliver(), {}
    yield "sliver soup", _soup(*_sliver()), {}
    for seed in range(3):
        yield f"damaged sphere {seed}", _damaged("sphere", seed), {}
        yield f"damaged sliver {seed}", _damaged("sliver", seed), {}
    copies = np.vstack([v, v[:12]])
    g = f.copy()
    g[1::2] = np.where(g[1::2] < 12, g[1::2] + n, g[1::2])
    yield "duplicate vertices", (copies, g), {}
    yield "collapsed faces", (v, np.vstack([f, [[0, 0, 1], [2, 2, 2], [3, 4, 3]]])), {}
    mid = np.vstack([v, v[f[0, :2]].mean(axis=0)])
    a, b, r = f[0]
    yield "cap", (mid, np.vstack([f[1:], [[a, n, r], [n, b, r], [a, n, b]]])), {}
    yield "duplicate faces", (v, np.vstack([f, f[:5], f[5:8, ::-1]])), {}
    yield "all inverted", (v, f[:, ::-1]), {}
    yield "small hole", (v, f[1:]), {}                     # one missing triangle: filled
    two = (np.vstack([v, v * 0.5 + [1.0, 0.0, 0.0]]), np.vstack([f + n, f]))
    yield "two bodies", two, {}
    yield "two bodies, largest", two, {"body": "largest"}
    yield "two bodies, second", two, {"body": 1}
    yield "moebius", _moebius(), {}
    pierced = v.copy()
    pierced[pierced[:, 0] > 0.09, 0] -= 0.25
    yield "self-intersection", (pierced, f), {}
    fin = np.vstack([v, [[0.5, 0.5, 0.5]]])
    yield "non-manifold", (fin, np.vstack([f, [[f[0, 0], f[0, 1], n]]])), {}


CASES = {name: (arrays, kw) for name, arrays, kw in _cases()}


@pytest.mark.parametrize("name", CASES)
def test_numpy_and_kernel_intake_are_identical(name):
    (v, f), kw = CASES[name]
    out = assert_same_intake(v, f, **kw)
    refused = {"two bodies": "2 disjoint bodies", "moebius": "cannot be oriented",
               "self-intersection": "intersects itself", "non-manifold": "non-manifold"}
    if name in refused:
        assert isinstance(out, str) and refused[name] in out
    else:
        assert not isinstance(out, str), out


@pytest.mark.parametrize("seed", range(3))
def test_self_intersection_rays_are_identical(seed):
    """The ray bookkeeping's NumPy form flags the same edges as the kernels on pierced spheres
    moved and turned at random, far from the origin too (embree's float32 frame)."""
    rng = np.random.default_rng(seed)
    v, f = _sphere()
    v = v.copy()
    v[v[:, 0] > rng.uniform(0.06, 0.095), 0] -= rng.uniform(0.18, 0.3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    v = v @ q + rng.normal(scale=10.0 ** seed, size=3)
    got = self_intersections(v, f, kernels=False)
    assert len(got) > 0
    np.testing.assert_array_equal(got, self_intersections(v, f, kernels=True))


def test_sections_are_identical_on_both_paths():
    """Section perimeters along case A's centerline by the NumPy forms (loops chained in Python,
    then, past ``python_sections`` sections of the mesh, by the kernel) and by the kernels."""
    from preform.geometry import load_mandrel
    from preform.geometry.centerline import read_centerline_csv, section_perimeters

    centerline = read_centerline_csv(ROOT / "mandrels" / "case_a_centerline.csv")
    s = np.linspace(0.01, 0.99, 40) * centerline.length
    by_kernels = section_perimeters(load_mandrel(ROOT / "mandrels" / "case_a.stl"), centerline, s, KERNELS)
    assert np.all(by_kernels > 0)
    for settings in (NUMPY, IntakeSettings(kernel_faces=10**12, python_sections=15)):
        mandrel = load_mandrel(ROOT / "mandrels" / "case_a.stl")     # a fresh section index
        assert section_perimeters(mandrel, centerline, s, settings).tobytes() == by_kernels.tobytes()
        assert mandrel.sections.metadata["_preform_sections_cut"] == len(s)


def test_mandrel_arrays_are_identical_on_both_paths():
    """Face normals, corner normals (crease-split: a box, the sliver cylinder's caps) and
    neighbours (-1 at open and doubly used edges) by the NumPy forms and by the kernels."""
    from preform.geometry.mandrel import mandrel_from_arrays

    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    v, f = _sphere()
    arrays = [repair_mesh(*read_stl(ROOT / "mandrels" / "bulge.stl"))[:2], _sliver(), (box.vertices, box.faces),
              (v, np.vstack([f[1:], f[5:6]]))]
    for v, f in arrays:
        a, b = (mandrel_from_arrays(v, f, check=False, settings=s) for s in (NUMPY, KERNELS))
        for name in ("vertices", "faces", "face_normals", "corner_normals", "neighbors"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert np.any(a.neighbors < 0)


def test_a_first_load_of_case_a_compiles_no_intake_kernel(tmp_path):
    """The command's geometry and checks (``pipeline.checked_geometry``) on case A in a fresh
    process with empty caches call none of the intake and mandrel kernels (they would have
    signatures)."""
    code = ("import json, sys\n"
            "from preform.config import load_config\n"
            "from preform.pipeline import checked_geometry\n"
            "from preform._kernels import edges, mesh, sections\n"
            "checked_geometry(load_config(sys.argv[1]))\n"
            "names = json.loads(sys.argv[2])\n"
            "mods = {'mesh': mesh, 'edges': edges, 'sections': sections}\n"
            "print(json.dumps({f'{m}.{k}': len(getattr(mods[m], k).signatures) for m in names for k in names[m]}))\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PREFORM_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, "-c", code, str(ROOT / "examples" / "case_a.toml"),
                           json.dumps(INTAKE_KERNELS)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    signatures = json.loads(done.stdout.splitlines()[-1])
    assert len(signatures) == sum(len(k) for k in INTAKE_KERNELS.values())
    assert {k: n for k, n in signatures.items() if n} == {}


def test_the_centerline_inside_check_decides_alike_on_both_paths():
    """preflight's winding numbers: case A passes on both paths; a centerline moved out of the
    mandrel is refused with the same message on both."""
    import dataclasses

    from preform.checks import _check_centerline_inside
    from preform.config import load_config
    from preform.geometry import load_mandrel
    from preform.geometry.centerline import read_centerline_csv

    config = load_config(ROOT / "examples" / "case_a.toml")
    mandrel = load_mandrel(config.mandrel.stl)
    centerline = read_centerline_csv(config.mandrel.centerline)
    for settings in (NUMPY, KERNELS):
        _check_centerline_inside(config, mandrel, centerline, settings)
    moved = dataclasses.replace(centerline, points=centerline.points + [0.0, 0.5, 0.0])
    messages = []
    for settings in (NUMPY, KERNELS):
        with pytest.raises(Exception, match="leaves the mandrel") as exc:
            _check_centerline_inside(config, mandrel, moved, settings)
        messages.append(str(exc.value))
    assert messages[0] == messages[1]
