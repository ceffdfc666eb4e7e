"""Measure, compare, calibrate, re-run: the friction and initial position of a small machine.

    python examples/calibration.py [--out DIR] [--workers N]

A 16-carrier machine braids a 75 mm cylinder with the yarn-interaction model (no guide ring).
The "real braid" is a run at yarn friction 0.22 and initial position 85 mm, sampled the way
one measures a braid, with Gaussian noise: 60 braid angles on the part (as image analysis gives
them), the convergence length every other time step, and 40 points along the free yarns in the
zone at the end (as photogrammetry gives them). The machine's config (``<out>/case.toml``) has the values one
would guess, friction 0 and 80 mm.

1. ``preform run`` the guessed config and ``preform compare`` it with the measurements;
2. ``preform calibrate`` friction (0 to 0.5) and initial position (60 to 120 mm) against
   precise measurements (0.02 deg, 0.05 mm, 0.02 mm of noise) and against measurements with
   the noise of a workshop (0.5 deg, 1 mm, 1 mm);
3. ``preform run`` the ``calibrated.toml`` of the precise calibration and compare it again.

Everything goes to ``<out>`` (default ``examples/results/calibration``); the pictures of
``docs/calibration.md`` are ``<out>/compare_guess/compare.png``, the calibrations'
``plots/misfit_*.png`` and ``<out>/compare_calibrated/compare.png``.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TRUTH = {"friction": 0.22, "initial_position": 0.085}
GUESS = {"friction": 0.0, "initial_position": 0.08}
PRECISE = {"angle": 0.02, "convergence": 5e-5, "yarn": 2e-5}
WORKSHOP = {"angle": 0.5, "convergence": 1e-3, "yarn": 1e-3}

CASE = """# A small machine: 16 carriers round a 75 mm cylinder, the yarn-interaction model
[mandrel]
stl = "cylinder.stl"
centerline = "cylinder.csv"

[machine]
carriers = 16
spool_radius = 0.12
angular_speed = 13.232

[yarn]
width = 4e-3
thickness = 2.5e-4
friction = {friction}

[process]
take_up_speed = 0.01
initial_position = {initial_position}
braid_length = 0.12

[model]
kind = "interaction"

[output]
dir = "{dir}"
snapshots = 2
"""


def write_case(folder: Path, name: str, values: dict, results: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(CASE.format(dir=results, **values))
    return path


def measure(run: Path, out: Path, noise: dict, seed: int) -> list[Path]:
    """The run sampled as a braid is measured, with Gaussian noise of ``noise`` per kind."""
    from preform.studies.compare import history_curve, load_run
    from preform.analysis.interlacing import azimuths

    rng = np.random.default_rng(seed)
    r = load_run(run)
    s, phi = azimuths(r.vertices[r.faces].mean(axis=1), r.centerline)
    phi = np.degrees(phi)
    a = r.cell_data["braid_angle_deg"]
    faces = rng.choice(np.flatnonzero(a > 0), 60, replace=False)
    files = [out / "angles.csv", out / "convergence.csv", out / "yarns.csv"]
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(files[0], np.column_stack([s[faces], phi[faces], a[faces] + rng.normal(0, noise["angle"], 60)]),
               delimiter=",", header="arc_length_m,azimuth_deg,braid_angle_deg", comments="", fmt="%.6f")
    L, H = history_curve(r)
    np.savetxt(files[1], np.column_stack([L[1::2], H[1::2] + rng.normal(0, noise["convergence"], len(L[1::2]))]),
               delimiter=",", header="braided_length_m,convergence_length_m", comments="", fmt="%.7f")
    pts, segs = r.snapshot(len(r.snapshot_files) - 1)      # points along the free yarns
    k, u = rng.integers(0, len(segs), 40), rng.uniform(0, 1, (40, 1))
    on = pts[segs[k, 0]] + u * (pts[segs[k, 1]] - pts[segs[k, 0]])
    np.savetxt(files[2], on + rng.normal(0, noise["yarn"], on.shape), delimiter=",",
               header="x_m,y_m,z_m", comments="", fmt="%.7f")
    return files


def preform(*args) -> None:
    from preform.cli import main as cli

    print("$ preform " + " ".join(str(a) for a in args), flush=True)
    code = cli([str(a) for a in args])
    if code != 0:
        raise SystemExit(f"preform {args[0]} failed with exit code {code}")


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="output folder (default examples/results/calibration)")
    ap.add_argument("--workers", type=int, default=2, help="Dask workers of the calibrations")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve() if args.out else HERE / "results" / "calibration"
    out.mkdir(parents=True, exist_ok=True)
    from preform.geometry import shapes
    import trimesh

    v, f = shapes.cylinder(0.075, 0.3, n_around=64)
    trimesh.Trimesh(v, f, process=False).export(out / "cylinder.stl")
    np.savetxt(out / "cylinder.csv", [[0, 0, 0], [0, 0, 0.3]], delimiter=",", header="x,y,z", comments="")

    # the real braid, measured
    truth = write_case(out, "truth", TRUTH, "results/truth")
    preform("run", truth, "--no-progress")
    precise = measure(out / "results" / "truth", out / "measured_precise", PRECISE, seed=7)
    workshop = measure(out / "results" / "truth", out / "measured_workshop", WORKSHOP, seed=8)

    # 1. the guess against the measurements
    case = write_case(out, "case", GUESS, "results/guess")
    preform("run", case, "--no-progress")
    preform("compare", out / "results" / "guess", *precise, "--out", out / "compare_guess")

    # 2. calibrate, with precise and with workshop measurements
    ranges = ["--param", "yarn.friction=0:0.5:3", "--param", "process.initial_position=0.06:0.12:4"]
    for name, files in (("precise", precise), ("workshop", workshop)):
        preform("calibrate", case, *files, *ranges, "--workers", args.workers,
                "--out", out / f"calibration_{name}", "--no-progress")

    # 3. re-run the calibrated config, compare again
    calibrated = out / "calibration_precise" / "calibrated.toml"
    preform("run", calibrated, "--no-progress")
    preform("compare", out / "calibration_precise" / "calibrated", *precise,
            "--out", out / "compare_calibrated")
    report = json.loads((out / "calibration_precise" / "calibrate.json").read_text())
    for key, p in report["parameters"].items():
        truth_value = TRUTH[key.split(".")[1]]
        print(f"{key}: truth {truth_value:g}, calibrated {p['value']:.4g} ± {p['sigma']:.2g}")
    return out


def copy_pictures(out: Path, docs: Path) -> None:
    """The pictures of docs/calibration.md, from a finished ``main`` into ``docs``."""
    docs.mkdir(parents=True, exist_ok=True)
    for src, name in ((out / "compare_guess" / "compare.png", "compare_guess.png"),
                      (out / "compare_calibrated" / "compare.png", "compare_calibrated.png")):
        shutil.copyfile(src, docs / name)
    for cal in ("precise", "workshop"):
        for png in sorted((out / f"calibration_{cal}" / "plots").glob("misfit_*.png")):
            shutil.copyfile(png, docs / f"{cal}_{png.name}")


if __name__ == "__main__":
    main()
