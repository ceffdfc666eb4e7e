"""Errors meant for people.

Every error a user can cause derives from :class:`PreformError`; the CLI prints its message (no
traceback) and exits with its ``exit_code``. A message names the input, the value and what is
expected, e.g. ``[machine] carriers = 95: expected an even number divisible by 4 for pattern
"regular" (2/2)``.
"""

from __future__ import annotations


class PreformError(Exception):
    """Base of all user-facing errors. ``exit_code`` is what the CLI returns."""

    exit_code = 2


class ConfigError(PreformError):
    """A configuration value is missing, unknown, of the wrong type or out of range."""


class MandrelError(PreformError):
    """The mandrel STL or its centerline cannot be used (not watertight, unreadable, ...)."""


class SimulationError(PreformError):
    """The simulation failed (no convergence, non-finite value). Partial results are kept."""

    exit_code = 1
