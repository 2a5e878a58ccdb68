"""Tests of other systems' calibrations read by `samba.cameras` (Qualisys QTM `.qca`,
EasyMocap `intri.yml` / `extri.yml`) and of `convert_calibration`; the lab calibration
and videos of ../shared/data/pose2sim are the check on real footage."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import shared_data_dir
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from samba.base import InputError
from samba.cameras import (
    Camera,
    CameraGroup,
    Triangulation,
    convert_calibration,
    read_calibration,
    with_size,
)
from samba.cameras.calibration_file import calibration_format

QTM_TO_OPENCV = np.diag([1.0, -1.0, -1.0])
LAB_POINTS = np.random.default_rng(7).uniform((-1.0, -1.0, 0.0), (1.0, 1.0, 2.0), (50, 3))
"""Points of a Z-up lab (meters) in front of the cameras of `lab_cameras`."""


def ours(lab_points: np.ndarray) -> np.ndarray:
    """Lab points of a Z-up world (..., 3) in our frame: our (x, y, z) = the lab's (y, z, x)."""
    return lab_points[..., [1, 2, 0]]


def lab_cameras() -> CameraGroup:
    """Three cameras of a Z-up lab (meters) round the origin, two with lens distortion."""
    cameras = []
    for i, (position, distortion) in enumerate(
        [
            ((3.0, -1.0, 2.0), (-0.05, 0.14, 0.001, -0.0005, 0.0)),
            ((-1.0, 3.0, 1.8), (0.0, 0.0, 0.0, 0.0, 0.0)),
            ((-3.0, -2.0, 2.2), (-0.1, 0.02, 0.0, 0.0, 0.01)),
        ]
    ):
        camera = Camera.look_at(f"cam{i + 1}", position, (0, 0, 1), (1088, 1920), 35.0, (0, 0, 1))
        cameras.append(dataclasses.replace(camera, distortion=np.array(distortion)))
    return CameraGroup(tuple(cameras))


# --- Qualisys QTM ------------------------------------------------------------------------


def element(tag: str, **attributes: float | str) -> str:
    """An empty XML element; numbers are written exactly (`repr`), strings as they are."""
    text = " ".join(
        f'{key}="{value if isinstance(value, str) else repr(float(value))}"'
        for key, value in attributes.items()
    )
    return f"<{tag} {text}/>\n"


def qca_text(cameras: CameraGroup, window: tuple[int, int] = (0, 0), extra: str = "") -> str:
    """A QTM calibration of `cameras` (a Z-up lab in meters) as QTM lays it out: each
    video the sensor window from `window` (left, top), sub-pixels, mm, QTM camera axes."""
    left, top = window
    parts = ['<?xml version="1.0"?>\n<calibration type="regular">\n<cameras>\n']
    for camera in cameras:
        lab_to_qtm = QTM_TO_OPENCV @ camera.rotation_matrix
        x, y, z = camera.center * 1000.0
        k, (k1, k2, p1, p2, k3) = camera.matrix, camera.distortion
        width, height = camera.size
        rotation = {f"r{i + 1}{j + 1}": lab_to_qtm[i, j] for i in range(3) for j in range(3)}
        window_ = {"left": left, "top": top, "right": left + width - 1, "bottom": top + height - 1}
        parts += [
            f'<camera active="1" serial="{camera.name}" viewrotation="0" {extra}>\n',
            element("fov_video", **{key: str(value) for key, value in window_.items()}),
            element("transform", x=x, y=y, z=z, **rotation),
            element(
                "intrinsic",
                focalLengthU=k[0, 0] * 64,
                focalLengthV=k[1, 1] * 64,
                centerPointU=(k[0, 2] + left) * 64,
                centerPointV=(k[1, 2] + top) * 64,
                skew="0",
                radialDistortion1=k1,
                radialDistortion2=k2,
                radialDistortion3=k3,
                tangentalDistortion1=p1,
                tangentalDistortion2=p2,
            ),
            "</camera>\n",
        ]
    return "".join(parts) + "</cameras>\n</calibration>\n"


@pytest.mark.parametrize("name", ["lab.qca", "lab.qca.txt", "lab.xml"])
def test_qca_of_known_cameras_reads_back_in_our_frame(tmp_path: Path, name: str) -> None:
    cameras = lab_cameras()
    path = tmp_path / name
    path.write_text(qca_text(cameras, window=(16, 8)))
    assert calibration_format(path) == "qualisys"
    group = read_calibration(path)
    assert group.names == cameras.names
    assert all(camera.size == (1088, 1920) for camera in group)
    np.testing.assert_allclose(
        group.project(ours(LAB_POINTS)), cameras.project(LAB_POINTS), atol=1e-6
    )
    # QTM's lab is Z up: the cameras stand 1.8-2.2 m above the floor in ours.
    np.testing.assert_allclose([camera.center[1] for camera in group], [2.0, 1.8, 2.2])


def test_qca_video_resolution_scales_the_sensor_window(tmp_path: Path) -> None:
    cameras = lab_cameras()
    path = tmp_path / "lab.qca"
    path.write_text(qca_text(cameras, extra='video_resolution="540p"'))
    group = read_calibration(path)
    half = CameraGroup(tuple(with_size(camera, (544, 960)) for camera in cameras))
    assert all(camera.size == (544, 960) for camera in group)
    np.testing.assert_allclose(group.project(ours(LAB_POINTS)), half.project(LAB_POINTS), atol=1e-6)


def test_qca_inside_qtm_parameters_reads(tmp_path: Path) -> None:
    cameras = lab_cameras()
    text = qca_text(cameras).replace('<?xml version="1.0"?>\n', "")
    path = tmp_path / "settings.xml"
    path.write_text(f"<QTM_Parameters_Ver_1.25>\n{text}</QTM_Parameters_Ver_1.25>\n")
    assert read_calibration(path).names == cameras.names


@pytest.mark.parametrize(
    ("edit", "problem"),
    [
        (lambda t: t.replace(' r12="', ' q12="', 1), "camera 1 (cam1): transform r12: missing"),
        (
            lambda t: t.replace('focalLengthU="', 'focalLengthU="x', 1),
            "camera 1 (cam1): intrinsic focalLengthU: not a number",
        ),
        (lambda t: t.replace('viewrotation="0"', 'viewrotation="90"', 1), "viewrotation 90"),
        (lambda t: t.replace('skew="0"', 'skew="2"', 1), "intrinsic skew 2"),
        (lambda t: t.replace(' r11="', ' r11="2', 1), "r11..r33 is not a rotation matrix"),
        (
            lambda t: t.replace("<transform", "<transformed", 1),
            "camera 1 (cam1): <transform> missing",
        ),
        (lambda t: t.replace('serial="cam2"', 'serial="cam1"'), "serial 'cam1' is used by more"),
        (
            lambda t: t.replace("<calibration", "<settings").replace("</calibration", "</settings"),
            "no <calibration> element",
        ),
        (lambda t: t.replace("</cameras>", ""), "not a Qualisys calibration: not XML"),
        (lambda t: t.split("<cameras>")[0] + "<cameras/></calibration>", "no <camera> elements"),
    ],
)
def test_bad_qca_is_refused_naming_file_camera_and_field(
    tmp_path: Path, edit: Callable[[str], str], problem: str
) -> None:
    path = tmp_path / "bad.qca"
    path.write_text(edit(qca_text(lab_cameras())))
    with pytest.raises(InputError) as error:
        read_calibration(path)
    message = str(error.value)
    assert message.startswith(f"{path}: ") and problem in message and "\n" not in message


def test_missing_qca_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="No such file"):
        read_calibration(tmp_path / "none.qca.txt")


# --- EasyMocap ---------------------------------------------------------------------------


def write_easymocap(
    folder: Path,
    cameras: CameraGroup,
    names: list[str | int] | None = None,
    sizes: bool = True,
    dist4: bool = False,
    rotation_key: str = "both",
) -> None:
    """`cameras` (world frame and meters of the file) as EasyMocap's write_camera lays them
    out, written by OpenCV's FileStorage: intri.yml (names, K_, dist_, H_, W_) and
    extri.yml (names, R_ Rodrigues 3 x 1, Rot_ 3 x 3, T_ 3 x 1)."""
    names = names if names is not None else list(cameras.names)
    intri = cv2.FileStorage(str(folder / "intri.yml"), cv2.FILE_STORAGE_WRITE)
    extri = cv2.FileStorage(str(folder / "extri.yml"), cv2.FILE_STORAGE_WRITE)
    for storage in (intri, extri):
        storage.startWriteStruct("names", cv2.FileNode_SEQ)
        for name in names:
            storage.write("", name)
        storage.endWriteStruct()
    for name, camera in zip(names, cameras, strict=True):
        intri.write(f"K_{name}", camera.matrix)
        intri.write(f"dist_{name}", camera.distortion[None, : 4 if dist4 else 5])
        if sizes:
            intri.write(f"H_{name}", camera.size[1])
            intri.write(f"W_{name}", camera.size[0])
        if rotation_key in ("both", "R"):
            extri.write(f"R_{name}", camera.rotation[:, None])
        if rotation_key in ("both", "Rot"):
            extri.write(f"Rot_{name}", camera.rotation_matrix)
        extri.write(f"T_{name}", camera.translation[:, None])
    intri.release()
    extri.release()


@pytest.mark.parametrize("given", ["folder", "intri.yml", "extri.yml"])
def test_easymocap_files_read_back_in_our_frame(tmp_path: Path, given: str) -> None:
    cameras = lab_cameras()
    write_easymocap(tmp_path, cameras)
    path = tmp_path if given == "folder" else tmp_path / given
    assert calibration_format(path) == "easymocap"
    group = read_calibration(path)
    assert group.names == cameras.names and [c.size for c in group] == [c.size for c in cameras]
    np.testing.assert_allclose(
        group.project(ours(LAB_POINTS)), cameras.project(LAB_POINTS), atol=1e-6
    )


def test_easymocap_optional_keys(tmp_path: Path) -> None:
    # Numbered cameras, no image sizes, four distortion coefficients, the rotation as Rot_ only.
    cameras = CameraGroup(
        tuple(
            dataclasses.replace(c, distortion=np.r_[c.distortion[:4], 0.0]) for c in lab_cameras()
        )
    )
    write_easymocap(tmp_path, cameras, names=[1, 2, 3], sizes=False, dist4=True, rotation_key="Rot")
    group = read_calibration(tmp_path)
    assert group.names == ("1", "2", "3")
    # Without W_ and H_ the size is twice the principal point ((1087 / 2, 1919 / 2) here).
    assert all(camera.size == (1087, 1919) for camera in group)
    np.testing.assert_allclose(
        group.project(ours(LAB_POINTS)), cameras.project(LAB_POINTS), atol=1e-6
    )


def test_easymocap_errors_name_the_file_and_key(tmp_path: Path) -> None:
    write_easymocap(tmp_path, lab_cameras())
    intri, extri = tmp_path / "intri.yml", tmp_path / "extri.yml"
    text = intri.read_text()
    intri.write_text(text.replace("K_cam2", "K_camX"))
    with pytest.raises(InputError, match=f"^{intri}: K_cam2: missing$"):
        read_calibration(tmp_path)
    intri.write_text("%YAML:1.0\nnames: [cam1\nK_cam1: {\n")
    with pytest.raises(InputError, match=f"^{intri}: not an OpenCV FileStorage file"):
        read_calibration(intri)
    intri.write_text(text)
    extri.unlink()
    with pytest.raises(InputError, match=f"^{extri}: No such file"):
        read_calibration(intri)
    far = dataclasses.replace(lab_cameras()[0], translation=np.array([0.0, 0.0, 1e5]))
    write_easymocap(tmp_path, CameraGroup((far,)))
    with pytest.raises(InputError, match=f"^{tmp_path}: camera 'cam1': more than 10000 m"):
        read_calibration(tmp_path)


# --- The lab's QTM calibration and its videos ----------------------------------------------

# Features clicked once on the lab's videos (views 0..3 = cam01..cam04), as pixels of the
# video frames (u right, v down), in views that see them. Fixed features (the same in every
# frame; clicked in frame 99): the bolt heads of the four silver brackets at the corners of
# the walkway's belt (named by where they come out in QTM's lab frame, x and y in meters),
# and the middle of the opening on top of the two black posts at its near end (the one
# with a cable, and the other). The subject in frame 99: the top of the
# head (the cap's outline: not the same point of the head from every side, the least exact
# feature) and the markers on the outside of the right and of the left ankle.
WALKWAY = {
    "bolt at lab (-0.6, -0.6)": {
        0: (278.4, 1359.8),
        1: (283.5, 1214.1),
        2: (532.8, 1075.3),
        3: (932.4, 1055.8),
    },
    "bolt at lab (-0.5, +0.6)": {
        0: (786.2, 1274.5),
        1: (802.3, 1267.0),
        2: (140.8, 1267.5),
        3: (486.2, 1132.0),
    },
    "bolt at lab (-1.6, +0.6)": {
        0: (511.8, 1034.2),
        1: (823.3, 1063.7),
        2: (519.5, 1499.0),
        3: (324.7, 1462.3),
    },
    "bolt at lab (-1.7, -0.6)": {
        0: (65.7, 1057.8),
        1: (414.2, 1034.5),
        2: (911.7, 1227.0),
        3: (884.5, 1428.2),
    },
}
POSTS = {
    "post with the cable, top": {
        0: (667.9, 1520.5),
        1: (272.3, 1315.5),
        2: (259.5, 969.5),
        3: (834.5, 857.1),
    },
    "other post, top": {0: (947.7, 1425.9), 1: (630.1, 1341.9), 2: (60.5, 1057.9)},
}
SUBJECT = {
    "top of the head": {0: (753.3, 477.5), 1: (394.5, 442.5), 2: (297.0, 430.8), 3: (484.5, 382.5)},
    "right ankle marker": {0: (476.2, 1200.2), 2: (439.5, 1131.2), 3: (683.8, 1097.8)},
    "left ankle marker": {0: (586.2, 1242.8), 1: (570.8, 1180.2), 3: (641.2, 1067.8)},
}
FEATURES = WALKWAY | POSTS | SUBJECT
MAX_ERROR_PX = 16.0
"""Largest reprojection error of a feature in any view with the lab's calibration (15.1 px
measured; see docs/calibration.md: the file's cameras are turned 0.3-0.8 degrees from the
videos')."""


@pytest.fixture(scope="module")
def lab() -> Path:
    """The Pose2Sim lab session of the shared data; skips the test when it is absent."""
    data = shared_data_dir()
    if data is None or not (data / "pose2sim" / "calibration" / "Calib.qca.txt").is_file():
        pytest.skip(
            "real Pose2Sim lab data not found: set SAMBA_DATA or put ../shared/data/pose2sim "
            "beside the project"
        )
    return data / "pose2sim"


@pytest.fixture(scope="module")
def lab_group(lab: Path) -> CameraGroup:
    """The lab's calibration converted, each camera at its video's image size: cam01 and
    cam02 were encoded 1080 wide, the sensor's 1088 columns cut at the right, so pixel
    coordinates are unchanged (`test_the_narrow_videos_are_cut_at_the_right`)."""
    group = read_calibration(lab / "calibration" / "Calib.qca.txt")
    cameras = []
    for camera in group:
        video = cv2.VideoCapture(str(lab / "videos" / f"{camera.name}.mp4"))
        size = (int(video.get(cv2.CAP_PROP_FRAME_WIDTH)), int(video.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        video.release()
        cameras.append(dataclasses.replace(camera, size=size))
    assert [camera.size for camera in cameras] == [(1080, 1920)] * 2 + [(1088, 1920)] * 2
    return CameraGroup(tuple(cameras))


def clicked(features: dict[str, dict[int, tuple[float, float]]]) -> np.ndarray:
    """The clicked pixels (4, n, 2) of `features`, NaN where a view does not see one."""
    pixels = np.full((4, len(features), 2), np.nan)
    for j, views in enumerate(features.values()):
        for view, uv in views.items():
            pixels[view, j] = uv
    return pixels


def triangulated(group: CameraGroup, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) m triangulated from raw pixels (4, n, 2) by least reprojection error,
    and their reprojection errors (4, n) px in the raw images (NaN where unseen)."""
    points = Triangulation.from_views(
        group.projections, group.undistort(pixels), refine=True
    ).points
    return points, np.linalg.norm(group.project(points) - pixels, axis=-1)


def test_qca_reads_the_lab_calibration(lab: Path) -> None:
    group = read_calibration(lab / "calibration" / "Calib.qca.txt")
    assert group.names == ("cam01", "cam02", "cam03", "cam04")
    assert all(camera.size == (1088, 1920) for camera in group)  # fov_video 0..1087 x 0..1919
    cam01 = group["cam01"]
    np.testing.assert_allclose(cam01.matrix[0], [107599.671875 / 64, 0.0, 34110.316406 / 64])
    np.testing.assert_allclose(cam01.matrix[1], [0.0, 107588.828125 / 64, 60680.792969 / 64])
    np.testing.assert_allclose(cam01.distortion, [-0.046183, 0.139983, 0.000608, 0.00069, 0.0])
    # transform x, y, z = 1460.2, -1909.2, 1896.5 mm in QTM's Z-up lab: ours is (y, z, x) in m.
    np.testing.assert_allclose(cam01.center, [-1.9091590, 1.8965059, 1.4602324], atol=1e-7)


def test_qca_matches_pose2sims_converter(lab: Path) -> None:
    # Pose2Sim converts this file (its demo Calib.qca.txt) to Calib_qualisys.toml in the
    # lab's own axes: cam01's rotation and translation there.
    group = read_calibration(lab / "calibration" / "Calib.qca.txt", up="+y")
    cam01 = group["cam01"]
    np.testing.assert_allclose(cam01.rotation, [1.68827548, 1.04832205, -0.41955852], atol=1e-7)
    np.testing.assert_allclose(cam01.translation, [0.32110489, 0.95633206, 2.89071305], atol=1e-7)


def test_convert_calibration_round_trips_the_qca(lab: Path, tmp_path: Path) -> None:
    source = lab / "calibration" / "Calib.qca.txt"
    converted = convert_calibration(source, tmp_path / "lab.toml")
    again = read_calibration(tmp_path / "lab.toml")
    assert again.names == converted.names
    points = ours(LAB_POINTS) + np.array([0.0, 0.0, -1.0])  # round the walkway
    np.testing.assert_allclose(
        again.project(points), read_calibration(source).project(points), atol=1e-6
    )


def test_clicked_features_triangulate_in_every_view(lab_group: CameraGroup) -> None:
    pixels = clicked(FEATURES)
    for camera, uv in zip(lab_group, pixels, strict=True):
        assert camera.in_image(uv[~np.isnan(uv[:, 0])]).all()
    _, error = triangulated(lab_group, pixels)
    assert np.nanmax(error) < MAX_ERROR_PX
    assert np.sqrt(np.nanmean(error**2)) < 11.0  # 10.2 px measured


def test_walkway_is_level_and_the_subject_stands_on_it(lab_group: CameraGroup) -> None:
    points, _ = triangulated(lab_group, clicked(FEATURES))
    corners = points[: len(WALKWAY)]
    middle = corners.mean(axis=0)
    normal = np.linalg.svd(corners - middle)[2][2]
    normal *= np.sign(normal[1])
    assert np.degrees(np.arccos(normal[1])) < 2.0  # 0.3 degrees measured
    sides = np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1)
    assert np.all((sides > 1.0) & (sides < 1.3))  # the belt's brackets: 1.12-1.17 m apart
    height = (points[len(WALKWAY) :] - middle) @ normal
    posts, head, ankles = height[:2], height[2], height[3:]
    assert np.all((posts > 0.1) & (posts < 0.3))
    assert 1.5 < head < 1.9  # 1.65 m: the top of the head above the walkway
    assert np.all((ankles > 0.05) & (ankles < 0.2))  # 0.13 and 0.14 m


def test_what_remains_is_the_cameras_turned_under_a_degree(lab_group: CameraGroup) -> None:
    # The errors are not a convention wrongly converted: turning each camera by under a
    # degree (least squares over the four turns and the points) fits every feature but the
    # head's outline within 3 px.
    fixed = {name: views for name, views in FEATURES.items() if name != "top of the head"}
    pixels = clicked(fixed)
    seen = ~np.isnan(pixels[..., 0])
    start, _ = triangulated(lab_group, pixels)

    def turned(turns: np.ndarray) -> CameraGroup:
        cameras = []
        for camera, turn in zip(lab_group, turns.reshape(4, 3), strict=True):
            rotation = Rotation.from_rotvec(turn) * Rotation.from_rotvec(camera.rotation.copy())
            translation = -rotation.apply(camera.center)
            cameras.append(
                dataclasses.replace(camera, rotation=rotation.as_rotvec(), translation=translation)
            )
        return CameraGroup(tuple(cameras))

    def residuals(x: np.ndarray) -> np.ndarray:
        return (turned(x[:12]).project(x[12:].reshape(-1, 3)) - pixels)[seen].ravel()

    fit = least_squares(residuals, np.concatenate([np.zeros(12), start.ravel()]))
    turns = np.degrees(np.linalg.norm(fit.x[:12].reshape(4, 3), axis=1))
    assert np.all(turns < 1.0)  # 0.81, 0.31, 0.34, 0.59 degrees
    assert np.linalg.norm(fit.fun.reshape(-1, 2), axis=1).max() < 3.0  # 2.7 px


def test_the_narrow_videos_are_cut_at_the_right(lab_group: CameraGroup) -> None:
    # cam01 and cam02 are 8 columns narrower than the calibration's sensor window: cut at
    # the right, their pixels are the sensor's; cut at the left, every u would be 8 less.
    # The clicked features fit the first better (RMS 10.2 px against 11.9).
    pixels = clicked(FEATURES)
    left_cut = CameraGroup(
        tuple(
            dataclasses.replace(camera, matrix=camera.matrix - [[0, 0, 8], [0, 0, 0], [0, 0, 0]])
            if camera.size[0] == 1080
            else camera
            for camera in lab_group
        )
    )
    rms = [np.sqrt(np.nanmean(triangulated(g, pixels)[1] ** 2)) for g in (lab_group, left_cut)]
    assert rms[0] < rms[1] - 1.0
