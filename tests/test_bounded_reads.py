"""Bounded reads of `samba db import` (issue 41, item 6): only regular files are read (a
FIFO or a device is refused by its type), each at most a size limit (`--max-file-mb`);
hierarchies and JSON messages nest at most so deep (no recursion without bound); an error
quotes at most 80 characters of the file; and a batch reports a bad file, whatever its
error, and goes on."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from bvh_fixtures import humanoid_bvh
from take_file_fixtures import pose_message, walk_poses, walk_take_file, write_take_file

import samba.ingest.batch as batch_module
import samba.ingest.input_files as input_files
from samba.cli import main
from samba.db.store import PoseStore
from samba.ingest.errors import BvhError

TIMEOUT = 300.0
"""Seconds the import subprocess may take on a loaded machine; never a pass/fail time (a
reader that blocks on a FIFO would wait forever)."""
MEMORY = 3 * 2**30
"""Address space (bytes) of the import subprocess: a reader that reads a device to its
end fails for want of memory instead of taking the machine's."""


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """`samba argv...` in-process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def store(tmp_path: Path) -> Path:
    return PoseStore.create(tmp_path / "db").path


@pytest.fixture
def good(tmp_path: Path) -> Path:
    """A sound BVH file, imported after the bad ones to show the batch went on."""
    path = tmp_path / "good.bvh"
    path.write_text(humanoid_bvh())
    return path


def assert_went_on(store: Path, out: str, err: str, failed: int) -> list[str]:
    """The batch imported the good file after `failed` bad ones, printed its summary and
    left a fresh index; returns the error lines (one per bad file)."""
    assert f"1 added, 0 already stored, {failed} failed; store now holds 1 takes" in out
    assert "Traceback" not in err
    errors = err.splitlines()
    assert len(errors) == failed and all(e.startswith("samba: error: ") for e in errors)
    assert PoseStore.open(store).index_is_fresh()
    return errors


def test_fifos_devices_and_links_to_them_are_refused_by_type(
    store: Path, good: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "folder"
    folder.mkdir()
    os.mkfifo(folder / "pipe.bvh")  # no writer: opening it to read would wait forever
    (folder / "zero.bvh").symlink_to("/dev/zero")
    argv = ["db", "import", str(store), "/dev/zero", str(folder), str(good), "--no-progress"]
    done = subprocess.run(
        [sys.executable, "-m", "samba.cli", *argv],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY)),
    )
    assert done.returncode == 1
    errors = assert_went_on(store, done.stdout, done.stderr, failed=3)
    assert errors == [
        "samba: error: /dev/zero: cannot read file: a character device, not a regular file",
        f"samba: error: {folder}/pipe.bvh: cannot read file: a FIFO (named pipe), not a "
        "regular file",
        f"samba: error: {folder}/zero.bvh: cannot read file: a character device, not a "
        "regular file",
    ]


def test_a_file_over_the_size_limit_is_refused_before_it_is_read(
    store: Path, good: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    big = tmp_path / "big.bvh"
    big.write_text(humanoid_bvh(frames=400))  # about 300 kB
    size = big.stat().st_size / 1e6
    argv = ["db", "import", str(store), str(big), str(good), "--no-progress"]
    code, out, err = run(capsys, *argv, "--max-file-mb", "0.1")
    assert code == 1
    (error,) = assert_went_on(store, out, err, failed=1)
    assert error == (
        f"samba: error: {big}: {size:.1f} MB, over the limit of 0.1 MB a file "
        "(samba db import --max-file-mb raises it)"
    )
    code, out, _ = run(capsys, *argv, "--max-file-mb", "1")
    assert code == 0 and "1 added, 1 already stored, 0 failed" in out


@pytest.mark.parametrize(("grown", "limit", "refused"), [(1000, 4000, False), (5000, 4000, True)])
def test_a_file_that_grows_while_it_is_read_is_read_whole_or_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, grown: int, limit: int, refused: bool
) -> None:
    path = tmp_path / "growing.bvh"
    path.write_bytes(b"x" * 2000)
    real_fstat = os.fstat
    sizes = []

    def fstat_then_grow(fd: int) -> os.stat_result:
        info = real_fstat(fd)
        sizes.append(info.st_size)
        if len(sizes) == 2:  # after the size check, before the read
            with path.open("ab") as out:
                out.write(b"y" * grown)
        return info

    monkeypatch.setattr(input_files.os, "fstat", fstat_then_grow)
    if refused:
        with pytest.raises(BvhError, match=r"growing.bvh: .* over the limit of 0.004 MB a file"):
            input_files.read_input(path, limit, BvhError)
    else:
        assert input_files.read_input(path, limit, BvhError) == b"x" * 2000 + b"y" * grown
    assert sizes == [2000, 2000]


def test_a_hierarchy_deeper_than_the_limit_fails_alone(
    store: Path, good: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    depth = 10_000
    deep = tmp_path / "deep.bvh"
    deep.write_text(
        "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n"
        + "".join(f"JOINT j{i}\n{{\nOFFSET 0 1 0\n" for i in range(depth))
        + "}\n" * (depth + 1)
        + "MOTION\nFrames: 1\nFrame Time: 0.033\n0 0 0\n"
    )
    code, out, err = run(capsys, "db", "import", str(store), str(deep), str(good), "--no-progress")
    assert code == 1
    (error,) = assert_went_on(store, out, err, failed=1)
    assert error == f"samba: error: {deep}:771: joints nest deeper than 256 levels"


def test_a_take_message_nested_deeper_than_the_limit_fails_alone(
    store: Path, good: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    messages = [pose_message(p) for p in walk_poses()]
    messages[3] = b"[" * 100_000 + b"]" * 100_000
    deep = write_take_file(tmp_path / "deep.mcap", messages)
    code, out, err = run(capsys, "db", "import", str(store), str(deep), str(good), "--no-progress")
    assert code == 1
    (error,) = assert_went_on(store, out, err, failed=1)
    assert error == f"samba: error: {deep}: /pose_raw message 3 nests deeper than 32 levels"


def test_errors_quote_at_most_80_characters_of_the_file(
    store: Path, good: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    token = tmp_path / "token.bvh"
    token.write_text("x" * 3_000_000)
    head = humanoid_bvh().split("MOTION")[0]
    line = tmp_path / "line.bvh"
    line.write_text(head + "MOTION\nFrames: 1\nFrame Time: 0.0333\n" + "1 " * 1_500_000 + "\n")
    argv = ["db", "import", str(store), str(token), str(line), str(good), "--no-progress"]
    code, out, err = run(capsys, *argv)
    assert code == 1
    errors = assert_went_on(store, out, err, failed=2)
    assert errors[0] == (
        f"samba: error: {token}:1: expected 'HIERARCHY', found '{'x' * 80}'... "
        "(3,000,000 characters)"
    )
    assert errors[1].endswith("frame 0 has more than 66 values, the hierarchy declares 66 channels")
    assert len(out) + len(err) < 2_000


@pytest.mark.parametrize("error", [RecursionError, MemoryError, OSError, KeyError])
def test_a_batch_reports_a_file_and_goes_on_whatever_its_error(
    store: Path,
    good: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    error: type[Exception],
) -> None:
    strange = tmp_path / "strange.bvh"
    strange.write_text(humanoid_bvh())
    load = batch_module.load_bvh_take

    def fail_on_strange(path: Path, options: object) -> object:
        if path.name == "strange.bvh":
            raise error("x" * 500)
        return load(path, options)

    monkeypatch.setattr(batch_module, "load_bvh_take", fail_on_strange)
    argv = ["db", "import", str(store), str(strange), str(good), "--no-progress"]
    code, out, err = run(capsys, *argv)
    assert code == 1
    (line,) = assert_went_on(store, out, err, failed=1)
    head = f"samba: error: {strange}: cannot import: {error.__name__}: "
    assert line.startswith(head) and line.endswith("x...")
    assert len(line) - len(head) == 80 + len("...")  # the error's text cut to 80 characters


def test_a_recorded_take_over_the_size_limit_is_refused(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    take = walk_take_file(tmp_path / "walk.mcap")
    code, _, err = run(capsys, "db", "import", str(store), str(take), "--max-file-mb", "0.001")
    assert code == 1 and f"{take}: " in err and "over the limit of 0.001 MB a file" in err
