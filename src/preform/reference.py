"""Quasi-static reference values of a set-up, before or beside a run.

Along the mandrel, with the cross-section's perimeter ``P(s)`` read as the perimeter-equivalent
radius ``r = P / (2 pi)``:

* Ko's steady braid angle ``tan(alpha) = omega r / v`` (paper eq. 2), with the take-up speed at
  that braided length;
* the kinematic steady convergence length ``H_inf = v sqrt(R^2 - r^2) / (omega r)`` (docs/theory.md
  §2), with ``R`` the supply radius (guide ring, else spool);
* the braided length needed to settle: by Du & Popper the start-up transient decays as
  ``exp(-L / H_inf)`` in braided length ``L`` (``omega r t / sqrt(R^2 - r^2)`` with ``L = v t``),
  so from ``H_0`` (the initial position) it is within a fraction ``q`` of ``H_inf`` after
  ``L_settle = H_inf ln(|H_0 - H_inf| / (q H_inf))`` (zero if it starts that close).

These are the numbers ``preform check`` prints and the history plots draw as references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the start-up transient is settled when it has fallen to this fraction (1 %: the steady-state
#: reading's tolerance on H, preform.analysis.steady)
SETTLED_FRACTION = 0.01


@dataclass(frozen=True)
class References:
    """s : (n,) m of centerline from the tip; radius : (n,) perimeter-equivalent radius, m;
    ko_deg : (n,) Ko's braid angle, deg; h_inf : (n,) m; settle_length : (n,) m of braid from
    the initial position to within SETTLED_FRACTION of h_inf."""

    s: np.ndarray
    radius: np.ndarray
    ko_deg: np.ndarray
    h_inf: np.ndarray
    settle_length: np.ndarray

    def at(self, s) -> tuple[float, float]:
        """(Ko's angle in deg, H_inf in m) at arc length s."""
        return (float(np.interp(s, self.s, self.ko_deg)), float(np.interp(s, self.s, self.h_inf)))


def supply_radius(machine_config) -> float:
    ring = machine_config.guide_ring
    return float(ring.radius if ring is not None else machine_config.spool_radius)


def references(config, s, perimeter) -> References:
    """The references at centerline arc lengths ``s`` (m) of sections of ``perimeter`` (m)."""
    s = np.asarray(s, dtype=float)
    r = np.asarray(perimeter, dtype=float) / (2.0 * math.pi)
    speeds = np.asarray(config.machine.angular_speeds, dtype=float)   # braided length ~ s
    omega = (float(speeds[0, 1]) if len(speeds) == 1
             else np.interp(s, speeds[:, 0], speeds[:, 1]))
    table = np.asarray(config.process.take_up_speed, dtype=float)
    v = np.full_like(s, table[0, 1]) if len(table) == 1 else np.interp(s, table[:, 0], table[:, 1])
    R = supply_radius(config.machine)
    ko = np.degrees(np.arctan(omega * r / v))
    with np.errstate(invalid="ignore", divide="ignore"):
        h_inf = np.where((r > 0) & (r < R), v * np.sqrt(np.maximum(R * R - r * r, 0.0)) / (omega * r), np.nan)
    h0 = float(config.process.initial_position)
    with np.errstate(invalid="ignore", divide="ignore"):
        settle = h_inf * np.log(np.abs(h0 - h_inf) / (SETTLED_FRACTION * h_inf))
    return References(s=s, radius=r, ko_deg=ko, h_inf=h_inf, settle_length=np.maximum(settle, 0.0))


def end_convergence_length(config, radius: float) -> float | None:
    """The kinematic convergence length (m) when ``braid_length`` is braided on a section of
    ``radius`` (m): Du & Popper from ``initial_position`` towards H_inf, at the fastest take-up
    speed; None where no tangent yarn exists (radius not inside the supply radius)."""
    from . import analytic

    R = supply_radius(config.machine)
    if not 0 < radius < R:
        return None
    p, omega = config.process, float(config.machine.angular_speed)
    v = max(speed for _, speed in p.take_up_speed)
    return float(analytic.du_popper_convergence_length(p.braid_length / v, p.initial_position,
                                                       omega, radius, v, R))


def check_lines(config, refs: References, length: float | None = None) -> list[str]:
    """What ``preform check`` says of the references over the part to braid; ``length``: the
    centerline's (m), so that advice to braid longer is given only where the mandrel can hold
    it (the braid plus the convergence zone ahead of it)."""
    end = min(config.process.braid_length, refs.s[-1])
    inside = (refs.s >= 0.0) & (refs.s <= end)
    if not np.any(inside) or not np.any(np.isfinite(refs.h_inf[inside])):
        return []
    ko, h, settle = refs.ko_deg[inside], refs.h_inf[inside], refs.settle_length[inside]
    lines = [f"Ko's braid angle {np.nanmin(ko):.1f}-{np.nanmax(ko):.1f} deg, kinematic steady "
             f"convergence length H_inf {np.nanmin(h):.3f}-{np.nanmax(h):.3f} m (perimeter-equivalent "
             "radius, quasi-static)"]
    need = float(np.nanmax(settle))
    if config.process.braid_length < need:
        h_start = float(np.nanmedian(h))
        start = f"start nearer H_inf: [process] initial_position = {h_start:.3g} m"
        if length is not None and need + float(np.nanmax(h)) > length:
            advice = (f"the {length:.3g} m mandrel cannot hold {need:.2f} m of braid and its "
                      f"convergence zone, so {start} (the median H_inf over the part, from where "
                      "the transient has little to settle)")
        else:
            advice = f"braid at least {need:.2f} m, or {start}"
        lines.append(f"braid_length = {config.process.braid_length:g} m is shorter than the "
                     f"{need:.2f} m the start-up transient needs to settle within {SETTLED_FRACTION:.0%} "
                     f"of H_inf from initial_position = {config.process.initial_position:g} m (Du & "
                     f"Popper): this run will not reach steady state; {advice}")
    return lines


#: sections sampled along the braided part for the automatic pose lead
POSE_SECTIONS = 21
#: a centerline whose points stray less than this fraction of its length from its chord is
#: straight: any lead gives the same pose, and 0 keeps the arithmetic of a plain axial feed
STRAIGHT_TOLERANCE = 1e-9


def is_straight(centerline) -> bool:
    pts = np.asarray(centerline.points, dtype=float)
    chord = pts[-1] - pts[0]
    length = float(np.linalg.norm(chord))
    if length == 0.0:
        return True
    u = chord / length
    rel = pts - pts[0]
    off = rel - np.outer(rel @ u, u)
    return float(np.max(np.linalg.norm(off, axis=1))) <= STRAIGHT_TOLERANCE * length


def automatic_pose_lead(config, mandrel, centerline) -> float:
    """The pose lead (m) for ``[process] pose_lead = "auto"``.

    The pose keeps the centerline on the machine axis ``lead`` ahead of the supply plane
    (``geometry.pose_at``). What must stay near the axis is the stretch of centerline inside the
    convergence zone: from the supply plane (where the unbraided mandrel passes the ring) to the
    fell front, about ``H`` ahead of it. On a bend of radius ``R_b``, centring that chord (lead
    ``H / 2``) keeps it within ``H^2 / (8 R_b)`` of the axis, where aligning one end keeps the other
    within ``H^2 / (2 R_b)``, four times as far, and a far end that swings off the axis makes the
    yarns bridge and catch. ``H`` is the kinematic steady ``H_inf`` (the median over the braided
    part's perimeter-equivalent sections); the interaction model's zone is shorter (friction
    shortens it), so ``H_inf / 2`` errs towards the fell front. A straight centerline gets 0: any
    lead poses it the same.
    """
    if is_straight(centerline):
        return 0.0
    from .geometry.centerline import section_perimeters

    end = min(config.process.braid_length, float(centerline.length))
    s = np.linspace(0.0, end, POSE_SECTIONS)
    perimeter = section_perimeters(mandrel, centerline, s)
    ok = perimeter > 0
    if not np.any(ok):
        return 0.0
    h_inf = references(config, s[ok], perimeter[ok]).h_inf
    h_inf = h_inf[np.isfinite(h_inf)]
    return 0.5 * float(np.median(h_inf)) if len(h_inf) else 0.0


def resolve_pose_lead(config, mandrel, centerline):
    """``config`` with ``[process] pose_lead`` a number (the automatic one where it is "auto")."""
    import dataclasses

    if config.process.trajectory is not None:
        return resolve_trajectory(config, centerline)
    if config.process.pose_lead is not None:
        return config
    lead = automatic_pose_lead(config, mandrel, centerline)
    return dataclasses.replace(config, process=dataclasses.replace(config.process, pose_lead=lead))


def resolve_trajectory(config, centerline):
    """``config`` of a run driven by ``[process] trajectory``, checked against the mandrel: its
    tip never behind the supply plane (ConfigError naming the row); ``initial_position`` the
    tip's distance ahead of the supply plane at the path's first row (for the estimates made
    before the run: Du and Popper's transient, the work)."""
    import dataclasses

    from .config import MAX_ANGULAR_SPEED_DEG, MAX_TAKE_UP_SPEED
    from .errors import ConfigError
    from .trajectory import quaternion_to_rotation, read_trajectory, tip_behind_problem

    path = read_trajectory(config.process.trajectory, max_take_up_speed=MAX_TAKE_UP_SPEED,
                           max_angular_speed_deg=MAX_ANGULAR_SPEED_DEG)
    ring = config.machine.guide_ring
    supply_z = 0.0 if ring is None else float(ring.offset)
    tip = np.asarray(centerline.frame_values(0.0)[0], dtype=float)
    problem = tip_behind_problem(path, tip, supply_z)
    if problem:
        raise ConfigError(problem)
    z0 = float((quaternion_to_rotation(path.quaternion[0]) @ tip)[2] + path.position[0, 2])
    return dataclasses.replace(config, process=dataclasses.replace(
        config.process, initial_position=z0 - supply_z))
