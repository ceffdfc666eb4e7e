"""Parameter sweeps on Dask (docs/guide/studies.md).

A sweep file names a base config and the values to vary, as a full grid and/or a list of points::

    base = "case_a.toml"                      # relative to this file
    [set]                                     # the same for every point (not varied)
    "model.kind" = "interaction"
    [grid]                                    # every combination, in the order written
    "yarn.friction" = [0.0, 0.25, 0.5]
    "process.initial_position" = [0.2, 0.4]
    [[points]]                                # and/or explicit points
    "yarn.friction" = 0.1
    [output]
    dir = "results/case_a_sweep"              # relative to this file

Every point is an ordinary run (:func:`preform.pipeline.run_case`, the same path as
``preform run``) with its own results folder under the sweep's, executed on a Dask cluster: a
``distributed.LocalCluster`` on the local machine by default (one single-threaded worker process per
run, since each run is numba-bound), or an existing scheduler (``scheduler="tcp://host:port"``;
``dask-jobqueue`` starts one on SLURM or PBS). A failed point does not stop the sweep: its error
is recorded. A finished point (complete ``summary.json`` with status done, and the same inputs
hash in its ``point.json``) is skipped on ``resume``. Results: ``sweep.csv`` (one row per point)
and, per varied key, ``plots/<key>.png``: convergence length and braid angle against braided
length, one curve per point (the paper's Fig. 14 and 16).
"""

from __future__ import annotations

import copy
import csv
import io
import itertools
import json
import math
import os
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import tomli_w

from ..checkpoint import inputs_sha256
from ..config import config_from_dict
from ..errors import ConfigError, PreformError
from ..io.atomic import atomic_write_text, safe_folder
from ..io.report import report_hook

SWEEP_CSV = "sweep.csv"
POINT_JSON = "point.json"
#: columns of sweep.csv after the varied keys
COLUMNS = ("status", "verdict", "braid_angle_final_deg", "braid_angle_steady_deg",
           "convergence_length_final_m", "wall_time_s", "results", "message")
SWEEP_KEYS = ("base", "set", "grid", "points", "output")


@dataclass(frozen=True)
class ClusterSettings:
    """How a sweep reaches its cluster."""

    #: seconds to wait for an existing scheduler to answer: a scheduler on a busy login node may
    #: take a few seconds; past this the address is wrong or the scheduler is down
    connect_timeout_s: float = 10.0


CLUSTER = ClusterSettings()


@dataclass(frozen=True)
class Point:
    """index: position in the sweep; values: dotted key -> value; name: its folder's name."""

    index: int
    values: dict
    name: str


@dataclass
class SweepSpec:
    """A parsed sweep file: the base config's TOML data, the points and the results folder."""

    source: Path
    base: Path
    base_data: dict
    keys: list
    points: list
    out_dir: Path
    configs: dict = field(default_factory=dict)   # point index -> validated Config
    data: dict = field(default_factory=dict)      # point index -> its config's TOML data


# ------------------------------------------------------------------------------ the sweep file

def _read_toml(path: Path, what: str) -> dict:
    if path.is_dir():
        raise ConfigError(f"{what} {path} is a folder: give the path of a .toml file")
    if not path.is_file():
        raise ConfigError(f"{what} {path} not found")
    try:
        return tomllib.loads(path.read_bytes().decode("utf-8-sig"))
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text; save it as UTF-8") from None


def _set(data: dict, dotted: str, value, where: str) -> None:
    """data[a][b]... = value for ``dotted`` = "a.b...", creating tables on the way; a number
    after an array of tables picks one of them, counted from 1 as ``preform`` names the layers:
    "layer.2.machine.angular_speed" is ``angular_speed`` in ``[layer.machine]`` of the second
    ``[[layer]]``."""
    parts = dotted.split(".")
    if len(parts) < 2 or not all(parts):
        raise ConfigError(f'{where}: key "{dotted}": expected "section.key" (e.g. "yarn.friction"'
                          ', or "layer.2.machine.angular_speed" for the second [[layer]])')
    table = data
    rest = parts[:-1]
    i = 0
    while i < len(rest):
        part = rest[i]
        below = table.get(part)
        if isinstance(below, list):
            if i + 1 == len(parts) - 1 or not parts[i + 1].isdigit():
                raise ConfigError(f'{where}: key "{dotted}": [[{part}]] is a list of {len(below)} '
                                  f'tables: name one by its number, e.g. "{part}.1.'
                                  f'{".".join(parts[i + 1:]) or "section.key"}"')
            k = int(parts[i + 1])
            if not 1 <= k <= len(below) or not isinstance(below[k - 1], dict):
                raise ConfigError(f'{where}: key "{dotted}": the base config has {len(below)} '
                                  f'[[{part}]] table(s); expected a number from 1 to {len(below)}')
            table = below[k - 1]
            i += 2
            continue
        table = table.setdefault(part, {})
        if not isinstance(table, dict):
            raise ConfigError(f'{where}: key "{dotted}": "{part}" is a value, not a table')
        i += 1
    if isinstance(table.get(parts[-1]), list) and table[parts[-1]] and \
            all(isinstance(t, dict) for t in table[parts[-1]]):
        raise ConfigError(f'{where}: key "{dotted}": [[{parts[-1]}]] is a list of tables; set a '
                          f'key inside one of them, e.g. "{dotted}.1.machine.angular_speed"')
    table[parts[-1]] = value


def _folder_name(index: int, values: dict) -> str:
    parts = [f"{_short(k)}={_text(v)}" for k, v in values.items()]
    name = f"{index:03d}" + ("_" + "_".join(parts) if parts else "")
    return "".join(c if c.isalnum() or c in "=._-" else "-" for c in name)[:120]


def _short(dotted: str) -> str:
    """The folder-name part of a key: its last name, after the layer it addresses if any
    ("layer.2.machine.angular_speed" -> "layer2-angular_speed")."""
    parts = dotted.split(".")
    where = [f"{a}{b}" for a, b in zip(parts, parts[1:]) if b.isdigit()]
    return "-".join(where + [parts[-1]])


def _text(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def load_sweep(path) -> SweepSpec:
    """Read and check a sweep file; every point's config is validated here, before any run."""
    path = Path(path).expanduser().resolve()
    data = _read_toml(path, "sweep file")
    unknown = sorted(set(data) - set(SWEEP_KEYS))
    if unknown:
        raise ConfigError(f"{path}: unknown key(s) {', '.join(unknown)}: a sweep file has "
                          f"{', '.join(SWEEP_KEYS)}")
    if not isinstance(data.get("base"), str):
        raise ConfigError(f'{path}: base = {data.get("base")!r}: expected the path of the base '
                          'config, relative to the sweep file (e.g. base = "case_a.toml")')
    base = (path.parent / data["base"]).resolve()
    base_data = _read_toml(base, "base config")
    fixed = data.get("set", {})
    if not isinstance(fixed, dict):
        raise ConfigError(f'{path}: [set] must be a table of "section.key" = value')
    for key, value in fixed.items():
        _set(base_data, key, value, f"{path}: [set]")
    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise ConfigError(f"{path}: [grid] must be a table of \"section.key\" = [values]")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(f'{path}: [grid] "{key}" = {values!r}: expected a non-empty list of values')
    listed = data.get("points", [])
    if not isinstance(listed, list) or not all(isinstance(p, dict) for p in listed):
        raise ConfigError(f'{path}: points must be [[points]] tables of "section.key" = value')
    combos = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())] if grid else []
    combos += [dict(p) for p in listed]
    if not combos:
        raise ConfigError(f"{path}: no points: give a [grid] or [[points]]")
    out = data.get("output", {})
    out_dir = (path.parent / out.get("dir", f"results/{path.stem}")).resolve()
    return spec_of_points(path, base, base_data, combos, out_dir)


def spec_of_points(source: Path, base: Path, base_data: dict, combos: list, out_dir: Path) -> SweepSpec:
    """The sweep of the points ``combos`` (dotted key -> value each) over the base config's TOML
    data ``base_data`` (from the file ``base``), results under ``out_dir``; every point's config
    is validated here, before any run (errors name ``source``)."""
    keys = list(dict.fromkeys(k for c in combos for k in c))
    path = source
    spec = SweepSpec(source=path, base=base, base_data=base_data, keys=keys, points=[], out_dir=out_dir)
    for i, values in enumerate(combos):
        point = Point(index=i, values=values, name=_folder_name(i, values))
        point_data = point_config_data(spec, point)
        spec.data[i] = point_data
        try:
            spec.configs[i] = config_from_dict(point_data, base_dir=base.parent, name=base.stem,
                                               source=base)
        except ConfigError as err:
            raise ConfigError(f"{path}: point {i} ({_describe(values)}): {err}") from None
        spec.points.append(point)
    return spec


def _describe(values: dict) -> str:
    return ", ".join(f"{k} = {_text(v)}" for k, v in values.items())


def point_config_data(spec: SweepSpec, point: Point) -> dict:
    """The base config's TOML data with the point's values and its own results folder."""
    data = copy.deepcopy(spec.base_data)
    for key, value in point.values.items():
        _set(data, key, value, f"{spec.source}: point {point.index}")
    mandrel = data.get("mandrel", {})
    for key in ("stl", "centerline"):   # absolute, so the point's config.toml runs from anywhere
        if isinstance(mandrel.get(key), str) and mandrel[key] != "auto":
            mandrel[key] = str((spec.base.parent / mandrel[key]).resolve())
    data.setdefault("output", {})["dir"] = str(spec.out_dir / point.name)
    return data


def inputs_hash(config) -> str:
    """The checkpoint's inputs hash: the config (less [output]) and the contents of its STL and
    centerline (``preform.checkpoint.input_record``)."""
    return inputs_sha256(config)


# ------------------------------------------------------------------------------ one point

def run_point(config, out_dir: str, index: int, values: dict, digest: str) -> dict:
    """Run one point in a worker; return its sweep.csv row. Never raises for a failed run."""
    from ..pipeline import run_case   # here: the workers simulate, the scheduling process does not

    row = {"point": index, **values, "results": str(out_dir)}
    t0 = time.perf_counter()
    try:
        outcome = run_case(config, out_dir)
    except PreformError as err:
        return {**row, "status": "failed", "message": str(err), "wall_time_s": time.perf_counter() - t0}
    except Exception as err:  # noqa: BLE001 - a sweep records every failure and goes on
        return {**row, "status": "failed", "message": f"{type(err).__name__}: {err}",
                "wall_time_s": time.perf_counter() - t0}
    _write_point_json(Path(out_dir), index, values, digest, outcome.status)
    return {**row, **row_from_summary(Path(out_dir))}


def _write_point_json(out_dir: Path, index, values, digest, status) -> None:
    atomic_write_text(out_dir / POINT_JSON, json.dumps(
        {"point": index, "values": values, "inputs_hash": digest, "status": status}, indent=2) + "\n")


def row_from_summary(out_dir: Path) -> dict:
    """The sweep.csv values of a finished point, read from its summary.json."""
    s = json.loads((out_dir / "summary.json").read_text(encoding="utf-8"))
    final = s["braid_angle_deg"]["final"]
    steady = s["braid_angle_deg"].get("steady")
    mean = lambda d: None if not d or d.get("warp") is None else 0.5 * (d["warp"] + d["weft"])  # noqa: E731
    return {"status": s["status"], "verdict": (s.get("quality") or {}).get("verdict"),
            "braid_angle_final_deg": mean(final), "braid_angle_steady_deg": mean(steady),
            "convergence_length_final_m": s["convergence_length_m"]["final"]["mean"],
            "wall_time_s": s["wall_time_s"], "message": s.get("message", "")}


def finished(spec: SweepSpec, point: Point) -> dict | None:
    """The row of a point finished with these inputs (for resume), else None."""
    out_dir = spec.out_dir / point.name
    try:
        meta = json.loads((out_dir / POINT_JSON).read_text(encoding="utf-8"))
        row = row_from_summary(out_dir)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if meta.get("inputs_hash") != inputs_hash(spec.configs[point.index]) or row["status"] != "done":
        return None
    return {"point": point.index, **point.values, "results": str(out_dir), **row}


# ------------------------------------------------------------------------------ the cluster

def open_client(scheduler=None, workers=None, settings: ClusterSettings = CLUSTER):
    """(client, local cluster or None) as a sweep makes them; the caller closes both."""
    return _client(scheduler, workers, settings)


def _client(scheduler, workers, settings: ClusterSettings):
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=f"{settings.connect_timeout_s}s"), None
        except (OSError, TimeoutError) as err:
            raise PreformError(f"--scheduler {scheduler}: no Dask scheduler answers there ({err}); "
                               "start one (dask scheduler) or leave --scheduler out to use this "
                               "machine") from None

    n = workers or max(1, (os.cpu_count() or 1))
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)
    return Client(cluster), cluster


def _report(progress, done, running, failed, total, label="sweep"):
    if progress:
        print(f"{label}: {done}/{total} done, {running} running, {failed} failed", file=sys.stderr, flush=True)


def sweep(path, *, scheduler=None, workers=None, resume=False, progress=True,
          cluster: ClusterSettings = CLUSTER) -> list[dict]:
    """Run a sweep file (see module docstring); return the rows of ``sweep.csv``."""
    spec = load_sweep(path)
    ordered = run_spec(spec, scheduler=scheduler, workers=workers, resume=resume,
                       progress=progress, cluster=cluster)
    write_sweep_csv(spec, ordered)
    plot_sweep(spec, ordered)
    report_hook(spec.out_dir, sweep=True)   # report.html of the sweep's folder
    return ordered


def run_spec(spec: SweepSpec, *, scheduler=None, workers=None, resume=False, progress=True,
             cluster: ClusterSettings = CLUSTER, label: str = "sweep", client=None) -> list[dict]:
    """Run the points of ``spec`` on Dask (with ``resume``, only those not finished with the same
    inputs); return their rows in the points' order. ``label`` starts the progress lines;
    ``client``: a ``distributed.Client`` to use (and leave open), else one is made for the run
    (:func:`open_client`) and closed after it."""
    safe_folder(spec.out_dir)
    rows, todo = {}, []
    for point in spec.points:   # each point runnable on its own: preform run <point>/config.toml
        atomic_write_text(safe_folder(spec.out_dir, point.name) / "config.toml",
                          tomli_w.dumps(spec.data[point.index]))
    for point in spec.points:
        row = finished(spec, point) if resume else None
        if row is not None:
            rows[point.index] = row
        else:
            todo.append(point)
    failed = 0
    total = len(spec.points)
    if todo:
        from distributed import as_completed

        own = client is None
        client, local = _client(scheduler, workers, cluster) if own else (client, None)
        try:
            futures = {client.submit(run_point, spec.configs[p.index], str(spec.out_dir / p.name),
                                     p.index, p.values, inputs_hash(spec.configs[p.index]),
                                     pure=False, key=f"preform-point-{p.index}-{time.time_ns()}"): p
                       for p in todo}
            _report(progress, len(rows), len(futures), 0, total, label)
            for future in as_completed(futures):
                point = futures[future]
                try:
                    row = future.result()
                except Exception as err:  # noqa: BLE001 - a worker died: record it, go on
                    row = {"point": point.index, **point.values, "status": "failed",
                           "results": str(spec.out_dir / point.name),
                           "message": f"worker lost: {type(err).__name__}: {err}"}
                rows[point.index] = row
                failed += row.get("status") != "done"
                _report(progress, len(rows) - failed, total - len(rows), failed, total, label)
        finally:
            if own:
                client.close()
                if local is not None:
                    local.close()
    return [rows[p.index] for p in spec.points]


def write_sweep_csv(spec: SweepSpec, rows) -> Path:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["point", *spec.keys, *COLUMNS])
    for row in rows:
        writer.writerow([row.get("point"), *(row.get(k, "") for k in spec.keys),
                         *(_cell(row.get(c)) for c in COLUMNS)])
    return atomic_write_text(spec.out_dir / SWEEP_CSV, buf.getvalue())


def _cell(value):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return repr(value) if isinstance(value, float) else value


def read_sweep_csv(path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


# ------------------------------------------------------------------------------ plots

def plot_sweep(spec: SweepSpec, rows) -> list[Path]:
    """Per varied key, ``plots/<key>.png``: H and braid angle against L, one curve per point."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..io.atomic import atomic_path, safe_folder
    from ..io.plots import start_rows

    histories = {}
    for row in rows:
        try:
            table = np.genfromtxt(Path(row["results"]) / "history.csv", delimiter=",", names=True)
        except (OSError, ValueError):
            continue
        if table.size > 1:
            histories[row["point"]] = table
    if not histories:
        return []
    plots = safe_folder(spec.out_dir, "plots")
    written = []
    styles = ("-", "--", ":", "-.")
    for key in spec.keys:
        fig = Figure(figsize=(7.2, 7.0), layout="constrained")
        ax_h, ax_a = fig.subplots(2, 1, sharex=True)
        points = [p for p in spec.points if p.index in histories]
        values = list(dict.fromkeys(_text(p.values.get(key, "base")) for p in points))
        others = list(dict.fromkeys(_describe({k: v for k, v in p.values.items() if k != key})
                                    for p in points))
        cmap = __import__("matplotlib").colormaps["viridis"]
        ranges = {ax_h: [], ax_a: []}
        for p in points:
            h = histories[p.index]
            value = _text(p.values.get(key, "base"))
            rest = _describe({k: v for k, v in p.values.items() if k != key})
            colour = cmap(values.index(value) / max(len(values) - 1, 1))
            style = styles[others.index(rest) % len(styles)]
            label = f"{key.split('.')[-1]} = {value}" + (f" ({rest})" if rest else "")
            L = h["braided_length_m"]
            alpha = 0.5 * (h["braid_angle_warp_deg"] + h["braid_angle_weft_deg"])
            skip = start_rows(L)
            for ax, y in ((ax_h, h["convergence_length_mean_m"]), (ax_a, alpha)):
                ax.plot(L, y, color=colour, linestyle=style, label=label)
                ranges[ax].append(y[skip:])
        for ax, ys in ranges.items():   # leave out the wind-up spike of every run
            y = np.concatenate(ys) if ys else np.zeros(0)
            y = y[np.isfinite(y)]
            if len(y):
                pad = max(0.08 * float(np.ptp(y)), 1e-6)
                ax.set_ylim(float(y.min()) - pad, float(y.max()) + pad)
        ax_h.set_ylabel("convergence length H (m)")
        ax_a.set_ylabel("braid angle α (deg)")
        ax_a.set_xlabel("braided length L (m)")
        for ax in (ax_h, ax_a):
            ax.grid(True, alpha=0.3)
        ax_h.legend(fontsize=8)
        ax_h.set_title(f"{spec.source.stem}: {key} (colour){'; other values: line style' if len(others) > 1 else ''}")
        FigureCanvasAgg(fig)
        path = plots / f"{key.replace('.', '_')}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=130)
        written.append(path)
    return written
