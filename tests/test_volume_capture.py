"""Model-free volumetric capture (issue 8): Isomap, spherical shells, frame and
sequence models, posing, the humanoid mapping, on synthetic volumes with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.volume.articulated_figure import creature_motion, long_chain, quadruped
from samba.volume.capture import capture_volumes
from samba.volume.evaluation import HumanReport, creature_take, exaggerated, human_take
from samba.volume.frame_kinematics import Branch, FrameModel, frame_model
from samba.volume.humanoid import walked_direction
from samba.volume.isomap import VoxelGraph, isomap
from samba.volume.sequence_model import fit_sequence
from samba.volume.spherical_shells import skeleton_curve, sweep_and_prune
from samba.volume.voxel_grid import VoxelGrid


def _box(low: tuple[int, int, int], high: tuple[int, int, int]) -> np.ndarray:
    """Grid indices (m, 3) of the voxels low..high - 1."""
    axes = [np.arange(a, b) for a, b in zip(low, high, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def test_sweep_and_prune_splits_at_gaps_on_any_axis() -> None:
    near = _box((0, 0, 0), (3, 3, 3)).astype(float)
    apart_in_x = near + np.array([10.0, 0.0, 0.0])
    apart_in_z = near + np.array([0.0, 0.0, 6.0])
    labels = sweep_and_prune(np.concatenate([near, apart_in_x, apart_in_z]), np.full(3, 2.0))
    assert len(np.unique(labels)) == 3
    assert len(np.unique(labels[:27])) == 1 and len(np.unique(labels[27:54])) == 1
    touching = sweep_and_prune(
        np.concatenate([near, near + np.array([2.5, 0.0, 0.0])]), np.full(3, 2.0)
    )
    assert len(np.unique(touching)) == 1


def test_voxel_graph_joins_26_neighbours_and_orders_components() -> None:
    cube = _box((0, 0, 0), (3, 3, 3))
    far = _box((10, 0, 0), (12, 1, 1))
    graph = VoxelGraph.from_indices(np.concatenate([far, cube]))
    degree = np.diff(graph.edges.indptr)
    centre = len(far) + 13  # voxel (1, 1, 1) of the cube
    assert degree[centre] == 26
    assert graph.edges[centre].max() == pytest.approx(np.sqrt(3.0))
    assert (graph.component[len(far) :] == 0).all() and (graph.component[: len(far)] == 1).all()
    with pytest.raises(InputError, match="voxel indices"):
        VoxelGraph.from_indices(np.zeros((4, 2), dtype=int))
    with pytest.raises(InputError, match="not connected"):
        isomap(graph)


def test_isomap_unfolds_a_bent_bar_to_its_length() -> None:
    along = _box((0, 0, 0), (40, 4, 4))
    up = _box((36, 4, 0), (40, 34, 4))
    graph = VoxelGraph.from_indices(np.concatenate([along, up]))
    points = isomap(graph).points
    span = np.ptp(points @ np.linalg.svd(points, full_matrices=False)[2][0])
    assert span == pytest.approx(40 + 34 - 4, rel=0.1)  # the path along the bar, not 50
    assert points.shape[1] == 3  # a bar's thickness adds no dimension


def test_isomap_keeps_a_quadrupeds_front_legs_apart() -> None:
    # A frame whose 3-D embedding put the front feet 3 voxels apart (32 along the
    # volume): front and hind legs spread left and right alike, two tied eigenvalues.
    figure, box = quadruped(), np.array([[-1.0, 0.0, -1.0], [1.0, 1.2, 1.0]])
    grid = VoxelGrid.from_bounds(box[0], box[1], 0.025)
    joints = figure.positions(creature_motion(figure, 30, seed=12, bounds=box))[10:11]
    indices = grid.indices(figure.voxelize(joints, grid)[0])
    graph = VoxelGraph.from_indices(indices)
    embedding = isomap(graph)
    positions = grid.points_at(indices)
    feet = [
        np.argmin(np.linalg.norm(positions - joints[0, figure.names.index(name)], axis=1))
        for name in ("front_left_foot", "front_right_foot")
    ]
    assert embedding.points.shape[1] >= 4
    assert np.linalg.norm(np.subtract(*embedding.points[feet])) > 20.0
    model = frame_model(skeleton_curve(embedding, graph, positions), positions)
    assert model.leaf_count == 6  # head, tail and four legs


def test_a_capsules_ends_lie_one_radius_inside_its_tips() -> None:
    # A straight capsule along x: axis from -20 to 20 voxels, radius 4, round caps.
    radius, half, voxel = 4, 20, 0.025
    reach = half + radius + 1
    axes = [np.arange(-reach, reach + 1)] + [np.arange(-radius - 1, radius + 2)] * 2
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    on_axis = np.clip(grid[:, 0], -half, half)
    inside = np.hypot(grid[:, 0] - on_axis, np.hypot(grid[:, 1], grid[:, 2])) <= radius
    indices = grid[inside]
    graph = VoxelGraph.from_indices(indices)
    positions = indices * voxel
    model = frame_model(skeleton_curve(isomap(graph), graph, positions), positions)
    fit = fit_sequence([model] * 3)
    assert len(model.branches) == 2
    for b, branch in enumerate(model.branches):
        assert abs(branch.points[-1, 0]) / voxel > half + 2  # the curve runs into the cap
        assert branch.inset / voxel == pytest.approx(radius - 1.5, abs=1.0)
        assert branch.radius / voxel == pytest.approx(radius, abs=0.5)
        assert abs(fit.branch_points[b][:, -1, 0]) / voxel == pytest.approx(half, abs=1.0)


def _kinked(at: float, degrees: float, length: float = 1.0, count: int = 21) -> np.ndarray:
    """Points (count or count + 1, 3) m of a polyline `length` m long from the origin
    along +x that turns by `degrees` towards +y at fraction `at` of its length: `count`
    evenly spaced points and the bend."""
    arc = np.union1d(np.linspace(0.0, 1.0, count), [at]) * length
    before, after = np.minimum(arc, at * length), np.maximum(arc - at * length, 0.0)
    angle = np.radians(degrees)
    return np.stack(
        [before + after * np.cos(angle), after * np.sin(angle), np.zeros_like(arc)], axis=1
    )


def test_a_leaf_end_stays_past_its_last_joint() -> None:
    points = _kinked(0.9, 90.0, count=11)  # a joint where the leaf turns, 0.1 m before its tip
    near_tip = FrameModel(np.zeros(3), (Branch(-1, points, np.array([0.9]), inset=0.3),))
    bare = FrameModel(np.zeros(3), (Branch(-1, points, np.zeros(0), inset=0.3),))
    assert fit_sequence([near_tip] * 4).branch_points[0][:, -1] == pytest.approx(
        np.tile([0.9, 0.05, 0.0], (4, 1))
    )
    assert fit_sequence([bare] * 4).branch_points[0][:, -1, 0] == pytest.approx(0.7)


def test_long_chain_gives_two_ends_and_its_links() -> None:
    report = creature_take(
        long_chain(6), "chain", seed=0, frames=16, bounds=((-1, 0, -1), (1, 0.8, 1))
    )
    assert report.model_ends == report.true_ends == 2
    assert report.model_links == report.true_links
    assert report.joints_found == 1.0  # every true joint within 2 voxels


def test_quadruped_branches_are_recovered() -> None:
    report = creature_take(quadruped(), "quadruped", seed=0, frames=16)
    assert report.model_ends == report.true_ends == 6
    assert report.true_links <= report.model_links <= report.true_links + 1  # the tail's exit
    assert report.joints_found == 1.0


def _star(ends: int, forked: bool = False) -> FrameModel:
    """A frame model of `ends` end branches, straight and 0.3 m long: from the root at
    the origin or, when `forked`, the first two from the end of a trunk branch."""
    trunk = Branch(-1, np.linspace([0.0, 0.0, 0.0], [0.0, 0.3, 0.0], 4), np.zeros(0))
    branches = [trunk] if forked else []
    for b in range(ends):
        fork = forked and b < 2
        start = trunk.points[-1] if fork else np.zeros(3)
        angle = 2 * np.pi * b / ends
        end = start + 0.3 * np.array([np.cos(angle), 0.0, np.sin(angle)])
        branches.append(Branch(0 if fork else -1, np.linspace(start, end, 4), np.zeros(0)))
    return FrameModel(np.zeros(3), tuple(branches))


def test_a_branch_seen_in_enough_frames_is_in_the_model_whatever_its_shape() -> None:
    # The sixth end (a tail) shows in 12 of 30 frames, in two tree shapes; the most
    # frequent shape alone has five ends.
    tail = [_star(6)] * 6 + [_star(6, forked=True)] * 6
    assert fit_sequence([_star(5)] * 18 + tail).model.branch_count == 6
    assert fit_sequence([_star(5)] * 22 + tail[:8]).model.branch_count == 5  # 27%: noise


def test_a_branch_gets_the_joint_count_its_frames_have_most_often() -> None:
    # One joint at mid-length, where the branch bends, in 7 frames; in 3 the skewness
    # test cut it five times over. The mean count (2.2) would round to 2 joints.
    points = _kinked(0.5, 45.0, length=0.6, count=13)
    clean = FrameModel(np.zeros(3), (Branch(-1, points, np.array([0.5])),))
    noisy = FrameModel(np.zeros(3), (Branch(-1, points, np.array([0.2, 0.4, 0.6, 0.8, 0.9])),))
    model = fit_sequence([clean] * 7 + [noisy] * 3).model
    assert len(model.joints[0]) == 1
    assert model.joints[0][0] == pytest.approx(0.5, abs=0.02)
    assert model.link_count == 2


def _forked(trunk_joint: float, bend: float = 0.0) -> FrameModel:
    """A trunk 0.5 m long along +x, radius 0.1 m, with a joint at `trunk_joint` of its
    length where it turns by `bend` degrees, carrying two straight legs 0.4 m long from
    its end."""
    points = _kinked(trunk_joint, bend, length=0.5, count=11)
    trunk = Branch(-1, points, np.array([trunk_joint]), radius=0.1)
    end = points[-1]
    legs = tuple(
        Branch(0, np.linspace(end, end + np.array([0.0, -0.4, side]), 9), np.zeros(0), radius=0.05)
        for side in (-0.1, 0.1)
    )
    return FrameModel(np.zeros(3), (trunk, *legs))


def test_a_trunk_joint_next_to_its_branching_node_becomes_the_trunks_end() -> None:
    # The joint 3 cm before the node (0.3 radii) stands for it: the trunk ends there,
    # one link; a joint at mid-trunk stays a joint of its own.
    fit = fit_sequence([_forked(0.94)] * 4)
    assert len(fit.model.joints[0]) == 0
    assert fit.model.link_count == 3
    assert fit.model.lengths[0] == pytest.approx(0.47)
    assert fit.branch_points[0][:, -1, 0] == pytest.approx(0.47)
    mid = fit_sequence([_forked(0.5, bend=30.0)] * 4)
    assert mid.model.joints[0] == pytest.approx([0.5])
    assert mid.branch_points[0][:, -1] == pytest.approx(
        np.tile(_kinked(0.5, 30.0, length=0.5)[-1], (4, 1))
    )


def test_a_leaf_drops_a_last_joint_in_its_round_tip() -> None:
    # Joints at 0.5 (where it bends) and 0.97 of a 1 m leaf of radius 0.05 m ending at
    # its curve's end: the last link would be 3 cm, shorter than the radius.
    points = _kinked(0.5, 45.0)
    tipped = FrameModel(np.zeros(3), (Branch(-1, points, np.array([0.5, 0.97]), radius=0.05),))
    fit = fit_sequence([tipped] * 4)
    assert fit.model.joints[0] == pytest.approx([0.5])
    assert fit.branch_points[0][:, -1] == pytest.approx(np.tile(points[-1], (4, 1)))


def _bent_trunk(degrees: float, front: float = 0.4) -> FrameModel:
    """A trunk along +x from x = -0.4 m to 0.1 m, its root at the origin, that turns by
    `degrees` towards +y at x = 0.1 m and goes on for `front` m (radius 0.1 m), each
    half carrying a 0.3 m leg."""
    turn = np.radians(degrees)
    out = np.outer(np.linspace(0.0, front, 9), [np.cos(turn), np.sin(turn), 0.0])
    out[:, 0] += 0.1
    front = np.concatenate([np.zeros((1, 3)), out])
    back = np.linspace([0.0, 0.0, 0.0], [-0.4, 0.0, 0.0], 9)
    halves = [Branch(-1, points, np.zeros(0), radius=0.1) for points in (back, front)]
    legs = [
        Branch(b, np.linspace(half.points[-1], half.points[-1] - [0.0, 0.3, 0.0], 7), np.zeros(0))
        for b, half in enumerate(halves)
    ]
    return FrameModel(np.zeros(3), (*halves, *legs))


def test_the_root_moves_to_where_the_trunk_bends() -> None:
    # The trunk bends 10 cm from the root by up to 40 degrees, or only 20; the root
    # stands for that joint. A trunk that never bends keeps its root.
    for most in (40.0, 20.0):
        bends = most * np.abs(np.sin(np.pi * np.arange(8) / 8))
        fit = fit_sequence([_bent_trunk(bend) for bend in bends])
        assert fit.root == pytest.approx(np.tile([0.1, 0.0, 0.0], (8, 1)), abs=0.006)
        assert fit.model.lengths[:2] == pytest.approx([0.5, 0.4], abs=0.006)
    assert (fit_sequence([_bent_trunk(0.0)] * 8).root == 0.0).all()


def test_the_root_stays_where_a_trunk_half_changes_its_length() -> None:
    # The front half is 0.5 m long in some frames and 0.25 m in others (where the legs
    # part from the trunk moves): one offset along the trunk is no one place on it.
    bends = 40.0 * np.abs(np.sin(np.pi * np.arange(8) / 8))
    frames = [_bent_trunk(bend, front=0.4 if t % 2 else 0.15) for t, bend in enumerate(bends)]
    assert (fit_sequence(frames).root == 0.0).all()


def _swinging(
    bends: np.ndarray, joints: list[np.ndarray], seed: int, radius: float = 0.0
) -> list[FrameModel]:
    """Frames of one 0.6 m branch (of `radius` m, 0: unknown) that turns by `bends` (n,)
    degrees at 0.4 of its length, swings about the root by up to 30 degrees and has
    per-frame skewness `joints`; its curve points jitter by 3 mm."""
    rng = np.random.default_rng(seed)
    frames = []
    for t, (bend, cuts) in enumerate(zip(bends, joints, strict=True)):
        points = _kinked(0.4, bend, length=0.6, count=25)
        swing = np.radians(30.0 * np.sin(2 * np.pi * t / len(bends)))
        turn = np.array(
            [[np.cos(swing), 0, np.sin(swing)], [0, 1, 0], [-np.sin(swing), 0, np.cos(swing)]]
        )
        points = points @ turn.T + rng.normal(0.0, 0.003, points.shape)
        frames.append(FrameModel(np.zeros(3), (Branch(-1, points, cuts, radius=radius),)))
    return frames


def test_a_branch_that_never_bends_keeps_no_joint() -> None:
    # The skewness test cut the straight, swinging branch once or twice in every frame,
    # at random: the frames' count says one joint at least, but no link bends.
    rng = np.random.default_rng(3)
    joints = [np.sort(rng.uniform(0.1, 0.9, rng.integers(1, 3))) for _ in range(12)]
    model = fit_sequence(_swinging(np.zeros(12), joints, seed=4)).model
    assert len(model.joints[0]) == 0
    assert model.link_count == 1


def test_a_branch_gets_one_joint_where_it_bends() -> None:
    # The branch bends at 0.4 of its length, by up to 40 degrees and back; the skewness
    # test also cut its straight outer link in most frames (two joints most often).
    rng = np.random.default_rng(5)
    bends = 40.0 * np.abs(np.sin(np.pi * np.arange(12) / 12))
    joints = [np.array([0.4 + rng.normal(0.0, 0.01), rng.uniform(0.55, 0.9)]) for _ in range(9)]
    joints += [np.array([0.4])] * 3
    model = fit_sequence(_swinging(bends, joints, seed=6)).model
    assert len(model.joints[0]) == 1
    assert model.joints[0][0] * model.lengths[0] == pytest.approx(0.24, abs=0.025)  # a voxel


def test_joints_sit_where_the_branch_bends_not_where_the_skewness_test_fired() -> None:
    # The skewness test fires past the bend (at half the length, 6 cm out) in every
    # frame; the straight links meet where the branch turns.
    bends = 40.0 * np.abs(np.sin(np.pi * np.arange(12) / 12))
    model = fit_sequence(_swinging(bends, [np.array([0.5])] * 12, seed=7)).model
    assert model.joints[0] * model.lengths[0] == pytest.approx([0.24], abs=0.025)  # a voxel


def test_frames_matched_to_another_limb_do_not_pull_the_joint() -> None:
    # 3 of 12 frames matched a curve that is not this limb: it turns by 90 degrees at
    # 0.8 of its length. Its samples cost at most one radius (5 cm) each; uncapped,
    # they took the joint to 0.4 m.
    bends = 40.0 * np.abs(np.sin(np.pi * np.arange(12) / 12))
    frames = _swinging(bends, [np.array([0.4])] * 12, seed=8, radius=0.05)
    other = Branch(-1, _kinked(0.8, 90.0, length=0.6, count=25), np.array([0.4]), radius=0.05)
    for t in (3, 6, 9):
        frames[t] = FrameModel(np.zeros(3), (other,))
    model = fit_sequence(frames).model
    assert model.joints[0] * model.lengths[0] == pytest.approx([0.24], abs=0.025)


def test_posed_model_keeps_the_measured_directions() -> None:
    report = creature_take(
        long_chain(4), "chain", seed=1, frames=12, bounds=((-1, 0, -1), (1, 0.8, 1))
    )
    motion = report.capture.motion
    forward, measured = motion.forward(), motion.positions
    assert forward.shape == measured.shape
    assert np.allclose(forward[:, 0], measured[:, 0])
    # Fixed link lengths (the sequence means) against each frame's measured joints.
    assert np.median(np.linalg.norm(forward - measured, axis=-1)) < 0.01
    smooth = motion.lowpassed(2.0)
    jitter = np.abs(np.diff(smooth.rotations, 2, axis=0)).mean()
    assert jitter < np.abs(np.diff(motion.rotations, 2, axis=0)).mean()
    assert np.allclose(np.linalg.norm(smooth.rotations, axis=-1), 1.0)
    with pytest.raises(InputError, match="--lowpass"):
        motion.lowpassed(100.0)


@pytest.fixture(scope="module")
def wave() -> HumanReport:
    """An exaggerated wave (the limbs held apart), seed 1."""
    return human_take("wave", seed=1, seconds=1.5)


def test_human_wave_has_human_topology_and_maps_to_13_joints(wave: HumanReport) -> None:
    report = wave
    assert report.separated.all()
    assert report.humanoid.mean() >= 0.9
    assert report.capture.fit.model.branch_count == 5
    assert np.nanmean(report.errors) < 12.0  # cm
    assert np.nanmean(report.errors[:, [7, 8]]) < 9.0  # cm: hips placed out and up from the crotch


@pytest.fixture(scope="module")
def natural_wave() -> HumanReport:
    """A natural wave (not exaggerated: feet together, arms near the body), seed 1."""
    return human_take("wave", seed=1, seconds=1.5, exaggerate=False)


def test_the_bvh_skeleton_keeps_the_fitted_joints_and_the_floor(wave: HumanReport) -> None:
    """The BVH's fixed links are as long as the fitted joints lie apart on average; as
    long as the curve between them (and a leaf's on into its round tip) they put the
    joints 5.9 cm off (median) and a foot 22 cm below the floor."""
    motion = wave.capture.motion
    forward = motion.forward()
    assert np.median(np.linalg.norm(forward - motion.positions, axis=-1)) < 0.02
    assert forward[..., 1].min() > -0.1  # m; the floor is at 0, the carved feet reach -0.04


def test_hips_of_a_subject_with_the_feet_together_stay_up(natural_wave: HumanReport) -> None:
    """Standing with the feet together, the legs carve one column and their branches part
    far below the hips; the legs reach up to the stature's leg length, so hips and knees
    map within 10 cm (34.6 and 21.1 cm from the carved crotch alone)."""
    report = natural_wave
    assert report.capture.fit.model.branch_count == 5
    assert np.nanmean(report.errors[:, [7, 8]]) < 10.0  # cm
    assert np.nanmean(report.errors[:, [9, 10]]) < 10.0  # cm


def test_shoulders_lie_out_from_the_top_of_the_trunk(natural_wave: HumanReport) -> None:
    """The arms branch from the top of the trunk, between the shoulders: each shoulder is
    placed out from there, level, so the shoulders map within 9 cm (12.6 cm at a fixed
    fraction along the arm, which drops with the arm)."""
    assert np.nanmean(natural_wave.errors[:, [1, 2]]) < 9.0  # cm


def test_fast_jumping_jack_arms_stay_matched_across_frames() -> None:
    """At 10 Hz the arms of a jumping jack move farther than 0.25 m between frames; they
    must still be matched (not interpolated in time), so the wrists map within 8 cm
    (25.8 cm with a 0.25 m gate)."""
    report = human_take("jumping_jacks", seed=2, seconds=1.5)
    assert report.capture.fit.model.branch_count == 5
    assert np.nanmean(report.errors[:, [5, 6]]) < 8.0  # cm


def test_exaggerated_poses_keep_bone_lengths() -> None:
    from samba.synthetic.motions import generate

    poses = generate("jumping_jacks", 1.0, 10.0, seed=4).poses.astype(np.float64)
    spread = exaggerated(poses)
    bones = [(1, 3), (3, 5), (2, 4), (4, 6), (7, 9), (9, 11), (8, 10), (10, 12)]
    for a, b in bones:
        before = np.linalg.norm(poses[:, a] - poses[:, b], axis=-1)
        assert np.allclose(np.linalg.norm(spread[:, a] - spread[:, b], axis=-1), before)
    assert np.allclose(spread[:, [0, 1, 2, 7, 8]], poses[:, [0, 1, 2, 7, 8]])
    feet = np.linalg.norm(spread[:, 11] - spread[:, 12], axis=-1)
    assert (feet > np.linalg.norm(poses[:, 11] - poses[:, 12], axis=-1)).all()


def test_the_walked_direction_is_the_horizontal_way_from_first_to_last_root() -> None:
    t = np.linspace(0.0, 1.0, 50)[:, None]
    walk = np.hstack([0.6 * t, 0.95 + 0.05 * np.sin(20 * t), -1.4 + 0.8 * t])  # (50, 3) m
    np.testing.assert_allclose(walked_direction(walk), [0.6, 0.0, 0.8], atol=1e-9)
    in_place = np.hstack([0.1 * t, 0.95 + 0.3 * t, 0.1 * t])  # crouching, 14 cm across
    assert walked_direction(in_place) is None


def test_empty_and_malformed_volumes_are_named() -> None:
    grid = VoxelGrid(np.zeros(3), 0.05, (10, 10, 10))
    volumes = np.zeros((2, 10, 10, 10), dtype=bool)
    volumes[:, 2:8, 2:8, 2:8] = True
    volumes[1] = False
    volumes[1, 0, 0, 0] = True
    with pytest.raises(InputError, match="frame 1"):
        capture_volumes(volumes, grid, 10.0)
    with pytest.raises(InputError, match="volumes must be"):
        capture_volumes(volumes[:, :5], grid, 10.0)
