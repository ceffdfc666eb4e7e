"""The import graph of ``src/preform`` has no cycle, and ``import preform`` stays light.

The graph is read from the source with ``ast`` (not by importing), so it includes imports inside
functions, which run later but still make a module depend on another: a cycle through one of them
is a cycle all the same. ``from package import name`` depends on the submodule ``package.name``
when there is one, else on the package's ``__init__``.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

from support.modules import SRC, imports_in, module_names


def imports_of(name: str, path: Path, modules) -> set[str]:
    """The modules of ``modules`` that module ``name`` (file ``path``) imports, anywhere in it."""
    return {target for _, target in imports_in(name, path, modules)}


def import_graph(src: Path) -> dict[str, set[str]]:
    modules = module_names(src)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_reader_sees_function_level_and_relative_imports(tmp_path):
    """The reader on a made-up package: a relative import inside a function closes a cycle."""
    pkg = tmp_path / "preform"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("VERSION = 1\n")
    (pkg / "leaf.py").write_text("from . import VERSION\n")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..a import g\n")
    graph = import_graph(tmp_path)
    assert graph["preform.leaf"] == {"preform"}
    assert graph["preform.a"] == {"preform.sub.b"}
    assert graph["preform.sub.b"] == {"preform.a"}
    assert cycles(graph) == [["preform.a", "preform.sub.b"]]


def test_no_import_cycle_in_the_package():
    found = cycles(import_graph(SRC))
    assert not found, "import cycles in src/preform: " + "; ".join(" <-> ".join(c) for c in found)


@pytest.mark.parametrize("module", ["preform", "preform.cli"])
@pytest.mark.parametrize("heavy", ["numba", "scipy", "trimesh", "pyvista", "matplotlib"])
def test_import_preform_is_light(heavy, module):
    """``import preform`` (and reading a config) and the command's module load none of the heavy
    packages: they load on first use of what needs them (a fresh interpreter, so nothing of this
    test run is loaded)."""
    code = (f"import sys, preform, {module}\n"
            "preform.load_config\n"
            f"print({heavy!r} in sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(SRC), "PATH": ""})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


def test_lazy_public_names_resolve_to_the_real_objects():
    """The names ``preform`` loads on first use are the functions and types themselves, with
    their own signatures (no ``**kwargs`` pass-through)."""
    import inspect

    import preform
    from preform.analysis.fields import SurfaceFields, map_to_surface

    assert preform.map_to_surface is map_to_surface
    assert preform.SurfaceFields is SurfaceFields
    assert "kwargs" not in str(inspect.signature(preform.map_to_surface))
    for name in preform.__all__:
        assert getattr(preform, name) is not None, name
    assert set(preform.__all__) <= set(dir(preform))


def test_the_function_simulate_is_not_shadowed_by_a_module():
    """``preform.simulate`` stays the function once every module of the package is imported
    (a module ``preform/simulate.py`` would replace it on its first import)."""
    import importlib

    import preform

    for name in sorted(module_names(SRC)):
        importlib.import_module(name)
    assert callable(preform.simulate) and preform.simulate.__name__ == "simulate"
    from preform.simulation import simulate

    assert preform.simulate is simulate


def test_both_zones_implement_the_zone_protocol():
    """The kinematic and the interaction zone have every method of ``preform.zone.Zone`` with
    its parameters (the class methods that build a zone and give its time step as class
    methods), and ``zone.ZONES`` maps both model kinds."""
    import inspect

    from preform.config import MODEL_KINDS
    from preform.zone import ZONES, Zone, zone_class

    assert sorted(ZONES) == sorted(MODEL_KINDS)
    methods = [name for name, _ in inspect.getmembers(Zone, inspect.isfunction) if not name.startswith("_")]
    assert sorted(methods) == ["export_state", "import_state", "snapshot", "start", "step"]
    builders = [name for name, _ in inspect.getmembers(Zone, inspect.ismethod) if not name.startswith("_")]
    assert sorted(builders) == ["default_time_step", "for_run"]
    for cls in map(zone_class, ZONES):
        for name in methods + builders:
            want = list(inspect.signature(getattr(Zone, name)).parameters)
            assert list(inspect.signature(getattr(cls, name)).parameters) == want, (cls, name)
        for name in builders:
            assert inspect.ismethod(getattr(cls, name)), (cls, name)


def test_a_kinematic_run_does_not_load_the_interaction_model(tmp_path):
    """The interaction model (its solvers, scipy.sparse, pymetis) is imported on first use: a
    kinematic stepper is built without it (0.7 s of a kinematic command's start measured)."""
    code = (
        "import sys\n"
        "import preform as pf\n"
        "from preform.simulation import load_geometry, make_stepper\n"
        "from pathlib import Path\n"
        f"cfg = pf.load_config(Path({str(EXAMPLES)!r}) / 'case_a.toml')\n"
        "make_stepper(cfg, *load_geometry(cfg))\n"
        "bad = [m for m in ('preform.interaction.model', 'preform.interaction.relax', "
        "'preform.interaction.frontal') if m in sys.modules]\n"
        "print(bad)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PREFORM_CACHE": "0"}, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_no_test_module_imports_another():
    """Test modules share code through ``tests/support`` only: no ``import`` of a ``test_*``
    module anywhere under ``tests/`` (read with ``ast``, imports inside functions included), and
    every test module is in a folder of its kind."""
    tests = SRC.parent / "tests"
    found = []
    for path in sorted(tests.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{path.relative_to(tests)}: {n}" for n in names if n.split(".")[-1].startswith("test_")]
    assert found == []
    astray = [str(p.relative_to(tests)) for p in sorted(tests.rglob("test_*.py"))
              if p.parent.name not in ("unit", "validation", "e2e")]
    assert astray == [], "test modules outside tests/unit, tests/validation, tests/e2e"
