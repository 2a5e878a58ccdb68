"""Offline markerless capture from recorded video: one camera's silhouettes tracked into
an MCAP take like the live service's (`samba track-video`), and a volumetric capture's
motion written as BVH with, for a human model, its 13 joints (`samba capture-volume`).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from samba.base import InputError, atomic_path
from samba.body import JOINT_NAMES, N_MARKERS
from samba.export import BvhSkeleton, write_bvh_motion
from samba.reconstruct import PoseEstimate
from samba.service.take_recorder import TakeRecorder
from samba.silhouette import SilhouetteExtractor, SilhouetteTracker, downsampled
from samba.volume import KinematicMotion


def track_video(
    frames: Iterator[tuple[int, np.ndarray]],
    extractor: SilhouetteExtractor,
    tracker: SilhouetteTracker,
    out: Path,
    fps: float,
    video: str,
    empty_stage: str,
) -> tuple[list[float], int]:
    """Track every frame (number, BGR image) of `video` from the first with somebody in
    view, writing the poses to the MCAP take `out` at `fps`; returns the seconds each
    tracked frame took and how many held the pose. A silhouette the tracker cannot place
    (it does not stand on the floor) raises InputError naming the video and the frame,
    and asking whether the empty stage (`empty_stage`, the flag that gave it) is free of
    people; a video with nobody in any frame raises InputError naming it. A failure
    leaves no take behind."""
    size = tracker.tree.view.size
    seconds, held = [], 0
    try:
        with TakeRecorder(out, fps) as recorder:
            for number, frame in frames:
                start = time.perf_counter()
                mask = extractor.silhouette(frame)
                if not seconds and not mask.any():
                    continue  # nobody in view yet
                if mask.shape != size[::-1]:
                    mask = downsampled(mask, size)
                try:
                    estimate = tracker.step(mask)
                except InputError as exc:
                    raise InputError(
                        video,
                        f"frame {number}: the silhouette cannot be placed ({exc.problem}); is the "
                        f"empty stage ({empty_stage}) free of people and of the same view?",
                    ) from exc
                seconds.append(time.perf_counter() - start)
                held += not estimate.found
                recorder.write_frame(
                    round(number / fps * 1e9),
                    PoseEstimate(
                        estimate.pose, estimate.distance, 0, estimate.found, not estimate.found
                    ),
                    np.full((N_MARKERS, 3), np.nan),
                )
        if not seconds:
            raise InputError(video, "nobody was seen in any frame")
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    return seconds, held


def write_volume_capture(
    out: Path,
    motion: KinematicMotion,
    unit: str,
    joints_out: Path | None,
    joints: np.ndarray | None,
) -> None:
    """Write `motion` to the BVH file `out` with lengths in `unit` (an End Site closing
    each leaf link, its length in meters along the link's Z axis), then, when given,
    `joints` (n, 13, 3) m to the archive `joints_out` (arrays `joints`, `names` (13,)
    and `fps`). Both atomically; a failure leaves neither file."""
    skeleton = BvhSkeleton(
        motion.names,
        motion.parents,
        motion.offsets,
        end_sites={leaf: np.array([0.0, 0.0, motion.lengths[leaf]]) for leaf in motion.leaves},
    )
    try:
        write_bvh_motion(out, skeleton, motion.rotations, motion.root, motion.fps, unit)
        if joints_out is not None and joints is not None:
            with atomic_path(joints_out) as tmp, open(tmp, "wb") as file:
                np.savez(file, joints=joints, names=np.array(JOINT_NAMES), fps=motion.fps)
    except BaseException:
        out.unlink(missing_ok=True)
        raise
