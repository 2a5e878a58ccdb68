"""Volumes from video: each camera's silhouette extractor learnt from its empty stage, and
the subject's volume carved from the cameras' frame streams read in lockstep.

A take runs from the first to the last frame with somebody in the volume: at least
`samba.volume.capture.MIN_VOXELS` voxels.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from samba.base import InputError
from samba.silhouette import SilhouetteExtractor
from samba.volume.capture import MIN_VOXELS
from samba.volume.visual_hull import VisualHull

Frames = Iterator[tuple[int, np.ndarray]]
"""One camera's (frame number, BGR uint8 image (H, W, 3)) in order."""


def learn_extractors(
    stages: Sequence[tuple[str, Frames]], method: str
) -> list[SilhouetteExtractor]:
    """Each camera's silhouette extractor (background model `method`), learnt from the
    frames of its empty stage, given with the name of the video or folder they come from;
    an `InputError` names that source."""
    extractors = []
    for source, stage in stages:
        empty = [frame for _, frame in stage]
        try:
            extractors.append(SilhouetteExtractor.learn(empty, method=method))
        except InputError as exc:
            raise InputError(source, f"{exc.source}: {exc.problem}") from None
    return extractors


def carve_streams(
    streams: Sequence[Frames],
    extractors: Sequence[SilhouetteExtractor],
    hull: VisualHull,
    min_views: int | None,
    tolerance: int = 0,
) -> tuple[int, list[np.ndarray], list[int]]:
    """The volumes (nx, ny, nz) bool of the frames read in lockstep from `streams` until
    the shortest ends, from the first to the last with at least `MIN_VOXELS` voxels
    (somebody in the volume), the frame number of the first of them, and each
    volume's voxel count. A voxel is kept when `min_views` cameras (None: all) see it
    in the silhouette or within `tolerance` pixels of it (`VisualHull.carve`)."""
    first, volumes, counts = 0, [], []
    for frames in zip(*streams, strict=False):
        silhouettes = [
            extractor.silhouette(frame)
            for extractor, (_, frame) in zip(extractors, frames, strict=True)
        ]
        volume = hull.carve(silhouettes, min_views, tolerance)
        count = int(volume.sum())
        if not volumes:
            if count < MIN_VOXELS:
                continue  # nobody in the volume yet
            first = frames[0][0]
        volumes.append(volume)
        counts.append(count)
    while counts and counts[-1] < MIN_VOXELS:  # the subject has left
        counts.pop()
        volumes.pop()
    return first, volumes, counts
