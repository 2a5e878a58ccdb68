"""How well model-free volumetric capture (`samba.volume.capture`) recovers known
bodies: the issue's acceptance experiments on synthetic volume sequences.

* Human takes: a synthetic motion (`samba.synthetic.motions`) of the capsule body, its limbs
  held apart as the paper's subjects held theirs (`exaggerated`), seen by the
  paper's four cameras around three sides of the volume (`volume_cameras`), carved
  into a visual hull. Reported: the share of frames whose own model has human
  topology, over all frames and over the frames with separated limbs (head, arms and
  legs at least `gap` voxels apart, the paper's "exaggerated, separated" motions),
  and the error of the 13 mapped joints (`samba.volume.humanoid`) in cm.
* Creatures (`samba.volume.articulated_figure`): scan-converted volumes of a figure with
  known joints. Reported: the common model's ends and links against the figure's,
  the over-segmentation (links more than the figure's), and per true joint the
  distance in voxels to the nearest model joint (median over frames).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from samba.body import (
    CAPSULE_NAMES,
    CAPSULE_PARTS,
    PART_NAMES,
    BodyModel,
    mean_facing,
    scaled_to,
    segment_distances,
)
from samba.synthetic import generate
from samba.volume.articulated_figure import ArticulatedFigure, creature_motion
from samba.volume.capture import CaptureSettings, VolumeCapture, capture_volumes
from samba.volume.frame_kinematics import HUMAN_END_BRANCHES
from samba.volume.humanoid import humanoid_joints
from samba.volume.visual_hull import human_volumes, volume_cameras
from samba.volume.voxel_grid import VoxelGrid

LIMB_PARTS = ("head", "l_arm", "r_arm", "l_leg", "r_leg")
"""Body parts that must stay apart for a frame to have separated limbs."""
ADJOINING = ("l_thigh", "r_thigh")
"""Limb capsules that meet at the trunk whatever the pose, left out of the gap test."""
SEPARATION_VOXELS = 2.0
"""Smallest gap between limbs, in voxels, of a frame with separated limbs."""
ARM_RANGE_DEG = (45.0, 120.0)
"""Range of the arms' angle from straight down in exaggerated takes, degrees."""
LEG_DEG = 12.0
"""Extra outward turn of each leg in exaggerated takes, degrees."""
PADDING = 0.25
"""Margin (m) of the capture volume around a take's joints."""


@dataclass(frozen=True)
class HumanReport:
    """One human take's result: `humanoid` (n,) bool per frame, `separated` (n,) bool
    frames with separated limbs, `errors` (n, 13) cm of the mapped joints (NaN when
    the common model is not humanoid), `volumes` (n, nx, ny, nz) bool the visual
    hulls and `voxels` (n,) their occupied voxels, `capture`."""

    name: str
    humanoid: np.ndarray
    separated: np.ndarray
    errors: np.ndarray
    volumes: np.ndarray
    voxels: np.ndarray
    capture: VolumeCapture

    @property
    def humanoid_rate_separated(self) -> float:
        """Share of the frames with separated limbs that have human topology (NaN if
        no frame has separated limbs)."""
        if not self.separated.any():
            return float("nan")
        return float(self.humanoid[self.separated].mean())


def human_take(
    motion: str,
    seed: int,
    seconds: float = 3.0,
    fps: float = 10.0,
    voxel: float = 0.03,
    noise: float = 0.0,
    exaggerate: bool = True,
    settings: CaptureSettings | None = None,
) -> HumanReport:
    """Capture a synthetic `motion` take (seed `seed`, `seconds` at `fps`, the paper's
    10 Hz by default) of the men-M capsule body from four 320x240 cameras, carved
    into `voxel` m voxels, with silhouettes spoilt at `noise` (`noisy_silhouettes`);
    with `exaggerate`, the limbs are held apart first (`exaggerated`)."""
    body = BodyModel.named("men-M")
    poses = scaled_to(generate(motion, seconds, fps, seed).poses, body.height).astype(np.float64)
    if exaggerate:
        poses = exaggerated(poses)
    low = poses.reshape(-1, 3).min(axis=0) - PADDING
    high = poses.reshape(-1, 3).max(axis=0) + PADDING
    low[1] = -0.05
    grid = VoxelGrid.from_bounds(low, high, voxel)
    volumes = human_volumes(poses, volume_cameras(grid, 4), body, grid, noise, seed)
    capture = capture_volumes(volumes, grid, fps, settings)
    if capture.fit.model.branch_count == HUMAN_END_BRANCHES:
        joints = humanoid_joints(capture.fit, mean_facing(poses[:1]))
        errors = np.linalg.norm(joints - poses, axis=-1) * 100.0
    else:
        errors = np.full(poses.shape[:2], np.nan)
    return HumanReport(
        name=f"{motion}-{seed}",
        humanoid=np.array([f.is_humanoid() for f in capture.frames]),
        separated=limbs_separated(poses, body, SEPARATION_VOXELS * voxel),
        errors=errors,
        volumes=volumes,
        voxels=volumes.sum(axis=(1, 2, 3)),
        capture=capture,
    )


def exaggerated(
    poses: np.ndarray, arm_range_deg: tuple[float, float] = ARM_RANGE_DEG, leg_deg: float = LEG_DEG
) -> np.ndarray:
    """Poses (n, 13, 3) m with the limbs held apart, as the paper's subjects held them:
    in the body's frontal plane (spanned by up and the hip line), each arm turns about
    its shoulder so its shoulder-to-wrist angle from straight down lies in
    `arm_range_deg`, and each leg turns outward about its hip by `leg_deg` more.
    Bone lengths are kept; everything else is unchanged."""
    out = np.array(poses, dtype=np.float64)
    across = out[:, 7] - out[:, 8]
    up = np.array([0.0, 1.0, 0.0])
    forward = np.cross(across, up)
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    for side, (root, middle, end) in ((1.0, (1, 3, 5)), (-1.0, (2, 4, 6))):
        limb = out[:, end] - out[:, root]
        outward = side * np.cross(up, forward)
        angle = np.degrees(np.arctan2(np.einsum("ij,ij->i", limb, outward), -limb[:, 1]))
        target = np.clip(angle, *arm_range_deg)
        _turn(out, root, (middle, end), forward * side, np.radians(target - angle))
    for side, (root, middle, end) in ((1.0, (7, 9, 11)), (-1.0, (8, 10, 12))):
        _turn(out, root, (middle, end), forward * side, np.full(len(out), np.radians(leg_deg)))
    return out


def _turn(
    poses: np.ndarray, pivot: int, joints: tuple[int, int], axis: np.ndarray, angle: np.ndarray
) -> None:
    """Rotate `joints` of `poses` (n, 13, 3) in place about unit `axis` (n, 3) through
    joint `pivot` by `angle` (n,) radians (right-handed)."""
    turn = Rotation.from_rotvec(axis * angle[:, None])
    for joint in joints:
        poses[:, joint] = poses[:, pivot] + turn.apply(poses[:, joint] - poses[:, pivot])


def limbs_separated(poses: np.ndarray, body: BodyModel, gap: float) -> np.ndarray:
    """(n,) bool: frames of `poses` (n, 13, 3) m in which every two of the head, arms
    and legs of `body` keep at least `gap` m between their capsules' surfaces (except
    the two thighs, which meet at the pelvis)."""
    starts, ends, radii, parts = body.capsules(poses)
    limb = np.array([PART_NAMES[p] in LIMB_PARTS for p in CAPSULE_PARTS])
    index = np.flatnonzero(limb)
    first, second = np.triu_indices(len(index), k=1)
    a, b = index[first], index[second]
    names = np.array(CAPSULE_NAMES)
    adjoining = np.array(
        [{x, y} == set(ADJOINING) for x, y in zip(names[a], names[b], strict=True)]
    )
    different = (parts[a] != parts[b]) & ~adjoining
    a, b = a[different], b[different]
    distance = segment_distances(starts[:, a], ends[:, a], starts[:, b], ends[:, b])
    return ((distance - radii[a] - radii[b]) >= gap).all(axis=1)


@dataclass(frozen=True)
class CreatureReport:
    """One creature take's result against the figure's truth.

    `true_ends` / `model_ends`: free ends of the figure's tree / leaf branches of the
    common model; `true_links` / `model_links`; `joint_voxels` (J + 1,) per true joint
    (then the root-side end when the root is an end) the median distance in voxels
    to the nearest model joint; `spurious` model joints farther than `tolerance`
    voxels from every true joint (median over frames): the over-segmentation.
    """

    name: str
    true_ends: int
    model_ends: int
    true_links: int
    model_links: int
    joint_voxels: np.ndarray
    spurious: int
    tolerance: float
    capture: VolumeCapture

    @property
    def joints_found(self) -> float:
        """Share of true joints with a model joint within `tolerance` voxels."""
        return float(np.mean(self.joint_voxels <= self.tolerance))


def creature_take(
    figure: ArticulatedFigure,
    name: str,
    seed: int,
    frames: int = 30,
    voxel: float = 0.025,
    bounds: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (-1.0, 0.0, -1.0),
        (1.0, 1.2, 1.0),
    ),
    tolerance: float = 2.0,
    settings: CaptureSettings | None = None,
) -> CreatureReport:
    """Capture `frames` frames of `figure` moving by `creature_motion` (seed `seed`)
    inside `bounds` (low, high corners, m), scan-converted at `voxel` m."""
    box = np.asarray(bounds, dtype=np.float64)
    grid = VoxelGrid.from_bounds(box[0], box[1], voxel)
    truth = figure.positions(creature_motion(figure, frames, seed, bounds=box))
    capture = capture_volumes(figure.voxelize(truth, grid), grid, 10.0, settings)
    model = capture.motion.positions
    distance = np.linalg.norm(model[:, :, None] - truth[:, None], axis=-1) / voxel
    joint_voxels = np.median(distance.min(axis=1), axis=0)
    spurious = int((np.median(distance.min(axis=2), axis=0) > tolerance).sum())
    root_is_end = len(figure.children[0]) == 1
    return CreatureReport(
        name=name,
        true_ends=figure.branch_count + int(root_is_end),
        model_ends=capture.fit.model.branch_count,
        true_links=figure.link_count,
        model_links=capture.fit.model.link_count,
        joint_voxels=joint_voxels,
        spurious=spurious,
        tolerance=tolerance,
        capture=capture,
    )
