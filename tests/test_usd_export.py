"""USD export: UsdValidation passes the files, the joints UsdSkel poses from them follow the
motion (within 1 mm at every time code) and the capture's bone directions (within 1°), the
skinned body follows the bones, and failed writes leave nothing behind."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from export_fixtures import box_mesh, real_takes, synthetic_motion
from pxr import Gf, Usd, UsdGeom, UsdSkel

from samba.body.take import Take
from samba.export.avatar_mesh import AvatarMesh
from samba.export.errors import ExportError
from samba.export.humanoid import BONE_INDEX, N_BONES, HumanoidRig
from samba.export.mannequin import mannequin
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import bone_direction_errors, retarget
from samba.export.usd_reader import read_usd_joint_positions, usd_validation_errors
from samba.export.usd_writer import write_usd
from samba.synthetic import motions as synthetic

ROOT = Path(__file__).resolve().parents[1]
HEADERS = {".usda": b"#usda 1.0", ".usdc": b"PXR-USDC", ".usd": b"PXR-USDC"}
"""The first bytes of a text and a binary (crate) USD file."""


def assert_round_trip(path: Path, take: Take, motion: HumanoidMotion) -> None:
    """Joints posed by UsdSkel from `path` match the motion within 1 mm at every time
    code, and the captured bone directions within 1°."""
    names, positions = read_usd_joint_positions(path)
    assert names == motion.rig.names
    assert positions.shape == (len(motion), N_BONES, 3)
    error = np.linalg.norm(positions - motion.world_positions(), axis=-1)
    assert error.max() < 0.001, (take.name, error.max())
    angles = bone_direction_errors(positions, take.poses)
    assert angles.max() < 1.0, (take.name, angles.max())


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
@pytest.mark.parametrize("skinned", [True, False], ids=["skinned", "skeleton-only"])
def test_export_validates_with_its_layout_and_metadata(
    tmp_path: Path, suffix: str, skinned: bool
) -> None:
    _, motion = synthetic_motion()
    mesh = box_mesh(motion.rig) if skinned else None
    path = tmp_path / f"walk{suffix}"
    write_usd(path, motion, mesh)
    assert usd_validation_errors(path) == []
    assert path.read_bytes().startswith(HEADERS[suffix])
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == motion.fps
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, len(motion) - 1)
    assert stage.GetDefaultPrim().GetPath() == "/Avatar"
    assert stage.GetDefaultPrim().IsA(UsdSkel.Root)
    skeleton = UsdSkel.Skeleton(stage.GetPrimAtPath("/Avatar/Skel"))
    assert skeleton.GetPrim().HasAPI(UsdSkel.BindingAPI)
    binding = UsdSkel.BindingAPI(skeleton)
    assert binding.GetAnimationSourceRel().GetTargets() == ["/Avatar/Skel/Anim"]
    joints = list(skeleton.GetJointsAttr().Get())
    assert joints[7] == "Hips/Spine/Chest/LeftUpperArm/LeftLowerArm/LeftHand"
    assert list(skeleton.GetJointNamesAttr().Get()) == list(motion.rig.names)
    bind = np.asarray(skeleton.GetBindTransformsAttr().Get())
    rest = np.asarray(skeleton.GetRestTransformsAttr().Get())
    assert np.allclose(bind[:, :3, :3], np.eye(3)) and np.allclose(rest[:, :3, :3], np.eye(3))
    assert np.allclose(bind[:, 3, :3], motion.rig.rest)
    assert np.allclose(rest[:, 3, :3], motion.rig.offsets)
    animation = UsdSkel.Animation(stage.GetPrimAtPath("/Avatar/Skel/Anim"))
    assert list(animation.GetJointsAttr().Get()) == joints
    for attr in (
        animation.GetTranslationsAttr(),
        animation.GetRotationsAttr(),
        animation.GetScalesAttr(),
    ):
        assert attr.GetTimeSamples() == list(range(len(motion)))
    body = stage.GetPrimAtPath("/Avatar/Body")
    assert bool(body) == skinned
    if skinned:
        _assert_body(UsdGeom.Mesh(body), mesh)


def _assert_body(body: UsdGeom.Mesh, mesh: AvatarMesh) -> None:
    """The Mesh prim carries `mesh` bound to the skeleton."""
    assert np.array_equal(np.asarray(body.GetPointsAttr().Get()), mesh.vertices)
    assert np.array_equal(np.asarray(body.GetNormalsAttr().Get()), mesh.normals)
    assert body.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    assert set(body.GetFaceVertexCountsAttr().Get()) == {3}
    assert np.array_equal(np.asarray(body.GetFaceVertexIndicesAttr().Get()), mesh.faces.ravel())
    extent = np.asarray(body.GetExtentAttr().Get())
    assert np.array_equal(extent, [mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)])
    binding = UsdSkel.BindingAPI(body)
    assert binding.GetSkeletonRel().GetTargets() == ["/Avatar/Skel"]
    for primvar, values in (
        (binding.GetJointIndicesPrimvar(), mesh.joints),
        (binding.GetJointWeightsPrimvar(), mesh.weights),
    ):
        assert primvar.GetElementSize() == 4
        assert primvar.GetInterpolation() == UsdGeom.Tokens.vertex
        assert np.array_equal(np.asarray(primvar.Get()), values.ravel())
    assert binding.GetGeomBindTransformAttr().Get() == Gf.Matrix4d(1.0)


def test_mannequin_export_validates(tmp_path: Path) -> None:
    """Text, binary and USDZ files pass every UsdValidation validator usd-core has,
    the USDZ package validators (ARKit's compliance rules) included, and read back."""
    take, motion = synthetic_motion("wave")
    mesh = mannequin(motion.rig)
    for suffix in (".usda", ".usdc", ".usdz"):
        path = tmp_path / f"wave{suffix}"
        write_usd(path, motion, mesh)
        assert usd_validation_errors(path) == []
        assert_round_trip(path, take, motion)


def test_validation_reports_a_broken_stage(tmp_path: Path) -> None:
    # no metadata, no default prim, a skinned mesh without SkelBindingAPI
    stage = Usd.Stage.CreateNew(str(tmp_path / "broken.usda"))
    UsdSkel.Root.Define(stage, "/Avatar")
    UsdGeom.Mesh.Define(stage, "/Avatar/Body").GetPrim().CreateRelationship("skel:skeleton")
    stage.Save()
    names = {issue.split(":")[0] for issue in usd_validation_errors(tmp_path / "broken.usda")}
    assert {
        "MissingDefaultPrim",
        "MissingUpAxisMetadata",
        "MissingMetersPerUnitMetadata",
        "MissingSkelBindingAPI",
    } <= names


@pytest.mark.parametrize("motion", synthetic.MOTIONS)
def test_synthetic_takes_round_trip(tmp_path: Path, motion: str) -> None:
    take, humanoid = synthetic_motion(motion)
    for suffix in (".usda", ".usdc"):
        path = tmp_path / f"{motion}{suffix}"
        write_usd(path, humanoid, box_mesh(humanoid.rig))
        assert_round_trip(path, take, humanoid)


def test_single_frame_and_usd_suffix_round_trip(tmp_path: Path) -> None:
    take, motion = synthetic_motion("kick")
    first = Take(take.name, take.poses[:1], take.fps)
    path = tmp_path / "kick.USD"
    write_usd(path, motion.frames(0, 1))
    assert path.read_bytes().startswith(HEADERS[".usd"])
    assert usd_validation_errors(path) == []
    assert_round_trip(path, first, motion.frames(0, 1))


def test_real_takes_round_trip(tmp_path: Path, cmu_dir: Path) -> None:
    rig = HumanoidRig.from_body()
    for take in real_takes(cmu_dir):
        path = tmp_path / f"{take.name}.usdc"
        motion = retarget(take.poses, rig, take.fps)
        write_usd(path, motion, box_mesh(rig))
        assert usd_validation_errors(path) == []
        assert_round_trip(path, take, motion)


def test_skinned_points_follow_the_bones(tmp_path: Path) -> None:
    _, motion = synthetic_motion("wave")
    mesh = box_mesh(motion.rig)
    path = tmp_path / "wave.usdc"
    write_usd(path, motion, mesh)
    stage = Usd.Stage.Open(str(path))
    root = UsdSkel.Root(stage.GetPrimAtPath("/Avatar"))
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    (target,) = binding.GetSkinningTargets()
    query = cache.GetSkelQuery(binding.GetSkeleton())
    world = motion.world_matrices()
    joints = motion.world_positions()
    hand = BONE_INDEX["LeftHand"]
    rigid_hand = (mesh.joints[:, 0] == hand) & (mesh.weights[:, 0] == 1.0)
    assert rigid_hand.sum() >= 4
    for frame in (0, 37, len(motion) - 1):
        points = UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get(frame)
        skinning = query.ComputeSkinningTransforms(frame)
        assert target.ComputeSkinnedPoints(skinning, points, frame)
        skinned = np.asarray(points)
        # linear blend skinning: each bone carries the vertex rigidly from its rest joint
        local = mesh.vertices[:, None, :] - motion.rig.rest[mesh.joints]
        moved = np.einsum("vkij,vkj->vki", world[frame][mesh.joints], local)
        moved += joints[frame][mesh.joints]
        expected = np.einsum("vk,vki->vi", mesh.weights, moved)
        assert np.abs(skinned - expected).max() < 1e-5
        hand_local = mesh.vertices[rigid_hand] - motion.rig.rest[hand]
        hand_now = (skinned[rigid_hand] - joints[frame, hand]) @ world[frame, hand]
        assert np.abs(hand_now - hand_local).max() < 1e-5
    assert np.abs(skinned[rigid_hand] - mesh.vertices[rigid_hand]).max() > 0.05


@pytest.mark.parametrize("name", ["take.usdzz", "take.glb", "take.txt", "take"])
def test_unsupported_suffix_raises_and_writes_nothing(tmp_path: Path, name: str) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    path = tmp_path / name
    with pytest.raises(ExportError, match="unsupported file type") as raised:
        write_usd(path, motion)
    assert raised.value.source == str(path)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("kind", ["missing folder", "directory", "permission denied"])
def test_unwritable_path_raises_and_leaves_no_file(tmp_path: Path, kind: str) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    folder = tmp_path / "out.usda" if kind == "directory" else tmp_path / "out"
    if kind == "missing folder":
        path = folder / "take.usda"
    elif kind == "directory":
        path = folder
        folder.mkdir()
    else:
        if os.geteuid() == 0:
            pytest.skip("root may write into a read-only folder")
        folder.mkdir(mode=0o500)
        path = folder / "take.usda"
    with pytest.raises(ExportError, match="cannot write the file") as raised:
        write_usd(path, motion)
    assert raised.value.source == str(path)
    assert path.is_dir() if kind == "directory" else not path.exists()
    assert [p.name for p in tmp_path.rglob("*")] == ([folder.name] if folder.exists() else [])


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_failure_midway_leaves_existing_file_untouched(tmp_path: Path, suffix: str) -> None:
    pytest.importorskip("resource", reason="file size limits need a POSIX system")
    path = tmp_path / f"take{suffix}"
    path.write_bytes(b"the previous export")
    # a child process whose files may not grow past 16 kB: USD's own writer fails midway
    script = textwrap.dedent(
        f"""
        import resource, signal, sys
        from test_gltf_export import synthetic_motion
        from samba.export.errors import ExportError
        from samba.export.usd_writer import write_usd

        _, motion = synthetic_motion()
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384))
        try:
            write_usd({str(path)!r}, motion)
        except ExportError as exc:
            print(exc)
            sys.exit(0)
        sys.exit("the write did not fail")
        """
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, check=False
    )
    assert done.returncode == 0, done.stderr
    assert f"{path}: cannot write the file" in done.stdout
    assert "File too large" in done.stdout
    assert path.read_bytes() == b"the previous export"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def _hand_made_skeleton(
    path: Path, joints: list[str], root: bool = True, rest: bool = True, animated: int = 0
) -> None:
    """A stage with a Skeleton (under a SkelRoot if `root`) whose joints sit 1 m above
    their parents at rest (restTransforms authored if `rest`), animated at time 0 by an
    animation of its first `animated` joints (none if 0)."""
    stage = Usd.Stage.CreateNew(str(path))
    if root:
        UsdSkel.Root.Define(stage, "/Root")
    skeleton = UsdSkel.Skeleton.Define(stage, "/Root/Skel" if root else "/Skel")
    skeleton.CreateJointsAttr(joints)
    up = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(0.0, 1.0, 0.0))
    skeleton.CreateBindTransformsAttr([up] * len(joints))
    if rest:
        skeleton.CreateRestTransformsAttr([up] * len(joints))
    if animated:
        animation = UsdSkel.Animation.Define(stage, skeleton.GetPath().AppendChild("Anim"))
        animation.CreateJointsAttr(joints[:animated])
        animation.CreateTranslationsAttr().Set([Gf.Vec3f(0.0, 2.0, 0.0)] * animated, 0)
        animation.CreateRotationsAttr().Set([Gf.Quatf(1.0)] * animated, 0)
        animation.CreateScalesAttr().Set([Gf.Vec3h(1.0, 1.0, 1.0)] * animated, 0)
        binding = UsdSkel.BindingAPI.Apply(skeleton.GetPrim())
        binding.CreateAnimationSourceRel().SetTargets([animation.GetPath()])
    stage.Save()


def test_reader_poses_a_skeleton_without_animation_at_rest(tmp_path: Path) -> None:
    path = tmp_path / "rest.usda"
    _hand_made_skeleton(path, ["a", "a/b", "a/b/c"])
    names, positions = read_usd_joint_positions(path)
    assert names == ("a", "b", "c")
    assert np.allclose(positions, [[[0.0, 1.0, 0.0], [0.0, 2.0, 0.0], [0.0, 3.0, 0.0]]])


def test_reader_rejects_unreadable_and_non_skeletal_files(tmp_path: Path) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    good = tmp_path / "good.usdc"
    write_usd(good, motion)
    plain = Usd.Stage.CreateNew(str(tmp_path / "plain.usda"))
    UsdGeom.Xform.Define(plain, "/World")
    plain.Save()
    _hand_made_skeleton(tmp_path / "loose.usda", ["a", "a/b"], root=False)
    _hand_made_skeleton(tmp_path / "misordered.usda", ["a/b", "a"])
    _hand_made_skeleton(tmp_path / "sparse.usda", ["a", "a/b"], rest=False, animated=1)
    (tmp_path / "text.usda").write_text("Hips 0 0 0\n")
    (tmp_path / "truncated.usdc").write_bytes(good.read_bytes()[:100])
    problems = {
        "missing.usda": "no such file",
        "text.usda": "cannot read the file as USD",
        "truncated.usdc": "cannot read the file as USD",
        "plain.usda": "no UsdSkel Skeleton",
        "loose.usda": "not under a SkelRoot",
        "misordered.usda": "invalid or has no joints",
        "sparse.usda": "cannot pose",
    }
    for name, problem in problems.items():
        path = tmp_path / name
        with pytest.raises(ExportError, match=problem) as raised:
            read_usd_joint_positions(path)
        assert raised.value.source == str(path)
    with pytest.raises(ExportError, match="cannot read") as raised:
        usd_validation_errors(tmp_path / "text.usda")
    assert raised.value.source == str(tmp_path / "text.usda")


def test_a_motion_at_a_rate_a_hair_off_a_whole_number_is_written_at_that_number(
    tmp_path: Path,
) -> None:
    """A take read at 59.9988 fps (BVH frame time 0.0166670) is written with 60 time codes
    per second, the rate it stands for."""
    _, motion = synthetic_motion(seconds=1.0)
    odd = HumanoidMotion(motion.rig, motion.rotations, motion.root, 1 / 0.016667)
    assert odd.fps == 60.0
    path = tmp_path / "odd.usda"
    write_usd(path, odd, box_mesh(odd.rig))
    assert Usd.Stage.Open(str(path)).GetTimeCodesPerSecond() == 60.0
