"""``summary.json`` and ``history.csv`` (docs/guide/results.md, result files).

The summary's figures are computed by ``preform.analysis.derived``; this module writes them.

``history.csv`` has exactly :data:`preform.result.HISTORY_COLUMNS` as header, one row per step,
floats written with :func:`repr` (shortest text that reads back to the same float64). Non-finite
values are refused: a NaN in a result file would look like data.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import SimulationError
from ..plain import jsonable
from ..result import HISTORY_COLUMNS
from ..trajectory import COLUMNS as PROCESS_COLUMNS
from .atomic import atomic_write_text

#: history columns that count things; written as integers
INTEGER_COLUMNS = ("contacts", "iterations")


# ---------------------------------------------------------------- history.csv

def history_table(result) -> np.ndarray:
    """The history as a (n_steps, len(HISTORY_COLUMNS)) float64 array, columns in contract order.

    Raises SimulationError when a column is missing, has the wrong length, or holds NaN/inf
    (naming the column and the row).
    """
    history = result.history
    missing = [c for c in HISTORY_COLUMNS if c not in history]
    if missing:
        raise SimulationError(f"history: missing column(s) {', '.join(missing)}; "
                              f"expected all of {', '.join(HISTORY_COLUMNS)}")
    n = len(np.asarray(history["time_s"]))
    table = np.empty((n, len(HISTORY_COLUMNS)), dtype=np.float64)
    for j, name in enumerate(HISTORY_COLUMNS):
        column = np.asarray(history[name], dtype=np.float64).reshape(-1)
        if len(column) != n:
            raise SimulationError(f"history: column {name} has {len(column)} rows; "
                                  f"expected {n} like time_s")
        bad = np.flatnonzero(~np.isfinite(column))
        if len(bad):
            raise SimulationError(f"history: column {name}, row {bad[0]} (step {bad[0]}) is "
                                  f"{column[bad[0]]!r}; expected a finite number "
                                  f"({len(bad)} non-finite value(s) in that column)")
        table[:, j] = column
    return table


def _cell(name: str, value: float) -> str:
    if name in INTEGER_COLUMNS and float(value).is_integer():
        return str(int(value))
    return repr(float(value))


def format_history(result) -> str:
    """history.csv text: header line, then one line per step."""
    table = history_table(result)
    lines = [",".join(HISTORY_COLUMNS)]
    lines += [",".join(_cell(c, v) for c, v in zip(HISTORY_COLUMNS, row)) for row in table]
    return "\n".join(lines) + "\n"


def write_history(result, path) -> Path:
    """Write ``history.csv`` atomically; refuses non-finite values (SimulationError)."""
    return atomic_write_text(path, format_history(result))


# ---------------------------------------------------------------- process.csv

def process_table(result) -> np.ndarray:
    """process.csv as a (n_steps, len(PROCESS_COLUMNS)) float64 array: per history row the time,
    the braided length (the history's), the take-up and angular (deg/s) speeds of the step that
    ended there (row 0: of the first step) and the mandrel's pose in the machine frame (origin
    m, unit quaternion w, x, y, z: ``preform.trajectory``). SimulationError where the run kept
    no process rows or one is not finite."""
    process = result.process
    n = len(np.asarray(result.history["time_s"]))
    if process is None or process.shape != (n, len(PROCESS_COLUMNS) - 1):
        shape = None if process is None else process.shape
        raise SimulationError(f"process: {shape} process rows for {n} history rows; expected "
                              f"({n}, {len(PROCESS_COLUMNS) - 1})")
    table = np.empty((n, len(PROCESS_COLUMNS)))
    table[:, 0] = process[:, 0]
    table[:, 1] = np.asarray(result.history["braided_length_m"], dtype=float)
    table[:, 2] = process[:, 1]
    table[:, 3] = np.degrees(process[:, 2])
    table[:, 4:] = process[:, 3:]
    bad = np.argwhere(~np.isfinite(table))
    if len(bad):
        k, j = (int(i) for i in bad[0])
        raise SimulationError(f"process: column {PROCESS_COLUMNS[j]}, row {k} is {table[k, j]!r}; "
                              "expected a finite number")
    return table


def write_process(result, path) -> Path:
    """Write ``process.csv`` atomically (header :data:`PROCESS_COLUMNS`, floats as :func:`repr`:
    the shortest text that reads back to the same float64, so a run driven by the file,
    ``[process] trajectory``, starts from the poses to the last bit)."""
    lines = [",".join(PROCESS_COLUMNS)]
    lines += [",".join(repr(float(v)) for v in row) for row in process_table(result)]
    return atomic_write_text(path, "\n".join(lines) + "\n")


# ---------------------------------------------------------------- summary.json

def write_summary(summary: dict, path) -> Path:
    """Write ``summary.json`` atomically: the dict ``summary`` (``preform.analysis.derived``'s
    figures and what the writing adds), with numbers, arrays and paths as JSON types."""
    text = json.dumps(jsonable(summary), indent=2, allow_nan=False)
    return atomic_write_text(path, text + "\n")
