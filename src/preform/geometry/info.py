"""``preform mandrel info``: is the STL a usable mandrel, and what does it measure."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .centerline import Centerline, auto_centerline, read_centerline_csv, with_perimeter
from .mandrel import Mandrel, load_mandrel

#: the unit plausibility test of ``preform check`` (checks.py ``_check_unit``) without a machine:
#: the largest braiding machines have a spool circle of about this radius (m) ...
LARGEST_SPOOL_RADIUS = 1.0
#: ... and a mandrel whose bounding-box diagonal exceeds this many of them while its cross-section
#: does not fit that circle cannot be braided (checks.MAX_DIAGONAL_SPOOL_RADII)
MAX_DIAGONAL_SPOOL_RADII = 20.0
#: the narrowest braiding yarns are about this wide (m) ...
NARROWEST_YARN = 1e-3
#: ... and a mandrel smaller than this many of them cannot be braided (checks.MIN_DIAGONAL_YARN_WIDTHS)
MIN_DIAGONAL_YARN_WIDTHS = 2.0


def unit_warnings(diagonal: float, section_radius: float, unit: str) -> list[str]:
    """Sentences saying the mandrel's size is implausible in ``unit`` (an STL in mm read as m, or the
    reverse), empty when it is plausible. diagonal: bounding-box diagonal (m); section_radius: the
    largest distance of the surface from the centerline (m)."""
    if (diagonal > MAX_DIAGONAL_SPOOL_RADII * LARGEST_SPOOL_RADIUS
            and section_radius >= LARGEST_SPOOL_RADIUS):
        return [f"read with unit {unit!r}, the mandrel is {diagonal:.4g} m across (bounding-box "
                f"diagonal) and {section_radius:.4g} m from its centerline: larger than any braiding "
                f"machine (more than {MAX_DIAGONAL_SPOOL_RADII:g} x a {LARGEST_SPOOL_RADIUS:g} m spool "
                f"radius, a cross-section outside its spool circle); "
                + ("is the STL in millimetres? use --unit mm" if unit == "m" else
                   "expected a mandrel that fits a braiding machine")]
    if diagonal < MIN_DIAGONAL_YARN_WIDTHS * NARROWEST_YARN:
        return [f"read with unit {unit!r}, the mandrel is {diagonal:.4g} m across (bounding-box "
                f"diagonal): smaller than {MIN_DIAGONAL_YARN_WIDTHS:g} x the narrowest braiding yarns "
                f"({NARROWEST_YARN:g} m); "
                + ("is the STL in metres? use --unit m" if unit == "mm" else
                   "expected a mandrel larger than the yarns")]
    return []


@dataclass(frozen=True, eq=False)
class MandrelInfo(Mapping):
    """What ``preform mandrel info`` reports. A read-only dict of plain values (``info["n_faces"]``,
    ``dict(info)``, JSON-ready: the keys of ``as_dict()``) that also carries the loaded
    ``mandrel`` and the ``centerline`` (with perimeters) as attributes.

    Lengths in m, volume in m^3, bounds (2, 3) m in the mandrel frame, whatever the STL's
    ``unit``. ``watertight`` and ``consistently_oriented`` are True for every loaded mandrel:
    ``load_mandrel`` refuses the others with a MandrelError that says what is wrong.
    ``warnings``: sentences on an implausible size for ``unit`` (``unit_warnings``).
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
    warnings: tuple
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
                "perimeter_max_at": self.perimeter_max_at, "repairs": list(self.repairs),
                "warnings": list(self.warnings)}


def _enclosed_volume(mandrel) -> float:
    """Volume (m^3) of the closed mandrel: the divergence theorem, sum over faces of
    (a - c) . ((b - c) x (d - c)) / 6 about the mean c of the face corners (trimesh's mass properties,
    which also integrate the inertia, take 1.7 s on 2 M faces)."""
    from .repair import _signed_volume

    return _signed_volume(mandrel.vertices, mandrel.faces)


def mandrel_info(path, unit: str = "m", centerline="auto", body=None) -> MandrelInfo:
    """Load (which checks watertightness and orientation), derive or read the centerline, measure.

    path: the STL; unit "m" | "mm" its length unit; centerline "auto" or the path of an x,y,z CSV
    (same unit); body: which body of a multi-body STL (``load_mandrel``). Perimeter min/max are
    over the inner sections (the end points sit on the caps).
    """
    mandrel = load_mandrel(path, unit=unit, body=body)
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
    # a convex section inside the circle of its largest radius R is at most 2 pi R around: the
    # perimeter's radius is a lower bound on the section's reach (no warning from it by mistake)
    section_radius = float(cl.perimeter[i_max]) / (2 * np.pi)
    return MandrelInfo(path=str(Path(path)), unit=unit, n_vertices=len(mandrel.vertices),
                       n_faces=len(mandrel.faces), watertight=True, consistently_oriented=True,
                       bounds=mandrel.bounds, volume=_enclosed_volume(mandrel), centerline_source=source,
                       centerline_length=cl.length, perimeter_min=float(cl.perimeter[i_min]),
                       perimeter_max=float(cl.perimeter[i_max]), perimeter_min_at=float(cl.s[i_min]),
                       perimeter_max_at=float(cl.s[i_max]), repairs=mandrel.repairs,
                       warnings=tuple(unit_warnings(float(mandrel.diagonal), section_radius, unit)),
                       centerline=cl,
                       mandrel=mandrel)


def format_mandrel_info(info: MandrelInfo) -> str:
    """A few aligned lines for people (what ``preform mandrel info`` prints): every length in metres
    (the unit of the config and of the results), whatever the STL's unit, which the first line names."""
    b = info.bounds
    lines = [
        f"mandrel      {info.path} (read as stl_unit = \"{info.unit}\"; lengths below in m)",
        f"mesh         {info.n_faces} triangles, {info.n_vertices} vertices, watertight, outward, "
        f"volume {info.volume:.6g} m^3",
        f"bounds       x {b[0, 0]:.4f} .. {b[1, 0]:.4f} m, y {b[0, 1]:.4f} .. {b[1, 1]:.4f} m, "
        f"z {b[0, 2]:.4f} .. {b[1, 2]:.4f} m",
        f"centerline   {info.centerline_source}: {info.centerline_length:.4f} m, {len(info.centerline.s)} points",
        f"perimeter    min {info.perimeter_min:.5f} m, max {info.perimeter_max:.5f} m "
        f"(at s = {info.perimeter_min_at:.3f} m and {info.perimeter_max_at:.3f} m from the tip)",
    ]
    for r in info.repairs:
        lines.append(f"repaired     {r}")
    return "\n".join(lines)
