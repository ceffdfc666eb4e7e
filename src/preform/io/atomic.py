"""Atomic file writes: write to a temporary name in the same folder, then rename (DESIGN.md §1).

An interrupted run never leaves a half-written file that looks whole: the final name appears only
through :func:`os.replace`, which is atomic on one filesystem. Every writer in ``preform.io`` goes
through here.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; rename it over ``path`` if the block succeeds.

    The temporary name keeps ``path``'s suffix so writers that pick their format from the suffix
    (VTK, matplotlib) do the right thing. If the block raises, the temporary file is removed and
    ``path`` is left as it was.

    path : str or Path, the final file name
    yields : Path, the temporary file name (does not exist yet)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    tmp.unlink()  # writers create it themselves; some refuse to overwrite
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"the writer did not create {tmp} for {path}")
        os.replace(tmp, path)
    finally:
        # no-op after a successful replace; cleans up after a failure
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return ``Path(path)``."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)


def atomic_write_text(path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8 by default); return ``Path(path)``."""
    return atomic_write_bytes(path, text.encode(encoding))
