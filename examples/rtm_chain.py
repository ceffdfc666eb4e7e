"""The chain from braiding to resin flow: braid case B, export for RTM, map Vf and K1.

    python examples/rtm_chain.py [--length M] [--out DIR]

Runs ``examples/case_b_rtm.toml`` (case B with the paper's 300 tex E-glass and a 1.2 mm cavity)
the way ``preform run`` does, then draws the fibre volume fraction, the principal permeability
K1 and the porosity on the unrolled surface (``<out>/plots/rtm_map.png``). The solver files are in
``<out>/rtm/``: ``lcmsim.h5`` for LCMsim, ``rtmsim.bdf`` + ``rtmsim_sets.csv`` for RTMsim.
"""

from __future__ import annotations

import argparse
import dataclasses
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
    print(f"results: {out}; RTM files in {out / 'rtm'}; map {png}")
    return png


if __name__ == "__main__":
    main()
