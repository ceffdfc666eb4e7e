"""How much work a run will be, and the limits beyond which it is refused.

A value can be valid on its own and still ask for unbounded work on a given mandrel:
``[output] field_edge_length = 1e-9`` m asks for ~1e17 field faces, ``[model] time_step = 1e-300`` s
for ~1e300 steps, and 10 000 yarns narrowed to 2 mm cannot lie side by side on a 40 mm tube at any
braid angle. :func:`estimate_work` gives the face and step counts and the size of the results;
:func:`check_work` refuses them above :data:`LIMITS` (each with its reason) unless ``force``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import ConfigError


@dataclass(frozen=True)
class WorkLimits:
    """Refusal thresholds; ``preform run --force`` passes over the face and step limits."""

    #: field faces: the mapping and the surface files take ~1 kB of memory a face (4e6: ~4 GB)
    max_field_faces: float = 4e6
    #: time steps: ~3e5 are a full-size case; 1e7 would be days of wall time and GBs of history
    max_steps: float = 1e7


LIMITS = WorkLimits()
#: bytes of result files per field face (surface.vtu + surface.h5, ~14 cell arrays of float64)
BYTES_PER_FACE = 2 * 14 * 8 + 2 * 3 * 8
#: bytes per yarn point and step (yarns.vtp, checkpoint): position, time, angle, face, flags
BYTES_PER_YARN_STEP = 2 * (3 * 8 + 8 + 8 + 8 + 1)


@dataclass(frozen=True)
class WorkEstimate:
    """field_faces: faces of the field mesh; steps: time steps; result_bytes: size of the results;
    field_edge_m, time_step_s: the field edge length (m) and the time step (s) they were counted
    with (the configured ones or the defaults), for the messages."""

    field_faces: int
    steps: int
    result_bytes: int
    field_edge_m: float = math.nan
    time_step_s: float = math.nan

    def lines(self) -> list[str]:
        return [f"estimated work: {self.field_faces:,} field faces, {self.steps:,} time steps, "
                f"about {self.result_bytes / 1e6:.0f} MB of results"]


def braiding_time(config) -> float:
    """Seconds of process time to feed ``braid_length`` through the take-up speed table."""
    table = np.asarray(config.process.take_up_speed, dtype=float)
    length = float(config.process.braid_length)
    if len(table) == 1:
        return length / float(table[0, 1])
    grid = np.linspace(0.0, length, 2001)
    speed = np.interp(grid, table[:, 0], table[:, 1])
    pace = 1.0 / speed
    return float(np.sum(0.5 * (pace[1:] + pace[:-1]) * np.diff(grid)))


def estimate_work(config, mandrel_area: float, time_step: float, convergence_length=None) -> WorkEstimate:
    """The work of ``config`` on a mandrel of ``mandrel_area`` (m^2) with ``time_step`` (s).

    convergence_length : float, m, the convergence length expected at the end of the run; the
    mandrel then travels ``braid_length + H_end - initial_position`` (the fell points start at the
    tip, ``initial_position`` from the supply plane), not just ``braid_length``.
    """
    from .analysis.fields import DEFAULT_EDGE_WIDTHS

    edge = config.output.field_edge_length if config.output is not None else None
    edge = edge or DEFAULT_EDGE_WIDTHS * config.yarn.width
    faces = _ratio(mandrel_area, math.sqrt(3.0) / 4.0 * edge * edge)
    steps = _ratio(braiding_time(config), time_step)
    if convergence_length is not None:
        length = float(config.process.braid_length)
        travel = max(length + convergence_length - config.process.initial_position, 0.1 * length)
        steps *= travel / length
    points = config.machine.carriers * min(steps, 1e12)
    size = BYTES_PER_FACE * min(faces, 1e15) + BYTES_PER_YARN_STEP * points
    return WorkEstimate(field_faces=_count(faces), steps=_count(steps), result_bytes=_count(size),
                        field_edge_m=float(edge), time_step_s=float(time_step))


def _ratio(a: float, b: float) -> float:
    """a / b for a >= 0, infinite where b is not positive: an edge or a time step so small that
    its square or the quotient leaves the floating-point range asks for unbounded work."""
    return a / b if b > 0 else math.inf


def _count(x: float) -> int:
    return int(min(x, 1e18))


def check_work(config, estimate: WorkEstimate, max_radius: float, *, force=False,
               limits: WorkLimits = LIMITS) -> None:
    """Raise ConfigError for work beyond ``limits`` (unless ``force``) or yarns that cannot fit.

    max_radius : float, m, the largest distance of the braided part's surface from the centerline.
    """
    fix = "; pass --force to run it anyway"
    if not force and estimate.field_faces > limits.max_field_faces:
        if config.output is not None and config.output.field_edge_length:
            edge = f"[output] field_edge_length = {estimate.field_edge_m:g} m"
            expected = f"an edge length of the order of the yarn width ({config.yarn.width:g} m)"
        else:
            edge = (f"the field edge length {estimate.field_edge_m:g} m (from [yarn] width = "
                    f"{config.yarn.width:g} m)")
            expected = "a yarn width of millimetres"
        raise ConfigError(
            f"{edge} asks for about {estimate.field_faces:.3g} field faces (limit "
            f"{limits.max_field_faces:.3g}, ~1 kB of memory each): expected {expected}{fix}")
    if not force and estimate.steps > limits.max_steps:
        if config.model.time_step:
            step = f"[model] time_step = {estimate.time_step_s:g} s"
            expected = "a step of the order of the automatic one (leave time_step out)"
        else:
            step = f"the automatic time step {estimate.time_step_s:g} s"
            expected = "a take-up speed of the order of mm/s to m/s"
        raise ConfigError(
            f"{step} makes about {estimate.steps:.3g} steps over the braided length at [process] "
            f"take_up_speed (limit {limits.max_steps:.3g}): expected {expected}{fix}")
    n = config.machine.carriers
    # the model narrows each yarn down to its least width ([yarn] min_width, paper §2.4.2) where
    # the perimeter is short: the bound is on that width, not on the nominal one
    width = config.yarn.least_width
    if n * width > 4.0 * math.pi * max_radius:
        # one group of n/2 yarns side by side at braid angle 0 covers n w / 2 of the perimeter
        raise ConfigError(
            f"[machine] carriers = {n}: {n // 2} yarns per group, each narrowed to its least width "
            f"{width:g} m ([yarn] min_width), need {n * width / 2:.4g} m of perimeter even laid "
            f"along the mandrel, and its largest perimeter is {2 * math.pi * max_radius:.4g} m: "
            f"expected at most {int(4 * math.pi * max_radius / width)} carriers, or a smaller "
            "[yarn] min_width")
