"""Takes by name or by `#id` (issue 41, item 5): `samba db rm`, `show`, `label`, `query
--pose` and `samba export --db` read a bare number as a name, an id as `#3`; a number
that names no take but is an id says how to write the id."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from store_fixtures import make_take

from samba.cli import main
from samba.db.store import PoseStore


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """`samba argv...` in-process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def numbered(tmp_path: Path) -> Path:
    """A store of takes #1 'a', #2 'b', #3 '1' (a take named with digits)."""
    store = PoseStore.create(tmp_path / "db")
    for seed, name in enumerate(("a", "b", "1")):
        store.add(make_take(name, 20, seed=seed))
    return store.path


def test_rm_of_a_bare_number_removes_the_take_of_that_name(
    numbered: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run(capsys, "db", "rm", str(numbered), "1")
    assert code == 0 and out.startswith("removed takes #3;")
    assert [(t.id, t.name) for t in PoseStore.open(numbered).takes] == [(1, "a"), (2, "b")]


def test_an_id_is_written_with_a_hash(
    numbered: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run(capsys, "db", "show", str(numbered), "#3", "--json")
    assert code == 0 and json.loads(out)["name"] == "1"
    code, out, _ = run(capsys, "db", "label", str(numbered), "#2", "--action", "run")
    assert code == 0 and out.startswith("take #2 b: ")
    assert run(capsys, "db", "query", str(numbered), "--pose", "#1:4", "-k", "1")[0] == 0
    exported = tmp_path / "b.bvh"
    assert run(capsys, "export", "#2", "--db", str(numbered), "-o", str(exported))[0] == 0
    assert exported.is_file()
    code, out, _ = run(capsys, "db", "rm", str(numbered), "#1")
    assert code == 0 and out.startswith("removed takes #1;")
    code, out, _ = run(capsys, "db", "ls", str(numbered))
    assert [" ".join(line.split()[:2]) for line in out.splitlines()[1:3]] == ["#2 b", "#3 1"]


def test_a_number_that_names_no_take_says_how_to_write_an_id(
    numbered: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv in (
        ("db", "rm", str(numbered), "2"),
        ("db", "show", str(numbered), "2"),
        ("export", "2", "--db", str(numbered), "-o", str(tmp_path / "x.bvh")),
    ):
        code, out, err = run(capsys, *argv)
        assert code == 1 and out == ""
        assert err == f"samba: error: {numbered}: no take named '2' (a take id is written '#2')\n"
    assert len(PoseStore.open(numbered).takes) == 3


def test_a_name_shared_by_takes_lists_their_ids(
    numbered: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    PoseStore.open(numbered).add(make_take("a", 20, seed=9))
    code, _, err = run(capsys, "db", "rm", str(numbered), "a")
    assert code == 1 and "2 takes are named 'a' (#1, #4): name one by its id" in err
    code, _, err = run(capsys, "db", "show", str(numbered), "#9")
    assert code == 1 and "no take with id #9" in err
