"""What a run's result files say beyond its arrays: computed here, written by ``preform.io``.

:func:`analyse_run` takes a simulated run (its Result and SurfaceFields) and returns an
:class:`Analysed`: the summary's figures (steady state, the quality verdict, interlacing, the
snapshot checks, flag counts, the echoed inputs), the RTM solver properties
(``rtm.solver_properties``), the structural plies and their binning
(``structural.layup.structural_layup``) and the fields on the input mesh where asked. The
writers only write what it holds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._version import __version__
from ..config import dump_config
from ..plain import jsonable
from ..result import FLAG_NAMES
from ..settings import resolved
from ..structural.layup import StructuralLayup, structural_layup
from .fields import fields_on_input
from .key_numbers import key_numbers
from .quality import QUALITY, assess, run_interlacing, surface_reasons, verdict
from .rtm import SolverProperties, solver_properties
from .steady import steady_state


@dataclass(frozen=True)
class Analysed:
    """A run ready to write: everything derived from it, nothing left to compute.

    result : preform.result.Result of the top-level files (a stack's first layer, with the whole
        run's config and status)
    fields : SurfaceFields (with the RTM arrays when the tow data are given; a stack's layers and
        totals) or None (no surface files)
    layer_results : the Results of layers 2, 3, ... (their ``layer{k}/`` files)
    summary : summary.json's figures (JSON-able), before the files, RTM, structural, pictures and
        timing entries that the writing adds
    rtm : the RTM solver properties, or None with ``rtm_reason`` saying why there are none
    structural : the structural plies and groups, or None with ``structural_reason``
    layers : summary.json's ``layers`` entries of a stack, or None for one layer
    input_mesh_fields : the fields on the mandrel's own triangles (``[output]
        input_mesh_fields``: ``fields.fields_on_input``), or None
    steady : the steady state of the run's history (``analysis.steady.steady_state`` with the
        settings' ``steady``), which summary.json gives and the history plots mark; None for a
        run without steps
    pictures : how the run's pictures are drawn (the settings' ``pictures``,
        ``preform.settings.PictureSettings``; None: the defaults)
    """

    result: object
    fields: object
    layer_results: tuple = ()
    summary: dict = field(default_factory=dict)
    rtm: SolverProperties | None = None
    rtm_reason: str = ""
    structural: StructuralLayup | None = None
    structural_reason: str = ""
    layers: list | None = None
    input_mesh_fields: object = None
    steady: dict | None = None
    pictures: object = None


def analyse_run(result, fields, layer_results=(), layers=None, settings=None) -> Analysed:
    """Everything the result files of ``result`` need beyond its arrays (module docstring).

    layers : summary.json's ``layers`` entries of a stack (:func:`layer_summary`), whose
        reasons to doubt a layer above the first make the whole run suspect
    settings : ``preform.Settings`` (None: the defaults): its ``steady``, ``interlacing`` and
        ``quality`` read the run, ``rtm`` bins the RTM solver cells, ``binning`` the plies
    """
    settings = resolved(settings)
    reasons = surface_reasons(result, fields, settings.quality)
    if layers is not None:
        reasons += [f"layer {e['layer']}: {reason}" for e in layers[1:] for reason in e["quality"]["reasons"]]
    config = result.config
    rtm, rtm_reason = None, "no config"
    if config is not None:
        rtm, rtm_reason = solver_properties(config, fields, settings.rtm)
    structural, structural_reason = structural_layup(result, fields, layer_results, settings.binning)
    output = getattr(config, "output", None)
    on_input = None
    if fields is not None and output is not None and output.input_mesh_fields and result.mandrel is not None:
        on_input = fields_on_input(fields, result.mandrel)
    steady = steady_state(result.history, settings.steady) if result.steps else None
    return Analysed(result=result, fields=fields, layer_results=tuple(layer_results),
                    summary=summary_dict(result, key_numbers(result, fields), quality_reasons=reasons,
                                         settings=settings, steady=steady), rtm=rtm,
                    rtm_reason=rtm_reason, structural=structural,
                    structural_reason=structural_reason, layers=layers, input_mesh_fields=on_input,
                    steady=steady, pictures=settings.pictures)


# ---------------------------------------------------------------- the summary's figures

def echo_inputs(config):
    """The config as JSON-able data (``preform.config.dump_config``), None without one."""
    return None if config is None else jsonable(dump_config(config))


def _final(result, name):
    column = np.asarray(result.history.get(name, ()), dtype=np.float64)
    return float(column[-1]) if len(column) else None


def flag_counts(yarns) -> dict:
    """Number of deposited points carrying each flag: {"bridge": n, "catch": n, "slip": n}."""
    flags = np.asarray(yarns.flags, dtype=np.int64)
    return {name: int(np.count_nonzero(flags & bit)) for bit, name in FLAG_NAMES.items()}


def snapshot_checks(result, settings=QUALITY):
    """The written snapshots against the re-balance that checks each (the written state is the
    run's own): the largest distance of a crossing from its re-balanced place (m), the tolerance
    the verdict holds it to (``QualitySettings.max_snapshot_shift_widths`` yarn widths), the
    times of the snapshots beyond it and of those whose re-balance failed; None where no
    snapshot was checked; ``settings``: the verdict's (``quality.QualitySettings``)."""
    shifts = [s.rebalance_shift_m for s in result.snapshots if np.isfinite(s.rebalance_shift_m)]
    failed = [s.time_s for s in result.snapshots if s.rebalance_error]
    if not shifts and not failed:
        return None
    tolerance = (settings.max_snapshot_shift_widths * float(result.config.yarn.width)
                 if result.config is not None else None)
    beyond = [s.time_s for s in result.snapshots if tolerance is not None
              and np.isfinite(s.rebalance_shift_m) and s.rebalance_shift_m > tolerance]
    return {"rebalance_shift_max_m": max(shifts) if shifts else None,
            "rebalance_shift_tolerance_m": tolerance, "beyond_tolerance_at_s": beyond,
            "rebalance_failed_at_s": failed}


def _interlacing(il):
    """Warp-weft crossings of the laid yarns against the pattern's (``preform.analysis.interlacing``;
    ``il``: ``quality.run_interlacing``'s)."""
    if il is None:
        return None
    return {"band_m": [il.s_start, il.s_end], "crossings": il.measured,
            "pattern_crossings": il.pattern, "ratio": il.ratio,
            "per_m2": il.measured_per_m2, "pattern_per_m2": il.pattern_per_m2}


def summary_dict(result, extra=None, quality_reasons=(), settings=None, steady=None) -> dict:
    """summary.json's figures of ``result``, as JSON-able data (non-finite numbers become null).

    quality_reasons : reasons to doubt the run found beyond its own (its fields', a stack's
        layers'), joined into the verdict
    extra : merged in at the top level
    settings : the run's ``preform.Settings`` (None: the defaults), whose ``steady``,
        ``interlacing`` and ``quality`` read the run
    steady : the run's steady state as :func:`analyse_run` read it; None: read here
    """
    settings = resolved(settings)
    config = result.config
    model = config.model.kind if config is not None else None
    if steady is None and result.steps:
        steady = steady_state(result.history, settings.steady)
    steady = steady or {}
    interlaced = run_interlacing(result, settings.interlacing)
    q = assess(result, settings.quality, interlacing=interlaced)
    summary = {
        "preform_version": __version__,
        "model": model,
        "status": result.status,
        "message": result.message,
        "steps": int(result.steps),
        "wall_time_s": float(result.wall_time_s),
        "braided_length_m": _final(result, "braided_length_m"),
        "braid_angle_deg": {
            "final": {"warp": _final(result, "braid_angle_warp_deg"),
                      "weft": _final(result, "braid_angle_weft_deg")},
            # only where the run reached it (steady_state says how far from it the run ended)
            "steady": steady["braid_angle_deg"] if steady.get("reached") else None,
        },
        "convergence_length_m": {
            "final": {"mean": _final(result, "convergence_length_mean_m"),
                      "min": _final(result, "convergence_length_min_m"),
                      "max": _final(result, "convergence_length_max_m")},
            "steady": steady["convergence_length_m"] if steady.get("reached") else None,
        },
        "steady_state": steady or None,
        "quality": verdict([*q["reasons"], *quality_reasons]),
        "mandrel_repairs": list(result.mandrel.repairs) if result.mandrel is not None else [],
        "yarns": {"count": int(result.yarns.n_yarns), "points": int(len(result.yarns.points)),
                  "flags": flag_counts(result.yarns)},
        "snapshots": len(result.snapshots),
        "snapshot_checks": snapshot_checks(result, settings.quality),
        "interlacing": _interlacing(interlaced),
        "inputs": echo_inputs(config),
    }
    if extra:
        summary.update(extra)
    return jsonable(summary)


def layer_summary(k, layer, result, fields, offset, settings=None) -> dict:
    """summary.json's entry for layer k (from 1) of a stack: its process figures and quality
    verdict (its history, yarns and fields, located on its own centerline), its fields' means
    over the faces it reached, and for k >= 2 the offset surface it was braided on;
    ``settings``: ``preform.Settings`` (None: the defaults)."""
    settings = resolved(settings)
    s = summary_dict(result, quality_reasons=surface_reasons(result, fields, settings.quality),
                     settings=settings)
    entry = {"layer": k, "direction": layer.direction, "model": s["model"], "status": s["status"],
             "message": s["message"], "steps": s["steps"], "wall_time_s": s["wall_time_s"],
             "braided_length_m": s["braided_length_m"], "braid_angle_deg": s["braid_angle_deg"],
             "convergence_length_m": s["convergence_length_m"], "quality": s["quality"],
             "offset": None if offset is None else offset.as_dict(), "fields": None}
    if fields is not None:
        cd = fields.cell_data
        V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
        area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
        on = (cd["reached_warp"] > 0) | (cd["reached_weft"] > 0)
        if on.any():
            entry["fields"] = {f"mean_{name}": float(np.average(cd[name][on], weights=area[on]))
                               for name in ("thickness_m", "cover_factor", "braid_angle_deg")}
    return entry
