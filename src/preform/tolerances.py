"""Numerical tolerances and solver defaults, in one place (used by code and tests)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerances:
    #: relative length below which two mesh vertices are merged (times the bounding-box diagonal)
    merge_vertices: float = 1e-9
    #: crease angle (deg) above which vertex normals are not averaged across an edge
    crease_angle_deg: float = 60.0
    #: tangency root: |g| below this (m) counts as tangent
    tangency: float = 1e-10
    #: offset (m, times the bounding-box diagonal) used to start rays just off the surface
    ray_offset: float = 1e-7
    #: maximum fell-point advance per step as a fraction of the yarn width (step control)
    max_fell_advance: float = 0.5
    #: maximum carrier rotation per step (rad) (step control)
    max_carrier_rotation: float = 0.01
    #: interaction model: maximum time step as a fraction of the pass period (the time between two
    #: passes along one yarn, ``Machine.pass_period``), and maximum fell-point advance per step as
    #: a fraction of the yarn width (``simulate.default_time_step``)
    interaction_pass_fraction: float = 1.0 / 3.0
    interaction_fell_advance: float = 2.0


tol = Tolerances()
