"""Reading CalculiX results back: the ``*NODE PRINT`` tables of a ``.dat`` file.

A ``.dat`` table starts with a title line such as ``displacements (vx,vy,vz) for set TIP and time
0.1000000E+01`` followed by one line per node: the node's number and its values. For composite
shells ``ccx`` prints the values of the shell's own nodes (the ``.frd`` file holds the 3-D
expanded elements instead, which ParaView shows through ``ccx2paraview``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_TITLE = re.compile(r"^\s*(?P<what>[a-z][a-z ]*?)\s*\((?P<columns>[^)]*)\)\s+for set\s+(?P<set>\S+)"
                    r"\s+and time\s+(?P<time>\S+)")


@dataclass(frozen=True)
class NodeTable:
    """One ``*NODE PRINT`` table: ``what`` (e.g. "displacements"), the node set, the step time,
    ``nodes`` (n,) int (the deck's numbers) and ``values`` (n, k)."""

    what: str
    set: str
    time: float
    nodes: np.ndarray
    values: np.ndarray


def read_dat(path) -> list[NodeTable]:
    """Every node table of a CalculiX ``.dat`` file, in file order."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: cannot be read as a CalculiX .dat file ({err})") from None
    tables, i = [], 0
    while i < len(lines):
        title = _TITLE.match(lines[i])
        i += 1
        if not title:
            continue
        rows = []
        while i < len(lines) and not lines[i].strip():
            i += 1
        while i < len(lines) and lines[i].strip():
            parts = lines[i].split()
            try:
                rows.append([float(v) for v in parts])
            except ValueError:
                break
            i += 1
        data = np.array(rows, dtype=float).reshape(len(rows), -1)
        tables.append(NodeTable(what=title["what"], set=title["set"], time=float(title["time"]),
                                nodes=data[:, 0].astype(np.int64), values=data[:, 1:]))
    return tables


def displacements(path, node_set: str) -> tuple[np.ndarray, np.ndarray]:
    """(nodes (n,), u (n, 3) m) of the last displacement table printed for ``node_set``."""
    found = [t for t in read_dat(path) if t.what.startswith("displacements") and t.set == node_set.upper()]
    if not found:
        raise ValueError(f"{path}: no displacements printed for node set {node_set} (add "
                         f"*NODE PRINT, NSET={node_set} / U to the step)")
    return found[-1].nodes, found[-1].values


def read_mesh(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(node numbers (n,), coordinates (n, 3) m, elements (ne, 6) node numbers) of a deck written
    by :func:`preform.io.fe_files.write_deck` (its ``*NODE`` and ``*ELEMENT`` blocks)."""
    lines = Path(path).read_text().splitlines()
    blocks = {"*NODE": [], "*ELEMENT": []}
    current = None
    for line in lines:
        if line.startswith("**"):
            continue
        if line.startswith("*"):
            card = line.split(",")[0].strip().upper()
            current = blocks.get(card)
            continue
        if current is not None and line.strip():
            current.append([float(v) for v in line.split(",")])
    nodes, elements = np.array(blocks["*NODE"]), np.array(blocks["*ELEMENT"])
    if len(nodes) == 0 or len(elements) == 0:
        raise ValueError(f"{path}: no *NODE or *ELEMENT block")
    return nodes[:, 0].astype(np.int64), nodes[:, 1:4], elements[:, 1:7].astype(np.int64)


def template_step(deck_text: str) -> str:
    """The deck's commented axial tension step, uncommented (the lines after its ``** ----``
    line), to append to the deck for a first analysis."""
    lines = deck_text.splitlines()
    start = next((k for k, line in enumerate(lines) if line == "** ----"), None)
    if start is None:
        raise ValueError("the deck has no template step (not written by preform?)")
    return "".join(line[3:] + "\n" for line in lines[start + 1:] if line.startswith("** "))
