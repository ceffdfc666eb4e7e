"""``preform mandrel info``: is the STL a usable mandrel, and what does it measure."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .centerline import Centerline, auto_centerline, read_centerline_csv, with_perimeter
from .mandrel import Mandrel, load_mandrel


@dataclass(frozen=True)
class MandrelInfo:
    path: str
    unit: str
    n_vertices: int
    n_faces: int
    watertight: bool
    consistently_oriented: bool
    bounds: np.ndarray          # (2, 3) m
    volume: float               # m^3
    centerline_source: str      # "auto" or the CSV path
    centerline_length: float    # m
    perimeter_min: float        # m
    perimeter_max: float        # m
    repairs: tuple
    centerline: Centerline
    mandrel: Mandrel

    def as_dict(self) -> dict:
        return {"path": self.path, "unit": self.unit, "n_vertices": self.n_vertices,
                "n_faces": self.n_faces, "watertight": self.watertight,
                "consistently_oriented": self.consistently_oriented, "bounds": self.bounds.tolist(),
                "volume": self.volume, "centerline": self.centerline_source,
                "centerline_length": self.centerline_length, "perimeter_min": self.perimeter_min,
                "perimeter_max": self.perimeter_max, "repairs": list(self.repairs)}


def mandrel_info(path, unit: str = "m", centerline="auto") -> MandrelInfo:
    """Load (which checks watertightness and orientation), derive or read the centerline, measure."""
    mandrel = load_mandrel(path, unit=unit)
    if isinstance(centerline, str) and centerline == "auto":
        cl = auto_centerline(mandrel)
        source = "auto"
    else:
        cl = read_centerline_csv(centerline, unit=unit)
        source = str(centerline)
    if cl.perimeter is None:
        cl = with_perimeter(cl, mandrel)
    inner = cl.perimeter[1:-1] if len(cl.perimeter) > 2 else cl.perimeter
    inner = inner[inner > 0] if np.any(inner > 0) else inner
    return MandrelInfo(path=str(Path(path)), unit=unit, n_vertices=len(mandrel.vertices),
                       n_faces=len(mandrel.faces), watertight=True, consistently_oriented=True,
                       bounds=mandrel.bounds, volume=float(mandrel.mesh.volume), centerline_source=source,
                       centerline_length=cl.length, perimeter_min=float(inner.min()),
                       perimeter_max=float(inner.max()), repairs=mandrel.repairs, centerline=cl,
                       mandrel=mandrel)


def format_mandrel_info(info: MandrelInfo) -> str:
    b = info.bounds
    lines = [
        f"mandrel      {info.path} (stl_unit = \"{info.unit}\")",
        f"mesh         {info.n_faces} triangles, {info.n_vertices} vertices, watertight, outward, "
        f"volume {info.volume * 1e9:.6g} mm^3",
        f"bounds       x {b[0, 0]:.4f} .. {b[1, 0]:.4f} m, y {b[0, 1]:.4f} .. {b[1, 1]:.4f} m, "
        f"z {b[0, 2]:.4f} .. {b[1, 2]:.4f} m",
        f"centerline   {info.centerline_source}: {info.centerline_length:.4f} m, {len(info.centerline.s)} points",
        f"perimeter    min {info.perimeter_min * 1e3:.2f} mm, max {info.perimeter_max * 1e3:.2f} mm",
    ]
    for r in info.repairs:
        lines.append(f"repaired     {r}")
    return "\n".join(lines)
