"""Building simulation configs and mandrels in tests without TOML files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from preform.config import (Config, GuideRingConfig, MachineConfig, MandrelConfig, ModelConfig,
                            OutputConfig, ProcessConfig, YarnConfig)


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
