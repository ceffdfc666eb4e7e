"""A braiding run composed: geometry, machine, the zone of ``[model] kind``, the stepper, Ctrl-C
and checkpoints (docs/architecture.md §4).

``simulate(config)`` loads the mandrel and centerline, ties every yarn to the mandrel's tip and
steps the process (``preform.stepping``) until ``braid_length`` of centerline is braided. It
returns a :class:`preform.result.Result`; an interrupted (Ctrl-C) or failed run returns what it
computed up to the last good step, with ``status`` saying so. The model is chosen here, once:
``zone.ZONES`` maps ``[model] kind`` to its zone class (``preform.zone.Zone``), which builds
itself from the config and the run's settings (``preform.Settings``).
"""

from __future__ import annotations

import dataclasses
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
from .tolerances import tol
from .zone import zone_class


def _checked_settings(settings):
    """``settings`` if it is a settings tree (``preform.Settings``) or None, else TypeError
    naming what was given (the tree is read by attribute here: it gathers the classes of the
    layers above)."""
    if settings is None or all(hasattr(settings, name) for name in ("tolerances", "interaction")):
        return settings
    raise TypeError(f"settings = {type(settings).__name__}(...): expected a preform.Settings, "
                    "the tree of every numerical setting; give a branch as "
                    "preform.Settings(interaction=...) or preform.Settings(tolerances=...)")


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
    """A fresh zone of ``[model] kind`` (``zone.ZONES``), built by its class's ``for_run`` from
    the config and ``settings`` (``preform.Settings``; None: the defaults); ``mandrel`` (mandrel
    frame) for its contact and deposition tests."""
    return zone_class(config.model.kind).for_run(config, machine, mandrel, settings)


def make_stepper(config, mandrel, centerline, settings=None) -> Stepper:
    """The stepper of a run at its start (yarns tied, nothing braided yet); ``settings``: the
    run's ``preform.Settings`` (None: the defaults): its ``tolerances`` for the stepper, the
    rest for the zone (``make_zone``)."""
    settings = _checked_settings(settings)
    config = resolve_pose_lead(config, mandrel, centerline)   # [process] pose_lead = "auto"
    machine = Machine.from_config(config.machine)
    tolerances = tol if settings is None else settings.tolerances
    return Stepper(config, machine, mandrel, centerline,
                   make_zone(config, machine, mandrel, settings), tolerances)


def simulate(config, progress=True, mandrel=None, centerline=None, checkpoint=None, resume=False,
             keep_checkpoint=False, settings=None) -> Result:
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
    settings : the numerical settings (``preform.Settings``; None: the defaults): the step
        control and geometry tolerances (``settings.tolerances``) and the zone's
        (``settings.interaction`` for the interaction model)
    keep_checkpoint : when the run is done, save its final state instead of removing the
        checkpoint, so that a caller writing results can remove it only once they are complete
        (``--resume`` on a finished checkpoint makes the results without simulating again)

    Ctrl-C, SIGTERM (batch schedulers, ``docker stop``) and SIGHUP (a closed terminal) stop after
    the current step, saying so at once; a second one stops at once.
    """
    wall0 = _time.perf_counter()
    settings = _checked_settings(settings)
    if mandrel is None or centerline is None:
        mandrel, centerline = load_geometry(config)
    ckpt = None if checkpoint is None else Checkpoint(checkpoint, config)
    stepper = make_stepper(config, mandrel, centerline, settings)
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
