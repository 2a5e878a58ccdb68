"""Tests of `samba.silhouette.shape_tree`: the shape hierarchy of single-camera silhouette tracking,
on the small tree of `silhouette_fixtures`."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest
from silhouette_fixtures import (
    BODY,
    HEADINGS,
    HOME,
    SmallBuild,
    facing_angles,
    library_poses,
    view,
)

from samba.base.errors import InputError
from samba.body.body_model import PART_NAMES, standing_heights
from samba.silhouette.distance import downsampled
from samba.silhouette.pose_selection import distinct_poses
from samba.silhouette.shape_tree import DEFAULT_RADII, LEVEL_SIZES, ShapeTree


def _descendants(tree: ShapeTree, level: int, node: int) -> np.ndarray:
    """Leaf indices under `node` on `level`."""
    nodes = np.array([node])
    for upper in range(level, len(tree.levels) - 1):
        nodes = tree.children(upper, nodes)
    return nodes


def _ancestors(tree: ShapeTree, level: int) -> np.ndarray:
    """Index (leaves,) on `level` of each leaf's ancestor there, by the parent links."""
    nodes = np.arange(len(tree.leaves))
    for lower in range(len(tree.levels) - 1, level, -1):
        nodes = tree.levels[lower].parents[nodes]
    return nodes


def _leaders(tree: ShapeTree, level: int) -> np.ndarray:
    """Index (nodes,) of the leaf each node of `level` takes its pose from: the one leaf
    under it with the node's pose (asserted to exist)."""
    leaders = []
    for node, pose in enumerate(tree.levels[level].poses):
        under = _descendants(tree, level, node)
        same = under[(tree.leaves.poses[under] == pose).all(axis=(1, 2))]
        assert len(same) >= 1, f"level {level} node {node} has no leaf with its pose"
        leaders.append(same[0])
    return np.array(leaders)


def _thumbnails(tree: ShapeTree) -> np.ndarray:
    """The leaves' silhouettes at the top level's size, (leaves, 60, 80) bool."""
    return downsampled(tree.leaves.silhouettes.to_masks(), LEVEL_SIZES[0])


def test_levels_have_the_pyramid_sizes_and_shrink_towards_the_top(
    small_tree: ShapeTree,
) -> None:
    sizes = [len(level) for level in small_tree.levels]
    assert [lv.silhouettes.size for lv in small_tree.levels] == list(LEVEL_SIZES)
    assert 1 < sizes[0] < sizes[1] < sizes[2]
    for level in small_tree.levels:
        assert len(level.silhouettes) == len(level.poses) == len(level.parents)
        assert level.floor_offsets.shape == (len(level), 3)
        assert level.visibility.shape == (len(level), len(PART_NAMES))
    assert small_tree.nbytes > sum(lv.silhouettes.nbytes for lv in small_tree.levels)


def test_every_leaf_has_a_parent_chain_to_the_top(small_tree: ShapeTree) -> None:
    levels = small_tree.levels
    assert (levels[0].parents == -1).all()
    for upper, lower in pairwise(levels):
        assert ((lower.parents >= 0) & (lower.parents < len(upper))).all()
        assert len(np.unique(lower.parents)) == len(upper)  # no childless node
    tops = _ancestors(small_tree, 0)
    assert ((tops >= 0) & (tops < len(levels[0]))).all()


def test_children_of_a_level_give_each_lower_node_once(small_tree: ShapeTree) -> None:
    for level in range(len(small_tree.levels) - 1):
        upper = len(small_tree.levels[level])
        every = small_tree.children(level, np.arange(upper))
        np.testing.assert_array_equal(np.sort(every), np.arange(len(small_tree.levels[level + 1])))
        parents = small_tree.levels[level + 1].parents
        for node in (0, upper // 2, upper - 1):
            children = small_tree.children(level, np.array([node]))
            assert len(children) and (parents[children] == node).all()
            assert set(children) == set(np.flatnonzero(parents == node))
        assert len(small_tree.children(level, np.zeros(0, dtype=int))) == 0


def test_nodes_carry_the_pose_and_silhouette_of_a_leaf_beneath_them(
    small_tree: ShapeTree,
) -> None:
    leaves = small_tree.leaves
    full = leaves.silhouettes.to_masks()
    for level in range(len(small_tree.levels) - 1):
        nodes = small_tree.levels[level]
        leaders = _leaders(small_tree, level)
        np.testing.assert_array_equal(nodes.poses, leaves.poses[leaders])
        np.testing.assert_array_equal(nodes.floor_offsets, leaves.floor_offsets[leaders])
        np.testing.assert_array_equal(nodes.visibility, leaves.visibility[leaders])
        expected = downsampled(full[leaders], LEVEL_SIZES[level])
        np.testing.assert_array_equal(nodes.silhouettes.to_masks(), expected)


def test_leaves_are_the_distinct_candidates_standing_at_home(small_build: SmallBuild) -> None:
    # Each database pose, scaled to the body, is turned to face the camera from home
    # and then by each heading; the leaves are the candidates distinct_poses keeps.
    kept = distinct_poses(small_build.candidates, 5.0)
    leaves = small_build.tree.leaves
    assert len(leaves) == len(kept), (
        f"{len(leaves)} leaves, but distinct_poses keeps {len(kept)} of the candidates "
        "that face the camera from home"
    )
    np.testing.assert_allclose(leaves.poses, small_build.candidates[kept], atol=1e-5)


def test_tree_poses_stand_at_home_at_the_body_height(small_tree: ShapeTree) -> None:
    for level in small_tree.levels:
        hips = level.poses[:, [7, 8]].mean(axis=1)
        np.testing.assert_allclose(
            hips[:, [0, 2]], np.broadcast_to(HOME[[0, 2]], (len(hips), 2)), atol=1e-9
        )
        np.testing.assert_allclose(standing_heights(level.poses), BODY.height, rtol=1e-5)


def test_tree_poses_face_the_camera_turned_by_a_heading(small_tree: ShapeTree) -> None:
    # Turned to face the camera from home, then by a multiple of 60 degrees: at home
    # every leaf's front is a multiple of 60 degrees away from the camera direction.
    angles = facing_angles(small_tree.leaves.poses)
    off_grid = np.abs((angles + 30.0) % 60.0 - 30.0)
    worst = int(np.argmax(off_grid))
    assert off_grid[worst] < 0.5, (
        f"leaf {worst} faces {angles[worst]:.1f} degrees from the camera at home, not a "
        f"multiple of 60 ({(off_grid > 0.5).mean():.0%} of the leaves are off the grid)"
    )


def test_members_are_near_their_node_and_a_tighter_radius_makes_more_nodes(
    small_tree: ShapeTree, small_build: SmallBuild
) -> None:
    # DEFAULT_RADII bound the XOR between a leader and its members in the principal
    # space of the clustering; in pixels most members stay within them.
    thumbnails = _thumbnails(small_tree)
    area = thumbnails.sum(axis=(1, 2)).mean()
    middle = _leaders(small_tree, 1)
    to_middle = (thumbnails ^ thumbnails[middle[small_tree.leaves.parents]]).sum(axis=(1, 2))
    assert np.median(to_middle) / area <= DEFAULT_RADII[1]
    tighter = ShapeTree.build(
        small_build.poses,
        small_tree.view,
        small_tree.body,
        headings=HEADINGS,
        radii=(DEFAULT_RADII[0] / 2, DEFAULT_RADII[1] / 2),
    )
    assert len(tighter.levels[0]) > len(small_tree.levels[0])
    assert len(tighter.levels[1]) > len(small_tree.levels[1])
    assert len(tighter.leaves) == len(small_tree.leaves)


def test_visibility_is_a_fraction_and_side_views_hide_an_arm(small_tree: ShapeTree) -> None:
    visibility = small_tree.leaves.visibility
    assert ((visibility >= 0) & (visibility <= 1)).all()
    torso, arms = PART_NAMES.index("torso"), [PART_NAMES.index(p) for p in ("l_arm", "r_arm")]
    assert np.median(visibility[:, torso]) > 0.5
    assert (visibility[:, arms].min(axis=1) < 0.3).any()


def test_progress_counts_every_rendered_leaf(small_build: SmallBuild) -> None:
    calls = small_build.progress
    total = calls[-1][1]
    assert calls[-1][0] == total >= len(small_build.tree.leaves)
    done = [d for d, _ in calls]
    assert done == sorted(done) and all(t == total for _, t in calls)


@pytest.mark.parametrize(
    "radii", [(0.1, 0.3), (0.3, 0.3), (0.3, 0.0), (0.3, -0.1), (0.3,), (0.5, 0.3, 0.1)]
)
def test_bad_radii_raise(radii: tuple[float, ...]) -> None:
    with pytest.raises(InputError, match="radii"):
        ShapeTree.build(library_poses()[:2], view(), BODY, radii=radii)


def test_bad_poses_and_thinning_angles_raise() -> None:
    poses = library_poses()[:3]
    broken = poses.copy()
    broken[1, 4, 0] = np.nan
    with pytest.raises(InputError, match="pose 1 contains NaN"):
        ShapeTree.build(broken, view(), BODY, headings=HEADINGS)
    with pytest.raises(InputError, match="min_degrees"):
        ShapeTree.build(poses, view(), BODY, headings=HEADINGS, min_degrees=0.0)
