"""Tests of the anipose / FreeMoCap / Pose2Sim calibration files
(`samba.cameras.calibration_file`)."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.cameras.calibration_file import read_calibration, write_calibration
from samba.cameras.camera import Camera, CameraGroup

# As aniposelib's CameraGroup.dump writes it (its test data, values shortened), in mm.
ANIPOSE_FILE = """\
[cam_0]
name = "cam088"
size = [ 1440, 1080,]
matrix = [ [ 1850.5, 0.0, 719.5,], [ 0.0, 1850.5, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.189, 0.0, 0.0, 0.0, 0.0,]
rotation = [ -0.0016, -0.0024, -0.0075,]
translation = [ 1.62, -0.60, 20.75,]

[cam_1]
name = "cam091"
size = [ 1440, 1080,]
matrix = [ [ 1807.3, 0.0, 719.5,], [ 0.0, 1807.3, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.213, 0.0, 0.0, 0.0, 0.0,]
rotation = [ -0.216, -2.976, 0.395,]
translation = [ 116.07, 257.24, 1396.73,]

[metadata]
adjusted = false
error = 0.163
"""

# As Pose2Sim's toml_write writes it (its demo Calib.toml, values shortened): tables named
# after the cameras, float sizes, four distortion coefficients, meters, Z up.
POSE2SIM_FILE = """\
[cam_01]
name = "cam_01"
size = [ 1088.0, 1920.0]
matrix = [ [ 1681.2, 0.0, 532.9], [ 0.0, 1681.0, 948.1], [ 0.0, 0.0, 1.0]]
distortions = [ -0.00072, 0.00218, 9.5e-06, 1.07e-05]
rotation = [ 1.688, 1.048, -0.419]
translation = [ 0.321, 0.956, 2.890]
fisheye = false

[cam_02]
name = "cam_02"
size = [ 1088.0, 1920.0]
matrix = [ [ 1673.7, 0.0, 534.4], [ 0.0, 1673.7, 963.2], [ 0.0, 0.0, 1.0]]
distortions = [ -0.00074, 0.00213, 1.5e-05, 4.5e-06]
rotation = [ 1.349, 1.596, -1.198]
translation = [ -0.111, 0.776, 3.067]
fisheye = false

[metadata]
adjusted = false
error = 0.0
"""


def _group() -> CameraGroup:
    """Three cameras with awkward numbers: distortion, skew-free K, rotations of all sizes."""
    rng = np.random.default_rng(5)
    cameras = []
    for i in range(3):
        rotation = rng.normal(size=3)
        rotation *= (0.3 + i) / np.linalg.norm(rotation)
        cameras.append(
            Camera(
                name=f"cam{i}" if i != 2 else "side left",
                size=(640 + 320 * i, 480 + 240 * i),
                matrix=np.array(
                    [
                        [rng.uniform(400, 900), 0.0, rng.uniform(300, 340)],
                        [0.0, rng.uniform(400, 900), rng.uniform(220, 260)],
                        [0.0, 0.0, 1.0],
                    ]
                ),
                rotation=rotation,
                translation=rng.normal(size=3) * 2.0,
                distortion=rng.normal(scale=0.05, size=5) / 3.0,
            )
        )
    return CameraGroup(tuple(cameras))


def _same(a: CameraGroup, b: CameraGroup) -> bool:
    return a.names == b.names and all(
        x.size == y.size
        and all(
            np.array_equal(getattr(x, f), getattr(y, f))
            for f in ("matrix", "rotation", "translation", "distortion")
        )
        for x, y in zip(a, b, strict=True)
    )


def test_round_trip_is_exact(tmp_path: Path) -> None:
    group = _group()
    path = tmp_path / "calib.toml"
    write_calibration(path, group, error_px=0.123)
    assert _same(read_calibration(path), group)
    assert not [p for p in tmp_path.iterdir() if p.name != "calib.toml"]  # no temp file left


def test_written_file_has_the_layout_aniposelib_and_pose2sim_read(tmp_path: Path) -> None:
    group = _group()
    path = tmp_path / "calib.toml"
    write_calibration(path, group, error_px=0.25)
    with open(path, "rb") as f:
        document = tomllib.load(f)
    assert list(document) == ["cam_0", "cam_1", "cam_2", "metadata"]
    assert document["metadata"] == {"adjusted": False, "error": 0.25, "units": "m", "up": "+y"}
    # aniposelib's CameraGroup.load: every key but metadata, sorted, through Camera.load_dict.
    tables = [document[k] for k in sorted(document) if k != "metadata"]
    for table, camera in zip(tables, group, strict=True):
        assert isinstance(table["name"], str) and table["name"] == camera.name
        assert table["size"] == list(camera.size) and all(type(s) is int for s in table["size"])
        assert np.array(table["matrix"]).shape == (3, 3)
        assert len(table["distortions"]) == 5 and len(table["rotation"]) == 3
        assert len(table["translation"]) == 3 and table["fisheye"] is False
        for key in ("matrix", "distortions", "rotation", "translation"):
            assert all(type(x) is float for x in _flat(table[key]))
        # Pose2Sim's read_toml / computeP: the same fields, used with cv2.Rodrigues.
        np.testing.assert_array_equal(table["rotation"], camera.rotation)
        np.testing.assert_array_equal(table["translation"], camera.translation)


def _flat(value: object) -> list[object]:
    return [y for x in value for y in _flat(x)] if isinstance(value, list) else [value]


def test_reads_anipose_files_with_their_units(tmp_path: Path) -> None:
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_FILE)
    in_mm = read_calibration(path, units="mm")
    as_is = read_calibration(path)  # no units in the metadata: meters assumed
    assert in_mm.names == ("cam088", "cam091")
    assert in_mm["cam091"].size == (1440, 1080)
    np.testing.assert_allclose(in_mm[1].translation, [0.11607, 0.25724, 1.39673])
    np.testing.assert_allclose(in_mm[1].center * 1000.0, as_is[1].center)
    np.testing.assert_array_equal(in_mm[0].distortion, [-0.189, 0.0, 0.0, 0.0, 0.0])
    path.write_text(ANIPOSE_FILE.replace("error = 0.163", 'error = 0.163\nunits = "mm"'))
    np.testing.assert_array_equal(read_calibration(path)[1].translation, in_mm[1].translation)
    np.testing.assert_array_equal(
        read_calibration(path, units="m")[1].translation, as_is[1].translation
    )


def test_reads_pose2sim_files_and_turns_z_up_into_y_up(tmp_path: Path) -> None:
    path = tmp_path / "Calib.toml"
    path.write_text(POSE2SIM_FILE)
    z_up = read_calibration(path, up="+z")
    as_is = read_calibration(path)
    assert z_up.names == ("cam_01", "cam_02") and z_up[0].size == (1088, 1920)
    np.testing.assert_array_equal(z_up[0].distortion, [-0.00072, 0.00218, 9.5e-06, 1.07e-05, 0])
    # Pose2Sim's zup2yup: our (x, y, z) is the file's (y, z, x).
    np.testing.assert_allclose(z_up[1].center, as_is[1].center[[1, 2, 0]], atol=1e-12)
    file_points = np.random.default_rng(6).uniform(-1, 1, (10, 3))
    np.testing.assert_allclose(
        z_up[1].project(file_points[:, [1, 2, 0]]), as_is[1].project(file_points), atol=1e-9
    )


@pytest.mark.parametrize(("units", "up"), [("mm", "+y"), ("m", "+z"), ("cm", "+z"), ("in", "+y")])
def test_writes_other_units_and_axes_and_reads_them_back(
    tmp_path: Path, units: str, up: str
) -> None:
    group = _group()
    path = tmp_path / "calib.toml"
    write_calibration(path, group, units=units, up=up)
    back = read_calibration(path)
    for camera, read in zip(group, back, strict=True):
        np.testing.assert_allclose(read.rotation_matrix, camera.rotation_matrix, atol=1e-12)
        np.testing.assert_allclose(read.translation, camera.translation, atol=1e-12)
    if units == "mm":
        with open(path, "rb") as f:
            table = tomllib.load(f)["cam_1"]
        np.testing.assert_allclose(table["translation"], group[1].translation * 1000.0)


GOOD_TABLE = {
    "name": '"cam0"',
    "size": "[640, 480]",
    "matrix": "[[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]",
    "distortions": "[0.0, 0.0, 0.0, 0.0, 0.0]",
    "rotation": "[0.0, 0.0, 0.0]",
    "translation": "[0.0, 0.0, 3.0]",
}


def _file(tmp_path: Path, **changes: str | None) -> Path:
    fields = {**GOOD_TABLE, **changes}
    body = "\n".join(f"{k} = {v}" for k, v in fields.items() if v is not None)
    path = tmp_path / "bad.toml"
    path.write_text(f"[cam_0]\n{body}\n")
    return path


@pytest.mark.parametrize(
    ("field", "value", "problem"),
    [
        ("name", None, "missing"),
        ("matrix", None, "missing"),
        ("translation", None, "missing"),
        ("name", "3", "non-empty string"),
        ("size", "[640, 480, 3]", "2 numbers"),
        ("size", "[640.5, 480]", "whole numbers"),
        ("size", "[0, 480]", "positive"),
        ("size", "[1000000000, 480]", "at most 32768"),
        ("matrix", "[[500.0, 0.0, 320.0], [0.0, 500.0, 240.0]]", "3 x 3 numbers"),
        ("matrix", "[[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 0.0]]", "last element"),
        ("matrix", "[[0.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]", "focal lengths"),
        ("matrix", "[[500.0, 0.0, 320.0], [0.0, -5.0, 240.0], [0.0, 0.0, 1.0]]", "focal lengths"),
        ("distortions", "[0.1, 0.0, 0.0]", "4 or 5 numbers"),
        ("distortions", "[0.1, 0.0, 0.0, 0.0, 0.0, 0.0]", "4 or 5 numbers"),
        ("rotation", "[0.0, 0.0]", "3 numbers"),
        ("rotation", '[0.0, "a", 0.0]', "3 numbers"),
        ("rotation", "[0.0, true, 0.0]", "3 numbers"),
        ("translation", "[0.0, nan, 3.0]", "NaN or infinity"),
        ("translation", "[0.0, 0.0, inf]", "NaN or infinity"),
        ("translation", "3.0", "3 numbers"),
        ("translation", "[0.0, 0.0, 1e308]", "more than 10000 m"),
        ("fisheye", "true", "not supported"),
        ("fisheye", '"no"', "must be true or false"),
    ],
)
def test_bad_fields_name_the_file_table_and_field(
    tmp_path: Path, field: str, value: str | None, problem: str
) -> None:
    path = _file(tmp_path, **{field: value})
    with pytest.raises(InputError, match=problem) as caught:
        read_calibration(path)
    assert caught.value.source == str(path)
    assert f"[cam_0] {field}:" in caught.value.problem


def test_bad_files_are_input_errors(tmp_path: Path) -> None:
    cases = {
        "missing.toml": None,
        "garbage.toml": b"[cam_0\nname = 1\n",
        "binary.toml": b"\xff\xfe\x00\x01",
        "empty.toml": b"",
        "only_metadata.toml": b"[metadata]\nadjusted = false\n",
        "loose_key.toml": b'name = "x"\n',
        "bad_metadata.toml": b"metadata = 3\n",
        "bad_units.toml": b'[metadata]\nunits = "furlong"\n',
    }
    problems = {
        "missing.toml": "No such file",
        "garbage.toml": "not a TOML file",
        "binary.toml": "not a TOML file",
        "empty.toml": "no camera tables",
        "only_metadata.toml": "no camera tables",
        "loose_key.toml": "'name' is not a camera table",
        "bad_metadata.toml": r"\[metadata\] must be a table",
        "bad_units.toml": r"\[metadata\] units: must be one of",
    }
    for name, content in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(InputError, match=problems[name]) as caught:
            read_calibration(path)
        assert caught.value.source == str(path)
    with pytest.raises(InputError):
        read_calibration(tmp_path)  # a folder
    two = _file(tmp_path).read_text()
    (tmp_path / "twice.toml").write_text(two + two.replace("[cam_0]", "[cam_1]"))
    with pytest.raises(InputError, match="'cam0' is used by more than one table"):
        read_calibration(tmp_path / "twice.toml")


def test_a_failed_write_keeps_the_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "calib.toml"
    write_calibration(path, _group())
    before = path.read_bytes()

    def fail(*_: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        write_calibration(path, CameraGroup((_group()[0],)))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["calib.toml"]
