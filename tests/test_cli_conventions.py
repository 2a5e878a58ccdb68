"""The conventions of docs/cli.md, checked on every command's parser: descriptions, help
with defaults, metavar style, one spelling per flag, and the output flags; and what
Ctrl-C says."""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from bvh_fixtures import make_humanoid

from samba.cli import build_parser, main
from samba.db import PoseStore
from samba.ingest import batch

METAVAR = re.compile(r"(?:[A-Z][A-Z0-9_]*|\.\.\.|[:,;]|\.[a-z0-9]+)+")
"""Capitals naming the value (FILE, STORE, HOST:PORT, X,Z, NAME,...), a file suffix in
lower case (FILE.toml)."""
NO_FORCE = {("serve",): "names every take itself and refuses a name in use"}
"""Commands that write into a folder without overwriting anything, so need no --force."""


def commands(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every parser of the tree with its words after `samba` (the top one has none)."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from commands(sub, (*path, name))


def options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The parser's own flags and positionals, without -h and the subcommand choice."""
    return [
        a
        for a in parser._actions
        if not isinstance(a, argparse._HelpAction | argparse._SubParsersAction)
    ]


def takes_value(action: argparse.Action) -> bool:
    """Whether a flag reads a value (not a switch such as --force)."""
    return action.nargs != 0


def in_required_group(parser: argparse.ArgumentParser, action: argparse.Action) -> bool:
    """Whether `action` is one of a group of which exactly one must be given."""
    return any(g.required and action in g._group_actions for g in parser._mutually_exclusive_groups)


def metavar_words(action: argparse.Action) -> tuple[str, ...]:
    """The metavar(s) a flag's help shows."""
    shown = action.metavar or action.dest.upper()
    return shown if isinstance(shown, tuple) else (shown,)


TREE = list(commands(build_parser()))
LEAVES = [
    (path, p)
    for path, p in TREE
    if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions)
]


def label(path: tuple[str, ...]) -> str:
    return " ".join(("samba", *path))


@pytest.mark.parametrize(("path", "parser"), TREE[1:], ids=[label(p) for p, _ in TREE[1:]])
def test_every_command_has_a_description(
    path: tuple[str, ...], parser: argparse.ArgumentParser
) -> None:
    assert parser.description, f"{label(path)} has no description"


@pytest.mark.parametrize(("path", "parser"), LEAVES, ids=[label(p) for p, _ in LEAVES])
def test_every_flag_has_help_that_gives_its_default(
    path: tuple[str, ...], parser: argparse.ArgumentParser
) -> None:
    problems = []
    for action in options(parser):
        name = "/".join(action.option_strings) or action.dest
        if not action.help:
            problems.append(f"{name} has no help")
        elif (
            action.option_strings
            and takes_value(action)
            and not action.required
            and not in_required_group(parser, action)
            and "default" not in action.help
        ):
            problems.append(f"{name}: help does not say the default")
    assert not problems, f"{label(path)}: {problems}"


@pytest.mark.parametrize(("path", "parser"), LEAVES, ids=[label(p) for p, _ in LEAVES])
def test_metavars_name_the_value_in_capitals(
    path: tuple[str, ...], parser: argparse.ArgumentParser
) -> None:
    problems = [
        f"{action.option_strings[-1]} {word}"
        for action in options(parser)
        if action.option_strings and takes_value(action) and not action.choices
        for word in metavar_words(action)
        if not METAVAR.fullmatch(word)
    ]
    assert not problems, f"{label(path)}: {problems}"


def test_a_flag_shows_the_same_metavar_in_every_command() -> None:
    """(A file suffix aside: `-o FILE.toml` and `-o FILE` are one spelling.)"""
    seen: dict[str, dict[tuple[str, ...], str]] = {}
    for path, parser in LEAVES:
        for action in options(parser):
            if action.option_strings and takes_value(action) and not action.choices:
                shown = re.sub(r"\.[a-z0-9]+", "", " ".join(metavar_words(action)))
                seen.setdefault(action.option_strings[-1], {})[shown] = label(path)
    differing = {flag: by for flag, by in seen.items() if len(by) > 1}
    assert not differing


@pytest.mark.parametrize(("path", "parser"), LEAVES, ids=[label(p) for p, _ in LEAVES])
def test_outputs_are_o_output_or_out_dir_and_need_force(
    path: tuple[str, ...], parser: argparse.ArgumentParser
) -> None:
    flags = parser._option_string_actions
    assert "--out" not in flags, f"{label(path)}: --out is spelt -o/--output or --out-dir"
    if "-o" in flags:
        assert flags["-o"].option_strings == ["-o", "--output"], label(path)
    if ("--output" in flags or "--out-dir" in flags) and path not in NO_FORCE:
        assert "--force" in flags, f"{label(path)} writes files but has no --force"


def test_ctrl_c_during_an_import_says_what_was_committed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "takes"
    folder.mkdir()
    (folder / "a_broken.bvh").write_text("HIERARCHY\n")
    for name in ("b_good", "c_interrupted"):
        (folder / f"{name}.bvh").write_text(make_humanoid("cmu-max", frames=20).text)
    read = batch._load_take

    def interrupted(path, options):  # Ctrl-C while the third file is read
        if path.name.startswith("c_"):
            raise KeyboardInterrupt
        return read(path, options)

    monkeypatch.setattr(batch, "_load_take", interrupted)
    assert main(["db", "init", str(tmp_path / "store")]) == 0
    capsys.readouterr()
    assert main(["db", "import", str(tmp_path / "store"), str(folder), "--no-progress"]) == 130
    err = capsys.readouterr().err
    # b_good is committed before the Ctrl-C only if reading it took over a second
    # (the commit timer): the line must say which, and the store must agree
    done = re.fullmatch(
        r"samba: interrupted: (\d) of 3 files done, (\d) of them added and committed; the "
        r"store holds those, the rest was not imported\n",
        err,
    )
    assert done is not None, err
    assert (done[1], done[2]) in {("1", "0"), ("2", "1")}
    assert len(PoseStore.open(tmp_path / "store").takes) == int(done[2])
