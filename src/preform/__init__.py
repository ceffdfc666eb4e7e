"""preform: biaxial overbraiding on CAD mandrels (docs/architecture.md).

``import preform`` is light: reading and checking a config needs only the standard library and
NumPy. The names that need numba, SciPy, trimesh or pyvista (``simulate``, ``map_to_surface``,
``write_results``, ``SurfaceFields``, ``Mandrel``, ``Settings``, ...) load their module on first
use (a module ``__getattr__``, PEP 562) and are the functions and types themselves, with their own signatures.
"""

from __future__ import annotations

from ._version import __version__
from .config import Config, load_config
from .errors import ConfigError, MandrelError, PreformError, SimulationError
from .result import Result, Snapshot, YarnPaths
from .tolerances import Tolerances, tol

#: the public names imported on first use (``__getattr__``)
_LAZY = ("simulate", "map_to_surface", "SurfaceFields", "write_results", "load_mandrel", "Mandrel",
         "Centerline", "CheckpointError", "sweep", "design_speed", "Settings")


def __getattr__(name):
    """The lazy names of ``_LAZY``: import their module, keep the object here, return it."""
    if name == "simulate":
        from .simulation import simulate as value
    elif name in ("map_to_surface", "SurfaceFields"):
        from .analysis import fields
        value = getattr(fields, name)
    elif name == "write_results":
        from .pipeline import write_results as value   # analyse, then write
    elif name in ("load_mandrel", "Mandrel", "Centerline"):
        from . import geometry
        value = getattr(geometry, name)
    elif name == "CheckpointError":
        from .checkpoint import CheckpointError as value
    elif name == "sweep":   # the module is preform.studies.sweeps, so this name stays the function
        from .studies.sweeps import sweep as value
    elif name == "design_speed":
        from .studies.design import design_speed as value
    elif name == "Settings":   # the numerical settings' tree: imports every stage's settings
        from .settings import Settings as value
    else:
        raise AttributeError(f"module 'preform' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "__version__",
    "load_config",
    "simulate",
    "map_to_surface",
    "write_results",
    "sweep",
    "design_speed",
    "load_mandrel",
    "Config",
    "Result",
    "YarnPaths",
    "Snapshot",
    "SurfaceFields",
    "Mandrel",
    "Centerline",
    "Settings",
    "Tolerances",
    "tol",
    "PreformError",
    "ConfigError",
    "MandrelError",
    "SimulationError",
    "CheckpointError",
]
