"""preform: biaxial overbraiding on CAD mandrels (DESIGN.md)."""

from __future__ import annotations

__version__ = "0.1.0"

from .config import load_config  # noqa: E402
from .errors import ConfigError, MandrelError, PreformError, SimulationError  # noqa: E402

# Imported eagerly: a lazy wrapper named like the submodule would be replaced by the module object
# the first time ``preform.simulate`` is imported.
from .simulate import simulate  # noqa: E402


def map_to_surface(result, **kwargs):
    """Per-face fields on the mandrel mesh; see :func:`preform.fields.map_to_surface`."""
    from .fields import map_to_surface as _map

    return _map(result, **kwargs)


def write_results(result, fields, out_dir):
    """Write every result file; see :func:`preform.io.write_results`."""
    from .io import write_results as _write

    return _write(result, fields, out_dir)


__all__ = [
    "__version__",
    "load_config",
    "simulate",
    "map_to_surface",
    "write_results",
    "PreformError",
    "ConfigError",
    "MandrelError",
    "SimulationError",
]
