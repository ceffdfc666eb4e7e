"""The reference paper's parametric studies (Table C.2): one curve per value, braid angle and
convergence length against braided length.

    python examples/studies.py case_a_friction        # mu_y = 0.0 ... 0.5, M_int = 0.4 m
    python examples/studies.py case_a_position        # M_int = 0.2 ... 0.8 m, mu_y = 0.3
    python examples/studies.py case_b_friction        # mu_y = 0, 0.25, 0.5, H_int = 0.2 m
    options: --model kinematic|interaction (default interaction), --length M (braided length),
             --carriers N (fewer carriers for a quick look), --values V [V ...] (some of the
             study's values only), --out DIR

Each study writes ``<out>/<study>.png`` and ``<out>/<study>.csv`` (braided length, then the
braid angle and convergence length of every run).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

import preform as pf

HERE = Path(__file__).resolve().parent

STUDIES = {
    "case_a_friction": ("case_a.toml", "yarn", "friction", [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], {"initial_position": 0.4}),
    "case_a_position": ("case_a.toml", "process", "initial_position", [0.2, 0.4, 0.6, 0.8], {"friction": 0.3}),
    "case_b_friction": ("case_b.toml", "yarn", "friction", [0.0, 0.25, 0.5], {"initial_position": 0.2}),
}


def _replace(cfg, section, key, value):
    return dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section), **{key: value})})


def study_configs(name, model="interaction", length=None, carriers=None, values=None):
    """(label, Config) per value of the study (``values``: a subset of them, default all)."""
    toml, section, key, all_values, fixed = STUDIES[name]
    if values is None:
        values = all_values
    else:
        values = [float(v) for v in values]
        unknown = [v for v in values if not any(np.isclose(v, a) for a in all_values)]
        if unknown:
            raise SystemExit(f"--values {' '.join(f'{v:g}' for v in unknown)}: not among the "
                             f"values of {name} ({', '.join(f'{a:g}' for a in all_values)})")
        values = [next(a for a in all_values if np.isclose(v, a)) for v in values]
    base = pf.load_config(HERE / toml)
    for k, v in fixed.items():
        base = _replace(base, "yarn" if k == "friction" else "process", k, v)
    base = _replace(base, "model", "kind", model)
    # the studies read history.csv only: no convergence-zone snapshots (each one re-solves the
    # zone to convergence)
    base = _replace(base, "output", "snapshots", 0)
    if length is not None:
        base = _replace(base, "process", "braid_length", length)
    if carriers is not None:
        base = _replace(base, "machine", "carriers", carriers)
    return [(f"{key} = {v}", _replace(base, section, key, v)) for v in values]


def run_study(name, out, model="interaction", length=None, carriers=None, progress=True,
              values=None):
    """Run every case of a study (or those of ``values``); write the plot and the table; return
    {label: Result}."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for label, cfg in study_configs(name, model, length, carriers, values):
        results[label] = pf.simulate(cfg, progress=progress)
        if results[label].status != "done":
            print(f"{name}, {label}: {results[label].status}: {results[label].message}")
        # plot and table after every run: a long study stopped half-way keeps its curves
        _plot(name, results, out / f"{name}.png")
        _table(results, out / f"{name}.csv")
    return results


def _plot(name, results, path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.2))
    FigureCanvasAgg(fig)
    ax_a, ax_h = fig.subplots(1, 2)
    for label, r in results.items():
        h = r.history
        L = h["braided_length_m"]
        if r.status != "done":
            label = f"{label} ({r.status} at {L[-1]:.2f} m)" if len(L) else f"{label} ({r.status})"
        ax_a.plot(L, 0.5 * (h["braid_angle_warp_deg"] + h["braid_angle_weft_deg"]), label=label)
        ax_h.plot(L, h["convergence_length_mean_m"], label=label)
    ax_a.set(xlabel="braided length L (m)", ylabel="braid angle (deg)", title=name)
    ax_h.set(xlabel="braided length L (m)", ylabel="convergence length H (m)")
    for ax in (ax_a, ax_h):
        ax.grid(alpha=0.3)
    ax_h.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _table(results, path):
    L = max((r.history["braided_length_m"] for r in results.values()), key=lambda a: a[-1])
    cols = [L]
    header = ["braided_length_m"]
    for label, r in results.items():
        h = r.history
        angle = 0.5 * (h["braid_angle_warp_deg"] + h["braid_angle_weft_deg"])
        # a run that stopped early has no values beyond where it stopped
        right = None if r.status == "done" else np.nan
        cols += [np.interp(L, h["braided_length_m"], angle, right=right),
                 np.interp(L, h["braided_length_m"], h["convergence_length_mean_m"], right=right)]
        header += [f"braid_angle_deg[{label}]", f"convergence_length_m[{label}]"]
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("study", choices=sorted(STUDIES))
    ap.add_argument("--model", default="interaction", choices=["kinematic", "interaction"])
    ap.add_argument("--length", type=float, help="braided length (m)")
    ap.add_argument("--carriers", type=int, help="override the carrier count")
    ap.add_argument("--values", type=float, nargs="+", help="some of the study's values only")
    ap.add_argument("--out", default=str(HERE / "results" / "studies"))
    args = ap.parse_args(argv)
    run_study(args.study, args.out, args.model, args.length, args.carriers, values=args.values)
    print(f"{args.study}: {Path(args.out) / (args.study + '.png')}")


if __name__ == "__main__":
    main()
