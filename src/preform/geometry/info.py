"""``preform mandrel info``: is the STL a usable mandrel, and what does it measure."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .centerline import Centerline, auto_centerline, read_centerline_csv, with_perimeter
from .mandrel import Mandrel, load_mandrel


@dataclass(frozen=True, eq=False)
class MandrelInfo(Mapping):
    """What ``preform mandrel info`` reports. A read-only dict of plain values (``info["n_faces"]``,
    ``dict(info)``, JSON-ready: the keys of ``as_dict()``) that also carries the loaded
    ``mandrel`` and the ``centerline`` (with perimeters) as attributes.

    Lengths in m, volume in m^3, bounds (2, 3) m in the mandrel frame. ``watertight`` and
    ``consistently_oriented`` are True for every loaded mandrel: ``load_mandrel`` refuses the others
    with a MandrelError that says what is wrong.
    """

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
    perimeter_min_at: float     # m of centerline from the tip
    perimeter_max_at: float     # m of centerline from the tip
    repairs: tuple
    centerline: Centerline
    mandrel: Mandrel

    def __getitem__(self, key):
        return self.as_dict()[key]

    def __iter__(self):
        return iter(self.as_dict())

    def __len__(self):
        return len(self.as_dict())

    def as_dict(self) -> dict:
        return {"path": self.path, "unit": self.unit, "n_vertices": self.n_vertices,
                "n_faces": self.n_faces, "watertight": self.watertight,
                "consistently_oriented": self.consistently_oriented, "bounds": self.bounds.tolist(),
                "volume": self.volume, "centerline": self.centerline_source,
                "centerline_length": self.centerline_length, "perimeter_min": self.perimeter_min,
                "perimeter_max": self.perimeter_max, "perimeter_min_at": self.perimeter_min_at,
                "perimeter_max_at": self.perimeter_max_at, "repairs": list(self.repairs)}


def mandrel_info(path, unit: str = "m", centerline="auto") -> MandrelInfo:
    """Load (which checks watertightness and orientation), derive or read the centerline, measure.

    path: the STL; unit "m" | "mm" its length unit; centerline "auto" or the path of an x,y,z CSV
    (same unit). Perimeter min/max are over the inner sections (the end points sit on the caps).
    """
    mandrel = load_mandrel(path, unit=unit)
    if isinstance(centerline, str) and centerline == "auto":
        cl = auto_centerline(mandrel)
        source = "auto"
    else:
        cl = read_centerline_csv(centerline, unit=unit)
        source = str(centerline)
    if cl.perimeter is None:
        cl = with_perimeter(cl, mandrel)
    inner = np.arange(1, len(cl.s) - 1) if len(cl.s) > 2 else np.arange(len(cl.s))
    if np.any(cl.perimeter[inner] > 0):
        inner = inner[cl.perimeter[inner] > 0]
    i_min = inner[np.argmin(cl.perimeter[inner])]
    i_max = inner[np.argmax(cl.perimeter[inner])]
    return MandrelInfo(path=str(Path(path)), unit=unit, n_vertices=len(mandrel.vertices),
                       n_faces=len(mandrel.faces), watertight=True, consistently_oriented=True,
                       bounds=mandrel.bounds, volume=float(mandrel.mesh.volume), centerline_source=source,
                       centerline_length=cl.length, perimeter_min=float(cl.perimeter[i_min]),
                       perimeter_max=float(cl.perimeter[i_max]), perimeter_min_at=float(cl.s[i_min]),
                       perimeter_max_at=float(cl.s[i_max]), repairs=mandrel.repairs, centerline=cl,
                       mandrel=mandrel)


def format_mandrel_info(info: MandrelInfo) -> str:
    """A few aligned lines for people (what ``preform mandrel info`` prints)."""
    b = info.bounds
    lines = [
        f"mandrel      {info.path} (stl_unit = \"{info.unit}\")",
        f"mesh         {info.n_faces} triangles, {info.n_vertices} vertices, watertight, outward, "
        f"volume {info.volume * 1e9:.6g} mm^3",
        f"bounds       x {b[0, 0]:.4f} .. {b[1, 0]:.4f} m, y {b[0, 1]:.4f} .. {b[1, 1]:.4f} m, "
        f"z {b[0, 2]:.4f} .. {b[1, 2]:.4f} m",
        f"centerline   {info.centerline_source}: {info.centerline_length:.4f} m, {len(info.centerline.s)} points",
        f"perimeter    min {info.perimeter_min * 1e3:.2f} mm, max {info.perimeter_max * 1e3:.2f} mm "
        f"(at s = {info.perimeter_min_at:.3f} m and {info.perimeter_max_at:.3f} m from the tip)",
    ]
    for r in info.repairs:
        lines.append(f"repaired     {r}")
    return "\n".join(lines)
