"""Whole runs with ``[model] solver = "relax"`` against the Newton reference: the case A
cylinder with 16 and 48 carriers (0.4 m) and a case-B-like run through a guide ring: the
convergence length within 1 % and the braid angles within 0.3 deg at every step, and every
crossing of the relaxation run's snapshot files in balance (with ``external_force_N``) and inside
the friction cone, read back from the files.

Friction 0.5 is not claimed: on the 16-carrier case A the two runs part at a step where a crossing
takes another equilibrium (H up to 2.1 % apart, the angle being laid up to 3.9 deg at one step;
``docs/decisions.md``): a run's sensitivity to each step's last digits."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import preform as pf
from preform import simulate
from preform.geometry import shapes
from support.simcase import FULL_SIZE, make_config, write_centerline, write_stl
from support.snapshot_checks import checked_snapshot_files

ROOT = Path(__file__).resolve().parents[2]


def _both(cfg):
    out = {}
    for solver in ("newton", "relax"):
        c = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction",
                                                               solver=solver))
        res = simulate(c, progress=False)
        assert res.status == "done", res.message
        out[solver] = res
    return out["newton"], out["relax"]


def _compare(a, b):
    """Largest relative difference of the mean convergence length and largest braid-angle
    difference (deg) over the steps of two runs."""
    ha, hb = a.history, b.history
    assert len(ha["time_s"]) == len(hb["time_s"])
    Ha, Hb = np.asarray(ha["convergence_length_mean_m"]), np.asarray(hb["convergence_length_mean_m"])
    dH = float(np.max(np.abs(Ha - Hb) / np.maximum(np.abs(Ha), 1e-12)))
    dA = max(float(np.max(np.abs(np.asarray(ha[f"braid_angle_{g}_deg"])
                                 - np.asarray(hb[f"braid_angle_{g}_deg"]))))
             for g in ("warp", "weft"))
    return dH, dA


@pytest.mark.slow
@pytest.mark.parametrize("carriers, mu", [(16, 0.0), (16, 0.25),
                                         pytest.param(48, 0.25, marks=FULL_SIZE)])
def test_case_a_runs_agree_with_newton(carriers, mu, tmp_path):
    """Measured: H within 1.3e-7, angles within 0.001 deg (both solvers to 1e-7 of the
    tensions; the relaxation's Newton fallback took 1-7 steps of 221-331)."""
    cfg = pf.load_config(ROOT / "examples" / "case_a.toml")
    cfg = dataclasses.replace(
        cfg, machine=dataclasses.replace(cfg.machine, carriers=carriers),
        yarn=dataclasses.replace(cfg.yarn, friction=mu),
        process=dataclasses.replace(cfg.process, braid_length=0.4, initial_position=0.4),
        output=dataclasses.replace(cfg.output, snapshots=3))
    newton, relax = _both(cfg)
    dH, dA = _compare(newton, relax)
    assert dH < 0.01 and dA < 0.3          # required: 1 % and 0.3 deg over the whole run
    checked_snapshot_files(relax.snapshots, tmp_path, mu)


@pytest.mark.slow
def test_guide_ring_run_agrees_with_newton(tmp_path):
    """Measured: H within 7.0e-5, angles within 0.08 deg (the ring points' stick and slip follow
    each step's solve, so the two runs' small differences feed back through the ring)."""
    v, f = shapes.case_b(length=0.5, blend=(0.35, 0.45), n_around=96)
    stl = write_stl(tmp_path / "b.stl", v, f)
    cl = write_centerline(tmp_path / "b.csv", [[0, 0, 0], [0, 0, 0.5]])
    cfg = make_config(stl, cl, carriers=16, spool_radius=0.2, friction=0.25, ring_friction=0.17,
                      guide_ring=(0.12, 0.0), braid_length=0.25, initial_position=0.08,
                      eccentricity=(0.02, 0.0), snapshots=3)
    newton, relax = _both(cfg)
    dH, dA = _compare(newton, relax)
    assert dH < 0.01 and dA < 0.3
    checked_snapshot_files(relax.snapshots, tmp_path / "out", 0.25)
