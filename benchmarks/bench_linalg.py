"""Sparse factorisations of a case-A-sized Newton system of the interaction model.

``python benchmarks/bench_linalg.py [--crossings 2232] [--repeat 7]``

Grows the synthetic zone of ``bench_interaction.py`` (144 carriers, case A speeds, mu = 0.25) to
``--crossings`` crossings (2232: 11160 unknowns, the size of a case A zone), assembles its Hessian
and times, in the nested-dissection order the solver uses, factorisation + one solve of every
backend of ``interaction/linalg.py`` (CHOLMOD when cvxopt is installed, SciPy's SuperLU) and, when
installed, ``qdldl`` (Apache-2, its own AMD order) for comparison. Prints the median time and
the relative residual of each; ``docs/decisions.md`` has the figures.

``python benchmarks/bench_linalg.py --blocks [--crossings 2880] [--repeat 7]`` times instead the
relaxation's block LDL^T (``_kernels/ldl.py``, 3 x 3 and 5 x 5 blocks) on a band lattice of about
``--crossings`` crossings (48 around, each crossing linked to two below it, random symmetric
positive definite blocks) in its band-dissection order: CPU time of the factorisation and of
one solve, medians, and the relative residual of the solve.
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


def band_blocks(crossings, nb, seed=0):
    """A band lattice of 48 x (crossings / 48) crossings, each linked to the two below it, its
    block pattern in the band-dissection order and random SPD values: (structure, values)."""
    from preform._kernels import ldl as LDL

    nu = 48
    nv = max(2, round(crossings / nu))
    m = nu * nv
    idx = np.arange(m).reshape(nv, nu)
    low = np.full((m, 2), -1, dtype=np.int64)
    up = np.full((m, 2), -1, dtype=np.int64)
    low[idx[1:].ravel(), 0] = idx[:-1].ravel()
    low[idx[1:].ravel(), 1] = np.roll(idx[:-1], -1, axis=1).ravel()
    up[idx[:-1].ravel(), 0] = idx[1:].ravel()
    up[np.roll(idx[:-1], -1, axis=1).ravel(), 1] = idx[1:].ravel()
    u = np.tile(np.arange(nu, dtype=float), nv) + 0.5 * np.repeat(np.arange(nv) % 2, nu)
    v = np.repeat(np.arange(nv, dtype=float), nu)
    perm = np.empty(m, dtype=np.int64)
    LDL.band_dissection(m, low, up, u, v, 4, 0.15, perm)
    Ap = np.empty(m + 1, dtype=np.int64)
    Ai = np.empty(3 * m, dtype=np.int64)
    diag = np.empty(m, dtype=np.int64)
    nslots = LDL.block_pattern(m, low, perm, Ap, Ai, diag, np.empty((m, 2), dtype=np.int64),
                               np.empty((m, 2), dtype=np.bool_))
    Ai = Ai[:nslots]
    rng = np.random.default_rng(seed)
    vals = 0.3 * rng.normal(size=(nslots, nb, nb))
    B = rng.normal(size=(m, nb, nb))
    vals[diag] = B @ B.transpose(0, 2, 1) + 4 * nb * np.eye(nb)
    etree = np.empty(m, dtype=np.int64)
    Lnz = np.empty(m, dtype=np.int64)
    nnz = LDL.ldl_symbolic(m, Ap, Ai, np.empty(m, dtype=np.int64), Lnz, etree)
    return NS(m=m, nb=nb, Ap=Ap, Ai=Ai, etree=etree, Lnz=Lnz, nnz=nnz, perm=perm), vals


def bench_blocks(crossings, repeat):
    """Median CPU times of the block LDL^T's factorisation and solve, 3 x 3 and 5 x 5."""
    from preform._kernels import ldl as LDL

    for nb in (3, 5):
        z, vals = band_blocks(crossings, nb)
        m, nnz = z.m, z.nnz
        Lp, Li = np.empty(m + 1, dtype=np.int64), np.empty(nnz, dtype=np.int64)
        Lx, Dinv = np.empty((nnz, nb, nb)), np.empty((m, nb, nb))
        marker, iw = np.zeros(m, dtype=np.bool_), np.empty((3, m), dtype=np.int64)
        y, D, x = np.zeros((m, nb, nb)), np.empty((nb, nb)), np.empty((m, nb))
        numeric, solve = LDL.LDL_KERNELS[nb]
        rhs = np.random.default_rng(1).normal(size=(m, nb))
        out = np.empty((m, nb))

        def fac():
            assert numeric(m, z.Ap, z.Ai, vals, Lp, Li, Lx, Dinv, z.etree, z.Lnz, marker, iw[0],
                           iw[1], iw[2], y, D)

        def sol():
            solve(m, Lp, Li, Lx, Dinv, z.perm, rhs, out, x)

        fac()
        sol()
        tf = median_time(fac, repeat, time.thread_time)[0]
        ts = median_time(sol, repeat, time.thread_time)[0]
        # the relative residual of the solve, A x from the upper triangle's blocks
        col = np.repeat(np.arange(m), np.diff(z.Ap))
        i, j = z.perm[z.Ai], z.perm[col]
        Ax = np.zeros((m, nb))
        np.add.at(Ax, i, np.einsum("qab,qb->qa", vals, out[j]))
        off = i != j
        np.add.at(Ax, j[off], np.einsum("qba,qb->qa", vals[off], out[i[off]]))
        err = np.linalg.norm(Ax - rhs) / np.linalg.norm(rhs)
        print(f"  {nb} x {nb} blocks, {m} crossings, {nnz} blocks of L: factor "
              f"{1e3 * tf:6.2f} ms, solve {1e6 * ts:7.1f} us (CPU, median of {repeat}); "
              f"relative residual {err:.1e}")


def median_time(f, repeat, clock=time.perf_counter):
    times, x = [], None
    for _ in range(repeat):
        t0 = clock()
        x = f()
        times.append(clock() - t0)
    return float(np.median(times)), x


def main(argv=None):
    from preform.interaction.linalg import AVAILABLE, LowerFactoriser

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--crossings", type=int, default=2232)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--blocks", action="store_true",
                    help="time the relaxation's block LDL^T instead")
    args = ap.parse_args(argv)
    if args.blocks:
        bench_blocks(args.crossings, args.repeat)
        return
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
