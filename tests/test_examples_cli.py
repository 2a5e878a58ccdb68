"""`samba examples DIR`: the input files of the README's and docs' examples, never written
over without --force, bad folders refused in one line."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from samba.base import InputError
from samba.cameras import read_calibration
from samba.cli import main
from samba.export import load_avatar
from samba.ingest import RigError, load_bvh_take, read_bvh
from samba.service.examples import BOARD_POSES, EXAMPLE_FILES


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """`samba argv...` in-process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str, *words: str) -> None:
    assert err.startswith("samba: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, err


def test_a_folder_that_is_a_file_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "inputs"
    target.write_text("mine")
    code, out, err = run(capsys, "examples", str(target))
    assert code == 1 and out == ""
    one_line_error(err, str(target), "is a file")
    assert target.read_text() == "mine"


@pytest.mark.parametrize("existing", ["cameras.toml", "left"])
def test_existing_example_files_are_kept_without_force(
    existing: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / existing
    if path.suffix:
        path.write_text("mine")
    else:
        path.mkdir()
    code, out, err = run(capsys, "examples", str(tmp_path))
    assert code == 1 and out == ""
    one_line_error(err, str(path), "already exists", "--force")
    assert [p.name for p in tmp_path.iterdir()] == [existing]


def test_a_wrong_flag_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["examples", str(tmp_path), "--overwrite"])
    assert exit_.value.code == 2
    assert "unrecognized arguments: --overwrite" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_the_examples_are_written_then_refused_then_replaced(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "new" / "inputs"
    code, out, _ = run(capsys, "examples", str(folder))
    assert code == 0
    assert sorted(p.name for p in folder.iterdir()) == sorted(EXAMPLE_FILES)
    for name in EXAMPLE_FILES:
        assert f"wrote {folder / name} " in out
    assert "samba calibrate left middle right --board checkerboard:9x6:0.08" in out
    for camera in ("left", "middle", "right"):
        assert len(list((folder / camera).glob("frame*.jpg"))) == 1 + BOARD_POSES
    stage = read_calibration(folder / "stage.toml")
    assert [c.name for c in stage] == ["front", "left", "right", "front_left"]
    assert {c.size for c in stage} == {(640, 480)}
    for camera in stage:
        assert len(list((folder / "jacks" / camera.name).glob("*.jpg"))) == 40
    assert len(read_calibration(folder / "cameras.toml")) == 2
    studio = read_bvh(folder / "studio_walk.bvh")
    assert studio.names[0] == "joint_Root" and "UpperArm_L" in studio.names
    assert load_bvh_take(folder / "studio_walk.bvh").poses.shape[1:] == (13, 3)
    with pytest.raises(RigError, match="not a humanoid skeleton: the left leg"):
        load_bvh_take(folder / "quadruped.bvh")
    with pytest.raises(InputError, match=r"buffer 0: cannot read its file .*me\.bin"):
        load_avatar(str(folder / "me.gltf"))
    assert not (folder / "me.bin").exists()
    for key in ("cam0.key", "cam1.key"):
        assert stat.S_IMODE((folder / key).stat().st_mode) == 0o600
        assert len((folder / key).read_bytes()) == 32
    size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    assert size < 12e6

    code, _, err = run(capsys, "examples", str(folder))
    assert code == 1
    one_line_error(err, str(folder / "store"), "already exists", "--force")

    (folder / "left" / "frame00.jpg").unlink()
    code, _, _ = run(capsys, "examples", str(folder), "--force")
    assert code == 0 and (folder / "left" / "frame00.jpg").is_file()
