"""What a pose store accepts (issue 41, item 1): one check (`samba.db.take_problems`) runs
before anything is committed and in `samba db verify`; a take outside it is refused alone,
the store stays usable, `verify` finds what an import would refuse and names the `db rm`
that removes it; `samba export` refuses an absurd frame rate or frame count in one line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import humanoid_bvh
from store_fixtures import make_take, snapshot_files
from take_file_fixtures import walk_take_file

from samba.body.take import Take
from samba.cli import main
from samba.db import store as store_module
from samba.db.errors import StoreError
from samba.db.store import PoseStore


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """`samba argv...` in-process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def query_pose(store: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """`samba db query STORE` for the markers of the walk's first pose."""
    return run(capsys, "db", "query", str(store), "--pose", "walk:0", "-k", "1")


@pytest.mark.parametrize("far", [1e30, 5e4])
def test_a_take_with_a_joint_far_out_is_refused_alone_and_the_store_stays_usable(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], far: float
) -> None:
    store = tmp_path / "db"
    walk = walk_take_file(tmp_path / "walk.mcap")
    bad = walk_take_file(tmp_path / "bad.mcap", far=far)
    assert run(capsys, "db", "init", str(store))[0] == 0
    code, out, err = run(capsys, "db", "import", str(store), str(bad), str(walk), "--no-progress")
    assert code == 1
    assert "1 added, 0 already stored, 1 failed" in out
    (error,) = err.splitlines()
    assert re.search(r"bad\.mcap: 1 joint coordinate NaN, infinite or beyond 10000 m", error)
    assert [t.name for t in PoseStore.open(store).takes] == ["walk"]
    assert query_pose(store, capsys)[0] == 0
    code, out, _ = run(capsys, "db", "verify", str(store))
    assert code == 0 and "ok (1 takes, 30 poses)" in out


def test_verify_finds_what_import_refuses_and_names_the_rm_that_removes_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A take stored before the check existed (here: with the check switched off)."""
    store = tmp_path / "db"
    PoseStore.create(store).add(make_take("walk", 30, seed=1), mirror=True)
    far = make_take("far one", 30, seed=2)
    far.poses[5, 3, 0] = 5e4
    monkeypatch.setattr(store_module, "check_addable", lambda take: None)
    PoseStore.open(store).add(far, mirror=True, build_index=False)
    monkeypatch.undo()

    code, out, _ = run(capsys, "db", "verify", str(store))
    assert code == 1 and f"{store}: DAMAGED (4 takes, 120 poses)" in out
    rm = f"samba db rm {store} 'far one'"
    problems = [line for line in out.splitlines() if line.startswith("problem:")]
    assert len(problems) == 2  # the take and its mirror, both removed by the one command
    for problem in problems:
        assert "import refuses it: 1 joint coordinate" in problem and f"`{rm}`" in problem
    code, _, err = query_pose(store, capsys)  # searching the store names the cure too
    assert code == 1 and "in take 3 ('far one'), 4 ('far one (mirrored)')" in err
    assert f"remove with `{rm}`" in err

    assert run(capsys, "db", "rm", str(store), "far one")[0] == 0
    assert run(capsys, "db", "verify", str(store))[0] == 0
    assert query_pose(store, capsys)[0] == 0


@pytest.mark.parametrize("fps", ["1e-300", "0.5", "5000", "nan"])
def test_a_take_file_frame_rate_outside_1_to_1000_fps_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], fps: str
) -> None:
    store = tmp_path / "db"
    PoseStore.create(store)
    take = walk_take_file(tmp_path / "odd.mcap", fps=fps)
    code, out, err = run(capsys, "db", "import", str(store), str(take), "--no-progress")
    assert code == 1 and "0 added, 0 already stored, 1 failed" in out
    rate = f"frame rate {float(fps):g} fps is outside 1-1000 fps"
    assert err == f"samba: error: {take}: take metadata: {rate}\n"
    code, _, err = run(capsys, "export", str(take), "-o", str(tmp_path / "odd.bvh"))
    assert code == 1 and "outside 1-1000 fps" in err and "Traceback" not in err


@pytest.mark.parametrize("fps", [0.5, 1001.0])
def test_the_store_and_the_import_flag_refuse_frame_rates_outside_1_to_1000_fps(
    store: PoseStore, path: Path, capsys: pytest.CaptureFixture[str], fps: float
) -> None:
    before = snapshot_files(path)
    with pytest.raises(StoreError, match=f"frame rate {fps:g} fps is outside 1-1000 fps"):
        store.add(make_take("slow", 20, seed=7, fps=fps))
    code, _, err = run(capsys, "db", "import", str(path), "x.bvh", "--fps", str(fps))
    assert code == 1 and f"frame rate {fps:g} fps is outside 1-1000 fps" in err
    assert snapshot_files(path) == before


def test_a_skeleton_of_zero_offsets_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "db"
    PoseStore.create(store)
    zero = tmp_path / "zero.bvh"
    zero.write_text(re.sub(r"OFFSET\s+\S+\s+\S+\s+\S+", "OFFSET 0 0 0", humanoid_bvh()))
    code, _, err = run(capsys, "db", "import", str(store), str(zero), "--no-progress")
    assert code == 1
    assert "the left upper arm is 0.000 m long (median over the take), outside 0.02-2 m" in err
    assert PoseStore.open(store).takes == []


def test_a_take_of_more_frames_than_the_limit_is_refused(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("samba.db.take_checks.MAX_TAKE_FRAMES", 25)
    before = snapshot_files(path)
    with pytest.raises(StoreError, match="26 frames, more than the limit of 25 a take"):
        store.add(make_take("long", 26, seed=7))
    assert snapshot_files(path) == before
    assert store.add(make_take("short", 25, seed=8)).take_ids == (4,)


def test_export_refuses_an_absurd_frame_rate_or_frame_count_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    store = tmp_path / "db"
    PoseStore.create(store).add(make_take("walk", 30, seed=1))
    out = tmp_path / "walk.bvh"
    for fps in ("1e-300", "5000"):
        code, _, err = run(
            capsys, "export", "walk", "--db", str(store), "-o", str(out), "--fps", fps
        )
        assert code == 1 and not out.exists()
        assert err == (
            f"samba: error: --fps: {float(fps):g} fps for a take of 30 frames at 30 fps: "
            f"frame rate {float(fps):g} fps is outside 1-1000 fps\n"
        )
    monkeypatch.setattr("samba.db.take_checks.MAX_TAKE_FRAMES", 500)  # 30 frames at 30 fps to 1000
    code, _, err = run(
        capsys, "export", "walk", "--db", str(store), "-o", str(out), "--fps", "1000"
    )
    assert code == 1 and not out.exists()
    assert (
        err.endswith("967 frames, more than the limit of 500 a take\n")
        and len(err.splitlines()) == 1
    )


def test_a_stored_take_with_frames_far_apart_is_refused_by_export(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Frame numbers that would fill more frames than a take may hold between two poses (a
    catalog from another tool, or damage) are refused before anything is interpolated."""
    monkeypatch.setattr("samba.db.take_checks.MAX_TAKE_FRAMES", 1000)
    store = PoseStore.create(tmp_path / "db")
    poses = make_take("gap", 2, seed=3).poses
    store.add(Take("gap", poses, 30.0, frames=np.array([0, 3000]), content_hash="g"))
    argv = ["export", "gap", "--db", str(store.path), "-o", str(tmp_path / "g.bvh")]
    code, _, err = run(capsys, *argv)
    assert code == 1
    assert err == (
        "samba: error: gap: its frames 0-3000 played whole: 3,001 frames, "
        "more than the limit of 1,000 a take\n"
    )
