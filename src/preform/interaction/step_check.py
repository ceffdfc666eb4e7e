"""Whether an interaction step has a solution, and what to tell the user when not.

``InteractionZone.step`` calls :func:`check_step` after its solve: a slack yarn
(``ZoneSettings.slack_tension``; the model admits none: every free yarn is pulled by its carrier)
or a residual above ``ZoneSettings.max_step_residual`` (the friction bounds the step held differ
from those of its solution by more than that share of the tensions they bound) raises
:class:`~preform.errors.SimulationError`, which stops the run as ``failed`` with its results up
to the last good step. :func:`with_cause` adds the likely cause to a solver's own failure. The
cause is read off where the crossing in question sits (:func:`likely_cause`): under the guide
ring (its yarn's highest crossing behind a ring), next to the mandrel (its lowest: the pose), or
in between (the yarns' friction).
"""

from __future__ import annotations

import numpy as np

from ..errors import SimulationError


def check_step(zone, where, held) -> None:
    """SimulationError where the step's solve left no state of the model (module docstring);
    the message names the step (``where``), the figure, the yarn and crossing, and the likely
    cause. ``held``: the bounds the step held (its posed state's; non-finite for new
    crossings)."""
    st, zs = zone.state, zone.settings.zone
    m = st.m
    residual = float(zone.last_report.residual)
    if m == 0:
        return
    ten = st.tension[:m]
    c, side = np.unravel_index(int(np.argmin(ten)), ten.shape)
    if ten[c, side] <= zs.slack_tension * zone.f_spool:
        k = int(st.yarn[c, side])
        raise SimulationError(
            f"the yarn-interaction model has a slack yarn {where}: {yarn_name(zone, k)}'s "
            f"segment below crossing {int(st.uid[c])} carries {ten[c, side]:.3g} N (spool "
            f"tension {zone.f_spool:g} N; the model admits no slack yarn, every free yarn is "
            f"pulled by its carrier), residual {residual:.3g}; likely cause: "
            f"{likely_cause(zone, c, side)}")
    if not residual <= zs.max_step_residual:
        change = np.abs(st.bound[:m] - held)
        change = np.where(np.isfinite(change), change, -1.0)
        c, side = np.unravel_index(int(np.argmax(change)), change.shape)
        what = (f"largest at {yarn_name(zone, int(st.yarn[c, side]))}'s crossing "
                f"{int(st.uid[c])}; likely cause: {likely_cause(zone, c, side)}"
                if change[c, side] >= 0.0 else
                "at the crossings the step created; likely cause: the creation of crossings "
                "(the carriers' passes, [machine] guide_ring)")
        raise SimulationError(
            f"the yarn-interaction model did not converge {where}: residual {residual:.3g} "
            f"(limit {zs.max_step_residual:g}: the friction bounds the step held differ from "
            f"those of its solution by more than that share of the tensions they bound), "
            f"{what}")


def with_cause(zone, err) -> SimulationError:
    """A solver's failure ``err`` with the likely cause read off the iterate it left in the
    zone: a slack yarn (the lowest tension, below ``slack_tension``), else where the crossing
    with the lowest tension sits (:func:`likely_cause`)."""
    st = zone.state
    if st.m == 0:
        return err
    ten = st.tension[: st.m]
    c, side = np.unravel_index(int(np.argmin(ten)), ten.shape)
    if ten[c, side] <= zone.settings.zone.slack_tension * zone.f_spool:
        cause = (f"a slack yarn ({yarn_name(zone, int(st.yarn[c, side]))} at "
                 f"{ten[c, side]:.3g} N below crossing {int(st.uid[c])} in the last iterate), "
                 f"at {likely_cause(zone, c, side)}")
    else:
        cause = likely_cause(zone, c, side)
    return SimulationError(f"{err}; likely cause: {cause}")


def yarn_name(zone, k) -> str:
    """"warp yarn i" or "weft yarn j" of the zone's yarn index k."""
    n = zone.machine.n_per_group
    return f"warp yarn {k}" if k < n else f"weft yarn {k - n}"


def likely_cause(zone, c, side) -> str:
    """Where crossing c of yarn side ``side`` sits, as the likely cause of a failed step: under
    the guide ring (its yarn's highest crossing), next to the mandrel (its lowest: the pose),
    or in between (the yarns' friction)."""
    st = zone.state
    k = int(st.yarn[c, side])
    if zone.machine.has_ring and st.highest[k] == c:
        return ("the guide ring (the yarn's highest crossing, under its ring point: [machine] "
                "guide_ring, [yarn] ring_friction)")
    if st.lowest[k] == c:
        return ("the pose (the yarn's lowest crossing, next to the mandrel: [process] "
                "pose_lead, eccentricity, and the mandrel's bends and sections there)")
    return ("the friction between the yarns (a crossing inside the zone: [yarn] friction, "
            "[model] time_step)")
