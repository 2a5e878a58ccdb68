"""Tests of the synthetic creatures of `samba.volume.articulated_figure`."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation

from samba.base.errors import InputError
from samba.body.segments import segment_distances
from samba.volume.articulated_figure import (
    ArticulatedFigure,
    creature_motion,
    long_chain,
    quadruped,
)
from samba.volume.voxel_grid import VoxelGrid

QUADRUPED_BOX = np.array([[-0.9, -0.01, -1.1], [0.9, 1.3, 1.2]])
"""Capture volume (low, high corner) m the quadruped's motion must stay in."""
CHAIN_BOX = np.array([[-1.0, -0.01, -0.9], [1.0, 0.5, 0.9]])
"""Capture volume (low, high corner) m of the lying chain: it must keep to the floor."""
FRAMES = 40


@pytest.fixture(scope="module")
def quadruped_motion() -> tuple[ArticulatedFigure, np.ndarray]:
    """The quadruped and its motion (FRAMES, J, 3) for seed 7 inside QUADRUPED_BOX."""
    figure = quadruped()
    return figure, creature_motion(figure, FRAMES, seed=7, bounds=QUADRUPED_BOX)


def _two_links(radius: float = 0.08) -> ArticulatedFigure:
    """A root at (0, 0.5, -0.25) with links of 0.5 m along +Z and 0.3 m along +X."""
    offsets = np.array([[0.0, 0.5, -0.25], [0.0, 0.0, 0.5], [0.3, 0.0, 0.0]])
    return ArticulatedFigure(("a", "b", "c"), (-1, 0, 1), offsets, np.full(3, radius))


def _bends(figure: ArticulatedFigure, rotations: np.ndarray) -> np.ndarray:
    """Per frame and joint with children (n, k), degrees: the largest angle by which the
    joint's rotation turns one of its child links away from its rest direction."""
    bends = []
    for joint, kids in enumerate(figure.children):
        if joint and kids:
            offsets = figure.offsets[list(kids)]
            turned = Rotation.from_rotvec(rotations[:, joint]).as_matrix() @ offsets.T
            cosine = (turned * offsets.T).sum(axis=1) / (offsets**2).sum(axis=1)
            bends.append(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).max(axis=1))
    return np.stack(bends, axis=1)


def test_built_in_creatures_count_links_and_branches() -> None:
    figure = quadruped()
    assert (figure.link_count, figure.branch_count) == (13, 6)
    assert {figure.names[leaf] for leaf in figure.leaves} == {
        "head",
        "tail",
        *(f"{end}_{side}_foot" for end in ("front", "hind") for side in ("left", "right")),
    }
    assert len(figure.children[figure.names.index("withers")]) == 3
    body = figure.offsets[1:3, 2].sum()
    legs = figure.link_lengths[[4, 5]].sum()
    assert body == pytest.approx(0.8) and legs == pytest.approx(0.5, abs=0.05)
    rest = figure.bounds(figure.positions(np.zeros((1, 14, 3))))
    assert rest[0, 1] == pytest.approx(0.0)  # standing on the floor
    chain = long_chain(6)
    assert (chain.link_count, chain.branch_count, chain.leaves) == (6, 1, (6,))
    np.testing.assert_allclose(chain.link_lengths, 0.25)
    with pytest.raises(InputError, match="links"):
        long_chain(0)


@pytest.mark.parametrize(
    ("change", "source"),
    [
        ({"parents": (-1, 2, 1)}, "parents"),
        ({"parents": (0, 0, 1)}, "parents"),
        ({"names": ("a", "a", "c")}, "names"),
        ({"offsets": np.zeros((3, 2))}, "offsets"),
        ({"offsets": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])}, "offsets"),
        ({"radii": np.array([0.0, 0.1, -0.1])}, "radii"),
    ],
)
def test_figure_rejects_bad_fields(change: dict, source: str) -> None:
    fields = {
        "names": ("a", "b", "c"),
        "parents": (-1, 0, 1),
        "offsets": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5], [0.3, 0.0, 0.0]]),
        "radii": np.array([0.0, 0.1, 0.1]),
    }
    with pytest.raises(InputError) as error:
        ArticulatedFigure(**(fields | change))
    assert error.value.source == source


def test_forward_kinematics_turns_children_about_their_joint() -> None:
    figure = _two_links()
    rotations = np.zeros((2, 3, 3))
    rotations[1, 1] = [0.0, np.pi / 2, 0.0]  # joint b turns its child link about +Y
    positions = figure.positions(rotations, translation=np.array([[0.0, 0.0, 0.0], [1.0, 0, 0]]))
    np.testing.assert_allclose(positions[0], [[0, 0.5, -0.25], [0, 0.5, 0.25], [0.3, 0.5, 0.25]])
    np.testing.assert_allclose(positions[1], [[1, 0.5, -0.25], [1, 0.5, 0.25], [1, 0.5, -0.05]])
    root_turn = np.zeros((1, 3, 3))
    root_turn[0, 0] = [0.0, np.pi, 0.0]
    np.testing.assert_allclose(figure.positions(root_turn)[0, 2], [-0.3, 0.5, -0.75], atol=1e-12)
    with pytest.raises(InputError, match="rotations"):
        figure.positions(np.zeros((2, 4, 3)))
    with pytest.raises(InputError, match="translation"):
        figure.positions(rotations, translation=np.zeros((3, 3)))


def test_forward_kinematics_keeps_link_lengths() -> None:
    figure = quadruped()
    rng = np.random.default_rng(3)
    rotations = rng.uniform(-np.pi, np.pi, size=(20, 14, 3))
    positions = figure.positions(rotations, translation=rng.normal(size=(20, 3)))
    lengths = np.linalg.norm(positions[:, 1:] - positions[:, list(figure.parents[1:])], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(figure.link_lengths, (20, 13)))


def test_voxelize_fills_a_capsule() -> None:
    figure = _two_links(radius=0.08)
    grid = VoxelGrid.from_bounds((-0.3, 0.2, -0.5), (0.3, 0.8, 0.5), 0.02)
    positions = figure.positions(np.zeros((1, 3, 3)))
    positions[0, 2] = positions[0, 1]  # fold the second link away to a point: one capsule
    volume = figure.voxelize(positions, grid)
    radius, length = 0.08, 0.5
    expected = (np.pi * radius**2 * length + 4.0 / 3.0 * np.pi * radius**3) / grid.voxel**3
    assert volume.sum() == pytest.approx(expected, rel=0.1)
    points = grid.points(volume[0])
    distance = segment_distances(points, points, positions[0, 0], positions[0, 1])
    assert distance.max() <= radius
    clipped = VoxelGrid.from_bounds((-0.3, 0.2, -0.5), (0.3, 0.8, 0.0), 0.02)
    half = figure.voxelize(positions, clipped).sum()
    assert half == pytest.approx(expected / 2, rel=0.1)


def test_creature_motion_is_seeded_and_bends_every_joint(
    quadruped_motion: tuple[ArticulatedFigure, np.ndarray],
) -> None:
    figure, rotations = quadruped_motion
    assert rotations.shape == (FRAMES, 14, 3)
    np.testing.assert_array_equal(
        rotations, creature_motion(figure, FRAMES, seed=7, bounds=QUADRUPED_BOX)
    )
    assert not np.allclose(rotations, creature_motion(figure, FRAMES, seed=8))
    still = [0, *figure.leaves]
    assert (rotations[:, still] == 0).all()
    bends = _bends(figure, rotations)
    assert (bends.max(axis=0) >= 25.0).all() and (bends <= 70.0).all()
    steps = np.degrees(np.linalg.norm(np.diff(rotations, axis=0), axis=-1))
    assert steps.max() < 25.0  # smooth: no joint jumps between frames
    chain = long_chain(6)
    chain_rotations = creature_motion(chain, FRAMES, seed=1, bounds=CHAIN_BOX)
    assert (_bends(chain, chain_rotations).max(axis=0) >= 25.0).all()


def test_creature_keeps_its_limbs_apart_inside_the_grid(
    quadruped_motion: tuple[ArticulatedFigure, np.ndarray],
) -> None:
    figure, rotations = quadruped_motion
    positions = figure.positions(rotations)
    low, high = figure.bounds(positions)
    assert (low >= QUADRUPED_BOX[0]).all() and (high <= QUADRUPED_BOX[1]).all()
    starts, ends = positions[:, list(figure.parents[1:])], positions[:, 1:]
    links = list(zip(figure.parents[1:], range(1, 14), strict=True))
    for a, (a0, a1) in enumerate(links):
        for b, (b0, b1) in enumerate(links[:a]):
            if {a0, a1} & {b0, b1}:
                continue
            gap = segment_distances(starts[:, a], ends[:, a], starts[:, b], ends[:, b])
            assert gap.min() > figure.radii[a1] + figure.radii[b1], (a1, b1)
    grid = VoxelGrid.from_bounds(*QUADRUPED_BOX, 0.03)
    volumes = figure.voxelize(positions[::4], grid)
    rest = figure.voxelize(figure.positions(np.zeros((1, 14, 3))), grid).sum()
    for volume in volumes:
        assert volume.sum() == pytest.approx(rest, rel=0.1)  # nothing clipped or merged away
        assert ndimage.label(volume, np.ones((3, 3, 3)))[1] == 1


def test_creature_motion_rejects_impossible_requests() -> None:
    figure = long_chain(4)
    with pytest.raises(InputError, match="rest pose"):
        creature_motion(figure, FRAMES, bounds=np.array([[-1.0, 0.02, -1.0], [1.0, 1.0, 1.0]]))
    with pytest.raises(InputError, match="link_1"):
        creature_motion(figure, FRAMES, bounds=np.array([[-0.1, -0.01, -0.6], [0.1, 0.2, 0.6]]))
    with pytest.raises(InputError, match="frames"):
        creature_motion(figure, 1)
    with pytest.raises(InputError, match="bounds"):
        creature_motion(figure, FRAMES, bounds=np.zeros((2, 3)))
