"""Mandrel geometry: STL intake, smooth normals, centerline and frames, pose in the machine."""

from .centerline import (Centerline, auto_centerline, centerline_from_points, read_centerline_csv,
                         section_perimeters, with_perimeter, write_centerline_csv)
from .mandrel import Mandrel, load_mandrel, mandrel_from_arrays
from .pose import Pose, pose_at

__all__ = ["Centerline", "Mandrel", "Pose", "auto_centerline", "centerline_from_points", "load_mandrel",
           "mandrel_from_arrays", "pose_at", "read_centerline_csv", "section_perimeters", "with_perimeter",
           "write_centerline_csv"]
