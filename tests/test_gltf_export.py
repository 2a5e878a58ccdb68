"""glTF export: the Khronos validator passes the files, and the joints read back from them
follow the motion (within 1 mm) and the capture's bone directions (within 1°)."""

from __future__ import annotations

import errno
import json
import os
import shutil
import struct
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pygltflib as gltf
import pytest
from export_fixtures import box_mesh, real_takes, synthetic_motion

from samba.body.take import Take
from samba.export import glb_with_json
from samba.export.avatar_mesh import AvatarMesh
from samba.export.errors import ExportError
from samba.export.gltf_reader import read_glb_joint_positions
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import N_BONES, HumanoidRig
from samba.export.mannequin import mannequin
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import bone_direction_errors, retarget
from samba.synthetic import motions as synthetic

VALIDATOR = "gltf-validator@2.0.0-dev.3.10"
RUNNER = Path(__file__).with_name("gltf_validate.js")
Validate = Callable[[Path], dict[str, Any]]


@pytest.fixture(scope="session")
def validate() -> Validate:
    """Runs the Khronos glTF validator on a file and returns its JSON report; installs the
    npm package once into a cache folder under the system temp dir. Skips without node or
    npm, fails with npm's output when the install fails."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("the glTF validator needs node and npm on PATH")
    tools = Path(tempfile.gettempdir()) / "samba-test-tools" / VALIDATOR.replace("@", "-")
    if not (tools / "node_modules" / "gltf-validator" / "package.json").is_file():
        done = subprocess.run(
            [npm, "install", "--no-save", "--no-audit", "--no-fund", "--prefix", tools, VALIDATOR],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            pytest.fail(f"npm install {VALIDATOR} failed:\n{done.stdout}\n{done.stderr}")
    env = {**os.environ, "NODE_PATH": str(tools / "node_modules")}

    def run(path: Path) -> dict[str, Any]:
        done = subprocess.run(
            [node, RUNNER, path], capture_output=True, text=True, env=env, check=False
        )
        if done.returncode == 2 or not done.stdout:
            pytest.fail(f"the validator could not run on {path}:\n{done.stderr}")
        return json.loads(done.stdout)

    return run


def assert_clean(report: dict[str, Any]) -> None:
    """No errors and no warnings in a validator report."""
    issues = report["issues"]
    serious = [m for m in issues["messages"] if m["severity"] <= 1]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, serious


def assert_round_trip(path: Path, take: Take, motion: HumanoidMotion) -> None:
    """Joints read back from `path` match the motion within 1 mm at every frame, and the
    captured bone directions within 1°."""
    names, positions = read_glb_joint_positions(path)
    assert names == motion.rig.names
    assert positions.shape == (len(motion), N_BONES, 3)
    error = np.linalg.norm(positions - motion.world_positions(), axis=-1)
    assert error.max() < 0.001, (take.name, error.max())
    angles = bone_direction_errors(positions, take.poses)
    assert angles.max() < 1.0, (take.name, angles.max())


def test_skinned_export_validates_with_bind_pose_matrices(
    tmp_path: Path, validate: Validate
) -> None:
    _, motion = synthetic_motion()
    path = tmp_path / "walk.glb"
    write_glb(path, motion, box_mesh(motion.rig))
    report = validate(path)
    assert_clean(report)
    assert report["info"]["hasSkins"] and report["info"]["animationCount"] == 1
    doc = gltf.GLTF2().load(str(path))
    offset = _byte_offset(doc, doc.skins[0].inverseBindMatrices)
    ibm = np.frombuffer(doc.binary_blob(), np.float32, N_BONES * 16, offset)
    ibm = ibm.reshape(N_BONES, 4, 4).swapaxes(1, 2)  # stored column-major
    bind = np.tile(np.eye(4), (N_BONES, 1, 1))
    bind[:, :3, 3] = motion.rig.rest  # world bind matrices: the rest joints, no rotation
    assert np.allclose(bind @ ibm, np.eye(4), atol=1e-6)
    assert [doc.nodes[j].name for j in doc.skins[0].joints] == list(motion.rig.names)


def test_skeleton_only_export_validates(tmp_path: Path, validate: Validate) -> None:
    take, motion = synthetic_motion("kick")
    for frames in (len(motion), 1):
        path = tmp_path / f"kick-{frames}.glb"
        write_glb(path, motion.frames(0, frames))
        report = validate(path)
        assert_clean(report)
        assert not report["info"]["hasSkins"]
        first = Take(take.name, take.poses[:frames], take.fps)
        assert_round_trip(path, first, motion.frames(0, frames))


def test_mannequin_export_validates(tmp_path: Path, validate: Validate) -> None:
    _, motion = synthetic_motion("wave")
    path = tmp_path / "wave.glb"
    write_glb(path, motion, mannequin(motion.rig))
    assert_clean(validate(path))


def test_real_takes_export_validates(tmp_path: Path, validate: Validate, cmu_dir: Path) -> None:
    rig = HumanoidRig.from_body()
    for take in real_takes(cmu_dir):
        path = tmp_path / f"{take.name}.glb"
        write_glb(path, retarget(take.poses, rig, take.fps), box_mesh(rig))
        assert_clean(validate(path))


@pytest.mark.parametrize("motion", synthetic.MOTIONS)
def test_synthetic_takes_round_trip(tmp_path: Path, motion: str) -> None:
    take, humanoid = synthetic_motion(motion)
    path = tmp_path / f"{motion}.glb"
    write_glb(path, humanoid, box_mesh(humanoid.rig))
    assert_round_trip(path, take, humanoid)


def test_real_takes_round_trip(tmp_path: Path, cmu_dir: Path) -> None:
    rig = HumanoidRig.from_body()
    for take in real_takes(cmu_dir):
        path = tmp_path / f"{take.name}.glb"
        motion = retarget(take.poses, rig, take.fps)
        write_glb(path, motion)
        assert_round_trip(path, take, motion)


def test_weights_sum_to_one_in_float32(tmp_path: Path) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    mesh = box_mesh(motion.rig)
    path = tmp_path / "weights.glb"
    write_glb(path, motion, mesh)
    doc = gltf.GLTF2().load(str(path))
    attributes = doc.meshes[0].primitives[0].attributes
    count = len(mesh.vertices)
    weights = np.frombuffer(
        doc.binary_blob(), np.float32, count * 4, _byte_offset(doc, attributes.WEIGHTS_0)
    ).reshape(count, 4)
    assert np.abs(weights.astype(np.float64).sum(axis=1) - 1.0).max() <= 1.2e-7
    assert np.allclose(weights, mesh.weights, atol=1e-6)


def test_reader_samples_step_linear_cubic_and_static_matrices(tmp_path: Path) -> None:
    # frame (static matrix: up 10 m) > root > child --(0, 0, 1)--> end. root translation:
    # STEP, 0 then 2 m up at 1 s; child rotation: LINEAR normalised int16 quaternions,
    # 0 -> 90° about Y over 0..1 s; child scale: CUBICSPLINE with zero tangents, 1, 3, 1 at
    # 0, 0.5, 2 s (it moves only the end). Keys: the union 0, 0.5, 1, 2 s.
    half = np.sqrt(0.5)
    quaternions = np.array([[0, 0, 0, 1], [0, half, 0, half]])
    cubic = np.zeros((9, 3), np.float32)
    cubic[[1, 4, 7]] = [[1.0] * 3, [3.0] * 3, [1.0] * 3]
    arrays = [
        np.array([0.0, 1.0], np.float32),
        np.array([[0, 0, 0], [0, 2, 0]], np.float32),
        np.round(quaternions * 32767).astype(np.int16),
        np.array([0.0, 0.5, 2.0], np.float32),
        cubic,
    ]
    frame = np.eye(4)
    frame[1, 3] = 10.0
    doc = gltf.GLTF2(
        scene=0,
        scenes=[gltf.Scene(nodes=[0])],
        nodes=[
            gltf.Node(name="frame", matrix=frame.T.ravel().tolist(), children=[1]),
            gltf.Node(name="root", children=[2]),
            gltf.Node(name="child", translation=[1.0, 0.0, 0.0], children=[3]),
            gltf.Node(name="end", translation=[0.0, 0.0, 1.0]),
        ],
    )
    blob = b""
    for i, array in enumerate(arrays):
        doc.bufferViews.append(
            gltf.BufferView(buffer=0, byteOffset=len(blob), byteLength=array.nbytes)
        )
        doc.accessors.append(
            gltf.Accessor(
                bufferView=i,
                componentType=gltf.SHORT if array.dtype == np.int16 else gltf.FLOAT,
                normalized=array.dtype == np.int16,
                count=len(array),
                type={1: gltf.SCALAR, 3: gltf.VEC3, 4: gltf.VEC4}[array[0].size],
            )
        )
        blob += array.tobytes() + bytes(-array.nbytes % 4)
    tracks = ((0, 1, 1, "translation", "STEP"), (0, 2, 2, "rotation", "LINEAR"))
    tracks += ((3, 4, 2, "scale", "CUBICSPLINE"),)
    doc.animations = [
        gltf.Animation(
            samplers=[
                gltf.AnimationSampler(input=i, output=o, interpolation=mode)
                for i, o, _, _, mode in tracks
            ],
            channels=[
                gltf.AnimationChannel(sampler=s, target=gltf.AnimationChannelTarget(node=n, path=p))
                for s, (_, _, n, p, _) in enumerate(tracks)
            ],
        )
    ]
    doc.buffers = [gltf.Buffer(byteLength=len(blob))]
    doc.set_binary_blob(blob)
    path = tmp_path / "chain.glb"
    doc.save_binary(str(path))

    names, positions = read_glb_joint_positions(path)

    assert names == ("root", "child", "end")
    height = 10.0 + np.array([0.0, 0.0, 2.0, 2.0])
    angle = np.radians([0.0, 45.0, 90.0, 90.0])
    u = (1.0 - 0.5) / (2.0 - 0.5)
    scale = np.array([1.0, 3.0, 3.0 - 2.0 * (3 * u**2 - 2 * u**3), 1.0])
    zero = np.zeros(4)
    assert np.allclose(positions[:, 0], np.stack([zero, height, zero], axis=1))
    assert np.allclose(positions[:, 1], np.stack([zero + 1.0, height, zero], axis=1))
    end = np.stack([1.0 + scale * np.sin(angle), height, scale * np.cos(angle)], axis=1)
    assert np.allclose(positions[:, 2], end, atol=1e-4)


@pytest.mark.parametrize("kind", ["missing folder", "directory", "permission denied"])
def test_unwritable_path_raises_and_leaves_no_file(tmp_path: Path, kind: str) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    folder = tmp_path / "out"
    if kind == "missing folder":
        path = folder / "take.glb"
    elif kind == "directory":
        path = folder
        folder.mkdir()
    else:
        if os.geteuid() == 0:
            pytest.skip("root may write into a read-only folder")
        folder.mkdir(mode=0o500)
        path = folder / "take.glb"
    with pytest.raises(ExportError) as raised:
        write_glb(path, motion)
    assert raised.value.source == str(path)
    assert path.is_dir() if kind == "directory" else not path.exists()
    assert sorted(p.name for p in tmp_path.rglob("*")) == (["out"] if folder.exists() else [])


def test_failure_midway_leaves_existing_file_untouched(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    path = tmp_path / "take.glb"
    path.write_bytes(b"the previous export")
    real_write = Path.write_bytes

    def disk_full(self: Path, data: bytes) -> int:
        real_write(self, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_bytes", disk_full)
    with pytest.raises(ExportError, match="No space left"):
        write_glb(path, motion)
    assert path.read_bytes() == b"the previous export"
    assert [p.name for p in tmp_path.iterdir()] == ["take.glb"]


def test_invalid_motion_is_refused_and_a_mesh_without_triangles_not_written(
    tmp_path: Path,
) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    root = motion.root.copy()
    root[1, 2] = np.nan
    rotations = motion.rotations.copy()
    rotations[0, 3] = 0.0
    for bad_rotations, bad_root in ((motion.rotations, root), (rotations, motion.root)):
        with pytest.raises(ValueError, match="non-finite"):
            HumanoidMotion(motion.rig, bad_rotations, bad_root, motion.fps)
    mesh = box_mesh(motion.rig)
    no_faces = AvatarMesh(mesh.vertices, mesh.normals, np.zeros((0, 3)), mesh.joints, mesh.weights)
    path = tmp_path / "take.glb"
    with pytest.raises(ValueError, match="no triangles"):
        write_glb(path, motion, no_faces)
    assert not any(tmp_path.iterdir())


CORRUPTIONS: dict[str, Callable[[bytes], bytes]] = {
    "text file": lambda glb: b"Hips 0 0 0\n" * 10,
    "empty file": lambda glb: b"",
    "truncated": lambda glb: glb[: len(glb) // 2],
    "version 1": lambda glb: glb[:4] + struct.pack("<I", 1) + glb[8:],
    "garbled JSON": lambda glb: glb[:20] + b"{]" + glb[22:],
    "accessor out of range": lambda glb: glb_with_json(
        glb, lambda doc: doc["animations"][0]["samplers"][0].update(output=999)
    ),
    "view past the data": lambda glb: glb_with_json(
        glb, lambda doc: doc["bufferViews"][-1].update(byteOffset=10**9)
    ),
    "node cycle": lambda glb: glb_with_json(glb, lambda doc: doc["nodes"][5].update(children=[0])),
    "two parents": lambda glb: glb_with_json(glb, lambda doc: doc["nodes"][5].update(children=[1])),
}


@pytest.mark.parametrize("corruption", CORRUPTIONS)
def test_reader_rejects_bad_files(tmp_path: Path, corruption: str) -> None:
    _, motion = synthetic_motion(seconds=0.1)
    good = tmp_path / "good.glb"
    write_glb(good, motion)
    path = tmp_path / "bad.glb"
    path.write_bytes(CORRUPTIONS[corruption](good.read_bytes()))
    with pytest.raises(ExportError) as raised:
        read_glb_joint_positions(path)
    assert raised.value.source == str(path)


def test_reader_names_a_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="cannot read"):
        read_glb_joint_positions(tmp_path / "none.glb")


def _byte_offset(doc: gltf.GLTF2, accessor: int) -> int:
    """Where an accessor's data starts in the binary chunk."""
    acc = doc.accessors[accessor]
    return doc.bufferViews[acc.bufferView].byteOffset + acc.byteOffset
