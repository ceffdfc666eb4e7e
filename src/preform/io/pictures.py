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

#: seconds the parent waits for the picture worker after its own work, before stopping it
TIMEOUT_S = 600.0


@dataclass(frozen=True)
class PictureJob:
    """One picture (or a set drawn together): ``names`` the files it writes, relative to the
    results folder (for the messages); ``draw()`` writes them and returns the paths written."""

    names: tuple
    draw: Callable[[], list]


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
    Without fork the jobs are drawn by :meth:`finish` itself (in this process)."""

    def __init__(self, jobs, timeout_s: float = TIMEOUT_S):
        self.jobs = list(jobs)
        self.timeout_s = float(timeout_s)
        self.pid = None
        self.fd = None
        if not self.jobs or not can_fork():
            return
        read, write = os.pipe()
        try:
            pid = os.fork()
        except OSError:
            os.close(read)
            os.close(write)
            return
        if pid == 0:   # the child: draw, report, leave without returning into the caller
            os.close(read)
            _child(self.jobs, write)
        os.close(write)
        self.pid, self.fd = pid, read

    def finish(self) -> tuple[list[Path], list[str]]:
        """Wait for the pictures (at most ``timeout_s``); (paths written, failure sentences)."""
        if self.pid is None:
            return run_jobs(self.jobs)
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
            names = ", ".join(n for job in self.jobs for n in job.names)
            why = (f"took longer than {self.timeout_s:g} s" if timed_out else
                   f"stopped by signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status) else
                   f"exited with code {os.WEXITSTATUS(status)}")
            return [], [f"{names} not drawn (the picture worker {why})"]
        for text in said:
            warnings.warn(text, RuntimeWarning, stacklevel=2)
        return written, failed

    def stop(self) -> None:
        """Stop the worker (the caller failed): kill it and reap it; no report."""
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.close(self.fd)
            os.waitpid(self.pid, 0)
            self.pid = None


def _child(jobs, fd) -> None:
    """The forked child's whole life: draw, send the JSON report, ``os._exit``."""
    code = 1
    try:
        # Ctrl-C goes to the whole process group: the parent reports the missing pictures
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                signal.signal(getattr(signal, name), signal.SIG_DFL)
        with warnings.catch_warnings(record=True) as caught:   # the filters as they were
            written, failed = run_jobs(jobs)
        # what the user is told: the renderers' own warnings, not libraries' deprecations
        said = [str(w.message) for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
        report = {"written": [str(p) for p in written], "failed": failed, "warnings": said}
        data = json.dumps(report).encode("utf-8")
        while data:
            data = data[os.write(fd, data):]
        code = 0
    finally:
        os._exit(code)
