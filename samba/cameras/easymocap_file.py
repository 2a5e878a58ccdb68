"""EasyMocap calibrations: `intri.yml` and `extri.yml`, OpenCV FileStorage (YAML) files.

The layout, as EasyMocap's `write_camera` / `read_camera` (`easymocap/mytools/camera_utils.py`)
write and read it, for cameras named in `names`:

    intri.yml                               extri.yml
    names: ["01", "02", ...]                names: ["01", "02", ...]
    K_01: !!opencv-matrix 3 x 3, pixels     R_01: !!opencv-matrix 3 x 1, Rodrigues vector
    dist_01: 1 x 5 (k1 k2 p1 p2 k3) or 1 x 4  Rot_01: 3 x 3, the same rotation as a matrix
    H_01: 1080, W_01: 1920 (optional)       T_01: 3 x 1, meters

Conventions (EasyMocap's documentation: "RX + T converts point X in world coordinate to
camera coordinate", "the metric of T must be meter"):

* R and T are OpenCV's world-to-camera pose, x_cam = R @ x_world + T, and K, dist OpenCV's
  pinhole intrinsics and distortion, so they are taken as they are. `R_` is read, else
  `Rot_`; `dist_`, else `D_` (as EasyMocap reads them). Names that are numbers are read as
  their digits and the name "none" is skipped, as EasyMocap does.
* The image size is `W_` x `H_`; EasyMocap makes both optional, and without them the size
  is taken as twice the principal point (EasyMocap's own guess of a camera puts it at
  W / 2, H / 2; Pose2Sim's converter does the same).
* The world is the calibration board's frame (the board lying on the floor for
  `calib_extri`), in meters. EasyMocap's check of a calibration draws a unit cube standing
  on the board from z = 0 to z = 1, so +Z is up; `read_calibration` turns it to ours.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from samba.base import InputError
from samba.cameras.camera import Camera, CameraGroup

INTRINSICS = "intri.yml"
EXTRINSICS = "extri.yml"
"""EasyMocap's two file names."""


def easymocap_paths(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """The (intri.yml, extri.yml) of `path`: a folder holding both, or either file with
    the other beside it."""
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    return folder / INTRINSICS, folder / EXTRINSICS


def read_easymocap(path: str | os.PathLike[str]) -> CameraGroup:
    """The cameras of an EasyMocap calibration, in its world frame and units (meters).

    `path` is the folder holding `intri.yml` and `extri.yml`, or either file with the
    other beside it. Cameras keep the order of `names` in intri.yml. InputError naming
    the file (and the camera and key) when a file is missing, is not a FileStorage file,
    or a camera lacks a key or has a malformed one.
    """
    intri_path, extri_path = easymocap_paths(path)
    intri, extri = _open(intri_path), _open(extri_path)
    names = _names(intri, str(intri_path))
    if not names:
        raise InputError(str(intri_path), "names: no cameras")
    extri_names = set(_names(extri, str(extri_path)))
    cameras = []
    for name in names:
        if name not in extri_names:
            raise InputError(str(extri_path), f"names: camera {name!r} of {INTRINSICS} missing")
        cameras.append(_camera(name, intri, str(intri_path), extri, str(extri_path)))
    if len(set(names)) < len(names):
        raise InputError(str(intri_path), "names: a camera is named more than once")
    return CameraGroup(tuple(cameras))


def _open(path: Path) -> cv2.FileStorage:
    """The FileStorage of `path` opened for reading; InputError when it cannot be."""
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise InputError(str(path), exc.strerror or str(exc)) from None
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # OpenCV's parse errors come wrapped in SystemError
        message = str(exc.__cause__ or exc).strip().splitlines()[-1]
        reason = re.search(r"error: \([^)]*\) (.*)", message)
        detail = reason.group(1) if reason else message
        raise InputError(str(path), f"not an OpenCV FileStorage file: {detail}") from None
    if not storage.isOpened():
        raise InputError(str(path), "not an OpenCV FileStorage file")
    return storage


def _names(storage: cv2.FileStorage, source: str) -> list[str]:
    """The camera names of the `names` sequence (numbers as their digits, "none" left out)."""
    node = storage.getNode("names")
    if node.empty() or not node.isSeq():
        raise InputError(source, "names: missing, or not a sequence of camera names")
    names = []
    for i in range(node.size()):
        item = node.at(i)
        if item.isString():
            name = item.string()
        elif item.isInt() or item.isReal():
            name = str(int(item.real()))
        else:
            raise InputError(source, f"names: item {i + 1} is not a name")
        if name != "none":
            names.append(name)
    return names


def _camera(
    name: str, intri: cv2.FileStorage, intri_source: str, extri: cv2.FileStorage, extri_source: str
) -> Camera:
    """The camera `name` from its keys in the two files."""
    matrix = _matrix(intri, intri_source, [f"K_{name}"], [(3, 3)])
    if not (matrix[0, 0] > 0 and matrix[1, 1] > 0 and matrix[2, 2] != 0):
        raise InputError(intri_source, f"K_{name}: focal lengths must be positive pixels")
    shapes = [(1, 5), (5, 1), (1, 4), (4, 1)]
    distortion = _matrix(intri, intri_source, [f"dist_{name}", f"D_{name}"], shapes).ravel()
    size = [_whole(intri, intri_source, f"{key}_{name}") for key in ("W", "H")]
    width, height = (
        round(2 * centre) if given is None else given
        for given, centre in zip(size, matrix[:2, 2], strict=True)
    )
    if not (width >= 1 and height >= 1):
        raise InputError(intri_source, f"W_{name}, H_{name}: image size {width}x{height}")
    if extri.getNode(f"R_{name}").empty():
        turn = _matrix(extri, extri_source, [f"Rot_{name}"], [(3, 3)])
        if not (np.abs(turn @ turn.T - np.eye(3)).max() < 1e-4 and np.linalg.det(turn) > 0):
            raise InputError(extri_source, f"Rot_{name}: not a rotation matrix")
        rotation = Rotation.from_matrix(turn).as_rotvec()
    else:
        rotation = _matrix(extri, extri_source, [f"R_{name}"], [(3, 1), (1, 3)]).ravel()
    translation = _matrix(extri, extri_source, [f"T_{name}"], [(3, 1), (1, 3)]).ravel()
    return Camera(
        name=name,
        size=(width, height),
        matrix=matrix,
        rotation=rotation,
        translation=translation,
        distortion=np.pad(distortion, (0, 5 - len(distortion))),
    )


def _matrix(
    storage: cv2.FileStorage, source: str, keys: list[str], shapes: list[tuple[int, int]]
) -> np.ndarray:
    """The matrix of the first of `keys` present, of one of `shapes`, finite, float64."""
    for key in keys:
        node = storage.getNode(key)
        if node.empty():
            continue
        try:
            value = node.mat() if node.isMap() else None
        except cv2.error:  # a mapping that is not a matrix
            value = None
        if value is None:
            raise InputError(source, f"{key}: not an OpenCV matrix (!!opencv-matrix)")
        if value.shape not in shapes:
            wanted = " or ".join(f"{r} x {c}" for r, c in shapes)
            rows, columns = value.shape
            raise InputError(source, f"{key}: must be {wanted}, got {rows} x {columns}")
        value = value.astype(np.float64)
        if not np.isfinite(value).all():
            raise InputError(source, f"{key}: contains NaN or infinity")
        return value
    raise InputError(source, f"{' or '.join(keys)}: missing")


def _whole(storage: cv2.FileStorage, source: str, key: str) -> int | None:
    """The whole number under `key`, None when absent."""
    node = storage.getNode(key)
    if node.empty():
        return None
    if not (node.isInt() or node.isReal()) or node.real() != int(node.real()):
        raise InputError(source, f"{key}: must be a whole number of pixels")
    return int(node.real())
