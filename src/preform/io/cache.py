"""An on-disk cache of work that depends only on a run's inputs (the repaired mandrel, the
field mesh), so that a second run of the same part does not repeat it.

Where: ``$PREFORM_CACHE_DIR``, else ``$XDG_CACHE_HOME/preform``, else ``~/.cache/preform``;
``PREFORM_CACHE=0`` turns the cache off. Deleting the folder is always safe.

An entry is one ``.npz`` of plain arrays, read with ``allow_pickle=False`` (no object arrays, no
code runs), named by a SHA-256 *key* of everything the work depends on: the input bytes, the
settings that matter, the versions of preform and of the libraries that did the work, and the
source of the modules that compute it (so an edited module invalidates its entries). The entry
holds its key and a SHA-256 *digest* of its arrays (names, dtypes, shapes, bytes); an entry that
is not a regular file (a planted symlink is not followed), cannot be read, has another key,
another digest or arrays of the wrong shape is ignored, never trusted, and rebuilt. Entries
are written atomically: an exclusive temporary file in the cache folder, renamed over the final
name (a symlink there is replaced, not followed). The cache is a convenience: any failure to
read or write it leaves the run to do the work itself, and the results are the same bytes
either way (``tests/unit/test_cache.py``).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
import tempfile
from pathlib import Path

import numpy as np

#: the entry format; entries of another format are ignored
FORMAT = 1
#: entries above this size are not read (a cache entry of a mandrel is a few MB)
MAX_ENTRY_BYTES = 4 << 30
META = "_meta"


def cache_dir() -> Path | None:
    """The cache folder (see module docstring), or None when ``PREFORM_CACHE=0``."""
    if os.environ.get("PREFORM_CACHE", "1").strip() in ("0", "off", "no", "false"):
        return None
    if os.environ.get("PREFORM_CACHE_DIR"):
        return Path(os.environ["PREFORM_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "preform"


def _feed(h, part) -> None:
    """Add one key part to the hash ``h``, typed, so that no two different parts hash alike."""
    if isinstance(part, np.ndarray):
        a = np.ascontiguousarray(part)
        h.update(f"array:{a.dtype.str}:{a.shape}:".encode())
        h.update(a.tobytes())
    elif isinstance(part, (bytes, bytearray, memoryview)):
        h.update(f"bytes:{len(part)}:".encode())
        h.update(part)
    else:
        text = json.dumps(part, sort_keys=True, default=repr)
        h.update(f"json:{len(text)}:".encode())
        h.update(text.encode())


def make_key(*parts) -> str:
    """SHA-256 (hex) of ``parts``: arrays (dtype, shape, bytes), bytes, or JSON-able values."""
    h = hashlib.sha256()
    for part in parts:
        _feed(h, part)
    return h.hexdigest()


def source_digest(*modules) -> str:
    """SHA-256 of the source files of ``modules`` (dotted names, found without importing them):
    a key part, so that an edited module gets new keys."""
    from importlib.util import find_spec

    h = hashlib.sha256()
    for name in modules:
        h.update(name.encode() + b"\0")
        h.update(Path(find_spec(name).origin).read_bytes())
    return h.hexdigest()


def library_versions(*names) -> dict:
    """The installed versions of the distributions ``names`` ("" when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = ""
    return out


def _digest(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        h.update(name.encode() + b"\0")
        _feed(h, arrays[name])
    return h.hexdigest()


def _entry(kind: str, key: str, folder: Path) -> Path:
    return folder / f"{kind}-{key[:40]}.npz"


def load(kind: str, key: str, check=None) -> dict | None:
    """The arrays of the entry ``kind``/``key``, or None (no cache, no entry, or an entry that is
    not to be trusted: see module docstring). ``check(arrays)`` may refuse it further by raising
    ValueError or returning False (shapes, index ranges)."""
    folder = cache_dir()
    if folder is None:
        return None
    path = _entry(kind, key, folder)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return None
    try:
        with open(fd, "rb") as fh:
            info = os.fstat(fh.fileno())
            if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_ENTRY_BYTES:
                return None
            with np.load(fh, allow_pickle=False) as npz:
                arrays = {name: npz[name] for name in npz.files}
        meta = json.loads(bytes(arrays.pop(META)).decode("utf-8"))
        if not (isinstance(meta, dict) and meta.get("format") == FORMAT and meta.get("kind") == kind
                and meta.get("key") == key and meta.get("digest") == _digest(arrays)):
            return None
        if any(a.dtype.hasobject for a in arrays.values()):
            return None
        if check is not None and not check(arrays):
            return None
        return arrays
    except Exception:  # noqa: BLE001 - a damaged or foreign entry is ignored and rebuilt
        return None


def store(kind: str, key: str, arrays: dict) -> Path | None:
    """Write ``arrays`` as the entry ``kind``/``key`` atomically; the path, or None when the cache
    is off or cannot be written (the run goes on without it)."""
    folder = cache_dir()
    if folder is None:
        return None
    arrays = {name: np.ascontiguousarray(a) for name, a in arrays.items()}
    meta = {"format": FORMAT, "kind": kind, "key": key, "digest": _digest(arrays)}
    tmp = None
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=folder)   # O_EXCL, 0600
        with open(fd, "wb") as fh:
            np.savez(fh, **arrays, **{META: np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)})
        path = _entry(kind, key, folder)
        os.replace(tmp, path)      # a symlink planted at the name is replaced, never followed
        tmp = None
        return path
    except OSError:
        return None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


# ------------------------------------------------------------------------------------ field mesh

def _field_mesh_key(mandrel, h, remesh) -> str:
    from .._version import __version__
    from ..analysis.fields import LOCATE_REACH_EDGES

    return make_key("field_mesh", __version__, source_digest("preform.analysis.fields", "preform.geometry.remesh"),
                    library_versions("numpy", "gpytoolbox", "pyfqmr", "trimesh", "embreex"),
                    np.asarray(mandrel.vertices, dtype=np.float64), np.asarray(mandrel.faces, dtype=np.int64),
                    float(h), repr(remesh), LOCATE_REACH_EDGES)


def cached_field_mesh(result, edge_length=None, remesh=None):
    """``preform.analysis.fields.field_mesh(result, edge_length, remesh)`` through the cache: the field
    mesh depends only on the mandrel's arrays, the edge length and the remesher's settings."""
    from ..analysis.fields import default_edge_length, field_mesh
    from ..geometry.remesh import RemeshSettings

    remesh = RemeshSettings() if remesh is None else remesh
    h = default_edge_length(result) if edge_length is None else float(edge_length)
    if not (np.isfinite(h) and h > 0):          # the input mesh itself, or an error: not cached
        return field_mesh(result, h, remesh)
    key = _field_mesh_key(result.mandrel, h, remesh)
    n_input = len(result.mandrel.faces)

    def check(a):
        V, F, S = a["vertices"], a["faces"], a["source_faces"]
        return (V.dtype == np.float64 and V.ndim == 2 and V.shape[1] == 3 and np.isfinite(V).all()
                and F.dtype == np.int64 and F.ndim == 2 and F.shape[1] == 3 and len(F) > 0
                and F.min() >= 0 and F.max() < len(V) and S.dtype == np.int64 and S.shape == (len(F),)
                and S.min() >= -1 and S.max() < n_input and a["edge_length"].shape == (1,)
                and a["edge_length"][0] == h)

    hit = load("field_mesh", key, check)
    if hit is not None:
        return hit["vertices"], hit["faces"], hit["source_faces"], float(hit["edge_length"][0])
    V, F, source, h_used = field_mesh(result, h, remesh)
    store("field_mesh", key, {"vertices": V, "faces": F, "source_faces": source,
                              "edge_length": np.array([h_used], dtype=np.float64)})
    return V, F, source, h_used


# --------------------------------------------------------------------------------------- mandrel

def _mandrel_key(path: Path, data: bytes, unit, body) -> str:
    from .._version import __version__

    return make_key("mandrel", __version__,
                    source_digest("preform.geometry.mandrel", "preform.geometry.repair",
                                  "preform._kernels.mesh", "preform.tolerances"),
                    library_versions("numpy", "scipy", "trimesh", "embreex"),
                    str(path), unit, body, data)


def cached_mandrel(path, unit: str = "m", body=None, build: bool = True):
    """``preform.geometry.load_mandrel(path, unit, body)`` through the cache: the repaired
    mandrel (arrays, repair sentences) depends only on the STL's bytes, its path (the sentences
    name it), the unit, the body and the code. An STL that cannot be read goes to
    ``load_mandrel``, which says what is wrong with it. ``build=False``: None instead of loading
    when the cache has no entry (or cannot be used)."""
    import dataclasses

    from ..geometry.mandrel import Mandrel, load_mandrel

    path = Path(path)
    folder = cache_dir()
    try:
        data = path.read_bytes() if folder is not None else None
    except OSError:
        data = None
    if data is None:
        return load_mandrel(path, unit=unit, body=body) if build else None
    key = _mandrel_key(path, data, unit, body)
    arrays = [f.name for f in dataclasses.fields(Mandrel) if f.name not in ("source", "repairs")]

    def check(a):
        if set(a) != {*arrays, "repairs"}:
            return False
        V, F = a["vertices"], a["faces"]
        nf = len(F)
        return (V.dtype == np.float64 and V.ndim == 2 and V.shape[1] == 3 and np.isfinite(V).all()
                and F.dtype == np.int64 and F.shape == (nf, 3) and nf > 0 and F.min() >= 0
                and F.max() < len(V) and a["face_normals"].shape == (nf, 3)
                and a["corner_normals"].shape == (nf, 3, 3) and a["neighbors"].shape == (nf, 3)
                and a["neighbors"].dtype == np.int64 and a["neighbors"].max() < nf
                and a["repairs"].dtype == np.uint8)

    hit = load("mandrel", key, check)
    if hit is not None:
        repairs = json.loads(bytes(hit.pop("repairs")).decode("utf-8"))
        if isinstance(repairs, list) and all(isinstance(r, str) for r in repairs):
            return Mandrel(**hit, source=str(path), repairs=tuple(repairs))
    if not build:
        return None
    mandrel = load_mandrel(path, unit=unit, body=body)
    values = {name: getattr(mandrel, name) for name in arrays}
    if all(isinstance(v, np.ndarray) for v in values.values()):   # a Mandrel of plain arrays only
        store("mandrel", key, {**values, "repairs": np.frombuffer(
            json.dumps(list(mandrel.repairs)).encode("utf-8"), dtype=np.uint8)})
    return mandrel
