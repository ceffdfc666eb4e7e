"""Checkpoints are plain data, written safely and never trusted:
``preform run CFG --resume`` refuses a crafted, damaged or foreign checkpoint with an
``error:`` line and exit 2, runs no code from it, and names what differs for other inputs."""

from __future__ import annotations

import json
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from preform.checkpoint import FORMAT_VERSION, HEADER, Checkpoint, arrays_sha256
from preform.cli import CHECKPOINT, main
from preform.config import load_config
from preform.geometry import shapes
from preform.interaction.zone_state import ZoneState
from preform.simulation import load_geometry, make_stepper
from support.simcase import write_cylinder_case, write_stl

def write_case(folder, kind="kinematic", friction=0.2, name="case"):
    """A case file in ``folder`` on its own copy of a cylinder; results in ``folder/<name>``."""
    return write_cylinder_case(folder, name=name, kind=kind, friction=friction, out=Path(folder) / name)


def make_checkpoint(folder, kind):
    """(case file, config, bytes of a checkpoint of it made after 12 steps) of one model."""
    path = write_case(folder, kind=kind)
    config = load_config(path)
    stepper = make_stepper(config, *load_geometry(config))
    stepper.run(progress=False, max_steps=12)
    checkpoint = Checkpoint(folder / "made.npz", config)
    checkpoint.save(stepper.state_arrays())
    return path, config, checkpoint.path.read_bytes()


@pytest.fixture(scope="module", params=["kinematic", "interaction"])
def made(request, tmp_path_factory):
    return make_checkpoint(tmp_path_factory.mktemp(request.param), request.param)


@pytest.fixture(scope="module")
def made_interaction(tmp_path_factory):
    """A checkpoint of the interaction model, whose zone holds crossings."""
    return make_checkpoint(tmp_path_factory.mktemp("zone"), "interaction")


def _resume(case, capsys):
    """``preform run CASE --resume``: (exit code, stderr)."""
    code = main(["run", str(case), "--resume", "--no-progress"])
    return code, capsys.readouterr().err


def _refused(case, capsys, *words):
    code, err = _resume(case, capsys)
    assert code == 2, err
    assert any(line.startswith("error: --resume: ") for line in err.splitlines()), err
    assert "Traceback" not in err
    for word in words:
        assert word in err, err
    return err


def _out(case):
    return load_config(case).output.dir


def _plant(case, data: bytes) -> Path:
    out = _out(case)
    out.mkdir(parents=True, exist_ok=True)
    (out / CHECKPOINT).write_bytes(data)
    return out / CHECKPOINT


def _arrays(data: bytes) -> dict:
    import io

    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        return {name: npz[name] for name in npz.files}


def _header(arrays) -> dict:
    return json.loads(arrays[HEADER].tobytes().decode())


def _save_raw(path, arrays, header):
    """An .npz of ``arrays`` and ``header`` as given (a crafted checkpoint)."""
    members = {k: v for k, v in arrays.items() if k != HEADER}
    members[HEADER] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with open(path, "wb") as fh:
        np.savez(fh, **members)


class Payload:
    """Unpickling this creates the file ``marker`` (stands for any code a pickle may run)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_the_payload_would_run_if_unpickled(tmp_path):
    """The crafted payload of the tests below does run code when unpickled (so that the tests
    asserting it did not run can fail)."""
    marker = tmp_path / "ran"
    pickle.loads(pickle.dumps(Payload(marker))).close()
    assert marker.exists()


# ---------------------------------------------------------------- accepted

def test_resume_through_the_cli_completes_and_removes_the_checkpoint(made, capsys):
    path, _, data = made
    checkpoint = _plant(path, data)
    code, err = _resume(path, capsys)
    assert code == 0, err
    assert not checkpoint.exists()
    summary = json.loads((_out(path) / "summary.json").read_text())
    assert summary["status"] == "done" and summary["steps"] > 12


# ---------------------------------------------------------------- crafted files run no code

def test_a_pickle_named_checkpoint_npz_is_refused_and_runs_nothing(made, tmp_path, capsys):
    path, _, _ = made
    marker = tmp_path / "pwned"
    _plant(path, pickle.dumps({"state": Payload(marker)}))
    _refused(path, capsys, "not a preform checkpoint")
    assert not marker.exists()


def test_an_npz_with_an_object_array_is_refused_and_runs_nothing(made, tmp_path, capsys):
    path, _, data = made
    marker = tmp_path / "pwned"
    arrays = _arrays(data)
    arrays["stepper.F"] = np.array([Payload(marker)], dtype=object)
    checkpoint = _plant(path, b"")
    with open(checkpoint, "wb") as fh:
        np.savez(fh, **arrays)           # numpy pickles the object array into the archive
    _refused(path, capsys, "cannot be read")
    assert not marker.exists()


def test_flipped_bytes_are_refused(made, capsys):
    path, _, data = made
    damaged = bytearray(data)
    middle = len(damaged) // 2
    damaged[middle:middle + 64] = bytes(b ^ 0xFF for b in damaged[middle:middle + 64])
    _plant(path, bytes(damaged))
    _refused(path, capsys)


def test_changed_arrays_fail_their_checksum(made, tmp_path, capsys):
    """An archive rewritten with one value changed (valid zip, old header) is refused."""
    path, _, data = made
    arrays = _arrays(data)
    arrays["stepper.F"] = arrays["stepper.F"] + 1e-9
    checkpoint = _plant(path, b"")
    _save_raw(checkpoint, arrays, _header(arrays))
    _refused(path, capsys, "checksum")


def _refused_after(path, config, arrays, capsys, *words):
    """Save ``arrays`` with a valid header and checksum (a crafted file, not damage) as the
    checkpoint of ``path``; ``--resume`` refuses it naming ``words``."""
    arrays.pop(HEADER)
    Checkpoint(_plant(path, b""), config).save(arrays)
    _refused(path, capsys, *words)


def test_an_out_of_range_face_index_is_refused_before_any_kernel(made, capsys):
    """A fell point's face beyond the mesh (the kinematic kernels read faces unchecked)."""
    path, config, data = made
    arrays = _arrays(data)
    n_faces = len(load_geometry(config)[0].faces)
    arrays["stepper.face"][3] = n_faces + 7
    _refused_after(path, config, arrays, capsys, "'face'", str(n_faces + 7))


def test_an_out_of_range_crossing_link_is_refused_before_any_kernel(made_interaction, capsys):
    """A crossing's link to the crossing below beyond the crossings (the frontal kernels walk
    the links unchecked)."""
    path, config, data = made_interaction
    arrays = _arrays(data)
    low = arrays["zone.state.low"]
    assert len(low) > 0
    low[len(low) // 2, 0] = 10**6
    _refused_after(path, config, arrays, capsys, "'low'", str(10**6))


def test_a_symlink_in_place_of_the_checkpoint_is_not_read(made, tmp_path, capsys):
    path, _, data = made
    real = tmp_path / "elsewhere.npz"
    real.write_bytes(data)
    checkpoint = _plant(path, b"")
    checkpoint.unlink()
    checkpoint.symlink_to(real)
    _refused(path, capsys, "symbolic link")


def test_a_folder_in_place_of_the_checkpoint_is_refused(made, capsys):
    path, _, _ = made
    checkpoint = _plant(path, b"")
    checkpoint.unlink()
    checkpoint.mkdir()
    try:
        _refused(path, capsys, "not a file")
    finally:
        checkpoint.rmdir()


# ---------------------------------------------------------------- other inputs, other format

def test_other_inputs_are_refused_naming_the_key_and_both_values(made, capsys):
    path, _, data = made
    _plant(path, data)
    text = path.read_text()
    other = path.with_name("friction.toml")
    other.write_text(text.replace("friction = 0.2", "friction = 0.3"))
    err = _refused(other, capsys, "[yarn] friction = 0.2 in the checkpoint, 0.3 now")
    assert "other inputs" in err


def test_the_other_model_is_refused_naming_it(made, capsys):
    path, config, data = made
    _plant(path, data)
    other = "interaction" if config.model.kind == "kinematic" else "kinematic"
    code = main(["run", str(path), "--resume", "--no-progress", "--model", other])
    err = capsys.readouterr().err
    assert code == 2 and f'[model] kind = "{config.model.kind}" in the checkpoint, "{other}" now' in err


def test_a_mandrel_changed_on_disk_is_refused_naming_the_file(made, tmp_path, capsys):
    path, config, data = made
    # a copy of the case whose STL is then re-exported (finer) under the same name
    copy = tmp_path / "copy"
    shutil.copytree(path.parent, copy, ignore=shutil.ignore_patterns("case", "*.npz"))
    case = copy / path.name
    case.write_text(path.read_text().replace(str(path.parent), str(copy)))
    config = load_config(case)
    stepper = make_stepper(config, *load_geometry(config))
    Checkpoint(_plant(case, b""), config).save(stepper.state_arrays())
    v, f = shapes.cylinder(0.075, 0.3, n_around=72)
    write_stl(copy / "c.stl", v, f)
    _refused(case, capsys, f"[mandrel] stl {copy / 'c.stl'}", "contents", "changed")


def test_another_format_version_is_refused_naming_both(made, capsys):
    path, _, data = made
    arrays = _arrays(data)
    header = _header(arrays)
    header["format_version"] = FORMAT_VERSION + 1
    checkpoint = _plant(path, b"")
    _save_raw(checkpoint, arrays, header)
    _refused(path, capsys, f"format version {FORMAT_VERSION + 1}", f"reads version {FORMAT_VERSION}")


def test_the_header_records_versions_hashes_and_a_checksum(made):
    path, config, data = made
    arrays = _arrays(data)
    header = _header(arrays)
    arrays.pop(HEADER)
    assert header["format"] == "preform-checkpoint" and header["format_version"] == FORMAT_VERSION
    import preform

    assert header["package_version"] == preform.__version__
    assert header["arrays_sha256"] == arrays_sha256(arrays)
    import hashlib

    stl = hashlib.sha256(Path(config.mandrel.stl).read_bytes()).hexdigest()
    csv = hashlib.sha256(Path(config.mandrel.centerline).read_bytes()).hexdigest()
    assert header["inputs"]["[mandrel] stl contents"] == f"sha256:{stl}"
    assert header["inputs"]["[mandrel] centerline contents"] == f"sha256:{csv}"
    assert not any(key.startswith("[output]") for key in header["inputs"])
    assert all(a.dtype.kind in "biuf" for a in arrays.values())


# ---------------------------------------------------------------- writing

def test_a_planted_symlink_at_the_checkpoint_is_replaced_not_followed(made, tmp_path):
    path, config, data = made
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    folder = tmp_path / "results"
    folder.mkdir()
    (folder / CHECKPOINT).symlink_to(victim)
    arrays = _arrays(data)
    arrays.pop(HEADER)
    Checkpoint(folder / CHECKPOINT, config).save(arrays)
    assert victim.read_text() == "keep me"
    assert not (folder / CHECKPOINT).is_symlink() and (folder / CHECKPOINT).is_file()
    assert sorted(p.name for p in folder.iterdir()) == [CHECKPOINT]     # no temporary left


def test_the_checkpoint_keeps_the_users_umask(made, tmp_path):
    """Written by a child process with umask 027: the file is rw-r----- (not the 0600 of
    tempfile, not world-readable)."""
    path, _, _ = made
    code = f"""
import os, numpy as np
os.umask(0o027)
from preform.checkpoint import write_exclusive
write_exclusive({str(tmp_path / "c.npz")!r}, lambda fh: np.savez(fh, x=np.zeros(3)))
"""
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
    assert (tmp_path / "c.npz").stat().st_mode & 0o777 == 0o640


def test_a_failed_write_leaves_no_temporary_file(tmp_path):
    from preform.checkpoint import write_exclusive

    def failing(fh):
        fh.write(b"partial")
        raise OSError("disk full")

    with pytest.raises(OSError):
        write_exclusive(tmp_path / CHECKPOINT, failing)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- ZoneState arrays

@pytest.fixture(scope="module")
def zone_state(made_interaction):
    path, config, data = made_interaction
    from preform.plain import unprefixed

    arrays = _arrays(data)
    return unprefixed("zone.state.", arrays), config


def test_zone_state_round_trips_through_arrays(zone_state):
    arrays, config = zone_state
    n_yarns = config.machine.carriers
    st = ZoneState.from_arrays(arrays, n_yarns)
    st.check()
    assert st.m == len(arrays["uid"]) > 0
    back = st.to_arrays()
    assert sorted(back) == sorted(arrays)
    for name, a in arrays.items():
        assert back[name].dtype == a.dtype and np.array_equal(back[name], a, equal_nan=True), name
    twin = st.copy()
    twin.pos[0] += 1.0
    assert not np.array_equal(twin.pos[0], st.pos[0]) and twin.m == st.m


@pytest.mark.parametrize("damage, words", [
    (lambda a, n: a["yarn"].__setitem__((0, 0), n), "yarn (warp)"),
    (lambda a, n: a["yarn"].__setitem__((0, 1), 0), "yarn (weft)"),
    (lambda a, n: a["up"].__setitem__((0, 0), 0), "does not link crossings"),
    (lambda a, n: a["low"].__setitem__((-1, 1), -5), "'low'"),
    (lambda a, n: a["lowest"].__setitem__(0, 10**9), "'lowest'"),
    (lambda a, n: a["pos"].__setitem__((0, 2), np.inf), "non-finite"),
    (lambda a, n: a.__setitem__("tension", a["tension"].astype(np.float32)), "dtype"),
    (lambda a, n: a.__setitem__("slip", a["slip"][:-1]), "shape"),
    (lambda a, n: a.pop("offset"), "missing"),
])
def test_zone_state_from_arrays_refuses_what_add_and_remove_never_make(zone_state, damage, words):
    arrays, config = zone_state
    arrays = {k: v.copy() for k, v in arrays.items()}
    damage(arrays, config.machine.carriers // 2)
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        ZoneState.from_arrays(arrays, config.machine.carriers)


def test_no_pickle_in_the_package():
    """No module of ours imports pickle (nothing is ever unpickled)."""
    src = Path(__file__).resolve().parents[2] / "src" / "preform"
    for path in src.rglob("*.py"):
        text = path.read_text()
        assert "import pickle" not in text and "__setstate__" not in text, path


def test_a_compressed_archive_is_refused_before_it_is_expanded(made, capsys):
    """np.savez_compressed members (what a zip bomb needs) are refused: preform stores arrays."""
    path, _, data = made
    arrays = _arrays(data)
    checkpoint = _plant(path, b"")
    with open(checkpoint, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    _refused(path, capsys, "compressed")
