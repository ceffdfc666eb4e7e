"""Ctrl-C during a run keeps a marked partial result; --resume reproduces the uninterrupted run."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]

CASE = """
[mandrel]
stl = "{root}/mandrels/cone.stl"
centerline = "{root}/mandrels/cone_centerline.csv"

[machine]
carriers = 48
spool_radius = 0.3
angular_speed = 13.232

[yarn]
width = 2e-3
thickness = 2.5e-4

[process]
take_up_speed = 0.01
initial_position = 0.05
braid_length = 0.3

[model]
time_step = 0.01

[output]
dir = "{out}"
field_edge_length = 0.05
snapshots = 2
"""


def _case(tmp_path, name):
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text(CASE.format(root=ROOT, out=tmp_path / name))
    return cfg


def _preform(*args, **kw):
    return subprocess.Popen([sys.executable, "-m", "preform.cli", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT, **kw)


@pytest.mark.skipif(os.name != "posix", reason="sends SIGINT")
def test_interrupted_run_is_marked_and_resumes_to_the_same_history(tmp_path):
    cfg = _case(tmp_path, "stopped")
    proc = _preform("run", cfg)
    # wait until the progress bar (stderr) shows 0.02 m of the 0.3 m braided, then Ctrl-C: a
    # length, not a time, so the stop falls early in the run however fast it steps
    seen = b""
    deadline = time.time() + 300
    braided = 0.0
    while braided < 0.02 and time.time() < deadline:
        seen += os.read(proc.stderr.fileno(), 256)
        done = re.findall(rb"(\d+\.\d+)/0\.300 m braided", seen[-512:])
        braided = float(done[-1]) if done else 0.0
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err.decode()[-2000:]
    result = tmp_path / "stopped"
    summary = json.loads((result / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert "resume" in summary["message"]
    assert (result / "checkpoint.npz").is_file()
    partial = (result / "history.csv").read_text().splitlines()
    assert len(partial) > 10

    resumed = _preform("run", cfg, "--resume", "--no-progress")
    _, err = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, err.decode()[-2000:]
    assert not (result / "checkpoint.npz").exists()

    # the uninterrupted run in-process, its history.csv written by the same writer
    from preform.config import load_config
    from preform.io.tables import write_history
    from preform.simulation import simulate

    reference = simulate(load_config(_case(tmp_path, "reference")), progress=False)
    assert reference.status == "done"
    full = write_history(reference, tmp_path / "reference.csv").read_text()
    assert (result / "history.csv").read_text() == full      # bit for bit
    assert partial == full.splitlines()[:len(partial)]


def test_resume_without_checkpoint_is_a_clear_error(tmp_path):
    proc = _preform("run", _case(tmp_path, "fresh"), "--resume", "--no-progress")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2
    assert "no checkpoint" in err.decode() and "Traceback" not in err.decode()


def test_a_checkpoint_keeps_its_time_step(tmp_path):
    """A run resumed with other step control (here: a third of the carrier rotation per step)
    goes on with the time step and snapshot stride it started with (both are state)."""
    import dataclasses

    from preform.checkpoint import Checkpoint
    from preform.config import load_config
    from preform.simulation import load_geometry, make_stepper
    from preform.settings import Settings
    from preform.tolerances import tol

    cfg = load_config(_case(tmp_path, "kept"))
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, time_step=None))
    mandrel, centerline = load_geometry(cfg)
    first = make_stepper(cfg, mandrel, centerline)
    checkpoint = Checkpoint(tmp_path / "checkpoint.npz", cfg)
    checkpoint.save(first.state_arrays())
    finer = dataclasses.replace(tol, max_carrier_rotation=tol.max_carrier_rotation / 3.0)
    second = make_stepper(cfg, mandrel, centerline, settings=Settings(tolerances=finer))
    assert second.dt < 0.5 * first.dt and second.snapshot_stride != first.snapshot_stride
    second.restore(checkpoint.load())
    assert second.dt == first.dt and second.snapshot_stride == first.snapshot_stride


# ---------------------------------------------------------------- resume, both models, in-process

R_MANDREL = 0.075


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    """A 75 mm cylinder of 0.6 m (STL and centerline CSV)."""
    from preform.geometry import shapes
    from support.simcase import write_centerline, write_stl

    d = tmp_path_factory.mktemp("cylinder")
    v, f = shapes.cylinder(R_MANDREL, 0.6, n_around=96)
    return write_stl(d / "c.stl", v, f), write_centerline(d / "c.csv", [[0, 0, 0], [0, 0, 0.6]])


def small_case(cylinder, model):
    """16 carriers around the cylinder (Ko angle 60 deg), 0.2 m braided (about 70 steps of the
    interaction model); ``interaction_ring``: behind a guide ring with ring friction, so that
    the ring points and the passes waiting for them are part of the state."""
    import dataclasses

    from support.simcase import make_config

    stl, cl = cylinder
    ring = {"guide_ring": (0.1, 0.0), "ring_friction": 0.2, "spool_radius": 0.4} if model == "interaction_ring" else {}
    cfg = make_config(stl, cl, **{"carriers": 16, "spool_radius": 0.12, "friction": 0.2, "braid_length": 0.2,
                                  "initial_position": 0.08, "snapshots": 4, **ring})
    kind = "kinematic" if model == "kinematic" else "interaction"
    return dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind=kind))


@pytest.fixture(scope="module", params=["kinematic", "interaction", "interaction_ring"])
def resumed_and_reference(request, cylinder, tmp_path_factory):
    """(resumed Result, uninterrupted Result, steps of the stopped run) of one model: the
    resumed run was stopped half way, checkpointed, and a new run continued from the file."""
    from preform.checkpoint import Checkpoint
    from preform.simulation import load_geometry, make_stepper, simulate

    cfg = small_case(cylinder, request.param)
    reference = simulate(cfg, progress=False)
    path = tmp_path_factory.mktemp(request.param) / "checkpoint.npz"
    stopped = make_stepper(cfg, *load_geometry(cfg))
    stopped.run(progress=False, max_steps=reference.steps // 2)
    Checkpoint(path, cfg).save(stopped.state_arrays())
    resumed = simulate(cfg, progress=False, checkpoint=path, resume=True)
    return resumed, reference, stopped.step


def test_resume_continues_mid_run(resumed_and_reference):
    resumed, reference, stopped_at = resumed_and_reference
    assert stopped_at == reference.steps // 2 >= 20
    assert resumed.status == reference.status == "done"
    # the interaction models stopped with crossings in their zones (state that must carry over)
    assert reference.history["contacts"][stopped_at] > 0 or reference.config.model.kind == "kinematic"


def test_resume_gives_the_same_history_csv_bit_for_bit(resumed_and_reference, tmp_path):
    from preform.io.tables import write_history

    resumed, reference, _ = resumed_and_reference
    a = write_history(resumed, tmp_path / "resumed.csv").read_bytes()
    b = write_history(reference, tmp_path / "reference.csv").read_bytes()
    assert a == b


def test_resume_gives_the_same_yarn_paths_and_snapshots(resumed_and_reference):
    resumed, reference, _ = resumed_and_reference
    for name in ("points", "offsets", "time_s", "braid_angle_deg", "face", "flags", "group"):
        a, b = getattr(resumed.yarns, name), getattr(reference.yarns, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert len(resumed.snapshots) == len(reference.snapshots) >= 3
    for a, b in zip(resumed.snapshots, reference.snapshots):
        assert a.time_s == b.time_s
        for name in ("points", "offsets", "tension_N", "contact_id", "slip", "group"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(resumed.convergence_length, reference.convergence_length)
    assert np.array_equal(resumed.fell_s, reference.fell_s)
