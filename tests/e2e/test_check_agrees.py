"""``preform check`` agrees with ``preform run``: what makes a run fail for a reason known before
simulating fails check with the same message, and check refuses nothing the model can do.

Cheap cases: a 0.3 m cylinder of 75 mm radius (``simcase.write_cylinder_case``, 16 carriers,
H_inf = 0.054 m), kinematic runs of a few hundred steps.
"""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from support.simcase import write_cylinder_case

import preform as pf
from preform.cli import _quality_line, main
from preform.pipeline import load_geometry, run_case

#: the cylinder case started 0.03 m from the supply plane: its Du & Popper convergence length
#: grows to H_inf = 0.054 m, so the 0.3 m mandrel holds about 0.3 - 0.054 = 0.246 m of braid
START = 'initial_position = 0.03'


def cylinder_case(folder, braid, **kw):
    path = write_cylinder_case(folder, braid=braid, snapshots=0, **kw)
    path.write_text(path.read_text().replace("initial_position = 0.08", START))
    return path


def _error_line(err: str) -> str:
    (line,) = [x for x in err.splitlines() if x.startswith("error: ")]
    return line


def test_a_mandrel_end_the_run_would_pass_fails_check_and_run_with_one_message(tmp_path, capsys):
    """0.26 m of braid needs the tip about 0.26 + 0.054 = 0.314 m past the spool plane on a
    0.3 m mandrel: check and run refuse it with the same line, before simulating."""
    path = cylinder_case(tmp_path, 0.26)
    assert main(["check", str(path)]) == 2
    check_err = _error_line(capsys.readouterr().err)
    assert "the mandrel's end passes the machine before [process] braid_length = 0.26 m" in check_err
    assert "shorten [process] braid_length to at most about 0.246 m" in check_err
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 2
    assert _error_line(capsys.readouterr().err) == check_err
    assert not out.exists()


@pytest.fixture(scope="module")
def past_check(tmp_path_factory):
    """The refused case simulated past the check (``run_case`` with the geometry given): what the
    run itself would have said."""
    folder = tmp_path_factory.mktemp("past_check")
    cfg = pf.load_config(cylinder_case(folder, 0.26))
    mandrel, centerline = load_geometry(cfg)
    return run_case(cfg, folder / "out", geometry=(mandrel, centerline, []))


def test_the_run_past_the_check_stops_with_the_check_s_message(past_check, tmp_path, capsys):
    result = past_check.result
    assert result.status == "failed"
    assert main(["check", str(cylinder_case(tmp_path, 0.26))]) == 2
    check_err = _error_line(capsys.readouterr().err)
    # the same sentence up to the numbers, which the run measures where check estimates them
    same = r"[\d.]+"
    pattern = re.escape(check_err.removeprefix("error: ")).replace(re.escape("0.314"), same)
    for number in re.findall(r"\d+\.\d+", check_err):
        if number not in ("0.26",):
            pattern = pattern.replace(re.escape(number), same)
    assert re.match(pattern, result.message), (check_err, result.message)
    # the estimate and the run agree on the tip's travel within 2 % (cylinder: Du & Popper is
    # the kinematic model's own transient; measured 0.316 m against 0.314 m)
    travel = [float(re.search(r"tip ([\d.]+) m past", m).group(1)) for m in (check_err, result.message)]
    assert travel[1] == pytest.approx(travel[0], rel=0.02)


def test_a_failed_run_is_never_ok_on_the_console_or_in_the_summary(past_check):
    summary = json.loads((past_check.out_dir / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert summary["quality"]["verdict"] != "ok"
    assert _quality_line(summary) != "quality: ok" and "did not finish" in _quality_line(summary)


def test_a_braid_the_mandrel_holds_passes_check_and_runs_to_the_end(tmp_path, capsys):
    """0.22 m of braid needs about 0.274 m of the 0.3 m mandrel: check passes, the run is done."""
    path = cylinder_case(tmp_path, 0.22)
    assert main(["check", str(path)]) == 0
    assert "mandrel's end" not in capsys.readouterr().err
    cfg = pf.load_config(path)
    mandrel, centerline = load_geometry(cfg)
    assert pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=centerline).status == "done"


def test_a_ring_the_mandrel_does_not_pass_fails_check_and_run_alike(tmp_path, capsys):
    path = cylinder_case(tmp_path, 0.1, extra="")
    text = path.read_text().replace("angular_speed = 13.232",
                                    "angular_speed = 13.232\nguide_ring = { radius = 0.07, offset = 0.0 }")
    path.write_text(text)
    assert main(["check", str(path)]) == 2
    check_err = _error_line(capsys.readouterr().err)
    assert "[machine] guide_ring.radius = 0.07" in check_err
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    assert _error_line(capsys.readouterr().err) == check_err


def test_the_carriers_fit_where_the_model_narrows_the_yarns(tmp_path, capsys):
    """64 yarns of 4 mm need 0.128 m a group side by side, more than a 20 mm tube's 0.126 m
    perimeter; narrowed to the default least width (2 mm, half the width) they need 0.064 m, so
    check passes; at min_width = width they cannot narrow, and check refuses them."""
    from preform.geometry import shapes
    from support.simcase import write_centerline, write_stl

    v, f = shapes.cylinder(0.02, 0.3, n_around=48)
    path = cylinder_case(tmp_path, 0.05, carriers=64)
    text = path.read_text()
    text = re.sub(r'stl = ".*"', f'stl = "{write_stl(tmp_path / "thin.stl", v, f)}"', text)
    text = re.sub(r'centerline = ".*"',
                  f'centerline = "{write_centerline(tmp_path / "thin.csv", [[0, 0, 0], [0, 0, 0.3]])}"', text)
    path.write_text(text)
    assert main(["check", str(path)]) == 0
    capsys.readouterr()
    path.write_text(text.replace("width = 4e-3", "width = 4e-3\nmin_width = 4e-3"))
    assert main(["check", str(path)]) == 2
    assert "carriers = 64: 32 yarns per group, each narrowed to its least width 0.004 m" in \
        _error_line(capsys.readouterr().err)


def test_the_transient_note_gives_advice_the_part_can_follow(tmp_path, capsys):
    """From 0.03 m the transient needs H_inf ln(0.0241 / 0.01 H_inf) = 0.0541 x 3.80 = 0.21 m
    to settle; on the 0.3 m mandrel 0.21 m + 0.054 m fits, on a 0.15 m one it does not: there check
    gives only the initial position to start from."""
    path = cylinder_case(tmp_path, 0.05)
    assert main(["check", str(path)]) == 0
    note = [x for x in capsys.readouterr().err.splitlines() if "will not reach steady state" in x]
    assert note and "braid at least 0.21 m" in note[0] and "initial_position = 0.0541 m" in note[0]
    short = cylinder_case(tmp_path / "short", 0.05, length=0.15)
    assert main(["check", str(short)]) == 0
    (note,) = [x for x in capsys.readouterr().err.splitlines() if "will not reach steady state" in x]
    assert "braid at least" not in note
    assert "the 0.15 m mandrel cannot hold 0.21 m of braid" in note and "initial_position = 0.0541 m" in note



def test_a_run_started_beyond_h_inf_needs_less_than_its_start_plus_its_braid(tmp_path, capsys):
    """From 0.12 m (beyond H_inf = 0.054 m) the zone shrinks as the braid grows: 0.2 m of braid
    needs the tip about 0.2 + 0.056 m past the spool plane, less than initial_position +
    braid_length = 0.32 m, which exceeds the 0.3 m mandrel. check passes (the stepper's own
    rule, ``stepping.end_passed``), and the run is done."""
    path = cylinder_case(tmp_path, 0.2)
    path.write_text(path.read_text().replace(START, "initial_position = 0.12"))
    assert main(["check", str(path)]) == 0
    assert "mandrel's end" not in capsys.readouterr().err
    cfg = pf.load_config(path)
    assert cfg.process.initial_position + cfg.process.braid_length > 0.3
    mandrel, centerline = load_geometry(cfg)
    assert pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=centerline).status == "done"


def test_the_interaction_step_estimate_takes_its_own_zone(tmp_path):
    """From 0.03 m the kinematic zone grows towards H_inf = 0.054 m, the interaction model's
    stays near its start: its estimate counts the travel braid_length + initial_position -
    initial_position, the kinematic one braid_length + H_end - initial_position."""
    from preform.pipeline import estimate
    from preform.reference import end_convergence_length

    path = cylinder_case(tmp_path, 0.1)
    kin = pf.load_config(path)
    inter = pf.load_config(path)
    inter = dataclasses.replace(inter, model=dataclasses.replace(inter.model, kind="interaction"))
    mandrel, centerline = load_geometry(kin)
    h_end = end_convergence_length(kin, 0.075)
    assert h_end > kin.process.initial_position
    k, i = estimate(kin, mandrel, centerline), estimate(inter, mandrel, centerline)
    # per unit time step the counts differ by the travel alone (0.1 m against 0.1 + H_end -
    # 0.03 m), to the rounding of the counts (one step)
    per_step = k.steps * k.time_step_s / i.time_step_s
    assert i.steps == pytest.approx(per_step * 0.1 / (0.1 + h_end - 0.03), abs=1.0)
