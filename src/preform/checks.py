"""Pre-flight checks of a whole set-up, once the mandrel and centerline are loaded (docs/guide/commands.md).

:func:`load_config` checks every value on its own; :func:`preflight` checks them against the
geometry: impossible set-ups raise (before any simulation starts), doubtful ones come back as
warnings for the user to read.

Only these attributes of the geometry objects are used, so any object providing them works:
``mandrel.vertices`` ((nv, 3) float64, m, mandrel frame), ``mandrel.diagonal`` (float, m, bounding
box), ``centerline.length`` (float, m) and ``centerline.project(points) -> (s, distance)`` ((nv,)
arc length from the tip and distance from the centerline, m).
"""

from __future__ import annotations

import math

import numpy as np

from . import analytic
from .errors import ConfigError, MandrelError
from .stepping import end_message, end_passed, setting_at
from .tolerances import tol

#: a mandrel that does not fit the spool circle and whose bounding-box diagonal exceeds this many
#: spool radii was read in the wrong unit (a long slender mandrel that fits is fine)
MAX_DIAGONAL_SPOOL_RADII = 20.0
#: ... or one smaller than this many yarn widths
MIN_DIAGONAL_YARN_WIDTHS = 2.0
#: warn when the gap between mandrel and supply radius is below this fraction of the supply radius
MIN_RADIAL_CLEARANCE = 0.05
#: warn outside this range of Ko's braid angle estimate (deg)
BRAID_ANGLE_RANGE_DEG = (10.0, 80.0)
#: warn above this yarn-yarn friction coefficient (measured values: 0.15-0.4, paper §1)
HIGH_FRICTION = 1.0
#: warn when a fixed time step turns the carriers by more than this many times the automatic bound
TIME_STEP_FACTOR = 10.0
#: sections (bins along the centerline) used for the braid-angle and jamming estimates
ESTIMATE_SECTIONS = 50


def preflight(config, mandrel, centerline) -> list[str]:
    """Check a config against its geometry; raise for impossible set-ups, return warnings.

    Raises ConfigError (or MandrelError where no config key can fix it) when the mandrel's unit is
    implausible for the machine (much larger than the machine and not fitting it, or smaller than
    two yarn widths), when the part of the mandrel that passes the machine
    (``s <= initial_position + braid_length``) plus the eccentricity does not fit inside the guide
    ring and the spool circle, when the mandrel's end has passed the machine at the start
    (:func:`_check_start`), or when a kinematic run's mandrel end would pass the machine before
    braid_length is braided (:func:`mandrel_end_problem`, the run's own rule and message; a
    warning for the interaction model).
    """
    vertices = np.asarray(mandrel.vertices, dtype=float)
    if vertices.ndim != 2 or len(vertices) == 0:
        raise MandrelError(f"{config.mandrel.stl}: the mandrel has no vertices")
    s, distance = (np.asarray(a, dtype=float) for a in centerline.project(vertices))
    _check_unit(config, float(mandrel.diagonal), float(distance.max()))
    _check_braid_length(config, float(centerline.length))
    _check_centerline_inside(config, mandrel, centerline)
    passing = s <= config.process.initial_position + config.process.braid_length
    reach = float(np.max(distance[passing], initial=0.0)) + config.process.largest_eccentricity
    warnings = _check_fit(config, reach)
    warnings += _braid_angle_warnings(config, s[passing], distance[passing])
    _check_time_step(config)
    from .reference import resolve_pose_lead

    lead = float(resolve_pose_lead(config, mandrel, centerline).process.pose_lead)
    _check_start(config, float(centerline.length), lead)
    radius = float(np.median(distance[passing])) if np.any(passing) else 0.0
    warnings += _check_mandrel_end(config, float(centerline.length), radius, lead,
                                   _section_changes(s[passing], distance[passing]))
    warnings += _value_warnings(config)
    return warnings


def _check_unit(config, diagonal: float, section_radius: float) -> None:
    """The mandrel's size against the machine: mm read as m (or m read as mm).

    diagonal : bounding-box diagonal (m). section_radius : largest distance from the centerline (m).
    """
    unit = config.mandrel.stl_unit
    spool = config.machine.spool_radius
    where = f'[mandrel] stl_unit = "{unit}"'
    if diagonal > MAX_DIAGONAL_SPOOL_RADII * spool and section_radius >= spool:
        size = (f"the mandrel's bounding-box diagonal is {diagonal:.4g} m, more than "
                f"{MAX_DIAGONAL_SPOOL_RADII:g} x [machine] spool_radius = {spool:g} m, and its "
                f"cross-section ({section_radius:.4g} m from the centerline) does not fit the spool circle")
        if unit == "m":
            raise ConfigError(f'{where}: {size}; is the STL in millimetres? expected stl_unit = "mm"')
        raise MandrelError(f"{config.mandrel.stl}: {size}; expected a mandrel that fits the machine")
    width = config.yarn.width
    if diagonal < MIN_DIAGONAL_YARN_WIDTHS * width:
        size = (f"the mandrel's bounding-box diagonal is {diagonal:.4g} m, less than "
                f"{MIN_DIAGONAL_YARN_WIDTHS:g} x [yarn] width = {width:g} m")
        if unit == "mm":
            raise ConfigError(f'{where}: {size}; is the STL in metres? expected stl_unit = "m"')
        raise MandrelError(f"{config.mandrel.stl}: {size}; expected a mandrel larger than the yarns")


#: centerline points tested for lying inside the mandrel
INSIDE_SAMPLES = 25


def _check_centerline_inside(config, mandrel, centerline) -> None:
    """The centerline must run inside the mandrel where it is braided (the yarns are tied around
    it): winding numbers (``_kernels.mesh.winding_numbers``)."""
    vertices, faces = getattr(mandrel, "vertices", None), getattr(mandrel, "faces", None)
    if vertices is None or faces is None:    # stand-in geometry without a mesh
        return
    end = min(config.process.initial_position + config.process.braid_length, centerline.length)
    s = np.linspace(0.02 * end, end, INSIDE_SAMPLES)
    points = np.ascontiguousarray(centerline.frames_at(s)[0], dtype=np.float64)
    # inside where the winding number of the (closed, outward) surface is 1, outside 0
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    from ._kernels.mesh import winding_numbers

    w = np.empty(len(points))
    winding_numbers(V, F, points, w)
    inside = w > 0.5
    if not np.all(inside):
        bad = s[~inside][0]
        p = points[~inside][0]
        raise ConfigError(
            f"[mandrel] centerline = {config.mandrel.centerline}: the centerline leaves the mandrel at "
            f"{bad:.4g} m from the tip (point {p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g} m in the STL frame); "
            "expected a centerline inside the mandrel, tip first, in the STL's frame and unit")


def _check_braid_length(config, length: float) -> None:
    """The braided length is centerline arc length from the tip: braid_length cannot exceed the
    centerline, whatever the convergence zone (how much less the mandrel holds is
    :func:`mandrel_end_problem`'s)."""
    p = config.process
    if p.braid_length > length:
        raise ConfigError(f"[process] braid_length = {p.braid_length:g}: expected at most the "
                          f"centerline length {length:.4g} m of the mandrel (less its convergence "
                          "zone at the end)")


def _check_start(config, length: float, lead: float = 0.0) -> None:
    """The mandrel must still be in the machine at the start: its tip ``initial_position`` past
    the supply plane (plus a guide ring's offset from the spool plane) within the centerline's
    length plus the pose lead (:func:`end_passed`, the rule the run stops by). How much braid the
    mandrel then holds is :func:`mandrel_end_problem`'s: a run started beyond H_inf needs less
    than ``initial_position + braid_length``, its convergence zone shrinking as it braids."""
    p = config.process
    ring = config.machine.guide_ring
    offset = ring.offset if ring is not None else 0.0
    if end_passed(p.initial_position + offset, length, lead):
        terms = f"[process] initial_position = {p.initial_position:g}"
        if offset:
            terms += f" plus [machine] guide_ring offset = {offset:g}"
        lead_text = f" plus the pose lead {lead:.3g} m" if lead else ""
        raise ConfigError(f"{terms} puts the mandrel's tip {p.initial_position + offset:.4g} m past the "
                          f"spool plane at the start, beyond the {length:.4g} m centerline{lead_text}: "
                          "its end has passed the machine before braiding begins; expected a smaller "
                          "initial_position")


def mandrel_end_problem(config, length: float, radius: float, lead: float = 0.0,
                        h_factor: float = 1.0) -> str:
    """:func:`end_message` when the run will need more mandrel than there is, else "".

    The convergence length at the end is the kinematic Du & Popper transient
    H_inf + (H_0 - H_inf) exp(-L / H_inf) from the initial position (``reference.
    end_convergence_length``) on a section of ``radius`` (m), times ``h_factor``."""
    from .reference import end_convergence_length

    ring = config.machine.guide_ring
    offset = ring.offset if ring is not None else 0.0
    h_end = end_convergence_length(config, radius)
    if h_end is None:
        return ""
    h_end *= h_factor
    if not end_passed(config.process.braid_length + h_end + offset, length, lead):
        return ""
    return end_message(config, length, lead, h_end, offset)


#: the end-of-mandrel estimate takes a cylinder's convergence length; on a section that widens
#: behind the fell the kinematic zone is longer (a cone of 41-80 mm radius: 0.55 m simulated
#: against 0.45 m estimated, +22 %), so within this factor of the estimate check warns
END_H_UNCERTAINTY = 1.3


#: a section whose largest radius varies by more than this fraction of the median along the
#: braided part is a changing section for the end-of-mandrel estimate
SECTION_CHANGE = 0.05


def _section_changes(s, distance) -> bool:
    """Whether the section's radius (its largest distance from the centerline, over
    ESTIMATE_SECTIONS bins of arc length) changes by more than SECTION_CHANGE along ``s``."""
    if len(s) == 0:
        return False
    bins = np.linspace(s.min(), s.max(), ESTIMATE_SECTIONS + 1)
    which = np.clip(np.searchsorted(bins, s, side="right") - 1, 0, ESTIMATE_SECTIONS - 1)
    radius = np.zeros(ESTIMATE_SECTIONS)
    np.maximum.at(radius, which, distance)
    radius = radius[radius > 0]
    return bool(radius.max() - radius.min() > SECTION_CHANGE * np.median(radius))


def _check_mandrel_end(config, length: float, radius: float, lead: float = 0.0,
                       changing: bool = False) -> list[str]:
    """The mandrel must last until the fell points reach braid_length (:func:`mandrel_end_problem`).

    The kinematic model's convergence length follows the Du & Popper transient that predicts it,
    so a kinematic run that would pass the mandrel's end is refused (ConfigError, the message the
    run would stop with); friction shortens the interaction model's zone by an amount known only
    by simulating, so for it the same message is a warning. On a ``changing`` section, within
    END_H_UNCERTAINTY of the estimate it is a warning for either model."""
    problem = mandrel_end_problem(config, length, radius, lead)
    if problem and config.model.kind == "kinematic":
        raise ConfigError(problem)
    if problem:
        return [f"likely: {problem} (the interaction model's convergence zone is shorter than "
                "the kinematic estimate by its friction, by how much only a run tells)"]
    problem = changing and mandrel_end_problem(config, length, radius, lead, END_H_UNCERTAINTY)
    if problem:
        return [f"possibly: {problem} (with a convergence zone {END_H_UNCERTAINTY - 1:.0%} longer "
                "than a cylinder's, as on a section that widens behind the fell)"]
    return []


def _check_fit(config, reach: float) -> list[str]:
    """The passing mandrel (max distance from its centerline + |eccentricity|) inside ring and spool."""
    ma = config.machine
    what = (f"the mandrel reaches {reach:.4g} m from the machine axis (its largest distance from the "
            "centerline plus |[process] eccentricity|)")
    if reach >= ma.spool_radius:
        raise ConfigError(f"[machine] spool_radius = {ma.spool_radius:g}: {what}; expected a spool "
                          "radius larger than that")
    ring = ma.guide_ring
    if ring is not None and reach >= ring.radius:
        raise ConfigError(f"[machine] guide_ring.radius = {ring.radius:g}: {what}; expected a guide "
                          "ring radius larger than that")
    supply = ma.spool_radius if ring is None else ring.radius
    if supply - reach < MIN_RADIAL_CLEARANCE * supply:
        key = "spool_radius" if ring is None else "guide_ring.radius"
        return [f"[machine] {key} = {supply:g}: the mandrel reaches {reach:.4g} m from the axis, "
                f"leaving less than {MIN_RADIAL_CLEARANCE:.0%} of the radius for the yarns"]
    return []


def _braid_angle_warnings(config, s, distance) -> list[str]:
    """Ko's estimate per section (radius ~ largest distance from the centerline there)."""
    if len(s) == 0:
        return []
    bins = np.linspace(s.min(), s.max(), ESTIMATE_SECTIONS + 1)
    which = np.clip(np.searchsorted(bins, s, side="right") - 1, 0, ESTIMATE_SECTIONS - 1)
    radius = np.zeros(ESTIMATE_SECTIONS)
    np.maximum.at(radius, which, distance)
    centre = 0.5 * (bins[1:] + bins[:-1])
    keep = radius > 0
    r, centre = radius[keep], centre[keep]
    table = np.asarray(config.process.take_up_speed, dtype=float)
    v = np.interp(centre, table[:, 0], table[:, 1])  # braided length ~ arc length from the tip
    ma, y = config.machine, config.yarn
    speeds = np.asarray(ma.angular_speeds, dtype=float)
    omega = np.interp(centre, speeds[:, 0], speeds[:, 1])
    alpha = np.degrees(analytic.ko_braid_angle(omega, r, v))
    # the yarns narrow to the available width (paper §2.4.2): they jam only where even their
    # least width does not fit (mixed yarns: the mean least width of a group's carriers, whose
    # sum is what must fit round the section)
    least = y.least_width
    if getattr(config, "is_mixed", False):
        kinds = config.carrier_types()[: ma.carriers // 2]
        least = float(np.mean([config.types[t].least_width for t in kinds]))
    jam = np.degrees(analytic.jamming_angle(ma.carriers, least, r))
    lo, hi = BRAID_ANGLE_RANGE_DEG
    warnings = []
    if np.any(alpha > jam):
        k = int(np.argmax(alpha - jam))
        warnings.append(f"the yarns will likely jam: Ko's braid angle estimate {alpha[k]:.1f} deg exceeds "
                        f"the jamming angle {jam[k]:.1f} deg of yarns narrowed to their least width "
                        f"({least:g} m, {'the mean over the carriers, ' if least != y.least_width else ''}"
                        f"[yarn] min_width) at {centre[k]:.3g} m from the tip "
                        "(check [machine] angular_speed, [process] take_up_speed, [yarn] width)")
    if alpha.min() < lo or alpha.max() > hi:
        warnings.append(f"Ko's braid angle estimate spans {alpha.min():.1f}-{alpha.max():.1f} deg, outside "
                        f"the usual {lo:g}-{hi:g} deg (check [machine] angular_speed and "
                        "[process] take_up_speed)")
    return warnings


def _check_time_step(config) -> None:
    """A fixed time step must resolve every pass of two carriers: within a step the carriers may
    turn by at most the angle between two carriers of a group, 2 pi / (N / 2); beyond it the yarns
    skip crossings and the fell points jump (the run then fails far from its cause)."""
    ma, mo = config.machine, config.model
    if mo.time_step is None:
        return
    between = 2.0 * math.pi / (ma.carriers / 2)
    fastest = max(speed for _, speed in ma.angular_speeds)
    turn = fastest * mo.time_step
    if turn > between:
        raise ConfigError(
            f"[model] time_step = {mo.time_step:g} s turns the carriers by {math.degrees(turn):.3g} deg "
            f"a step, more than the {math.degrees(between):.3g} deg between two carriers of a group: "
            f"expected at most {between / fastest:.3g} s (leave time_step out for the "
            "automatic step control)")


def _value_warnings(config) -> list[str]:
    y, ma, mo = config.yarn, config.machine, config.model
    warnings = []
    if y.thickness > y.width:
        warnings.append(f"[yarn] thickness = {y.thickness:g} is larger than [yarn] width = {y.width:g}: "
                        "swapped?")
    for key in ("friction", "ring_friction"):
        mu = getattr(y, key)
        if mu > HIGH_FRICTION:
            warnings.append(f"[yarn] {key} = {mu:g} is unusually high (measured yarn values: 0.15-0.4)")
    if mo.time_step is not None:
        turn = max(speed for _, speed in ma.angular_speeds) * mo.time_step
        if turn > TIME_STEP_FACTOR * tol.max_carrier_rotation:
            warnings.append(f"[model] time_step = {mo.time_step:g} turns the carriers by "
                            f"{math.degrees(turn):.3g} deg per step: results may be coarse")
    return warnings


def _over_run(table, end: float) -> tuple[np.ndarray, np.ndarray]:
    """(braided lengths, values (n, k)) where a table over the braided length has its extremes
    on [0, end]: its rows inside, and both ends (linear between rows, constant beyond)."""
    table = np.asarray(table, dtype=float)
    L = np.unique(np.concatenate([[0.0, end], table[(table[:, 0] > 0.0) & (table[:, 0] < end), 0]]))
    return L, np.array([setting_at(table, length) for length in L])


def _range_line(name, unit, L, values, scale, digits=3):
    """One setting's range over the run: constant, or least and most and where."""
    lo, hi = int(np.argmin(values)), int(np.argmax(values))
    show = lambda v: f"{v * scale:.{digits}g}"   # noqa: E731
    if values[hi] == values[lo]:
        return f"{name} {show(values[lo])} {unit} throughout"
    return (f"{name} {show(values[lo])}-{show(values[hi])} {unit} over the run: least at "
            f"{L[lo]:.3g} m braided, most at {L[hi]:.3g} m (where first reached)")


def setting_ranges(config) -> list[str]:
    """What ``preform check`` says of the process settings over the run: per setting (take-up
    speed, angular speed, eccentricity) its value, or its least and largest over the braided
    length ``[0, braid_length]`` and where; for a run driven by ``[process] trajectory`` the
    path's spans instead (time, braided length, speeds, the origin's coordinates, the turn of
    the orientation), with the rows where the speeds are least and largest."""
    p, ma = config.process, config.machine
    if p.trajectory is not None:
        return _trajectory_ranges(config)
    end = float(p.braid_length)
    L, v = _over_run(p.take_up_speed, end)
    lines = [_range_line("take-up speed", "mm/s", L, v[:, 0], 1e3)]
    L, w = _over_run(ma.angular_speeds, end)
    lines.append(_range_line("angular speed", "deg/s", L, w[:, 0], 180.0 / math.pi))
    L, e = _over_run(p.eccentricities, end)
    if not p.eccentricity_table:
        lines.append(f"eccentricity [{p.eccentricity[0]:g}, {p.eccentricity[1]:g}] m throughout")
    else:
        lines.append(_range_line("eccentricity |[x, y]|", "mm", L, np.hypot(e[:, 0], e[:, 1]), 1e3))
    return lines


def _trajectory_ranges(config) -> list[str]:
    from .config import MAX_ANGULAR_SPEED_DEG, MAX_TAKE_UP_SPEED
    from .trajectory import read_trajectory

    path = read_trajectory(config.process.trajectory, max_take_up_speed=MAX_TAKE_UP_SPEED,
                           max_angular_speed_deg=MAX_ANGULAR_SPEED_DEG)
    t = path.time

    def span(name, unit, values, scale):
        lo, hi = int(np.argmin(values)), int(np.argmax(values))
        if values[lo] == values[hi]:
            return f"{name} {values[lo] * scale:.3g} {unit} throughout"
        return (f"{name} {values[lo] * scale:.3g}-{values[hi] * scale:.3g} {unit} (least at row "
                f"{lo + 1}, t = {t[lo]:.4g} s; most at row {hi + 1}, t = {t[hi]:.4g} s)")

    q = path.quaternion
    turn = np.degrees(2.0 * np.arccos(np.clip(np.abs(q @ q[0]), 0.0, 1.0)))
    x = path.position
    return [f"trajectory {path.path}: {len(t)} rows over {t[-1] - t[0]:.4g} s, braided length "
            f"{path.braided.min():.3g}-{path.braided.max():.3g} m",
            span("take-up speed", "mm/s", path.take_up, 1e3),
            span("angular speed", "deg/s", path.angular, 180.0 / math.pi),
            "the mandrel frame's origin (machine frame) x from {:.4g} to {:.4g} m, y from {:.4g} "
            "to {:.4g} m, z from {:.4g} to {:.4g} m; its orientation turns up to {:.3g} deg from "
            "the first row's".format(x[:, 0].min(), x[:, 0].max(), x[:, 1].min(), x[:, 1].max(),
                                     x[:, 2].min(), x[:, 2].max(), float(turn.max()))]
