"""Imports only go down the layers of docs/architecture.md §3.

Every module of ``src/preform`` belongs to one layer (:data:`LAYERS`, lowest first, the table of
docs/architecture.md §3); a module may import from its own layer and the ones below, never from
one above. The imports are read from the source with ``ast``, at module level and inside
functions alike: an import inside a function runs later, but the module depends on the other all
the same. A failure names the file, the line, the module imported and the two layers.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from support.modules import SRC, imports_in, module_names

#: the layers, lowest first: (name, the modules and packages in it). A module belongs to the layer
#: of the longest entry that is it or a package holding it; ``preform`` stands for the package's
#: ``__init__`` alone.
LAYERS = (
    ("base", ("preform.errors", "preform.plain", "preform.tolerances", "preform.analytic",
              "preform.result", "preform.zone", "preform._version", "preform.materials",
              "preform.drawing")),
    ("kernels", ("preform._kernels",)),
    ("geometry", ("preform.geometry",)),
    ("inputs", ("preform.config", "preform.machine")),
    ("models", ("preform.kinematic", "preform.interaction", "preform.laid", "preform.reference",
                "preform.recording", "preform.stepping", "preform.checkpoint", "preform.simulation")),
    ("analysis", ("preform.analysis", "preform.checks", "preform.budget", "preform.structural.layup",
                  "preform.structural.micromechanics", "preform.settings")),
    ("io", ("preform.io", "preform.structural")),
    ("pipeline", ("preform.pipeline",)),
    ("studies", ("preform.studies",)),
    ("front", ("preform.cli", "preform._jit", "preform")),
)


def layer_of(module: str, layers=LAYERS) -> tuple[int, str] | None:
    """(rank, name) of the layer that ``module`` belongs to, or None when no entry holds it."""
    best = None
    for rank, (name, entries) in enumerate(layers):
        for entry in entries:
            inside = module == entry or ("." in entry and module.startswith(entry + "."))
            if inside and (best is None or len(entry) > best[0]):
                best = (len(entry), rank, name)
    return None if best is None else best[1:]


def climbs(src: Path, layers=LAYERS) -> list[str]:
    """One sentence per import of a higher layer, and per module that no layer holds."""
    modules = module_names(src)
    out = []
    for name, path in modules.items():
        here = layer_of(name, layers)
        where = path.relative_to(src.parent) if src.parent in path.parents else path
        if here is None:
            out.append(f"{where}: module {name} is in no layer; add it to LAYERS here and to the "
                       "table of docs/architecture.md §3")
            continue
        for line, target in imports_in(name, path, modules):
            there = layer_of(target, layers)
            if there is not None and there[0] > here[0]:
                out.append(f"{where}:{line}: {name} (layer {here[1]}) imports {target} "
                           f"(layer {there[1]}, above it)")
    return out


def test_the_reader_finds_a_climb_inside_a_function_and_a_module_without_layer(tmp_path):
    """A made-up package: a relative import inside a function of a low layer, of a module of a
    higher one, is reported with its file, line and the two layers; a module no layer holds is
    reported; imports down the layers are not."""
    pkg = tmp_path / "preform"
    (pkg / "low").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "high.py").write_text("from .low import deep\n")
    (pkg / "low" / "__init__.py").write_text("")
    (pkg / "low" / "deep.py").write_text("import math\n\n\ndef f():\n    from .. import high\n")
    (pkg / "stray.py").write_text("")
    layers = (("low", ("preform.low",)), ("high", ("preform.high", "preform")))
    found = climbs(tmp_path, layers)
    assert len(found) == 2, found
    assert "preform/low/deep.py:5: preform.low.deep (layer low) imports preform.high (layer high" in found[0]
    assert "preform/stray.py: module preform.stray is in no layer" in found[1]
    layers = (("low", ("preform.low", "preform.stray")), ("high", ("preform.high", "preform")))
    assert len(climbs(tmp_path, layers)) == 1


def test_layer_of_takes_the_longest_entry():
    assert layer_of("preform.structural.layup") == (5, "analysis")
    assert layer_of("preform.structural.results") == (6, "io")
    assert layer_of("preform.analysis.fields") == (5, "analysis")
    assert layer_of("preform") == (9, "front")
    assert layer_of("preform.stray") is None
    assert layer_of("numpy") is None


def test_imports_only_go_down_the_layers():
    found = climbs(SRC)
    assert not found, "imports that climb the layers (docs/architecture.md §3):\n" + "\n".join(found)


def package_cycles(src: Path) -> list[str]:
    """Import cycles that run through a package's ``__init__``: importing ``package.x`` from
    outside ``package`` runs ``package/__init__.py`` first, so a module that imports ``package.x``
    depends on everything that ``__init__`` imports at module level. One sentence per module
    that such an ``__init__`` imports and that imports back into the package."""
    modules = module_names(src)
    out = []
    for package, path in modules.items():
        if path.name != "__init__.py" or package == "preform":
            continue
        top = [node for node in ast.parse(path.read_text(encoding="utf-8")).body
               if isinstance(node, (ast.Import, ast.ImportFrom))]
        imported = {target for line, target in imports_in(package, path, modules)
                    if any(node.lineno == line for node in top)}
        for name in sorted(imported):
            if name.startswith(package + "."):
                continue
            for line, target in imports_in(name, modules[name], modules):
                if target.startswith(package + "."):
                    out.append(f"{modules[name].relative_to(src.parent)}:{line}: {name} imports "
                               f"{target}, whose package __init__ imports {name} at module level")
    return out


def test_no_cycle_through_a_package_init():
    """A module imported by a package's ``__init__`` must not import from that package: imported
    first, in a fresh interpreter, it would meet the package half made (an ImportError)."""
    found = package_cycles(SRC)
    assert not found, "cycles through a package __init__:\n" + "\n".join(found)


def test_the_architecture_page_lists_the_layers_in_order():
    """docs/architecture.md §3's table has one row per layer, in this order, naming its modules."""
    text = (SRC.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## §3", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines()
            if line.startswith("| ") and not line.startswith(("| layer", "| ---"))]
    names = [row.split("|")[1].strip() for row in rows]
    assert names == [name for name, _ in LAYERS]
    for row, (name, entries) in zip(rows, LAYERS):
        for entry in entries:
            short = entry.removeprefix("preform.") if entry != "preform" else "__init__"
            assert f"`{short}" in row, (name, entry)


@pytest.mark.parametrize("module", ["preform.io.atomic", "preform.analysis.fields", "preform.materials"])
def test_the_named_modules_exist(module):
    """The modules the layers were fixed around are where the table says (a rename would leave
    the table naming nothing)."""
    assert module in module_names(SRC)
