"""The everyday run, stage by stage: ``examples/case_a.toml`` (kinematic).

Two ways:

- ``--command`` (the figure of ``benchmarks/README.md``'s table): ``preform run`` as a user runs
  it, ``--repeat``
  times in fresh processes; prints each run's wall time (measured outside the process) and the
  stages of its summary (start, load and check, simulate, analyse, write, pictures), and the medians.
  ``--fresh`` makes every run a first run in a fresh environment: an empty numba cache
  (``NUMBA_CACHE_DIR``) and an empty preform cache (``PREFORM_CACHE_DIR``), so the kernels
  compile and the mandrel and the field mesh are built again. ``--jit`` adds each run's numba
  compile time per process (the command's own and the first-run worker's, ``preform._jit``;
  numba's compile events, not cache loads) with the worker's jobs, and at the
  end the table per kernel (medians).
- otherwise, through the Python API in this process: load and repair the STL (through the
  cache), centerline, checks, JIT (a 2 cm run that compiles or loads the numba cache), simulate,
  map (field mesh from the cache), analyse (``analysis.derived.analyse_run``), write the data
  files, pictures (as ``preform run`` does: the 3-D renders in a worker process started after
  the simulation, beside the map, the analysis, the data files and the matplotlib plots).

Run: ``python benchmarks/bench_pipeline.py [--command] [--fresh] [--repeat 5]
[--toml examples/case_a.toml] [--stl other.stl --unit mm]`` (``--stl`` swaps the mandrel, API
mode only, e.g. a generated sliver cylinder).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def config(toml, stl=None, unit="m"):
    import preform as pf

    cfg = pf.load_config(toml)
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="kinematic"))
    if stl is not None:
        cfg = dataclasses.replace(cfg, mandrel=dataclasses.replace(cfg.mandrel, stl=Path(stl),
                                                                   stl_unit=unit, centerline="auto"))
    return cfg


def run_once(cfg, out_dir):
    import preform as pf
    from preform import pipeline
    from preform.analysis.derived import analyse_run
    from preform.io import start_pictures
    from preform.io.cache import cached_field_mesh, cached_mandrel

    t = {}
    t0 = time.perf_counter()
    mc = cfg.mandrel
    mandrel = cached_mandrel(mc.stl, unit=mc.stl_unit, body=mc.body)
    t["load+repair"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    from preform import geometry

    if isinstance(mc.centerline, str) and mc.centerline == "auto":
        cl = geometry.auto_centerline(mandrel, roll_reference=mc.roll_reference)
    else:
        cl = geometry.read_centerline_csv(mc.centerline, unit=mc.stl_unit, roll_reference=mc.roll_reference)
    t["centerline"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    from preform.checks import preflight

    preflight(cfg, mandrel, cl)
    pipeline.reference_lines(cfg, mandrel, cl)
    pipeline.estimate(cfg, mandrel, cl)
    t["checks"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    short = dataclasses.replace(cfg, process=dataclasses.replace(cfg.process, braid_length=0.02))
    pf.simulate(short, progress=False, mandrel=mandrel, centerline=cl)
    t["jit (2 cm run)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=cl)
    t["simulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pictures = start_pictures(result, out_dir)   # as preform run: the 3-D renders beside the map
    fields = pf.map_to_surface(result, mesh=cached_field_mesh(result))
    t["map"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    analysed = analyse_run(result, fields)
    t["analyse"] = time.perf_counter() - t0
    pipeline.write(analysed, out_dir, stages={}, pictures=pictures)
    stages = json.loads((Path(out_dir) / "summary.json").read_text())["stages_s"]
    t["write"], t["pictures"] = stages["write"], stages["pictures"]
    return t, result, fields


def api(args):
    cfg = config(args.toml, args.stl, args.unit)
    rows = []
    for i in range(args.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            t, result, fields = run_once(cfg, tmp)
        rows.append(t)
        print(f"run {i}: " + ", ".join(f"{k} {v:.2f} s" for k, v in t.items())
              + f" | total {sum(t.values()):.2f} s; {result.steps} steps x {result.yarns.n_yarns} yarns, "
              f"field mesh {len(fields.faces)} faces", flush=True)
    print("median: " + ", ".join(f"{k} {statistics.median(r[k] for r in rows):.2f} s" for k in rows[0])
          + f" | total {statistics.median(sum(r.values()) for r in rows):.2f} s")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB")


def command(args):
    walls, cpus, summaries, compiles = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):
            env = dict(os.environ)
            if args.fresh:
                env["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(dir=tmp, prefix="numba-")
                env["PREFORM_CACHE_DIR"] = tempfile.mkdtemp(dir=tmp, prefix="preform-")
            out = Path(tmp) / f"run{i}"
            log = Path(tmp) / f"jit{i}.jsonl"
            if args.jit:
                env["PREFORM_JIT_LOG"] = str(log)
            t0 = time.perf_counter()
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            done = subprocess.run([sys.executable, "-m", "preform.cli", "run", args.toml, "--out", str(out),
                                   "--no-progress"], env=env, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            if done.returncode != 0:
                sys.exit(f"run {i} failed ({done.returncode}):\n{done.stderr}")
            summary = json.loads((out / "summary.json").read_text())
            walls.append(wall)
            cpus.append(cpu)
            summaries.append(summary)
            stages = summary["stages_s"]
            print(f"run {i}: {wall:.2f} s wall, {cpu:.1f} s CPU (summary {summary['wall_time_s']:.2f} s: "
                  + ", ".join(f"{k} {v:.2f}" for k, v in stages.items()) + ")", flush=True)
            if args.jit:
                compiles.append(jit_lines(log))
    keys = summaries[0]["stages_s"]
    print(f"median of {args.repeat}{' fresh' if args.fresh else ''} runs: {statistics.median(walls):.2f} s wall, "
          f"{statistics.median(cpus):.1f} s CPU "
          f"(summary {statistics.median(s['wall_time_s'] for s in summaries):.2f} s: "
          + ", ".join(f"{k} {statistics.median(s['stages_s'][k] for s in summaries):.2f}" for k in keys) + ")")
    if args.jit:
        jit_table(compiles)


def jit_lines(log):
    """The top-level compilations of one run (``$PREFORM_JIT_LOG`` lines of ``preform._jit``, depth
    0: a kernel called from Python, the kernels it calls included); prints their totals per
    process and the worker's jobs (wall seconds)."""
    lines = [json.loads(x) for x in log.read_text().splitlines()] if log.exists() else []
    top = [d for d in lines if d.get("event", "compile") == "compile" and d["depth"] == 0]
    for role in ("main", "worker"):
        mine = [d for d in top if d["role"] == role]
        jobs = ", ".join(f"{d['job']} {d['wall_s']:.2f}" for d in lines if d.get("event") == "job" and d["role"] == role)
        if mine or jobs:
            print(f"    JIT {role}: {sum(d['wall_s'] for d in mine):.2f} s wall, "
                  f"{sum(d['cpu_s'] for d in mine):.2f} s CPU, {len(mine)} kernels; jobs (s wall): {jobs or '-'}",
                  flush=True)
    return top


def jit_table(runs):
    """Per kernel over the runs: median CPU and wall seconds of its compilation and where it ran."""
    by_kernel = {}
    for top in runs:
        for d in top:
            by_kernel.setdefault(d["kernel"], []).append(d)
    print(f"compilations (median over {len(runs)} runs; process / warm-up job):")
    rows = sorted(by_kernel.items(), key=lambda kv: -statistics.median(d["cpu_s"] for d in kv[1]))
    for kernel, ds in rows:
        where = sorted({f"{d['role']}/{d['job'] or 'run'}" for d in ds})
        print(f"  {statistics.median(d['cpu_s'] for d in ds):5.2f} s CPU {statistics.median(d['wall_s'] for d in ds):5.2f} s wall"
              f"  {kernel}  [{', '.join(where)}; {len(ds)}x]")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--toml", default=str(ROOT / "examples" / "case_a.toml"))
    ap.add_argument("--stl", default=None)
    ap.add_argument("--unit", default="m")
    ap.add_argument("--command", action="store_true", help="time `preform run` in fresh processes")
    ap.add_argument("--fresh", action="store_true",
                    help="with --command: empty numba and preform caches for every run (a first run)")
    ap.add_argument("--jit", action="store_true",
                    help="with --command: numba's compile time per process and per kernel")
    args = ap.parse_args(argv)
    (command if args.command else api)(args)


if __name__ == "__main__":
    main()
