"""The convergence zone's interface: what each fell point's free yarn pulls towards, step by step.

The stepper (``preform.stepping``) asks its zone, each time step, for the point every yarn's lowest
free segment runs to (``G_mid`` at the middle of the step, ``G_end`` at its end, machine frame) and
for the crossings that reached the mandrel (``deposits``). Two models implement :class:`Zone`: the
kinematic one (``preform.kinematic.KinematicZone``: the free yarn runs straight to the supply point,
docs/theory.md §3) and the interaction one (``preform.interaction.model.InteractionZone``: its yarns
run to their lowest crossing, docs/theory.md §4). The run picks one by ``[model] kind``
(``preform.simulation.ZONES``). This module is a leaf: it imports nothing of ours but ``result``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from .result import Snapshot


@dataclass(frozen=True)
class ZoneStep:
    """What a zone says about one step. Arrays (ny, 3) float64, m, machine frame.

    deposits : list of (yarn index, point (3,) machine frame): crossings now on the mandrel,
        which become that yarn's fell point.
    contacts, iterations, residual : the zone's solve (0 for the kinematic model), for history.csv
    """

    G_mid: np.ndarray
    G_end: np.ndarray
    deposits: list = field(default_factory=list)
    contacts: int = 0
    iterations: int = 0
    residual: float = 0.0

    @classmethod
    def kinematic(cls, supply):
        """The free yarns run straight to ``supply`` (ny, 3) over the whole step."""
        return cls(G_mid=supply, G_end=supply)


@runtime_checkable
class Zone(Protocol):
    """A convergence zone: built as ``Zone(config, machine, mandrel)``, then driven by the stepper.

    Points are (ny, 3) float64, m, machine frame; ``pose`` / ``pose_end`` are the mandrel's
    ``preform.geometry.Pose`` at that time. ``export_state`` / ``import_state`` carry whatever the
    zone keeps from one step to the next as plain arrays (checkpoints, ``preform.checkpoint``).
    The stepper sets ``snapshot_due`` (bool) before a step whose state it will snapshot, so that a
    zone whose step changes its state after solving it (the interaction zone's deposit) can keep
    the solved one; ``stage`` (str, optional) names the part of a step under way for the message
    of a fault inside it.
    """

    def start(self, t: float, F_machine: np.ndarray, pose) -> None:
        """Called once with the tie points and the mandrel pose at time t."""

    def step(self, t0: float, dt: float, F_machine: np.ndarray, pose_end) -> ZoneStep:
        """The step from t0 to t0 + dt; F_machine: fell points at its end; pose_end: the mandrel's."""

    def snapshot(self, t: float, F_machine: np.ndarray) -> Snapshot:
        """The zone at time t (its yarns as polylines, fell point first) for convergence.pvd."""

    def export_state(self) -> dict[str, np.ndarray]:
        """The zone's state as named plain arrays (numeric dtypes only)."""

    def import_state(self, arrays: dict[str, np.ndarray]) -> None:
        """Replace the state by one ``export_state`` gave (validated: ValueError if unusable)."""
