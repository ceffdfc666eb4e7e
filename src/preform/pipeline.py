"""One case from config to result files: what ``preform run`` does, callable from a sweep worker.

``run_case`` loads and checks the geometry, simulates (with a checkpoint in the results folder),
maps the fields and writes every result file. It returns a :class:`CaseOutcome` instead of
printing, so the CLI and a sweep's workers run exactly the same path.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

#: the state of a running simulation, saved periodically and on a stop, removed once the results
#: are written
CHECKPOINT = "checkpoint.npz"


@dataclass
class CaseOutcome:
    """result: preform.result.Result; written: paths written (summary.json last); notes: the
    repairs and pre-flight warnings, in order, for the caller to show."""

    result: object
    out_dir: Path
    written: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def status(self) -> str:
        return self.result.status


def checked_geometry(config):
    """(mandrel, centerline, notes): the geometry of ``config`` after the pre-flight checks.

    Impossible set-ups raise PreformError; the mandrel's repairs and the doubtful points come back
    as notes ("mandrel: ...", "warning: ...").
    """
    from .checks import preflight
    from .simulation import load_geometry

    mandrel, centerline = load_geometry(config)
    notes = [f"mandrel: {repair}" for repair in mandrel.repairs]
    notes += [f"warning: {w}" for w in preflight(config, mandrel, centerline)]
    return mandrel, centerline, notes


def run_case(config, out_dir, *, progress=False, resume=False, geometry=None) -> CaseOutcome:
    """Simulate ``config`` and write its results into ``out_dir`` (see module docstring).

    geometry : (mandrel, centerline, notes) already checked, or None to load and check here.
    Raises PreformError for bad input (before simulating) and OSError when writing fails.
    """
    from .fields import map_to_surface
    from .io import write_results
    from .simulation import simulate

    out_dir = Path(out_dir)
    mandrel, centerline, notes = geometry if geometry is not None else checked_geometry(config)
    result = simulate(config, progress=progress, mandrel=mandrel, centerline=centerline,
                      checkpoint=out_dir / CHECKPOINT, resume=resume)
    fields = map_to_surface(result) if len(result.yarns.points) else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        written = write_results(result, fields, out_dir)
    notes += [f"warning: {w.message}" for w in caught]
    return CaseOutcome(result=result, out_dir=out_dir, written=written, notes=notes)
