"""Building simulation configs and mandrels in tests without TOML files."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

from preform.config import (Config, GuideRingConfig, MachineConfig, MandrelConfig, ModelConfig,
                            OutputConfig, ProcessConfig, YarnConfig)

#: the repository's root
ROOT = Path(__file__).resolve().parents[2]


def write_stl(path: Path, vertices, faces, scale=1.0) -> Path:
    trimesh.Trimesh(np.asarray(vertices) * scale, faces, process=False).export(path)
    return path


def write_centerline(path: Path, points, scale=1.0) -> Path:
    np.savetxt(path, np.asarray(points) * scale, delimiter=",", header="x,y,z", comments="")
    return path


def make_config(stl, centerline="auto", *, stl_unit="m", carriers=16, spool_radius=0.3,
                angular_speed=0.2309401, pattern="regular", guide_ring=None, width=4e-3,
                thickness=2.5e-4, friction=0.2, take_up_speed=0.01, initial_position=0.1,
                braid_length=0.3, eccentricity=(0.0, 0.0), pose_lead=0.0, time_step=None,
                roll_reference=None, out=None, snapshots=5, **yarn_extra) -> Config:
    """A kinematic config; angular_speed in rad/s (default: Ko angle 60 deg at r = 75 mm, v = 10 mm/s)."""
    ring = None if guide_ring is None else GuideRingConfig(*guide_ring)
    yarn = YarnConfig(width=width, thickness=thickness, friction=friction, **yarn_extra)
    return Config(
        mandrel=MandrelConfig(stl=Path(stl), stl_unit=stl_unit, centerline=centerline,
                              roll_reference=roll_reference),
        machine=MachineConfig(carriers=carriers, spool_radius=spool_radius, angular_speed=angular_speed,
                              pattern=pattern, guide_ring=ring),
        yarn=yarn,
        process=ProcessConfig(take_up_speed=((0.0, take_up_speed),), initial_position=initial_position,
                              braid_length=braid_length, eccentricity=tuple(eccentricity),
                              pose_lead=pose_lead),
        model=ModelConfig(kind="kinematic", time_step=time_step),
        output=OutputConfig(dir=Path(out) if out else Path("results"), snapshots=snapshots),
    )


#: a small kinematic case on a 150 mm cylinder: 16 carriers on a 0.12 m spool circle, Ko's 60 deg
CYLINDER_CASE = """
[mandrel]
stl = "{stl}"
centerline = "{csv}"

[machine]
carriers = {carriers}
spool_radius = 0.12
angular_speed = 13.232

[yarn]
width = 4e-3
thickness = 2.5e-4
friction = {friction}
{yarn_extra}

[process]
take_up_speed = 0.01
initial_position = 0.08
braid_length = {braid}

[model]
kind = "{kind}"
{model_extra}

[output]
{out_line}
snapshots = {snapshots}
{output_extra}
{extra}
"""


def write_cylinder_case(folder, *, name="case", length=0.3, kind="kinematic", friction=0.2,
                        braid=0.06, carriers=16, snapshots=2, out=None, yarn_extra="",
                        model_extra="", output_extra="", extra="", n_around=64) -> Path:
    """A case file ``folder/<name>.toml`` on its own cylinder (radius 75 mm, ``length`` m) and
    centerline; results in ``out`` (default: the config's default folder)."""
    from preform.geometry import shapes

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    v, f = shapes.cylinder(0.075, length, n_around=n_around)
    stl = write_stl(folder / "c.stl", v, f)
    csv = write_centerline(folder / "c.csv", [[0, 0, 0], [0, 0, length]])
    path = folder / f"{name}.toml"
    path.write_text(CYLINDER_CASE.format(
        stl=stl, csv=csv, carriers=carriers, friction=friction, yarn_extra=yarn_extra, braid=braid,
        kind=kind, model_extra=model_extra, out_line="" if out is None else f'dir = "{out}"',
        snapshots=snapshots, output_extra=output_extra, extra=extra))
    return path


def case_b_like_config(folder, ring_friction):
    """An interaction-model config on a case-B-like mandrel (rounded square blending into a
    circle, 0.6 m) with case B's ring (0.17 m) and spool (0.85 m) radii, 16 carriers, 18 deg/s,
    26.3 mm/s, 0.3 m braided, no snapshots; files in ``folder``."""
    import dataclasses

    from preform.geometry import shapes

    folder = Path(folder)
    v, f = shapes.case_b(length=0.6, blend=(0.35, 0.45), n_around=96)
    stl = write_stl(folder / "b.stl", v, f)
    cl = write_centerline(folder / "b.csv", [[0, 0, 0], [0, 0, 0.6]])
    cfg = make_config(stl, cl, carriers=16, spool_radius=0.85, friction=0.25,
                      ring_friction=ring_friction, guide_ring=(0.17, 0.0), braid_length=0.3,
                      initial_position=0.2, angular_speed=np.radians(18.0), take_up_speed=0.0263,
                      eccentricity=(0.02, 0.0), snapshots=0)
    return dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"))


def case_a_interaction_config(carriers, mu, solver="newton"):
    """``examples/case_a.toml`` with the interaction model (``solver``), ``carriers`` carriers,
    yarn friction ``mu`` and no snapshots: the case A steps the relaxation tests capture."""
    import dataclasses

    from preform.config import load_config

    cfg = load_config(ROOT / "examples" / "case_a.toml")
    return dataclasses.replace(
        cfg, model=dataclasses.replace(cfg.model, kind="interaction", solver=solver),
        machine=dataclasses.replace(cfg.machine, carriers=carriers),
        yarn=dataclasses.replace(cfg.yarn, friction=mu),
        output=dataclasses.replace(cfg.output, snapshots=0))


def advanced_stepper(cfg, steps, settings=None):
    """(stepper, take-up speed function) of ``cfg`` (its pose lead resolved) after ``steps``
    steps; ``settings``: the interaction model's (None: its defaults)."""
    from preform.reference import resolve_pose_lead
    from preform.settings import Settings
    from preform.simulation import load_geometry, make_stepper
    from preform.stepping import take_up_speed

    mandrel, cl = load_geometry(cfg)
    cfg = resolve_pose_lead(cfg, mandrel, cl)
    s = make_stepper(cfg, mandrel, cl,
                     settings=None if settings is None else Settings(interaction=settings))
    return advance(s, cfg, steps)


def advance(s, cfg, steps):
    """Advance the stepper ``s`` of ``cfg`` by ``steps`` steps; (s, take-up speed function)."""
    from preform.stepping import take_up_speed

    speed = lambda: take_up_speed(cfg.process.take_up_speed, s.braided)  # noqa: E731
    for _ in range(steps):
        s.advance(speed())
    return s, speed


def capture_step(s, speed):
    """(state, boundary with wall planes, top tensions, friction centres) of the step the
    interaction stepper ``s`` takes next, on copies: the problem ``InteractionZone.step`` poses
    its solver (fell points anchored, crossings created, normals radial)."""
    import copy

    from preform._kernels import frontal as FK
    from preform.interaction import frontal

    t0, dt = s.clock.t, s.dt
    pose_end = s.pose(s.clock.travel + speed() * dt)
    z = copy.deepcopy(s.zone)
    bc = z.boundary(t0 + dt, pose_end.to_machine(s.F))
    st = z.state
    st.material_fell[:] = frontal.fell_material(st, bc)
    z._create_crossings(t0, t0 + dt, bc)
    FK.radial_normals(st.m, st.pos, st.normal)
    z.pose_end = pose_end
    return st, z._with_wall(bc), z.f_top.copy(), frontal.friction_centres(st).copy()


def snapshot_solves(st, bc, centre, newton_only):
    """A snapshot's final solve (``friction_tol`` given) of the posed ``st`` through
    ``relax.solve_zone``, with the default settings and with ``newton_only`` (the
    ``RelaxSettings`` that send it to Newton's frontal iteration alone), on copies:
    ((state, report) by default, (state, report) by Newton alone)."""
    from preform.interaction import relax as R
    from preform.interaction.settings import DEFAULT

    fr = DEFAULT.frontal
    out = []
    for settings in (None, newton_only):
        x = st.copy()
        report = R.solve_zone(x, bc, centre=centre, max_iter=fr.snapshot_iterations,
                              friction_tol=fr.snapshot_tolerance, relax_settings=settings,
                              mode="final")
        out.append((x, report))
    return out


def write_cone_case(folder, *, name, braid_length, pictures=True) -> Path:
    """``folder/<name>.toml``: a short kinematic run on the shipped 1 m cone (16 carriers, from
    0.15 m at 10 mm/s), results in ``folder/results/<name>``, no snapshots; about a second."""
    path = Path(folder) / f"{name}.toml"
    path.write_text(f"""
[mandrel]
stl = "{ROOT / 'mandrels' / 'cone.stl'}"
centerline = "{ROOT / 'mandrels' / 'cone_centerline.csv'}"
[machine]
carriers = 16
spool_radius = 0.25
angular_speed = 20.0
[yarn]
width = 4e-3
thickness = 2.5e-4
[process]
take_up_speed = 0.01
initial_position = 0.15
braid_length = {braid_length}
[output]
dir = "results/{name}"
snapshots = 0
{"" if pictures else "pictures = false"}
""")
    return path


#: the larger validations (48 carriers, the bent tube's snapshots) of cases the suite also checks
#: at 16 carriers: run with ``PREFORM_FULLSIZE=1``, like ``tests/validation/test_fullsize.py``
FULL_SIZE = pytest.mark.skipif(os.environ.get("PREFORM_FULLSIZE") != "1",
                               reason="a larger case of a validation the suite runs small: set PREFORM_FULLSIZE=1")
