"""`samba export`: BVH files and store takes to USD / glTF / BVH from the command line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import make_humanoid
from glb_edit import write_gltf
from pxr import Usd, UsdGeom

from samba.body.skeleton import Body
from samba.cli import main
from samba.db.store import PoseStore
from samba.export.bvh_writer import write_bvh
from samba.export.gltf_reader import read_glb_joint_positions
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import BONE_NAMES, HumanoidRig
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import bone_direction_errors, retarget
from samba.export.usd_reader import read_usd_joint_positions
from samba.export.usd_writer import write_usd
from samba.ingest.bvh import read_bvh
from samba.synthetic.motions import generate


@pytest.fixture(scope="module")
def bvh_takes(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two synthetic takes saved as BVH files of the humanoid rig (90 and 60 frames)."""
    folder = tmp_path_factory.mktemp("takes")
    paths = []
    for name, seconds in (("walk", 3.0), ("kick", 2.0)):
        take = generate(name, seconds=seconds, seed=7)
        path = folder / f"{name}.bvh"
        write_bvh(path, retarget(take.poses, HumanoidRig.from_body(Body.from_height(1.8)), 30))
        paths.append(path)
    return paths


def run(*argv: object) -> int:
    return main(["export", *map(str, argv)])


def test_a_bvh_file_to_each_format_opens_in_its_reader(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    walk = bvh_takes[0]
    for suffix in (".glb", ".usda", ".usdc", ".bvh"):
        out = tmp_path / f"walk{suffix}"
        assert run(walk, "-o", out) == 0
        assert f"-> {out}: 90 frames at 30 fps" in capsys.readouterr().out
    names, positions = read_glb_joint_positions(tmp_path / "walk.glb")
    assert names == BONE_NAMES and positions.shape == (90, 17, 3)
    names, usd = read_usd_joint_positions(tmp_path / "walk.usdc")
    assert usd.shape == (90, 17, 3)
    assert read_bvh(tmp_path / "walk.bvh").n_frames == 90


def test_a_store_take_with_range_and_frame_rate(tmp_path: Path) -> None:
    store = PoseStore.create(tmp_path / "db")
    take = generate("squat", seconds=4.0, seed=3)
    store.add(take, min_change=0.01)
    out = tmp_path / "squat.glb"
    assert (
        run(take.name, "--db", tmp_path / "db", "--range", "30:90", "--fps", "60", "-o", out) == 0
    )
    names, positions = read_glb_joint_positions(out)
    assert len(positions) == 119  # 60 frames at 30 fps span 59/30 s: 119 frames at 60 fps
    avatar = positions[::2][:, [names.index(n) for n in BONE_NAMES]]
    errors = bone_direction_errors(avatar, take.poses[30:90])
    assert np.percentile(errors, 99) < 2.0  # store dropped near-duplicate poses (1 cm)


def test_several_takes_go_to_a_folder_and_a_bad_one_does_not_stop_the_rest(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "broken.bvh"
    broken.write_text("HIERARCHY\nROOT Hips\n{\n")
    out = tmp_path / "out"
    assert run(*bvh_takes, broken, "--format", "bvh", "--out-dir", out) == 1
    assert sorted(p.name for p in out.iterdir()) == ["kick.bvh", "walk.bvh"]
    err = capsys.readouterr().err
    assert str(broken) in err and "1 of 3 takes failed" in err


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (["--range", "5-9"], "--range: expected A:B"),
        (["--range", "500:"], "--range: 500: selects no frames"),
        (["--avatar", "{tmp}/none.vrm"], "none.vrm: cannot read the file"),
        (["-o", "{tmp}/walk.fbx"], "walk.fbx: cannot tell the format"),
        (["--format", "glb", "-o", "{tmp}/walk.usda"], "a glb file must end in .glb"),
        (["-o", "{tmp}/missing/walk.glb"], "missing/walk.glb: its folder"),
    ],
)
def test_bad_input_is_named_and_nothing_is_left_behind(
    tmp_path: Path,
    bvh_takes: list[Path],
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    problem: str,
) -> None:
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "walk.glb")]
    assert run(bvh_takes[0], *args) == 1
    assert problem in capsys.readouterr().err
    assert not list(tmp_path.rglob("*.glb")) and not list(tmp_path.rglob("*.tmp*"))


def test_unknown_store_take_and_non_bvh_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    PoseStore.create(tmp_path / "db")
    assert run("nosuchtake", "--db", tmp_path / "db", "-o", tmp_path / "x.glb") == 1
    assert "no take named 'nosuchtake'" in capsys.readouterr().err
    assert run(tmp_path / "take.mp4", "-o", tmp_path / "x.glb") == 1
    assert "take.mp4: not a .bvh file" in capsys.readouterr().err


@pytest.mark.parametrize("avatar_name", ["small.glb", "small.gltf", "small.usda"])
def test_an_avatar_file_gives_the_take_its_proportions(
    tmp_path: Path, bvh_takes: list[Path], avatar_name: str
) -> None:
    small = HumanoidRig.from_body(Body.from_height(1.45), arm_angle_deg=45)
    avatar = tmp_path / avatar_name
    still = HumanoidMotion(small, np.tile([0.0, 0.0, 0.0, 1.0], (1, 17, 1)), small.rest[:1], 30)
    if avatar.suffix == ".usda":
        write_usd(avatar, still)
    else:
        write_glb(tmp_path / "source.glb", still)
        if avatar.suffix == ".gltf":
            write_gltf((tmp_path / "source.glb").read_bytes(), avatar, "small.bin")
        else:
            (tmp_path / "source.glb").rename(avatar)
    out = tmp_path / "walk.glb"
    assert run(bvh_takes[0], "--avatar", avatar, "-o", out) == 0
    names, positions = read_glb_joint_positions(out)
    shin = np.linalg.norm(
        positions[:, names.index("LeftFoot")] - positions[:, names.index("LeftLowerLeg")], axis=-1
    )
    np.testing.assert_allclose(shin, np.linalg.norm(small.rest[13] - small.rest[12]), atol=1e-5)


def test_a_bad_gltf_or_usd_avatar_is_one_error_line_naming_it(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    still = HumanoidMotion(
        HumanoidRig.from_body(), np.tile([0.0, 0.0, 0.0, 1.0], (1, 17, 1)), np.zeros((1, 3)), 30
    )
    write_glb(tmp_path / "source.glb", still)
    write_gltf((tmp_path / "source.glb").read_bytes(), tmp_path / "lost.gltf", "lost.bin")
    (tmp_path / "lost.bin").unlink()
    (tmp_path / "broken.gltf").write_text('{"asset": {"version": "2.0"}, "nodes": [')
    stage = Usd.Stage.CreateNew(str(tmp_path / "empty.usda"))
    UsdGeom.Xform.Define(stage, "/World")
    stage.Save()
    problems = {
        "lost.gltf": f"buffer 0: cannot read its file {tmp_path / 'lost.bin'}",
        "broken.gltf": "the file is not valid JSON",
        "empty.usda": "no UsdSkel Skeleton prim in the file",
    }
    for name, problem in problems.items():
        out = tmp_path / "walk.usda"
        assert run(bvh_takes[0], "--avatar", tmp_path / name, "-o", out) == 1
        err = capsys.readouterr().err
        assert err.startswith(f"samba: error: {tmp_path / name}: {problem}")
        assert err.count("\n") == 1 and not out.exists()


def test_skip_tpose_drops_the_leading_t_pose_frames_the_warning_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = tmp_path / "tpose.bvh"
    source.write_text(make_humanoid("cmu-max", frames=40, tpose_frames=3).text)
    assert run(source, "-o", tmp_path / "kept.bvh") == 0
    out = capsys.readouterr()
    assert "40 frames at 30 fps" in out.out and "--skip-tpose drops them" in out.err
    assert run(source, "-o", tmp_path / "dropped.bvh", "--skip-tpose") == 0
    out = capsys.readouterr()
    assert "37 frames at 30 fps" in out.out and "T-pose" not in out.err


def test_one_file_is_never_overwritten_without_force(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    victim = tmp_path / "victim.glb"
    victim.write_bytes(b"somebody's work")
    assert run(bvh_takes[0], "-o", victim) == 1
    err = capsys.readouterr().err
    assert err == f"samba: error: {victim}: already exists; --force overwrites\n"
    assert victim.read_bytes() == b"somebody's work"
    assert run(bvh_takes[0], "-o", victim, "--force") == 0
    assert read_glb_joint_positions(victim)[1].shape == (90, 17, 3)


def test_a_take_is_never_written_over_its_own_source_even_with_force(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    source = tmp_path / "self.bvh"
    source.write_bytes(bvh_takes[0].read_bytes())
    link = tmp_path / "link.bvh"
    link.symlink_to(source)
    for out in (source, link):
        assert run(source, "--format", "bvh", "-o", out, "--force") == 1
        err = capsys.readouterr().err
        assert err.startswith(f"samba: error: {out}: is an input of this command")
        assert err.count("\n") == 1
    assert source.read_bytes() == bvh_takes[0].read_bytes()


def test_several_takes_never_overwrite_files_in_the_folder_without_force(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "exports"
    folder.mkdir()
    (folder / "kick.bvh").write_text("mine")
    assert run(*bvh_takes, "--format", "bvh", "--out-dir", folder) == 1
    err = capsys.readouterr().err
    assert err == f"samba: error: {folder / 'kick.bvh'}: already exists; --force overwrites\n"
    assert sorted(p.name for p in folder.iterdir()) == ["kick.bvh"]  # nothing written
    assert run(*bvh_takes, "--format", "bvh", "--out-dir", folder, "--force") == 0
    assert read_bvh(folder / "kick.bvh").n_frames == 60


def test_several_takes_to_one_file_is_an_error(
    tmp_path: Path, bvh_takes: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert run(*bvh_takes, "-o", tmp_path / "two.glb") == 1
    err = capsys.readouterr().err
    assert err == "samba: error: --output: 2 takes cannot go to one file; give --out-dir DIR\n"
    assert not list(tmp_path.iterdir())
