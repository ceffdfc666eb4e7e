"""Checkpoints: a run's state as plain data, written safely and read without trusting the file.

A checkpoint is one ``.npz`` archive (NumPy's zip of ``.npy`` arrays) of numeric arrays only,
written with :func:`numpy.savez` and read with ``allow_pickle=False``: nothing in it is ever
unpickled or executed. Its JSON header is a member of the same archive (``header``, a uint8 array
of UTF-8 JSON), so that header and arrays are replaced together by one rename and can never
belong to different saves (a sidecar file would need two renames). The header holds

- ``format`` / ``format_version``: what the arrays mean (``FORMAT_VERSION``; another version is
  refused, since its arrays may mean something else);
- ``package_version``: the preform that wrote it (recorded, not compared: the step control a run
  started with is part of the state, so a run resumed by another version goes on with it);
- ``inputs`` and ``inputs_sha256``: the config without ``[output]`` (and without the path of the
  TOML file itself), flattened to ``"[section] key"`` entries, plus the SHA-256 of the contents
  of the mandrel STL and of the centerline CSV, so a mandrel re-exported under the same name is
  noticed; a checkpoint of other inputs is refused naming each key that differs, with both values;
- ``arrays_sha256``: SHA-256 over every array's name, dtype, shape and bytes, in name order, so
  damaged bytes are refused even where the zip's own CRC-32 would let them through.

Reading checks, in order: a regular file, not a link; a zip archive whose members are stored
uncompressed (as ``np.savez`` writes them: reading needs no more memory than the file's size);
numeric arrays only; the header's format version and inputs; the checksum. What the arrays hold
is then checked by their owners before any computation
(``Stepper.restore``, ``Recording.from_arrays``, ``ZoneState.from_arrays``; ``preform.plain``).

Writing: a temporary file created exclusively (``O_CREAT | O_EXCL``, random name) in the target
folder, with the permissions the user's umask gives, flushed and renamed over the checkpoint; a
symbolic link planted at the checkpoint's name is replaced, never followed; a link planted at a
temporary name makes the exclusive create fail (another random name is tried).
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
import stat
import zipfile
from pathlib import Path

import numpy as np

from ._version import __version__
from .config import dump_config
from .errors import PreformError

#: the state of a running simulation in its results folder, saved periodically and on a stop,
#: removed once the results are written (``preform.pipeline``)
CHECKPOINT = "checkpoint.npz"
#: the checkpoint of layer k (from 1) of a run with [[layer]] tables
LAYER_CHECKPOINT = "checkpoint_layer{k}.npz"

FORMAT = "preform-checkpoint"
#: version of the arrays' layout and meaning; bump it when either changes
FORMAT_VERSION = 3   # 3: the stepper's carriers' clock and process rows; 2: snapshots' external_force_N
#: the archive member holding the JSON header
HEADER = "header"
#: dtype kinds a checkpoint may hold: bool, signed and unsigned integers, floats
NUMERIC_KINDS = "biuf"
_ZIP_MAGIC = b"PK\x03\x04"
_READ_CHUNK = 1 << 20


class CheckpointError(PreformError):
    """A checkpoint cannot be resumed from (unreadable, damaged, crafted, other inputs or format)."""


def file_sha256(path) -> str:
    """Hex SHA-256 of a file's contents."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(_READ_CHUNK), b""):
            digest.update(chunk)
    return digest.hexdigest()


def input_record(config) -> dict:
    """What a run's results depend on, flattened to ``"[section] key" -> JSON value``: the config
    without ``[output]`` and ``source``, and the SHA-256 of the mandrel STL's and (unless
    ``auto``) the centerline CSV's contents (``"[mandrel] stl contents"``, ...)."""
    d = dump_config(config)
    d.pop("output", None)
    d.pop("source", None)
    flat = {f"[{section}] {key}": value for section, values in d.items() for key, value in values.items()}
    flat["[mandrel] stl contents"] = "sha256:" + file_sha256(config.mandrel.stl)
    if not (isinstance(config.mandrel.centerline, str) and config.mandrel.centerline == "auto"):
        flat["[mandrel] centerline contents"] = "sha256:" + file_sha256(config.mandrel.centerline)
    # through JSON and back: the form the header gives when read (lists, not tuples)
    return json.loads(json.dumps(flat, sort_keys=True, default=str))


def inputs_sha256(config) -> str:
    """Hex SHA-256 of :func:`input_record` (what a checkpoint's ``inputs_sha256`` holds)."""
    return hashlib.sha256(_canonical(input_record(config))).hexdigest()


def _canonical(value) -> bytes:
    return json.dumps(value, sort_keys=True, separators=(",", ":")).encode("utf-8")


def arrays_sha256(arrays) -> str:
    """Hex SHA-256 over every array's name, dtype, shape and C-order bytes, in name order."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        a = np.asarray(arrays[name], order="C")
        digest.update(_canonical([name, a.dtype.str, list(a.shape)]))
        digest.update(a.tobytes())
    return digest.hexdigest()


def _check_numeric(name, a):
    if not isinstance(a, np.ndarray) or a.dtype.kind not in NUMERIC_KINDS or a.dtype.fields is not None:
        found = a.dtype if isinstance(a, np.ndarray) else type(a).__name__
        raise ValueError(f"array {name!r} has dtype {found}: a checkpoint holds numeric arrays only")


def write_exclusive(path, write) -> Path:
    """Call ``write(file)`` on a new temporary file in ``path``'s folder, then rename it to
    ``path`` (module docstring). The temporary file is removed if anything fails."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        break
    else:
        raise FileExistsError(f"no free temporary name next to {path}")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


class Checkpoint:
    """The checkpoint file of a run of ``config`` at ``path`` (``<out>/checkpoint.npz``)."""

    def __init__(self, path, config):
        self.path = Path(path)
        self.inputs = input_record(config)

    def header(self, arrays) -> dict:
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "package_version": __version__,
                "inputs": self.inputs, "inputs_sha256": hashlib.sha256(_canonical(self.inputs)).hexdigest(),
                "arrays_sha256": arrays_sha256(arrays)}

    def save(self, arrays) -> Path:
        """Write ``arrays`` (name -> numeric ndarray) and their header atomically."""
        arrays = {name: np.asarray(a, order="C") for name, a in arrays.items()}
        for name, a in arrays.items():
            _check_numeric(name, a)
        if HEADER in arrays:
            raise ValueError(f"{HEADER!r} is the header's name")
        header = np.frombuffer(_canonical(self.header(arrays)), dtype=np.uint8)
        return write_exclusive(self.path, lambda fh: np.savez(fh, **arrays, **{HEADER: header}))

    def exists(self) -> bool:
        return os.path.lexists(self.path)

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)

    def load(self) -> dict:
        """The arrays of the checkpoint, after checking that it is a checkpoint of this format,
        of these inputs and undamaged; CheckpointError saying what is wrong otherwise."""
        where = f"--resume: the checkpoint {self.path}"
        with self._open(where) as fh:
            if fh.read(len(_ZIP_MAGIC)) != _ZIP_MAGIC:
                raise CheckpointError(f"{where} is not a preform checkpoint (not an .npz archive); "
                                      "remove it and run without --resume")
            fh.seek(0)
            self._check_stored(fh, where)
            fh.seek(0)
            try:
                with np.load(fh, allow_pickle=False) as npz:
                    arrays = {name: npz[name] for name in npz.files}
            except Exception as exc:   # whatever a damaged or crafted archive raises: nothing ran
                raise CheckpointError(f"{where} cannot be read ({type(exc).__name__}: {exc}); "
                                      "run without --resume") from None
        header = self._header(arrays.pop(HEADER, None), where)
        try:
            for name, a in arrays.items():
                _check_numeric(name, a)
        except ValueError as exc:
            raise CheckpointError(f"{where} is damaged: {exc}; run without --resume") from None
        if arrays_sha256(arrays) != header.get("arrays_sha256"):
            raise CheckpointError(f"{where} is damaged: its arrays do not match their checksum; "
                                  "run without --resume")
        return arrays

    @staticmethod
    def _check_stored(fh, where):
        """Refuse compressed members or members larger than the file: ``np.savez`` stores its
        arrays uncompressed, so reading a checkpoint never needs more memory than its size
        (a crafted archive of compressed members could expand without bound)."""
        try:
            with zipfile.ZipFile(fh) as archive:
                members = archive.infolist()
        except (zipfile.BadZipFile, OSError, ValueError) as exc:
            raise CheckpointError(f"{where} cannot be read ({exc}); run without --resume") from None
        size = os.fstat(fh.fileno()).st_size
        if any(m.compress_type != zipfile.ZIP_STORED for m in members) or sum(m.file_size for m in members) > size:
            raise CheckpointError(f"{where} holds compressed or oversized members, which preform "
                                  "never writes; run without --resume")

    def _open(self, where):
        """The checkpoint opened for reading, never through a symbolic link."""
        try:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0))
        except FileNotFoundError:
            raise CheckpointError(f"--resume: no checkpoint to resume from at {self.path}; "
                                  "run without --resume") from None
        except OSError as exc:
            if self.path.is_symlink():
                raise CheckpointError(f"{where} is a symbolic link; preform writes checkpoints as "
                                      "files: remove the link and run without --resume") from None
            raise CheckpointError(f"{where} cannot be read ({exc.strerror}); run without --resume") from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise CheckpointError(f"{where} is not a file; remove it and run without --resume")
        return os.fdopen(fd, "rb")

    def _header(self, raw, where) -> dict:
        try:
            if raw is None or raw.dtype != np.uint8 or raw.ndim != 1:
                raise ValueError("no header")
            header = json.loads(raw.tobytes().decode("utf-8"))
            if not isinstance(header, dict) or header.get("format") != FORMAT:
                raise ValueError("not a preform checkpoint")
        except (ValueError, UnicodeDecodeError) as exc:
            raise CheckpointError(f"{where} has no readable header ({exc}); run without --resume") from None
        version = header.get("format_version")
        if version != FORMAT_VERSION:
            raise CheckpointError(
                f"{where} is of checkpoint format version {version} (written by preform "
                f"{header.get('package_version')}); this preform {__version__} reads version "
                f"{FORMAT_VERSION}: run without --resume to start again")
        theirs = header.get("inputs")
        if not isinstance(theirs, dict):
            raise CheckpointError(f"{where} has no inputs in its header; run without --resume")
        if theirs != self.inputs or header.get("inputs_sha256") != hashlib.sha256(_canonical(theirs)).hexdigest():
            raise CheckpointError(f"{where} was made with other inputs: {describe_changes(theirs, self.inputs)}; "
                                  "run without --resume to start again")
        return header


def describe_changes(old: dict, new: dict) -> str:
    """The entries of two input records that differ, for people: ``[yarn] friction = 0.25 in the
    checkpoint, 0.3 now``; for a file's contents, the file and that its contents changed."""
    parts = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key, "(absent)"), new.get(key, "(absent)")
        if a == b:
            continue
        if key.endswith(" contents"):
            name = key.removesuffix(" contents")
            path = new.get(name, old.get(name))
            parts.append(f"the contents of {name} {path} changed since the checkpoint was made "
                         f"({a} then, {b} now)")
        else:
            parts.append(f"{key} = {json.dumps(a)} in the checkpoint, {json.dumps(b)} now")
    return "; ".join(parts) or "the header's inputs hash does not match its inputs"
