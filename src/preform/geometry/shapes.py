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
