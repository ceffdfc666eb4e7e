"""TOML configuration -> frozen dataclasses (DESIGN.md §1).

SI units inside; angles in the file are degrees and are converted here (``angular_speed`` is
stored in rad/s). Paths are resolved against the config file's folder.

The dataclasses below are the contract between the config and the rest of the package.
:func:`load_config` validates everything before any simulation starts and raises
:class:`preform.errors.ConfigError` naming the key, the value and what is expected.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class MandrelConfig:
    stl: Path                       # absolute path
    stl_unit: str = "m"             # "m" | "mm"
    centerline: str | Path = "auto"  # "auto" or absolute path of a CSV (x,y,z in the STL's unit, tip first)
    #: optional direction (STL frame) that the pose maps to machine +x at the tip; None: automatic
    roll_reference: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class GuideRingConfig:
    radius: float                   # m
    offset: float = 0.0             # m, axial distance of the ring plane from the spool plane (towards +z)


@dataclass(frozen=True)
class MachineConfig:
    carriers: int                   # total; half warp, half weft
    spool_radius: float             # m
    angular_speed: float            # rad/s (config file: deg/s)
    pattern: str = "regular"        # "diamond" | "regular" | "hercules"
    guide_ring: GuideRingConfig | None = None

    @property
    def pattern_m(self) -> int:
        """Crossings over (and under) in a row: 1 diamond, 2 regular, 3 hercules."""
        return {"diamond": 1, "regular": 2, "hercules": 3}[self.pattern]


@dataclass(frozen=True)
class YarnConfig:
    width: float                    # m
    thickness: float                # m
    tension: float = 4.7            # N, spool tension
    friction: float = 0.0           # yarn-yarn mu_y
    ring_friction: float = 0.0      # yarn-ring mu_r


@dataclass(frozen=True)
class ProcessConfig:
    #: constant take-up speed (m/s) as a 1-tuple, or a table ((braided_length_m, speed_m_s), ...)
    take_up_speed: tuple[tuple[float, float], ...]
    initial_position: float         # m, mandrel tip to the supply plane at t = 0
    braid_length: float             # m of centerline to braid
    eccentricity: tuple[float, float] = (0.0, 0.0)   # m, machine x, y
    #: axial distance (m) ahead of the supply plane where the pose puts the centerline on the axis
    #: (DESIGN.md §2; see geometry/pose.py). 0: at the supply plane.
    pose_lead: float = 0.0


@dataclass(frozen=True)
class ModelConfig:
    kind: str = "kinematic"         # "kinematic" | "interaction"
    time_step: float | None = None  # s; None: automatic step control
    start: str = "tip"              # "tip" | "random": initial fell points
    seed: int = 0                   # for start = "random"


@dataclass(frozen=True)
class OutputConfig:
    dir: Path                       # absolute path
    field_edge_length: float | None = None   # m; None: a few yarn widths
    snapshots: int = 20             # number of convergence-zone snapshots written


@dataclass(frozen=True)
class Config:
    mandrel: MandrelConfig
    machine: MachineConfig
    yarn: YarnConfig
    process: ProcessConfig
    model: ModelConfig = field(default_factory=ModelConfig)
    output: OutputConfig | None = None
    source: Path | None = None      # the TOML file this came from


def load_config(path) -> Config:  # pragma: no cover - implemented in the config issue work
    raise NotImplementedError
