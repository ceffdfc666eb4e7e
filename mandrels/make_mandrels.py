"""Make the shipped mandrels: binary STLs in metres with their centerline CSVs (x,y,z, tip first).

Run from anywhere: ``python mandrels/make_mandrels.py``. Every mandrel has its tip at the origin
and runs along +z (the bent tube turns towards +x).

- case_a: the reference paper's case A cylinder, diameter 150 mm (Ko's formula with the steady
  60 deg angle: r = v tan(60) / omega = 0.01 * 1.732 / 0.2309 = 75 mm), 3 m long: long enough
  for examples/case_a.toml to braid to steady state (1.6 m braided, 0.8 m convergence zone).
- case_b: rounded square (90 mm, corner radius 15 mm) blending into a circle of the same
  perimeter between 0.9 and 1.1 m, 1.5 m long (like the paper's Fig. 11).
- bent_tube: rounded square 60 mm, 0.4 m straight, a 90 deg bend of radius 0.35 m, 0.4 m straight.
- cone: radius 40 -> 80 mm over 1 m.
- waist: radius 75 mm with an hourglass dip to 45 mm (Gaussian, width 30 mm): concave enough
  axially that yarns bridge.
- bulge: radius 50 mm with a ring bulge to 90 mm (Gaussian, width 15 mm): steep enough that free
  yarns catch on it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from preform.geometry import shapes

HERE = Path(__file__).resolve().parent


def straight(length):
    return np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]])


MANDRELS = {
    "case_a": (lambda: shapes.cylinder(0.075, 3.0, n_around=128), straight(3.0)),
    "case_b": (lambda: shapes.case_b(n_around=128, spacing=0.01), straight(1.5)),
    "bent_tube": (lambda: shapes.bent_tube(n_around=96, spacing=0.008), shapes.bent_tube_path()),
    "cone": (lambda: shapes.cone(0.04, 0.08, 1.0, n_around=128, n_along=100), straight(1.0)),
    # 240 rings (5 mm) resolve the 30 mm / 15 mm Gaussians and keep the files under 3 MiB
    "waist": (lambda: shapes.waist(n_around=128, n_along=240), straight(1.2)),
    "bulge": (lambda: shapes.bulge(n_around=128, n_along=240), straight(1.2)),
}


def write(name, out_dir=None):
    """Write ``<name>.stl`` (binary, m) and ``<name>_centerline.csv`` (x,y,z, tip first) into out_dir
    (default: this folder)."""
    out_dir = Path(out_dir or HERE)
    make, path = MANDRELS[name]
    vertices, faces = make()
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, name
    stl = Path(out_dir) / f"{name}.stl"
    _atomic(stl, lambda tmp: mesh.export(tmp, file_type="stl"))
    _atomic(Path(out_dir) / f"{name}_centerline.csv",
            lambda tmp: np.savetxt(tmp, path, delimiter=",", header="x,y,z", comments="", fmt="%.9g"))
    return stl


def _atomic(target, write_to):
    """Write through a temporary name beside target, then rename (no half files)."""
    tmp = target.with_name(f".{target.name}.tmp")
    try:
        write_to(str(tmp))
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def main(out_dir=None):
    """Write every mandrel into out_dir (default: this folder)."""
    for name in MANDRELS:
        stl = write(name, out_dir)
        n_faces = len(trimesh.load(stl, file_type="stl").faces)
        print(f"{name}: {n_faces} triangles, {stl.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
