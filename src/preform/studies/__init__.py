"""Studies built on runs: ``sweeps`` (parameter sweeps on Dask), ``design`` (the take-up speed
for a target braid angle), ``compare`` (a run against measured braid angles) and ``calibrate``
(parameters fitted to measurements). Each runs the pipeline (``preform.pipeline``) or the
simulation; the submodules are imported where used.
"""
