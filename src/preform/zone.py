"""The convergence zone's interface: what each fell point's free yarn pulls towards, step by step.

The stepper (``preform.stepping``) asks its zone, each time step, for the point every yarn's lowest
free segment runs to (``G_mid`` at the middle of the step, ``G_end`` at its end, machine frame) and
for the crossings that reached the mandrel (``deposits``). Two models implement :class:`Zone`: the
kinematic one (``preform.kinematic.KinematicZone``: the free yarn runs straight to the supply point,
docs/theory.md §3) and the interaction one (``preform.interaction.model.InteractionZone``: its yarns
run to their lowest crossing, docs/theory.md §4). The run picks one by ``[model] kind``
(:data:`ZONES`) and builds it with :meth:`Zone.for_run`; what differs between the models (their
numerical settings, the interaction zone's step solver, the default time step) is behind that
protocol, so the stepper and ``simulate`` never ask which model runs. This module is a leaf: it
imports nothing of ours but ``result`` and ``errors`` (the models' modules are named by strings
and imported on first use, so that a kinematic run does not load the interaction model).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from .errors import ConfigError
from .result import Snapshot

#: ``[model] kind`` -> (module, class) of that model's zone (``config.MODEL_KINDS`` are its keys)
ZONES = {"kinematic": ("preform.kinematic", "KinematicZone"),
         "interaction": ("preform.interaction.model", "InteractionZone")}
#: ``[model] solver`` -> (module, function) of the interaction zone's solver of a step
#: (``InteractionZone(solve_zone=)``; ``config.SOLVERS`` are its keys): Newton's frontal
#: iteration or the force-density relaxation
SOLVERS = {"newton": ("preform.interaction.frontal", "solve_zone_inplace"),
           "relax": ("preform.interaction.relax", "solve_zone")}


def zone_class(kind):
    """The zone class of ``[model] kind`` (:data:`ZONES`), imported on first use."""
    if kind not in ZONES:
        raise ConfigError(f"[model] kind = {kind!r}: expected one of "
                          f"{', '.join(map(repr, ZONES))}")
    module, name = ZONES[kind]
    return getattr(importlib.import_module(module), name)


def solver_of(name):
    """The interaction zone's step solver of ``[model] solver`` (:data:`SOLVERS`)."""
    if name not in SOLVERS:
        raise ConfigError(f"[model] solver = {name!r}: expected one of "
                          f"{', '.join(map(repr, SOLVERS))}")
    module, function = SOLVERS[name]
    return getattr(importlib.import_module(module), function)


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
    """A convergence zone: built by ``for_run``, then driven by the stepper.

    Points are (ny, 3) float64, m, machine frame; ``pose`` / ``pose_end`` are the mandrel's
    ``preform.geometry.Pose`` at that time. ``export_state`` / ``import_state`` carry whatever the
    zone keeps from one step to the next as plain arrays (checkpoints, ``preform.checkpoint``).
    The stepper sets ``snapshot_due`` (bool) before a step whose state it will snapshot, so that a
    zone whose step changes its state after solving it (the interaction zone's deposit) can keep
    the solved one; ``stage`` (str, optional) names the part of a step under way for the message
    of a fault inside it.
    """

    #: what a run of this model costs, said before it starts, with ``{steps}`` its estimated
    #: time steps (``str.format``); "" where nothing need be said
    cost_note: str
    #: whether a first run starts the worker that compiles its later kernels meanwhile
    #: (``preform._jit``, whose jobs are the kinematic run's)
    first_run_worker: bool

    @classmethod
    def for_run(cls, config, machine, mandrel, settings=None) -> "Zone":
        """The zone of a run of ``config``: ``mandrel`` (mandrel frame) for its contact tests;
        ``settings`` the run's ``preform.Settings`` (None: the defaults), of which the zone
        takes its own branch."""

    @classmethod
    def default_time_step(cls, machine, per_width: float, tolerances) -> float:
        """The model's time step (s) where ``[model] time_step`` is not given (the stepper's
        step control, ``stepping.default_time_step``): ``per_width`` s for the fell points to
        advance a yarn width, ``tolerances`` the run's ``preform.tolerances.Tolerances``."""

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
