"""Every hint names something that exists (docs/cli.md, "Messages").

A hint is a flag or a `samba COMMAND ...` a text suggests. Three sweeps: every
`samba COMMAND --flag` written in the sources, README.md and docs/ names a flag that
command accepts; every bare `--flag` in a command's own module is that command's; and
the hints the shared readers print (T-pose frames, an unknown rig, a duplicate file)
name, in every command that prints them, a flag of that command, and the `samba db rm`
a duplicate suggests really lets the file be imported anew.
"""

from __future__ import annotations

import argparse
import ast
import re
import shlex
from collections.abc import Iterator
from pathlib import Path

import pytest
from bvh_fixtures import make_humanoid

from samba.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("samba", "db", "ingest", "export", "service")
FLAG = re.compile(r"(?<![\w-])(--[a-zA-Z][a-zA-Z0-9-]*|-[a-z])(?![\w-])")
"""A flag: `--word` (`--K` too), or one lower-case letter (`-o`; `-Z` is an axis)."""
MENTION = re.compile(r"\bsamba ([a-z][a-z-]*)(?: ([a-z][a-z-]*))?")
SPAN_END = re.compile(r"[`;()\n]| \| | && | # ")
FOREIGN_FLAGS = {"--clear", "--quiet", "--no-deps"}
"""Flags of other programs the sources pass on (the segmenter's venv and pip)."""
CLI_MODULES = {
    "samba/cli.py": [("db", "rig"), ("eval",), ("warmup",)],
    "samba/cameras/cli.py": [("calibrate",)],
    "db/cli.py": [("db", name) for name in ("init", "ls", "show", "label", "rm", "verify")]
    + [("db", name) for name in ("stats", "tree", "query")]
    + [("track-video",), ("node",)],  # the camera and body flags they share
    "ingest/cli.py": [("db", "import"), ("eval",), ("reconstruct",), ("demo",), ("node",)],
    "export/cli.py": [("export",)],
    **{
        f"service/cli/{name.replace('-', '_')}.py": [(name,)]
        for name in ("serve", "demo", "node", "reconstruct", "track-video", "capture-volume")
    },
}
"""A command's own module -> the commands whose parsers it builds (in part)."""


def parsers() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every command's parser by its words after `samba`."""
    found: dict[tuple[str, ...], argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
        found[path] = parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*path, name))

    walk(build_parser(), ())
    return found


PARSERS = parsers()
EVERY_FLAG = {flag for parser in PARSERS.values() for flag in parser._option_string_actions}


def mentions(text: str) -> Iterator[tuple[tuple[str, ...], list[str], tuple[int, int]]]:
    """Each `samba COMMAND [ACTION] ...` in `text`: the command's words, the flags up to
    the end of the mention (a backtick, `;`, a bracket, a line's end, a pipe, the next
    mention) and the mention's span."""
    starts = list(MENTION.finditer(text))
    for n, match in enumerate(starts):
        area, action = match.groups()
        if ("" if area is None else area,) not in {p[:1] for p in PARSERS if p}:
            continue
        path: tuple[str, ...] = (area,)
        if (area, action) in PARSERS:
            path = (area, action)
        elif any(len(p) == 2 and p[0] == area for p in PARSERS):
            continue  # `samba db STORE ...`: no action named
        stop = starts[n + 1].start() if n + 1 < len(starts) else len(text)
        end = SPAN_END.search(text, match.end(), stop)
        span = (match.start(), end.start() if end else stop)
        yield path, FLAG.findall(text[span[0] : span[1]]), span


def unknown_flags(path: tuple[str, ...], flags: list[str]) -> list[str]:
    """The `flags` the parser of `samba PATH` does not accept."""
    accepted = PARSERS[path]._option_string_actions
    return [flag for flag in flags if flag not in accepted]


def string_constants(source: str) -> Iterator[str]:
    """Every string in a module's code, f-strings with `{}` for their fields, and
    implicitly joined literals as one."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.value
        elif isinstance(node, ast.JoinedStr):
            yield "".join(
                part.value if isinstance(part, ast.Constant) else "{}" for part in node.values
            )


def source_files() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def documents() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def test_every_samba_command_written_in_the_sources_and_docs_takes_its_flags() -> None:
    wrong = []
    for path in [*source_files(), *documents()]:
        text = path.read_text(encoding="utf-8")
        texts = string_constants(text) if path.suffix == ".py" else [text]
        for piece in texts:
            for command, flags, _ in mentions(piece):
                for flag in unknown_flags(command, flags):
                    wrong.append(f"{path.relative_to(ROOT)}: samba {' '.join(command)} {flag}")
    assert not wrong


def test_every_flag_a_command_module_names_is_a_flag_of_its_commands() -> None:
    wrong = []
    for module, commands in CLI_MODULES.items():
        accepted = {f for c in commands for f in PARSERS[c]._option_string_actions}
        for text in string_constants((ROOT / module).read_text(encoding="utf-8")):
            spans = [span for *_, span in mentions(text)]
            bare = "".join(
                ch
                for i, ch in enumerate(text)
                if not any(start <= i < stop for start, stop in spans)
            )
            wrong += [f"{module}: {flag}" for flag in FLAG.findall(bare) if flag not in accepted]
    assert not wrong


def test_every_flag_the_sources_name_is_a_flag_of_some_command() -> None:
    named = {
        flag
        for path in source_files()
        for text in string_constants(path.read_text(encoding="utf-8"))
        for flag in FLAG.findall(text)
        if flag.startswith("--")
    }
    assert not named - EVERY_FLAG - FOREIGN_FLAGS


def run(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str]:
    """`samba argv...` in-process: its exit status and all it printed, after checking
    that every hint in it names a flag of this command or a real command."""
    words = [str(a) for a in argv]
    code = main(words)
    out, err = capsys.readouterr()
    printed = out + err
    command = tuple(words[:2]) if tuple(words[:2]) in PARSERS else tuple(words[:1])
    for line in printed.splitlines():
        spans = []
        for named, flags, span in mentions(line):
            assert not unknown_flags(named, flags), line
            spans.append(span)
        bare = "".join(ch for i, ch in enumerate(line) if not any(a <= i < b for a, b in spans))
        assert not unknown_flags(command, FLAG.findall(bare)), f"samba {words[0]}: {line}"
    return code, printed


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    """A BVH file starting with 3 T-pose frames, one of a skeleton no rig fits, a pose
    store and an empty folder."""
    tpose = tmp_path / "tpose.bvh"
    tpose.write_text(make_humanoid("cmu-max", frames=40, tpose_frames=3).text)
    odd = tmp_path / "odd.bvh"
    odd.write_text(
        "HIERARCHY\nROOT Base\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n"
        " JOINT Arm\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n"
        "  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 2\n"
        "Frame Time: 0.0333333\n0 0 0 0 0 0\n0 0 0 0 0 0\n"
    )
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["db", "init", str(tmp_path / "store")]) == 0
    return {"tpose": tpose, "odd": odd, "store": tmp_path / "store", "empty": empty}


def test_the_t_pose_hint_names_a_flag_of_import_and_export(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, printed = run(capsys, "export", files["tpose"], "-o", tmp_path / "x.glb")
    assert code == 0 and "starts with 3 T-pose frame(s) (0.10 s); --skip-tpose" in printed
    code, printed = run(capsys, "db", "import", files["store"], files["tpose"], "--no-progress")
    assert code == 0 and "starts with 3 T-pose frame(s) (0.10 s); --skip-tpose" in printed


def test_a_duplicate_says_how_to_import_it_anew_and_that_works(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    importing = ("db", "import", files["store"], files["tpose"], "--no-progress")
    run(capsys, *importing)
    code, printed = run(capsys, *importing, "--skip-tpose")
    assert code == 0 and "0 added, 1 already stored" in printed
    rm = re.search(r"samba (db rm .*?) to import it anew", printed)
    assert rm, printed
    code, _ = run(capsys, *shlex.split(rm.group(1)))
    assert code == 0
    code, printed = run(capsys, *importing, "--skip-tpose")
    assert code == 0 and "1 added" in printed and "T-pose" not in printed


@pytest.mark.parametrize(
    "argv",
    [
        ("export", "{odd}", "-o", "{tmp}/x.glb"),
        ("db", "import", "{store}", "{odd}", "--no-progress"),
        ("eval", "--train", "{odd}", "--test", "{odd}"),
        ("demo", "--motion", "{odd}", "--out-dir", "{tmp}/demo"),
        ("db", "rig", "{odd}"),
    ],
    ids=lambda argv: " ".join(argv[:2]),
)
def test_an_unknown_rig_hint_names_a_flag_of_the_command(
    files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    argv: tuple[str, ...],
) -> None:
    names = {"odd": files["odd"], "store": files["store"], "tmp": tmp_path}
    code, printed = run(capsys, *(a.format(**names) for a in argv))
    assert code == 1 and "not a humanoid skeleton" in printed
    assert not (tmp_path / "demo").exists() and not (tmp_path / "x.glb").exists()


def test_an_empty_folder_names_both_formats_import_reads(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    code, printed = run(capsys, "db", "import", files["store"], files["empty"])
    assert code == 1
    assert printed == f"samba: error: {files['empty']}: no .bvh or .mcap files found\n"
