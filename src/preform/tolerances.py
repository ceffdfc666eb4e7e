"""Numerical tolerances and settings of the geometry and the time stepper, in one place.

One frozen :class:`Tolerances` object, ``tol``, is the default everywhere; a run takes it as the
``tolerances`` branch of its settings' tree (``preform.simulate(config,
settings=preform.Settings(tolerances=...))``), so tests and studies run with other settings by
passing another object (``dataclasses.replace(tol, ...)``), never by editing a module. The
interaction solver's own constants live in ``preform.interaction.settings``.
"""

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
    #: a fraction of the yarn width (``stepping.default_time_step``)
    interaction_pass_fraction: float = 1.0 / 3.0
    interaction_fell_advance: float = 2.0
    #: yarns are tied this many yarn widths from the tip along the centerline: clear of the tip's
    #: edge, where the smooth normals of the cap and the side blend
    tie_offset_widths: float = 2.0
    #: the catch test casts the free yarn from its own centerline, half a yarn thickness off the
    #: surface (in thicknesses) ...
    catch_clearance_thickness: float = 0.5
    #: ... and at least this fraction of the mandrel's diagonal off it, clear of ray round-off
    catch_clearance_diagonal: float = 1e-5
    #: a concave stretch is flagged ``bridge`` only where the straight span stands off the surface
    #: by more than this many yarn thicknesses: the micrometre dips of a faceted (e.g. offset)
    #: mesh lie within the yarn's own thickness, the yarn lies on them
    bridge_depth_thickness: float = 0.1
    #: longest straight piece (in yarn widths) of a fell point's walk over the surface: the walk
    #: follows the smooth normals, a piece this short keeps it on a curved surface
    walk_piece_widths: float = 0.5
    #: longest walk of a fell point in one step: this many times what the machine moves a point
    #: in a step (carrier speed at the mandrel's size plus take-up) ...
    walk_reach_factor: float = 20.0
    #: ... and at least this many yarn widths: a walk that needs more has lost the surface
    walk_reach_widths: float = 10.0
    #: steps between updates of the braided length (the stopping test and the progress bar): the
    #: projection of all fell points costs about a step
    braided_length_every: int = 10
    #: sample spacing (m) of the centerline for the arc length of points (``analysis.
    #: CenterlineProjector``), refined to the exact projection on the nearest segments
    projector_spacing: float = 5e-4
    #: slip tendency (docs/theory.md §3): |kappa_g| exceeds mu |kappa_n| by more than this (1/m), so
    #: that round-off on a geodesic (kappa_g = 0 exactly) never flags
    slip_curvature: float = 1e-9


tol = Tolerances()
