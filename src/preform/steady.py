"""When does the braid reach steady state? (paper eq. 1: dalpha/dL = dH/dL = 0)

In a finite run "steady" is read with tolerances: the braided length from which the mean
convergence length stays within ``rel_H`` of its final value and both braid angles within
``angle_deg`` of theirs, provided the run ends flat (over its last ``tail`` fraction of braided
length H changes by less than ``rel_H / 2`` and the angles by less than ``angle_deg / 2``);
otherwise the run ended before steady state (or on a changing cross-section).
"""

from __future__ import annotations

import numpy as np

#: defaults of the steady-state reading
REL_H = 0.01
ANGLE_DEG = 0.25
TAIL = 0.1


def steady_state(history, rel_H=REL_H, angle_deg=ANGLE_DEG, tail=TAIL) -> dict:
    """{"reached": bool, "braided_length_m": L or None, "convergence_length_m", "braid_angle_deg"}."""
    L = np.asarray(history["braided_length_m"], dtype=float)
    H = np.asarray(history["convergence_length_mean_m"], dtype=float)
    warp = np.asarray(history["braid_angle_warp_deg"], dtype=float)
    weft = np.asarray(history["braid_angle_weft_deg"], dtype=float)
    out = {"reached": False, "braided_length_m": None, "convergence_length_m": None, "braid_angle_deg": None,
           "definition": f"H within {rel_H:.0%} and braid angles within {angle_deg} deg of their final values "
                         "from this braided length on, with the run ending flat"}
    if len(L) < 3 or L[-1] <= L[0]:
        return out
    end = L >= L[-1] - tail * (L[-1] - L[0])
    flat = (np.ptp(H[end]) <= 0.5 * rel_H * abs(H[-1]) and np.ptp(warp[end]) <= 0.5 * angle_deg
            and np.ptp(weft[end]) <= 0.5 * angle_deg)
    if not flat:
        return out
    ok = ((np.abs(H - H[-1]) <= rel_H * abs(H[-1])) & (np.abs(warp - warp[-1]) <= angle_deg)
          & (np.abs(weft - weft[-1]) <= angle_deg))
    bad = np.nonzero(~ok)[0]
    first = 0 if len(bad) == 0 else bad[-1] + 1
    out.update(reached=True, braided_length_m=float(L[first]), convergence_length_m=float(H[-1]),
               braid_angle_deg={"warp": float(warp[-1]), "weft": float(weft[-1])})
    return out
