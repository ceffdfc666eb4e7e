"""The results folder: checked before simulating, one run at a time."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import pytest

from preform.io.folder import LOCK, OutputError, RunLock, StaleLockWarning, check_results_folder


def test_a_file_as_results_folder_is_refused(tmp_path):
    f = tmp_path / "out"
    f.write_text("x")
    with pytest.raises(OutputError, match="is a file, not a folder"):
        check_results_folder(f)


def test_a_read_only_filesystem_is_refused(small_tmpfs):
    ro = small_tmpfs(read_only=True)
    with pytest.raises(OutputError, match="cannot be written.*Read-only"):
        check_results_folder(ro)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_results_folder_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="cannot be written"):
            check_results_folder(ro / "out")
    finally:
        ro.chmod(0o700)


def test_a_full_filesystem_is_refused(small_tmpfs):
    full = small_tmpfs(size="64k")
    with pytest.raises(OutputError, match="MB free"):
        check_results_folder(full / "out", expected_bytes=1_000_000)


def test_too_little_room_is_refused(tmp_path):
    with pytest.raises(OutputError, match="MB free"):
        check_results_folder(tmp_path / "out", expected_bytes=10**18)
    check_results_folder(tmp_path / "out", expected_bytes=1000)


def test_check_leaves_nothing_behind(tmp_path):
    check_results_folder(tmp_path / "out")
    assert list((tmp_path / "out").iterdir()) == []


def test_a_second_run_into_a_busy_folder_is_refused(tmp_path):
    # a live process of this host holds the lock
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (tmp_path / LOCK).write_text(json.dumps({"pid": holder.pid, "host": socket.gethostname(),
                                                 "started": "2026-12-01T00:00:00Z"}))
        with pytest.raises(OutputError, match=f"in use by another run \\(PID {holder.pid}"):
            RunLock(tmp_path).acquire()
        assert (tmp_path / LOCK).exists()
    finally:
        holder.kill()
        holder.wait()


def test_a_stale_lock_is_taken_over_with_a_warning(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / LOCK).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(),
                                             "started": "2026-12-01T00:00:00Z"}))
    with pytest.warns(StaleLockWarning, match=f"PID {dead.pid}"):
        with RunLock(tmp_path):
            assert json.loads((tmp_path / LOCK).read_text())["pid"] == os.getpid()
    assert not (tmp_path / LOCK).exists()


def test_a_lock_from_another_host_is_respected(tmp_path):
    (tmp_path / LOCK).write_text(json.dumps({"pid": 1, "host": "other-host", "started": "x"}))
    with pytest.raises(OutputError, match="other-host"):
        RunLock(tmp_path).acquire()


def test_a_symlink_planted_as_the_lock_is_not_followed(tmp_path):
    outside = tmp_path / "outside"
    outside.write_text("precious")
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK).symlink_to(outside)
    with pytest.warns(StaleLockWarning):
        with RunLock(out):
            pass
    assert outside.read_text() == "precious"
