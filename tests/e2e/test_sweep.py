"""Parameter sweeps on Dask: a LocalCluster and a separate scheduler, failures
recorded, resume, and rows equal to separate ``preform run``s."""

from __future__ import annotations

import csv
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from preform.cli import main
from preform.errors import ConfigError, PreformError
from preform.studies.sweeps import ClusterSettings, load_sweep, read_sweep_csv, sweep

ROOT = Path(__file__).resolve().parents[2]
BASE = f"""
[mandrel]
stl = "{ROOT / 'mandrels' / 'cone.stl'}"
centerline = "{ROOT / 'mandrels' / 'cone_centerline.csv'}"
[machine]
carriers = 16
spool_radius = 0.5
angular_speed = 30.0
[yarn]
width = 4e-3
thickness = 2.5e-4
friction = 0.2
[process]
take_up_speed = 0.01
initial_position = 0.1
braid_length = 0.03
[output]
snapshots = 2
pictures = false      # each point's pictures: tests/e2e/test_pictures_*.py; the sweep's plots stay
"""
SWEEP = """
base = "base.toml"
[grid]
"yarn.friction" = [0.0, 0.3]
"process.initial_position" = [0.1, 0.15]
[[points]]                     # fails in its worker: the mandrel's end passes the machine
"process.braid_length" = 5.0
[output]
dir = "out"
"""


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep")
    (folder / "base.toml").write_text(BASE)
    (folder / "sweep.toml").write_text(SWEEP)
    rows = sweep(folder / "sweep.toml", workers=2, progress=False)
    return folder, rows


def test_every_point_has_a_row_and_a_results_folder(local_sweep):
    folder, rows = local_sweep
    assert [r["point"] for r in rows] == [0, 1, 2, 3, 4]
    assert [r["status"] for r in rows] == ["done"] * 4 + ["failed"]
    assert "braid_length" in rows[4]["message"]
    table = read_sweep_csv(folder / "out" / "sweep.csv")
    assert [t["yarn.friction"] for t in table[:4]] == ["0.0", "0.0", "0.3", "0.3"]
    assert [t["process.initial_position"] for t in table[:4]] == ["0.1", "0.15", "0.1", "0.15"]
    assert table[4]["status"] == "failed" and table[4]["process.braid_length"] == "5.0"
    for r in rows[:4]:
        assert (Path(r["results"]) / "summary.json").is_file()
    assert {p.name for p in (folder / "out" / "plots").iterdir()} == {
        "yarn_friction.png", "process_initial_position.png", "process_braid_length.png"}


def test_a_point_equals_a_separate_preform_run(local_sweep, tmp_path):
    folder, rows = local_sweep
    for r in rows[:4:3]:   # the first and the last grid point
        point = Path(r["results"])
        assert main(["run", str(point / "config.toml"), "--out", str(tmp_path / point.name),
                     "--no-progress"]) == 0
        assert (tmp_path / point.name / "history.csv").read_bytes() == (point / "history.csv").read_bytes()


def test_pf_sweep_is_the_function_and_stays_so():
    import preform as pf
    import preform.studies.sweeps  # noqa: F401 - importing the module must not replace pf.sweep

    assert pf.sweep is sweep and callable(pf.sweep)


def test_resume_runs_only_what_is_missing(local_sweep):
    folder, rows = local_sweep
    summaries = {r["point"]: Path(r["results"]) / "summary.json" for r in rows[:4]}
    before = {k: p.stat().st_mtime_ns for k, p in summaries.items()}
    summaries[1].unlink()
    again = sweep(folder / "sweep.toml", workers=1, resume=True, progress=False)
    assert [r["status"] for r in again] == ["done"] * 4 + ["failed"]
    after = {k: p.stat().st_mtime_ns for k, p in summaries.items()}
    assert after[0] == before[0] and after[2] == before[2] and after[3] == before[3]
    assert summaries[1].is_file()


def test_bad_sweep_files_are_refused_before_any_run(tmp_path):
    (tmp_path / "base.toml").write_text(BASE)
    (tmp_path / "s.toml").write_text('base = "base.toml"\n[grid]\n"yarn.friction" = [0.1, -1.0]\n')
    with pytest.raises(ConfigError, match=r"point 1 \(yarn.friction = -1\).*friction"):
        load_sweep(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text('base = "nowhere.toml"\n[grid]\n"yarn.friction" = [0.1]\n')
    with pytest.raises(ConfigError, match="base config .*nowhere.toml not found"):
        load_sweep(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text('base = "base.toml"\n[grid]\n"friction" = [0.1]\n')
    with pytest.raises(ConfigError, match='expected "section.key"'):
        load_sweep(tmp_path / "s.toml")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_sweep_on_a_separately_started_scheduler_and_workers(tmp_path, capsys):
    (tmp_path / "base.toml").write_text(BASE)
    (tmp_path / "sweep.toml").write_text('base = "base.toml"\n[grid]\n"yarn.friction" = [0.0, 0.3]\n'
                                         '[output]\ndir = "out"\n')
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler = subprocess.Popen([*dask, "--host", "127.0.0.1", "--port", str(port),
                                  "--dashboard-address", "127.0.0.1:0"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                 "--nthreads", "1", "--host", "127.0.0.1", "--dashboard-address",
                                 "127.0.0.1:0"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
               for _ in range(1)]   # one worker: a second adds its start, not a property
    try:
        deadline = time.monotonic() + 60
        while True:   # wait for the scheduler to listen
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        assert main(["sweep", str(tmp_path / "sweep.toml"), "--scheduler", address, "--no-progress"]) == 0
        assert "2 of 2 points done" in capsys.readouterr().out
        with open(tmp_path / "out" / "sweep.csv", newline="") as f:
            assert [r["status"] for r in csv.DictReader(f)] == ["done", "done"]
    finally:
        for p in [*workers, scheduler]:
            p.terminate()
        for p in [*workers, scheduler]:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_an_unreachable_scheduler_is_said_so(tmp_path):
    (tmp_path / "base.toml").write_text(BASE)
    (tmp_path / "sweep.toml").write_text('base = "base.toml"\n[grid]\n"yarn.friction" = [0.0]\n')
    with pytest.raises(PreformError, match="no Dask scheduler answers there"):
        sweep(tmp_path / "sweep.toml", scheduler=f"tcp://127.0.0.1:{_free_port()}", progress=False,
              cluster=ClusterSettings(connect_timeout_s=1.0))


def test_a_sweep_key_addresses_one_layer(tmp_path):
    """"layer.K.section.key" sets a key of the K-th [[layer]] (counted from 1, as preform names
    the layers); the other layer and the top-level sections keep theirs."""
    import numpy as np

    ex = Path(__file__).resolve().parents[2] / "examples"
    (tmp_path / "s.toml").write_text(
        f'base = "{(ex / "two_layers.toml").as_posix()}"\n'
        '[grid]\n"layer.2.machine.angular_speed" = [12.0, 20.0]\n'
        '[set]\n"layer.1.yarn.friction" = 0.3\n')
    spec = load_sweep(tmp_path / "s.toml")
    assert [p.name for p in spec.points] == ["000_layer2-angular_speed=12",
                                            "001_layer2-angular_speed=20"]
    for point, deg in zip(spec.points, (12.0, 20.0)):
        cfg = spec.configs[point.index]
        assert cfg.layer_config(1).machine.angular_speed == pytest.approx(np.radians(deg))
        assert cfg.layer_config(0).machine.angular_speed == pytest.approx(np.radians(9.55))
        assert cfg.layer_config(0).yarn.friction == 0.3
        assert cfg.layer_config(1).yarn.friction == 0.25
        assert cfg.layers[1].direction == "backward"


@pytest.mark.parametrize("key, says", [
    ("layer.3.machine.angular_speed", "has 2 \\[\\[layer\\]\\] table\\(s\\); expected a number from 1 to 2"),
    ("layer.machine.angular_speed", "name one by its number"),
    ("layer", 'expected "section.key"'),
])
def test_a_layer_key_that_names_no_layer_is_refused(tmp_path, key, says):
    ex = Path(__file__).resolve().parents[2] / "examples"
    (tmp_path / "s.toml").write_text(f'base = "{(ex / "two_layers.toml").as_posix()}"\n'
                                     f'[grid]\n"{key}" = [12.0]\n')
    with pytest.raises(ConfigError, match=says):
        load_sweep(tmp_path / "s.toml")
