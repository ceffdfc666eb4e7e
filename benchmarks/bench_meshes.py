"""One cylinder, three triangulations, end to end: well-shaped (~100 k faces), CAD
slivers (trimesh's 256 sections: 512 side faces 1.6 m x 1 mm) and fine (~1 M faces).

Each run (in its own process, so peak memory is its own) loads the STL with the automatic
centerline, simulates 16 carriers kinematically over 1 m, maps to the surface and writes all
results (Python API: simulate, map_to_surface, write_results). Prints per stage wall times, the
total (wall and CPU time) and the peak RSS; then ``mandrel info`` on a 2 M-face STL.

Run: ``python benchmarks/bench_meshes.py [--repeat 1] [--skip-info]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
R, LENGTH = 0.04, 1.6
STAGES = ("load+repair", "centerline", "simulate", "map", "write+render")


def make_stl(kind, path):
    import numpy as np
    import trimesh

    from preform.geometry import shapes

    if kind == "sliver":
        m = trimesh.creation.cylinder(radius=R, height=LENGTH, sections=256)
        m.apply_translation([0.0, 0.0, LENGTH / 2])
    else:
        n_around, n_along = {"well": (128, 400), "fine": (512, 1000), "info": (1024, 1000)}[kind]
        V, F = shapes.cylinder(R, LENGTH, n_around=n_around, n_along=n_along)
        m = trimesh.Trimesh(V, np.asarray(F), process=False)
    m.export(path)
    return len(m.faces)


def run(stl):
    """One end-to-end run in this process; prints a JSON line of stage times."""
    import preform as pf
    from preform import geometry

    cfg = pf.load_config(ROOT / "examples" / "case_a.toml")
    cfg = dataclasses.replace(
        cfg, mandrel=dataclasses.replace(cfg.mandrel, stl=Path(stl), centerline="auto"),
        machine=dataclasses.replace(cfg.machine, carriers=16, spool_radius=0.3),
        process=dataclasses.replace(cfg.process, initial_position=0.1, braid_length=1.0),
        model=dataclasses.replace(cfg.model, kind="kinematic"))
    t = {}
    c0 = time.process_time()
    t0 = time.perf_counter()
    mandrel = geometry.load_mandrel(stl)
    t["load+repair"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    cl = geometry.auto_centerline(mandrel)
    t["centerline"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=cl)
    t["simulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fields = pf.map_to_surface(result)
    t["map"] = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        pf.write_results(result, fields, out)
        t["write+render"] = time.perf_counter() - t0
    t["total"] = sum(t[k] for k in STAGES)
    t["cpu_total"] = time.process_time() - c0        # less sensitive to other load than wall time
    t["peak_rss_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    t["field_faces"] = len(fields.faces)
    t["angle_deg"] = float(result.history["braid_angle_warp_deg"][-1])
    print(json.dumps(t))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--skip-info", action="store_true")
    ap.add_argument("--run", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.run:
        run(args.run)
        return
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, __file__, "--run", str(ROOT / "mandrels" / "case_a.stl")],
                       capture_output=True)                       # JIT warm-up (numba cache)
        for kind in ("well", "sliver", "fine"):
            stl = Path(tmp) / f"{kind}.stl"
            n = make_stl(kind, stl)
            rows = []
            for _ in range(args.repeat):
                out = subprocess.run([sys.executable, __file__, "--run", str(stl)], capture_output=True,
                                     text=True)
                rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
            print(f"{kind:6s} {n:>9,} faces (medians of {len(rows)}): " + ", ".join(
                f"{k} {v:.2f}" for k, v in med.items() if k not in ("field_faces",))
                + f" | field mesh {med['field_faces']:.0f} faces", flush=True)
        if not args.skip_info:
            stl = Path(tmp) / "info.stl"
            n = make_stl("info", stl)
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "preform.cli", "mandrel", "info", str(stl)],
                           capture_output=True, cwd=tmp)
            print(f"mandrel info on {n:,} faces: {time.perf_counter() - t0:.2f} s (whole command)")


if __name__ == "__main__":
    main()
