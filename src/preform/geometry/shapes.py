"""Closed, outward-wound mandrel meshes swept along a centerline (tests and ``mandrels/``).

Every generator returns ``(vertices (nv, 3) float64 m, faces (nf, 3) int64)`` with the tip at the
origin and the mandrel running along ``+z`` (the bent tube turns towards ``+x``). Sections are
polygons with the same number of points, swept with rotation-minimising frames and closed with
flat fan caps.

Resolution: ``n_around`` points per section; unless given, the axial ring spacing follows it,
``aspect`` times the around edge length (at the largest section), so that refining ``n_around``
(64, 128, 256, 512) refines the whole mesh alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .centerline import centerline_from_points


def sweep(path_points, section, n_around: int, s_values=None, caps: bool = True):
    """Sweep ``section(s) -> (n_around, 2)`` (CCW in the frame's (N, B) plane) along a polyline.

    path_points (n, 3) m: the centerline, tip first. s_values (m,) m: arc lengths of the rings
    (default: the polyline's own points). caps: close both ends with flat fans (an open tube
    otherwise, for tests of the intake checks). Returns (vertices (nv, 3), faces (nf, 3) int64),
    wound outwards.
    """
    cl = centerline_from_points(path_points, roll_reference=[1.0, 0.0, 0.0])
    s_values = cl.s if s_values is None else np.asarray(s_values, dtype=float)
    p, T, N, B = cl.frames_at(s_values)
    rings = []
    for k, s in enumerate(s_values):
        xy = np.asarray(section(float(s)), dtype=float)
        if xy.shape != (n_around, 2):
            raise ValueError(f"section({s:g}) has shape {xy.shape}, expected ({n_around}, 2)")
        rings.append(p[k] + xy[:, :1] * N[k] + xy[:, 1:] * B[k])
    rings = np.array(rings)                        # (m, n_around, 3)
    m = len(rings)
    V = np.vstack([rings.reshape(-1, 3), p[0], p[-1]]) if caps else rings.reshape(-1, 3)
    faces = []
    i = np.arange(n_around)
    j = (i + 1) % n_around
    for r in range(m - 1):
        a, b = r * n_around + i, r * n_around + j
        a2, b2 = a + n_around, b + n_around
        faces.append(np.stack([a, b, b2], axis=1))
        faces.append(np.stack([a, b2, a2], axis=1))
    if caps:
        c0, c1 = m * n_around, m * n_around + 1
        last = (m - 1) * n_around
        faces.append(np.stack([np.full(n_around, c0), j, i], axis=1))
        faces.append(np.stack([np.full(n_around, c1), last + i, last + j], axis=1))
    F = np.vstack(faces).astype(np.int64)
    # the side winding is outward for a CCW section; check it by the side's own orientation
    # (signed volume of the capped surface, or of the side with its ends closed about the centroids)
    if _signed_volume(V, F, rings if not caps else None) < 0:
        F = F[:, ::-1].copy()
    return V, F


def _signed_volume(V, F, rings=None):
    """Six times the signed volume; an open tube is closed virtually by fans about its end centroids."""
    vol = np.einsum("ij,ij->", V[F[:, 0]], np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]))
    if rings is None:
        return vol
    for ring, sign in ((rings[0], 1.0), (rings[-1], -1.0)):
        c = ring.mean(axis=0)
        a, b = ring, np.roll(ring, -1, axis=0)
        vol += sign * np.einsum("ij,ij->", np.broadcast_to(c, a.shape), np.cross(b - c, a - c))
    return vol


def _n_along(length, largest_perimeter, n_around, aspect):
    """Rings spacing ``aspect`` times the around edge length: number of intervals along."""
    return max(1, int(np.ceil(length / (aspect * largest_perimeter / n_around))))


def circle(radius, n_around):
    """(n_around, 2) points of a circle of ``radius`` m, CCW from (radius, 0)."""
    th = 2 * np.pi * np.arange(n_around) / n_around
    return np.column_stack([radius * np.cos(th), radius * np.sin(th)])


def rounded_square(side, corner_radius, n_around):
    """Points uniform in arc length on a rounded square centred at 0, from (side/2, 0), CCW."""
    a = side / 2.0
    rc = corner_radius
    straight = 2 * (a - rc)
    arc = 0.5 * np.pi * rc
    per = 4 * (straight + arc)
    u = per * np.arange(n_around) / n_around
    u = (u + straight / 2) % per           # start at the middle of the right side
    out = np.empty((n_around, 2))
    for k, q in enumerate(u):
        side_i, r = divmod(q, straight + arc)
        rot = np.pi / 2 * side_i
        if r < straight:
            x, y = a, -(a - rc) + r
        else:
            phi = (r - straight) / rc
            x, y = (a - rc) + rc * np.cos(phi), (a - rc) + rc * np.sin(phi)
        c, s = np.cos(rot), np.sin(rot)
        out[k] = (c * x - s * y, s * x + c * y)
    return out


def rounded_square_perimeter(side, corner_radius):
    """Perimeter (m) of a square of ``side`` m with corners rounded to ``corner_radius`` m."""
    return 4 * (side - 2 * corner_radius) + 2 * np.pi * corner_radius


def _straight(length):
    return np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]])


def _rings(length, spacing):
    return np.linspace(0.0, length, max(2, int(np.ceil(length / spacing)) + 1))


def revolution(radius_fn, length, n_around=128, n_along=None, aspect=4.0):
    """Surface of revolution r(s) along z, s in [0, length] m.

    n_along intervals along (default: axial edges ``aspect`` times the around edges at the largest
    radius).
    """
    r_max = max(radius_fn(s) for s in np.linspace(0, length, 201))
    n_along = n_along or _n_along(length, 2 * np.pi * r_max, n_around, aspect)
    s = np.linspace(0.0, length, n_along + 1)
    return sweep(_straight(length), lambda q: circle(radius_fn(q), n_around), n_around, s)


def cylinder(radius, length, n_around=128, n_along=None, aspect=4.0):
    """Circular cylinder of ``radius`` m, ``length`` m along +z from the origin."""
    return revolution(lambda s: radius, length, n_around, n_along, aspect)


def cone(r_tip, r_back, length, n_around=128, n_along=None, aspect=4.0):
    """Truncated cone, radius r_tip at z = 0 to r_back at z = length (m)."""
    return revolution(lambda s: r_tip + (r_back - r_tip) * s / length, length, n_around, n_along, aspect)


def waist_radius(s, radius=0.075, depth=0.03, width=0.03, centre=0.5):
    """Hourglass profile r(s) = radius - depth exp(-((s - centre)/width)^2), m.

    Its axial curvature at the bottom is r'' = 2 depth / width^2 (66.7 /m by default): a yarn at
    braid angle alpha bridges where r'' > tan(alpha)^2 / r, i.e. up to alpha = 60 deg at r = 45 mm.
    """
    return radius - depth * np.exp(-(((s - centre) / width) ** 2))


def bulge_radius(s, radius=0.05, height=0.04, width=0.015, centre=0.45):
    """Ring bulge profile r(s) = radius + height exp(-((s - centre)/width)^2), m.

    Steepest flank |r'| = height sqrt(2/e) / width (2.3, i.e. 66 deg, by default): free yarns
    from the tip side catch on it.
    """
    return radius + height * np.exp(-(((s - centre) / width) ** 2))


def waist(radius=0.075, depth=0.03, width=0.03, centre=0.5, length=1.2, n_around=128, n_along=None,
          aspect=1.0):
    """Hourglass cylinder (see ``waist_radius``); axial edges follow the around edges (aspect 1)."""
    return revolution(lambda s: waist_radius(s, radius, depth, width, centre), length, n_around, n_along, aspect)


def bulge(radius=0.05, height=0.04, width=0.015, centre=0.45, length=1.2, n_around=128, n_along=None,
          aspect=1.0):
    """Cylinder with a ring bulge (see ``bulge_radius``); axial edges follow the around edges."""
    return revolution(lambda s: bulge_radius(s, radius, height, width, centre), length, n_around, n_along,
                      aspect)


def smoothstep(x):
    """3x^2 - 2x^3 on [0, 1], clamped: a blend with zero slope at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def case_b(side=0.09, corner_radius=0.015, length=1.5, blend=(0.9, 1.1), n_around=128, spacing=None,
           aspect=4.0):
    """Rounded square blending into a circle of the same perimeter (paper Fig. 11, case B-like).

    side, corner_radius m; the blend (a smoothstep between the two polygons) runs over ``blend``
    (m of z). spacing: ring spacing m (default ``aspect`` times the around edge length).
    """
    per = rounded_square_perimeter(side, corner_radius)
    sq = rounded_square(side, corner_radius, n_around)
    circ = circle(per / (2 * np.pi), n_around)

    def section(s):
        w = smoothstep((s - blend[0]) / (blend[1] - blend[0]))
        return (1 - w) * sq + w * circ

    spacing = spacing or aspect * per / n_around
    return sweep(_straight(length), section, n_around, _rings(length, spacing))


def bent_tube_path(straight=0.4, bend_radius=0.35, n_bend=48):
    """Centerline (n, 3) m: straight along +z, a 90 deg bend towards +x, straight along +x."""
    a = np.linspace(0, np.pi / 2, n_bend + 1)
    bend = np.column_stack([bend_radius * (1 - np.cos(a)), np.zeros_like(a), straight + bend_radius * np.sin(a)])
    end = bend[-1] + np.array([straight, 0.0, 0.0])
    return np.vstack([[0.0, 0.0, 0.0], bend, end])


def bent_tube(side=0.06, corner_radius=0.012, straight=0.4, bend_radius=0.35, n_around=96, spacing=None,
              aspect=4.0):
    """Rounded-square tube (side, corner_radius m) swept along ``bent_tube_path``.

    spacing: ring spacing m (default ``aspect`` times the around edge length).
    """
    path = bent_tube_path(straight, bend_radius)
    cl = centerline_from_points(path)
    spacing = spacing or aspect * rounded_square_perimeter(side, corner_radius) / n_around
    return sweep(path, lambda s: rounded_square(side, corner_radius, n_around), n_around, _rings(cl.length, spacing))


# -- a family of curved, changing parts (bends, S-bends, transitions, tapers) ------------------

def rounded_rectangle(width, height, corner_radius, n_around):
    """Points uniform in arc length on a ``width`` x ``height`` m rectangle (along the frame's N
    and B) with corners rounded to ``corner_radius`` m, centred at 0, from (width/2, 0), CCW:
    the same start and sense as ``circle``, so the two blend point by point."""
    a, b, rc = width / 2.0, height / 2.0, corner_radius
    if not 0.0 < rc <= min(a, b):
        raise ValueError(f"corner radius {rc} m: expected in (0, {min(a, b)}] for a "
                         f"{width} x {height} m rectangle")
    sx, sy, arc = 2 * (b - rc), 2 * (a - rc), 0.5 * np.pi * rc
    # the pieces CCW from the middle of the right side: right, corner, top, corner, ...
    pieces = [("line", (a, -(b - rc)), (0.0, 1.0), sx), ("arc", (a - rc, b - rc), 0.0, arc),
              ("line", (a - rc, b), (-1.0, 0.0), sy), ("arc", (-(a - rc), b - rc), 0.5 * np.pi, arc),
              ("line", (-a, b - rc), (0.0, -1.0), sx), ("arc", (-(a - rc), -(b - rc)), np.pi, arc),
              ("line", (-(a - rc), -b), (1.0, 0.0), sy), ("arc", (a - rc, -(b - rc)), 1.5 * np.pi, arc)]
    per = sum(p[-1] for p in pieces)
    u = (per * np.arange(n_around) / n_around + sx / 2.0) % per
    out = np.empty((n_around, 2))
    starts = np.concatenate([[0.0], np.cumsum([p[-1] for p in pieces])])
    for k, q in enumerate(u):
        i = min(int(np.searchsorted(starts, q, side="right")) - 1, len(pieces) - 1)
        kind, origin, how, _ = pieces[i]
        r = q - starts[i]
        if kind == "line":
            out[k] = (origin[0] + r * how[0], origin[1] + r * how[1])
        else:
            phi = how + r / rc
            out[k] = (origin[0] + rc * np.cos(phi), origin[1] + rc * np.sin(phi))
    return out


def rounded_rectangle_perimeter(width, height, corner_radius):
    """Perimeter (m) of ``rounded_rectangle``."""
    return 2 * (width + height) - 8 * corner_radius + 2 * np.pi * corner_radius


def bend_path(pieces, step=0.01, arc_step_deg=2.0):
    """(points (n, 3) m, s of the ends of the pieces (len(pieces) + 1,) m) of a centerline from
    the origin along +z made of ``pieces``: ``("line", length)`` or ``("arc", radius, angle_deg)``,
    the arcs turning in the x-z plane (a positive angle towards +x, a negative one back): an
    S-bend is ``arc +a, line, arc -a``. Lines are sampled every ``step`` m, arcs every
    ``arc_step_deg``."""
    p = np.zeros(3)
    t = np.array([0.0, 0.0, 1.0])
    pts, ends, s = [p.copy()], [0.0], 0.0
    for piece in pieces:
        if piece[0] == "line":
            length = float(piece[1])
            k = max(1, int(np.ceil(length / step)))
            for j in range(1, k + 1):
                pts.append(p + t * length * j / k)
            p = p + t * length
            s += length
        elif piece[0] == "arc":
            radius, angle = float(piece[1]), np.radians(float(piece[2]))
            side = np.sign(angle)
            # the centre lies to the side the arc turns to, in the x-z plane
            normal = side * np.array([t[2], 0.0, -t[0]])
            centre = p + radius * normal
            k = max(2, int(np.ceil(abs(np.degrees(angle)) / arc_step_deg)))
            for j in range(1, k + 1):
                a = abs(angle) * j / k
                pts.append(centre - radius * normal * np.cos(a) + radius * t * np.sin(a))
            a = abs(angle)
            p, t = centre - radius * normal * np.cos(a) + radius * t * np.sin(a), \
                t * np.cos(a) + normal * np.sin(a)
            s += radius * abs(angle)
        else:
            raise ValueError(f"path piece {piece!r}: expected ('line', length) or "
                             "('arc', radius, angle_deg)")
        ends.append(s)
    return np.array(pts), np.array(ends)


def blend_sections(first, second, start, end):
    """``section(s)``: the polygon ``first`` (n, 2) up to arc length ``start`` m, ``second`` from
    ``end`` on, a smoothstep between (both from the frame's N axis, CCW)."""
    first, second = np.asarray(first, dtype=float), np.asarray(second, dtype=float)

    def section(s):
        w = smoothstep((s - start) / max(end - start, 1e-12))
        return (1 - w) * first + w * second

    return section


def part_rings(length, breaks, spacing, triangulation="even", arcs=(), arc_spacing=None):
    """Arc lengths (m) of a part's rings: ``"even"`` every ``spacing`` m; ``"sliver"`` as a CAD
    export tessellates by chord tolerance: rings only at the ``breaks`` (ends of the path's
    pieces and of the section's changes) and every ``arc_spacing`` m (default ``spacing``)
    inside the ``arcs`` and changes ((start, end) m each), so a straight piece of constant
    section is spanned by faces as long as the piece (aspect ratios in the hundreds)."""
    if triangulation == "even":
        return _rings(length, spacing)
    if triangulation != "sliver":
        raise ValueError(f"triangulation {triangulation!r}: expected 'even' or 'sliver'")
    step = spacing if arc_spacing is None else arc_spacing
    s = [0.0, length, *[b for b in breaks if 0.0 < b < length]]
    for a, b in arcs:
        k = max(1, int(np.ceil((b - a) / step)))
        s.extend(np.linspace(a, b, k + 1))
    s = np.unique(np.round(np.clip(s, 0.0, length), 12))
    return s


def sliver_faces(V, F, n_around, every=3):
    """The side faces of a swept part (``sweep``: its side quads as consecutive triangle pairs,
    caps last) re-triangulated as CAD exports do: in all but every ``every``-th quad around a
    ring strip the other diagonal, so the strip has triangles leaning both ways, long thin ones
    beside wide ones (the surface is the same polyhedron only where the quads are planar; on a
    swept part they nearly are). Returns new faces (same vertices, same winding)."""
    F = np.asarray(F).copy()
    n_side = len(F) - 2 * n_around if len(V) % n_around == 2 else len(F)
    for q in range(n_side // 2):
        if (q % n_around) % every == 0:
            continue
        t1, t2 = F[2 * q], F[2 * q + 1]
        shared = set(t1.tolist()) & set(t2.tolist())
        if len(shared) != 2:
            continue
        # t1 as (u, d1, d2) with u its corner off the diagonal, w the other triangle's
        k = next(i for i in range(3) if t1[i] not in shared)
        u, d1, d2 = t1[k], t1[(k + 1) % 3], t1[(k + 2) % 3]
        w = next(x for x in t2.tolist() if x not in shared)
        # the quad u -> d1 -> w -> d2: the diagonal u-w instead of d1-d2
        F[2 * q] = (u, d1, w)
        F[2 * q + 1] = (w, d2, u)
    return F


@dataclass(frozen=True)
class PartSpec:
    """One part of the family (``family_part``): a centerline of ``pieces`` (``bend_path``) and
    a section: a circle of ``radius`` m, or a rounded ``rectangle`` (width, height, corner m)
    blending into a circle of ``radius`` (``to_circle``; the other way round if False) over
    ``change`` (start, end) m of arc length, or a taper from ``radius`` to ``radius_end``."""

    name: str
    pieces: tuple
    radius: float
    rectangle: tuple | None = None
    to_circle: bool = True
    radius_end: float | None = None
    change: tuple | None = None


def _family():
    S = 0.3
    return {
        "bend30": PartSpec("bend30", (("line", 0.2), ("arc", S, 30.0), ("line", 0.4)), 0.025),
        "bend60": PartSpec("bend60", (("line", 0.2), ("arc", S, 60.0), ("line", 0.4)), 0.025),
        "bend90": PartSpec("bend90", (("line", 0.2), ("arc", 0.4, 90.0), ("line", 0.4)), 0.025),
        "s_bend": PartSpec("s_bend", (("line", 0.15), ("arc", S, 35.0), ("line", 0.08),
                                      ("arc", S, -35.0), ("line", 0.3)), 0.025),
        # the S-bend from near the tip: a short braid lies on its first bend
        "s_bend_tip": PartSpec("s_bend_tip", (("line", 0.03), ("arc", S, 35.0), ("line", 0.05),
                                              ("arc", S, -35.0), ("line", 0.4)), 0.025),
        # a single bend from near the tip, gentle enough for the kinematic model's straight
        # yarns to follow its inner side (at 0.3 m they lift off there and catch ahead)
        "bend_tip": PartSpec("bend_tip", (("line", 0.03), ("arc", 0.45, 35.0), ("line", 0.5)),
                             0.025),
        "rect_to_circle": PartSpec("rect_to_circle", (("line", 0.9),), 0.025,
                                   rectangle=(0.06, 0.04, 0.01), change=(0.25, 0.45)),
        "circle_to_rect": PartSpec("circle_to_rect", (("line", 0.9),), 0.025,
                                   rectangle=(0.06, 0.04, 0.01), to_circle=False,
                                   change=(0.25, 0.45)),
        "taper": PartSpec("taper", (("line", 0.9),), 0.03, radius_end=0.02, change=(0.1, 0.7)),
        # the S-bent tube of a user's part: two 35 deg bends of radius 300 mm, a 60 x 40 mm
        # rounded rectangle blending into a 50 mm circle, 744 mm long
        "s_tube": PartSpec("s_tube", (("line", 0.15), ("arc", S, 35.0), ("line", 0.0775),
                                      ("arc", S, -35.0), ("line", 0.15)), 0.025,
                           rectangle=(0.06, 0.04, 0.01), change=(0.2, 0.5)),
    }


#: the names of ``family_part``'s parts
FAMILY = tuple(_family())


def family_part(name, n_around=48, triangulation="even", spacing=None, scale=1.0):
    """(vertices (nv, 3), faces (nf, 3) int64, centerline points (n, 3)) of the family's part
    ``name`` (``FAMILY``), tip at the origin along +z, in metres times ``scale`` (1000: the
    millimetres of a CAD export). ``triangulation``: ``"even"`` (rings every ``spacing`` m,
    default twice the around edge) or ``"sliver"`` (``part_rings``' CAD tessellation, and
    ``sliver_faces``' long thin diagonals)."""
    parts = _family()
    if name not in parts:
        raise ValueError(f"part {name!r}: expected one of {', '.join(parts)}")
    spec = parts[name]
    path, ends = bend_path(spec.pieces)
    length = float(ends[-1])
    circ = circle(spec.radius, n_around)
    if spec.rectangle is not None:
        rect = rounded_rectangle(*spec.rectangle, n_around)
        first, second = (rect, circ) if spec.to_circle else (circ, rect)
        section = blend_sections(first, second, *spec.change)
        largest = rounded_rectangle_perimeter(*spec.rectangle)
    elif spec.radius_end is not None:
        r0, r1 = spec.radius, spec.radius_end
        a, b = spec.change

        def section(s):
            w = np.clip((s - a) / (b - a), 0.0, 1.0)
            return circle(r0 + (r1 - r0) * w, n_around)

        largest = 2 * np.pi * max(r0, r1)
    else:
        section = lambda s: circ  # noqa: E731
        largest = 2 * np.pi * spec.radius
    spacing = spacing or 2.0 * largest / n_around
    arcs = [(ends[i], ends[i + 1]) for i, p in enumerate(spec.pieces) if p[0] == "arc"]
    breaks = list(ends)
    if spec.change is not None:
        arcs.append(tuple(spec.change))
        breaks.extend(spec.change)
    s = part_rings(length, breaks, spacing, triangulation, arcs)
    V, F = sweep(path, section, n_around, s)
    if triangulation == "sliver":
        F = sliver_faces(V, F, n_around)
    return V * scale, F, path * scale
