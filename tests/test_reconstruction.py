"""13 joints from 8 markers (`samba.reconstruct.reconstruction`, `samba.reconstruct.methods`)
on a small synthetic database: database poses come back, missing or infinite markers never
give NaN poses, the live and batch paths agree, and `best` beats `samba` beats `nn`."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import samba.db.index
from samba.body.skeleton import markers_of, mirror_poses, standard_pose
from samba.db.index import PoseIndex
from samba.reconstruct.methods import method
from samba.reconstruct.reconstruction import Reconstruction, Reconstructor, reconstruct_together
from samba.synthetic.motions import MOTIONS, generate, library

METHOD_NAMES = ("nn", "samba", "best")
PAIRS = ((0, 1), (2, 3), (4, 5), (6, 7))
"""Left/right marker pairs: shoulders, wrists, knees, feet."""
LEFT, RIGHT = [0, 2, 4, 6], [1, 3, 5, 7]
TAKES_PER_MOTION, FRAMES = 2, 120  # the database: 4 s takes at 30 fps
UNIQUE = 0.006
"""A database pose counts as identifiable from its markers when every other pose's
markers are at least this far (index feature distance, m): `best` weighs samples within
a few millimetres of the observation alike, so near-duplicates blend."""


@pytest.fixture(scope="module")
def database() -> np.ndarray:
    """(1920, 13, 3) float32 poses: two 4 s takes of each synthetic motion."""
    takes = library(takes_per_motion=TAKES_PER_MOTION, seconds=FRAMES / 30.0)
    return np.concatenate([take.poses for take in takes])


@pytest.fixture(scope="module")
def reconstructors(database: np.ndarray) -> dict[str, Reconstructor]:
    """A reconstructor per method, over the mirrored database where the method wants it."""
    plain = PoseIndex.build(database)
    mirrored = PoseIndex.build(np.concatenate([database, mirror_poses(database)]))
    return {
        name: method(name).build(mirrored if method(name).mirrored_database else plain)
        for name in METHOD_NAMES
    }


@pytest.fixture(scope="module")
def identifiable(database: np.ndarray, reconstructors: dict[str, Reconstructor]) -> np.ndarray:
    """One identifiable database row per motion that has one (most do)."""
    distances, _ = reconstructors["best"].source.query(markers_of(database), k=2)
    per_motion = TAKES_PER_MOTION * FRAMES
    rows = []
    for m in range(len(MOTIONS)):
        motion_rows = per_motion * m + np.arange(per_motion)
        unique = motion_rows[distances[motion_rows, 1] >= UNIQUE]
        rows.extend(unique[len(unique) // 2 : len(unique) // 2 + 1])
    assert len(rows) >= 5
    return np.array(rows)


def _observe(
    motion: str, seed: int, seconds: float = 2.0, sigma: float = 0.003
) -> tuple[np.ndarray, np.ndarray]:
    """A held-out take's poses (F, 13, 3) and its markers (F, 8, 3) with `sigma` m noise."""
    poses = generate(motion, seconds=seconds, seed=seed).poses.astype(np.float64)
    rng = np.random.default_rng(seed)
    return poses, markers_of(poses) + rng.normal(0.0, sigma, (len(poses), 8, 3))


def _mpjpe(result: Reconstruction, poses: np.ndarray) -> float:
    return float(np.linalg.norm(result.poses - poses, axis=-1).mean())


@pytest.mark.parametrize("name", ["best", "nn"])
def test_noise_free_database_pose_comes_back_confident(
    database: np.ndarray,
    reconstructors: dict[str, Reconstructor],
    identifiable: np.ndarray,
    name: str,
) -> None:
    r = reconstructors[name]
    for row in identifiable:
        r.reset()
        estimate = r.step(markers_of(database[row]))
        assert np.linalg.norm(estimate.pose - database[row], axis=-1).max() < 1e-3
        assert estimate.residual < 1e-3
        assert estimate.confident
        assert not estimate.predicted
        assert estimate.markers_used == 8


SPECIAL_MASKS = [
    np.zeros(8, dtype=bool),  # all missing
    *(np.arange(8) == i for i in range(8)),  # a single marker
    np.isin(np.arange(8), LEFT),  # one side only
    np.isin(np.arange(8), RIGHT),
    np.isin(np.arange(8), [0, 1]),  # a pair alone: too few markers
]
masks = st.one_of(
    st.sampled_from(SPECIAL_MASKS),
    st.lists(st.booleans(), min_size=8, max_size=8).map(np.array),
)


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(["best", "samba"]),
    present=st.lists(masks, min_size=1, max_size=6).map(np.stack),
    start=st.integers(0, 50),
    live=st.booleans(),
)
def test_missing_markers_never_give_nan(
    reconstructors: dict[str, Reconstructor],
    name: str,
    present: np.ndarray,
    start: int,
    live: bool,
) -> None:
    _, markers = _observe("wave", seed=500)
    markers = markers[start : start + len(present)]
    markers[~present] = np.nan
    r = reconstructors[name]
    r.reset()
    if live:
        estimates = [r.step(m) for m in markers]
        poses = np.stack([e.pose for e in estimates])
        predicted = np.array([e.predicted for e in estimates])
        confident = np.array([e.confident for e in estimates])
        used = np.array([e.markers_used for e in estimates])
    else:
        result = r.reconstruct(markers)
        poses, predicted = result.poses, result.predicted
        confident, used = result.confident, result.markers_used
    assert np.isfinite(poses).all()
    count = present.sum(axis=1)
    paired = np.any([present[:, a] & present[:, b] for a, b in PAIRS], axis=0)
    assert np.array_equal(predicted, (count < 3) | ~paired)
    assert not confident[predicted].any()
    assert np.array_equal(used[~predicted], count[~predicted])


@pytest.mark.parametrize("name", METHOD_NAMES)
def test_all_missing_at_the_first_frame_gives_the_standard_pose(
    reconstructors: dict[str, Reconstructor], name: str
) -> None:
    r = reconstructors[name]
    r.reset()
    estimate = r.step(np.full((8, 3), np.nan))
    assert np.isfinite(estimate.pose).all()
    assert np.abs(estimate.pose - standard_pose()).max() < 1e-9
    assert estimate.predicted
    assert not estimate.confident


@pytest.mark.parametrize("name", ["samba", "best"])
def test_live_path_equals_batch_path(reconstructors: dict[str, Reconstructor], name: str) -> None:
    _, markers = _observe("kick", seed=501)
    markers[np.random.default_rng(0).random(markers.shape[:2]) < 0.2] = np.nan
    r = reconstructors[name]
    r.reset()
    batch = r.reconstruct(markers)
    r.reset()
    live = [r.step(m) for m in markers]
    assert np.abs(np.stack([e.pose for e in live]) - batch.poses).max() < 1e-9
    assert np.abs(np.array([e.residual for e in live]) - batch.residual).max() < 1e-9
    assert [e.markers_used for e in live] == batch.markers_used.tolist()
    assert [e.confident for e in live] == batch.confident.tolist()
    assert [e.predicted for e in live] == batch.predicted.tolist()


@pytest.mark.parametrize("name", ["samba", "best", "nn"])
def test_sessions_reconstructed_together_get_their_own_poses(
    reconstructors: dict[str, Reconstructor], name: str
) -> None:
    """Three live sessions on one database, their frames in one batch each instant: every
    session gets the poses it gets alone, its smoothness term from its own history, also
    when one session loses its markers or starts later."""
    motions = ["kick", "walk", "squat"]
    takes = [_observe(motion, seed=600 + i)[1] for i, motion in enumerate(motions)]
    takes[1][20:26] = np.nan  # the second session loses every marker for a while
    source, config = reconstructors[name].source, reconstructors[name].config
    alone = [type(reconstructors[name])(source, config) for _ in takes]
    expected = [r.reconstruct(m) for r, m in zip(alone, takes, strict=True)]
    sessions = [type(r)(source, config) for r in alone]
    together: list[list[np.ndarray]] = [[], [], []]
    for f in range(len(takes[0])):
        running = [s for s in range(3) if not (s == 2 and f < 10)]  # the third starts late
        frames = np.stack([takes[s][f if s != 2 else f - 10] for s in running])
        result = reconstruct_together([sessions[s] for s in running], frames)
        for row, s in enumerate(running):
            together[s].append(result.estimate(row).pose)
            assert result.estimate(row).predicted == (s == 1 and 20 <= f < 26)
    for s in range(3):
        got = np.stack(together[s])
        assert np.abs(got - expected[s].poses[: len(got)]).max() < 1e-9


def test_reconstructed_together_only_with_one_source_and_configuration(
    reconstructors: dict[str, Reconstructor],
) -> None:
    samba, best = reconstructors["samba"], reconstructors["best"]
    markers = np.repeat(markers_of(standard_pose())[None], 2, axis=0)
    with pytest.raises(ValueError, match="share class, configuration and source"):
        reconstruct_together([samba, best], markers)
    with pytest.raises(ValueError, match="one frame per reconstructor"):
        reconstruct_together([samba], markers)


@pytest.mark.parametrize("name", ["samba", "best"])
def test_prepared_index_builds_nothing_when_markers_are_lost(
    database: np.ndarray, name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A live capture whose markers get occluded must not stall a frame building the
    index's table for the new marker mask: construction prepares every single missing
    marker, `prepare(2)` every pair (with `best`'s part masks of them)."""
    chosen = method(name)
    poses = (
        np.concatenate([database, mirror_poses(database)]) if chosen.mirrored_database else database
    )
    r = chosen.build(PoseIndex.build(poses))
    assert r.prepare(2) == 36
    built: list[np.ndarray] = []
    real = samba.db.index._Tree.build

    def counted(features: np.ndarray, *args: object, **kwargs: object) -> object:
        built.append(features)
        return real(features, *args, **kwargs)

    monkeypatch.setattr(samba.db.index._Tree, "build", counted)
    _, markers = _observe("walk", seed=502)
    lost = np.random.default_rng(1).random(markers.shape[:2]) < 0.1
    lost[np.cumsum(lost, axis=1) > 2] = False  # at most two markers lost per frame
    markers[lost] = np.nan
    assert (lost.sum(axis=1) == 2).any()
    r.reset()
    result = r.reconstruct(markers)
    assert not built
    assert np.isfinite(result.poses).all()
    r.reset()
    r.step(np.where(np.arange(8)[:, None] < 3, np.nan, markers[0]))  # three lost: built now
    assert built


def test_accuracy_best_beats_samba_beats_nn(reconstructors: dict[str, Reconstructor]) -> None:
    takes = [_observe(motion, seed=600 + i) for i, motion in enumerate(("walk", "squat", "turn"))]
    mpjpe = {}
    for name, r in reconstructors.items():
        errors = []
        for poses, markers in takes:
            r.reset()
            errors.append(_mpjpe(r.reconstruct(markers), poses))
        mpjpe[name] = np.mean(errors)
    assert mpjpe["best"] < mpjpe["samba"] < mpjpe["nn"], mpjpe
    assert mpjpe["best"] < 0.04, mpjpe


def test_infinite_markers_count_as_missing(reconstructors: dict[str, Reconstructor]) -> None:
    _, markers = _observe("walk", seed=502, seconds=0.5)
    infinite, missing = markers.copy(), markers.copy()
    infinite[::2, 2, 1] = np.inf
    infinite[1::3, 5] = -np.inf
    missing[::2, 2] = np.nan
    missing[1::3, 5] = np.nan
    r = reconstructors["samba"]
    r.reset()
    expected = r.reconstruct(missing)
    r.reset()
    result = r.reconstruct(infinite)
    assert np.isfinite(result.poses).all()
    assert np.abs(result.poses - expected.poses).max() < 1e-12
    assert np.array_equal(result.markers_used, expected.markers_used)
    assert (result.markers_used < 8).any()


@pytest.mark.parametrize("shape", [(8, 3), (4, 7, 3), (4, 8, 2), (4, 8, 3, 1)])
def test_wrong_marker_shape_raises(
    reconstructors: dict[str, Reconstructor], shape: tuple[int, ...]
) -> None:
    with pytest.raises(ValueError, match="markers must be"):
        reconstructors["samba"].reconstruct(np.zeros(shape))


@pytest.mark.parametrize("shape", [(7, 3), (8, 2), (1, 8, 3)])
def test_wrong_step_shape_raises(
    reconstructors: dict[str, Reconstructor], shape: tuple[int, ...]
) -> None:
    with pytest.raises(ValueError, match="markers must be"):
        reconstructors["best"].step(np.zeros(shape))
