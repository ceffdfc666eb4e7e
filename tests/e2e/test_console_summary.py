"""What a run tells its user: the work estimate before it simulates, with the model's own step
count; summary.json's references and field statistics; no convergence snapshots from a
kinematic run unless asked for.

Cheap cases: ``simcase.write_cylinder_case`` (a 0.3 m cylinder of 75 mm radius, 16 carriers,
0.06 m braided, no pictures).
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from support.simcase import write_cylinder_case

import preform as pf
from preform.analysis.key_numbers import field_statistics
from preform.pipeline import CHECKPOINT, checked_geometry, estimate, run_case

#: the cylinder case's machine and process (simcase.CYLINDER_CASE)
OMEGA, SPOOL, SPEED, RADIUS, N_AROUND = math.radians(13.232), 0.12, 0.01, 0.075, 64


@pytest.fixture(scope="module")
def kinematic_run(tmp_path_factory):
    """(outcome, summary, notes with what existed when each was said) of a kinematic run."""
    folder = tmp_path_factory.mktemp("kinematic")
    path = write_cylinder_case(folder, output_extra="pictures = false")
    path.write_text(path.read_text().replace("snapshots = 2\n", ""))   # [output] snapshots unset
    cfg = pf.load_config(path)
    out = folder / "out"
    said = []
    outcome = run_case(cfg, out, say=lambda note: said.append(
        (note, (out / CHECKPOINT).exists() or (out / "summary.json").exists())))
    return outcome, json.loads((out / "summary.json").read_text()), said


def test_the_estimate_is_said_before_the_simulation(kinematic_run):
    outcome, summary, said = kinematic_run
    (line,) = [(n, late) for n, late in said if n.startswith("note: estimated work:")]
    # said while the folder held neither the simulation's checkpoint nor its summary
    assert line[1] is False
    assert summary["status"] == "done"


def test_the_interaction_estimate_counts_the_interaction_model_s_steps(tmp_path):
    """The interaction model's step without a ring is the pass-fraction / fell-advance bound
    (``InteractionZone.default_time_step``), not the kinematic one: the estimate's step count
    follows the model's time step, and its cost line says the same count."""
    from preform.machine import Machine
    from preform.stepping import default_time_step

    counts = {}
    for kind in ("kinematic", "interaction"):
        cfg = pf.load_config(write_cylinder_case(tmp_path / kind, kind=kind))
        mandrel, centerline, notes = checked_geometry(cfg)
        work = estimate(cfg, mandrel, centerline)
        dt = default_time_step(cfg, Machine.from_config(cfg.machine), mandrel, centerline, pf.Settings().tolerances)
        assert work.time_step_s == pytest.approx(dt, rel=1e-12)
        counts[kind] = work.steps
        if kind == "interaction":
            assert any(f"about {work.steps:,} time steps" in n for n in notes)
    assert counts["interaction"] != counts["kinematic"]


def test_the_summary_carries_ko_s_angle_and_h_inf_where_the_braid_ends(kinematic_run):
    _, summary, _ = kinematic_run
    # the 64-gon's perimeter-equivalent radius: n r sin(pi / n) / pi
    r = N_AROUND * RADIUS * math.sin(math.pi / N_AROUND) / math.pi
    ko = math.degrees(math.atan(OMEGA * r / SPEED))
    h_inf = SPEED * math.sqrt(SPOOL ** 2 - r ** 2) / (OMEGA * r)
    # the section's perimeter is measured on the mesh's loop: round-off of the polygon's, 1e-6
    assert summary["ko_braid_angle_deg"] == pytest.approx(ko, rel=1e-6)
    assert summary["h_inf_m"] == pytest.approx(h_inf, rel=1e-6)


def test_the_summary_carries_the_field_statistics(kinematic_run):
    _, summary, _ = kinematic_run
    fields = summary["fields"]
    assert set(fields) == {"braid_angle_deg", "cover_factor", "thickness_m"}
    for name, stats in fields.items():
        assert stats["min"] <= stats["mean"] <= stats["max"], name
    # the braid angle on the cylinder lies around Ko's (within the start-up transient's spread)
    assert 30.0 < fields["braid_angle_deg"]["mean"] < 80.0
    assert 0.0 < fields["cover_factor"]["max"] <= 1.0 and fields["thickness_m"]["min"] >= 0.0


def test_field_statistics_are_area_weighted_over_the_reached_faces():
    """Three faces of areas 1, 3 and 2 (right triangles), the last not reached: the mean is
    (1 x 10 + 3 x 20) / 4 = 17.5, min 10, max 20; the unreached face's 99 does not count."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [3, 0, 0], [9, 9, 9], [9, 9, 9],
                  [0, 0, 5], [2, 0, 5], [0, 2, 5]], dtype=float)
    F = np.array([[0, 1, 2], [0, 3, 2], [6, 7, 8]])
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    assert area.tolist() == [1.0, 3.0, 2.0]
    values = np.array([10.0, 20.0, 99.0])
    cd = {"braid_angle_deg": values, "cover_factor": values / 100, "thickness_m": values * 1e-6,
          "reached_warp": np.array([1, 0, 0], np.uint8), "reached_weft": np.array([0, 1, 0], np.uint8)}
    stats = field_statistics(SimpleNamespace(vertices=V, faces=F, cell_data=cd))
    assert stats["braid_angle_deg"] == pytest.approx({"mean": 17.5, "min": 10.0, "max": 20.0})
    assert stats["thickness_m"]["mean"] == pytest.approx(17.5e-6)


def test_a_kinematic_run_writes_no_snapshots_unless_asked(kinematic_run, tmp_path):
    _, summary, _ = kinematic_run
    assert summary["snapshots"] == 0
    assert summary["inputs"]["output"]["snapshots"] == 0
    cfg = pf.load_config(write_cylinder_case(tmp_path, snapshots=3, output_extra="pictures = false"))
    mandrel, centerline, _ = checked_geometry(cfg)
    res = pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=centerline)
    # about 3 (the stride is the estimated step count over 3, so 3 or 4 with the tie's)
    assert 3 <= len(res.snapshots) <= 5


def test_a_layered_run_prints_one_line_per_layer(kinematic_run, tmp_path):
    """The end of ``preform run`` for a run with two layers: the run's three lines, then each
    layer's status, steps and final angles from summary.json's ``layers``."""
    from preform.cli import summary_lines

    outcome, summary, _ = kinematic_run
    layer = {"layer": 2, "direction": "backward", "status": "done", "steps": 1881,
             "braided_length_m": 0.3, "braid_angle_deg": {"final": {"warp": 57.04, "weft": 56.96}},
             "quality": {"verdict": "ok", "reasons": []}}
    first = {**layer, "layer": 1, "direction": "forward", "steps": summary["steps"]}
    lines = summary_lines(outcome.result, tmp_path, 3, {**summary, "layers": [first, layer]})
    assert len(lines) == 5 and lines[3].startswith("layer 1 (forward): done; ")
    assert lines[4] == ("layer 2 (backward): done; 1881 steps, braided length 0.300 m, final braid "
                        "angle warp 57.04 deg, weft 56.96 deg; quality ok")
