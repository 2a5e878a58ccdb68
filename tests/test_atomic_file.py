"""Atomic writes: whole new content or the old file, and the permissions of a plain file."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from samba.base.atomic_file import atomic_path, write_bytes_atomic, write_text_atomic


def test_written_files_get_the_mode_a_plain_file_would(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        write_text_atomic(tmp_path / "a.txt", "hello")
        (tmp_path / "plain.txt").write_text("hello")
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "a.txt").stat().st_mode)
    assert mode == stat.S_IMODE((tmp_path / "plain.txt").stat().st_mode) == 0o640


def test_a_secret_gets_its_mode_also_over_a_readable_file(tmp_path: Path) -> None:
    key = tmp_path / "cam0.key"
    key.write_bytes(b"old")
    key.chmod(0o644)
    write_bytes_atomic(key, b"new secret", mode=0o600)
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    assert key.read_bytes() == b"new secret"


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "take.usda"
    write_bytes_atomic(path, b"old")
    with pytest.raises(RuntimeError), atomic_path(path) as tmp:
        assert tmp.suffix == ".usda" and tmp.parent == tmp_path
        tmp.write_bytes(b"half")
        raise RuntimeError("disk full")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["take.usda"]
