"""Sparse factorisations of a case-A-sized Newton system of the interaction model.

``python benchmarks/bench_linalg.py [--crossings 2232] [--repeat 7]``

Grows the synthetic zone of ``bench_interaction.py`` (144 carriers, case A speeds, mu = 0.25) to
``--crossings`` crossings (2232: 11160 unknowns, the size of a case A zone), assembles its Hessian
and times, in the nested-dissection order the solver uses, factorisation + one solve of every
backend of ``interaction/linalg.py`` (CHOLMOD when cvxopt is installed, SciPy's SuperLU) and, when
installed, ``qdldl`` (Apache-2, its own AMD order) for comparison. Prints the median time and
the relative residual of each; ``docs/decisions.md`` has the figures.
"""

from __future__ import annotations

import argparse
import time
from types import SimpleNamespace as NS

import numpy as np
import scipy.sparse as sp


class _Identity:
    def to_mandrel(self, x):
        return np.asarray(x)

    def to_machine(self, x):
        return np.asarray(x)


def hessian(crossings):
    """(lower triangle (r, c, values) in the dissection order, n, the right-hand side there)."""
    from preform.config import MachineConfig
    from preform.interaction import frontal
    from preform._kernels import frontal as frontal_kernels
    from preform.interaction.model import InteractionZone
    from preform.machine import Machine

    mc = MachineConfig(carriers=144, spool_radius=1.382, angular_speed=np.radians(13.232),
                       pattern="regular")
    machine = Machine.from_config(mc)
    cfg = NS(yarn=NS(width=4e-3, thickness=2.5e-4, tension=4.7, friction=0.25, ring_friction=0.0),
             machine=mc)
    zone = InteractionZone(cfg, machine, None, distance=lambda p: np.hypot(p[:, 0], p[:, 1]) - 0.075)
    phi = machine.azimuths(0.0)
    F = np.stack([0.075 * np.cos(phi), 0.075 * np.sin(phi), np.full_like(phi, 0.6)], 1)
    zone.start(0.0, F, _Identity())
    dt, t = 0.01 / machine.omega, 0.0
    while zone.state.m < crossings:
        zone.step(t, dt, F, _Identity())
        t += dt
    st = zone.state
    net = frontal._Network(st, zone.boundary(t, F))
    net.tension[:] = st.tension[: st.m]
    bound, _, net.f_top = net.bounds()
    net.bound = np.where(np.isfinite(st.bound[: st.m]), st.bound[: st.m], bound)
    _, nnz = net.assemble()
    p = net.pattern(nnz)
    v = np.empty(p.size)
    frontal_kernels.accumulate(nnz, p.slot, net.vals, v)
    return p.r, p.c, v, 5 * st.m, -net.grad[: st.m].ravel()[net.order]


def median_time(f, repeat):
    times, x = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        x = f()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), x


def main(argv=None):
    from preform.interaction.linalg import AVAILABLE, LowerFactoriser

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--crossings", type=int, default=2232)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    r, c, v, n, rhs = hessian(args.crossings)
    lower = sp.csc_matrix((v, (r, c)), shape=(n, n))
    H = (lower + sp.tril(lower, -1).T).tocsc()
    print(f"{n} unknowns, {H.nnz} entries; median of {args.repeat}, factorisation + solve")

    def report(name, seconds, x):
        res = np.linalg.norm(H @ x - rhs) / np.linalg.norm(rhs)
        print(f"  {name:40s} {1e3 * seconds:7.1f} ms   relative residual {res:.1e}")

    for name in AVAILABLE:
        f = LowerFactoriser(r, c, n, name)
        f.factorise(v)     # CHOLMOD's analysis, made once per pattern in the solver
        report(name, *median_time(lambda: f.factorise(v)(rhs), args.repeat))
    try:
        import qdldl
    except ImportError:
        print("  qdldl not installed")
    else:
        s = qdldl.Solver(H)

        def qd():
            s.update(H)
            return s.solve(rhs)
        report("qdldl (its AMD order, update)", *median_time(qd, args.repeat))


if __name__ == "__main__":
    main()
