"""Live takes to MCAP and back: `TakeRecorder`, `read_take` (also of killed recordings) and
the `samba db import` / `samba export` hooks for .mcap files."""

from __future__ import annotations

import base64
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from samba.base.errors import InputError
from samba.body.skeleton import markers_of
from samba.body.take import Take
from samba.cli import main
from samba.db.store import PoseStore
from samba.ingest.bvh import read_bvh
from samba.ingest.errors import TakeFileError
from samba.ingest.mcap_take import read_take
from samba.reconstruct.reconstruction import PoseEstimate
from samba.service.errors import ServiceError
from samba.service.take_recorder import SKELETON_LINES, TakeRecorder
from samba.synthetic.motions import generate

ROOT = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000_000_000_000
"""Capture time of the first frame, ns."""
FLUSHED = 55
"""Frames the killed recorder flushes before writing 5 more and waiting to be killed."""


def frame_time(i: int, fps: float = 30.0) -> int:
    return T0 + round(i * 1e9 / fps)


def frame_markers(pose: np.ndarray, i: int) -> np.ndarray:
    """The pose's 8 markers, with marker i % 8 missing."""
    markers = markers_of(pose).astype(np.float64)
    markers[i % 8] = np.nan
    return markers


@pytest.fixture(scope="module")
def take() -> Take:
    return generate("walk", seconds=2)


@pytest.fixture(scope="module")
def recording(take: Take, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The walk recorded with 2 cameras' 2D markers; every 10th frame predicted."""
    path = tmp_path_factory.mktemp("rec") / "walk_take.mcap"
    with TakeRecorder(path, take.fps) as recorder:
        for i, pose in enumerate(take.poses):
            estimate = PoseEstimate(pose, 0.004, 7, i % 10 != 0, i % 10 == 0)
            markers = frame_markers(pose, i)
            cameras = {"0": markers[:, :2] * 500, "1": markers[:, 1:] * 500}
            recorder.write_frame(frame_time(i), estimate, markers, cameras)
    return path


def test_topics_schemas_and_counts(recording: Path, take: Take) -> None:
    with recording.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        n = len(take)
        topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        assert topics == {
            "/pose_raw": "samba.PoseRaw",
            "/skeleton": "foxglove.SceneUpdate",
            "/markers": "foxglove.PointCloud",
            "/tf": "foxglove.FrameTransforms",
            "/camera/0/markers": "samba.CameraMarkers",
            "/camera/1/markers": "samba.CameraMarkers",
        }
        counts = {
            summary.channels[cid].topic: count
            for cid, count in summary.statistics.channel_message_counts.items()
        }
        assert counts == {topic: 1 if topic == "/tf" else n for topic in topics}
        assert summary.statistics.message_count == 5 * n + 1
        times = [m.log_time for _, _, m in reader.iter_messages(topics=["/pose_raw"])]
        assert times == [frame_time(i) for i in range(n)]
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta["take"]["name"] == "walk_take" and float(meta["take"]["fps"]) == 30.0
        assert meta["take"]["start_time"].endswith("+00:00")


def messages(path: Path, topic: str) -> list[dict]:
    with path.open("rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def test_messages_decode(recording: Path, take: Take) -> None:
    pose_raw = messages(recording, "/pose_raw")[3]
    assert np.array_equal(np.array(pose_raw["joints"], dtype=np.float32), take.poses[3])
    assert pose_raw["frame"] == 3 and pose_raw["markers_used"] == 7
    assert pose_raw["confident"] and not pose_raw["predicted"]
    assert pose_raw["timestamp"] == {"sec": 1_700_000_000, "nsec": 100_000_000}

    (entity,) = messages(recording, "/skeleton")[3]["entities"]
    assert entity["frame_id"] == "mocap" and entity["id"] == "skeleton"
    centres = [[s["pose"]["position"][a] for a in "xyz"] for s in entity["spheres"]]
    assert np.array_equal(np.array(centres, dtype=np.float32), take.poses[3])
    (lines,) = entity["lines"]
    assert lines["type"] == 2 and len(lines["points"]) == 13
    assert lines["indices"] == [j for pair in SKELETON_LINES for j in pair]

    cloud = messages(recording, "/markers")[3]
    assert cloud["frame_id"] == "mocap" and cloud["point_stride"] == 16
    points = np.frombuffer(
        base64.b64decode(cloud["data"]),
        dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("marker", "<u4")],
    )
    assert points["marker"].tolist() == [0, 1, 2, 4, 5, 6, 7]  # marker 3 missing in frame 3
    xyz = np.stack([points[a] for a in "xyz"], axis=1)
    assert np.array_equal(xyz, markers_of(take.poses[3])[points["marker"]])

    camera = messages(recording, "/camera/1/markers")[3]
    assert camera["camera"] == "1" and camera["markers"][3] is None
    assert camera["markers"][0] == pytest.approx(markers_of(take.poses[3])[0, 1:] * 500)

    (tf,) = messages(recording, "/tf")[0]["transforms"]
    assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("world", "mocap")
    assert tf["rotation"] == pytest.approx({"x": 0.5**0.5, "y": 0.0, "z": 0.0, "w": 0.5**0.5})


def test_read_take_gives_back_the_poses(recording: Path, take: Take) -> None:
    back = read_take(recording)
    assert back.poses.dtype == np.float32 and np.array_equal(back.poses, take.poses)
    assert (back.name, back.fps, back.rig, back.warnings) == ("walk_take", 30.0, "live", [])


def test_an_existing_file_is_not_overwritten(recording: Path) -> None:
    before = recording.read_bytes()
    with pytest.raises(ServiceError, match="already exists"):
        TakeRecorder(recording, 30.0)
    assert recording.read_bytes() == before


def test_a_file_cut_anywhere_gives_a_prefix_of_the_take(
    recording: Path, take: Take, tmp_path: Path
) -> None:
    data = recording.read_bytes()
    cut = tmp_path / "cut.mcap"
    recovered = []
    for size in range(0, len(data), 997):
        cut.write_bytes(data[:size])
        try:
            back = read_take(cut)
        except TakeFileError as exc:
            assert str(cut) in str(exc)
            continue
        assert np.array_equal(back.poses, take.poses[: len(back)])
        assert (
            "cut short" in back.warnings[0] and f"recovered {len(back)} frames" in back.warnings[0]
        )
        recovered.append(len(back))
    assert recovered == sorted(recovered) and recovered[0] > 0 and recovered[-1] <= len(take)


def test_a_file_damaged_inside_is_told_from_one_cut_short(
    recording: Path, take: Take, tmp_path: Path
) -> None:
    # One flipped bit in the middle of a whole file (its closing magic intact): the
    # chunk no longer decompresses (or fails its CRC), the frames before it come back,
    # and the warning says damage, not a cut.
    data = bytearray(recording.read_bytes())
    data[len(data) // 2] ^= 0x10
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    back = read_take(damaged)
    assert 0 < len(back) < len(take) and np.array_equal(back.poses, take.poses[: len(back)])
    (warning,) = back.warnings
    assert warning.startswith("file damaged inside (") and "cut short" not in warning
    assert f"recovered the {len(back)} frames before the damaged chunk" in warning


def test_exporting_a_recovered_take_warns_what_it_lost(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[: recording.stat().st_size // 2])
    assert main(["export", str(cut), "-o", str(tmp_path / "cut.glb")]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"samba: warning: {cut}: file cut short") and "recovered" in err


KILLED_RECORDER = f"""
import sys, time
from samba.reconstruct.reconstruction import PoseEstimate
from samba.body.skeleton import markers_of
from samba.synthetic.motions import generate
from samba.service.take_recorder import TakeRecorder

take = generate("walk", seconds=2)
recorder = TakeRecorder(sys.argv[1], take.fps, flush_interval_s=3600)
for i, pose in enumerate(take.poses[:{FLUSHED + 5}]):
    recorder.write_frame(i * 33_333_333, PoseEstimate(pose, 0.0, 8, True, False), markers_of(pose))
    if i + 1 == {FLUSHED}:
        recorder.flush()
print("ready", flush=True)
time.sleep(60)
"""


def test_a_killed_recorder_leaves_every_flushed_frame(tmp_path: Path, take: Take) -> None:
    path = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED_RECORDER, str(path)],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    back = read_take(path)
    assert len(back) == FLUSHED and np.array_equal(back.poses, take.poses[:FLUSHED])
    (warning,) = back.warnings
    assert "cut short" in warning and f"recovered {FLUSHED} frames" in warning


def test_a_file_that_is_not_mcap_is_named_in_the_error(tmp_path: Path) -> None:
    path = tmp_path / "notes.mcap"
    path.write_text("not a recording\n")
    with pytest.raises(InputError, match=re.escape(f"{path}: not an MCAP file")):
        read_take(path)
    missing = tmp_path / "missing.mcap"
    with pytest.raises(InputError, match=re.escape(f"{missing}: cannot read file")):
        read_take(missing)


def test_db_import_of_a_recording(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "db"
    assert main(["db", "init", str(store)]) == 0
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + bytes(40))
    argv = ["db", "import", str(store), str(recording), str(bad), "--subject", "ann"]
    assert main([*argv, "--no-progress"]) == 1  # the bad file fails, the recording is added
    out = capsys.readouterr().out
    assert "1 added, 0 already stored, 1 failed" in out and "bad.mcap" in out
    (info,) = PoseStore.open(store).takes
    assert (info.name, info.frame_count, info.fps) == ("walk_take", 60, 30.0)
    assert (info.rig, info.subject) == ("live", "ann")


def test_export_of_a_recording(recording: Path, tmp_path: Path) -> None:
    out = tmp_path / "x.bvh"
    assert main(["export", str(recording), "-o", str(out)]) == 0
    assert read_bvh(out).n_frames == 60


def test_a_take_with_dropped_frames_keeps_its_recorded_timing(
    take: Take, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Frames 20-29 (0.33 s) and 35-54 (0.67 s) of a 2-s walk were never recorded: the
    take still lasts 2 s at 30 fps, the short gap interpolated, the long one held, and
    the export says so and plays the motion at its speed."""
    path = tmp_path / "gaps.mcap"
    kept = [i for i in range(len(take)) if not (20 <= i < 30 or 35 <= i < 55)]
    with TakeRecorder(path, take.fps) as recorder:
        for i in kept:
            estimate = PoseEstimate(take.poses[i], 0.004, 8, True, False)
            recorder.write_frame(frame_time(i), estimate, markers_of(take.poses[i]))
    read = read_take(path)
    assert len(read) == len(take) and read.fps == take.fps and read.source_frames == len(kept)
    (warning,) = read.warnings
    assert warning.startswith("2 gaps of dropped frames (longest 0.70 s, about 30 frames")
    assert "the last pose held across 1 longer" in warning
    np.testing.assert_allclose(read.poses[kept], take.poses[kept], atol=1e-5)
    step = (np.arange(1, 11) / 11)[:, None, None]  # the short gap: linear from 19 to 30
    bridged = take.poses[19] + step * (take.poses[30] - take.poses[19])
    np.testing.assert_allclose(read.poses[20:30], bridged, atol=1e-5)
    np.testing.assert_allclose(read.poses[35:55], np.broadcast_to(take.poses[34], (20, 13, 3)))
    assert main(["export", str(path), "-o", str(tmp_path / "gaps.bvh")]) == 0
    out = capsys.readouterr()
    assert f"{len(take)} frames at 30 fps ({(len(take) - 1) / 30:.1f} s)" in out.out
    assert "gaps of dropped frames" in out.err
