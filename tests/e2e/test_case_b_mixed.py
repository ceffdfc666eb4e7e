"""``examples/case_b_mixed.toml``: the paper's case B as its experiment ran (72 glass, 24
polyester spools), through ``preform check``: the mix and every pair's friction are printed."""

from __future__ import annotations

from pathlib import Path

import pytest

from preform import cli
from preform.config import load_config

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "case_b_mixed.toml"


def test_the_example_carries_the_papers_spools():
    cfg = load_config(EXAMPLE)
    kinds = cfg.carrier_types()
    names = cfg.type_names
    spools = {name: int((kinds == i).sum()) for i, name in enumerate(names)}
    assert spools == {"yarn": 72, "polyester": 24}        # the paper's 72 + 24, both groups
    assert cfg.yarn.linear_density_tex == 300.0
    assert cfg.yarn_type("polyester").linear_density_tex == 110.0
    n = cfg.machine.carriers // 2
    assert kinds[:n].tolist() == kinds[n:].tolist()          # warp and weft alike


def test_check_prints_the_mix_and_every_pairs_friction(capsys):
    if not (EXAMPLE.parent.parent / "mandrels" / "case_b.stl").is_file():
        pytest.skip("mandrels/ not built yet")
    assert cli.main(["check", str(EXAMPLE)]) == 0
    err = capsys.readouterr().err
    assert "note: yarns: yarn 36, polyester 12 carriers per group" in err
    for pair, source in (("yarn-yarn", "the type's own friction"),
                         ("yarn-polyester", "[[friction_pair]]"),
                         ("polyester-polyester", "the type's own friction")):
        assert f"note: friction {pair}: 0.25 ({source})" in err


MIX = """
[[yarn_type]]
name = "polyester"
width = 2e-3
thickness = 1.5e-4
linear_density_tex = 110.0
fibre_density = 1380.0
fibre_radius = 1.0e-5

[[friction_pair]]
types = ["yarn", "polyester"]
friction = 0.15
"""


def test_preform_run_of_a_mix_writes_every_yarns_type(tmp_path):
    """A small mixed cylinder through ``preform run`` (kinematic, 16 carriers, 30 mm): done, the
    mix echoed in summary.json, yarns.vtp with each yarn's type, the per-type fields written."""
    import json

    from support.simcase import write_cylinder_case

    out = tmp_path / "out"
    path = write_cylinder_case(tmp_path, braid=0.03, out=out, extra=MIX,
                               yarn_extra="linear_density_tex = 300.0\nfibre_density = 2550.0\n"
                                          "fibre_radius = 6.5e-6",
                               output_extra="pictures = false")
    text = path.read_text().replace("angular_speed = 13.232", "angular_speed = 13.232\n"
                                    'carrier_yarns = ["yarn", "polyester"]')
    path.write_text(text)
    assert cli.main(["run", str(path)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "done"
    inputs = summary["inputs"]
    assert inputs["machine"]["carrier_yarns"] == ["yarn", "polyester"]
    assert inputs["friction_pairs"] == {"1": {"types": ["yarn", "polyester"], "friction": 0.15}}
    vtp = (out / "yarns.vtp").read_bytes()
    for name in (b'Name="yarn_type"', b'Name="yarn_type_yarn"', b'Name="yarn_type_polyester"'):
        assert name in vtp
    surface = (out / "surface.vtu").read_bytes()
    for name in (b"coverage_polyester", b"yarn_length_yarn_m_per_m2", b"areal_weight_kg_m2"):
        assert name in surface
