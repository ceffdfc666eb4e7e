"""A braiding run composed: geometry, machine, the zone of ``[model] kind``, the stepper, Ctrl-C
and checkpoints (docs/architecture.md §4).

``simulate(config)`` loads the mandrel and centerline, ties every yarn to the mandrel's tip and
steps the process (``preform.stepping``) until ``braid_length`` of centerline is braided. It
returns a :class:`preform.result.Result`; an interrupted (Ctrl-C) or failed run returns what it
computed up to the last good step, with ``status`` saying so. The model is chosen here, once:
``ZONES`` maps ``[model] kind`` to its zone class (``preform.zone.Zone``).
"""

from __future__ import annotations

import dataclasses
import functools
import signal
import sys
import threading
import time as _time
from contextlib import contextmanager

from . import geometry
from .checkpoint import Checkpoint, CheckpointError
from .errors import ConfigError, SimulationError
from .machine import Machine
from .reference import resolve_pose_lead
from .result import Result
from .stepping import Stepper
from .tolerances import Tolerances, tol

#: ``[model] kind`` -> (module, class) of that model's zone, built as ``cls(config, machine,
#: mandrel)``; imported on first use, so that a kinematic run does not load the interaction model
ZONES = {"kinematic": ("preform.kinematic", "KinematicZone"),
         "interaction": ("preform.interaction.model", "InteractionZone")}
#: ``[model] solver`` -> (module, function) of the interaction zone's solver of a step
#: (``InteractionZone(solve_zone=)``); None: the zone's default, Newton's
#: ``frontal.solve_zone_inplace``
SOLVERS = {"newton": None, "relax": ("preform.interaction.relax", "solve_zone")}


def _named(where):
    import importlib

    return None if where is None else getattr(importlib.import_module(where[0]), where[1])


def zone_class(kind):
    """The zone class of ``[model] kind`` (``ZONES``)."""
    try:
        return _named(ZONES[kind])
    except KeyError:
        raise ConfigError(f"[model] kind = {kind!r}: expected one of "
                          f"{', '.join(map(repr, ZONES))}") from None


def solver_of(name):
    """The step solver of ``[model] solver`` (``SOLVERS``; None: the zone's default)."""
    if name not in SOLVERS:
        raise ConfigError(f"[model] solver = {name!r}: expected one of "
                          f"{', '.join(map(repr, SOLVERS))}")
    return _named(SOLVERS[name])


def load_geometry(config, load_mandrel=None):
    """(Mandrel, Centerline) of a config, in metres, mandrel frame; ``load_mandrel(path, unit=,
    body=)`` reads the STL (None: ``geometry.load_mandrel``; ``preform run`` passes the on-disk
    cache's ``io.cache.cached_mandrel``)."""
    mc = config.mandrel
    load = geometry.load_mandrel if load_mandrel is None else load_mandrel
    mandrel = load(mc.stl, unit=mc.stl_unit, body=mc.body)
    if isinstance(mc.centerline, str) and mc.centerline == "auto":
        centerline = geometry.auto_centerline(mandrel, roll_reference=mc.roll_reference)
    else:
        centerline = geometry.read_centerline_csv(mc.centerline, unit=mc.stl_unit,
                                                  roll_reference=mc.roll_reference)
    return mandrel, centerline


def make_zone(config, machine, mandrel, settings=None):
    """A fresh zone of ``[model] kind`` (``ZONES``), the interaction zone with the solver of
    ``[model] solver`` (``SOLVERS``) and ``[model] frontal_iterations`` friction-bound updates a
    step; ``mandrel`` (mandrel frame) for its contact and deposition tests; ``settings``: the
    interaction model's numerical settings (``interaction.settings.InteractionSettings``;
    None: its defaults)."""
    cls = zone_class(config.model.kind)
    if config.model.kind != "interaction":
        return cls(config, machine, mandrel)
    solve = solver_of(config.model.solver)
    iterations = config.model.frontal_iterations
    if iterations == 1:
        return cls(config, machine, mandrel, solve_zone=solve, settings=settings)
    from .interaction import relax
    from .interaction.settings import DEFAULT

    base = DEFAULT if settings is None else settings
    settings = dataclasses.replace(
        base, frontal=dataclasses.replace(base.frontal, max_iterations=iterations))
    if solve is relax.solve_zone:
        # nearly consistent bounds make the top rows stick, where the block preconditioner
        # stalls: the "full" one (stick stiffness along a stuck yarn) before Newton
        solve = functools.partial(relax.solve_zone,
                                  relax_settings=relax.RelaxSettings(full_retry=True))
    return cls(config, machine, mandrel, settings=settings, solve_zone=solve)


def make_stepper(config, mandrel, centerline, tolerances: Tolerances = tol,
                 settings=None) -> Stepper:
    """The stepper of a run at its start (yarns tied, nothing braided yet); ``settings``: the
    interaction model's (``make_zone``)."""
    config = resolve_pose_lead(config, mandrel, centerline)   # [process] pose_lead = "auto"
    machine = Machine.from_config(config.machine)
    return Stepper(config, machine, mandrel, centerline,
                   make_zone(config, machine, mandrel, settings), tolerances)


def simulate(config, progress=True, mandrel=None, centerline=None, checkpoint=None, resume=False,
             tolerances: Tolerances = tol, keep_checkpoint=False, settings=None) -> Result:
    """Run the configured model and return a Result (see module docstring).

    config : preform.config.Config
    progress : show a progress bar (tqdm) on stderr
    mandrel, centerline : the config's, when already loaded (the CLI checks them first)
    checkpoint : str or Path or None, a file where the run's state is saved every
        ``stepping.CHECKPOINT_EVERY_S`` seconds of wall time and when it is interrupted
        (``preform.checkpoint``); removed when the run is done
    resume : continue from ``checkpoint``, giving the same results as a run that was never
        stopped; a checkpoint of other inputs, another format or damaged is refused
        (CheckpointError, naming what differs)
    tolerances : step control and geometry settings (``preform.tolerances``)
    settings : the interaction model's numerical settings
        (``interaction.settings.InteractionSettings``; None: its defaults)
    keep_checkpoint : when the run is done, save its final state instead of removing the
        checkpoint, so that a caller writing results can remove it only once they are complete
        (``--resume`` on a finished checkpoint makes the results without simulating again)

    Ctrl-C, SIGTERM (batch schedulers, ``docker stop``) and SIGHUP (a closed terminal) stop after
    the current step, saying so at once; a second one stops at once.
    """
    wall0 = _time.perf_counter()
    if mandrel is None or centerline is None:
        mandrel, centerline = load_geometry(config)
    ckpt = None if checkpoint is None else Checkpoint(checkpoint, config)
    stepper = make_stepper(config, mandrel, centerline, tolerances, settings)
    if resume:
        if ckpt is None:
            raise ConfigError("--resume: no checkpoint file given to resume from; run without --resume")
        arrays = ckpt.load()
        try:
            stepper.restore(arrays)
        except ValueError as exc:
            raise CheckpointError(f"--resume: the checkpoint {ckpt.path} is damaged or was not "
                                  f"made by preform: {exc}; run without --resume") from None
    status, message = "done", ""
    with _graceful_interrupt(stepper):
        try:
            stepper.run(progress=progress, checkpoint=ckpt)
        except KeyboardInterrupt:
            status = "interrupted"
            who = "the user (Ctrl-C)" if stepper.stop_signal in ("", "SIGINT") else stepper.stop_signal
            message = f"interrupted by {who} at t = {stepper.clock.t:.4g} s"
            if ckpt is not None and stepper.consistent and stepper.save_checkpoint(ckpt):
                message += "; resume with --resume"
            elif ckpt is not None and ckpt.exists():
                message += "; stopped inside a step: --resume continues from the last checkpoint"
        except SimulationError as exc:
            status, message = "failed", str(exc)
    if status == "done" and ckpt is not None:
        if keep_checkpoint:
            stepper.save_checkpoint(ckpt)
        else:
            ckpt.remove()
    result = stepper.result(status, message, _time.perf_counter() - wall0)
    return dataclasses.replace(result, stop_signal=stepper.stop_signal if status == "interrupted" else "")


#: the signals that stop a run after its current step (SIGHUP where the platform has it)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextmanager
def _graceful_interrupt(stepper):
    """First Ctrl-C / SIGTERM / SIGHUP: say so at once, stop after the current step (the state
    stays consistent); a second one: stop at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if stepper.stop_requested:
            raise KeyboardInterrupt
        stepper.stop_requested = True
        stepper.stop_signal = signal.Signals(signum).name
        sys.stderr.write(f"\n{stepper.stop_signal}: stopping after this step and saving the "
                         "results so far (press Ctrl-C again to stop at once)\n")
        sys.stderr.flush()

    previous = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
