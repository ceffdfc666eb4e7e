"""``preform.Settings``: one tree of every numerical setting, passed from ``simulate`` and
``pipeline.run_case`` down to the stage that uses each branch.

Checked: that ``Settings()`` is, branch by branch, the default each stage's own function takes
when given none (read from the functions' signatures, so a default changed in one place and not
the other fails here), that each knob is one field (the relaxation solves to the Newton
reference's tolerances and floor; what differs by model is the zone's, reached through
``zone.ZONES``), and that a non-default knob given through the tree reaches the stage that
uses it: a balance tolerance the relaxation's own failure message names, the frontal
tolerance and iterations its consistent bounds stop by, the geometric floor its
preconditioner uses, a near clearance the
interaction zone's mandrel look-ups hold, the tolerances the stepper's time step follows, the
work limits the estimate refuses by, and the verdict's, steady state's, interlacing's and field
mesh's settings in the files of one short run, each against the stage called directly with the
same settings.
"""

from __future__ import annotations

import dataclasses
import inspect
import json

import numpy as np
import pytest

import preform as pf
from preform.budget import LIMITS, check_work
from preform.errors import ConfigError
from preform.analysis.fields import default_edge_length, field_mesh, map_to_surface
from preform.geometry.offset import offset_surface
from preform.geometry.remesh import RemeshSettings, isotropic_remesh
from preform.interaction import relax
from preform.interaction.mandrel_distance import NEAR, MandrelDistance, NearSettings
from preform.interaction.settings import DEFAULT as INTERACTION
from preform.analysis.interlacing import INTERLACING, interlacing
from preform.machine import Machine
from preform.analysis.quality import QUALITY, assess, surface_reasons
from preform.analysis.rtm import BINNING, bin_cells, solver_properties
from preform.settings import DEFAULT, Settings
from preform.simulation import load_geometry, make_stepper, make_zone
from preform.analysis.steady import STEADY, steady_state
from preform.structural.layup import BinSettings, bin_plies
from preform.tolerances import tol
from preform.io.maps import write_surface_map
from preform.io.plots import plot_history
from preform.io.render3d import render_braided_mandrel
from preform.io.surface import write_surface_pictures
from preform.settings import PICTURES
from support.simcase import write_cylinder_case


def _default(function, name):
    """The default value of parameter ``name`` of ``function``."""
    return inspect.signature(function).parameters[name].default


def test_the_tree_is_the_defaults_every_stage_takes():
    """``Settings()``: each branch equal to the module default and to the default argument of
    the function of the stage that uses it."""
    s = Settings()
    assert s == DEFAULT
    assert s.tolerances == tol
    assert s.interaction == INTERACTION
    assert s.interaction.relax == _default(relax.relax, "settings") == relax.RelaxSettings()
    assert s.interaction.near == NEAR == _default(MandrelDistance.__init__, "settings")
    assert s.remesh == _default(isotropic_remesh, "settings") == _default(map_to_surface, "remesh")
    assert s.remesh == _default(field_mesh, "remesh")
    assert s.offset == _default(offset_surface, "settings")
    assert s.interlacing == INTERLACING == _default(interlacing, "settings")
    assert s.steady == STEADY == _default(steady_state, "settings")
    assert s.quality == QUALITY == _default(assess, "settings") == _default(surface_reasons, "settings")
    assert s.limits == LIMITS == _default(check_work, "limits")
    assert s.binning == BinSettings() == _default(bin_plies, "settings")
    assert s.rtm == BINNING == _default(bin_cells, "settings")
    assert _default(solver_properties, "settings") is None and _default(solver_properties, "n_sets") is None
    assert s.pictures == PICTURES == _default(plot_history, "pictures") == _default(write_surface_pictures, "pictures")
    assert s.pictures == _default(render_braided_mandrel, "pictures") == _default(write_surface_map, "pictures")
    # frozen all the way down: a knob is changed by building another tree
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.interaction.relax.max_iter = 1


def test_a_branch_instead_of_the_tree_is_refused_by_name(tmp_path):
    cfg = pf.load_config(write_cylinder_case(tmp_path, kind="interaction", braid=0.01))
    with pytest.raises(TypeError, match=r"settings = InteractionSettings\(\.\.\.\): expected a "
                                        r"preform\.Settings.*Settings\(interaction=\.\.\.\)"):
        pf.simulate(cfg, progress=False, settings=INTERACTION)


@pytest.fixture(scope="module")
def interaction_case(tmp_path_factory):
    """A 16-carrier interaction run on a cylinder, 1 cm braided, and its geometry."""
    folder = tmp_path_factory.mktemp("tree_interaction")
    cfg = pf.load_config(write_cylinder_case(folder, kind="interaction", braid=0.01, snapshots=0))
    return cfg, *load_geometry(cfg)


def test_a_near_clearance_reaches_the_zones_mandrel_look_ups(interaction_case):
    cfg, mandrel, _ = interaction_case
    near = NearSettings(wall_clearance=1.25e-3, reach=3e-2)
    tree = Settings(interaction=dataclasses.replace(INTERACTION, near=near))
    zone = make_zone(cfg, Machine.from_config(cfg.machine), mandrel, tree)
    assert zone.settings.near == near
    assert zone.distance.settings == near          # the object that looks the faces up
    assert make_zone(cfg, Machine.from_config(cfg.machine), mandrel).distance.settings == NEAR


def test_the_balance_tolerance_reaches_the_relaxation(interaction_case):
    """One relaxation iteration a step, no Newton fallback, no staged retry of a failed step,
    and a balance tolerance (``NewtonSettings.balance_tolerance``, the one both solvers take)
    of 3.21e-9: the run stops at its first step with crossings, with the relaxation's own
    message naming that iteration limit and that tolerance (the defaults converge: 200
    iterations, 1e-7)."""
    cfg, mandrel, centerline = interaction_case
    rs = dataclasses.replace(INTERACTION.relax, max_iter=1, newton_fallback=False)
    tree = Settings(interaction=dataclasses.replace(
        INTERACTION, relax=rs, zone=dataclasses.replace(INTERACTION.zone, boundary_stages=()),
        newton=dataclasses.replace(INTERACTION.newton, balance_tolerance=3.21e-9)))
    res = pf.simulate(cfg, progress=False, mandrel=mandrel, centerline=centerline, settings=tree)
    assert res.status == "failed"
    assert "after 1 iterations (tolerance 3.21e-09" in res.message


def test_the_relaxation_has_no_knob_of_the_model_twice():
    """The relaxation's own settings are its iteration's; the tolerances, iteration limits and
    constants of the equations it shares with the Newton reference are fields of the Newton,
    frontal and energy settings only (no name of theirs, nor the short names a tolerance or a
    floor went by, among the relaxation's)."""
    own = {f.name for f in dataclasses.fields(relax.RelaxSettings)}
    shared = {f.name for branch in (INTERACTION.newton, INTERACTION.frontal, INTERACTION.energy)
              for f in dataclasses.fields(branch)}
    assert not own & shared
    assert not own & {"tol", "floor", "friction_tol", "bound_iterations"}


@pytest.fixture(scope="module")
def captured_step(interaction_case):
    """(args, keywords) of ``relax.relax`` for the first step of ``interaction_case``'s run with
    at least 20 crossings, as its zone poses it to the solver."""
    from support.simcase import advance, advanced_stepper, capture_step

    cfg = interaction_case[0]
    stepper, speed = advanced_stepper(cfg, 0)
    for _ in range(400):
        st, bc, _, centres = capture_step(stepper, speed)
        if st.m >= 20:
            break
        advance(stepper, cfg, 1)
    assert st.m >= 20
    m = st.m
    bounds, f_top = relax.start_bounds(st, bc)
    args = (relax.lattice_of(st), st.pos[:m], st.material[:m], st.material_fell, centres[:m],
            bc.fell, bc.top, f_top, bounds)
    return args, dict(f_spool=bc.f_spool, mu=bc.mu, h=bc.h, width=bc.width, plane=bc.plane,
                      top_tensions=relax.ring_top_tensions(st, bc))


def _model(**branches):
    """The interaction settings with ``branch={field: value}`` changed."""
    return dataclasses.replace(INTERACTION, **{
        name: dataclasses.replace(getattr(INTERACTION, name), **fields)
        for name, fields in branches.items()})


def test_the_geometric_floor_reaches_the_relaxation(captured_step):
    """``EnergySettings.geometric_floor`` is the least force density of the relaxation's
    preconditioner too: a floor of 10 N (above every tension, 4.7 N spool tension) changes the
    iteration, not its fixed point (positions within 1e-6 m, the relaxation tests' bound)."""
    args, kw = captured_step
    plain = relax.relax(*args, **kw)
    floored = relax.relax(*args, model=_model(energy=dict(geometric_floor=10.0)), **kw)
    assert plain.converged and floored.converged
    assert not np.array_equal(plain.history, floored.history)
    assert np.abs(plain.pos - floored.pos).max() < 1e-6


def test_the_frontal_tolerance_and_iterations_reach_the_consistent_relaxation(captured_step):
    """With consistent bounds the relaxation solves the step again up to
    ``FrontalSettings.max_iterations - 1`` times, until the bounds change by less than
    ``friction_tolerance``: with 3 iterations and a tolerance of 1e300 (every change is below it)
    it stops after the first solve; with a tolerance of 1e-300 it takes all three solves."""
    args, kw = captured_step
    once = relax.relax(*args, **kw)
    loose = relax.relax(*args, consistent=True, **kw,
                        model=_model(frontal=dict(max_iterations=3, friction_tolerance=1e300)))
    tight = relax.relax(*args, consistent=True, **kw,
                        model=_model(frontal=dict(max_iterations=3, friction_tolerance=1e-300)))
    assert loose.iterations == once.iterations and loose.converged
    assert tight.iterations > loose.iterations and not tight.converged


def test_what_differs_by_model_is_the_zones(interaction_case):
    """The cost note said before a run and whether a first run starts the compiling worker are
    the zone class's (``zone.ZONES``, ``Zone.cost_note`` and ``first_run_worker``): the load
    stage's notes carry the interaction zone's note with the estimate's steps, and none for
    the kinematic model."""
    from preform import _jit
    from preform.pipeline import checked_geometry, estimate
    from preform.zone import ZONES, Zone, zone_class

    cfg = interaction_case[0]
    for kind in ZONES:
        zone = zone_class(kind)
        assert isinstance(zone.cost_note, str) and isinstance(zone.first_run_worker, bool)
        assert {"cost_note", "first_run_worker"} <= set(Zone.__annotations__)
        on = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind=kind))
        mandrel, centerline, notes = checked_geometry(on)
        said = [n for n in notes if n.startswith('note: [model] kind = ')]
        if zone.cost_note:
            steps = estimate(on, mandrel, centerline, force=True).steps
            assert said == [f"note: {zone.cost_note.format(steps=steps)}"]
        else:
            assert said == []
        warmup = _jit.Warmup(on, "unused.toml")
        assert (warmup.compiles.first is not None) == zone.first_run_worker
    assert zone_class("interaction").cost_note and not zone_class("kinematic").cost_note


def test_the_tolerances_reach_the_stepper(interaction_case):
    """A third of the carrier rotation per step: the kinematic step a third as long."""
    cfg, mandrel, centerline = interaction_case
    kin = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="kinematic"))
    finer = dataclasses.replace(tol, max_carrier_rotation=tol.max_carrier_rotation / 3.0)
    a = make_stepper(kin, mandrel, centerline)
    b = make_stepper(kin, mandrel, centerline, settings=Settings(tolerances=finer))
    assert b.dt < a.dt and b.dt <= finer.max_carrier_rotation / b.machine.omega


def test_the_work_limits_reach_the_estimate(tmp_path):
    """A limit of 10 steps refuses a run of more before anything is simulated or written."""
    from preform.pipeline import run_case

    cfg = pf.load_config(write_cylinder_case(tmp_path, braid=0.02, snapshots=0))
    limits = dataclasses.replace(LIMITS, max_steps=10)
    with pytest.raises(ConfigError, match="steps"):
        run_case(cfg, tmp_path / "out", settings=Settings(limits=limits))
    assert not (tmp_path / "out" / "summary.json").exists()


#: the run's non-default settings, each to be seen in its files
QUALITY_STRICT = dataclasses.replace(QUALITY, max_fell_jump=1e-3)
STEADY_LONG_TAIL = dataclasses.replace(STEADY, fit_fraction=0.9, angle_deg=10.0, rel_H=0.5)
INTERLACING_COARSE = dataclasses.replace(INTERLACING, points_per_yarn=2)
REMESH_FEW = dataclasses.replace(RemeshSettings(), iterations=1)
BINNING_COARSE = BinSettings(angle_step_deg=5.0)
RTM_FEW_SETS = dataclasses.replace(BINNING, sets=2)


@pytest.fixture(scope="module")
def strict_run(tmp_path_factory):
    """(result, summary.json, folder) of a short kinematic run on a cylinder, with tow data and a
    material (so the RTM fields and the shell deck are written), through ``pipeline.run_case``
    with the non-default settings above."""
    from preform.pipeline import run_case

    folder = tmp_path_factory.mktemp("tree_run")
    cfg = pf.load_config(write_cylinder_case(
        folder, braid=0.05, carriers=48, snapshots=0, output_extra="pictures = false",
        yarn_extra="linear_density_tex = 800.0\nfibre_density = 1780.0\nfibre_radius = 3.5e-6",
        extra='[rtm]\ncavity_thickness = 1e-3\n[material]\npreset = "AS4/3501-6"'))
    tree = Settings(quality=QUALITY_STRICT, steady=STEADY_LONG_TAIL, interlacing=INTERLACING_COARSE,
                    remesh=REMESH_FEW, binning=BINNING_COARSE, rtm=RTM_FEW_SETS)
    outcome = run_case(cfg, folder / "out", settings=tree)
    summary = json.loads((folder / "out" / "summary.json").read_text())
    return outcome.result, summary, folder / "out"


def test_a_quality_threshold_reaches_the_verdict(strict_run):
    """A fell-front jump threshold of 1e-3 take-up advances: steps exceed it, so the written
    verdict is suspect for that reason; the same run under the default threshold (5) has no
    such reason."""
    result, summary, _ = strict_run
    jumps = [r for r in summary["quality"]["reasons"] if r.startswith("the fell front jumps")]
    assert summary["status"] == "done" and summary["quality"]["verdict"] == "suspect"
    assert len(jumps) == 1 and "more than 0.001x the take-up advance" in jumps[0]
    assert not [r for r in assess(result)["reasons"] if r.startswith("the fell front jumps")]


def test_the_steady_and_interlacing_settings_reach_the_summary(strict_run):
    """summary.json's steady state and interlacing are those of the stages called with the
    tree's settings, and differ from the defaults'."""
    result, summary, _ = strict_run
    ours = json.loads(json.dumps(steady_state(result.history, STEADY_LONG_TAIL)))
    assert summary["steady_state"] == ours
    assert ours != json.loads(json.dumps(steady_state(result.history)))
    coarse = interlacing(result.yarns, result.centerline, settings=INTERLACING_COARSE)
    default = interlacing(result.yarns, result.centerline)
    assert summary["interlacing"]["crossings"] == coarse.measured
    assert summary["interlacing"]["band_m"] == [coarse.s_start, coarse.s_end]
    # the pattern's crossings over the band, integrated along the yarns' points used: two
    # points a yarn move it in the 7th digit, exactly the value written
    assert summary["interlacing"]["pattern_crossings"] == coarse.pattern != default.pattern


def test_the_remesh_settings_reach_the_field_mesh(strict_run):
    """surface.vtu's faces and vertices are those of the field mesh remeshed with the tree's
    settings, which differ from the default remesh's."""
    import pyvista as pv

    result, _, out = strict_run
    written = pv.read(out / "surface.vtu")
    h = default_edge_length(result)
    V, F, _, _ = field_mesh(result, h, REMESH_FEW)
    V0, F0, _, _ = field_mesh(result, h)
    assert written.n_cells == len(F)
    assert np.array_equal(np.asarray(written.points, dtype=float), V)
    assert len(F0) != len(F) or not np.array_equal(V0, V)


def test_the_binning_reaches_the_shell_deck(strict_run):
    """Ply angles binned to 5 deg: the deck's largest angle change is above the 0.125 deg the
    default 0.25 deg step allows (half a step) and within half the coarse step."""
    _, summary, out = strict_run
    structural = summary["structural"]
    assert structural["written"] and (out / "fe" / "preform.inp").is_file()
    assert 0.125 < structural["binning_error"]["angle_deg"] <= 2.5


def test_the_rtm_sets_reach_the_rtm_files(strict_run):
    """Two property sets: the faces without preform take one, the preform's K1 the other (the
    default four give this run four)."""
    _, summary, out = strict_run
    assert summary["rtm"]["written"] and (out / "rtm" / "rtmsim.bdf").is_file()
    assert summary["rtm"]["sets"] == 2


def test_the_picture_settings_reach_the_pictures(strict_run, tmp_path):
    """History figures at 50 dots per inch through the tree: 7.2 in x 50 = 360 px wide (the
    default 150 dpi: 1080 px), drawn by the job the results' writer runs."""
    from PIL import Image

    from preform.io import _picture_jobs

    result = strict_run[0]
    result = dataclasses.replace(result, config=dataclasses.replace(
        result.config, output=dataclasses.replace(result.config.output, pictures=True)))
    tree = Settings(pictures=dataclasses.replace(PICTURES, history_dpi=50))
    (plot,) = [job for job in _picture_jobs(result, None, tmp_path,
                                                      pictures=tree.pictures)[0]
               if "plots/braid_angle.png" in job.names]
    paths = plot.draw()
    assert Image.open(paths[0]).size[0] == 360
    assert PICTURES.history_dpi * PICTURES.history_size_in[0] == 1080
