"""``centerline.csv``: a centerline as ``x,y,z,s,perimeter`` rows, as ``preform mandrel info
--csv`` writes it and ``preform.geometry.read_centerline_csv`` reads it back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry.centerline import Centerline, _check_unit
from ..geometry.mandrel import UNITS
from .atomic import atomic_write_text


def write_centerline_csv(path, centerline: Centerline, unit: str = "m") -> Path:
    """Write ``x,y,z,s,perimeter`` (lengths in ``unit``) atomically; readable by read_centerline_csv.

    The file is written atomically with the user's umask (``preform.io.atomic``): an interrupted
    write never leaves a half file, and a symlink planted at ``path`` is replaced, never followed.
    ``write_centerline_csv(centerline, path)`` is accepted too. perimeter is ``nan`` when the centerline has none.
    """
    if isinstance(path, Centerline):
        path, centerline = centerline, path
    _check_unit(unit, "centerline unit")
    path = Path(path)
    scale = 1.0 / UNITS[unit]
    per = centerline.perimeter if centerline.perimeter is not None else np.full(len(centerline.s), np.nan)
    lines = ["x,y,z,s,perimeter"]
    for p, s, q in zip(centerline.points * scale, centerline.s * scale, per * scale):
        lines.append(f"{p[0]:.9g},{p[1]:.9g},{p[2]:.9g},{s:.9g},{q:.9g}")
    return atomic_write_text(path, "\n".join(lines) + "\n")
