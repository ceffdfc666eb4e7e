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
