"""From braiding to a structural result: braid two layers on the cone, solve the composite shells
with CalculiX under axial tension, and draw the deformed part.

    python examples/structural_chain.py [--length M] [--edge M] [--out DIR]

Runs ``examples/two_layers.toml`` (two carbon layers, their ``[material]`` AS4/3501-6) the way
``preform run`` does; the deck ``<out>/fe/preform.inp`` gets its own commented tension step
(the narrow end held, 1 kN along the axis at the wide end) and ``ccx`` solves it in ``<out>/fe/``
(``tension.frd`` for ParaView through ``ccx2paraview``, ``tension.dat``). The picture
``<out>/plots/structural_deformed.png`` shows the shells displaced (magnified) and coloured by
the displacement along the axis.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

import preform as pf
from preform.pipeline import run_case
from preform.structural.results import displacements, read_mesh, template_step

HERE = Path(__file__).resolve().parent
PICTURE = "structural_deformed.png"


def solve(fe: Path, job: str = "tension") -> Path:
    """The deck with its template step and the END/BRAIDED displacements printed, run by ccx."""
    ccx = shutil.which("ccx")
    if ccx is None:
        raise SystemExit("ccx (CalculiX) not found: install it (Debian/Ubuntu: apt install calculix-ccx)")
    deck = (fe / "preform.inp").read_text()
    step = template_step(deck).replace("*END STEP", "*NODE PRINT, NSET=BRAIDED\nU\n*END STEP")
    (fe / f"{job}.inp").write_text(deck + step)
    done = subprocess.run([ccx, "-i", job], cwd=fe, capture_output=True, text=True)
    if done.returncode != 0 or "Job finished" not in done.stdout:
        raise SystemExit(f"ccx failed:\n{done.stdout[-3000:]}{done.stderr[-2000:]}")
    return fe / f"{job}.dat"


def draw(fe: Path, dat: Path, png: Path, title: str) -> Path:
    """The shells' corner triangles displaced by ``scale`` x u, coloured by u along the axis."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    ids, xyz, elements = read_mesh(fe / "preform.inp")
    printed, u = displacements(dat, "BRAIDED")
    where = np.searchsorted(ids, printed)
    U = np.zeros_like(xyz)
    U[where] = u
    size = float(np.ptp(xyz, axis=0).max())
    # most displacements within 8 % of the part (the END edge's nodal loads make a few spikes)
    scale = 0.08 * size / max(float(np.percentile(np.linalg.norm(U, axis=1), 99)), 1e-30)
    tri = np.searchsorted(ids, elements[:, :3])
    faces = np.column_stack([np.full(len(tri), 3), tri]).ravel()
    before = pv.PolyData(xyz, faces)
    after = pv.PolyData(xyz + scale * U, faces)
    after.point_data["u_axial_mm"] = U[:, 2] * 1e3
    plotter = pv.Plotter(off_screen=True, window_size=(1600, 900))
    plotter.add_mesh(before, style="wireframe", color="#9a9a9a", opacity=0.25)
    plotter.add_mesh(after, scalars="u_axial_mm", cmap="viridis",
                     scalar_bar_args={"title": "displacement along the axis (mm)"})
    plotter.add_text(f"{title}\ndisplacements x {scale:.0f}", font_size=12)
    centre = xyz.mean(axis=0)
    _, _, vt = np.linalg.svd(xyz - centre, full_matrices=False)   # the part's long axis: vt[0]
    plotter.view_vector(vt[1] + 0.4 * vt[0] + 0.3 * vt[2], viewup=vt[2])
    plotter.reset_camera(bounds=after.bounds)
    plotter.camera.zoom(1.4)
    png.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(png))
    plotter.close()
    return png


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, help="braided length of each layer (m; default the config's 0.7)")
    ap.add_argument("--edge", type=float, help="field mesh edge (m; default the config's)")
    ap.add_argument("--out", help="results folder (default the config's)")
    args = ap.parse_args(argv)
    config = pf.load_config(HERE / "two_layers.toml")
    if args.length:
        config = dataclasses.replace(config, process=dataclasses.replace(config.process, braid_length=args.length))
    if args.edge:
        config = dataclasses.replace(config, output=dataclasses.replace(config.output, field_edge_length=args.edge))
    out = Path(args.out) if args.out else config.output.dir
    run_case(config, out)
    fe = out / "fe"
    png = draw(fe, solve(fe), out / "plots" / PICTURE,
               "Two braided carbon layers on the cone, 1 kN axial tension (CalculiX)")
    print(f"results: {out}; deck {fe / 'preform.inp'}; ccx results {fe / 'tension.frd'}; picture {png}")
    return png


if __name__ == "__main__":
    main()
