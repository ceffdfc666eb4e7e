"""Make the shipped mandrels: binary STLs in metres with their centerline CSVs (x,y,z, tip first).

Run from anywhere: ``python mandrels/make_mandrels.py``. Every mandrel has its tip at the origin
and runs along +z (the bent tube turns towards +x).

- case_a: the reference paper's case A cylinder, diameter 150 mm (Ko's formula with the steady
  60 deg angle: r = v tan(60) / omega = 0.01 * 1.732 / 0.2309 = 75 mm), 2 m long.
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

from pathlib import Path

import numpy as np
import trimesh

from preform.geometry import shapes

HERE = Path(__file__).resolve().parent


def straight(length):
    return np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]])


MANDRELS = {
    "case_a": (lambda: shapes.cylinder(0.075, 2.0, n_around=128), straight(2.0)),
    "case_b": (lambda: shapes.case_b(), straight(1.5)),
    "bent_tube": (lambda: shapes.bent_tube(), shapes.bent_tube_path()),
    "cone": (lambda: shapes.cone(0.04, 0.08, 1.0, n_around=128, n_along=100), straight(1.0)),
    "waist": (lambda: shapes.waist(), straight(1.2)),
    "bulge": (lambda: shapes.bulge(), straight(1.2)),
}


def main():
    for name, (make, path) in MANDRELS.items():
        vertices, faces = make()
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.volume > 0, name
        mesh.export(HERE / f"{name}.stl")
        np.savetxt(HERE / f"{name}_centerline.csv", path, delimiter=",", header="x,y,z", comments="",
                   fmt="%.9g")
        print(f"{name}: {len(faces)} triangles, {(HERE / f'{name}.stl').stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
