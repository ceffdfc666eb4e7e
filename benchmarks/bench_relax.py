"""Force-density relaxation against the Newton reference on captured steps.

``python benchmarks/bench_relax.py [--carriers 48 96 144] [--mu 0.25] [--steps 3] [--repeat 3]
[--preconditioner block full scalar] [--warm-solver relax|newton] [--warm N] [--case FILE]``

``python benchmarks/bench_relax.py --run examples/case_b.toml [--out DIR]``: one run end to end
through ``preform run`` with the interaction model (fields and files included), then its wall
time, the share of steps the relaxation gave to the Newton fallback and the median relaxation
iterations a step (the time steps' ``SolveReport.fallback`` and ``relax_iterations``).

``--case FILE``: capture the steps from that example (its own carriers unless ``--carriers``
is given; behind a guide ring ``solve_zone`` uses ``RelaxSettings.ring_preconditioner``,
``"full"``) instead of case A.

For each carrier count a case A run (``examples/case_a.toml``, or ``--case``; interaction
model, the ``--warm-solver``) is advanced to a zone of full size (``--warm``: 250 steps; 300
with 144 carriers), then ``--steps`` consecutive steps are captured (the problem
``InteractionZone.step`` poses its solver: fell points anchored, crossings created, wall
planes) and each is solved by ``frontal.solve_zone_inplace`` and by ``relax.relax`` with each
``--preconditioner`` (``--repeat`` times, medians). Printed per step: crossings, Newton ms and
Newton steps, relaxation ms, iterations (NOT CONVERGED where it stalls), microseconds per
crossing per iteration, the breakdown per part in ms per step (set-up: order, pattern and
symbolic analysis; material sweeps with the segments; forces, residual and friction bounds;
factorisation; solves; wall; block-Jacobi corrections; Anderson mixing), material Newton steps
per sweep and yarn, and the largest position difference to Newton's solution. Then per carrier
count and preconditioner the steps converged and the medians over the steps, and the spread of
the microseconds per crossing per iteration between the carrier counts.

Microseconds per crossing per iteration: the time of the whole ``relax`` call (its set-up:
order, pattern and symbolic analysis; every iteration with its factorisations; the friction
bounds of the converged geometry) over crossings x iterations, the median of ``--repeat``
calls, on two clocks: wall (``time.perf_counter``) and the CPU time of the calling thread
(``time.thread_time``: the relaxation's own work; on a shared machine the wall clock also
counts the time other processes hold the core, more of it in a longer call).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def _case_config(path, carriers, mu, solver):
    """The example at ``path`` with the interaction model and ``solver``, no snapshots; its
    carriers and friction unless given."""
    import dataclasses

    import preform as pf

    cfg = pf.load_config(path)
    cfg = dataclasses.replace(
        cfg, model=dataclasses.replace(cfg.model, kind="interaction", solver=solver),
        output=dataclasses.replace(cfg.output, snapshots=0),
        yarn=dataclasses.replace(cfg.yarn, friction=cfg.yarn.friction if mu is None else mu))
    if carriers is not None:
        cfg = dataclasses.replace(cfg, machine=dataclasses.replace(cfg.machine,
                                                                   carriers=carriers))
    return cfg


def _stepper(carriers, mu, steps, solver, case=None):
    from support.simcase import advanced_stepper
    from test_relax import _config

    cfg = (_config(carriers, 0.25 if mu is None else mu, solver) if case is None
           else _case_config(case, carriers, mu, solver))
    return advanced_stepper(cfg, steps)


def run_end_to_end(config, out):
    """``preform run config --model interaction`` in this process; prints the wall time, the
    share of steps solved by the Newton fallback and the median relaxation iterations a
    step."""
    from preform import cli
    from preform.interaction import relax as R

    reports = []
    solver = R.solve_zone

    def recorded(*a, **k):
        report = solver(*a, **k)
        if k.get("mode", "step") == "step":
            reports.append(report)
        return report
    # the zone takes its solver from ``relax.solve_zone`` when it is built (``zone.solver_of``)
    R.solve_zone = recorded
    try:
        t0 = time.perf_counter()
        code = cli.main(["run", str(config), "--model", "interaction", "--out", str(out),
                         "--no-progress"])
        wall = time.perf_counter() - t0
    finally:
        R.solve_zone = solver
    its = [r.relax_iterations for r in reports]
    fallbacks = sum(r.fallback for r in reports)
    print(f"{config}: exit {code}, {wall:.1f} s end to end; {len(its)} steps given to the "
          f"relaxation, {fallbacks} ({fallbacks / max(len(its), 1):.1%}) solved by the Newton "
          f"fallback; median {np.median(its) if its else float('nan'):.0f} relaxation "
          "iterations a step")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--run", default=None, help="an example to run end to end instead")
    ap.add_argument("--out", default=None, help="result folder of --run (default: a temporary "
                                                "folder)")
    ap.add_argument("--case", default=None, help="the example to capture steps from (default "
                                                 "case A)")
    ap.add_argument("--carriers", type=int, nargs="+", default=None,
                    help="default 48 96 144 (case A), the example's own with --case")
    ap.add_argument("--mu", type=float, default=None, help="default 0.25 (case A), the "
                                                           "example's own with --case")
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--preconditioner", nargs="+", default=None,
                    choices=["block", "full", "scalar"],
                    help="default block scalar (case A), full block with a guide ring")
    ap.add_argument("--warm-solver", default="relax", choices=["relax", "newton"],
                    help="solver of the run that brings the zone to full size")
    ap.add_argument("--warm", type=int, default=None,
                    help="steps before the captured ones (default 250, 300 with 144 carriers; "
                         "from about 420 at 144 carriers a fifth of the segments jam)")
    args = ap.parse_args(argv)
    if args.run is not None:
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            run_end_to_end(args.run, args.out or tmp)
        return
    from support.simcase import capture_step as _capture
    from preform.interaction import frontal, relax as R

    summary = {}
    carriers = args.carriers or ([None] if args.case else [48, 96, 144])
    if args.preconditioner is None:
        ring = args.case is not None and _case_config(args.case, None, None,
                                                      "relax").machine.guide_ring is not None
        args.preconditioner = ["full", "block"] if ring else ["block", "scalar"]
    for n in carriers:
        warm = args.warm if args.warm is not None else (300 if (n or 0) >= 144 else 250)
        s, speed = _stepper(n, args.mu, warm, args.warm_solver, args.case)
        for k in range(args.steps):
            st, bc, f_top, s_old = _capture(s, speed)
            m = st.m
            tn, newton = [], 0
            for _ in range(args.repeat):
                stN = st.copy()
                t0 = time.perf_counter()
                rep = frontal.solve_zone_inplace(stN, bc, centre=s_old)
                tn.append(time.perf_counter() - t0)
                newton = rep.newton
            b0, f0 = R.start_bounds(st, bc)
            for pre in args.preconditioner:
                settings = R.RelaxSettings(preconditioner=pre)
                tr, tc, parts = [], [], []
                for _ in range(args.repeat):
                    t0, c0 = time.perf_counter(), time.thread_time()
                    res = R.relax(R.lattice_of(st), st.pos[:m], st.material[:m],
                                  st.material_fell, s_old[:m], bc.fell, bc.top, f0, b0,
                                  f_spool=bc.f_spool, mu=bc.mu, h=bc.h, width=bc.width,
                                  plane=bc.plane, settings=settings)
                    tc.append(time.thread_time() - c0)
                    tr.append(time.perf_counter() - t0)
                    parts.append(res.times)
                it = max(res.iterations, 1)
                part = {key: 1e3 * float(np.median([p[key] for p in parts])) for key in parts[0]}
                sweeps = it * (1 + (settings.smoothing if pre == "scalar" else 0)) + 1
                newton_per = res.sweep_stats[0] / (sweeps * st.n_yarns)
                us = 1e6 * np.median(tr) / (it * m)
                us_cpu = 1e6 * np.median(tc) / (it * m)
                summary.setdefault((n, pre), []).append((1e3 * np.median(tr), it, us, part,
                                                         res.converged, us_cpu))
                per = ", ".join(f"{key} {v:.1f}" for key, v in part.items())
                note = "" if res.converged else " (NOT CONVERGED)"
                note += " (scalar after a block stall)" if res.fallback_scalar else ""
                print(f"{st.n_yarns} carriers, mu {bc.mu}, step {k}, {pre}: {m} crossings; Newton "
                      f"{1e3 * np.median(tn):.1f} ms ({newton} Newton steps); relax "
                      f"{1e3 * np.median(tr):.1f} ms, {res.iterations} iterations{note}, "
                      f"{res.factorisations} factorisations, "
                      f"{us:.3f} us per crossing per iteration (CPU {us_cpu:.3f}); ms per step "
                      f"(wall): {per}; "
                      f"{newton_per:.2f} material Newton steps per sweep and yarn; "
                      f"{int(res.active.sum())} on the wall; |pos - Newton| "
                      f"{float(np.abs(res.pos - stN.pos[:m]).max()):.2e} m")
                sys.stdout.flush()
            s.advance(speed())          # the next step of the run
    print("medians over the steps (us per crossing per iteration: the whole relax call, set-up, "
          "iterations and last friction bounds, over crossings x iterations; wall and thread "
          "CPU time, medians of --repeat calls):")
    for pre in args.preconditioner:
        per_n, per_cpu = {}, {}
        for n in carriers:
            rows = summary[(n, pre)]
            ms, its, us = (float(np.median([r[i] for r in rows])) for i in range(3))
            per_n[n] = us
            per_cpu[n] = float(np.median([r[5] for r in rows]))
            part = {key: float(np.median([r[3][key] for r in rows])) for key in rows[0][3]}
            done = sum(r[4] for r in rows)
            print(f"  {pre}, {n or 'the example'} carriers: {done} of {len(rows)} steps "
                  f"converged; {ms:.1f} ms a step, {its:.0f} iterations, {us:.3f} us "
                  f"per crossing per iteration (CPU {per_cpu[n]:.3f}); " +
                  ", ".join(f"{k} {v:.1f}" for k, v in part.items()) + " ms")
        if len(per_n) > 1:
            print(f"  {pre}: largest / smallest us per crossing per iteration "
                  f"{max(per_n.values()) / min(per_n.values()):.2f} wall, "
                  f"{max(per_cpu.values()) / min(per_cpu.values()):.2f} CPU "
                  "(target: within 1.3)")


if __name__ == "__main__":
    main()
