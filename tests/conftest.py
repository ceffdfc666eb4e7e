"""Shared test set-up: headless matplotlib and a small synthetic Result for the writers."""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")
# the suite's disk cache (preform.io.cache) in a folder of its own, removed at the end: tests never
# read a cache entry left by the user's runs, nor leave entries in the user's ~/.cache
import shutil  # noqa: E402
import tempfile  # noqa: E402

_CACHE = tempfile.mkdtemp(prefix="preform-test-cache-")
os.environ["PREFORM_CACHE_DIR"] = _CACHE

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from preform.config import (Config, MachineConfig, MandrelConfig, ModelConfig,  # noqa: E402
                            ProcessConfig, YarnConfig)
from preform.result import (FLAG_BRIDGE, FLAG_CATCH, FLAG_SLIP, HISTORY_COLUMNS,  # noqa: E402
                            Result, Snapshot, YarnPaths)


def synthetic_result(n_steps=6, snapshot_points=((2, 2, 3, 4), (2, 3, 2, 2))) -> Result:
    """A hand-built Result: 4 helical yarns (2 warp, 2 weft) of 5 points on a 50 mm cylinder,
    ``n_steps`` history rows with made-up but finite values, one Snapshot per entry of
    ``snapshot_points`` (points per yarn). Not physics: only the file writers look at it."""
    rng = np.random.default_rng(7)
    n_yarns, per_yarn = 4, 5
    t = np.linspace(0.0, 2.0, per_yarn)
    yarn_points = []
    for k in range(n_yarns):
        sign = 1.0 if k < 2 else -1.0
        phi = k * np.pi / 2 + sign * 0.8 * t
        yarn_points.append(np.column_stack([0.05 * np.cos(phi), 0.05 * np.sin(phi), 0.01 * t]))
    flags = np.zeros(n_yarns * per_yarn, np.uint8)
    flags[[3, 7]] = FLAG_BRIDGE
    flags[8] = FLAG_CATCH | FLAG_SLIP
    yarns = YarnPaths(
        points=np.vstack(yarn_points),
        offsets=np.arange(0, n_yarns * per_yarn + 1, per_yarn, dtype=np.int64),
        time_s=np.tile(t, n_yarns),
        braid_angle_deg=45.0 + rng.normal(0.0, 1.0, n_yarns * per_yarn) / 3.0,
        face=np.arange(n_yarns * per_yarn, dtype=np.int64),
        flags=flags,
        group=np.array([0, 0, 1, 1], np.int8),
    )
    steps = np.arange(n_steps, dtype=np.float64)
    history = {name: rng.uniform(0.1, 1.0, n_steps) / 3.0 for name in HISTORY_COLUMNS}
    history["time_s"] = steps * 0.5
    history["braided_length_m"] = steps * 0.005
    history["braid_angle_warp_deg"] = 45.0 + 10.0 / (1.0 + steps)
    history["braid_angle_weft_deg"] = 45.5 + 10.0 / (1.0 + steps)
    history["contacts"] = steps * 3
    history["iterations"] = steps + 1
    snapshots = []
    for i, counts in enumerate(snapshot_points):
        m = sum(counts)
        snapshots.append(Snapshot(
            time_s=0.25 * (i + 1),
            points=rng.normal(0.0, 0.1, (m, 3)),
            offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            tension_N=rng.uniform(4.0, 6.0, m - len(counts)),
            contact_id=np.where(rng.random(m) < 0.5, -1, np.arange(m)).astype(np.int64),
            slip=(rng.random(m) < 0.5).astype(np.int8),
            group=np.array([0, 0, 1, 1], np.int8),
        ))
    config = Config(
        mandrel=MandrelConfig(stl=Path("/nowhere/mandrel.stl")),
        machine=MachineConfig(carriers=4, spool_radius=0.3, angular_speed=0.2),
        yarn=YarnConfig(width=4e-3, thickness=2.5e-4),
        process=ProcessConfig(take_up_speed=((0.0, 0.01),), initial_position=0.1, braid_length=0.3),
        model=ModelConfig(kind="kinematic"),
    )
    return Result(config=config, mandrel=None, centerline=None, yarns=yarns, history=history,
                  snapshots=snapshots, status="done", wall_time_s=1.25)


@pytest.fixture
def small_result() -> Result:
    return synthetic_result()


@pytest.fixture
def small_tmpfs(tmp_path):
    """``mount(size, read_only=False) -> Path``: a small tmpfs (root only; skips elsewhere).

    Full and read-only filesystems are real here, not monkeypatched writes."""
    import subprocess

    mounted = []

    def mount(size="256k", read_only=False):
        if os.geteuid() != 0:
            pytest.skip("mounting a tmpfs needs root")
        point = tmp_path / f"fs{len(mounted)}"
        point.mkdir()
        opts = f"size={size}" + (",ro" if read_only else "")
        if subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(point)],
                          capture_output=True).returncode != 0:
            pytest.skip("this machine refuses to mount a tmpfs")
        mounted.append(point)
        return point

    yield mount
    for point in mounted:
        subprocess.run(["umount", "-l", str(point)], capture_output=True)


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(_CACHE, ignore_errors=True)
