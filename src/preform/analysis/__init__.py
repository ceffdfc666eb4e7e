"""The analysis stage: everything derived from a simulated run, computed before anything is
written (docs/architecture.md §4).

``fields`` (the laid yarns pooled into per-face fields on the field mesh), ``steady`` (where the
run is in steady state), ``interlacing`` (warp-weft crossings against the pattern's),
``quality`` (the verdict), ``rtm`` (fibre content and permeability for resin transfer
moulding) and ``derived`` (the structural plies, the snapshot checks and the summary's figures).
The submodules are imported where used, so that importing this package stays light.
"""
