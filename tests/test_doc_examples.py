"""Every command example of README.md and docs/ runs as printed, in a folder `samba
examples` wrote (`doc_examples` reads them from the Markdown).

Pages run in order, each in a fresh copy of that folder, with `../shared/data` beside it
leading to the real data; the pages of `PAGE_GROUPS` share one folder, in that order,
since their examples go on from each other's (the live example's take, the database
page's store). `samba` is the venv's console script. A command ending in `&`, and every
`samba serve`, runs in the background (a server is waited for until it listens); when
its block ends the other background commands are waited for, then each server stopped
with Ctrl-C (SIGINT). A `NAME=value` line sets NAME for the commands after it. Every
command must exit with the status its page shows (`doc_examples.Command.status`) and
print every error line the page shows, word for word (`doc_examples.Command.errors`): an
example of an error fails for the reason the page gives, not for another that names the
same file (an input `samba examples` does not write). Blocks that read the real data are
skipped when it is absent, and so are the later blocks that name a path a skipped block
named, unless `samba examples` wrote it (`mocap-db`, not `store`). `~` is a folder of
the test's own. The real-footage page's captures take about 3 min (four 1080x1920 videos).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from conftest import shared_data_dir
from doc_examples import Block, Command, page_blocks

from samba.service.examples import EXAMPLE_FILES

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PAGE_GROUPS = (
    ("README.md",),
    ("docs/live.md", "docs/database.md", "docs/export.md", "docs/real-markers.md"),
)
"""Pages that share one folder, in this order; every other page runs alone."""
NO_DATA = "needs the real data in ../shared/data (or $SAMBA_DATA)"
"""Why a block that reads the real data is skipped where it is absent."""
COMMAND_TIMEOUT_S = 600.0
SERVER_READY = "camera packets on udp"
"""What a server prints once it listens."""


def _pages() -> list[str]:
    docs = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.md"))
    return [p for p in ["README.md", *docs] if page_blocks(ROOT / p, p)]


def _groups() -> list[tuple[str, ...]]:
    grouped = {page for group in PAGE_GROUPS for page in group}
    return [*PAGE_GROUPS, *((page,) for page in _pages() if page not in grouped)]


@dataclass
class _Background:
    """A command running in the background and what it printed (stdout and stderr)."""

    command: Command
    process: subprocess.Popen[str]
    server: bool
    lines: list[str] = field(default_factory=list)
    ready: threading.Event = field(default_factory=threading.Event)

    def start(self) -> None:
        """Collect its output in a thread; `ready` is set when a server listens or it ends."""

        def read() -> None:
            assert self.process.stdout is not None
            for line in self.process.stdout:
                self.lines.append(line)
                if SERVER_READY in line:
                    self.ready.set()
            self.ready.set()

        threading.Thread(target=read, daemon=True).start()


@dataclass
class _Runner:
    """Runs blocks in `folder` with `env`, collecting `failures`."""

    folder: Path
    env: dict[str, str]
    failures: list[str] = field(default_factory=list)

    def block(self, block: Block) -> None:
        """Run `block`'s commands in order, then end its background commands."""
        background: list[_Background] = []
        began = time.monotonic()
        try:
            for command in block.commands:
                self._command(block, command, background)
        finally:
            self._finish(block, background)
            print(f"{time.monotonic() - began:6.1f} s  {block.name}")  # shown with -s

    def _command(self, block: Block, command: Command, background: list[_Background]) -> None:
        text = command.text
        assignment = re.match(r"^([A-Za-z_][A-Za-z0-9_]*)=", text)
        if assignment:
            name = assignment.group(1)
            script = f'{text}\nprintf %s "${name}"'
            self.env[name] = self._run(script).stdout
            return
        if text.endswith("&") or re.match(r"^samba serve\b", text):
            running = _Background(
                command,
                subprocess.Popen(
                    ["bash", "-c", "exec " + text.rstrip("&").strip()],
                    cwd=self.folder,
                    env=self.env,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT,
                    text=True,
                ),
                server=re.match(r"^samba serve\b", text) is not None,
            )
            running.start()
            background.append(running)
            if running.server:
                running.ready.wait(COMMAND_TIMEOUT_S)
                if running.process.poll() not in (None, 0):
                    self._fail(block, command, running.process.returncode, "".join(running.lines))
            return
        done = self._run(text + "\nexit ${PIPESTATUS[0]}")
        self._check(block, command, done.returncode, done.stdout + done.stderr)

    def _run(self, script: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            ["bash", "-c", script],
            cwd=self.folder,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=COMMAND_TIMEOUT_S,
        )

    def _finish(self, block: Block, background: list[_Background]) -> None:
        """Wait for the block's background commands, then stop its servers (Ctrl-C)."""
        for running in sorted(background, key=lambda r: r.server):
            if running.server and running.process.poll() is None:
                running.process.send_signal(signal.SIGINT)
            try:
                status = running.process.wait(COMMAND_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                running.process.kill()
                status = running.process.wait()
            running.ready.wait(10.0)
            output = "".join(running.lines)
            print(f"`{running.command.text}` exited {status}:\n{output}")  # shown on failure
            self._check(block, running.command, status, output)

    def _check(self, block: Block, command: Command, status: int, output: str) -> None:
        if status != command.status:
            self._fail(block, command, status, output)
        else:
            printed = {line.strip() for line in output.splitlines()}
            for error in command.errors:
                if error not in printed:
                    self._fail(block, command, status, output, f"does not print `{error}`")

    def _fail(
        self, block: Block, command: Command, status: int, output: str, why: str = ""
    ) -> None:
        tail = "\n    ".join(output.strip().splitlines()[-6:])
        self.failures.append(
            f"{block.page}:{command.line}: `{command.text}` exited {status} "
            f"(the page shows {command.status}){'; ' + why if why else ''}\n    {tail}"
        )


@pytest.fixture(scope="module")
def examples_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder `samba examples` wrote, run as a user runs it."""
    folder = tmp_path_factory.mktemp("examples") / "inputs"
    done = subprocess.run(
        [str(BIN / "samba"), "examples", str(folder)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "wrote" in done.stdout and "samba calibrate left middle right" in done.stdout
    return folder


@contextlib.contextmanager
def _one_server_at_a_time(group: tuple[str, ...]) -> Iterator[None]:
    """The examples' servers listen on the default ports: a group that starts one runs
    alone among those that do, also across the workers of pytest-xdist."""
    blocks = [block for page in group for block in page_blocks(ROOT / page, page)]
    if not any(c.text.startswith("samba serve") for b in blocks for c in b.commands):
        yield
        return
    with open(Path(tempfile.gettempdir()) / "samba-doc-examples.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


@pytest.mark.slow
@pytest.mark.parametrize("group", _groups(), ids=lambda group: "+".join(group))
def test_every_command_example_runs_as_printed(
    group: tuple[str, ...], examples_dir: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "work"
    shutil.copytree(examples_dir, folder)
    data = shared_data_dir()
    if data is not None:
        (tmp_path / "shared").mkdir()
        (tmp_path / "shared" / "data").symlink_to(data.resolve())
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}"}
    env["PYTHONUNBUFFERED"] = "1"
    env["HOME"] = str(tmp_path / "home")  # what an example writes under ~ stays here
    (tmp_path / "home").mkdir()
    runner = _Runner(folder, env)
    plan = _plan(group, {path.name for path in examples_dir.iterdir()}, data is not None)
    with _one_server_at_a_time(group):
        for block, reason in plan:
            if reason is None:
                runner.block(block)
    assert not runner.failures, "\n".join(runner.failures)
    skipped = [f"{block.name}: {reason}" for block, reason in plan if reason is not None]
    if skipped:
        pytest.skip("; ".join(skipped))


def _plan(
    group: tuple[str, ...], given: set[str], with_data: bool
) -> list[tuple[Block, str | None]]:
    """The blocks of `group`'s pages in order, each with why it is skipped (None: it
    runs) when the example folder holds `given` and the real data is there or not."""
    plan: list[tuple[Block, str | None]] = []
    unmade: set[str] = set()  # paths the skipped blocks name, and so may have made
    for page in group:
        for block in page_blocks(ROOT / page, page):
            reason = None if with_data or "shared/data" not in _text(block) else NO_DATA
            missing = sorted(p for p in _paths(block) & unmade if p not in given)
            if reason is None and missing:
                reason = f"reads {missing[0]}, which a block skipped before it makes"
            if reason is not None:
                unmade |= {p for p in _paths(block) if "shared/data" not in p}
            plan.append((block, reason))
    return plan


def _text(block: Block) -> str:
    return "\n".join(command.text for command in block.commands)


def _paths(block: Block) -> set[str]:
    """The words of the block's commands that look like paths (a dot, a dash or a slash
    in them; not a flag)."""
    words = (word for command in block.commands for word in command.text.split())
    return {w.rstrip("/") for w in words if re.search(r"[./-]", w) and not w.startswith("-")}


def test_the_examples_are_found() -> None:
    """The reader finds the examples the pages show, with their shown exit status."""
    readme = page_blocks(ROOT / "README.md", "README.md")
    commands = [command for block in readme for command in block.commands]
    assert any(c.text.startswith("samba calibrate left middle right") for c in commands)
    assert any(c.text.startswith("T=$((") for c in commands)
    errors = [c for b in page_blocks(ROOT / "docs/export.md", "e") for c in b.commands]
    assert {c.status for c in errors} == {0, 1}
    in_list = [c.text for b in page_blocks(ROOT / "docs/cli.md", "c") for c in b.commands]
    assert "samba export studio_walk.bvh -o walk.glb" in in_list  # fences in list items
    shown = {error for c in errors for error in c.errors}
    assert (
        "samba: error: me.gltf: buffer 0: cannot read its file me.bin: No such file or "
        "directory" in shown
    )


def test_without_the_data_only_what_needs_it_is_skipped() -> None:
    plan = _plan(("README.md",), set(EXAMPLE_FILES), with_data=False)
    running = [c.text for block, reason in plan if reason is None for c in block.commands]
    reasons = {reason for _, reason in plan} - {None}
    assert any(text.startswith("samba calibrate left middle right") for text in running)
    assert any(text.startswith("samba track-video wave/") for text in running)
    assert not any("shared/data" in text or "mocap-db" in text for text in running)
    assert reasons == {
        NO_DATA,
        "reads mocap-db, which a block skipped before it makes",
    }
    with_data = _plan(("README.md",), set(EXAMPLE_FILES), with_data=True)
    assert all(reason is None for _, reason in with_data)


def test_the_real_footage_captures_run_where_the_data_is() -> None:
    page = ("docs/real-footage.md",)
    plan = _plan(page, set(EXAMPLE_FILES), with_data=True)
    commands = [c.text for block, reason in plan if reason is None for c in block.commands]
    assert any(text.startswith("samba capture-volume $D/videos/cam01.mp4") for text in commands)
    assert any(text.startswith("samba track-video $D/videos/cam01.mp4") for text in commands)
    without = _plan(page, set(EXAMPLE_FILES), with_data=False)
    assert {reason for _, reason in without} == {NO_DATA}
