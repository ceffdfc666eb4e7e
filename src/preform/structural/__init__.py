"""The structural hand-off: the braided part as composite shells for CalculiX and Abaqus.

``layup`` (the plies of each face of a run and their binning into groups: the analysis),
``micromechanics`` (a ply's constants at its fibre volume fraction), ``results`` (reading
CalculiX results back); the deck ``fe/preform.inp`` and ``fe/layup.csv`` is written by
``preform.io.fe_files``, the fibre and matrix constants and presets are ``preform.materials``. The user's guide is
``docs/structural.md``.
"""
