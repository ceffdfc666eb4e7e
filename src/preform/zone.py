"""The convergence zone: what each fell point's free yarn pulls towards, step by step.

The stepper (``simulate.py``) asks its zone, each time step, for the point every yarn's lowest free
segment runs to (``G_mid`` at the middle of the step, ``G_end`` at its end, machine frame) and for
the crossings that reached the mandrel (``deposits``). The kinematic zone is the machine itself:
the free yarn runs straight to the supply point (DESIGN.md §3.2). The interaction model
(``preform.interaction``) has the same interface: its yarns run to their lowest crossing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .result import Snapshot


@dataclass(frozen=True)
class ZoneStep:
    """What a zone says about one step. Arrays (ny, 3) float64, m, machine frame.

    deposits : list of (yarn index, point (3,) machine frame): crossings now on the mandrel,
        which become that yarn's fell point.
    """

    G_mid: np.ndarray
    G_end: np.ndarray
    deposits: list = field(default_factory=list)
    contacts: int = 0
    iterations: int = 0
    residual: float = 0.0

    @classmethod
    def kinematic(cls, supply):
        return cls(G_mid=supply, G_end=supply)


class KinematicZone:
    """Free yarns straight from fell point to supply point (spool, or guide-ring point)."""

    def __init__(self, config, machine, mandrel=None):
        self.config = config
        self.machine = machine

    def start(self, t, F_machine, pose):
        """Called once with the tie points (machine frame) and the mandrel pose at time t."""

    def step(self, t0, dt, F_machine, pose_end) -> ZoneStep:
        """The step from t0 to t0 + dt; F_machine: fell points at its end; pose_end: the mandrel's."""
        m = self.machine
        return ZoneStep(G_mid=m.supply_points(t0 + 0.5 * dt), G_end=m.supply_points(t0 + dt))

    def snapshot(self, t, F_machine) -> Snapshot:
        """Fell point, supply point (and spool point behind a guide ring) of every yarn."""
        ends = [F_machine, self.machine.supply_points(t)]
        if self.config.machine.guide_ring is not None:
            ends.append(self.machine.spool_points(t))
        ny = len(F_machine)
        per = len(ends)
        points = np.stack(ends, axis=1).reshape(-1, 3)
        return Snapshot(time_s=t, points=points, offsets=np.arange(ny + 1, dtype=np.int64) * per,
                        tension_N=np.full(ny * (per - 1), float(self.config.yarn.tension)),
                        contact_id=np.full(len(points), -1, dtype=np.int64),
                        slip=np.zeros(len(points), dtype=np.int8), group=self.machine.group.copy())


def make_zone(config, machine, mandrel):
    """The zone of ``[model] kind``; ``mandrel`` (mandrel frame) for contact and deposition tests."""
    if config.model.kind == "interaction":
        from .interaction.model import InteractionZone

        return InteractionZone(config, machine, mandrel)
    return KinematicZone(config, machine)
