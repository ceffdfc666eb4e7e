"""Both models on a family of curved and changing parts (``preform.geometry.shapes.family_part``).

``python benchmarks/bench_family.py [--quick] [--carriers 24] [--length 0.1] [--friction 0 0.25]
[--parts bend30 s_tube ...] [--repeat 3]``

Every part of the family (single bends of 30, 60 and 90 deg, one of 35 deg and 0.45 m from 30 mm
of the tip, S-bends from 0.15 m and from 30 mm of the tip, rectangle-to-circle and
circle-to-rectangle transitions, a taper, the 744 mm S-bent tube of a user's part) on a
case-B-like machine (ring 0.17 m, spool 0.85 m, 18 deg/s, 26.3 mm/s, tip 0.2 m beyond the
ring), well-shaped in metres and with CAD slivers in millimetres, with the guide ring and
eccentric by 10 mm, and without the ring (the spools at the ring's 0.17 m); each case with the
kinematic model and with the interaction model at each ``--friction`` (the ring's friction 0.17
where the yarns' is not 0).
For every run one line: part, triangulation, ring, model and friction, status, steps, residual
median / p99 / max (``history.csv``'s), and against the kinematic run of the same case the
braid angle (mean of warp and weft) and H at ten braided lengths: the largest difference
(deg, %; ``skip``: the lengths left out where a kinematic yarn caught on a bend in the zone),
the share of laid points caught or bridged (``flag %``), and the wall time split into the
geometry (load, repair, automatic centerline) and the simulation (median of ``--repeat``
runs). The parts' own centerlines are given (CSV), so the geometry time is the load and repair. ``--quick``: the suite's size (two parts, 0.06 m).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def _config(stl, centerline, unit, kind, friction, ring, carriers, length):
    from support.simcase import make_config

    mu_r = 0.17 if (ring and friction > 0.0) else 0.0
    # without the ring the spools take its place (0.17 m): the same convergence length
    cfg = make_config(stl, centerline, stl_unit=unit, carriers=carriers,
                      spool_radius=0.85 if ring else 0.17,
                      friction=friction, ring_friction=mu_r,
                      guide_ring=(0.17, 0.0) if ring else None, initial_position=0.2,
                      angular_speed=np.radians(18.0), take_up_speed=0.0263, braid_length=length,
                      eccentricity=(0.01, 0.0) if ring else (0.0, 0.0), pose_lead=None,
                      snapshots=0)
    return dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind=kind))


def _run(cfg, repeat):
    """(result, geometry s, simulation s median)."""
    from preform.simulation import load_geometry, simulate

    geo, sim, res = [], [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        mandrel, cl = load_geometry(cfg)
        t1 = time.perf_counter()
        res = simulate(cfg, progress=False, mandrel=mandrel, centerline=cl)
        geo.append(t1 - t0)
        sim.append(time.perf_counter() - t1)
    return res, float(np.median(geo)), float(np.median(sim))


def _against(res, ref, length):
    """(largest |angle difference| deg, largest |H difference| %, lengths skipped) at ten
    braided lengths, the first after the first tenth of the run (the tie points' start is the
    same in both), leaving out those where a kinematic yarn has caught on the mandrel (its H
    below half the mean: a straight yarn from the ring cut through a bend in the zone, so the
    kinematic run is no reference there)."""
    h, k = res.history, ref.history
    da, dh, skipped = 0.0, 0.0, 0
    for L in np.linspace(0.1 * length, length, 10):
        i = int(np.searchsorted(h["braided_length_m"], L))
        j = int(np.searchsorted(k["braided_length_m"], L))
        if i >= len(h["time_s"]) or j >= len(k["time_s"]):
            return float("nan"), float("nan"), skipped
        Hk = k["convergence_length_mean_m"][j]
        if k["convergence_length_min_m"][j] < 0.5 * Hk:
            skipped += 1
            continue
        a = 0.5 * (h["braid_angle_warp_deg"][i] + h["braid_angle_weft_deg"][i])
        b = 0.5 * (k["braid_angle_warp_deg"][j] + k["braid_angle_weft_deg"][j])
        da = max(da, abs(a - b))
        dh = max(dh, 100.0 * abs(h["convergence_length_mean_m"][i] - Hk) / Hk)
    return da, dh, skipped


def _flagged(res):
    """% of the laid points flagged caught or bridged."""
    from preform.result import FLAG_BRIDGE, FLAG_CATCH

    flags = np.asarray(res.yarns.flags)
    return 100.0 * float(np.mean((flags & (FLAG_BRIDGE | FLAG_CATCH)) > 0)) if len(flags) else 0.0


def main(argv=None):
    from preform.geometry import shapes
    from support.simcase import write_centerline, write_stl

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="the suite's size: two parts, 0.06 m")
    ap.add_argument("--parts", nargs="*", default=None, help=f"of {', '.join(shapes.FAMILY)}")
    ap.add_argument("--carriers", type=int, default=24)
    ap.add_argument("--length", type=float, default=None, help="m braided (default 0.1)")
    ap.add_argument("--friction", type=float, nargs="*", default=[0.0, 0.25])
    ap.add_argument("--repeat", type=int, default=1, help="runs per case (medians)")
    ap.add_argument("--no-slivers", action="store_true", help="the well-shaped meshes only")
    ap.add_argument("--ring-only", action="store_true", help="behind a ring only")
    a = ap.parse_args(argv)
    parts = a.parts or (["s_bend", "rect_to_circle"] if a.quick else list(shapes.FAMILY))
    length = a.length or (0.06 if a.quick else 0.1)
    meshes = [("even", "m", 1.0)] + ([] if a.no_slivers else [("sliver", "mm", 1000.0)])
    rings = [True] if a.ring_only else [True, False]
    head = (f"{'part':15s} {'mesh':9s} {'ring':4s} {'model':14s} {'status':6s} {'steps':>5s} "
            f"{'res med':>8s} {'res p99':>8s} {'res max':>8s} {'d angle':>7s} {'d H %':>6s} {'skip':>4s} "
            f"{'flag %':>6s} "
            f"{'geom s':>6s} {'sim s':>6s}")
    print(f"# {a.carriers} carriers, {length} m braided, ring runs eccentric by 10 mm")
    print(head)
    with tempfile.TemporaryDirectory() as tmp:
        for name in parts:
            for tri, unit, scale in meshes:
                V, F, path = shapes.family_part(name, triangulation=tri, scale=scale)
                stl = write_stl(Path(tmp) / f"{name}_{tri}.stl", V, F)
                # the part's own centerline (the automatic one does not start on a part that
                # bends 30 mm from its tip, s_bend_tip)
                csv = write_centerline(Path(tmp) / f"{name}_{tri}.csv", path)
                for ring in rings:
                    ref = None
                    for kind, mu in [("kinematic", 0.0)] + [("interaction", m) for m in a.friction]:
                        cfg = _config(stl, csv, unit, kind, mu, ring, a.carriers, length)
                        res, geo, sim = _run(cfg, a.repeat)
                        r = res.history["residual"]
                        if ref is None:
                            ref = res
                            da = dh = 0.0
                            skipped = 0
                        else:
                            da, dh, skipped = _against(res, ref, length)
                        label = kind if kind == "kinematic" else f"inter mu={mu:g}"
                        print(f"{name:15s} {tri + ' ' + unit:9s} {'yes' if ring else 'no':4s} "
                              f"{label:14s} {res.status:6s} {len(r) - 1:5d} {np.median(r):8.1e} "
                              f"{np.percentile(r, 99):8.1e} {np.max(r):8.1e} {da:7.2f} {dh:6.1f} {skipped:4d} "
                              f"{_flagged(res):6.2f} "
                              f"{geo:6.2f} {sim:6.1f}", flush=True)


if __name__ == "__main__":
    main()
