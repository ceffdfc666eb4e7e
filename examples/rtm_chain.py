"""The chain from braiding to resin flow: braid case B, export for RTM, map Vf and K1.

    python examples/rtm_chain.py [--length M] [--out DIR]

Runs ``examples/case_b_rtm.toml`` (case B with the paper's 300 tex E-glass, compressed into an
80 um cavity: a fibre volume fraction of about 0.49) the way ``preform run`` does, then draws the
fibre volume fraction, the principal permeability K1 and the porosity on the unrolled surface
(``<out>/plots/rtm_map.png``). The solver files are in ``<out>/rtm/``: ``lcmsim.h5`` for LCMsim
(every face's values), ``rtmsim.bdf`` + ``rtmsim_sets.csv`` for RTMsim (its four property sets).
It prints every file it made, the sets and their binning error, and the fibre content.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import preform as pf
from preform.io.maps import RTM_PANELS, write_surface_map
from preform.io.plots import run_title
from preform.pipeline import run_case

HERE = Path(__file__).resolve().parent


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, help="braided length (m; default the config's 1.2)")
    ap.add_argument("--out", help="results folder (default the config's)")
    args = ap.parse_args(argv)
    config = pf.load_config(HERE / "case_b_rtm.toml")
    if args.length:
        config = dataclasses.replace(config, process=dataclasses.replace(config.process, braid_length=args.length))
    out = Path(args.out) if args.out else config.output.dir
    outcome = run_case(config, out)
    from preform.analysis.fields import map_to_surface
    from preform.pipeline import with_rtm_fields

    fields = with_rtm_fields(outcome.result, map_to_surface(outcome.result))
    png = write_surface_map(fields, outcome.result.centerline, out / "plots" / "rtm_map.png",
                            run_title(outcome.result, "RTM hand-off: fibre content and permeability"),
                            panels=RTM_PANELS)
    said = json.loads((out / "summary.json").read_text())["rtm"]
    print(f"results: {out} (status {outcome.result.status})")
    if not said.get("written"):
        print(f"RTM files: none ({said.get('reason')})")
        return png
    vf, binning = said["fibre_volume_fraction"], said["k1_binning"]
    print("  rtm/lcmsim.h5          LCMsim: mesh and every face's thickness, porosity, K1, K2/K1, direction")
    print(f"  rtm/rtmsim.bdf         RTMsim: mesh (Nastran), {said['sets']} property sets as SET1 cards")
    print("  rtm/rtmsim_sets.csv    RTMsim's patch table: each set's values, by the bdf's property id")
    print("  plots/rtm_map.png      fibre volume fraction, K1 and porosity, unrolled")
    print(f"sets: faces {said['faces_per_set']} (the last: {said['faces'] - said['preform_faces']} faces "
          f"without preform, a resin channel); K1 binning error: typically x{binning['rms_factor']:.2f}, "
          f"at most x{binning['max_factor']:.1f} (docs/guide/results.md)")
    squeeze = f", compressed {said['compression']:.1f} times" if said.get("compression") else ""
    print(f"fibre volume fraction {vf['mean']:.2f} (area mean; {vf['min']:.2f}-{vf['max']:.2f}){squeeze}")
    return png


if __name__ == "__main__":
    main()
