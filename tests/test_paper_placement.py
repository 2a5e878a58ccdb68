"""The paper's placement and marker hold (issue 44): a retrieved pose goes where the
observation has its shoulders, and a marker lost for a few frames stays where it was
seen, on a real CMU take where the marker centroid places the poses elsewhere."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from samba.body import Alignment, markers_of, standard_pose
from samba.db import PoseIndex
from samba.evaluation.protocol import capture_take
from samba.ingest import load_bvh_take
from samba.reconstruct import MarkerHold, Method, method

TEST_TAKE, DATABASE = "cgspeed_131_01", ("cgspeed_131_02", "cgspeed_131_03", "iclone_002_01")
FRAMES = 150


@pytest.fixture(scope="module")
def real_take(cmu_dir: Path) -> tuple[np.ndarray, PoseIndex]:
    """A real CMU take (5 s at 30 fps) and a pose index of three other real takes."""
    truth = load_bvh_take(cmu_dir / f"{TEST_TAKE}.bvh").poses[:FRAMES].astype(np.float64)
    database = np.concatenate([load_bvh_take(cmu_dir / f"{n}.bvh").poses for n in DATABASE])
    return truth, PoseIndex.build(database)


def placed(name: str, by_shoulders: bool) -> Method:
    """Method `name` placing its poses by the shoulder midpoint or by the marker centroid."""
    chosen = method(name)
    return replace(chosen, config=replace(chosen.config, shoulder_origin=by_shoulders))


def head_and_mean_cm(poses: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    errors = np.linalg.norm(poses - truth, axis=-1) * 100.0
    return float(errors[:, 0].mean()), float(errors.mean())


def test_shoulder_origin_moves_only_the_origin() -> None:
    markers = markers_of(standard_pose())[None] + np.array([0.3, 0.0, -0.2])
    markers[0, 4] += [0.0, 0.0, 0.25]  # a knee forward: the centroid moves, not the shoulders
    by_centroid = Alignment.from_markers(markers)
    by_shoulders = Alignment.from_markers(markers, shoulder_origin=True)
    assert np.allclose(by_shoulders.origin[0], markers[0, :2].mean(axis=0))
    assert np.allclose(by_shoulders.yaw, by_centroid.yaw)
    assert not np.allclose(by_shoulders.origin, by_centroid.origin)
    markers[0, 1] = np.nan  # one shoulder lost: the centroid again
    assert np.allclose(
        Alignment.from_markers(markers, shoulder_origin=True).origin,
        Alignment.from_markers(markers).origin,
    )


def test_nn_puts_the_retrieved_shoulders_on_the_observed_ones(real_take) -> None:
    truth, index = real_take
    markers = capture_take(TEST_TAKE, truth, seed=0).markers
    shoulders = markers[:, :2].mean(axis=1)
    both = ~np.isnan(shoulders).any(axis=1)
    by_shoulders = placed("nn", True).build(index).reconstruct(markers).poses
    by_centroid = placed("nn", False).build(index).reconstruct(markers).poses
    gap = np.linalg.norm(by_centroid[:, 1:3].mean(axis=1) - shoulders, axis=-1)[both]
    assert np.abs(by_shoulders[both, 1:3].mean(axis=1) - shoulders[both]).max() < 1e-9
    assert gap.mean() > 0.03  # on this take the centroid puts them 3 cm and more away
    head_shoulders, _ = head_and_mean_cm(by_shoulders, truth)
    head_centroid, _ = head_and_mean_cm(by_centroid, truth)
    assert head_shoulders < 0.5 * head_centroid


def test_samba_placed_by_the_shoulders_finds_the_head(real_take) -> None:
    truth, index = real_take
    markers = capture_take(TEST_TAKE, truth, seed=0).markers
    head_shoulders, mean_shoulders = head_and_mean_cm(
        placed("samba", True).build(index).reconstruct(markers).poses, truth
    )
    head_centroid, mean_centroid = head_and_mean_cm(
        placed("samba", False).build(index).reconstruct(markers).poses, truth
    )
    assert head_shoulders < head_centroid - 1.0
    assert mean_shoulders < mean_centroid


def test_held_markers_keep_samba_close_to_its_clean_error(real_take) -> None:
    truth, index = real_take
    clean = capture_take(TEST_TAKE, truth, seed=0).markers
    dropped = capture_take(TEST_TAKE, truth, seed=0, dropout=0.1).markers
    samba = method("samba")
    unheld = replace(samba, config=replace(samba.config, hold_frames=0))
    _, clean_cm = head_and_mean_cm(samba.build(index).reconstruct(clean).poses, truth)
    held_result = samba.build(index).reconstruct(dropped)
    _, held_cm = head_and_mean_cm(held_result.poses, truth)
    _, unheld_cm = head_and_mean_cm(unheld.build(index).reconstruct(dropped).poses, truth)
    assert held_cm < unheld_cm
    assert held_cm < 1.1 * clean_cm
    seen = (~np.isnan(dropped).any(axis=-1)).sum(axis=1)
    assert np.array_equal(held_result.markers_used, seen)  # held markers are not counted


def test_a_marker_is_held_for_at_most_hold_frames() -> None:
    frames = np.zeros((6, 8, 3))
    frames[:, 2] = np.arange(6)[:, None]
    frames[1:5, 2] = np.nan  # the left wrist lost for four frames
    held = MarkerHold(2).fill(frames)
    assert np.allclose(held[1:3, 2], 0.0)  # held at its last position for two frames
    assert np.isnan(held[3:5, 2]).all()  # then missing
    assert np.allclose(held[5, 2], 5.0)
    assert np.allclose(np.delete(held, 2, axis=1), 0.0)
    assert np.isnan(MarkerHold(0).fill(frames)[1:5, 2]).all()


def test_the_hold_carries_over_between_steps_and_is_reset(real_take) -> None:
    truth, index = real_take
    markers = capture_take(TEST_TAKE, truth[:4], seed=0).markers
    markers[2:, 3] = np.nan  # the right wrist lost from frame 2
    live = method("samba").build(index)
    stepped = np.stack([live.step(m).pose for m in markers])
    batch = method("samba").build(index).reconstruct(markers).poses
    assert np.abs(stepped - batch).max() < 1e-9
    live.reset()
    assert np.isnan(live.held.last).all()
