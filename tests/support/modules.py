"""The package's source tree as the import tests read it: its root and its modules by name."""

from __future__ import annotations

import ast
from pathlib import Path

#: the ``src`` folder holding the ``preform`` package
SRC = Path(__file__).resolve().parents[2] / "src"


def module_names(src: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every module of the ``preform`` package under ``src``."""
    out = {}
    for path in sorted((src / "preform").rglob("*.py")):
        parts = list(path.relative_to(src).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def imports_in(name: str, path: Path, modules) -> list[tuple[int, str]]:
    """(line, module) of every import of one of ``modules`` in module ``name`` (file ``path``),
    anywhere in it; ``from package import name`` imports the submodule ``package.name`` when
    there is one, else the package."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []

    def add(line, target):
        while target and target not in modules:   # the deepest of our modules that it names
            target = target.rpartition(".")[0]
        if target and target != name:
            found.append((line, target))

    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(node.lineno, alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                add(node.lineno, sub if sub in modules else source)
    return sorted(set(found))
