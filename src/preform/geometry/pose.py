"""Where the mandrel is in the machine at a given feed (docs/architecture.md §2).

Machine frame: ``z`` is the machine axis, the supply plane is ``z = 0``, the mandrel moves towards
``+z`` tip first. ``pose_at`` puts the centerline point at arc length ``s_a = travel - lead`` at
machine ``(ex, ey, lead)`` with its tangent (towards increasing s, away from the tip) along ``-z``
and its rotation-minimising normal along ``+x``: a straight mandrel with ``lead = 0`` has its tip at
``z = travel``; a curved one turns as a robot would hold it, keeping the centerline on the axis
``lead`` ahead of the supply plane. ``lead`` near the convergence length keeps the braiding zone
aligned with the machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Pose:
    """x_machine = R @ x_mandrel + t.  R (3, 3) rotation, t (3,) m."""

    R: np.ndarray
    t: np.ndarray

    def to_machine(self, x):
        """Mandrel-frame points (3,) or (n, 3) -> machine frame."""
        return np.asarray(x, dtype=float) @ self.R.T + self.t

    def to_mandrel(self, X):
        """Machine-frame points (3,) or (n, 3) -> mandrel frame."""
        return (np.asarray(X, dtype=float) - self.t) @ self.R


#: (e_x[i], e_y[i], e_z[i]) for the rows i of R
_UNIT_ROWS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def pose_at(centerline, travel: float, eccentricity=(0.0, 0.0), lead: float = 0.0) -> Pose:
    """The mandrel pose when ``travel`` m of centerline have been fed past the supply plane."""
    p, T, N, B = centerline.frame_values(travel - lead)
    # R = e_x N^T - e_y B^T - e_z T^T (rows N, -B, -T), in plain floats (it runs twice a step)
    R = np.array([[(a * N[j] - b * B[j]) - c * T[j] for j in range(3)] for a, b, c in _UNIT_ROWS])
    t = np.array([eccentricity[0], eccentricity[1], lead]) - R @ np.array(p)
    return Pose(R=R, t=t)
