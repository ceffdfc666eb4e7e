"""Mandrel geometry: STL intake, smooth normals, centerline and frames, pose in the machine.

Frames (docs/architecture.md §2): the mandrel frame is the STL's own frame in metres; ``Pose`` maps it into
the machine frame. Shape generators for tests and ``mandrels/`` are in ``preform.geometry.shapes``.
"""

from .centerline import (Centerline, auto_centerline, centerline_from_points, read_centerline_csv,
                         section_perimeters, with_perimeter)
from .info import MandrelInfo, format_mandrel_info, mandrel_info
from .mandrel import Mandrel, load_mandrel, mandrel_from_arrays
from .pose import Pose, pose_at

__all__ = ["Centerline", "Mandrel", "MandrelInfo", "Pose", "auto_centerline", "centerline_from_points",
           "format_mandrel_info", "load_mandrel", "mandrel_from_arrays", "mandrel_info", "pose_at",
           "read_centerline_csv", "section_perimeters", "with_perimeter"]
