"""Case A with the kinematic model: 144 carriers, 1 m braided.

Prints the wall time of each run after a JIT warm-up and the time per fell-point update
(one yarn, one time step). Run: ``python benchmarks/bench_kinematic.py [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

import preform as pf

ROOT = Path(__file__).resolve().parents[1]


def case_a(braid_length=1.0):
    cfg = pf.load_config(ROOT / "examples" / "case_a.toml")
    # the paper's case A start (0.4 m), as the benchmarks table measures it
    process = dataclasses.replace(cfg.process, braid_length=braid_length, initial_position=0.4)
    model = dataclasses.replace(cfg.model, kind="kinematic")
    return dataclasses.replace(cfg, process=process, model=model)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--length", type=float, default=1.0, help="braided length, m")
    args = ap.parse_args(argv)
    pf.simulate(case_a(0.02), progress=False)  # JIT warm-up (numba cache) and imports
    walls = []
    for i in range(args.repeat):
        t0 = time.perf_counter()
        result = pf.simulate(case_a(args.length), progress=False)
        walls.append(time.perf_counter() - t0)
        updates = result.steps * result.yarns.n_yarns
        print(f"run {i}: wall {walls[-1]:.3f} s, {result.steps} steps x {result.yarns.n_yarns} yarns, "
              f"{1e6 * walls[-1] / updates:.2f} us per fell-point update")
    print(f"median wall {statistics.median(walls):.3f} s over {args.repeat} runs "
          f"(case A, kinematic, {args.length} m braided)")


if __name__ == "__main__":
    main()
