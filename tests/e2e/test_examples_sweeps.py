"""The shipped sweep files are the paper's Table C.2 studies and load as valid sweeps."""

from __future__ import annotations

from pathlib import Path

import pytest

from preform.studies.sweeps import load_sweep

SWEEPS = Path(__file__).resolve().parents[2] / "examples" / "sweeps"


@pytest.mark.parametrize("name,key,values,fixed", [
    ("case_a_friction", "yarn.friction", [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], ("process", "initial_position", 0.4)),
    ("case_a_position", "process.initial_position", [0.2, 0.4, 0.6, 0.8], ("yarn", "friction", 0.3)),
    ("case_b_friction", "yarn.friction", [0.0, 0.25, 0.5], ("process", "initial_position", 0.2)),
])
def test_sweep_files_follow_table_c2(name, key, values, fixed):
    spec = load_sweep(SWEEPS / f"{name}.toml")
    assert spec.keys == [key]
    assert [p.values[key] for p in spec.points] == values
    section, field, value = fixed
    for config in spec.configs.values():
        assert getattr(getattr(config, section), field) == value
        assert config.model.kind == "interaction" and config.output.snapshots == 0
    assert spec.out_dir == (SWEEPS.parent / "results" / name).resolve()


def test_the_rtm_chain_example_writes_the_solver_files_and_its_map(tmp_path):
    """examples/rtm_chain.py (a short stretch of case B): rtm/ files and the Vf / K1 map."""
    import importlib.util
    import json

    spec = importlib.util.spec_from_file_location("rtm_chain", SWEEPS.parent / "rtm_chain.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    png = module.main(["--length", "0.15", "--out", str(tmp_path / "out")])
    assert png.stat().st_size > 20_000
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["rtm"]["written"]
    for name in ("lcmsim.h5", "rtmsim.bdf", "rtmsim_sets.csv"):
        assert (tmp_path / "out" / "rtm" / name).stat().st_size > 0
