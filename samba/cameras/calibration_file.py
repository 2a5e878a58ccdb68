"""Calibration files: ours, the TOML layout of anipose (aniposelib), FreeMoCap and Pose2Sim,
and the calibrations of other systems read in their place.

The layout, as those tools write it (checked against aniposelib's `CameraGroup.dump` /
`Camera.get_dict`, a calibration in aniposelib's test data, and Pose2Sim's `toml_write`
and its demo `Calib.toml`):

    [cam_0]                       # aniposelib: cam_0, cam_1, ...; Pose2Sim: the camera's name
    name = "cam0"
    size = [640, 480]             # width, height; Pose2Sim writes floats (1088.0)
    matrix = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    distortions = [k1, k2, p1, p2, k3]   # aniposelib 5 values, Pose2Sim 4 (k3 = 0)
    rotation = [rx, ry, rz]       # Rodrigues vector of the world-to-camera rotation
    translation = [tx, ty, tz]    # x_cam = R @ x_world + t
    fisheye = false               # Pose2Sim always; aniposelib only for fisheye cameras

    [metadata]                    # aniposelib and Pose2Sim: adjusted (bool), error (px)
    adjusted = false
    error = 0.16

Every top-level table but `metadata` is a camera, read in file order (aniposelib
itself reloads its tables in sorted key order, which differs from ours from 11 cameras
on; the names stay with their cameras). A fisheye camera (`fisheye = true`, whose four
coefficients belong to OpenCV's other lens model) is refused. Other keys are ignored.

Units and axes: our world is meters with +Y up. The tools differ: Pose2Sim works in
meters with +Z up; aniposelib in the unit of the board's square side (often mm) with
the first camera's frame or the board as the world. `write_calibration` writes meters
and +Y up unless told otherwise and records both in `metadata` (`units`, `up`, our
additions, which the other tools ignore). `read_calibration` converts a file to our
frame from the units and up axis given as arguments, else from its `metadata`, else
assumes meters and +Y up. Up "+z" is Pose2Sim's convention, converted the way its
`zup2yup` converts its outputs: our (x, y, z) = the file's (y, z, x).

Other systems' calibrations are read by `read_calibration` too, chosen by the path
(`calibration_format`), and converted to our world from their own units and up axis
(the arguments override both):

* Qualisys QTM: a `.qca`, `.qca.txt` or `.xml` file (`samba.cameras.qualisys_file`),
  millimetres, +Z up (QTM's default lab frame);
* EasyMocap: a folder holding `intri.yml` and `extri.yml`, or either file with the other
  beside it (`samba.cameras.easymocap_file`), meters, +Z up (its board frame).

`convert_calibration` writes any of them as ours (`samba calibrate --convert`).
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import tomli_w
from scipy.spatial.transform import Rotation

from samba.base import InputError, write_text_atomic
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.easymocap_file import EXTRINSICS, INTRINSICS, read_easymocap
from samba.cameras.qualisys_file import read_qualisys

UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
"""Length units a calibration file may use, in meters."""
UP_AXES: dict[str, np.ndarray | None] = {
    "+y": None,
    "+z": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
}
"""Up axis of a file's world -> rotation taking our world coordinates to the file's
(None: the same axes)."""
METADATA = "metadata"
"""The table that is not a camera."""
MAX_IMAGE_SIDE = 32768
"""Largest image width or height (pixels) a camera table may give: past 8K video, and
far short of a size whose frames could not be allocated."""
MAX_TRANSLATION_M = 10_000.0
"""Largest translation component (meters) a camera table may give: a stage is meters
across; a value like 1e308 is a broken file whose projections overflow."""

PathLike = str | os.PathLike[str]
FOREIGN_FORMATS: dict[str, tuple[Callable[[PathLike], CameraGroup], str, str]] = {
    "qualisys": (read_qualisys, "mm", "+z"),
    "easymocap": (read_easymocap, "m", "+z"),
}
"""Other systems' calibrations: format -> (reader giving the cameras in the file's own
units and axes, its units, its up axis)."""


def calibration_format(path: PathLike) -> str:
    """The kind of calibration at `path`, by its name: "easymocap" for a folder or a file
    named intri.yml / extri.yml, "qualisys" for a .qca, .qca.txt or .xml file, else "toml"
    (ours, anipose's, FreeMoCap's and Pose2Sim's)."""
    path = Path(path)
    name = path.name.lower()
    if path.is_dir() or name in (INTRINSICS, EXTRINSICS):
        return "easymocap"
    if name.endswith((".qca", ".qca.txt", ".xml")):
        return "qualisys"
    return "toml"


def read_calibration(
    path: PathLike, units: str | None = None, up: str | None = None
) -> CameraGroup:
    """The cameras of a calibration, in our world frame (meters, +Y up).

    `path` is any calibration `calibration_format` knows. `units` (a key of `UNITS`) and
    `up` (a key of `UP_AXES`) say how the file's world is measured; None takes them from
    a TOML file's `metadata`, else meters and "+y", and for another system's file from its
    own convention (`FOREIGN_FORMATS`). InputError naming the file (and the camera and
    field) when the file is missing, is not of its format, or a camera lacks a field or
    has a malformed one.
    """
    source = str(path)
    kind = calibration_format(path)
    if kind in FOREIGN_FORMATS:
        read, file_units, file_up = FOREIGN_FORMATS[kind]
        return _reframed(
            source,
            read(path),
            UNITS[_choice(source, "units", units, {}, UNITS, file_units)],
            UP_AXES[_choice(source, "up", up, {}, UP_AXES, file_up)],
        )
    try:
        with open(path, "rb") as f:
            document = tomllib.load(f)
    except OSError as exc:
        raise InputError(source, exc.strerror or str(exc)) from None
    except UnicodeDecodeError:
        raise InputError(source, "not a TOML file: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(source, f"not a TOML file: {exc}") from None
    metadata = document.get(METADATA, {})
    if not isinstance(metadata, dict):
        raise InputError(source, f"[{METADATA}] must be a table")
    scale = UNITS[_choice(source, "units", units, metadata, UNITS, "m")]
    to_file = UP_AXES[_choice(source, "up", up, metadata, UP_AXES, "+y")]
    cameras = []
    for key, table in document.items():
        if key == METADATA:
            continue
        if not isinstance(table, dict):
            raise InputError(source, f"top-level key {key!r} is not a camera table")
        cameras.append(_camera(source, key, table, scale, to_file))
    if not cameras:
        raise InputError(source, "no camera tables")
    names = [camera.name for camera in cameras]
    for name in names:
        if names.count(name) > 1:
            raise InputError(source, f"camera name {name!r} is used by more than one table")
    return CameraGroup(tuple(cameras))


def write_calibration(
    path: PathLike,
    cameras: CameraGroup,
    error_px: float | None = None,
    units: str = "m",
    up: str = "+y",
) -> None:
    """Write `cameras` to `path` atomically in the layout of the module docstring.

    Tables are `cam_0`, `cam_1`, ... in the group's order with 5 distortion coefficients
    and integer sizes, as aniposelib writes them; `metadata` holds adjusted = false, the
    mean reprojection `error` in pixels when given, and `units` / `up` of the file's
    world, into which our world (meters, +Y up) is converted.
    """
    if units not in UNITS or up not in UP_AXES:
        raise ValueError(f"units must be one of {list(UNITS)} and up one of {list(UP_AXES)}")
    scale, to_file = UNITS[units], UP_AXES[up]
    document: dict[str, object] = {}
    for i, camera in enumerate(cameras):
        rotation = _turned(camera.rotation, None if to_file is None else to_file.T)
        document[f"cam_{i}"] = {
            "name": camera.name,
            "size": list(camera.size),
            "matrix": camera.matrix.tolist(),
            "distortions": camera.distortion.tolist(),
            "rotation": rotation.tolist(),
            "translation": (camera.translation / scale).tolist(),
            "fisheye": False,
        }
    metadata: dict[str, object] = {"adjusted": False}
    if error_px is not None:
        metadata["error"] = float(error_px)
    metadata.update(units=units, up=up)
    document[METADATA] = metadata
    write_text_atomic(path, tomli_w.dumps(document))


def convert_calibration(
    source: PathLike, target: PathLike, units: str | None = None, up: str | None = None
) -> CameraGroup:
    """Write the calibration `source` (any `read_calibration` reads, `units` and `up` as
    there) to `target` as ours (meters, +Y up, atomically); returns its cameras."""
    cameras = read_calibration(source, units, up)
    write_calibration(target, cameras)
    return cameras


def _reframed(
    source: str, cameras: CameraGroup, scale: float, to_file: np.ndarray | None
) -> CameraGroup:
    """`cameras` of a world measured in units of `scale` meters whose axes `to_file` takes
    ours to (None: the same axes), in our world; InputError naming `source` for a camera
    implausibly far from the origin."""
    moved = []
    for camera in cameras:
        translation = camera.translation * scale
        if np.abs(translation).max() > MAX_TRANSLATION_M:
            raise InputError(
                source,
                f"camera {camera.name!r}: more than {MAX_TRANSLATION_M:g} m from the world origin",
            )
        rotation = _turned(camera.rotation, to_file)
        moved.append(dataclasses.replace(camera, rotation=rotation, translation=translation))
    return CameraGroup(tuple(moved))


def _choice(
    source: str,
    key: str,
    given: str | None,
    metadata: Mapping[str, object],
    allowed: Mapping[str, object],
    default: str,
) -> str:
    """The `given` value (ValueError if not allowed), else the metadata's (InputError if
    not allowed), else the default."""
    if given is not None:
        if given not in allowed:
            raise ValueError(f"{key} must be one of {list(allowed)}, got {given!r}")
        return given
    value = metadata.get(key, default)
    if not (isinstance(value, str) and value in allowed):
        raise InputError(
            source, f"[{METADATA}] {key}: must be one of {list(allowed)}, got {value!r}"
        )
    return value


def _camera(
    source: str, key: str, table: Mapping[str, object], scale: float, to_file: np.ndarray | None
) -> Camera:
    """The camera of table `key`, in our world frame."""

    def fail(field: str, problem: str) -> InputError:
        return InputError(source, f"[{key}] {field}: {problem}")

    for field in ("name", "size", "matrix", "distortions", "rotation", "translation"):
        if field not in table:
            raise fail(field, "missing")
    name = table["name"]
    if not isinstance(name, str) or not name:
        raise fail("name", f"must be a non-empty string, got {name!r}")
    fisheye = table.get("fisheye", False)
    if not isinstance(fisheye, bool):
        raise fail("fisheye", f"must be true or false, got {fisheye!r}")
    if fisheye:
        raise fail("fisheye", "fisheye lenses are not supported (OpenCV's pinhole model only)")
    size = _numbers(table["size"], (2,), lambda p: fail("size", p))
    if not all(1 <= s <= MAX_IMAGE_SIDE and s == int(s) for s in size):
        raise fail(
            "size",
            f"must be two positive whole numbers of pixels [width, height], at most "
            f"{MAX_IMAGE_SIDE}, got {[float(v) for v in size]}",
        )
    matrix = _numbers(table["matrix"], (3, 3), lambda p: fail("matrix", p))
    if not (matrix[0, 0] > 0 and matrix[1, 1] > 0):
        raise fail(
            "matrix",
            f"focal lengths fx, fy must be positive pixels, got {matrix[0, 0]:g}, {matrix[1, 1]:g}",
        )
    distortions = table["distortions"]
    if not (isinstance(distortions, list) and len(distortions) in (4, 5)):
        raise fail("distortions", f"must be 4 or 5 numbers (k1 k2 p1 p2 [k3]), got {distortions!r}")
    distortion = _numbers(distortions, (len(distortions),), lambda p: fail("distortions", p))
    rotation = _numbers(table["rotation"], (3,), lambda p: fail("rotation", p))
    translation = _numbers(table["translation"], (3,), lambda p: fail("translation", p))
    if np.abs(translation * scale).max() > MAX_TRANSLATION_M:
        raise fail("translation", f"more than {MAX_TRANSLATION_M:g} m from the world origin")
    if matrix[2, 2] == 0:
        raise fail("matrix", "the last element is 0")
    return Camera(
        name=name,
        size=(int(size[0]), int(size[1])),
        matrix=matrix,
        rotation=_turned(rotation, to_file),
        translation=translation * scale,
        distortion=np.pad(distortion, (0, 5 - len(distortion))),
    )


def _numbers(
    value: object, shape: tuple[int, ...], fail: Callable[[str], InputError]
) -> np.ndarray:
    """`value` as a float array of `shape`, or the InputError `fail(problem)` raised."""
    wanted = " x ".join(str(n) for n in shape) + " numbers"
    if not _is_nested_numbers(value, shape):
        raise fail(f"must be {wanted}, got {value!r}")
    array = np.array(value, dtype=np.float64)
    if not np.isfinite(array).all():
        raise fail(f"contains NaN or infinity: {value!r}")
    return array


def _is_nested_numbers(value: object, shape: tuple[int, ...]) -> bool:
    """Whether `value` is nested lists of the given shape holding ints or floats."""
    if not shape:
        return isinstance(value, int | float) and not isinstance(value, bool)
    return (
        isinstance(value, list)
        and len(value) == shape[0]
        and all(_is_nested_numbers(item, shape[1:]) for item in value)
    )


def _turned(rotation_vector: np.ndarray, axes: np.ndarray | None) -> np.ndarray:
    """The Rodrigues vector (3,) of the world-to-camera rotation after a change of world
    axes: R @ axes, where `axes` (3, 3) takes the new world's coordinates to the old
    one's; None leaves the vector exactly as it is."""
    vector = np.array(rotation_vector, dtype=np.float64)  # a writable copy, for scipy
    if axes is None:
        return vector
    return (Rotation.from_rotvec(vector) * Rotation.from_matrix(axes)).as_rotvec()
