"""Calibrating a group of cameras from their recordings of a board (`samba calibrate`).

Each recording is one camera: a folder of images or a video file
(`samba.cameras.frame_source`); frame n of every camera is the same instant. The board is found
in every frame (`samba.cameras.calibration_board`), the cameras are calibrated jointly
(`samba.cameras.calibration`) and written as a calibration file (`samba.cameras.calibration_file`).
A camera is named after its folder or video file (without the extension).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from tqdm import tqdm

from samba.base import InputError
from samba.cameras.calibration import MIN_VIEWS, CalibrationResult, calibrate
from samba.cameras.calibration_board import Board, BoardView
from samba.cameras.frame_source import FrameSource, open_frames


@dataclass(frozen=True)
class RecordingCalibration:
    """What `calibrate_recordings` found and solved: the calibration `result`, and per
    camera the frames examined and the board's views (frame number -> view)."""

    result: CalibrationResult
    frames: list[int]
    detections: list[dict[int, BoardView]]

    def report(self) -> str:
        """The table `samba calibrate` prints: per camera the frames examined, those with
        the board, those used, the reprojection error, intrinsics and position (m)."""
        result = self.result
        header = (
            f"{'camera':<12} {'frames':>6} {'board':>6} {'used':>5} {'rms px':>7} {'fx':>8} "
            f"{'fy':>8} {'cx':>7} {'cy':>7}  position (m)"
        )
        lines = [header, "-" * len(header)]
        for i, camera in enumerate(result.cameras):
            k = camera.matrix
            x, y, z = camera.center
            lines.append(
                f"{camera.name:<12} {self.frames[i]:>6} {len(self.detections[i]):>6} "
                f"{result.views[i]:>5} {result.rms_px[i]:>7.3f} {k[0, 0]:>8.1f} "
                f"{k[1, 1]:>8.1f} {k[0, 2]:>7.1f} {k[1, 2]:>7.1f}  ({x:6.3f}, {y:6.3f}, {z:6.3f})"
            )
        lines.append(
            "frames: examined; board: frames in which the board was found; used: of those, in"
        )
        lines.append("the joint adjustment; rms px: reprojection error there")
        if result.world == "board":
            lines.append(
                f"world: the board on the floor in frame {result.floor_frame} is y = 0, "
                "+Y up, origin at its first corner, meters"
            )
        else:
            lines.append(
                f"world: camera {result.cameras[0].name} at the origin looking along -Z, +Y up"
            )
        return "\n".join(lines)


def calibrate_recordings(
    paths: Sequence[str],
    board: Board,
    world: str = "board",
    floor_frame: int | None = None,
    every: int = 1,
    refine_intrinsics: bool = False,
) -> RecordingCalibration:
    """Calibrate the cameras of `paths` (one folder of images or video per camera; frame
    n of every camera is the same instant) from the `board` found in every `every`-th
    frame (`samba.cameras.calibration.calibrate` with `world`, `floor_frame` and
    `refine_intrinsics`). Cameras are named after their folder or video file. Raises
    `InputError` naming the flag or recording that is wrong."""
    sources = [open_frames(path) for path in paths]
    if floor_frame is not None and world != "board":
        raise InputError("--floor-frame", "applies to --world board only")
    if floor_frame is not None and floor_frame % every:
        raise InputError("--floor-frame", f"frame {floor_frame} is skipped by --every")
    detections, sizes, frames = [], [], []
    for source in sources:
        found, size, count = _detect(board, source, every)
        detections.append(found)
        sizes.append(size)
        frames.append(count)
    result = calibrate(
        board,
        detections,
        sizes,
        _camera_names(sources),
        world=world,
        floor_frame=floor_frame,
        refine_intrinsics=refine_intrinsics,
    )
    return RecordingCalibration(result, frames, detections)


def _camera_names(sources: Sequence[FrameSource]) -> list[str]:
    """Each source's folder name or video file stem; cam0, cam1, ... if they repeat."""
    names = [source.path.stem if source.is_video else source.path.name for source in sources]
    if len(set(names)) < len(names):
        return [f"cam{i}" for i in range(len(sources))]
    return names


def _detect(
    board: Board, source: FrameSource, every: int
) -> tuple[dict[int, BoardView], tuple[int, int], int]:
    """The board's views in a camera's frames (frame number -> view), the image size
    (width, height) and the number of frames examined. InputError when the board is found
    in fewer than `MIN_VIEWS` frames."""
    found: dict[int, BoardView] = {}
    size, count = (0, 0), 0
    frames = tqdm(source.frames(every), desc=str(source.path), unit="frame", disable=None)
    for number, image in frames:
        size, count = (image.shape[1], image.shape[0]), count + 1
        view = board.detect(image)
        if view is not None:
            found[number] = view
    if not found:
        raise InputError(
            str(source.path), f"the board ({board.spec}) was not found in any of its {count} frames"
        )
    if len(found) < MIN_VIEWS:
        raise InputError(
            str(source.path),
            f"the board was found in only {len(found)} of its {count} frames; calibration "
            f"needs at least {MIN_VIEWS}",
        )
    return found, size, count
