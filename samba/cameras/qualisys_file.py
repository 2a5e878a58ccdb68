"""Qualisys Track Manager (QTM) calibrations: the `.qca` XML file (often saved as `.qca.txt`).

The layout, as QTM writes it and the Qualisys SDKs parse it (every number an attribute):

    <calibration ...>
      <cameras>
        <camera serial="cam01" viewrotation="0" [video_resolution="1080p"] ...>
          <fov_video left="0" top="0" right="1087" bottom="1919"/>
          <transform x="1460.2" y="-1909.2" z="1896.5" r11="0.55" r12="0.80" ... r33="0.38"/>
          <intrinsic focalLengthU="107599.7" focalLengthV="107588.8" centerPointU="34110.3"
                     centerPointV="60680.8" skew="0" radialDistortion1="-0.046"
                     radialDistortion2="0.140" radialDistortion3="0" tangentalDistortion1="0.0006"
                     tangentalDistortion2="0.0007" .../>
        </camera>
        ...

(the root may also be a `QTM_Parameters` element holding `calibration`, as QTM's real-time
protocol sends it). Its conventions, taken from Pose2Sim's QTM converter (`read_qca` and
`calib_qca_fun` of `Pose2Sim/calibration.py`) and checked on the lab calibration and videos
of `../shared/data/pose2sim` (tests/test_foreign_calibrations.py):

* The lab frame is QTM's, in millimetres: `x y z` of `transform` is the camera's optical
  centre. QTM's default lab frame has +Z up; `read_calibration` turns it to ours.
* The matrix M = [[r11 r12 r13], [r21 r22 r23], [r31 r32 r33]] takes lab directions to
  QTM's camera frame (its rows are the camera's axes in the lab), whose camera looks along
  its -z with its y up the image. OpenCV's camera looks along +z with y down the image, so
  the world-to-camera rotation is R = diag(1, -1, -1) @ M and t = -R @ centre. (The
  columns instead put every camera of the lab file facing away from the walkway.)
* Intrinsics are in sub-pixels, 64 to a pixel, of the sensor: fx = focalLengthU / 64,
  cx = centerPointU / 64 - left of `fov_video`, the sensor window the video shows, whose
  bounds are inclusive pixels (width = right - left + 1).
* `video_resolution` ("720p", ...) scales that window and the intrinsics by res / 1080
  (Pose2Sim), the pixel grid as `with_size` scales it; absent, the video is the window.
* Distortion is OpenCV's model of normalised coordinates, taken as written: k1, k2, k3 =
  radialDistortion1..3, p1, p2 = tangentalDistortion1..2. Pose2Sim divides these by 64
  too, which leaves next to no distortion; `samba calibrate` on the lab's checkerboard
  photos of cam02 finds k1 = -0.054, k2 = 0.142, where the file has -0.048, 0.137.
* A camera with a `viewrotation` other than 0 (QTM shows its image turned by 90, 180 or
  270 degrees) or a non-zero `skew` is refused: how either relates to a video's pixels is
  not documented.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from samba.base import InputError
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.synthetic_cameras import with_size

SUBPIXELS = 64.0
"""QTM's sub-pixel units per pixel."""
QTM_TO_OPENCV = np.diag([1.0, -1.0, -1.0])
"""Takes QTM's camera frame (looking along -z, y up) to OpenCV's (along +z, y down)."""
ROTATION_TOLERANCE = 1e-4
"""Largest deviation of M M^T from the identity accepted as a rotation (the files give
r11..r33 to about 1e-9; QTM's own exports to 6 decimals)."""
_TRANSFORM = ("x", "y", "z", "r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33")
_INTRINSIC = (
    "focalLengthU",
    "focalLengthV",
    "centerPointU",
    "centerPointV",
    "radialDistortion1",
    "radialDistortion2",
    "radialDistortion3",
    "tangentalDistortion1",
    "tangentalDistortion2",
)
_FOV = ("left", "top", "right", "bottom")


def read_qualisys(path: str | os.PathLike[str]) -> CameraGroup:
    """The cameras of a QTM calibration file, in its lab frame and millimetres.

    Cameras keep the file's order and are named by their `serial`; pixels are the video
    image's (see the module docstring). `read_calibration` converts the result to meters
    and +Y up. InputError naming the file (and the camera and field) when it is missing,
    not XML, not a QTM calibration, or a camera lacks or has a malformed field.
    """
    source = str(path)
    try:
        root = ET.parse(path).getroot()
    except OSError as exc:
        raise InputError(source, exc.strerror or str(exc)) from None
    except ET.ParseError as exc:
        raise InputError(source, f"not a Qualisys calibration: not XML ({exc})") from None
    calibration = root if root.tag == "calibration" else root.find("calibration")
    if calibration is None:
        raise InputError(
            source, f"not a Qualisys calibration: no <calibration> element (root <{root.tag}>)"
        )
    elements = calibration.findall("cameras/camera")
    if not elements:
        raise InputError(source, "no <camera> elements in <calibration><cameras>")
    cameras = [_camera(source, i, element) for i, element in enumerate(elements)]
    names = [camera.name for camera in cameras]
    for name in names:
        if names.count(name) > 1:
            raise InputError(source, f"camera serial {name!r} is used by more than one camera")
    return CameraGroup(tuple(cameras))


def _camera(source: str, index: int, element: ET.Element) -> Camera:
    """Camera `index` of the file, in the lab frame (millimetres)."""
    name = element.get("serial") or f"camera{index + 1}"

    def fail(problem: str) -> InputError:
        return InputError(source, f"camera {index + 1} ({name}): {problem}")

    rotation = element.get("viewrotation", "0")
    if rotation.strip() not in ("0", "0.0"):
        raise fail(
            f"viewrotation {rotation}: turned camera views are not supported "
            "(only the sensor's own orientation, viewrotation 0)"
        )
    transform = _numbers(element, "transform", _TRANSFORM, fail)
    intrinsic = _numbers(element, "intrinsic", _INTRINSIC, fail)
    fov = _numbers(element, "fov_video", _FOV, fail)
    skew = _numbers(element, "intrinsic", ("skew",), fail, optional=True).get("skew", 0.0)
    if skew != 0.0:
        raise fail(f"intrinsic skew {skew:g}: a skewed pixel grid is not supported")
    width, height = fov["right"] - fov["left"] + 1, fov["bottom"] - fov["top"] + 1
    if not (width >= 1 and height >= 1 and width == int(width) and height == int(height)):
        raise fail(f"fov_video {fov}: not a window of whole pixels")
    fx, fy = intrinsic["focalLengthU"] / SUBPIXELS, intrinsic["focalLengthV"] / SUBPIXELS
    if not (fx > 0 and fy > 0):
        raise fail(f"intrinsic focal lengths must be positive, got {fx:g}, {fy:g} pixels")
    cx = intrinsic["centerPointU"] / SUBPIXELS - fov["left"]
    cy = intrinsic["centerPointV"] / SUBPIXELS - fov["top"]
    lab_to_qtm = np.array([transform[k] for k in _TRANSFORM[3:]]).reshape(3, 3)
    if not (
        np.abs(lab_to_qtm @ lab_to_qtm.T - np.eye(3)).max() < ROTATION_TOLERANCE
        and np.linalg.det(lab_to_qtm) > 0
    ):
        raise fail("transform r11..r33 is not a rotation matrix")
    world_to_camera = QTM_TO_OPENCV @ lab_to_qtm
    centre = np.array([transform["x"], transform["y"], transform["z"]])
    camera = Camera(
        name=name,
        size=(int(width), int(height)),
        matrix=np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]),
        rotation=Rotation.from_matrix(world_to_camera).as_rotvec(),
        translation=-world_to_camera @ centre,
        distortion=np.array([intrinsic[k] for k in _INTRINSIC[4:]])[[0, 1, 3, 4, 2]],
    )
    resolution = element.get("video_resolution")
    if resolution is None:
        return camera
    lines = resolution.removesuffix("p")
    if not (lines.isdigit() and int(lines) > 0):
        raise fail(f"video_resolution {resolution!r}: expected lines and 'p', e.g. '720p'")
    scale = int(lines) / 1080
    return with_size(camera, (round(width * scale), round(height * scale)))


def _numbers(
    element: ET.Element,
    tag: str,
    keys: tuple[str, ...],
    fail: Callable[[str], InputError],
    optional: bool = False,
) -> dict[str, float]:
    """The attributes `keys` of the child `tag` of `element` as finite floats (an absent
    attribute is left out when `optional`); `fail(problem)` raised otherwise."""
    child = element.find(tag)
    if child is None:
        if optional:
            return {}
        raise fail(f"<{tag}> missing")
    values = {}
    for key in keys:
        text = child.get(key)
        if text is None:
            if optional:
                continue
            raise fail(f"{tag} {key}: missing")
        try:
            value = float(text)
        except ValueError:
            raise fail(f"{tag} {key}: not a number: {text!r}") from None
        if not math.isfinite(value):
            raise fail(f"{tag} {key}: {text!r} is not finite")
        values[key] = value
    return values
