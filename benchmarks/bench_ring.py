"""A time step behind a guide ring against one without, at the same size; and ``preform run``
with the interaction model end to end, by stage.

Steps (default): the case-B-like mandrel (``tests/support/simcase.case_b_like_config``: rounded square
to circle, 20 mm eccentricity, 18 deg/s, 26.3 mm/s) with ``--carriers`` carriers, stepped
``--steps`` steps through its start-up, twice: behind case B's guide ring (0.17 m, ring friction
``--mu-r``, spool 0.85 m), and without a ring with the spool circle where the ring was (radius
0.17 m in the ring's plane), so that the yarns run to the same circle and the zone holds about the
same crossings. Per variant: the steps with crossings, the median crossings, the time a step
(median; the zone's solve and the rest of the step), the time per crossing, the solver's
iterations and Newton fallbacks, the history's residual (median, p99, max); then the ratio of
the ring's time a step to the other's.

``--run TOML [TOML ...]``: ``preform run TOML --model interaction`` in a fresh process each,
``--repeat`` times: its wall time (outside the process) and the stages of its summary, medians.

Run: ``python benchmarks/bench_ring.py [--carriers 96] [--steps 600] [--mu 0.25] [--repeat 3]``,
``python benchmarks/bench_ring.py --run examples/bent_tube.toml examples/case_b.toml``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def stepped(cfg, steps):
    """Step ``cfg`` ``steps`` steps; per step (crossings, solve s, step s, iterations,
    residual) and the Newton fallbacks."""
    from preform.interaction.model import InteractionZone
    from preform.machine import Machine
    from preform.reference import resolve_pose_lead
    from preform.simulation import load_geometry
    from preform.zone import solver_of
    from preform.stepping import Stepper, take_up_speed

    mandrel, cl = load_geometry(cfg)
    cfg = resolve_pose_lead(cfg, mandrel, cl)
    machine = Machine.from_config(cfg.machine)
    inner = solver_of(cfg.model.solver)
    solve_time = [0.0]
    fallbacks = [0]

    def solve(st, bc, **kw):
        t = time.perf_counter()
        try:
            report = inner(st, bc, **kw)
            fallbacks[0] += report.fallback
            return report
        finally:
            solve_time[0] += time.perf_counter() - t

    zone = InteractionZone(cfg, machine, mandrel, solve_zone=solve)
    s = Stepper(cfg, machine, mandrel, cl, zone)
    rows = []
    for _ in range(steps):
        solve_time[0] = 0.0
        t = time.perf_counter()
        s.advance(take_up_speed(cfg.process.take_up_speed, s.braided))
        dt = time.perf_counter() - t
        rep = zone.last_report
        rows.append((zone.state.m, solve_time[0], dt, rep.iterations if rep else 0,
                     rep.residual if rep else 0.0))
    return np.array(rows, dtype=float), fallbacks[0]


def variant(folder, carriers, mu, mu_r, ring):
    from support.simcase import case_b_like_config

    cfg = case_b_like_config(folder, mu_r)
    m = dataclasses.replace(cfg.machine, carriers=carriers)
    if not ring:
        # the spool circle where the ring was: same supply circle, no ring contact
        m = dataclasses.replace(m, guide_ring=None, spool_radius=cfg.machine.guide_ring.radius)
    return dataclasses.replace(cfg, machine=m, yarn=dataclasses.replace(cfg.yarn, friction=mu))


def steps_mode(args):
    medians = {}
    for ring in (True, False):
        name = "ring" if ring else "no ring"
        per = []
        for rep in range(args.repeat):
            with tempfile.TemporaryDirectory() as tmp:
                cfg = variant(Path(tmp), args.carriers, args.mu, args.mu_r, ring)
                rows, fb = stepped(cfg, args.steps)
            live = rows[rows[:, 0] > 0]
            if not len(live):
                print(f"{name}: no crossings in {args.steps} steps")
                continue
            r = live[:, 4]
            t_step, t_solve = np.median(live[:, 2]), np.median(live[:, 1])
            per.append(t_step)
            print(f"{name} run {rep}: {len(live)} steps with crossings, crossings median "
                  f"{np.median(live[:, 0]):.0f}; a step {1e3 * t_step:.2f} ms (solve "
                  f"{1e3 * t_solve:.2f}, rest {1e3 * (t_step - t_solve):.2f}), "
                  f"{1e6 * np.median(live[:, 2] / live[:, 0]):.1f} us per crossing; iterations "
                  f"median {np.median(live[:, 3]):.0f}, fallbacks {fb}; residual median "
                  f"{np.median(r):.2g} p99 {np.percentile(r, 99):.2g} max {r.max():.2g}",
                  flush=True)
        if per:
            medians[name] = statistics.median(per)
    if len(medians) == 2:
        print(f"median a step: ring {1e3 * medians['ring']:.2f} ms, no ring "
              f"{1e3 * medians['no ring']:.2f} ms, ratio {medians['ring'] / medians['no ring']:.2f}")


def run_mode(args):
    for toml in args.run:
        walls, stages = [], []
        for i in range(args.repeat):
            with tempfile.TemporaryDirectory() as tmp:
                t = time.perf_counter()
                p = subprocess.run([sys.executable, "-m", "preform.cli", "run", toml, "--model",
                                    "interaction", "--out", tmp], capture_output=True, text=True)
                wall = time.perf_counter() - t
                if p.returncode != 0:
                    print(f"{toml} run {i}: exit {p.returncode}\n{p.stderr[-2000:]}")
                    break
                summary = json.loads((Path(tmp) / "summary.json").read_text())
            walls.append(wall)
            stages.append(summary.get("stages_s", {}))
            quality = summary.get("quality") or {}
            print(f"{toml} run {i}: {wall:.1f} s; " + ", ".join(
                f"{k} {v:.1f}" for k, v in stages[-1].items()) + f"; status "
                f"{summary.get('status')}, quality {quality.get('verdict', quality)}", flush=True)
        if walls:
            keys = stages[0].keys()
            print(f"{toml} median: {statistics.median(walls):.1f} s; " + ", ".join(
                f"{k} {statistics.median(s.get(k, 0.0) for s in stages):.1f}" for k in keys))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--carriers", type=int, default=96)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--mu", type=float, default=0.25)
    ap.add_argument("--mu-r", type=float, default=0.17)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--run", nargs="+", default=None, help="TOML files: preform run end to end")
    args = ap.parse_args()
    run_mode(args) if args.run else steps_mode(args)


if __name__ == "__main__":
    main()
