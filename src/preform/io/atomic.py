"""Atomic, contained file writes (docs/architecture.md §1).

Two promises, for every file a run writes:

* **Atomic.** The final name appears only through :func:`os.replace`, which is atomic on one
  filesystem, so an interrupted run never leaves a half-written file that looks whole.
* **Contained.** Nothing is written outside the results folder. A writer gets a path inside a
  private temporary folder (``tempfile.mkdtemp``: created exclusively, random name, mode 0700) in
  the target folder, so no planted file or symlink can sit at the name it opens, and the file it
  creates gets the user's umask (a ``mkstemp`` file would be 0600). ``os.replace`` then renames it
  over the final name: a symlink planted there is replaced, never followed, and a
  :class:`UnsafePathWarning` says so. :func:`safe_folder` makes the subfolders of a results folder
  (``plots``, ``convergence``) the same way: a symlink in their place is replaced by a real folder.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import warnings
from pathlib import Path

#: prefix of the private temporary folders (removed after each write; a crash may leave one)
TEMP_PREFIX = ".preform-tmp-"


class UnsafePathWarning(UserWarning):
    """A symlink stood where the run writes; it was replaced, its target left untouched."""


def _replace_link(path: Path, what: str) -> None:
    target = os.readlink(path)
    warnings.warn(f"{path} was a symlink (to {target}); replaced by the {what}, the link's target is "
                  "untouched", UnsafePathWarning, stacklevel=3)
    path.unlink()


def safe_folder(root, *parts) -> Path:
    """``root / parts...`` as real folders, created where missing; return the deepest.

    ``root`` (the results folder the user named) may itself be a symlink: that is the user's
    choice. Below it, a component that is a symlink is replaced by a real folder (with an
    :class:`UnsafePathWarning`), and one that is a file raises :class:`NotADirectoryError`.
    """
    folder = Path(root)
    folder.mkdir(parents=True, exist_ok=True)
    for part in parts:
        folder = folder / part
        if folder.is_symlink():
            _replace_link(folder, "folder of results")
        with contextlib.suppress(FileExistsError):
            folder.mkdir()
        if not folder.is_dir() or folder.is_symlink():
            raise NotADirectoryError(f"{folder} exists and is not a folder")
    return folder


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path for ``path``; rename it over ``path`` if the block succeeds.

    The temporary path has ``path``'s file name (writers that pick their format from the suffix,
    VTK and matplotlib, do the right thing) inside a private folder next to ``path``. If the block
    raises, nothing is left behind and ``path`` is as it was. ``path``'s folder must exist (make
    it with :func:`safe_folder` inside a results folder; elsewhere missing folders are made).

    path : str or Path, the final file name
    yields : Path, the temporary file name (does not exist yet)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    private = Path(tempfile.mkdtemp(prefix=TEMP_PREFIX, dir=path.parent))
    tmp = private / path.name
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"the writer did not create {tmp} for {path}")
        place(tmp, path)
    finally:
        shutil.rmtree(private, ignore_errors=True)


def place(tmp, path) -> Path:
    """Rename ``tmp`` over ``path`` (same filesystem); a symlink at ``path`` is replaced, not followed."""
    path = Path(path)
    if path.is_symlink():
        _replace_link(path, "result file")
    os.replace(tmp, path)
    return path


def atomic_write_bytes(path, data: bytes, sync: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically; return ``Path(path)``.

    sync : flush the contents to disk before the rename (True), or leave that to the operating
        system (False: for large result files, like the VTK, meshio and matplotlib writers do; the
        rename is atomic either way, so a stopped run never leaves a half-written file)
    """
    with atomic_path(path) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o666)
        with open(fd, "wb") as f:
            f.write(data)
            if sync:
                f.flush()
                os.fsync(f.fileno())
    return Path(path)


def atomic_write_text(path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8 by default); return ``Path(path)``."""
    return atomic_write_bytes(path, text.encode(encoding))
