"""Calibrating cameras from their recordings of a board (`samba calibrate`).

Each recording is one camera: a folder of images or a video file
(`samba.cameras.frame_source`); frame n of every camera is the same instant. The board is found
in every frame (`samba.cameras.calibration_board`), the cameras are calibrated jointly
(`samba.cameras.calibration`), or one camera's lens alone (`calibrate_lens_recording`), and
written as a calibration file (`samba.cameras.calibration_file`). A camera is named after
its folder or video file (without the extension).
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from tqdm import tqdm

from samba.base import InputError
from samba.cameras.calibration import (
    MIN_VIEWS,
    OUTLIER_FACTOR,
    OUTLIER_MARGIN_PX,
    CalibrationResult,
    calibrate,
    calibrate_lens,
)
from samba.cameras.calibration_board import Board, BoardView, Detection
from samba.cameras.camera import CameraGroup
from samba.cameras.frame_source import FrameSource, open_frames

Log = Callable[[str], None]
"""Takes one line per image examined: camera, image and `Detection.summary`."""


@dataclass(frozen=True)
class CameraFrames:
    """One camera's recording as searched for the board: its `name`, image `size`
    (width, height) pixels, and per frame examined (frame number ->) its `labels` (the
    image's file name, or "frame N" of a video) and `detections`."""

    name: str
    size: tuple[int, int]
    labels: dict[int, str]
    detections: dict[int, Detection]

    @property
    def views(self) -> dict[int, BoardView]:
        """The frames in which the board was found -> its view there."""
        return {n: d.view for n, d in self.detections.items() if d.view is not None}


@dataclass(frozen=True)
class RecordingCalibration:
    """What `calibrate_recordings` or `calibrate_lens_recording` found and solved: the
    calibration `result` and each camera's `frames` as searched for the board."""

    result: CalibrationResult
    frames: list[CameraFrames]

    def report(self) -> str:
        """What `samba calibrate` prints: per camera the frames examined, those with the
        board, those used, the reprojection error, intrinsics and position (m); then each
        image's reprojection error in the first lens solve, the images dropped as
        outliers, and the world frame."""
        result = self.result
        lines = camera_table(
            result.cameras,
            [
                (f.name, len(f.detections), len(f.views), int(used), float(rms))
                for f, used, rms in zip(self.frames, result.views, result.rms_px, strict=True)
            ],
        )
        solve = "the lens solve" if result.world is None else "the joint adjustment"
        lines.append(
            "frames: examined; board: frames in which the board was found; used: of those, in"
        )
        lines.append(f"{solve}; rms px: reprojection error there")
        lines += self._image_errors()
        if result.world is None:
            lines.append("intrinsics only: the camera at the origin, rotation and translation zero")
        elif result.world == "board":
            lines.append(
                f"world: the board on the floor in frame {result.floor_frame} is y = 0, "
                "+Y up, origin at its first corner, meters"
            )
        else:
            lines.append(
                f"world: camera {result.cameras[0].name} at the origin looking along -Z, +Y up"
            )
        return "\n".join(lines)

    def _image_errors(self) -> list[str]:
        """The per-image errors of every camera's first lens solve and the images dropped."""
        lines = ["reprojection error per image, px (each camera's first lens solve):"]
        dropped = []
        for frames, lens in zip(self.frames, self.result.intrinsics, strict=True):
            entries = [f"{frames.labels[n]} {e:.3f}" for n, e in lens.view_rms_px.items()]
            lines += textwrap.wrap(
                ", ".join(entries),
                width=88,
                initial_indent=f"  {frames.name}: ",
                subsequent_indent="    ",
                break_on_hyphens=False,
            )
            for n in lens.dropped:
                dropped.append(
                    f"{frames.name}: dropped {frames.labels[n]} as an outlier "
                    f"({lens.view_rms_px[n]:.2f} px > {lens.limit_px:.2f} px = max("
                    f"{OUTLIER_FACTOR:g} x median, median + {OUTLIER_MARGIN_PX:g} px)); "
                    f"lens solved again on {len(lens.used)} images"
                )
        return lines + dropped


def camera_table(
    cameras: CameraGroup, counts: Sequence[tuple[str, int, int, int, float]] | None = None
) -> list[str]:
    """A table of `cameras`, one line each: name, image size, focal lengths fx, fy and
    principal point cx, cy (pixels) and position (m); with `counts` (per camera: name,
    frames examined, frames with the board, frames used, RMS error px) those instead of
    the size. Returns the lines, header first."""
    width = max(12, *(len(camera.name) for camera in cameras))
    middle = f"{'frames':>6} {'board':>6} {'used':>5} {'rms px':>7}" if counts else f"{'size':>11}"
    header = f"{'camera':<{width}} {middle} {'fx':>8} {'fy':>8} {'cx':>7} {'cy':>7}  position (m)"
    lines = [header, "-" * len(header)]
    for i, camera in enumerate(cameras):
        k = camera.matrix
        x, y, z = camera.center
        if counts:
            _, examined, found, used, rms = counts[i]
            middle = f"{examined:>6} {found:>6} {used:>5} {rms:>7.3f}"
        else:
            middle = f"{f'{camera.size[0]}x{camera.size[1]}':>11}"
        lines.append(
            f"{camera.name:<{width}} {middle} {k[0, 0]:>8.1f} {k[1, 1]:>8.1f} {k[0, 2]:>7.1f} "
            f"{k[1, 2]:>7.1f}  ({x:6.3f}, {y:6.3f}, {z:6.3f})"
        )
    return lines


def calibrate_recordings(
    paths: Sequence[str],
    board: Board,
    world: str = "board",
    floor_frame: int | None = None,
    every: int = 1,
    refine_intrinsics: bool = False,
    log: Log | None = None,
) -> RecordingCalibration:
    """Calibrate the cameras of `paths` (one folder of images or video per camera; frame
    n of every camera is the same instant) from the `board` found in every `every`-th
    frame (`samba.cameras.calibration.calibrate` with `world`, `floor_frame` and
    `refine_intrinsics`). Cameras are named after their folder or video file; `log`, if
    given, takes a line per image saying which detector found the board or why none did.
    Raises `InputError` naming the flag or recording that is wrong."""
    sources = [open_frames(path) for path in paths]
    if floor_frame is not None and world != "board":
        raise InputError("--floor-frame", "applies to --world board only")
    if floor_frame is not None and floor_frame % every:
        raise InputError("--floor-frame", f"frame {floor_frame} is skipped by --every")
    names = _camera_names(sources)
    frames = [
        _detect(board, source, name, every, log)
        for source, name in zip(sources, names, strict=True)
    ]
    result = calibrate(
        board,
        [f.views for f in frames],
        [f.size for f in frames],
        names,
        world=world,
        floor_frame=floor_frame,
        refine_intrinsics=refine_intrinsics,
    )
    return RecordingCalibration(result, frames)


def calibrate_lens_recording(
    path: str, board: Board, every: int = 1, log: Log | None = None
) -> RecordingCalibration:
    """One camera's intrinsics alone (`samba.cameras.calibration.calibrate_lens`) from the
    `board` in every `every`-th frame of `path` (a folder of images or a video); `log`
    as for `calibrate_recordings`. InputError naming the recording when the board is
    found in too few frames."""
    source = open_frames(path)
    frames = _detect(board, source, _camera_names([source])[0], every, log)
    return RecordingCalibration(
        calibrate_lens(board, frames.views, frames.size, frames.name), [frames]
    )


def _camera_names(sources: Sequence[FrameSource]) -> list[str]:
    """Each source's folder name or video file stem; cam0, cam1, ... if they repeat."""
    names = [source.path.stem if source.is_video else source.path.name for source in sources]
    if len(set(names)) < len(names):
        return [f"cam{i}" for i in range(len(sources))]
    return names


def _detect(
    board: Board, source: FrameSource, name: str, every: int, log: Log | None
) -> CameraFrames:
    """The board looked for in a camera's frames; InputError when it is found in fewer
    than `MIN_VIEWS` frames."""
    detections: dict[int, Detection] = {}
    labels: dict[int, str] = {}
    size = (0, 0)
    frames = tqdm(source.frames(every), desc=str(source.path), unit="frame", disable=None)
    for number, image in frames:
        size = (image.shape[1], image.shape[0])
        detections[number] = board.find(image)
        labels[number] = source.label(number)
        if log is not None:
            log(f"{name}  {labels[number]}: {detections[number].summary}")
    camera = CameraFrames(name, size, labels, detections)
    count, found = len(detections), len(camera.views)
    hint = " (samba calibrate -v says why for each)" if log is None else ""
    if not found:
        raise InputError(
            str(source.path),
            f"the board ({board.spec}) was not found in any of its {count} frames{hint}",
        )
    if found < MIN_VIEWS:
        raise InputError(
            str(source.path),
            f"the board was found in only {found} of its {count} frames; calibration "
            f"needs at least {MIN_VIEWS}{hint}",
        )
    return camera
