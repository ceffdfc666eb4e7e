"""Single-contact solvers: nanoseconds per crossing solve and per ring solve (issue 4, items 2-3).

Random braid-like crossings (lower points 4 mm apart, supply directions near the continuation of the
yarns, tensions 2-8 N, mu 0.05-0.5, previous angles from a perturbed crossing) are solved by the
batch driver ``_kernels.contact.solve_crossings`` after a JIT warm-up; the time is split by what the
corrector did (stick, one yarn slipping, both). Then the same for ring contacts.
Run: ``python benchmarks/bench_contact.py [--n 20000] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from preform._kernels import contact as CK
from preform._kernels import ring as RK
from preform.interaction.contact import crossing_angles


def crossings(n, rng, predictor_noise):
    A_X = np.array([-0.002, 0, 0]) + rng.normal(0, 3e-4, (n, 3))
    A_O = np.array([0.002, 0, 0]) + rng.normal(0, 3e-4, (n, 3))
    C0 = np.array([0, 0.004, 0]) + rng.normal(0, 5e-4, (n, 3))
    tilt = rng.choice([-1, 1], n) * rng.uniform(0.05, 0.3, n)
    dirs = []
    for A, sign in ((A_X, 1), (A_O, -1)):
        u = (C0 - A) / np.linalg.norm(C0 - A, axis=1)[:, None] + rng.normal(0, 0.15, (n, 3))
        u[:, 2] += sign * tilt
        dirs.append(rng.uniform(2, 8, (n, 1)) * u / np.linalg.norm(u, axis=1)[:, None])
    Cp = C0 + rng.normal(0, predictor_noise, (n, 3))
    theta = np.array([crossing_angles(A_X[i], A_O[i], Cp[i]) for i in range(n)])
    return A_X, A_O, dirs[0], dirs[1], theta, rng.uniform(0.05, 0.5, n)


def time_batch(fn, args, repeat):
    fn(*args)  # JIT warm-up / cache load
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best


def bench_crossings(n, repeat, rng):
    for noise in (1e-4, 4e-4):
        A_X, A_O, F_X, F_O, theta, mu = crossings(n, rng, noise)
        out, status = CK.empty_out(n), np.zeros(n, np.int64)
        wall = time_batch(CK.solve_crossings, (A_X, A_O, F_X, F_O, theta, mu, out, status), repeat)
        slips = out[:, CK.OUT_SLIP_X] + out[:, CK.OUT_SLIP_O]
        print(f"crossings (predictor noise {noise * 1e3:.1f} mm): {1e9 * wall / n:8.1f} ns per solve "
              f"(best of {repeat}, n = {n}); stick {np.mean(slips == 0):.0%}, one slips "
              f"{np.mean(slips == 1):.0%}, both {np.mean(slips == 2):.0%}, failed {np.mean(status != 0):.1%}")
        for label, mask in (("stick", slips == 0), ("one slips", slips == 1), ("both slip", slips == 2)):
            if mask.sum() < 10:
                continue
            idx = np.flatnonzero(mask)
            sub = tuple(a[idx] for a in (A_X, A_O, F_X, F_O, theta, mu))
            o, st = CK.empty_out(len(idx)), np.zeros(len(idx), np.int64)
            w = time_batch(CK.solve_crossings, (*sub, o, st), repeat)
            evals = o[:, CK.OUT_ITERATIONS].mean()
            extra = f", {evals:.1f} residual evaluations" if label == "both slip" else ""
            print(f"    {label:10s} {1e9 * w / len(idx):8.1f} ns per solve{extra}")


def bench_rings(n, repeat, rng):
    phi_b = rng.uniform(-np.pi, np.pi, n)
    phi_a = phi_b + rng.uniform(-1.2, 1.2, n)
    A = np.column_stack([0.05 * np.cos(phi_a), 0.05 * np.sin(phi_a), rng.uniform(0.15, 0.4, n)])
    B = np.column_stack([0.85 * np.cos(phi_b), 0.85 * np.sin(phi_b), np.zeros(n)])
    f, theta = rng.uniform(2, 8, n), phi_b + rng.uniform(-0.4, 0.4, n)
    out, status = RK.empty_out(n), np.zeros(n, np.int64)
    wall = time_batch(RK.solve_rings, (A, B, f, 0.17, 0.05, theta, 0.2, -1.0, out, status), repeat)
    print(f"ring contacts: {1e9 * wall / n:8.1f} ns per solve (best of {repeat}, n = {n}); "
          f"slip {out[:, RK.RING_OUT_SLIP].mean():.0%}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    bench_crossings(args.n, args.repeat, rng)
    bench_rings(args.n, args.repeat, rng)


if __name__ == "__main__":
    main()
