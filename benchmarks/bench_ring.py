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

``--breakdown``: each run's steps by part as well: the solves a step (the posed iteration's
extra ones), relaxation iterations, factorisations and Newton fallbacks, and the shares of the
step's time (the solves, the fell points' anchoring, the crossings' creation, the mandrel
look-ups, the ring contact, the deposit, the rest: the depositor's walk and the recording) and
of the solves' time (the relaxation's parts: set-up, sweeps, forces, factorisations, solves,
wall, mixing and line search). ``--toml FILE``: step that config alone (the interaction
model, no snapshots) instead of the two variants. ``--set relax.reuse_factor=False ...``:
settings of the interaction model other than the defaults (``InteractionSettings`` branch
and field), to compare a lever back to back.

``--run TOML [TOML ...]``: ``preform run TOML --model interaction`` in a fresh process each,
``--repeat`` times: its wall time (outside the process) and the stages of its summary, medians.

Run: ``python benchmarks/bench_ring.py [--carriers 96] [--steps 600] [--mu 0.25] [--repeat 3]``,
``python benchmarks/bench_ring.py --run examples/bent_tube.toml examples/case_b.toml``.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


#: the zone's parts a step goes through, timed in ``stepped`` (``InteractionZone`` methods)
PARTS = {"fell_anchor": "anchor", "_create_crossings": "create", "_with_near_wall": "near",
         "_left_clearance": "near", "slide_rings": "ring", "ring_material": "ring",
         "_deposit": "deposit"}


def timed_zone(base, clock):
    """A subclass of ``base`` (``InteractionZone``) whose methods of :data:`PARTS` add their
    wall and CPU time to ``clock[part]`` (a dict of [wall, cpu])."""
    def wrap(name, part):
        inner = getattr(base, name)

        def method(self, *a, **kw):
            t, c = time.perf_counter(), time.process_time()
            try:
                return inner(self, *a, **kw)
            finally:
                acc = clock.setdefault(part, [0.0, 0.0])
                acc[0] += time.perf_counter() - t
                acc[1] += time.process_time() - c
        return method
    return type("TimedZone", (base,), {n: wrap(n, p) for n, p in PARTS.items()})


def model_settings(assignments):
    """The interaction model's settings with ``assignments`` ("branch.field=value", value a
    Python literal: ``relax.reuse_factor=False``) applied to the defaults."""
    import ast

    from preform.interaction.settings import DEFAULT

    out = DEFAULT
    for item in assignments or ():
        key, value = item.split("=", 1)
        branch, name = key.split(".")
        sub = dataclasses.replace(getattr(out, branch), **{name: ast.literal_eval(value)})
        out = dataclasses.replace(out, **{branch: sub})
    return out


def stepped(cfg, steps, settings=None):
    """Step ``cfg`` ``steps`` steps; per step a dict: crossings ``m``, ``wall`` and ``cpu`` s
    of the whole step, ``solve`` s (wall) of the zone's solves, the last report's
    ``iterations`` and ``residual``, ``solves`` (zone solves: more than one where a step is
    solved again), ``posed`` (the posed iteration's extra solves), ``fallback`` (Newton's),
    ``factorisations``, the zone's parts (:data:`PARTS`, CPU s; ``solve_cpu`` the solves')
    and the relaxation's (``relax.*``, ``RelaxResult.times``, wall s)."""
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
    clock = {}
    row = {}

    def solve(st, bc, **kw):
        t, c = time.perf_counter(), time.process_time()
        try:
            report = inner(st, bc, **kw)
            row["solves"] = row.get("solves", 0) + 1
            row["posed"] = row.get("posed", 0) + report.posed_solves
            row["fallback"] = row.get("fallback", 0) + int(report.fallback)
            row["factorisations"] = row.get("factorisations", 0) + report.factorisations
            row["relax_iterations"] = row.get("relax_iterations", 0) + report.relax_iterations
            for k, v in (report.relax_times or {}).items():
                row["relax." + k] = row.get("relax." + k, 0.0) + v
            return report
        finally:
            row["solve"] = row.get("solve", 0.0) + time.perf_counter() - t
            row["solve_cpu"] = row.get("solve_cpu", 0.0) + time.process_time() - c

    zone = timed_zone(InteractionZone, clock)(cfg, machine, mandrel, solve_zone=solve,
                                              settings=settings)
    s = Stepper(cfg, machine, mandrel, cl, zone)
    rows = []
    for _ in range(steps):
        row.clear()
        clock.clear()
        t, c = time.perf_counter(), time.process_time()
        s.advance(take_up_speed(cfg.process.take_up_speed, s.braided))
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        rep = zone.last_report
        out = dict(row, m=zone.state.m, wall=wall, cpu=cpu,
                   iterations=rep.iterations if rep else 0,
                   residual=rep.residual if rep else 0.0)
        out.update({k: v[1] for k, v in clock.items()})
        rows.append(out)
    return rows


def breakdown(rows):
    """Lines of the per-step breakdown of ``rows`` (``stepped``) over the steps with
    crossings: medians and means a step, and each part's share of the steps' CPU time (the
    solves' parts: of the solves' wall time, as the relaxation times them)."""
    live = [r for r in rows if r["m"] > 0]
    if not live:
        return []

    def col(k):
        return np.array([r.get(k, 0.0) for r in live], dtype=float)

    total = col("cpu").sum()
    lines = [f"  {len(live)} steps with crossings; wall {1e3 * np.median(col('wall')):.1f} ms "
             f"(median), CPU {1e3 * np.median(col('cpu')):.1f} ms; solves a step mean "
             f"{col('solves').mean():.2f}, posed extra solves mean {col('posed').mean():.2f} "
             f"(max {col('posed').max():.0f}), relaxation iterations mean "
             f"{col('relax_iterations').mean():.1f} (median "
             f"{np.median(col('relax_iterations')):.0f}), factorisations mean "
             f"{col('factorisations').mean():.2f}, Newton fallbacks {col('fallback').sum():.0f}"]
    shares = {"solve": col("solve_cpu").sum()}
    shares.update({p: col(p).sum() for p in sorted(set(PARTS.values()))})
    shares["rest (depositor walk, recording, check)"] = total - sum(shares.values())
    lines.append("  share of the steps' CPU time: " + ", ".join(
        f"{p} {100 * v / total:.1f} %" for p, v in shares.items()))
    relax = sorted({k for r in live for k in r if k.startswith("relax.")})
    if relax:
        sol = col("solve").sum()
        lines.append("  the solves' wall time by part: " + ", ".join(
            f"{k[6:]} {100 * col(k).sum() / sol:.1f} %" for k in relax)
            + f", other {100 * (sol - sum(col(k).sum() for k in relax)) / sol:.1f} %")
    return lines


def variant(folder, carriers, mu, mu_r, ring):
    from support.simcase import case_b_like_config

    cfg = case_b_like_config(folder, mu_r)
    m = dataclasses.replace(cfg.machine, carriers=carriers)
    if not ring:
        # the spool circle where the ring was: same supply circle, no ring contact
        m = dataclasses.replace(m, guide_ring=None, spool_radius=cfg.machine.guide_ring.radius)
    return dataclasses.replace(cfg, machine=m, yarn=dataclasses.replace(cfg.yarn, friction=mu))


def from_toml(path):
    """The config of ``path`` with the interaction model and no snapshots."""
    from preform.config import load_config

    cfg = load_config(path)
    return dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"),
                               output=dataclasses.replace(cfg.output, snapshots=0))


def steps_mode(args):
    medians = {}
    names = [args.toml] if args.toml else ["ring", "no ring"]
    for name in names:
        per, cpu = [], []
        for rep in range(args.repeat):
            with tempfile.TemporaryDirectory() as tmp:
                cfg = (from_toml(name) if args.toml else
                       variant(Path(tmp), args.carriers, args.mu, args.mu_r, name == "ring"))
                rows = stepped(cfg, args.steps, model_settings(args.set))
            live = [r for r in rows if r["m"] > 0]
            if not live:
                print(f"{name}: no crossings in {args.steps} steps")
                continue

            def col(k):
                return np.array([r.get(k, 0.0) for r in live], dtype=float)

            r, m = col("residual"), col("m")
            t_step, t_solve = np.median(col("wall")), np.median(col("solve"))
            per.append(t_step)
            cpu.append(np.median(col("cpu")))
            print(f"{name} run {rep}: {len(live)} steps with crossings, crossings median "
                  f"{np.median(m):.0f}; a step {1e3 * t_step:.2f} ms wall, "
                  f"{1e3 * cpu[-1]:.2f} ms CPU (solve {1e3 * t_solve:.2f}, rest "
                  f"{1e3 * (t_step - t_solve):.2f}), "
                  f"{1e6 * np.median(col('wall') / m):.1f} us per crossing; iterations "
                  f"median {np.median(col('iterations')):.0f}, fallbacks "
                  f"{col('fallback').sum():.0f}; residual median "
                  f"{np.median(r):.2g} p99 {np.percentile(r, 99):.2g} max {r.max():.2g}",
                  flush=True)
            if args.breakdown:
                print("\n".join(breakdown(rows)), flush=True)
        if per:
            medians[name] = (statistics.median(per), statistics.median(cpu))
    if len(medians) == 2:
        (rw, rc), (nw, nc) = medians["ring"], medians["no ring"]
        print(f"median a step: ring {1e3 * rw:.2f} ms wall {1e3 * rc:.2f} ms CPU, no ring "
              f"{1e3 * nw:.2f} ms wall {1e3 * nc:.2f} ms CPU, ratio {rw / nw:.2f} wall "
              f"{rc / nc:.2f} CPU")


def run_mode(args):
    for toml in args.run:
        walls, cpus, stages = [], [], []
        for i in range(args.repeat):
            with tempfile.TemporaryDirectory() as tmp:
                t = time.perf_counter()
                c = resource.getrusage(resource.RUSAGE_CHILDREN)
                p = subprocess.run([sys.executable, "-m", "preform.cli", "run", toml, "--model",
                                    "interaction", "--out", tmp], capture_output=True, text=True)
                wall = time.perf_counter() - t
                d = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = d.ru_utime + d.ru_stime - c.ru_utime - c.ru_stime
                if p.returncode != 0:
                    print(f"{toml} run {i}: exit {p.returncode}\n{p.stderr[-2000:]}")
                    break
                summary = json.loads((Path(tmp) / "summary.json").read_text())
            walls.append(wall)
            cpus.append(cpu)
            stages.append(summary.get("stages_s", {}))
            quality = summary.get("quality") or {}
            print(f"{toml} run {i}: {wall:.1f} s ({cpu:.1f} s CPU, the process and its "
                  f"workers); " + ", ".join(
                f"{k} {v:.1f}" for k, v in stages[-1].items()) + f"; status "
                f"{summary.get('status')}, quality {quality.get('verdict', quality)}"
                + "".join(f"\n  reason: {r}" for r in quality.get("reasons", ())), flush=True)
        if walls:
            keys = stages[0].keys()
            print(f"{toml} median: {statistics.median(walls):.1f} s "
                  f"({statistics.median(cpus):.1f} s CPU); " + ", ".join(
                f"{k} {statistics.median(s.get(k, 0.0) for s in stages):.1f}" for k in keys))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--carriers", type=int, default=96)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--mu", type=float, default=0.25)
    ap.add_argument("--mu-r", type=float, default=0.17)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--run", nargs="+", default=None, help="TOML files: preform run end to end")
    ap.add_argument("--toml", default=None,
                    help="steps mode: step this config (interaction model, no snapshots) alone")
    ap.add_argument("--set", nargs="+", default=None, metavar="BRANCH.FIELD=VALUE",
                    help="steps mode: the interaction model's settings changed from the "
                         "defaults, e.g. relax.reuse_factor=False")
    ap.add_argument("--breakdown", action="store_true",
                    help="steps mode: each run's steps by part (zone parts, solver parts)")
    args = ap.parse_args()
    run_mode(args) if args.run else steps_mode(args)


if __name__ == "__main__":
    main()
