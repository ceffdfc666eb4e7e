"""The pictures of a run, drawn beside its data files (``preform run``: a worker process).

A picture answers a question about a run; the data files are the run. So a picture that fails
(no OpenGL, a VTK error, a crash of the renderer) never costs a data file: each job is run on
its own, its failure comes back as a sentence, and the caller reports it (``write_results``:
a ``RuntimeWarning`` and the summary's ``pictures.failed``).

:class:`PictureWorker` draws a list of jobs in a child process forked from this one (POSIX
``fork``: the child sees the result and the fields as they are in memory, nothing is
serialised, and only a JSON report comes back through a pipe), while the parent writes the data
files and draws the other pictures: the machine's second core draws, instead of the user
waiting for the pictures after the data. Where ``fork`` is missing (Windows) or fails, the jobs
run in this process. A child that dies (a signal), or runs past ``timeout_s``, is reported with
the pictures it did not write; a child never returns into the caller's code (it leaves with
``os._exit``).

A worker can be started before the data it draws last exists (``preform run`` forks it right
after the simulation, so that it imports pyvista and renders the braided mandrel while the
parent maps the fields): its ``later`` jobs take a dict of plain arrays that the parent hands
over with :meth:`PictureWorker.send` (``np.savez`` into a memory file the child inherited, read
back with ``np.load(allow_pickle=False)``; a one-byte pipe says it is there). The parent never
blocks on the child to send, and the child, which is still drawing its first jobs, reads the
arrays only when it gets to them.
"""

from __future__ import annotations

import json
import os
import select
import signal
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..drawing import PICTURES as PICTURE_SETTINGS


@dataclass(frozen=True)
class PictureJob:
    """One picture (or a set drawn together): ``names`` the files it writes, relative to the
    results folder (for the messages); ``draw()`` writes them and returns the paths written."""

    names: tuple
    draw: Callable[[], list]


@dataclass(frozen=True)
class LaterJob:
    """A picture of data the worker receives after it started (:meth:`PictureWorker.send`):
    ``draw(arrays)`` writes the files ``names`` from a dict name -> numpy array."""

    names: tuple
    draw: Callable[[dict], list]


def bound(jobs, arrays) -> list[PictureJob]:
    """``LaterJob`` s given their arrays: plain :class:`PictureJob` s."""
    return [PictureJob(job.names, (lambda job=job: job.draw(arrays))) for job in jobs]


def run_jobs(jobs) -> tuple[list[Path], list[str]]:
    """Draw ``jobs`` here, each on its own: (paths written, one sentence per failed job)."""
    written, failed = [], []
    for job in jobs:
        try:
            written += [Path(p) for p in job.draw()]
        except Exception as error:  # noqa: BLE001 - a picture never stops the results
            failed.append(f"{', '.join(job.names)} not drawn ({type(error).__name__}: {error})")
    return written, failed


def can_fork() -> bool:
    """Whether :class:`PictureWorker` can fork here (Linux: fork is safe with the libraries we
    load; macOS' system frameworks are not fork-safe, Windows has no fork)."""
    return sys.platform.startswith("linux") and hasattr(os, "fork")


class PictureWorker:
    """``PictureWorker(jobs)`` starts drawing ``jobs`` in a forked child; :meth:`finish` waits for
    it and returns (paths written, failure sentences), re-emitting the child's warnings here.
    Without fork the jobs are drawn by :meth:`finish` itself (in this process).

    timeout_s : seconds :meth:`finish` waits for the child after the parent's own work
        (``PictureSettings.worker_timeout_s``)

    later : :class:`LaterJob` s the child draws after ``jobs``, once :meth:`send` gave it their
        arrays (skipped when the parent sends None or never sends)
    """

    def __init__(self, jobs, timeout_s: float = PICTURE_SETTINGS.worker_timeout_s, later=()):
        self.jobs = list(jobs)
        self.later = list(later)
        self.timeout_s = float(timeout_s)
        self.pid = None
        self.fd = None
        self.arrays = None        # what send() was given (drawn here when there is no child)
        self.sent = False
        self.unsent = ""          # why send() could not hand the arrays over ("" if it could)
        self._memory = self._ready = None
        if not (self.jobs or self.later) or not can_fork():
            return
        read, write = os.pipe()
        inbox = None
        try:
            if self.later:
                inbox = (os.memfd_create("preform-pictures", os.MFD_CLOEXEC), *os.pipe())
            pid = os.fork()
        except OSError:
            for fd in (read, write, *(inbox or ())):
                os.close(fd)
            return
        if pid == 0:   # the child: draw, report, leave without returning into the caller
            os.close(read)
            if inbox is not None:
                os.close(inbox[2])
            _child(self.jobs, write, self.later, inbox and (inbox[0], inbox[1]))
        os.close(write)
        if inbox is not None:
            os.close(inbox[1])
            self._memory, self._ready = inbox[0], inbox[2]
        self.pid, self.fd = pid, read

    def send(self, arrays) -> None:
        """Hand the ``later`` jobs their arrays (dict name -> numpy array), or None to skip them.
        Returns at once: the arrays go to a memory file the child reads when it gets to them."""
        if self.sent:
            raise RuntimeError("PictureWorker.send: the arrays were sent already")
        self.sent = True
        self.arrays = arrays
        if self._ready is None:
            return
        try:
            if arrays is not None:
                with os.fdopen(os.dup(self._memory), "wb") as file:
                    np.savez(file, **arrays)
                os.write(self._ready, b"1")
        except BrokenPipeError:
            pass    # the child is gone already: finish() reports these pictures with its end
        except Exception as error:  # noqa: BLE001 - costs those pictures, reported by finish()
            names = ", ".join(n for job in self.later for n in job.names)
            self.unsent = f"{names} not drawn (could not hand their arrays to the picture worker: " \
                          f"{type(error).__name__}: {error})"
            self.arrays = None
        finally:
            self._close_inbox()

    def _close_inbox(self) -> None:
        for fd in (self._memory, self._ready):
            if fd is not None:
                os.close(fd)
        self._memory = self._ready = None

    def _names(self) -> str:
        later = self.later if self.arrays is not None else []
        return ", ".join(n for job in [*self.jobs, *later] for n in job.names)

    def finish(self) -> tuple[list[Path], list[str]]:
        """Wait for the pictures (at most ``timeout_s``); (paths written, failure sentences)."""
        if not self.sent:
            self.send(None)
        written, failed = self._wait()
        return written, failed + ([self.unsent] if self.unsent else [])

    def _wait(self) -> tuple[list[Path], list[str]]:
        if self.pid is None:
            return run_jobs([*self.jobs, *(bound(self.later, self.arrays) if self.arrays is not None else [])])
        data, deadline, timed_out = b"", time.monotonic() + self.timeout_s, False
        try:
            while True:
                left = deadline - time.monotonic()
                ready = select.select([self.fd], [], [], max(left, 0.0))[0] if left > 0 else []
                if not ready:
                    timed_out = True
                    os.kill(self.pid, signal.SIGKILL)
                    break
                chunk = os.read(self.fd, 1 << 16)
                if not chunk:
                    break
                data += chunk
        finally:
            os.close(self.fd)
            _, status = os.waitpid(self.pid, 0)
            self.pid = None
        try:
            report = json.loads(data.decode("utf-8"))
            written = [Path(p) for p in report["written"]]
            failed = [str(f) for f in report["failed"]]
            said = [str(w) for w in report["warnings"]]
        except (ValueError, KeyError, TypeError):
            names = self._names()
            why = (f"took longer than {self.timeout_s:g} s" if timed_out else
                   f"stopped by signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status) else
                   f"exited with code {os.WEXITSTATUS(status)}")
            return [], [f"{names} not drawn (the picture worker {why})"]
        for text in said:
            warnings.warn(text, RuntimeWarning, stacklevel=2)
        return written, failed

    def stop(self) -> None:
        """Stop the worker (the caller failed): kill it and reap it; no report."""
        self._close_inbox()
        self.sent = True
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.close(self.fd)
            os.waitpid(self.pid, 0)
            self.pid = None


def _child(jobs, fd, later=(), inbox=None) -> None:
    """The forked child's whole life: draw, send the JSON report, ``os._exit``.

    inbox : (memory file, read end of the pipe) that :meth:`PictureWorker.send` fills: one byte
        when the arrays of the ``later`` jobs are in the memory file, end of file when not
    """
    code = 1
    try:
        # Ctrl-C goes to the whole process group: the parent reports the missing pictures
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                signal.signal(getattr(signal, name), signal.SIG_DFL)
        with warnings.catch_warnings(record=True) as caught:   # the filters as they were
            written, failed = run_jobs(jobs)
            if inbox is not None and later:
                w, f = run_jobs(_received(later, *inbox))
                written, failed = written + w, failed + f
        # what the user is told: the renderers' own warnings, not libraries' deprecations
        said = [str(w.message) for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
        report = {"written": [str(p) for p in written], "failed": failed, "warnings": said}
        data = json.dumps(report).encode("utf-8")
        while data:
            data = data[os.write(fd, data):]
        code = 0
    finally:
        os._exit(code)


def _received(later, memory, ready) -> list[PictureJob]:
    """The ``later`` jobs bound to the arrays the parent sent ([] when it sent none); a failure
    to read them fails those jobs (a sentence each), not the worker."""
    try:
        if os.read(ready, 1) != b"1":   # end of file: the parent had nothing to send
            return []
        os.lseek(memory, 0, os.SEEK_SET)
        with os.fdopen(memory, "rb", closefd=False) as file, np.load(file, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in npz.files}
    except Exception as error:  # noqa: BLE001 - reported as the pictures it costs
        def failed(error=error):
            raise RuntimeError(f"their arrays could not be received ({type(error).__name__}: {error})")
        return [PictureJob(job.names, failed) for job in later]
    return bound(later, arrays)
