"""Ctrl-C during a run keeps a marked partial result; --resume reproduces the uninterrupted run
(issue 5, items 4-5)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CASE = """
[mandrel]
stl = "{root}/mandrels/cone.stl"
centerline = "{root}/mandrels/cone_centerline.csv"

[machine]
carriers = 96
spool_radius = 0.3
angular_speed = 13.232

[yarn]
width = 2e-3
thickness = 2.5e-4

[process]
take_up_speed = 0.01
initial_position = 0.05
braid_length = 0.5

[model]
time_step = 0.005

[output]
dir = "{out}"
field_edge_length = 0.02
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
    # wait until the simulation is stepping (the progress bar is on stderr), then Ctrl-C; the
    # simulation takes about 4 s at this time step (13600 steps), so 0.5 s in it is still stepping
    seen = b""
    deadline = time.time() + 300
    while b"braiding" not in seen and time.time() < deadline:
        seen += os.read(proc.stderr.fileno(), 256)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err.decode()[-2000:]
    result = tmp_path / "stopped"
    summary = json.loads((result / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert "resume" in summary["message"]
    assert (result / "checkpoint.pkl").is_file()
    partial = (result / "history.csv").read_text().splitlines()
    assert len(partial) > 10

    resumed = _preform("run", cfg, "--resume", "--no-progress")
    _, err = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, err.decode()[-2000:]
    assert not (result / "checkpoint.pkl").exists()

    reference = _preform("run", _case(tmp_path, "reference"), "--no-progress")
    _, err = reference.communicate(timeout=600)
    assert reference.returncode == 0, err.decode()[-2000:]
    full = (tmp_path / "reference" / "history.csv").read_text()
    assert (result / "history.csv").read_text() == full      # bit for bit
    assert partial == full.splitlines()[:len(partial)]


def test_resume_without_checkpoint_is_a_clear_error(tmp_path):
    proc = _preform("run", _case(tmp_path, "fresh"), "--resume", "--no-progress")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2
    assert "no checkpoint" in err.decode() and "Traceback" not in err.decode()


def test_a_checkpoint_keeps_its_time_step(tmp_path, monkeypatch):
    """A run resumed by a version whose step control gives another step goes on with the step it
    started with (``simulate._STATE`` holds ``dt`` and the snapshot stride)."""
    import dataclasses
    import importlib

    from preform.config import load_config

    sim = importlib.import_module("preform.simulate")
    cfg = load_config(_case(tmp_path, "kept"))
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, time_step=None))
    mandrel, centerline = sim.load_geometry(cfg)
    machine = sim.Machine.from_config(cfg.machine)
    first = sim._Stepper(cfg, machine, mandrel, centerline)
    first.save(tmp_path / "c.pkl")
    monkeypatch.setattr(sim, "default_time_step", lambda *a: 3.0 * first.dt)
    second = sim._Stepper(cfg, machine, mandrel, centerline)
    assert second.dt == pytest.approx(3.0 * first.dt)
    second.restore(tmp_path / "c.pkl")
    assert second.dt == first.dt and second.snapshot_stride == first.snapshot_stride
