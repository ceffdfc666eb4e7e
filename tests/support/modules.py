"""The package's source tree as the import tests read it: its root and its modules by name."""

from __future__ import annotations

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
