"""Closed, outward-wound mandrel meshes swept along a centerline (tests and ``mandrels/``).

Every generator returns ``(vertices (nv, 3) float64 m, faces (nf, 3) int64)`` with the tip at the
origin and the mandrel running along ``+z`` (the bent tube turns towards ``+x``). Sections are
polygons with the same number of points, swept with rotation-minimising frames and closed with
flat fan caps.
"""

from __future__ import annotations

import numpy as np

from .centerline import centerline_from_points


def sweep(path_points, section, n_around: int, s_values=None):
    """Sweep ``section(s) -> (n_around, 2)`` (CCW in the frame's (N, B) plane) along a polyline.

    path_points (n, 3): the centerline, tip first. s_values: arc lengths of the rings (default:
    the polyline's own points).
    """
    cl = centerline_from_points(path_points, roll_reference=[1.0, 0.0, 0.0])
    s_values = cl.s if s_values is None else np.asarray(s_values, dtype=float)
    p, T, N, B = cl.frames_at(s_values)
    rings = []
    for k, s in enumerate(s_values):
        xy = np.asarray(section(float(s)), dtype=float)
        assert xy.shape == (n_around, 2)
        rings.append(p[k] + xy[:, :1] * N[k] + xy[:, 1:] * B[k])
    rings = np.array(rings)                        # (m, n_around, 3)
    m = len(rings)
    V = np.vstack([rings.reshape(-1, 3), p[0], p[-1]])
    c0, c1 = m * n_around, m * n_around + 1
    faces = []
    i = np.arange(n_around)
    j = (i + 1) % n_around
    for r in range(m - 1):
        a, b = r * n_around + i, r * n_around + j
        a2, b2 = a + n_around, b + n_around
        faces.append(np.stack([a, b, b2], axis=1))
        faces.append(np.stack([a, b2, a2], axis=1))
    faces.append(np.stack([np.full(n_around, c0), j, i], axis=1))
    last = (m - 1) * n_around
    faces.append(np.stack([np.full(n_around, c1), last + i, last + j], axis=1))
    F = np.vstack(faces).astype(np.int64)
    vol = np.einsum("ij,ij->", V[F[:, 0]], np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]))
    if vol < 0:
        F = F[:, ::-1].copy()
    return V, F


def circle(radius, n_around):
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
    return 4 * (side - 2 * corner_radius) + 2 * np.pi * corner_radius


def _straight(length):
    return np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]])


def _rings(length, spacing):
    return np.linspace(0.0, length, max(2, int(np.ceil(length / spacing)) + 1))


def revolution(radius_fn, length, n_around=128, n_along=None):
    """Surface of revolution r(s) along z; n_along rings (default: edges of ~4x the around spacing)."""
    r_max = max(radius_fn(s) for s in np.linspace(0, length, 201))
    n_along = n_along or int(np.ceil(length / (4 * 2 * np.pi * r_max / n_around)))
    s = np.linspace(0.0, length, n_along + 1)
    return sweep(_straight(length), lambda q: circle(radius_fn(q), n_around), n_around, s)


def cylinder(radius, length, n_around=128, n_along=None):
    return revolution(lambda s: radius, length, n_around, n_along)


def cone(r_tip, r_back, length, n_around=128, n_along=None):
    return revolution(lambda s: r_tip + (r_back - r_tip) * s / length, length, n_around, n_along)


def waist(radius=0.075, depth=0.03, width=0.03, centre=0.5, length=1.2, n_around=128, n_along=240):
    """Hourglass: r = radius - depth exp(-((s - centre)/width)^2)."""
    return revolution(lambda s: radius - depth * np.exp(-((s - centre) / width) ** 2), length, n_around, n_along)


def bulge(radius=0.05, height=0.04, width=0.015, centre=0.45, length=1.2, n_around=128, n_along=240):
    """A ring bulge: r = radius + height exp(-((s - centre)/width)^2)."""
    return revolution(lambda s: radius + height * np.exp(-((s - centre) / width) ** 2), length, n_around, n_along)


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def case_b(side=0.09, corner_radius=0.015, length=1.5, blend=(0.9, 1.1), n_around=128, spacing=0.01):
    """Rounded square blending into a circle of the same perimeter (paper Fig. 11, case B-like)."""
    sq = rounded_square(side, corner_radius, n_around)
    r_circle = rounded_square_perimeter(side, corner_radius) / (2 * np.pi)
    circ = circle(r_circle, n_around)

    def section(s):
        w = smoothstep((s - blend[0]) / (blend[1] - blend[0]))
        return (1 - w) * sq + w * circ

    return sweep(_straight(length), section, n_around, _rings(length, spacing))


def bent_tube_path(straight=0.4, bend_radius=0.35, n_bend=48):
    """Centerline: straight along +z, a 90 deg bend towards +x, straight along +x."""
    a = np.linspace(0, np.pi / 2, n_bend + 1)
    bend = np.column_stack([bend_radius * (1 - np.cos(a)), np.zeros_like(a), straight + bend_radius * np.sin(a)])
    end = bend[-1] + np.array([straight, 0.0, 0.0])
    return np.vstack([[0.0, 0.0, 0.0], bend, end])


def bent_tube(side=0.06, corner_radius=0.012, straight=0.4, bend_radius=0.35, n_around=96, spacing=0.008):
    path = bent_tube_path(straight, bend_radius)
    cl = centerline_from_points(path)
    return sweep(path, lambda s: rounded_square(side, corner_radius, n_around), n_around, _rings(cl.length, spacing))
