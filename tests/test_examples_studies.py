"""The study scripts in examples/ run and draw one curve per value (plumbing, short and small)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _studies():
    spec = importlib.util.spec_from_file_location("studies", ROOT / "examples" / "studies.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_study_values_follow_table_c2():
    s = _studies()
    labels = [label for label, _ in s.study_configs("case_a_friction", model="kinematic")]
    assert labels == [f"friction = {v}" for v in (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)]
    cfgs = [c for _, c in s.study_configs("case_a_position", model="kinematic")]
    assert [c.process.initial_position for c in cfgs] == [0.2, 0.4, 0.6, 0.8]
    assert all(c.yarn.friction == 0.3 for c in cfgs)
    cfgs = [c for _, c in s.study_configs("case_b_friction", model="kinematic")]
    assert [c.yarn.friction for c in cfgs] == [0.0, 0.25, 0.5]


def test_study_runs_and_plots(tmp_path):
    s = _studies()
    results = s.run_study("case_b_friction", tmp_path, model="kinematic", length=0.03, carriers=16, progress=False)
    assert len(results) == 3
    png = tmp_path / "case_b_friction.png"
    assert png.stat().st_size > 10_000
    table = np.loadtxt(tmp_path / "case_b_friction.csv", delimiter=",", skiprows=1)
    assert table.shape[1] == 1 + 2 * 3 and np.all(np.isfinite(table))


def test_study_values_subset():
    s = _studies()
    labels = [label for label, _ in s.study_configs("case_a_friction", model="kinematic",
                                                     values=[0, 0.1 + 0.2, 0.5])]
    assert labels == ["friction = 0.0", "friction = 0.3", "friction = 0.5"]
    with pytest.raises(SystemExit, match="--values 0.25: not among the values of case_a_friction"):
        s.study_configs("case_a_friction", model="kinematic", values=[0.25])


def test_study_table_leaves_a_stopped_run_empty_beyond_its_end(tmp_path):
    s = _studies()
    full = {"braided_length_m": np.linspace(0.0, 1.0, 11), "braid_angle_warp_deg": np.full(11, 30.0),
            "braid_angle_weft_deg": np.full(11, 30.0), "convergence_length_mean_m": np.full(11, 0.2)}
    part = {k: v[:4] for k, v in full.items()}
    results = {"friction = 0.0": NS(status="failed", history=part),
               "friction = 0.5": NS(status="done", history=full)}
    s._table(results, tmp_path / "t.csv")
    table = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    assert np.all(np.isfinite(table[:4])) and np.all(np.isnan(table[4:, 1:3]))
    assert np.all(np.isfinite(table[:, 3:]))
    s._plot("case_a_friction", results, tmp_path / "t.png")
    assert (tmp_path / "t.png").stat().st_size > 10_000
