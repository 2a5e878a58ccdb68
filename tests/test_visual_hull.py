"""Tests of `samba.volume.voxel_grid` and the silhouette carving of `samba.volume.visual_hull`."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import ndimage

from samba.base.errors import InputError
from samba.body.body_model import BodyModel, scaled_to
from samba.body.skeleton import standard_pose
from samba.cameras.camera import Camera
from samba.volume.visual_hull import OUTSIDE, VisualHull, human_volumes, volume_cameras
from samba.volume.voxel_grid import VoxelGrid

GRID = VoxelGrid.from_bounds((-1.0, 0.0, -0.625), (1.0, 2.0, 0.625), 0.025)
CAMERAS = volume_cameras(GRID)
BODY = BodyModel.for_subject(1.70)
ALL_NEIGHBOURS = np.ones((3, 3, 3), dtype=bool)


@pytest.fixture(scope="module")
def hull() -> VisualHull:
    """The visual hull of the 80 x 80 x 50 grid in the four volume cameras."""
    return VisualHull(GRID, CAMERAS)


def _sphere_masks(centre: np.ndarray, radius: float) -> list[np.ndarray]:
    """Exact silhouettes of a sphere: pixels whose ray passes within `radius` of `centre`."""
    masks = []
    for camera in CAMERAS:
        width, height = camera.size
        u, v = np.meshgrid(np.arange(width), np.arange(height))
        rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(camera.matrix).T
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        point = camera.to_camera(centre)
        masks.append(point @ point - (rays @ point) ** 2 <= radius**2)
    return masks


def _pose(arm_angle_deg: float) -> np.ndarray:
    """The standard pose (1, 13, 3) at the body model's stature."""
    return scaled_to(standard_pose(1.70, arm_angle_deg)[None], BODY.height)


def test_grid_from_bounds_covers_the_box_with_centred_voxels() -> None:
    assert GRID.shape == (80, 80, 50)
    assert GRID.count == 80 * 80 * 50
    np.testing.assert_allclose(GRID.bounds, [[-1.0, 0.0, -0.625], [1.0, 2.0, 0.625]], atol=1e-12)
    odd = VoxelGrid.from_bounds((0.0, 0.0, 0.0), (0.25, 0.1, 0.3), 0.1)
    assert odd.shape == (3, 1, 3)
    low, high = odd.bounds
    assert (low <= 0.0).all() and (high >= [0.25, 0.1, 0.3]).all()
    np.testing.assert_allclose(0.5 * (low + high), [0.125, 0.05, 0.15])


def test_grid_centres_points_and_occupancy_agree() -> None:
    grid = VoxelGrid(np.array([1.0, 2.0, 3.0]), 0.5, (2, 3, 4))
    centres = grid.centers()
    assert centres.shape == (24, 3)
    np.testing.assert_allclose(centres[0], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(centres[(1 * 3 + 2) * 4 + 3], [1.5, 3.0, 4.5])  # C order
    occupancy = np.zeros(grid.shape, dtype=bool)
    occupancy[1, 2, 3] = occupancy[0, 1, 0] = True
    np.testing.assert_array_equal(grid.indices(occupancy), [[0, 1, 0], [1, 2, 3]])
    np.testing.assert_allclose(grid.points(occupancy), [[1.0, 2.5, 3.0], [1.5, 3.0, 4.5]])
    jitter = grid.points(occupancy) + np.array([0.2, -0.2, 0.24])
    outside = [[0.7, 2.0, 3.0], [1.0, 3.8, 3.0], [np.nan, 2.0, 3.0]]
    np.testing.assert_array_equal(grid.occupancy_of(np.vstack([jitter, outside])), occupancy)


@pytest.mark.parametrize(
    ("arguments", "source"),
    [
        (((0.0, 0.0), 0.1, (2, 2, 2)), "origin"),
        (((0.0, 0.0, np.nan), 0.1, (2, 2, 2)), "origin"),
        (((0.0, 0.0, 0.0), 0.0, (2, 2, 2)), "voxel"),
        (((0.0, 0.0, 0.0), "a", (2, 2, 2)), "voxel"),
        (((0.0, 0.0, 0.0), 0.1, (2, 0, 2)), "shape"),
        (((0.0, 0.0, 0.0), 0.1, (2, 2)), "shape"),
    ],
)
def test_grid_rejects_bad_fields(arguments: tuple, source: str) -> None:
    with pytest.raises(InputError) as error:
        VoxelGrid(*arguments)
    assert error.value.source == source


def test_grid_rejects_bad_boxes_and_occupancies() -> None:
    with pytest.raises(InputError, match="exceed"):
        VoxelGrid.from_bounds((0.0, 0.0, 0.0), (1.0, 0.0, 1.0), 0.1)
    with pytest.raises(InputError, match="occupancy"):
        GRID.points(np.zeros((80, 80, 49), dtype=bool))
    with pytest.raises(InputError, match="occupancy"):
        GRID.indices(np.zeros(GRID.shape, dtype=np.uint8))


def test_volume_cameras_see_the_whole_volume_from_three_sides() -> None:
    assert CAMERAS.names == ("front", "left", "right", "front_left")
    corners = np.array(list(itertools.product(*GRID.bounds.T)))
    for camera in CAMERAS:
        assert camera.size == (320, 240)
        assert 1.5 <= camera.center[1] <= 2.0
        assert camera.in_image(camera.project(corners)).all()
    assert CAMERAS["front"].center[2] > 0 > CAMERAS["right"].center[0]
    assert len(volume_cameras(GRID, count=5, size=(160, 120))) == 5
    with pytest.raises(InputError, match="count"):
        volume_cameras(GRID, count=6)


def test_tables_hold_the_nearest_pixel_or_outside() -> None:
    grid = VoxelGrid.from_bounds((-1.5, 0.0, -1.5), (1.5, 2.0, 1.5), 0.1)
    camera = Camera.look_at("near", (0.0, 1.0, 1.2), (0.0, 1.0, 0.0), (64, 48), 60.0)
    tables = VisualHull(grid, [camera]).tables
    assert tables.shape == (1, grid.count) and tables.dtype == np.int32
    pixels = camera.project(grid.centers())
    seen = camera.in_image(pixels)
    assert 0 < seen.sum() < grid.count and (tables[0, ~seen] == OUTSIDE).all()
    u, v = np.floor(pixels[seen] + 0.5).T
    np.testing.assert_array_equal(tables[0, seen], v * 64 + u)
    behind = grid.centers()[:, 2] > 1.2
    assert behind.any() and (tables[0, behind] == OUTSIDE).all()


def test_hull_of_a_sphere_holds_it_with_little_excess(hull: VisualHull) -> None:
    centre, radius = np.array([0.1, 1.0, 0.05]), 0.3
    occupancy = hull.carve(_sphere_masks(centre, radius))
    distance = np.linalg.norm(GRID.centers() - centre, axis=1).reshape(GRID.shape)
    sphere = distance <= radius
    assert occupancy[distance <= radius - GRID.voxel].all()
    assert occupancy.sum() < 1.3 * sphere.sum()
    assert distance[occupancy].max() < 1.5 * radius


def test_min_views_counts_the_cameras_holding_a_voxel(hull: VisualHull) -> None:
    rng = np.random.default_rng(1)
    masks = [rng.random((240, 320)) < 0.6 for _ in CAMERAS]
    pixels = hull.tables
    counts = sum(np.append(mask, False)[table] for mask, table in zip(masks, pixels, strict=True))
    counts = counts.reshape(GRID.shape)
    carved = [hull.carve(masks, min_views) for min_views in (1, 2, 3, 4)]
    for min_views, occupancy in enumerate(carved, start=1):
        np.testing.assert_array_equal(occupancy, counts >= min_views)
    np.testing.assert_array_equal(hull.carve(masks), carved[-1])
    assert carved[0].sum() > carved[1].sum() > carved[2].sum() > carved[3].sum() > 0
    for bad in (0, 5, 2.5):
        with pytest.raises(InputError, match="min_views"):
            hull.carve(masks, bad)


def test_tolerance_keeps_a_thin_part_a_calibration_misses_by_a_few_pixels(
    hull: VisualHull,
) -> None:
    # A 10 cm ball (a foot) whose silhouette in one camera lies 5 px off where the
    # calibration projects it: carved without tolerance, almost all of it is lost.
    centre, radius = np.array([0.1, 0.3, 0.05]), 0.05
    masks = _sphere_masks(centre, radius)
    masks[1] = np.roll(masks[1], 5, axis=1)
    distance = np.linalg.norm(GRID.centers() - centre, axis=1).reshape(GRID.shape)
    inner = distance <= radius - GRID.voxel
    assert hull.carve(masks)[inner].mean() < 0.5
    kept = hull.carve(masks, tolerance=5)
    assert kept[inner].all()
    assert distance[kept].max() < 4 * radius  # the price: a wider hull round it (0.14 m)
    np.testing.assert_array_equal(hull.carve(masks, tolerance=0), hull.carve(masks))
    for bad in (-1, 2.5, "3"):
        with pytest.raises(InputError, match="tolerance"):
            hull.carve(masks, tolerance=bad)


def test_carve_many_carves_frame_by_frame(hull: VisualHull) -> None:
    rng = np.random.default_rng(2)
    stack = rng.random((4, 3, 240, 320)) < 0.7
    volumes = hull.carve_many(stack, min_views=3)
    assert volumes.shape == (3, *GRID.shape)
    for frame, volume in enumerate(volumes):
        np.testing.assert_array_equal(volume, hull.carve(list(stack[:, frame]), min_views=3))


def test_masks_of_the_wrong_size_name_the_camera(hull: VisualHull) -> None:
    masks = [np.zeros((240, 320), dtype=bool) for _ in CAMERAS]
    masks[2] = np.zeros((120, 160), dtype=bool)
    with pytest.raises(InputError, match="'right'") as error:
        hull.carve(masks)
    assert "320x240" in str(error.value)
    masks[2] = np.zeros((240, 320), dtype=np.uint8)
    with pytest.raises(InputError, match="'right'"):
        hull.carve(masks)
    with pytest.raises(InputError, match="4 cameras"):
        hull.carve(masks[:3])
    with pytest.raises(InputError, match="'front'"):
        hull.carve_many([mask for mask in np.zeros((4, 240, 320), dtype=bool)])


def test_human_volume_is_one_piece_with_the_arms_apart() -> None:
    pose = _pose(60.0)
    volume = human_volumes(pose, CAMERAS, BODY, GRID)
    assert volume.shape == (1, *GRID.shape)
    _, pieces = ndimage.label(volume[0], ALL_NEIGHBOURS)
    assert pieces == 1
    assert 0.04 < volume.sum() * GRID.voxel**3 < 0.15  # m^3; the body is about 0.07
    elbow, wrist = pose[0, 3], pose[0, 5]
    forearm = round((0.5 * (elbow[1] + wrist[1]) - GRID.origin[1]) / GRID.voxel)
    labels, parts = ndimage.label(volume[0, :, forearm, :], np.ones((3, 3), dtype=bool))
    assert parts == 3  # left forearm, trunk, right forearm
    mid_x = [GRID.voxel * np.argwhere(labels == part)[:, 0].mean() for part in (1, 2, 3)]
    np.testing.assert_allclose(
        np.sort(np.array(mid_x) + GRID.origin[0]),
        [-0.5 * (elbow[0] + wrist[0]), 0.0, 0.5 * (elbow[0] + wrist[0])],
        atol=0.05,
    )


def test_noisy_human_volumes_are_seeded() -> None:
    poses = _pose(45.0)
    clean = human_volumes(poses, CAMERAS, BODY, GRID)
    noisy = human_volumes(poses, CAMERAS, BODY, GRID, noise=1.0, seed=3)
    np.testing.assert_array_equal(noisy, human_volumes(poses, CAMERAS, BODY, GRID, 1.0, 3))
    overlap = (noisy & clean).sum() / (noisy | clean).sum()
    assert 0.6 < overlap < 1.0
