"""The everyday run, stage by stage: ``examples/case_a.toml`` (kinematic) through the Python API.

Stages: load and repair the STL, centerline, JIT (a 2 cm run that compiles or loads the numba
cache), simulate, map to the surface (field mesh + clipping + pooling), write the data files, render
the pictures and plots. Prints each run's stage times and the median of each stage.

Run: ``python benchmarks/bench_pipeline.py [--repeat 3] [--toml examples/case_a.toml]
[--stl other.stl --unit mm]`` (``--stl`` swaps the mandrel, e.g. a generated sliver cylinder).
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import statistics
import tempfile
import time
from pathlib import Path

import preform as pf
from preform import geometry
from preform.io import plots, surface
from preform.io import write_convergence, write_history, write_summary, write_yarns_vtp

ROOT = Path(__file__).resolve().parents[1]


def config(toml, stl=None, unit="m"):
    cfg = pf.load_config(toml)
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="kinematic"))
    if stl is not None:
        cfg = dataclasses.replace(cfg, mandrel=dataclasses.replace(cfg.mandrel, stl=Path(stl),
                                                                   stl_unit=unit, centerline="auto"))
    return cfg


def run_once(cfg, out_dir):
    t = {}
    t0 = time.perf_counter()
    mandrel = geometry.load_mandrel(cfg.mandrel.stl, unit=cfg.mandrel.stl_unit)
    t["load+repair"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    mc = cfg.mandrel
    if isinstance(mc.centerline, str) and mc.centerline == "auto":
        cl = geometry.auto_centerline(mandrel, roll_reference=mc.roll_reference)
    else:
        cl = geometry.read_centerline_csv(mc.centerline, unit=mc.stl_unit, roll_reference=mc.roll_reference)
    t["centerline"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    short = dataclasses.replace(cfg, process=dataclasses.replace(cfg.process, braid_length=0.02))
    pf.simulate(short, progress=False, mandrel=mandrel, centerline=cl)
    t["jit (2 cm run)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=cl)
    t["simulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fields = pf.map_to_surface(result)
    t["map"] = time.perf_counter() - t0
    out = Path(out_dir)
    t0 = time.perf_counter()
    write_history(result, out / "history.csv")
    write_yarns_vtp(result.yarns, out / "yarns.vtp")
    write_convergence(result.snapshots, out)
    mesh = surface.surface_mesh(fields)
    import meshio
    meshio.write(out / "surface.vtu", mesh, file_format="vtu")
    meshio.write(out / "surface.xdmf", mesh, file_format="xdmf")
    write_summary(result, out / "summary.json")
    t["write"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    surface.write_surface_pictures(fields, out / "plots")
    plots.plot_history(result, out / "plots")
    plots.plot_yarns_3d(result, out / "plots" / "yarns.png")
    t["render"] = time.perf_counter() - t0
    return t, result, fields


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--toml", default=str(ROOT / "examples" / "case_a.toml"))
    ap.add_argument("--stl", default=None)
    ap.add_argument("--unit", default="m")
    args = ap.parse_args(argv)
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


if __name__ == "__main__":
    main()
