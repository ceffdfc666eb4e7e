"""Force balance and the friction law of written convergence-zone snapshots, read back from their
.vtp files alone: each crossing's four tension vectors from the file's own
points and ``tension_N``, plus its points' ``external_force_N``; shared by the interaction
tests. Nothing here calls preform's solver code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyvista as pv

from preform.io.vtk_yarns import write_convergence


def read_snapshot(path):
    """Per yarn (points, segment tensions, contact ids) from a written .vtp (one line cell per
    segment, docs/guide/results.md; cells of a yarn in order)."""
    poly = pv.read(path)
    lines = np.asarray(poly.lines).reshape(-1, 3)[:, 1:]
    ten = np.asarray(poly.cell_data["tension_N"])
    yid = np.asarray(poly.cell_data["yarn_id"])
    cid = np.asarray(poly.point_data["contact_id"])
    pts = np.asarray(poly.points, dtype=float)
    out = []
    for k in np.unique(yid):
        cells = np.nonzero(yid == k)[0]
        idx = np.concatenate([[lines[cells[0], 0]], lines[cells, 1]])
        assert np.all(lines[cells[1:], 0] == lines[cells[:-1], 1])
        out.append((pts[idx], ten[cells], cid[idx]))
    return out


def balance_and_psi(yarns, mu):
    """Max relative force imbalance and max Psi / tension over the crossings of a snapshot."""
    forces = {}
    psis = []
    for pts, ten, cid in yarns:
        for i in range(1, len(pts) - 1):
            if cid[i] < 0:
                continue
            lo, hi = pts[i - 1] - pts[i], pts[i + 1] - pts[i]
            f_lo, f_hi = ten[i - 1], ten[i]
            u_lo, u_hi = lo / np.linalg.norm(lo), hi / np.linalg.norm(hi)
            forces.setdefault(cid[i], []).append((f_lo * u_lo + f_hi * u_hi, f_lo + f_hi))
            cb = u_lo @ u_hi
            c, s = np.sqrt(max(0, (1 - cb) / 2)), np.sqrt(max(0, (1 + cb) / 2))
            psis.append((abs(f_lo - f_hi) * c - mu * (f_lo + f_hi) * s) / max(f_lo, f_hi))
    assert all(len(v) == 2 for v in forces.values())
    err = [np.linalg.norm(v[0][0] + v[1][0]) / (v[0][1] + v[1][1]) for v in forces.values()]
    return max(err), max(psis)


def read_external_forces(path):
    """Per yarn the point data ``external_force_N`` (k, 3) of its points, in the order of
    ``read_snapshot``'s points."""
    poly = pv.read(path)
    lines = np.asarray(poly.lines).reshape(-1, 3)[:, 1:]
    yid = np.asarray(poly.cell_data["yarn_id"])
    ext = np.asarray(poly.point_data["external_force_N"], dtype=float).reshape(-1, 3)
    out = []
    for k in np.unique(yid):
        cells = np.nonzero(yid == k)[0]
        out.append(ext[np.concatenate([[lines[cells[0], 0]], lines[cells, 1]])])
    return out


def crossing_balance(yarns, external):
    """Per crossing (contact id) of a snapshot read back from its file: the net force of its two
    points, the two tension vectors along the written segments at each point (tension_N times
    the unit vector from the point to its neighbour) plus both points' external_force_N.
    Returns (largest |net| / the largest tension of the file, largest |net| / the sum of the
    crossing's four tensions, crossings, crossings with a non-zero external force)."""
    net, total = {}, {}
    pushed = set()
    f_max = max(float(np.max(ten)) for _, ten, _ in yarns)
    for (pts, ten, cid), ext in zip(yarns, external):
        for i in range(1, len(pts) - 1):
            if cid[i] < 0:
                continue
            lo, hi = pts[i - 1] - pts[i], pts[i + 1] - pts[i]
            f = ten[i - 1] * lo / np.linalg.norm(lo) + ten[i] * hi / np.linalg.norm(hi) + ext[i]
            net[cid[i]] = net.get(cid[i], 0.0) + f
            total[cid[i]] = total.get(cid[i], 0.0) + ten[i - 1] + ten[i]
            if np.any(ext[i] != 0.0):
                pushed.add(cid[i])
    size = np.array([np.linalg.norm(v) for v in net.values()])
    rel = size / np.array([total[c] for c in net])
    return float(size.max() / f_max), float(rel.max()), len(net), len(pushed)


def checked_snapshot_files(snapshots, out_dir, mu, rebalanced=False):
    """Write the snapshots as convergence.pvd + .vtp, read each back and assert force balance
    (with ``external_force_N``) at every crossing; the written snapshots are the run's
    own states, whose friction law holds to the step's lag of the bounds, so the friction law
    is asserted on the re-balanced copies that check them (``Snapshot.rebalanced``),
    written and read back the same way, which must balance too. The yarns (``read_snapshot``)
    of every written file that has crossings (``rebalanced``: of the re-balanced copies')."""
    out = []
    checked = [s.rebalanced for s in snapshots]
    assert all(c is not None for c in checked), "a snapshot was not checked by a re-balance"
    written = write_convergence(snapshots, out_dir)[1:]
    again = write_convergence(checked, Path(out_dir) / "rebalanced")[1:]
    for p, q in zip(written, again):
        yarns = read_snapshot(p)
        if not any(np.any(c >= 0) for _, _, c in yarns):
            continue
        err, _, _, _ = crossing_balance(yarns, read_external_forces(p))
        assert err < 1e-3     # required: tensions + external forces balance to 1e-3 x max tension
        re = read_snapshot(q)
        _, psi = balance_and_psi(re, mu)
        err, _, _, _ = crossing_balance(re, read_external_forces(q))
        assert err < 1e-3
        assert psi < 1e-3     # required: Psi <= 1e-3 tension
        out.append(re if rebalanced else yarns)
    return out
