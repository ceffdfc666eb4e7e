"""Atomic writes: the final name appears only when the write succeeded."""

from __future__ import annotations

import pytest

from preform.io.atomic import atomic_path, atomic_write_bytes, atomic_write_text


def test_write_text_and_bytes(tmp_path):
    path = atomic_write_text(tmp_path / "sub" / "a.txt", "héllo\n")
    assert path.read_text(encoding="utf-8") == "héllo\n"
    atomic_write_bytes(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in path.parent.iterdir()) == ["a.txt"]


def test_temporary_path_keeps_suffix_and_folder(tmp_path):
    with atomic_path(tmp_path / "yarns.vtp") as tmp:
        assert tmp.suffix == ".vtp"
        assert tmp.parent == tmp_path
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
