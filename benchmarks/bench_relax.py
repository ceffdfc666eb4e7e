"""Force-density relaxation against the Newton reference on captured case A steps (issue 14).

``python benchmarks/bench_relax.py [--carriers 48 96 144] [--mu 0.25] [--steps 3] [--repeat 3]``

For each carrier count a case A run (``examples/case_a.toml``, interaction model, Newton solver)
is advanced to a zone of full size (250 steps; 300 with 144 carriers), then ``--steps``
consecutive steps are captured (the problem ``InteractionZone.step`` poses its solver: fell points
anchored, crossings created, wall planes) and each is solved by ``frontal.solve_zone_inplace`` and by
``relax.relax`` (``--repeat`` times, medians). Printed per carrier count: crossings, Newton ms
and Newton steps per step, relaxation ms, iterations, microseconds per crossing per iteration and
the breakdown per part (material sweep, forces and residual, factorisation, solves, wall, Anderson
mixing), and the largest position difference between the two solutions.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--carriers", type=int, nargs="+", default=[48, 96, 144])
    ap.add_argument("--mu", type=float, default=0.25)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--refactor-every", type=int, default=None,
                    help="iterations between factorisations (default: RelaxSettings')")
    args = ap.parse_args(argv)
    from test_relax import _stepper, captured   # the tests' capture of a zone step
    from preform.interaction import frontal, relax as R

    settings = (R.RelaxSettings() if args.refactor_every is None
                else R.RelaxSettings(refactor_every=args.refactor_every))
    for n in args.carriers:
        warm = 300 if n >= 144 else 250
        s, speed = _stepper(n, args.mu, warm)
        rows = []
        for k in range(args.steps):
            st, bc, f_top, s_old = captured(n, args.mu, warm)
            m = st.m
            tn, newton = [], 0
            for _ in range(args.repeat):
                stN = st.copy()
                t0 = time.perf_counter()
                rep = frontal.solve_zone_inplace(stN, bc, centre=s_old)
                tn.append(time.perf_counter() - t0)
                newton = rep.newton
            b0, f0 = R.start_bounds(st, bc)
            tr, parts = [], []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                res = R.relax(R.lattice_of(st), st.pos[:m], st.material[:m], st.material_fell,
                              s_old[:m],
                              bc.fell, bc.top, f0, b0, f_spool=bc.f_spool, mu=bc.mu, h=bc.h,
                              width=bc.width, plane=bc.plane, settings=settings)
                tr.append(time.perf_counter() - t0)
                parts.append(res.times)
            it = max(res.iterations, 1)
            part = {key: 1e3 * float(np.median([p[key] for p in parts])) / it for key in parts[0]}
            rows.append((m, 1e3 * np.median(tn), newton, 1e3 * np.median(tr), res.iterations,
                         1e6 * np.median(tr) / (it * m), part,
                         float(np.abs(res.pos - stN.pos[:m]).max()), res.converged,
                         int(res.active.sum())))
            s.advance(speed())          # the next step of the run (Newton)
        for m, tN, newton, tR, its, us, part, dpos, ok, act in rows:
            per = ", ".join(f"{key} {v:.3f}" for key, v in part.items())
            print(f"{n} carriers, mu {args.mu}: {m} crossings; Newton {tN:.1f} ms ({newton} "
                  f"Newton steps); relax {tR:.1f} ms, {its} iterations{'' if ok else ' (NOT CONVERGED)'}, "
                  f"{us:.3f} us per crossing per iteration; ms per iteration: {per}; "
                  f"{act} on the wall; |pos - Newton| {dpos:.2e} m")
        sys.stdout.flush()
        _stepper.cache_clear()


if __name__ == "__main__":
    main()
