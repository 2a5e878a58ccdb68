"""`samba examples DIR`: the input files every command example of the README and the
manual (`docs/`) runs on, made by the project's own renderers, under the names the
examples use, so that every example runs as printed from inside DIR.

What is written (`EXAMPLE_FILES`), all synthetic and a few MB:

- `store/`: a pose store of the built-in motions (`samba.db.build_synthetic_store`, one
  3-s take of each, mirrored), the `--db store` of the live, reconstruct and markerless
  examples;
- `cameras.toml`: the two cameras of `samba demo`, which the live examples' nodes film
  with;
- `left/`, `middle/`, `right/`: photos of a 9x6 checkerboard of 8 cm squares, on the
  floor (frame00) and then in 20 poses, as three 640x480 cameras (two with lens
  distortion) take them (`samba.cameras.board_render`), for `samba calibrate`;
- `stage.toml`: four 640x480 cameras round a stage (front, left, right, front_left;
  `samba.volume.volume_cameras`);
- `wave/` and `empty/`: the front camera's colour frames of a wave at 15 fps (a 1.75 m
  subject) and of the empty stage (`samba.silhouette.person_frames`), for `samba
  track-video`;
- `jacks/<camera>/`: each stage camera's frames at 30 fps, 10 of the empty stage then 1 s
  of jumping jacks (the men's-M body), for `samba capture-volume`;
- `studio_walk.bvh`: a synthetic walk as a game-studio rig writes it (names like
  `UpperArm_L`, a `joint_Root` above the hips, six channels on every joint; 120 fps);
- `quadruped.bvh`: a four-legged rig whose joints are named `Bone0`, `Bone1`, ...
  (`samba.ingest.QUADRUPED`), which `samba db import` refuses: not a humanoid;
- `ue_avatar.glb`: a skeleton-only avatar with Unreal's bone names, its Hips joint 8 cm
  above its legs;
- `me.gltf`: a JSON glTF avatar whose buffer file `me.bin` is missing, which `samba
  export --avatar` refuses naming that file;
- `keys.toml`, `cam0.key`, `cam1.key`, `stages.toml`: a stage on a LAN, its two nodes'
  keys (32 random bytes each, readable by their owner only), the keys file naming them
  and a sessions file (one session, `stage1`, of `cameras.toml` and `store`).

Images are JPEG (quality `JPEG_QUALITY`). Nothing is written over an existing file or
folder unless `force`, which replaces them.
"""

from __future__ import annotations

import json
import secrets
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from samba.base import (
    FORCE_HINT,
    InputError,
    check_outputs,
    write_bytes_atomic,
    write_text_atomic,
)
from samba.body import BodyModel, scaled_to
from samba.cameras import (
    board_poses,
    floor_pose,
    parse_board,
    render_board,
    stage_cameras,
    write_calibration,
)
from samba.db import build_synthetic_store
from samba.export import (
    BvhSkeleton,
    HumanoidRig,
    read_glb,
    retarget,
    write_bvh_motion,
    write_named_avatar,
)
from samba.ingest import (
    QUADRUPED,
    RIG_STRUCTURES,
    read_bvh,
    rest_pose_bvh,
    rig_variant,
    unnamed_rig,
)
from samba.service.demo import DemoSettings, demo_capture
from samba.silhouette import (
    SilhouetteView,
    empty_stage_frames,
    person_frames,
    stage_background,
    staged,
)
from samba.synthetic import generate
from samba.volume import VoxelGrid, volume_cameras

BOARD = "checkerboard:9x6:0.08"
"""The board of the calibration examples."""
BOARD_CAMERAS = ("left", "middle", "right")
BOARD_DISTORTIONS = ((-0.12, 0.03, 0.0, 0.0, 0.0), (0.0,) * 5, (-0.05, 0.01, 5e-4, -5e-4, 0.0))
"""OpenCV distortion coefficients of the board cameras (k1, k2, p1, p2, k3)."""
BOARD_POSES = 20
"""Poses of the board in the air, after its place on the floor."""
STORE_SECONDS = 3.0
"""Seconds of each built-in motion in the store: a small store, whose shape tree
(`samba db tree`) builds in seconds."""
SUBJECT_HEIGHT = 1.75
"""Stature (m) of the markerless examples' subject: their `--height`."""
WAVE_FPS, WAVE_SECONDS = 15.0, 3.0
JACKS_FPS, JACKS_SECONDS, EMPTY_FRAMES = 30.0, 1.0, 10
STAGE_SIZE = (640, 480)
JPEG_QUALITY = 80
EXAMPLE_FILES = (
    "store",
    "cameras.toml",
    *BOARD_CAMERAS,
    "stage.toml",
    "wave",
    "empty",
    "jacks",
    "studio_walk.bvh",
    "quadruped.bvh",
    "ue_avatar.glb",
    "me.gltf",
    "keys.toml",
    "cam0.key",
    "cam1.key",
    "stages.toml",
)
"""What `write_examples` writes in its folder: files and folders."""
KEYS_TOML = """[[node]]
key_file = "cam0.key"
cameras = [0]

[[node]]
key_file = "cam1.key"
cameras = [1]
"""
STAGES_TOML = """# the sessions of samba serve --config (docs/live.md)
[[session]]
name = "stage1"
calibration = "cameras.toml"
database = "store"
fps = 30
"""
NEXT_COMMANDS = (
    "samba calibrate left middle right --board checkerboard:9x6:0.08 -o calib.toml",
    "samba db tree store --calib stage.toml --height 1.75",
    "samba track-video wave/ --calib stage.toml --db store --height 1.75 --background empty/ "
    "--fps 15 -o wave.mcap",
    "samba export studio_walk.bvh --avatar ue_avatar.glb -o studio_walk.glb",
)
"""What `samba examples` suggests running next, in DIR."""


def write_examples(folder: str | Path, force: bool = False) -> list[tuple[Path, str]]:
    """Write `EXAMPLE_FILES` into `folder` (made if missing); returns each path written
    with what it is, in order. `InputError` naming `folder` when it is a file, or the
    first of the files that exists when not `force` (then nothing is written); with
    `force` those are replaced."""
    root = Path(folder)
    if root.exists() and not root.is_dir():
        raise InputError(str(root), "is a file; examples go into a folder")
    paths = [root / name for name in EXAMPLE_FILES]
    folders = [p for p in paths if not p.suffix and (p.exists() or p.is_symlink())]
    if folders and not force:
        more = f" (and {len(folders) - 1} more example folders)" if len(folders) > 1 else ""
        raise InputError(str(folders[0]), f"already exists{more}; {FORCE_HINT}")
    if root.is_dir():
        check_outputs([p for p in paths if p.suffix], force)
    existing = [p for p in paths if p.exists() or p.is_symlink()]
    root.mkdir(parents=True, exist_ok=True)
    for path in existing:
        shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
    written: list[tuple[Path, str]] = []
    for write in _WRITERS:
        written.extend(write(root))
    return written


def _store(root: Path) -> list[tuple[Path, str]]:
    store = build_synthetic_store(root / "store", takes_per_motion=1, seconds=STORE_SECONDS, seed=0)
    return [(root / "store", f"pose store of the built-in motions ({len(store)} poses)")]


def _live_cameras(root: Path) -> list[tuple[Path, str]]:
    capture, _ = demo_capture(DemoSettings())
    write_calibration(root / "cameras.toml", capture.cameras)
    return [(root / "cameras.toml", "the two cameras of samba demo (live examples)")]


def _board_photos(root: Path) -> list[tuple[Path, str]]:
    board = parse_board(BOARD)
    cameras = stage_cameras(len(BOARD_CAMERAS), BOARD_DISTORTIONS)
    rng = np.random.default_rng(11)
    poses = [floor_pose(), *board_poses(board, cameras, BOARD_POSES, rng)]
    written = []
    for name, camera in zip(BOARD_CAMERAS, cameras, strict=True):
        frames = [render_board(camera, board, pose, rng) for pose in poses]
        written.append((_images(root / name, frames, "frame"), f"{len(frames)} photos of {BOARD}"))
    return written


def _stage(root: Path) -> list[tuple[Path, str]]:
    """stage.toml, the wave and empty stage of its front camera, the jumping jacks of all."""
    body = BodyModel.named("men-M")
    jacks = generate("jumping_jacks", seconds=JACKS_SECONDS, fps=JACKS_FPS, seed=1).poses
    jacks = scaled_to(jacks.astype(np.float64), body.height)
    low = jacks.reshape(-1, 3).min(axis=0) - 0.35
    high = jacks.reshape(-1, 3).max(axis=0) + 0.35
    low[1] = 0.0
    cameras = volume_cameras(VoxelGrid.from_bounds(low, high, 0.03), 4, STAGE_SIZE)
    write_calibration(root / "stage.toml", cameras)
    rng = np.random.default_rng(7)
    written = [(root / "stage.toml", "four 640x480 cameras: front, left, right, front_left")]
    front = cameras[0]
    subject = BodyModel.for_subject(SUBJECT_HEIGHT)
    wave = generate("wave", WAVE_SECONDS, WAVE_FPS, seed=202).poses.astype(np.float64)
    wave = staged(wave, SilhouetteView(front), SUBJECT_HEIGHT)
    background = stage_background(front.size, rng)
    frames = person_frames(wave, front, subject, background, rng)
    written.append((_images(root / "wave", frames), f"front camera: a wave, {WAVE_FPS:g} fps"))
    empty = empty_stage_frames(background, 8, rng)
    written.append((_images(root / "empty", empty), "its empty stage"))
    for camera in cameras:
        background = stage_background(camera.size, rng)
        empty = empty_stage_frames(background, EMPTY_FRAMES, rng)
        frames = person_frames(jacks, camera, body, background, rng)
        _images(root / "jacks" / camera.name, np.concatenate([empty, frames]))
    written.append(
        (root / "jacks", f"each camera's folder: {EMPTY_FRAMES} empty frames, 1 s of jacks")
    )
    return written


def _studio_walk(root: Path) -> list[tuple[Path, str]]:
    take = generate("walk", seconds=8.0, fps=120.0, seed=5)
    path = root / "studio_walk.bvh"
    with tempfile.TemporaryDirectory() as scratch:
        plain = Path(scratch) / "walk.bvh"
        motion = retarget(take.poses, HumanoidRig.from_body(), take.fps)
        skeleton = BvhSkeleton.from_rig(motion.rig)
        write_bvh_motion(plain, skeleton, motion.rotations, motion.root, motion.fps, "cm")
        bvh = read_bvh(plain)
        text = rig_variant(bvh, "game studio", RIG_STRUCTURES, frames=len(bvh.motion))
    write_text_atomic(path, text)
    return [(path, f"a walk of a game-studio rig, {len(take.poses)} frames at 120 fps")]


def _quadruped(root: Path) -> list[tuple[Path, str]]:
    write_text_atomic(root / "quadruped.bvh", rest_pose_bvh(unnamed_rig(QUADRUPED)))
    return [(root / "quadruped.bvh", "a four-legged rig, which samba db import refuses")]


def _avatars(root: Path) -> list[tuple[Path, str]]:
    """ue_avatar.glb, and me.gltf: a Unity-named avatar as JSON glTF without its me.bin."""
    write_named_avatar(root / "ue_avatar.glb", "unreal", 0.08)
    with tempfile.TemporaryDirectory() as scratch:
        glb = Path(scratch) / "me.glb"
        write_named_avatar(glb, "unity")
        doc = read_glb(glb).doc
    doc["buffers"][0]["uri"] = "me.bin"
    write_text_atomic(root / "me.gltf", json.dumps(doc))
    return [
        (root / "ue_avatar.glb", "an avatar with Unreal's bone names"),
        (root / "me.gltf", "a glTF avatar without its buffer file me.bin"),
    ]


def _lan_stage(root: Path) -> list[tuple[Path, str]]:
    """keys.toml naming two fresh node keys (mode 0600), and stages.toml."""
    write_text_atomic(root / "keys.toml", KEYS_TOML)
    written = [(root / "keys.toml", "which node key signs for which camera (LAN example)")]
    for node in range(2):
        key = root / f"cam{node}.key"
        write_bytes_atomic(key, secrets.token_bytes(32), mode=0o600)
        written.append((key, f"node {node}'s key, 32 random bytes, readable by you only"))
    write_text_atomic(root / "stages.toml", STAGES_TOML)
    written.append((root / "stages.toml", "one session, stage1, for samba serve --config"))
    return written


def _images(folder: Path, frames: np.ndarray | list[np.ndarray], prefix: str = "") -> Path:
    """`frames` (n, H, W[, 3]) uint8 as JPEG files `folder`/PREFIXnn.jpg (made); returns it."""
    folder.mkdir(parents=True)
    digits = max(2, len(str(len(frames) - 1)))
    for i, frame in enumerate(frames):
        name = folder / f"{prefix}{i:0{digits}d}.jpg"
        if not cv2.imwrite(str(name), frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]):
            raise InputError(str(name), "cannot be written")
    return folder


_WRITERS: tuple[Callable[[Path], list[tuple[Path, str]]], ...] = (
    _store,
    _live_cameras,
    _board_photos,
    _stage,
    _studio_walk,
    _quadruped,
    _avatars,
    _lan_stage,
)
