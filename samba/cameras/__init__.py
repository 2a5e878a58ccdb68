"""Cameras: the calibrated camera model and camera groups, calibration from board images
(detection, bundle adjustment, recordings), calibration files of other tools and systems
(anipose, FreeMoCap, Pose2Sim, Qualisys QTM, EasyMocap), the frames of a camera (image
folders, videos), triangulation, and rendered photos of a board for trying it all.
"""

from samba.cameras.board_render import board_poses, floor_pose, render_board, stage_cameras
from samba.cameras.calibration import WORLDS
from samba.cameras.calibration_board import BOARD_SPEC_HELP, parse_board
from samba.cameras.calibration_file import (
    convert_calibration,
    read_calibration,
    write_calibration,
)
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.frame_io import read_frames, write_video
from samba.cameras.frame_source import (
    FrameSource,
    camera_frames,
    cut_note,
    open_frames,
    open_video,
    sized_frames,
)
from samba.cameras.recordings import (
    RecordingCalibration,
    calibrate_lens_recording,
    calibrate_recordings,
    camera_table,
)
from samba.cameras.synthetic_cameras import with_size
from samba.cameras.triangulation import Triangulation, triangulate, triangulate_cameras

__all__ = [
    "BOARD_SPEC_HELP",
    "WORLDS",
    "Camera",
    "CameraGroup",
    "FrameSource",
    "RecordingCalibration",
    "Triangulation",
    "board_poses",
    "calibrate_lens_recording",
    "calibrate_recordings",
    "camera_frames",
    "camera_table",
    "convert_calibration",
    "cut_note",
    "floor_pose",
    "open_frames",
    "open_video",
    "parse_board",
    "read_calibration",
    "read_frames",
    "render_board",
    "sized_frames",
    "stage_cameras",
    "triangulate",
    "triangulate_cameras",
    "with_size",
    "write_calibration",
    "write_video",
]
