"""Atomic writes: the final name appears only when the write succeeded."""

from __future__ import annotations

import os
import stat
import warnings

import pytest

from preform.io.atomic import UnsafePathWarning, atomic_path, atomic_write_bytes, atomic_write_text, safe_folder


def test_write_text_and_bytes(tmp_path):
    path = atomic_write_text(tmp_path / "sub" / "a.txt", "héllo\n")
    assert path.read_text(encoding="utf-8") == "héllo\n"
    atomic_write_bytes(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in path.parent.iterdir()) == ["a.txt"]


def test_temporary_path_keeps_name_in_a_private_folder_beside_the_target(tmp_path):
    with atomic_path(tmp_path / "yarns.vtp") as tmp:
        assert tmp.name == "yarns.vtp"
        assert tmp.parent.parent == tmp_path
        assert stat.S_IMODE(tmp.parent.stat().st_mode) == 0o700   # nobody else can plant a file there
        assert not tmp.exists()
        tmp.write_text("x")
    assert (tmp_path / "yarns.vtp").read_text() == "x"
    assert [p.name for p in tmp_path.iterdir()] == ["yarns.vtp"]


def test_failed_block_leaves_no_file(tmp_path):
    target = tmp_path / "summary.json"
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_path(target) as tmp:
            tmp.write_text('{"half": ')
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_failed_block_keeps_previous_file(tmp_path):
    target = atomic_write_text(tmp_path / "history.csv", "old\n")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("new, half")
            raise KeyboardInterrupt
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["history.csv"]


def test_writer_that_writes_nothing_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        with atomic_path(tmp_path / "x.png"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_written_files_keep_the_users_umask(tmp_path):
    old = os.umask(0o022)
    try:
        text = atomic_write_text(tmp_path / "summary.json", "{}")
        with atomic_path(tmp_path / "x.png") as tmp:
            tmp.write_bytes(b"png")
    finally:
        os.umask(old)
    assert stat.S_IMODE(text.stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "x.png").stat().st_mode) == 0o644


def test_a_symlink_at_the_final_name_is_replaced_not_followed(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("precious")
    results = tmp_path / "results"
    results.mkdir()
    (results / "history.csv").symlink_to(outside)
    with pytest.warns(UnsafePathWarning, match="symlink"):
        atomic_write_text(results / "history.csv", "new\n")
    assert outside.read_text() == "precious"
    assert not (results / "history.csv").is_symlink()
    assert (results / "history.csv").read_text() == "new\n"


def test_safe_folder_replaces_a_planted_folder_symlink(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    results = tmp_path / "results"
    results.mkdir()
    (results / "plots").symlink_to(elsewhere, target_is_directory=True)
    with pytest.warns(UnsafePathWarning):
        plots = safe_folder(results, "plots")
    atomic_write_text(plots / "a.png", "x")
    assert list(elsewhere.iterdir()) == []
    assert plots.is_dir() and not plots.is_symlink()


def test_safe_folder_refuses_a_file_in_place_of_a_folder(tmp_path):
    (tmp_path / "plots").write_text("not a folder")
    with pytest.raises(NotADirectoryError, match="not a folder"):
        safe_folder(tmp_path, "plots")


def test_the_results_folder_itself_may_be_a_symlink(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real, target_is_directory=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        atomic_write_text(safe_folder(tmp_path / "link") / "a.txt", "x")
    assert (real / "a.txt").read_text() == "x"
