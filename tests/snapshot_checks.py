"""Force balance and the friction law of written convergence-zone snapshots, read back from their
.vtp files (issue 4); shared by the interaction tests."""

from __future__ import annotations

import numpy as np
import pyvista as pv

from preform.io.vtk_yarns import write_convergence


def read_snapshot(path):
    """Per yarn (points, segment tensions, contact ids) from a written .vtp (one line cell per
    segment, DESIGN.md §1; cells of a yarn in order)."""
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


def checked_snapshot_files(snapshots, out_dir, mu):
    """Write the snapshots as convergence.pvd + .vtp, read each back and assert force balance and
    the friction law at every crossing (issue 4); the yarns (``read_snapshot``) of every file
    that has crossings."""
    out = []
    for p in write_convergence(snapshots, out_dir)[1:]:
        yarns = read_snapshot(p)
        if not any(np.any(c >= 0) for _, _, c in yarns):
            continue
        err, psi = balance_and_psi(yarns, mu)
        assert err < 1e-3     # issue 4: relative force-balance error < 1e-3
        assert psi < 1e-3     # issue 4: Psi <= 1e-3 tension
        out.append(yarns)
    return out
