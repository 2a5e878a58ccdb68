"""The command examples of the README and the manual, read from their Markdown.

A fenced code block (no language, or bash / sh / shell / console; indented in a list
item or not) is an example when a `samba` command is in it. Two styles:

- prompt style: lines starting with `$ ` are commands (a line ending in a backslash
  goes on in the next line); the lines after a command, up to the next `$ `, are its
  output as the page shows it;
- script style (no `$ ` line): a bash block, or one whose every line is a command
  (`samba ...`, `python ...`, `NAME=value`) or goes on from one; nothing is shown.

`Command.status` is the exit status the page says: 1 when its output shows a `samba:
error:` line, 2 for a usage error, else 0; `Command.errors` are the error lines shown.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

SHELL_LANGUAGES = ("", "bash", "sh", "shell", "console")
_SCRIPT_LINE = re.compile(r"^(samba |python |[A-Za-z_][A-Za-z0-9_]*=)")


@dataclass(frozen=True)
class Command:
    """One command of a page: its shell `text` (continuations joined), the Markdown
    `line` it starts on, and the `output` lines the page shows after it."""

    text: str
    line: int
    output: tuple[str, ...] = ()

    @property
    def status(self) -> int:
        """The exit status the page shows: 1 after a `samba: error:` line, 2 after a usage
        line, else 0."""
        if any(line.startswith("samba: error:") for line in self.output):
            return 1
        if any(line.startswith("usage: samba") for line in self.output):
            return 2
        return 0

    @property
    def errors(self) -> tuple[str, ...]:
        """The `samba: error:` lines the page shows, each as the command must print it."""
        return tuple(line.strip() for line in self.output if line.startswith("samba: error:"))

    @property
    def is_samba(self) -> bool:
        """Whether the command runs `samba`."""
        return re.match(r"^samba\b", self.text) is not None


@dataclass(frozen=True)
class Block:
    """The commands of one fenced block of `page`, in order; `line` is the fence's line."""

    page: str
    line: int
    commands: tuple[Command, ...]

    @property
    def name(self) -> str:
        """`page:line`, for messages."""
        return f"{self.page}:{self.line}"


def page_blocks(path: Path, page: str) -> list[Block]:
    """The example blocks (with a `samba` command) of the Markdown file `path`, named
    `page` in messages, in page order."""
    blocks, lines = [], path.read_text().splitlines()
    i = 0
    while i < len(lines):
        fence = lines[i].strip()
        if not fence.startswith("```"):
            i += 1
            continue
        start, language = i + 1, fence[3:].strip()
        end = next((j for j in range(start, len(lines)) if lines[j].strip() == "```"), len(lines))
        indent = len(lines[i]) - len(lines[i].lstrip())  # a block in a list item
        if language in SHELL_LANGUAGES:
            body = [ln[indent:] if not ln[:indent].strip() else ln for ln in lines[start:end]]
            commands = _commands(body, start + 1, language)
            if any(c.is_samba for c in commands):
                blocks.append(Block(page, i + 1, tuple(commands)))
        i = end + 1
    return blocks


def _commands(body: list[str], first_line: int, language: str) -> list[Command]:
    """The commands of a block's lines `body`, the first being Markdown line `first_line`."""
    if any(line.startswith("$ ") for line in body):
        return _prompted(body, first_line)
    joined = _joined([(first_line + k, line) for k, line in enumerate(body)])
    if language in ("bash", "sh", "shell") or all(_SCRIPT_LINE.match(text) for _, text in joined):
        return [Command(_without_comment(text), number) for number, text in joined]
    return []


def _prompted(body: list[str], first_line: int) -> list[Command]:
    commands: list[Command] = []
    k = 0
    while k < len(body):
        if not body[k].startswith("$ "):
            k += 1
            continue
        number, text = first_line + k, body[k][2:]
        while text.rstrip().endswith("\\") and k + 1 < len(body):
            k += 1
            text = text.rstrip()[:-1].rstrip() + " " + body[k].strip()
        k += 1
        output = []
        while k < len(body) and not body[k].startswith("$ "):
            output.append(body[k])
            k += 1
        commands.append(Command(text.strip(), number, tuple(output)))
    return commands


def _joined(numbered: list[tuple[int, str]]) -> list[tuple[int, str]]:
    """Non-empty, non-comment lines with their continuations joined, each with the line
    number it starts on."""
    joined: list[tuple[int, str]] = []
    going_on = False
    for number, line in numbered:
        text = line.strip()
        if going_on:
            previous_number, previous = joined[-1]
            joined[-1] = (previous_number, previous[:-1].rstrip() + " " + text)
        elif text and not text.startswith("#"):
            joined.append((number, text))
        going_on = bool(joined) and joined[-1][1].endswith("\\")
    return joined


def _without_comment(text: str) -> str:
    """`text` without a trailing `  # comment`."""
    return re.sub(r"\s+#\s.*$", "", text)
