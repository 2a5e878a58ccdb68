"""The default capture volume of a calibration (`samba.volume.capture_region`): the box
over the floor that the cameras all see, on a synthetic stage and on the shared lab's
Qualisys calibration, whose walkway it must hold."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_data_dir

from samba.base import InputError
from samba.cameras import Camera, CameraGroup, read_calibration
from samba.volume import VoxelGrid, capture_region
from samba.volume.visual_hull import volume_cameras

WALKWAY = ((-0.6, -1.7), (0.6, -0.5))
"""The shared lab's walkway on the floor, (x, z) m of two opposite corners in our frame."""


def test_the_region_of_cameras_round_a_stage_is_the_floor_they_all_see() -> None:
    grid = VoxelGrid.from_bounds((-1.0, 0.0, -1.0), (1.0, 2.0, 1.0), 0.05)
    cameras = volume_cameras(grid, 4, (320, 240))
    (x0, y0, z0), (x1, y1, z1) = capture_region(cameras)
    assert (y0, y1) == (0.0, 2.2)  # from the floor to a person's reach
    assert x0 <= -1.0 and x1 >= 1.0 and z0 <= -1.0 and z1 >= 1.0  # the stage all see
    assert x1 - x0 < 6.0 and z1 - z0 < 6.0  # not the whole floor within range
    (x0, _, z0), (x1, _, z1) = capture_region(cameras, min_views=2)
    assert x1 - x0 >= 2.0 and z1 - z0 >= 2.0


def test_cameras_that_see_no_common_floor_are_named() -> None:
    up = [
        Camera.look_at(f"sky{i}", (3.0 * i, 1.5, 0.0), (3.0 * i, 5.0, 0.5), (320, 240), 40.0)
        for i in range(2)
    ]
    with pytest.raises(InputError, match="sky0, sky1") as error:
        capture_region(CameraGroup(tuple(up)))
    assert "--bounds" in str(error.value) and "\n" not in str(error.value)


@pytest.fixture(scope="module")
def lab_cameras() -> CameraGroup:
    """The shared lab's four cameras, from its Qualisys calibration."""
    data = shared_data_dir()
    calibration = None if data is None else data / "pose2sim" / "calibration" / "Calib.qca.txt"
    if calibration is None or not calibration.is_file():
        pytest.skip("the shared lab calibration is not here: set SAMBA_DATA or put ../shared/data")
    return read_calibration(calibration)


def test_the_lab_region_holds_its_walkway_and_little_more(lab_cameras: CameraGroup) -> None:
    (x0, y0, z0), (x1, y1, z1) = capture_region(lab_cameras)
    (wx0, wz0), (wx1, wz1) = WALKWAY
    assert x0 <= wx0 and x1 >= wx1 and z0 <= wz0 and z1 >= wz1
    assert (y0, y1) == (0.0, 2.2)
    area = (x1 - x0) * (z1 - z0)
    assert area < 6 * (wx1 - wx0) * (wz1 - wz0)  # 7.1 m2 against the walkway's 1.44 m2
    grid = VoxelGrid.from_bounds((x0, y0, z0), (x1, y1, z1), 0.03)
    assert grid.count < 2e7  # a grid the carving holds in memory
    centre = np.array([0.0, 1.0, -1.1])
    for camera in lab_cameras:
        assert camera.in_image(camera.project(centre[None]))[0]
