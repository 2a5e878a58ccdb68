"""The capture chain on real footage, end to end: `samba capture-volume` and `samba
track-video` on the last 20 frames (80-99) of the shared lab's four videos of a person
walking (../shared/data/pose2sim), with the lab's Qualisys calibration as it is, learnt
person segmentation for the silhouettes (no empty stage) and the default capture volume.
cam01 and cam02 are 8 columns narrower than the calibration's image: taken with a note.

What a user checks: the derived skeleton's height against the top of the head
triangulated from clicked pixels (1.65 m above the walkway in frame 99,
tests/test_foreign_calibrations.py), its feet against the walkway, and where on the
walkway the subject is. docs/real-footage.md has the whole clip's measures."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import shared_data_dir
from test_track_video import samba

from samba.ingest import read_bvh, read_take

pytestmark = pytest.mark.slow  # benchmark-like or end to end: CI runs it

FIRST_FRAME = 80
"""First video frame of the slice; it runs to the clip's last, 99."""
FPS = 60.0
WALKWAY_Y = -0.004
"""Height (m) of the walkway in our frame: the mean of its four bolts, triangulated."""
WALKWAY = ((-0.6, -1.7), (0.6, -0.5))
"""The walkway on the floor, (x, z) m of two opposite corners."""
HEAD_TOP_99 = 1.65
"""Top of the head above the walkway in frame 99, m (triangulated from clicked pixels)."""
SUBJECT = 1.65
"""The subject's height given to track-video, m."""


@dataclass(frozen=True)
class Lab:
    """The calibration and the slice's image folders (one per camera)."""

    calibration: Path
    folders: list[Path]


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Lab:
    """Frames 80-99 of the four videos as JPEG folders; skips without the shared data."""
    data = shared_data_dir()
    lab = None if data is None else data / "pose2sim"
    if lab is None or not (lab / "videos" / "cam04.mp4").is_file():
        pytest.skip("the shared lab videos are not here: set SAMBA_DATA or put ../shared/data")
    root = tmp_path_factory.mktemp("lab")
    folders = []
    for camera in ("cam01", "cam02", "cam03", "cam04"):
        folder = root / camera
        folder.mkdir()
        video = cv2.VideoCapture(str(lab / "videos" / f"{camera}.mp4"))
        number, ok = 0, True
        while ok:
            ok, frame = video.read()
            if ok and number >= FIRST_FRAME:
                image = folder / f"{number:03d}.jpg"
                cv2.imwrite(str(image), frame, [cv2.IMWRITE_JPEG_QUALITY, 95])
            number += 1
        video.release()
        folders.append(folder)
    return Lab(lab / "calibration" / "Calib.qca.txt", folders)


@dataclass(frozen=True)
class Walk:
    """What `samba capture-volume` printed and the BVH's joints and End Sites (n, k, 3) m."""

    code: int
    printed: str
    err: str
    points: np.ndarray


@pytest.fixture(scope="module")
def walk(lab: Lab, tmp_path_factory: pytest.TempPathFactory) -> Walk:
    """The slice captured by `samba capture-volume --segment` with every default."""
    out = tmp_path_factory.mktemp("walk") / "walk.bvh"
    code, printed, err = samba(
        "capture-volume", *lab.folders, "--calib", lab.calibration, "--segment",
        "--fps", FPS, "-o", out,
    )  # fmt: skip
    points = np.empty((0, 0, 3))
    if code == 0:
        motion = read_bvh(out)
        points = motion.positions(list(range(len(motion.joints))))
    return Walk(code, printed, err, points)


def test_capture_volume_runs_on_the_real_videos_as_they_are(lab: Lab, walk: Walk) -> None:
    assert walk.code == 0, walk.err
    lines = walk.printed.splitlines()
    assert lines[0].startswith("capture volume x ") and "the floor all 4 cameras see" in lines[0]
    for folder in lab.folders[:2]:
        assert any(
            line.startswith(f"{folder}: frames are 1080x1920") and "8 columns at the right" in line
            for line in lines
        )
    assert not any(str(folder) in walk.printed for folder in lab.folders[2:])
    assert "20 frames (video frames 0..19)" in lines[-1] and "model of 5 branches" in lines[-1]
    assert len(walk.points) == 20


def test_the_derived_skeleton_is_as_tall_as_the_subject(walk: Walk) -> None:
    top = walk.points[..., 1].max(axis=1) - WALKWAY_Y
    assert abs(top[-1] - HEAD_TOP_99) < 0.1 * HEAD_TOP_99  # 1.57 m in frame 99
    assert np.all(np.abs(top - HEAD_TOP_99) < 0.15 * HEAD_TOP_99)


def test_the_derived_skeletons_feet_are_on_the_walkway(walk: Walk) -> None:
    lowest = walk.points[..., 1].min(axis=1) - WALKWAY_Y
    assert abs(np.median(lowest)) < 0.10  # 7 cm: the feet's End Sites sit in their tips
    assert lowest.min() > -0.10 and lowest.max() < 0.25  # a stride lifts the lower foot too


def test_the_subject_walks_along_the_walkway(walk: Walk) -> None:
    (x0, z0), (x1, z1) = WALKWAY
    root = walk.points[:, 0]
    assert np.all((root[:, 0] > x0) & (root[:, 0] < x1))
    assert np.all((root[:, 2] > z0) & (root[:, 2] < z1))
    assert 0.1 < root[-1, 2] - root[0, 2] < 0.3  # towards +z at about 0.5 m/s: 0.18 m


def test_track_video_runs_on_one_real_view(
    lab: Lab, cmu_dir: Path, walk: Walk, tmp_path: Path
) -> None:
    store, take = tmp_path / "store", tmp_path / "walk.mcap"
    assert samba("db", "init", store)[0] == 0
    walks = [cmu_dir / f"iclone_007_0{n}.bvh" for n in (1, 2)]
    imported = samba("db", "import", store, *walks, "--fps", 15, "--skip-tpose", "--mirror")
    assert imported[0] == 0, imported[2]
    body = ("--calib", lab.calibration, "--camera", "cam01", "--height", SUBJECT)
    home = ("--home", "0.0,-1.0")
    tree = samba("db", "tree", store, *body, *home, "--headings", 30)
    assert tree[0] == 0, tree[2]
    code, printed, err = samba(
        "track-video", lab.folders[0], *body, *home, "--db", store, "--segment",
        "--fps", FPS, "-o", take,
    )  # fmt: skip
    assert code == 0, err
    assert printed.startswith(f"{lab.folders[0]}: frames are 1080x1920")
    poses = read_take(take).poses.astype(np.float64)
    assert poses.shape == (20, 13, 3)
    (x0, z0), (x1, z1) = WALKWAY
    hips = poses[:, 7:9].mean(axis=1)
    assert np.all((hips[:, 0] > x0) & (hips[:, 0] < x1) & (hips[:, 2] > z0) & (hips[:, 2] < z1))
    feet = poses[:, 11:13, 1].min(axis=1) - WALKWAY_Y
    assert abs(np.median(feet)) < 0.10  # 3 cm
    apart = np.linalg.norm(hips[:, [0, 2]] - walk.points[:, 0, [0, 2]], axis=1)
    assert np.median(apart) < 0.3  # one view against four: 0.2 m on the floor
