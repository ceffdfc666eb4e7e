"""One case from config to result files: what ``preform run`` does, callable from a sweep worker.

:func:`run_case` does, in this order, so that nothing is lost and nothing is written elsewhere:

1. load and check the geometry (impossible set-ups raise before anything runs);
2. estimate the work (field faces, steps, result size: ``preform.budget``) and refuse what is
   beyond its limits unless ``force``;
3. check that the results folder can be created and written and has room (``io.folder``), and
   take its lock (one run per folder);
4. simulate, with the checkpoint in the results folder; when the run is done its final state is
   saved there too;
5. map the fields and write every result file; only then is the checkpoint removed. If writing
   fails, the checkpoint stays and the error says how to finish: ``--resume`` on a finished
   checkpoint writes the results without simulating again.

It returns a :class:`CaseOutcome` instead of printing, so the CLI and a sweep's workers run
exactly the same path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import PreformError

#: the state of a running simulation, saved periodically and on a stop, removed once the results
#: are written
CHECKPOINT = "checkpoint.npz"


class ResultsWriteError(PreformError):
    """The results could not be written; the simulation is kept in the checkpoint."""

    exit_code = 1


@dataclass
class CaseOutcome:
    """result: preform.result.Result; written: paths written (summary.json last); notes: the
    repairs, pre-flight warnings and estimates, in order, for the caller to show."""

    result: object
    out_dir: Path
    written: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def status(self) -> str:
        return self.result.status


def checked_geometry(config):
    """(mandrel, centerline, notes): the geometry of ``config`` after the pre-flight checks.

    Impossible set-ups raise PreformError; the mandrel's repairs, the doubtful points and the
    quasi-static references (Ko, H_inf, whether the braid can settle) come back as notes.
    """
    from .checks import preflight
    from .simulation import load_geometry

    mandrel, centerline = load_geometry(config)
    notes = [f"mandrel: {repair}" for repair in mandrel.repairs]
    notes += [f"warning: {w}" for w in preflight(config, mandrel, centerline)]
    notes += [f"note: {line}" for line in reference_lines(config, mandrel, centerline)]
    return mandrel, centerline, notes


def reference_lines(config, mandrel, centerline) -> list[str]:
    """``preform.reference.check_lines`` over the part to braid (sections every ~2 cm)."""
    from .geometry.centerline import section_perimeters
    from .reference import check_lines, references

    end = min(float(config.process.braid_length), float(centerline.length))
    s = np.linspace(0.0, end, 25)
    perimeter = section_perimeters(mandrel, centerline, s)
    ok = perimeter > 0
    if np.count_nonzero(ok) < 2:
        return []
    return check_lines(config, references(config, s[ok], perimeter[ok]))


def estimate(config, mandrel, centerline, *, force=False):
    """The work estimate of a run (``preform.budget``), refused beyond its limits unless ``force``."""
    from .budget import check_work, estimate_work
    from .machine import Machine
    from .reference import end_convergence_length, resolve_pose_lead
    from .stepping import default_time_step

    config = resolve_pose_lead(config, mandrel, centerline)
    dt = config.model.time_step or default_time_step(config, Machine.from_config(config.machine),
                                                     mandrel, centerline)
    tri = np.asarray(mandrel.vertices)[np.asarray(mandrel.faces)]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    distance = centerline.project(mandrel.vertices)[1]
    work = estimate_work(config, area, dt, end_convergence_length(config, float(np.median(distance))))
    max_radius = float(np.max(distance))
    check_work(config, work, max_radius, force=force)
    return work


def with_rtm_fields(result, fields):
    """``fields`` with the RTM arrays (``preform.rtm``) when the config has tow material data."""
    from .rtm import missing_material, rtm_fields

    if fields is None or missing_material(result.config):
        return fields
    V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
    s, _ = result.centerline.project(V[F].mean(axis=1))
    tangents = result.centerline.frames_at(s)[1]
    fields.cell_data.update(rtm_fields(fields, result.config, tangents))
    return fields


def run_case(config, out_dir, *, progress=False, resume=False, force=False, geometry=None,
             started=None) -> CaseOutcome:
    """Simulate ``config`` and write its results into ``out_dir`` (see module docstring).

    geometry : (mandrel, centerline, notes) already checked, or None to load and check here.
    started : ``time.perf_counter()`` when the command began (before loading the geometry), so
        the summary's wall time is the command's; None: from this call.
    Raises PreformError for bad input or an unusable folder (before simulating) and
    ResultsWriteError when writing fails after the simulation (the checkpoint is kept).
    """
    from .checkpoint import Checkpoint
    from .fields import map_to_surface
    from .io import write_results
    from .io.folder import RunLock, check_results_folder
    from .simulation import simulate

    import time

    t0 = time.perf_counter() if started is None else started
    out_dir = Path(out_dir)
    mandrel, centerline, notes = geometry if geometry is not None else checked_geometry(config)
    work = estimate(config, mandrel, centerline, force=force)
    notes = [*notes, *(f"note: {line}" for line in work.lines())]
    check_results_folder(out_dir, work.result_bytes)
    checkpoint = out_dir / CHECKPOINT
    with RunLock(out_dir):
        stages = {"load_and_check": time.perf_counter() - t0}
        t = time.perf_counter()
        result = simulate(config, progress=progress, mandrel=mandrel, centerline=centerline,
                          checkpoint=checkpoint, resume=resume, keep_checkpoint=True)
        stages["simulate"], t = time.perf_counter() - t, time.perf_counter()
        fields = map_to_surface(result) if len(result.yarns.points) else None
        fields = with_rtm_fields(result, fields)
        stages["map"] = time.perf_counter() - t
        try:
            written = write_results(result, fields, out_dir, stages=stages)
        except OSError as err:
            raise ResultsWriteError(
                f"cannot write the results to {out_dir} ({err.strerror or err}); the simulation "
                f"is kept in {checkpoint}: once the folder is writable, `preform run CONFIG "
                "--resume` writes the results without simulating again") from None
        if result.status == "done":
            Checkpoint(checkpoint, result.config).remove()
    return CaseOutcome(result=result, out_dir=out_dir, written=written, notes=notes)
