"""The live server finds the marker labels camera nodes lost (`labels = "server"`).

Three rendered synthetic camera nodes (`CameraNode`: detection and tracking, as `samba
node` runs them) film a held-out kick; their packets' contents, labelled markers and
unlabelled blobs (`CameraMarkers`), go through the session's `FramePipeline` once with
the server's labelling and once with the nodes' labels as they are; as packets, through
a `CaptureSession`, whose metrics count the labels the server found.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from live_fixtures import config

from samba.body.skeleton import N_MARKERS, markers_of
from samba.cameras.calibration_file import write_calibration
from samba.cameras.camera import CameraGroup
from samba.cameras.synthetic_cameras import with_size
from samba.markers.lead_in import standing_lead_in
from samba.markers.observation import spread_cameras
from samba.markers.stage_tracking import StageTracker
from samba.service.frame_pipeline import CameraMarkers, FramePipeline
from samba.service.node import CameraNode, SubjectStart, SyntheticFeed
from samba.service.packet import MarkerPacket
from samba.service.pipeline_workers import FrameDone, InlinePipelines
from samba.service.session import CaptureSession
from samba.synthetic.motions import generate

FPS = 30.0


class Filmed:
    """What the nodes sent: `frames` (one `CameraMarkers` per frame), `truth` (F, 8, 3)
    m, and the calibration file of the `cameras`."""

    def __init__(self, tmp_path: Path) -> None:
        poses = generate("kick", seconds=4, fps=FPS, seed=5).poses
        lead_in = standing_lead_in(poses, FPS)
        self.cameras = CameraGroup(
            tuple(with_size(c, (320, 240)) for c in spread_cameras(poses, 3))
        )
        self.calibration = tmp_path / "stage.toml"
        write_calibration(self.calibration, self.cameras)
        self.truth = markers_of(lead_in.poses)
        labels = np.full((len(self.cameras), len(lead_in.poses), N_MARKERS, 2), np.nan)
        blobs: list[list[np.ndarray]] = []
        for i, camera in enumerate(self.cameras):
            feed = SyntheticFeed(camera, i, lead_in, FPS, seed=3, start_at=0.0, pace=False)
            node = CameraNode(camera, SubjectStart.of(lead_in), feed.mask)
            blobs.append([])
            for f, capture in enumerate(feed.captures()):
                labels[i, f] = node.process(capture.frame)
                blobs[i].append(node.unlabelled())
        self.frames = [
            CameraMarkers(labels[:, f], tuple(b[f] for b in blobs))
            for f in range(len(lead_in.poses))
        ]


@pytest.fixture(scope="module")
def filmed(tmp_path_factory: pytest.TempPathFactory) -> Filmed:
    return Filmed(tmp_path_factory.mktemp("server-labels"))


def triangulated(
    filmed: Filmed, store: Path, labels: str, frames: list[CameraMarkers]
) -> np.ndarray:
    """The markers (F, 8, 3) m the session's pipeline triangulates from `frames`."""
    pipeline = FramePipeline(config(filmed.calibration, store, labels=labels), 0.0)
    try:
        return np.stack([pipeline.process(frame, 0.0, 0.0).markers for frame in frames])
    finally:
        pipeline.close()


def without_packets(frames: list[CameraMarkers], rate: float, seed: int) -> list[CameraMarkers]:
    """The frames with each camera's packet lost at `rate`, never all of a frame's."""
    rng = np.random.default_rng(seed)
    out = []
    for frame in frames:
        lost = rng.random(len(frame.blobs)) < rate
        lost[rng.integers(len(lost))] = False
        labels = np.where(lost[:, None, None], np.nan, frame.labels)
        out.append(
            CameraMarkers(
                labels, tuple(None if x else b for x, b in zip(lost, frame.blobs, strict=True))
            )
        )
    return out


@pytest.mark.parametrize("loss", [0.0, 0.1])
def test_the_server_finds_labels_the_nodes_lost_without_swapping(
    filmed: Filmed, live_store: Path, loss: float
) -> None:
    frames = without_packets(filmed.frames, loss, seed=2) if loss else filmed.frames
    server = triangulated(filmed, live_store, "server", frames)
    nodes = triangulated(filmed, live_store, "nodes", frames)
    missing = {
        name: np.isnan(m[..., 0]).mean() for name, m in (("server", server), ("nodes", nodes))
    }
    assert missing["server"] < 0.75 * missing["nodes"], missing
    error = np.linalg.norm(server - filmed.truth, axis=-1)
    found = ~np.isnan(error)
    assert error[found].max() < 0.03  # meters: no marker under another's label
    assert np.sqrt(np.mean(error[found] ** 2)) < 0.015


def test_the_server_labels_by_default_with_three_cameras_or_more(
    filmed: Filmed, live_store: Path, live_calibration: Path
) -> None:
    for calibration, expected in ((filmed.calibration, True), (live_calibration, False)):
        pipeline = FramePipeline(config(calibration, live_store, labels="auto"), 0.0)
        pipeline.close()
        assert pipeline.server_labels is expected


def test_the_nodes_labels_stand_and_a_lost_frame_is_skipped(filmed: Filmed) -> None:
    frames = filmed.frames[:40]
    stage = StageTracker.from_labels(filmed.cameras, frames[0].labels)
    for frame in frames:
        out = stage.step(frame.centroids(), known=frame.labels)
        given = ~np.isnan(frame.labels)
        np.testing.assert_array_equal(out[given], frame.labels[given])
    gap = stage.step([None, *frames[-1].centroids()[1:]], known=frames[-1].labels)
    assert np.isnan(gap[0]).all() and not np.isnan(gap[1:]).all()


def test_the_session_metrics_count_the_labels_the_server_found(
    filmed: Filmed, live_store: Path, tmp_path: Path
) -> None:
    labelled: list[np.ndarray] = []

    def deliver(done: FrameDone) -> None:
        assert done.output is not None, done.error
        labelled.append(done.output.labels)
        session.complete(done.sequence, done.output)

    cfg = config(filmed.calibration, live_store, labels="server", fps=FPS)
    session = CaptureSession(cfg, tmp_path, InlinePipelines(deliver))
    for f, frame in enumerate(filmed.frames):
        for camera, (markers, blobs) in enumerate(zip(frame.labels, frame.blobs, strict=True)):
            packet = MarkerPacket(camera, f, f / FPS, markers, "stage", blobs[:16])
            session.on_packet(packet, f / FPS + 0.002)
    session.close()
    counts = session.metrics()["labels"]
    sent = ~np.isnan(np.stack([frame.labels for frame in filmed.frames])).any(axis=-1)
    out = ~np.isnan(np.stack(labelled)).any(axis=-1)
    assert len(labelled) == session.frames_out == len(filmed.frames)
    assert counts == {
        "from_nodes": sent.sum(),
        "found_by_server": (out & ~sent).sum(),
        "missing": (~out).sum(),
        "subject_found_again": 0,
    }
    assert counts["found_by_server"] > 0.2 * (~sent).sum()
