"""When does the braid reach steady state? (paper eq. 1: dalpha/dL = dH/dL = 0)

In a finite run "steady" is read with tolerances: the braided length from which the mean
convergence length stays within ``rel_H`` of its final value and both braid angles within
``angle_deg`` of theirs, provided the run ends flat (over its last ``tail`` fraction of braided
length, and at least ``tail_convergence_lengths`` convergence lengths, H changes by less than
``rel_H / 2`` and the angles by less than ``angle_deg / 2``);
otherwise the run ended before steady state (or on a changing cross-section), and what is
reported instead is how fast the run was still changing at its end (the drift: least-squares
slopes over the tail, per metre braided).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SteadySettings:
    """Tolerances of the steady-state reading."""

    #: H within this fraction of its final value: the paper's convergence plots settle to ~1 %
    rel_H: float = 0.01
    #: braid angles within this many degrees of their final values: below a measurable angle
    angle_deg: float = 0.25
    #: fraction of the braided length at the end of the run that must be flat
    tail: float = 0.1
    #: ... and at least this many convergence lengths of braid: the start-up transient decays
    #: over one convergence length (Du & Popper), so a shorter flat stretch proves nothing
    tail_convergence_lengths: float = 0.5


STEADY = SteadySettings()
#: history rows the flat tail needs before a run can be called steady
MIN_TAIL_ROWS = 3


def _slope(x, y) -> float:
    if len(x) < 2 or np.ptp(x) <= 0:
        return 0.0
    return float(np.polyfit(x, y, 1)[0])


def steady_state(history, settings: SteadySettings = STEADY) -> dict:
    """The steady state of a run's history (``Result.history`` columns).

    Returns {"reached": bool, "definition": str, and, if reached, "braided_length_m" (where it
    starts), "convergence_length_m" and "braid_angle_deg" {"warp", "weft"} (means over the steady
    part); if not, "drift": {"convergence_length_m_per_m", "braid_angle_warp_deg_per_m",
    "braid_angle_weft_deg_per_m"} over the last ``tail`` of the run, or None for a run too short
    to say}.
    """
    rel_H, angle_deg, tail = settings.rel_H, settings.angle_deg, settings.tail
    L = np.asarray(history["braided_length_m"], dtype=float)
    H = np.asarray(history["convergence_length_mean_m"], dtype=float)
    warp = np.asarray(history["braid_angle_warp_deg"], dtype=float)
    weft = np.asarray(history["braid_angle_weft_deg"], dtype=float)
    out = {"reached": False,
           "definition": f"H within {rel_H:.0%} and braid angles within {angle_deg} deg of their final "
                         "values from this braided length on, with the run ending flat",
           "drift": None}
    if len(L) < 3 or L[-1] <= L[0]:
        return out
    window = max(tail * (L[-1] - L[0]), settings.tail_convergence_lengths * abs(H[-1]))
    if window > L[-1] - L[0]:
        return out   # the run is shorter than the stretch that must be flat
    end = L >= L[-1] - window
    if np.count_nonzero(end) < MIN_TAIL_ROWS:
        return out   # too few steps at the end to say whether it is flat
    flat = (np.ptp(H[end]) <= 0.5 * rel_H * abs(H[-1]) and np.ptp(warp[end]) <= 0.5 * angle_deg
            and np.ptp(weft[end]) <= 0.5 * angle_deg)
    if not flat:
        out["drift"] = {"convergence_length_m_per_m": _slope(L[end], H[end]),
                        "braid_angle_warp_deg_per_m": _slope(L[end], warp[end]),
                        "braid_angle_weft_deg_per_m": _slope(L[end], weft[end])}
        return out
    ok = ((np.abs(H - H[-1]) <= rel_H * abs(H[-1])) & (np.abs(warp - warp[-1]) <= angle_deg)
          & (np.abs(weft - weft[-1]) <= angle_deg))
    bad = np.nonzero(~ok)[0]
    first = 0 if len(bad) == 0 else bad[-1] + 1
    del out["drift"]
    out.update(reached=True, braided_length_m=float(L[first]),
               convergence_length_m=float(np.mean(H[first:])),
               braid_angle_deg={"warp": float(np.mean(warp[first:])), "weft": float(np.mean(weft[first:]))})
    return out
