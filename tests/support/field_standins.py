"""Shared stand-ins for the surface-field tests: a trimesh cylinder, helical yarns at a chosen
braid angle, and a Result stand-in with exactly the attributes ``map_to_surface`` reads."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import trimesh

from preform.analysis.fields import face_geometry
from preform.result import YarnPaths

R, HEIGHT, WIDTH, THICKNESS = 0.05, 0.2, 4e-3, 2.5e-4


def cylinder(r=R, height=HEIGHT, sections=32):
    """Closed cylinder mesh from z = 0 to height, outward wound (long sliver side faces)."""
    m = trimesh.creation.cylinder(radius=r, height=height, sections=sections)
    m.apply_translation([0.0, 0.0, height / 2])
    return NS(vertices=np.asarray(m.vertices, dtype=np.float64),
              faces=np.asarray(m.faces, dtype=np.int64))


class ZCenterline:
    """Straight centerline along +z: s = z, T = (0, 0, 1)."""

    def project(self, points):
        points = np.asarray(points)
        return points[:, 2].copy(), np.hypot(points[:, 0], points[:, 1])

    def frames_at(self, s):
        n = len(s)
        P = np.zeros((n, 3))
        P[:, 2] = s
        return P, np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([1.0, 0.0, 0.0], (n, 1)), \
            np.tile([0.0, 1.0, 0.0], (n, 1))


def helices(alpha, n_per_group, z0=0.0, z1=HEIGHT, dz=1e-3, r=R, phase=0.1):
    """Warp (clockwise, theta falling) and weft helices on the true cylinder at braid angle
    alpha(z) (rad; callable or number): d theta / dz = tan(alpha) / r."""
    alpha_of_z = alpha if callable(alpha) else (lambda z: np.full_like(z, alpha))
    z = np.linspace(z0, z1, int(round((z1 - z0) / dz)) + 1)
    tan = np.tan(alpha_of_z(z))
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (tan[1:] + tan[:-1]) * np.diff(z))]) / r
    points, offsets, group = [], [0], []
    for g, sign in ((0, -1.0), (1, 1.0)):
        for i in range(n_per_group):
            phi = 2 * np.pi * i / n_per_group + phase + sign * theta
            points.append(np.column_stack([r * np.cos(phi), r * np.sin(phi), z]))
            offsets.append(offsets[-1] + len(z))
            group.append(g)
    return pack_yarns(points, offsets, group)


def pack_yarns(points, offsets, group) -> YarnPaths:
    """YarnPaths of polylines ``points`` (list of (n_i, 3)) with their ``offsets`` and groups."""
    P = np.vstack(points)
    m = len(P)
    return YarnPaths(points=P, offsets=np.array(offsets, np.int64), time_s=np.zeros(m),
                     braid_angle_deg=np.zeros(m), face=np.full(m, -1, np.int64),
                     flags=np.zeros(m, np.uint8), group=np.array(group, np.int8))


def make_result(mandrel, yarns, width=WIDTH, thickness=THICKNESS, edge=None):
    config = NS(yarn=NS(width=width, thickness=thickness, least_width=0.5 * width),
                output=NS(field_edge_length=edge), axial=lambda: (0, width, thickness, None))
    return NS(config=config, mandrel=mandrel, centerline=ZCenterline(), yarns=yarns)


def side_faces(fields, z0=0.0, z1=HEIGHT, margin=0.0):
    """Mask of side faces (not caps) with centroid z in [z0 + margin, z1 - margin]; areas."""
    normals, areas, centroids = face_geometry(fields.vertices, fields.faces)
    z = centroids[:, 2]
    return (np.abs(normals[:, 2]) < 0.5) & (z >= z0 + margin) & (z <= z1 - margin), areas


def coverage_closed_form(n_per_group, alpha, width=WIDTH, r=R):
    return n_per_group * width / (2 * np.pi * r * np.cos(alpha))


def area_mean(fields, name, mask, areas):
    return np.average(fields.cell_data[name][mask], weights=areas[mask])


