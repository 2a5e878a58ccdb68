"""BVH file to `Take`: read, map the rig, resample, normalise to meters / +Y up / floor."""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.body import Take, resample_times
from samba.db import frame_count_problem, frame_rate_problem
from samba.ingest.bvh import parse_bvh
from samba.ingest.errors import BvhError
from samba.ingest.input_files import MAX_FILE_BYTES, read_input
from samba.ingest.normalize import (
    UNITS,
    UP_AXES,
    chirality,
    detect_units,
    detect_up,
    floor_height,
    leading_tpose_frames,
    leg_length,
    level_floor,
    rotation_to_y_up,
)
from samba.ingest.rigs import RigMap, map_rig

_CMU_NAME = re.compile(r"(\d+)_(\d+)$")
_MAX_REACH = 1e9
"""Largest joint coordinate accepted, in file units (1000 km in mm): beyond is corrupt data."""


@dataclass(frozen=True)
class BvhImportOptions:
    """How to turn a BVH file into a take.

    `fps`: the output rate (frames per second), None for the file's own.
    `skip_frames`: leading source frames to drop. `skip_tpose`: drop leading T-pose frames found by
    `samba.ingest.normalize.leading_tpose_frames` (otherwise they are kept with a warning).
    `units`: 'auto' or a key of `samba.ingest.normalize.UNITS`. `up`:
    'auto' or a signed axis such as '+z'. `handedness`: 'auto' (mirror data whose knees
    bend backwards), 'right' (keep) or 'left' (negate X). `rig`: a rig map, or None to
    detect one. `subject` / `action`: catalog labels ('' derives the subject from CMU
    style names such as 131_01). `max_file_bytes`: the largest file read (bytes; also
    of the .mcap takes of an import).
    """

    fps: float | None = 30.0
    skip_frames: int = 0
    skip_tpose: bool = False
    units: str = "auto"
    up: str = "auto"
    handedness: str = "auto"
    rig: RigMap | None = None
    subject: str = ""
    action: str = ""
    max_file_bytes: int = MAX_FILE_BYTES

    def __post_init__(self) -> None:
        problem = None if self.fps is None else frame_rate_problem(self.fps)
        if problem:
            raise ValueError(f"--fps: {problem}")
        if self.max_file_bytes <= 0:
            raise ValueError(f"--max-file-mb must be positive, got {self.max_file_bytes / 1e6:g}")
        if self.skip_frames < 0:
            raise ValueError(f"--skip-frames must be >= 0, got {self.skip_frames}")
        if self.units != "auto" and self.units not in UNITS:
            raise ValueError(
                f"--units must be auto or one of {', '.join(UNITS)}, got {self.units!r}"
            )
        if self.up != "auto" and self.up not in UP_AXES:
            raise ValueError(f"--up must be auto or one of {', '.join(UP_AXES)}, got {self.up!r}")
        if self.handedness not in ("auto", "right", "left"):
            raise ValueError(f"--handedness must be auto, right or left, got {self.handedness!r}")


def load_bvh_take(path: str | Path, options: BvhImportOptions | None = None) -> Take:
    """Read a BVH file of any supported rig as a `Take` of 13-joint poses in meters, +Y up.

    Raises `BvhError` / `RigError` naming the file (and line) on bad input.
    """
    options = options or BvhImportOptions()
    path = Path(path)
    source = str(path)
    data = read_input(path, options.max_file_bytes, BvhError)

    def sample(n_frames: int, source_fps: float) -> np.ndarray:
        try:
            return _source_times(n_frames, source_fps, options, source) + options.skip_frames
        except BvhError:  # raised again below, once the file is read
            return np.zeros(0)

    bvh = parse_bvh(data, source=source, sample=sample)
    rig, joints = map_rig(bvh.names, source, bvh.skeleton, options.rig)
    fps = options.fps or bvh.fps
    times = _source_times(bvh.n_frames, bvh.fps, options, source)
    with np.errstate(over="ignore", invalid="ignore"):
        positions = bvh.sampled_positions(joints, times + options.skip_frames)
    reach = float(np.abs(positions).max())
    if not reach < _MAX_REACH:  # also catches NaN from overflowing values
        raise BvhError(
            source, f"joint positions reach {reach:.3g} file units: offsets or motion out of range"
        )

    warnings: list[str] = []
    units = detect_units(positions) if options.units == "auto" else options.units
    positions = positions * UNITS[units]
    up = detect_up(positions) if options.up == "auto" else options.up
    positions = positions @ rotation_to_y_up(up).T
    handedness = options.handedness
    if handedness == "auto":
        score = chirality(positions)
        handedness = "left" if score < -0.5 else "right"
        if handedness == "left":
            warnings.append(f"knees bend backwards (chirality {score:+.2f}): mirrored X")
    if handedness == "left":
        positions[..., 0] *= -1.0
    tpose = leading_tpose_frames(positions)
    if tpose == len(positions):
        tpose = 0
    first = 0
    if tpose and options.skip_tpose:
        positions, first = positions[tpose:], tpose
    elif tpose:  # counted in the file's frames, whatever rate the take is read at
        held = int(np.ceil(times[tpose] - 1e-9))
        warnings.append(
            f"starts with {held} T-pose frame(s) ({held / bvh.fps:.2f} s); --skip-tpose drops them"
        )
    positions, tilt = level_floor(positions, fps)
    if tilt > 1.0:
        warnings.append(f"capture floor tilted {tilt:.1f} degrees: levelled")
    positions[..., 1] -= floor_height(positions, fps)
    leg = leg_length(positions)
    if not 0.4 <= leg <= 1.2:
        warnings.append(
            f"leg length {leg:.2f} m is implausible: is the file in {units}? (samba db "
            "import --units sets the unit)"
        )

    subject = options.subject
    match = _CMU_NAME.search(path.stem)
    if not subject and match:
        subject = str(int(match.group(1)))
    return Take(
        name=path.stem,
        poses=positions,
        fps=fps,
        source=str(path.resolve()),
        content_hash=hashlib.sha256(data).hexdigest(),
        rig=rig.name,
        subject=subject,
        action=options.action,
        frames=np.arange(first, first + len(positions)),
        source_frames=bvh.n_frames,
        warnings=warnings,
        meta={
            "units": units,
            "up": up,
            "source_fps": f"{bvh.fps:.3f}",
            "handedness": handedness,
            "floor_tilt_deg": f"{tilt:.2f}",
        },
    )


def _source_times(
    n_frames: int, source_fps: float, options: BvhImportOptions, source: str
) -> np.ndarray:
    """The fractional frames (m,) after `options.skip_frames` of a file of `n_frames`
    frames at `source_fps` that its take samples (at `options.fps`); raises `BvhError`
    naming `source` when they are none or too many."""
    if options.skip_frames >= n_frames:
        raise BvhError(source, f"--skip-frames {options.skip_frames} drops all {n_frames} frames")
    fps = options.fps or source_fps
    frames_out = int((n_frames - 1 - options.skip_frames) * fps / source_fps) + 1
    problem = frame_count_problem(frames_out)
    if problem:
        raise BvhError(source, f"read at {fps:g} fps: {problem}")
    return resample_times(n_frames - options.skip_frames, source_fps, fps)
