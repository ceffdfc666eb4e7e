"""``summary.json`` and ``history.csv`` (docs/guide/results.md, result files).

``history.csv`` has exactly :data:`preform.result.HISTORY_COLUMNS` as header, one row per step,
floats written with :func:`repr` (shortest text that reads back to the same float64). Non-finite
values are refused: a NaN in a result file would look like data.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from ..errors import SimulationError
from ..result import FLAG_NAMES, HISTORY_COLUMNS
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


# ---------------------------------------------------------------- summary.json

def _jsonable(value):
    """Plain JSON types: Paths -> str, tuples -> lists, numpy -> Python, non-finite -> None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)


def echo_inputs(config):
    """The config as JSON-able data: ``preform.config.dump_config`` when it exists, else the
    dataclass fields (SI units, angular speed in rad/s) as a best effort."""
    if config is None:
        return None
    try:
        from ..config import dump_config
    except ImportError:
        dump_config = None
    if dump_config is not None:
        return _jsonable(dump_config(config))
    return _jsonable(config)


def _final(result, name):
    column = np.asarray(result.history.get(name, ()), dtype=np.float64)
    return float(column[-1]) if len(column) else None


def _steady_state(result, settings):
    from ..steady import steady_state

    if not result.steps:
        return None
    return steady_state(result.history, settings)


def _quality(result, settings, fields_reasons=(), interlacing=False):
    from ..quality import assess, verdict

    q = assess(result, settings, interlacing=interlacing)
    return verdict([*q["reasons"], *fields_reasons])


def flag_counts(yarns) -> dict:
    """Number of deposited points carrying each flag: {"bridge": n, "catch": n, "slip": n}."""
    flags = np.asarray(yarns.flags, dtype=np.int64)
    return {name: int(np.count_nonzero(flags & bit)) for bit, name in FLAG_NAMES.items()}


def _snapshot_checks(result, settings):
    """The written snapshots against the re-balance that checks each (the written state is the
    run's own): the largest distance of a crossing from its re-balanced place (m), the tolerance
    the verdict holds it to (``QualitySettings.max_snapshot_shift_widths`` yarn widths), the
    times of the snapshots beyond it and of those whose re-balance failed; None where no
    snapshot was checked; ``settings``: the verdict's (``quality.QualitySettings``)."""
    shifts = [s.rebalance_shift_m for s in result.snapshots if np.isfinite(s.rebalance_shift_m)]
    failed = [s.time_s for s in result.snapshots if s.rebalance_error]
    if not shifts and not failed:
        return None
    tolerance = (settings.max_snapshot_shift_widths * float(result.config.yarn.width)
                 if result.config is not None else None)
    beyond = [s.time_s for s in result.snapshots if tolerance is not None
              and np.isfinite(s.rebalance_shift_m) and s.rebalance_shift_m > tolerance]
    return {"rebalance_shift_max_m": max(shifts) if shifts else None,
            "rebalance_shift_tolerance_m": tolerance, "beyond_tolerance_at_s": beyond,
            "rebalance_failed_at_s": failed}


def _interlacing(il):
    """Warp-weft crossings of the laid yarns against the pattern's (``preform.interlacing``;
    ``il``: ``quality.run_interlacing``'s)."""
    if il is None:
        return None
    return {"band_m": [il.s_start, il.s_end], "crossings": il.measured,
            "pattern_crossings": il.pattern, "ratio": il.ratio,
            "per_m2": il.measured_per_m2, "pattern_per_m2": il.pattern_per_m2}


def summary_dict(result, extra=None, settings=None) -> dict:
    """Everything summary.json holds, as JSON-able data (non-finite numbers become null);
    ``settings``: the run's ``preform.Settings`` (None: the defaults), whose ``steady``,
    ``interlacing`` and ``quality`` read the run."""
    from .._version import __version__
    from ..settings import resolved

    settings = resolved(settings)
    config = result.config
    model = config.model.kind if config is not None else None
    extra = dict(extra or {})
    steady = _steady_state(result, settings.steady) or {}
    from ..quality import run_interlacing

    interlaced = run_interlacing(result, settings.interlacing)
    summary = {
        "preform_version": __version__,
        "model": model,
        "status": result.status,
        "message": result.message,
        "steps": int(result.steps),
        "wall_time_s": float(result.wall_time_s),
        "braided_length_m": _final(result, "braided_length_m"),
        "braid_angle_deg": {
            "final": {"warp": _final(result, "braid_angle_warp_deg"),
                      "weft": _final(result, "braid_angle_weft_deg")},
            # only where the run reached it (steady_state says how far from it the run ended)
            "steady": steady["braid_angle_deg"] if steady.get("reached") else None,
        },
        "convergence_length_m": {
            "final": {"mean": _final(result, "convergence_length_mean_m"),
                      "min": _final(result, "convergence_length_min_m"),
                      "max": _final(result, "convergence_length_max_m")},
            "steady": steady["convergence_length_m"] if steady.get("reached") else None,
        },
        "steady_state": steady or None,
        "quality": _quality(result, settings.quality, (extra or {}).pop("quality_reasons", ()),
                            interlaced),
        "mandrel_repairs": list(result.mandrel.repairs) if result.mandrel is not None else [],
        "yarns": {"count": int(result.yarns.n_yarns), "points": int(len(result.yarns.points)),
                  "flags": flag_counts(result.yarns)},
        "snapshots": len(result.snapshots),
        "snapshot_checks": _snapshot_checks(result, settings.quality),
        "interlacing": _interlacing(interlaced),
        "inputs": echo_inputs(config),
    }
    if extra:
        summary.update(extra)
    return _jsonable(summary)


def write_summary(result, path, extra=None, settings=None) -> Path:
    """Write ``summary.json`` atomically; ``extra`` (dict) is merged in at the top level
    (``write_results`` passes ``{"files": [...]}``); ``settings``: :func:`summary_dict`'s."""
    text = json.dumps(summary_dict(result, extra, settings), indent=2, allow_nan=False)
    return atomic_write_text(path, text + "\n")
