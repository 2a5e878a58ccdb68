"""BVH export: our reader, bvhio and our importer read the files back to the motion's joints
(within 1 mm) and the capture's bone directions (within 1°); bad input fails cleanly."""

from __future__ import annotations

import errno
import hashlib
import os
from pathlib import Path

import bvhio
import numpy as np
import pytest
from export_fixtures import real_takes, synthetic_motion
from scipy.spatial.transform import Rotation

from samba.body.take import Take
from samba.export.bvh_writer import UNITS, BvhSkeleton, euler_zxy, write_bvh, write_bvh_motion
from samba.export.errors import ExportError
from samba.export.humanoid import CAPTURE_JOINT, N_BONES, TIP_BONES, HumanoidRig
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import bone_direction_errors, retarget
from samba.ingest.bvh import read_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take

SYNTHETIC = ("walk", "kick", "turn", "jumping_jacks")
UNIT = pytest.mark.parametrize("unit", list(UNITS))
BONE_OF_JOINT = [next(b for b, j in CAPTURE_JOINT.items() if j == i) for i in range(13)]
"""The humanoid bone at each of the 13 capture joints."""


def real_motions(cmu_dir: Path) -> list[tuple[Take, HumanoidMotion]]:
    """The first take of each rig family in the shared CMU data, retargeted."""
    return [
        (take, retarget(take.poses, HumanoidRig.from_body(), take.fps))
        for take in real_takes(cmu_dir)
    ]


def read_back(path: Path, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """Joint (n, 17, 3) and End Site (n, 5, 3) world positions in meters, by our reader."""
    bvh = read_bvh(path)
    rig = HumanoidRig.from_body()
    joints = [bvh.names.index(name) for name in rig.names]
    tips = [bvh.names.index(f"{rig.names[b]}_end") for b in TIP_BONES]
    positions = bvh.positions(joints + tips) / UNITS[unit]
    return positions[:, :N_BONES], positions[:, N_BONES:]


def assert_round_trip(path: Path, unit: str, take: Take, motion: HumanoidMotion) -> None:
    """Our reader gets the motion's joints and tips back within 1 mm at every frame, and the
    captured bone directions within 1°."""
    joints, tips = read_back(path, unit)
    assert joints.shape == (len(motion), N_BONES, 3)
    error = np.linalg.norm(joints - motion.world_positions(), axis=-1)
    assert error.max() < 0.001, (take.name, unit, error.max())
    tip_error = np.linalg.norm(tips - motion.tip_positions(), axis=-1)
    assert tip_error.max() < 0.001, (take.name, unit, tip_error.max())
    angles = bone_direction_errors(joints, take.poses)
    assert angles.max() < 1.0, (take.name, unit, angles.max())


def assert_bvhio_agrees(path: Path, unit: str, motion: HumanoidMotion) -> None:
    """bvhio reads as many frames and, on the first, middle and last, the same joints."""
    root = bvhio.readAsHierarchy(str(path))
    assert len(root.Keyframes) == len(motion)
    expected = motion.world_positions() * UNITS[unit]
    for frame in sorted({0, len(motion) // 2, len(motion) - 1}):
        root.loadPose(frame)
        layout = root.layout()
        assert [joint.Name for joint, _, _ in layout] == list(motion.rig.names)
        got = np.array([list(joint.PositionWorld) for joint, _, _ in layout])
        error = np.linalg.norm(got - expected[frame], axis=-1) / UNITS[unit]
        assert error.max() < 0.001, (path.name, frame, error.max())


def assert_imports_as_take(path: Path, unit: str, motion: HumanoidMotion) -> None:
    """Our importer detects the humanoid rig and gets the 13 joints back (up to the floor
    height it chooses) within 1 mm, in the right unit, upright and not mirrored."""
    take = load_bvh_take(path, BvhImportOptions(fps=None))
    assert take.rig == "humanoid"
    assert take.meta["units"] == unit
    assert take.meta["up"] == "+y"
    assert take.meta["handedness"] == "right"
    assert take.fps == pytest.approx(motion.fps, rel=1e-6)
    offset = take.poses - motion.world_positions()[:, BONE_OF_JOINT]
    floor = np.median(offset[..., 1])
    assert np.abs(offset - [0.0, floor, 0.0]).max() < 0.001


@UNIT
@pytest.mark.parametrize("name", SYNTHETIC)
def test_synthetic_takes_round_trip(tmp_path: Path, name: str, unit: str) -> None:
    take, motion = synthetic_motion(name, seed=5)
    path = tmp_path / f"{name}.bvh"
    write_bvh(path, motion, unit)
    assert_round_trip(path, unit, take, motion)
    assert_bvhio_agrees(path, unit, motion)
    assert_imports_as_take(path, unit, motion)


@UNIT
def test_real_takes_round_trip(tmp_path: Path, cmu_dir: Path, unit: str) -> None:
    for take, motion in real_motions(cmu_dir):
        path = tmp_path / f"{take.name}.bvh"
        write_bvh(path, motion, unit)
        assert_round_trip(path, unit, take, motion)
        assert_bvhio_agrees(path, unit, motion)
        assert_imports_as_take(path, unit, motion)


def test_file_layout(tmp_path: Path) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.5)
    path = tmp_path / "walk.bvh"
    write_bvh(path, motion, "cm")
    text = path.read_text()
    bvh = read_bvh(path)
    hips = bvh.joints[0]
    assert (hips.name, hips.parent, hips.offset.tolist()) == ("Hips", -1, [0.0, 0.0, 0.0])
    assert hips.channels == (
        "Xposition",
        "Yposition",
        "Zposition",
        "Zrotation",
        "Xrotation",
        "Yrotation",
    )
    joints = [j for j in bvh.joints if not j.end_site]
    assert [j.name for j in joints] == list(motion.rig.names)
    assert all(j.channels == ("Zrotation", "Xrotation", "Yrotation") for j in joints[1:])
    offsets = np.array([j.offset for j in joints[1:]])
    np.testing.assert_allclose(offsets, motion.rig.offsets[1:] * 100, atol=5e-7)
    ends = [j for j in bvh.joints if j.end_site]
    assert [bvh.joints[j.parent].name for j in ends] == [motion.rig.names[b] for b in TIP_BONES]
    np.testing.assert_allclose([j.offset for j in ends], motion.rig.tips * 100, atol=5e-7)
    np.testing.assert_allclose(bvh.motion[:, :3], motion.root * 100, atol=5e-7)
    assert bvh.n_frames == len(motion)
    assert "-0.000000" not in text
    assert text.endswith("\n")


@pytest.mark.parametrize("fps", [24.0, 29.97, 30.0, 60.0, 120.0])
def test_frame_time_keeps_the_frame_rate(tmp_path: Path, fps: float) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.2)
    path = tmp_path / "take.bvh"
    write_bvh(path, HumanoidMotion(motion.rig, motion.rotations, motion.root, fps), "m")
    assert read_bvh(path).fps == pytest.approx(fps, rel=1e-6)
    assert len(bvhio.readAsHierarchy(str(path)).Keyframes) == len(motion)


def test_euler_angles_are_exact_and_continuous_through_gimbal_lock() -> None:
    """A sweep of X through 90° (where the principal angles flip Z and Y by 180°) and a
    spin about Y over several turns come back as the angles they were made of."""
    t = np.linspace(0.0, 1.0, 200)
    sweep = np.stack([20 + 40 * t, 60 + 60 * t, -30 + 50 * t], axis=-1)
    spin = np.stack([10 * np.sin(6 * t), 5 * np.cos(4 * t), 1500 * t], axis=-1)
    angles = np.stack([sweep, spin], axis=1)
    rotations = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True)
    quaternions = rotations.as_quat().reshape(len(t), 2, 4)
    out = euler_zxy(quaternions)
    rebuilt = Rotation.from_euler("ZXY", out.reshape(-1, 3), degrees=True)
    assert np.allclose(rebuilt.as_matrix(), rotations.as_matrix(), atol=1e-12)
    assert np.allclose(out, angles, atol=1e-9)


def test_exported_angles_rebuild_the_local_rotations() -> None:
    _, motion = synthetic_motion("jumping_jacks", seed=5)
    angles = euler_zxy(motion.rotations)
    rebuilt = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True)
    local = Rotation.from_quat(motion.rotations.reshape(-1, 4))
    assert np.allclose(rebuilt.as_matrix(), local.as_matrix(), atol=1e-12)
    assert np.abs(np.diff(angles, axis=0)).max() < 90.0


def test_bad_unit_is_refused_before_writing(tmp_path: Path) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.1)
    path = tmp_path / "take.bvh"
    path.write_text("the previous export")
    with pytest.raises(ValueError, match="--unit must be one of m, cm, got 'mm'"):
        write_bvh(path, motion, "mm")
    assert path.read_text() == "the previous export"
    assert [p.name for p in tmp_path.iterdir()] == ["take.bvh"]


@pytest.mark.parametrize("kind", ["missing folder", "directory", "permission denied"])
def test_unwritable_path_raises_and_leaves_no_file(tmp_path: Path, kind: str) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.1)
    folder = tmp_path / "out"
    if kind == "missing folder":
        path = folder / "take.bvh"
    elif kind == "directory":
        path = folder
        folder.mkdir()
    else:
        if os.geteuid() == 0:
            pytest.skip("root may write into a read-only folder")
        folder.mkdir(mode=0o500)
        path = folder / "take.bvh"
    with pytest.raises(ExportError, match="cannot write the file") as raised:
        write_bvh(path, motion)
    assert raised.value.source == str(path)
    assert path.is_dir() if kind == "directory" else not path.exists()
    assert sorted(p.name for p in tmp_path.rglob("*")) == (["out"] if folder.exists() else [])


def test_failure_midway_leaves_existing_file_untouched(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.1)
    path = tmp_path / "take.bvh"
    path.write_text("the previous export")
    real_write = Path.write_bytes

    def disk_full(self: Path, data: bytes) -> int:
        real_write(self, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_bytes", disk_full)
    with pytest.raises(ExportError, match="No space left"):
        write_bvh(path, motion)
    assert path.read_text() == "the previous export"
    assert [p.name for p in tmp_path.iterdir()] == ["take.bvh"]


BRANCHES = BvhSkeleton(
    names=("pelvis", "tail1", "legL1", "legR1", "tail2", "legL2", "legR2", "tail3", "legL3"),
    parents=(-1, 0, 0, 0, 1, 2, 3, 4, 5),
    offsets=np.array(
        [
            [5.0, 5.0, 5.0],  # the root's offset is ignored
            [0.0, 0.1, -0.3],
            [0.12, -0.05, 0.2],
            [-0.12, -0.05, 0.2],
            [0.0, 0.02, -0.25],
            [0.03, -0.35, 0.01],
            [-0.03, -0.35, 0.01],
            [0.01, -0.04, -0.2],
            [0.0, -0.3, 0.06],
        ]
    ),
    end_sites={7: np.array([0.0, 0.0, -0.15]), 8: np.array([0.0, -0.02, 0.1])},
)
"""A quadruped-like tree of three branches from the root (tail, left leg, right leg) whose
joint indices interleave the branches, so declaration order differs from index order;
the right leg ends without an End Site."""


def scipy_forward_kinematics(
    skeleton: BvhSkeleton, rotations: np.ndarray, root: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World positions in meters of the joints (n, J, 3) and of the End Sites (n, E, 3),
    in `end_sites` order, of local quaternions (n, J, 4) and root positions (n, 3)."""
    world: list[Rotation] = []
    joints = np.empty((len(root), len(skeleton.names), 3))
    for joint, parent in enumerate(skeleton.parents):
        local = Rotation.from_quat(rotations[:, joint])
        if parent < 0:
            world.append(local)
            joints[:, joint] = root
        else:
            world.append(world[parent] * local)
            joints[:, joint] = joints[:, parent] + world[parent].apply(skeleton.offsets[joint])
    ends = [joints[:, j] + world[j].apply(end) for j, end in skeleton.end_sites.items()]
    return joints, np.stack(ends, axis=1)


@UNIT
def test_any_tree_skeleton_round_trips_through_our_reader(tmp_path: Path, unit: str) -> None:
    rng = np.random.default_rng(7)
    n = 40
    rotations = rng.normal(size=(n, len(BRANCHES.names), 4))  # any norm: normalised
    root = rng.normal(scale=0.5, size=(n, 3))
    path = tmp_path / "branches.bvh"
    write_bvh_motion(path, BRANCHES, rotations, root, 30.0, unit)
    bvh = read_bvh(path)
    joints = [j for j in bvh.joints if not j.end_site]
    assert [j.name for j in joints] == [BRANCHES.names[i] for i in (0, 1, 4, 7, 2, 5, 8, 3, 6)]
    assert (joints[0].parent, joints[0].offset.tolist()) == (-1, [0.0, 0.0, 0.0])
    assert joints[0].channels[:3] == ("Xposition", "Yposition", "Zposition")
    assert all(j.channels[-3:] == ("Zrotation", "Xrotation", "Yrotation") for j in joints)
    assert [bvh.joints[j.parent].name for j in bvh.joints if j.end_site] == ["tail3", "legL3"]
    assert bvh.fps == pytest.approx(30.0, rel=1e-6)
    names = [bvh.names.index(name) for name in BRANCHES.names]
    ends = [bvh.names.index(f"{BRANCHES.names[j]}_end") for j in BRANCHES.end_sites]
    got = bvh.positions(names + ends) / UNITS[unit]
    want_joints, want_ends = scipy_forward_kinematics(BRANCHES, rotations, root)
    want = np.concatenate([want_joints, want_ends], axis=1)
    assert np.linalg.norm(got - want, axis=-1).max() < 1e-5


def test_a_single_joint_skeleton_is_a_root_alone(tmp_path: Path) -> None:
    skeleton = BvhSkeleton(("body",), (-1,), np.zeros((1, 3)), {0: [0.0, 0.5, 0.0]})
    path = tmp_path / "body.bvh"
    write_bvh_motion(path, skeleton, [[[0.0, 0.0, 0.0, 1.0]]], [[1.0, 2.0, 3.0]], 24.0)
    bvh = read_bvh(path)
    assert bvh.names == ("body", "body_end")
    np.testing.assert_allclose(bvh.positions([0, 1])[0], [[1.0, 2.0, 3.0], [1.0, 2.5, 3.0]])


def skeleton_with(**changes: object) -> BvhSkeleton:
    """A chain root -> a -> b with an End Site on b, with some fields replaced."""
    fields: dict[str, object] = {
        "names": ("root", "a", "b"),
        "parents": (-1, 0, 1),
        "offsets": np.ones((3, 3)),
        "end_sites": {2: np.ones(3)},
    }
    return BvhSkeleton(**{**fields, **changes})


def test_skeleton_is_normalised_and_copies_its_input() -> None:
    offsets = np.ones((3, 3))
    skeleton = skeleton_with(
        names=["root", "a", "b"], parents=np.array([-1, 0, 1]), offsets=offsets
    )
    offsets[:] = np.nan
    assert skeleton.names == ("root", "a", "b")
    assert skeleton.parents == (-1, 0, 1)
    assert all(type(p) is int for p in skeleton.parents)
    assert np.isfinite(skeleton.offsets).all()
    with pytest.raises(TypeError):
        skeleton.end_sites[1] = np.zeros(3)  # type: ignore[index]


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"names": (), "parents": (), "offsets": np.zeros((0, 3))}, "skeleton has no joints"),
        ({"names": ("root", "left arm", "b")}, "'left arm' is not a BVH name"),
        ({"names": ("root", "", "b")}, "'' is not a BVH name"),
        ({"names": ("root", "a{", "b")}, "'a{' is not a BVH name"),
        ({"names": ("root", "a\x00", "b")}, "is not a BVH name"),
        ({"names": ("root", 1, "b")}, "1 is not a BVH name"),
        ({"names": ("root", "a", "a")}, "'a' is used twice"),
        ({"parents": (-1, 0)}, "one parent per joint: 3 names, 2 parents"),
        ({"parents": (1, -1, 1)}, r"joint 0 \(root\) must be the root"),
        ({"parents": (-1, -1, 1)}, "second root, a; BVH gets one root"),
        ({"parents": (-1, 2, 0)}, "parent of a is 2: every parent must be a joint declared"),
        ({"parents": (-1, 0, 7)}, "parent of b is 7"),
        ({"parents": (-1, 0, 0.5)}, "parent of b is 0.5, not an index"),
        ({"offsets": np.ones((2, 3))}, r"offsets must have shape \(3, 3\), got \(2, 3\)"),
        ({"offsets": np.full((3, 3), np.nan)}, "offsets must be finite"),
        ({"end_sites": {1: np.ones(3)}}, r"End Site on joint 1 \(a\), which has children"),
        ({"end_sites": {3: np.ones(3)}}, "End Site on 3, which is not a joint index"),
        ({"end_sites": {"b": np.ones(3)}}, "End Site on 'b', which is not a joint index"),
        ({"end_sites": {2: np.ones(2)}}, r"End Site offset of joint 2 \(b\) must have shape"),
        ({"end_sites": {2: [0.0, np.inf, 0.0]}}, r"End Site offset of joint 2 \(b\) must be"),
    ],
)
def test_bad_skeletons_are_refused(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        skeleton_with(**changes)


@pytest.mark.parametrize(
    ("rotations", "root", "fps", "message"),
    [
        (np.ones((2, 2, 4)), np.zeros((2, 3)), 30.0, r"rotations \(n, 3, 4\) and root"),
        (np.ones((0, 3, 4)), np.zeros((0, 3)), 30.0, "with n > 0"),
        (np.ones((2, 3, 4)), np.zeros((3, 3)), 30.0, r"got \(2, 3, 4\) and \(3, 3\)"),
        (np.ones(4), np.zeros(3), 30.0, "needs rotations"),
        (np.ones((2, 3, 4)), np.zeros((2, 3)), 0.0, "fps must be positive and finite, got 0.0"),
        (np.ones((2, 3, 4)), np.zeros((2, 3)), np.inf, "fps must be positive and finite"),
        (np.zeros((2, 3, 4)), np.zeros((2, 3)), 30.0, "non-finite / zero rotations"),
        (np.ones((2, 3, 4)), np.full((2, 3), np.nan), 30.0, "non-finite root positions"),
    ],
)
def test_motion_that_does_not_fit_the_skeleton_is_refused(
    tmp_path: Path, rotations: np.ndarray, root: np.ndarray, fps: float, message: str
) -> None:
    path = tmp_path / "chain.bvh"
    with pytest.raises(ValueError, match=message):
        write_bvh_motion(path, skeleton_with(), rotations, root, fps)
    assert not path.exists()


def test_generic_writer_refuses_an_unknown_unit_and_names_an_unwritable_path(
    tmp_path: Path,
) -> None:
    rotations, root = np.ones((2, 3, 4)), np.zeros((2, 3))
    with pytest.raises(ValueError, match="--unit must be one of m, cm, got 'in'"):
        write_bvh_motion(tmp_path / "chain.bvh", skeleton_with(), rotations, root, 30.0, "in")
    path = tmp_path / "missing" / "chain.bvh"
    with pytest.raises(ExportError, match="cannot write the file") as raised:
        write_bvh_motion(path, skeleton_with(), rotations, root, 30.0)
    assert raised.value.source == str(path)
    assert list(tmp_path.iterdir()) == []


HUMANOID_BVH_SHA256 = "df463c413bbeb7f450bebbf3ec3466dfd99a959752a7aeebef495da60dd1b9e4"
"""SHA-256 of the BVH of `closed_form_motion()` in centimeters as `write_bvh` wrote it
before it became a wrapper of `write_bvh_motion`: the humanoid output must not change."""


def closed_form_motion() -> HumanoidMotion:
    """Three frames on the default rig whose Euler angles are whole degrees (|X| < 90) and
    root positions whole centimeters, so that rounding cannot differ between platforms."""
    t = np.arange(3.0)[:, None]
    bone = np.arange(float(N_BONES))[None, :]
    angles = np.stack(
        np.broadcast_arrays(10 * t + 3 * bone - 20, 7 * bone - 5 * t - 50, 4 * t * bone - 30),
        axis=-1,
    )
    rotations = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True).as_quat()
    root = np.stack([0.1 * t[:, 0], 0.9 + 0.01 * t[:, 0], -0.05 * t[:, 0]], axis=-1)
    return HumanoidMotion(HumanoidRig.from_body(), rotations.reshape(3, N_BONES, 4), root, 30.0)


def test_humanoid_output_is_unchanged(tmp_path: Path) -> None:
    motion = closed_form_motion()
    path = tmp_path / "humanoid.bvh"
    write_bvh(path, motion, "cm")
    data = path.read_bytes()
    assert data.splitlines()[-1].startswith(
        b"20.000000 92.000000 -10.000000 0.000000 -60.000000 -30.000000 "
    )
    assert hashlib.sha256(data).hexdigest() == HUMANOID_BVH_SHA256
    generic = tmp_path / "generic.bvh"
    skeleton = BvhSkeleton.from_rig(motion.rig)
    write_bvh_motion(generic, skeleton, motion.rotations, motion.root, motion.fps, "cm")
    assert generic.read_bytes() == data
