"""The results folder of a run: checked before simulating, held by one run at a time.

:func:`check_results_folder` makes sure, before any simulation time is spent, that the folder can
be created and written and that its filesystem has room for the expected results; it raises
:class:`OutputError` (exit code 2) otherwise. :class:`RunLock` is a lock file
(``<out>/.preform.lock``, created exclusively, holding the PID, host and start time) that refuses a
second run into a busy folder and takes over the lock of a run that died on this host.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import time
import warnings
from pathlib import Path

from ..errors import PreformError
from .atomic import safe_folder

LOCK = ".preform.lock"
#: free space demanded beyond the estimate: room for the temporary copy of the largest file
SPACE_MARGIN = 2.0


class OutputError(PreformError):
    """The results folder cannot be used: not a folder, not writable, full, or busy."""


class StaleLockWarning(UserWarning):
    """The lock of a run that is no longer alive was taken over."""


def check_results_folder(out_dir, expected_bytes: int = 0) -> Path:
    """Create ``out_dir`` if needed and prove it writable with room for ``expected_bytes``.

    Returns the folder. Raises OutputError naming the folder and what is wrong.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f"results folder {out_dir} is a file, not a folder: give --out a folder "
                          "(or [output] dir)")
    try:
        safe_folder(out_dir)
        probe = out_dir / f".preform-probe-{os.getpid()}-{time.monotonic_ns()}"
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
        try:
            os.write(fd, b"preform")
        finally:
            os.close(fd)
            probe.unlink()
    except OSError as err:
        reason = err.strerror or str(err)
        raise OutputError(f"results folder {out_dir} cannot be written ({reason}): choose another "
                          "--out or fix its permissions") from None
    free = shutil.disk_usage(out_dir).free
    need = int(SPACE_MARGIN * expected_bytes)
    if need > free:
        raise OutputError(f"results folder {out_dir} has {free / 1e6:.1f} MB free, the results need "
                          f"about {need / 1e6:.1f} MB: free some space or choose another --out")
    return out_dir


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # alive, another user's
        return True
    return True


class RunLock:
    """``with RunLock(out_dir):`` holds ``out_dir`` for this process (see module docstring)."""

    def __init__(self, out_dir):
        self.path = Path(out_dir) / LOCK
        self.host = socket.gethostname()
        self.pid = os.getpid()
        self.held = False

    def _create(self) -> bool:
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
        try:
            fd = os.open(self.path, flags, 0o644)
        except FileExistsError:
            return False
        info = {"pid": self.pid, "host": self.host,
                "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        with open(fd, "w", encoding="utf-8") as f:
            json.dump(info, f)
        return True

    def _holder(self) -> dict:
        try:
            if self.path.is_symlink():
                return {}
            info = json.loads(self.path.read_text(encoding="utf-8"))
            return info if isinstance(info, dict) else {}
        except (OSError, ValueError):
            return {}

    def acquire(self) -> "RunLock":
        for _ in range(3):   # another process may take over a stale lock at the same moment
            if self._create():
                self.held = True
                return self
            holder = self._holder()
            pid, host = holder.get("pid"), holder.get("host")
            since = holder.get("started", "an unknown time")
            if isinstance(pid, int) and host == self.host and not _alive(pid):
                warnings.warn(f"{self.path}: the run that held this results folder (PID {pid}, "
                              f"since {since}) is gone; taking its lock over", StaleLockWarning,
                              stacklevel=2)
            elif not holder:
                warnings.warn(f"{self.path} is unreadable or not a lock file; replacing it",
                              StaleLockWarning, stacklevel=2)
            else:
                raise OutputError(
                    f"results folder {self.path.parent} is in use by another run (PID {pid} on "
                    f"{host}, since {since}): wait for it, or choose another --out; if no run is "
                    f"active there, delete {self.path}")
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
        raise OutputError(f"could not take the lock {self.path}: another run keeps taking it")

    def release(self) -> None:
        if self.held and self._holder().get("pid") == self.pid:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
        self.held = False

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
        return False
