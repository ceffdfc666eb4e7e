"""Interaction model timing and frontal residual per iteration.

``python benchmarks/bench_interaction.py [--full] [--png residual.png] [--linear-solver splu]``
``python benchmarks/bench_interaction.py --breakdown [--case examples/bent_tube.toml]``

* default: a synthetic zone (fell points held on a 75 mm circle at z = 0.6 m, case-A machine
  speeds, spool radius 1.382 m) for 48, 96 and 144 carriers: prints the time per crossing per
  Newton step (assembly, sparse factorisation and line search over positions and material
  coordinates; the unit of work of the solver, see
  ``interaction/frontal.py``) and writes the plot of its iterations (``--png``, 144 carriers): the
  balance residual and the energy per Newton iteration of a few time steps (the energy falls at
  every iteration, Armijo; the residual does not: the first Newton steps of a time step move the
  crossings next to the fell points by millimetres across segments a centimetre long, and the
  tension there jumps before the next steps bring it back) and the friction-bound change per
  frontal iteration of a few snapshot solves;
* ``--breakdown``: case A (``examples/case_a.toml``, ``kind = "interaction"``, ``solver =
  "relax"``, from 0.4 m, ``--length`` braided, 20 snapshots per m) through ``preform run``'s
  ``run_case`` (simulate, fields, files), timed by part: the zone's step outside its solver and
  the stepper around it (ms a step), the relaxation's solves, the Newton fallbacks (with the
  relaxation's failed attempt, and Newton's part of them), the snapshots (and their Newton
  re-balance), fields and files; wall and process time; with ``--case FILE`` that example as
  it is (``preform run FILE --model interaction``; ``--carriers``, ``--mu``, ``--length``,
  ``--snapshots`` override it);
* ``--full``: ``examples/case_a.toml`` with ``kind = "interaction"`` (1 m braided, 144 carriers) and
  the same case with 48 and 96 carriers through ``preform.simulate`` (needs the geometry package
  and ``mandrels/case_a.stl``); ``--carriers 48 --length 0.4 --step-factor 1`` runs the time step
  study of ``stepping.default_time_step``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


class _Identity:
    def to_mandrel(self, x):
        return np.asarray(x)

    def to_machine(self, x):
        return np.asarray(x)


def _count_newton_steps():
    """Count the Newton steps of runs through ``preform.simulate``, which builds its zone itself:
    the solver's Newton step is wrapped with a counter (a benchmark's instrument, not a model
    setting); the counter (list of one int)."""
    from preform.interaction import frontal

    count = [0]
    step = getattr(frontal._newton_step_inplace, "wrapped", frontal._newton_step_inplace)

    def counted(*a, **k):
        count[0] += 1
        return step(*a, **k)

    counted.wrapped = step
    frontal._newton_step_inplace = counted
    return count


def synthetic(carriers, steps, mu=0.25, linear_solver="auto"):
    """Run a zone with fixed fell points; (wall s, crossing-iterations, residual histories,
    crossings at the end, mean Newton steps per timed step, Newton traces). The residual
    histories are the frontal (friction-bound) iterations of five steps solved to convergence;
    the Newton traces (residual, energy) those of eight ordinary steps from the middle of the
    run."""
    from preform.config import MachineConfig
    from preform.interaction import frontal
    from preform.interaction.model import InteractionZone
    from preform.interaction.settings import DEFAULT
    from preform.machine import Machine

    mc = MachineConfig(carriers=carriers, spool_radius=1.382, angular_speed=np.radians(13.232),
                       pattern="regular")
    machine = Machine.from_config(mc)
    cfg = NS(yarn=NS(width=4e-3, thickness=2.5e-4, tension=4.7, friction=mu, ring_friction=0.0),
             machine=mc)
    iterations = [DEFAULT.frontal.max_iterations]   # frontal iterations of the next step

    def solve(*a, **k):
        k.setdefault("max_iter", iterations[0])
        return frontal.solve_zone_inplace(*a, **k)

    settings = dataclasses.replace(DEFAULT, newton=dataclasses.replace(
        DEFAULT.newton, linear_solver=linear_solver))
    zone = InteractionZone(cfg, machine, None, distance=lambda p: np.hypot(p[:, 0], p[:, 1]) - 0.075,
                           settings=settings, solve_zone=solve)
    phi = machine.azimuths(0.0)
    F = np.stack([0.075 * np.cos(phi), 0.075 * np.sin(phi), np.full_like(phi, 0.6)], 1)
    zone.start(0.0, F, _Identity())
    dt = 0.01 / machine.omega
    t, work, wall, hist, newton, timed = 0.0, 0, 0.0, [], 0, 0
    traces = []
    for i in range(steps):
        # five steps spread over the run iterate the friction bounds to convergence (as a
        # snapshot does) for the residual plot; they are left out of the timing
        full = i in {int(steps * f) for f in (0.2, 0.4, 0.6, 0.8, 0.99)}
        iterations[0] = (DEFAULT.frontal.snapshot_iterations if full
                         else DEFAULT.frontal.max_iterations)
        t0 = time.perf_counter()
        zs = zone.step(t, dt, F, _Identity())
        if full:
            hist.append(zone.last_report.history)
        else:
            wall += time.perf_counter() - t0
            work += zs.contacts * zone.last_report.newton
            newton += zone.last_report.newton
            timed += 1
            if steps // 2 <= i < steps // 2 + 8:
                rep = zone.last_report
                traces.append((rep.newton_residual, rep.newton_energy))
        t += dt
    return wall, work, hist, zone.state.m, newton / max(timed, 1), traces


def full(carriers, mu, length, step_factor=None):
    """Case A through ``preform.simulate``; step_factor: the time step as a multiple of the
    kinematic model's default step (None: the interaction model's own default)."""
    import preform as pf
    from preform.machine import Machine
    from preform.simulation import load_geometry
    from preform.stepping import default_time_step

    cfg = pf.load_config(ROOT / "examples" / "case_a.toml")
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"),
                              machine=dataclasses.replace(cfg.machine, carriers=carriers),
                              yarn=dataclasses.replace(cfg.yarn, friction=mu),
                              process=dataclasses.replace(cfg.process, braid_length=length,
                                                          initial_position=0.4),
                              output=dataclasses.replace(cfg.output, snapshots=0))
    if step_factor is not None:
        kin = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="kinematic"))
        dt = step_factor * default_time_step(kin, Machine.from_config(cfg.machine),
                                             *load_geometry(cfg))
        cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, time_step=dt))
    count = _count_newton_steps()
    t0 = time.perf_counter()
    res = pf.simulate(cfg, progress=False)
    wall = time.perf_counter() - t0
    h = res.history
    n = len(h["time_s"])
    L, H = h["braided_length_m"], h["convergence_length_mean_m"]
    at = "  ".join(f"{x:g} m: H {np.interp(x, L, H):.4f} m, angle "
                   f"{np.interp(x, L, h['braid_angle_warp_deg']):.2f} deg"
                   for x in np.linspace(0.0, length, 4)[1:])
    print(f"case A, {carriers} carriers, mu {mu}, {length} m, step {step_factor or 'default'}: "
          f"{res.status} {res.message}, wall {wall:.2f} s, {n} steps, {count[0] / n:.1f} Newton "
          f"steps per step, max {int(h['contacts'].max())} crossings; {at}")


class _Timers:
    """Wall time (s) and call counts by part of a run through ``preform run``'s ``run_case``: the
    zone's steps, their solves (the relaxation, and the Newton fallbacks with the relaxation's
    failed attempt before them), the snapshots (and the Newton re-balance inside them), the
    stepper's work around the zone, packing the result, the fields and the files. The wrappers
    are a benchmark's instrument (installed on the classes and the solver table for one run,
    removed after it), not model settings."""

    def __init__(self):
        self.s = dict.fromkeys(("advance", "step", "solve", "fallback", "fallback_newton",
                                "snapshot", "snapshot_newton", "loop"), 0.0)
        self.cpu = dict.fromkeys(self.s, 0.0)    # process time (s) of the same parts
        self.n = dict.fromkeys(("step", "fallback", "snapshot", "snapshot_newton"), 0)
        self.inside = None          # "step" or "snapshot": who calls the solver now

    def wrap(self, owner, name, part, count=None, inside=None):
        orig = getattr(owner, name)

        def timed(*a, **k):
            outer = self.inside
            if inside is not None:
                self.inside = inside
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return orig(*a, **k)
            finally:
                self.s[part] += time.perf_counter() - t0
                self.cpu[part] += time.process_time() - c0
                if count is not None:
                    self.n[count] += 1
                self.inside = outer

        setattr(owner, name, timed)
        return lambda: setattr(owner, name, orig)


def breakdown(carriers, mu, length, snapshots, out_dir, case=None):
    """Case A (``examples/case_a.toml``, interaction model, ``solver = "relax"``, from 0.4 m)
    through ``pipeline.run_case`` (simulate, fields, files) with the time of every part (see
    ``_Timers``); snapshots: the number a run of ``length`` writes (default: as many as a 1 m run
    writes per metre, 20 per m, so the snapshots' share is that of the full run).

    ``case``: another example file, run as it is with ``kind = "interaction"`` and ``solver =
    "relax"`` (its own carriers, friction, start, length and snapshots unless ``carriers``,
    ``mu``, ``length`` or ``snapshots`` are given): what ``preform run FILE --model
    interaction`` does, timed by part."""
    import preform as pf
    from preform import stepping
    from preform.interaction import frontal, relax
    from preform.interaction.model import InteractionZone
    from preform.pipeline import run_case

    if case is None:
        cfg = pf.load_config(ROOT / "examples" / "case_a.toml")
        cfg = dataclasses.replace(
            cfg, model=dataclasses.replace(cfg.model, kind="interaction", solver="relax"),
            machine=dataclasses.replace(cfg.machine, carriers=carriers),
            yarn=dataclasses.replace(cfg.yarn, friction=mu),
            process=dataclasses.replace(cfg.process, braid_length=length, initial_position=0.4),
            output=dataclasses.replace(cfg.output, snapshots=snapshots))
    else:
        cfg = pf.load_config(case)
        cfg = dataclasses.replace(
            cfg, model=dataclasses.replace(cfg.model, kind="interaction", solver="relax"))
        if carriers is not None:
            cfg = dataclasses.replace(cfg, machine=dataclasses.replace(cfg.machine,
                                                                       carriers=carriers))
        if mu is not None:
            cfg = dataclasses.replace(cfg, yarn=dataclasses.replace(cfg.yarn, friction=mu))
        if length is not None:
            cfg = dataclasses.replace(cfg, process=dataclasses.replace(cfg.process,
                                                                       braid_length=length))
        if snapshots is not None:
            cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output,
                                                                      snapshots=snapshots))
    T = _Timers()
    solver = relax.solve_zone
    newton = frontal.solve_zone_inplace

    iterations = []

    def solve(state, bc, **k):
        report = None
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            report = solver(state, bc, **k)
            return report
        finally:
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            if report is not None and T.inside != "snapshot" and k.get("mode", "step") == "step":
                iterations.append(report.relax_iterations)
            if T.inside == "snapshot":
                pass                                    # counted by the snapshot's timers
            elif report is not None and report.fallback:
                T.s["fallback"] += dt
                T.cpu["fallback"] += dc
                T.n["fallback"] += 1
            else:
                T.s["solve"] += dt
                T.cpu["solve"] += dc

    def newton_timed(*a, **k):
        t0 = time.perf_counter()
        try:
            return newton(*a, **k)
        finally:
            if T.inside == "snapshot":
                T.s["snapshot_newton"] += time.perf_counter() - t0
                T.n["snapshot_newton"] += 1
            else:
                T.s["fallback_newton"] += time.perf_counter() - t0

    undo = [T.wrap(stepping.Stepper, "advance", "advance"),
            T.wrap(stepping.Stepper, "run", "loop"),
            T.wrap(InteractionZone, "step", "step", "step", inside="step"),
            T.wrap(InteractionZone, "snapshot", "snapshot", "snapshot", inside="snapshot")]
    # the zone takes its solver from ``relax.solve_zone`` when it is built (``zone.solver_of``)
    relax.solve_zone = solve
    frontal.solve_zone_inplace = newton_timed
    try:
        t0, c_start = time.perf_counter(), time.process_time()
        outcome = run_case(cfg, out_dir)
        wall = time.perf_counter() - t0
    finally:
        relax.solve_zone = solver
        frontal.solve_zone_inplace = newton
        for u in undo:
            u()
    import json
    summary = json.loads((Path(out_dir) / "summary.json").read_text())
    stages = summary.get("stages_s", {})
    s, n = T.s, T.n
    steps = max(n["step"], 1)
    outside = s["step"] - s["solve"] - s["fallback"]
    h = outcome.result.history
    name = "case A" if case is None else Path(case).name
    print(f"{name}, {cfg.machine.carriers} carriers, mu {cfg.yarn.friction}, "
          f"{cfg.process.braid_length} m, relax: {outcome.result.status}, wall {wall:.1f} s, "
          f"process time {time.process_time() - c_start:.1f} s, {n['step']} steps, max "
          f"{int(np.max(h['contacts']))} crossings, median "
          f"{np.median(iterations) if iterations else 0:.0f}"
          " relaxation iterations a step")
    rows = [
        ("zone step outside the solver", outside, outside / steps * 1e3),
        ("stepper around the zone step", s["advance"] - s["step"] - s["snapshot"],
         (s["advance"] - s["step"] - s["snapshot"]) / steps * 1e3),
        ("relaxation solves (converged)", s["solve"],
         s["solve"] / max(steps - n["fallback"], 1) * 1e3),
        (f"Newton fallbacks ({n['fallback']}, with the failed relaxation)", s["fallback"],
         s["fallback"] / max(n["fallback"], 1) * 1e3),
        ("  of which Newton's solves", s["fallback_newton"],
         s["fallback_newton"] / max(n["fallback"], 1) * 1e3),
        (f"snapshots ({n['snapshot']}; {n['snapshot_newton']} Newton solves "
         f"{s['snapshot_newton']:.1f} s)", s["snapshot"],
         s["snapshot"] / max(n["snapshot"], 1) * 1e3),
        ("time loop, rest", s["loop"] - s["advance"], float("nan")),
        ("simulate outside the loop (geometry, result)", stages.get("simulate", 0.0) - s["loop"],
         float("nan")),
        ("load and check", stages.get("load_and_check", 0.0), float("nan")),
        ("fields and analysis", stages.get("analyse", 0.0), float("nan")),
        ("files (write)", stages.get("write", 0.0), float("nan")),
    ]
    for name, total, per in rows:
        print(f"  {name:<62s} {total:8.2f} s" + (f"  {per:8.2f} ms each" if per == per else ""))
    c = T.cpu
    print(f"  process time: zone step outside the solver "
          f"{(c['step'] - c['solve'] - c['fallback']) / steps * 1e3:.2f} ms, stepper around it "
          f"{(c['advance'] - c['step'] - c['snapshot']) / steps * 1e3:.2f} ms, solver "
          f"{c['solve'] / max(steps - n['fallback'], 1) * 1e3:.2f} ms a step; snapshots "
          f"{c['snapshot'] / max(n['snapshot'], 1):.2f} s each")
    return s, n, stages


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--mu", type=float, default=0.0)
    ap.add_argument("--length", type=float, default=1.0)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--carriers", type=int, nargs="+", default=[144, 96, 48],
                    help="--full: the carrier counts to run")
    ap.add_argument("--step-factor", type=float, default=None,
                    help="--full: time step as a multiple of the kinematic model's default step "
                         "(default: the interaction model's own)")
    ap.add_argument("--breakdown", action="store_true",
                    help="case A with solver = 'relax' through preform run's run_case, time by "
                         "part (--carriers, --mu, --length, --snapshots, --out)")
    ap.add_argument("--snapshots", type=int, default=None,
                    help="--breakdown: snapshots written (default 20 per m braided)")
    ap.add_argument("--out", default=None, help="--breakdown: results folder (default: temporary)")
    ap.add_argument("--case", default=None,
                    help="--breakdown: this example as it is (e.g. examples/bent_tube.toml) "
                         "instead of case A; --carriers, --mu, --length, --snapshots override it")
    ap.add_argument("--png", default=str(ROOT / "benchmarks" / "frontal_residual.png"))
    ap.add_argument("--linear-solver", default="auto", choices=("auto", "cholmod", "splu"),
                    help="factorisation of the Newton systems (interaction/linalg.py)")
    ap.add_argument("--no-plot", action="store_true", help="timings only")
    args = ap.parse_args(argv)
    given = set(sys.argv[1:] if argv is None else argv)
    args.carriers_given = "--carriers" in given
    args.mu_given = "--mu" in given
    args.length_given = "--length" in given
    if args.breakdown:
        import tempfile
        if args.case is not None:
            with tempfile.TemporaryDirectory() as tmp:
                breakdown(args.carriers[0] if args.carriers_given else None,
                          args.mu if args.mu_given else None,
                          args.length if args.length_given else None, args.snapshots,
                          args.out or tmp, case=args.case)
            return
        snaps = args.snapshots if args.snapshots is not None else max(1, round(20 * args.length))
        for n in args.carriers:
            with tempfile.TemporaryDirectory() as tmp:
                breakdown(n, args.mu, args.length, snaps, args.out or tmp)
        return
    if args.full:
        for n in args.carriers:
            full(n, args.mu, args.length, args.step_factor)
        return
    synthetic(16, 5)   # JIT warm-up
    hists, traces = {}, {}
    for n in (48, 96, 144):
        wall, work, hist, m, per_step, trace = synthetic(n, args.steps,
                                                         linear_solver=args.linear_solver)
        hists[n], traces[n] = hist, trace
        print(f"{n} carriers: {args.steps} steps, {m} crossings at the end, wall {wall:.2f} s, "
              f"{1e9 * wall / max(work, 1):.1f} ns per crossing per Newton step, "
              f"{per_step:.1f} Newton steps per step ({args.linear_solver})")
    if args.no_plot:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from preform.interaction.settings import DEFAULT
    roundoff = DEFAULT.newton.roundoff
    fig, (ax_r, ax_e, ax_f) = plt.subplots(1, 3, figsize=(15, 4.2))
    rises = e_rises = 0
    for res, E in traces[144]:
        k = np.arange(len(res))
        ax_r.semilogy(k, res, marker=".")
        # E's distance to its value at the solution (the last iterate), floored at its round-off
        ax_e.semilogy(k, np.maximum(E - E[-1], roundoff * abs(E[-1])), marker=".")
        rises += int(np.any(np.diff(res) > 0))
        # Armijo on E allows a rise of its round-off (settings.newton.roundoff |E|)
        e_rises += int(np.any(np.diff(E) > roundoff * np.abs(E[1:])))
    ax_r.set(xlabel="Newton iteration of a time step", ylabel="relative force imbalance",
             title="balance residual per Newton iteration")
    ax_e.set(xlabel="Newton iteration of a time step", ylabel="E - E(solution) (J)",
             title="energy per Newton iteration")
    for h in hists[144]:
        ax_f.semilogy(np.arange(1, len(h) + 1), h, marker=".")
    ax_f.set(xlabel="frontal iteration (friction bounds)", ylabel="change of the bounds / tensions",
             title="snapshot: friction-bound iteration")
    fig.suptitle(f"synthetic zone, 144 carriers, mu = 0.25: {len(traces[144])} time steps (left, "
                 f"middle), {len(hists[144])} snapshot solves (right)")
    fig.tight_layout()
    fig.savefig(args.png, dpi=100)
    print(f"144 carriers: the balance residual rose at some Newton iteration in {rises} of "
          f"{len(traces[144])} plotted steps, the energy in {e_rises}")
    print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
