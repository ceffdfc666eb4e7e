"""The package version, in a leaf module so that modules of ours that record it (checkpoints,
``summary.json``, ``--version``) need not import the package's ``__init__``."""

__version__ = "0.1.0"
