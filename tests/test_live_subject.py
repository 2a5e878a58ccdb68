"""A live session that calibrates its subject from its first seconds: the frames before go
out as always, the offsets are removed after, and the take stores them."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import numpy as np
import pytest
from live_fixtures import MAX_SKEW_S, WAIT_MS, config, offline_poses, until

from samba.ingest.mcap_take import read_take
from samba.reconstruct import SkinOffsets
from samba.service.errors import ServiceError
from samba.service.packet import random_epoch
from samba.service.serve import LiveServer
from samba.service.synthetic_capture import SyntheticCapture, play

LAPS = 10
"""Most runs of the 2 s capture a test plays before the calibration must have reached a frame."""


@pytest.mark.parametrize("workers", [0, 2], ids=["in the event loop", "in worker processes"])
def test_a_session_calibrates_its_subject_and_stores_the_offsets_with_its_take(
    live_store: Path,
    live_calibration: Path,
    live_capture: SyntheticCapture,
    tmp_path: Path,
    workers: int,
) -> None:
    async def run() -> None:
        cfg = config(live_calibration, live_store, wait_ms=WAIT_MS, calibrate_s=0.5)
        bind = {"udp": ("127.0.0.1", 0), "http": None, "workers": workers}
        # a lap's frames are stamped on one grid from `start`: after a slow lap the next
        # is sent late, in a burst, and must not be dropped as off clock
        async with LiveServer([cfg], tmp_path / "takes", max_skew_s=MAX_SKEW_S, **bind) as live:
            assert live.server is not None
            session = live.server.session("stage")
            session.start_take("walk")
            # the calibration runs beside the frames and reaches the first frame after it
            # ends: the nodes go on filming (the walk again, one run) until it has, however
            # busy the machine
            start, epoch, n = time.time() + 0.2, random_epoch(), live_capture.frames
            for lap in range(LAPS):
                await play(
                    live_capture,
                    live.udp_address,
                    start + lap * n / live_capture.fps,
                    session="stage",
                    sequence0=lap * n,
                    epoch=epoch,
                )
                await until(lambda lap=lap: session.frames_out == (lap + 1) * n)
                assert session.frames_out == (lap + 1) * n, session.metrics()  # none lost
                if session.subject is not None:
                    break
            session.stop_take()
            assert session.subject is not None, f"not calibrated after {LAPS} laps"
            assert session.metrics()["subject_calibrated"]

    asyncio.run(run())
    take = read_take(tmp_path / "takes" / "stage" / "walk.mcap")
    assert len(take) % live_capture.frames == 0 and len(take) > 0
    offsets = SkinOffsets.from_dict(json.loads(take.meta["skin_offsets"]))
    assert offsets.frames == 30  # 0.5 s at 60 fps
    assert np.linalg.norm(offsets.offsets, axis=1).max() < 0.08  # these markers sit on joints
    before = offline_poses(live_capture, live_store)[:30]
    assert np.linalg.norm(take.poses[:30] - before, axis=-1).max() < 0.001  # as always


def test_calibrate_s_must_be_a_number_of_seconds(live_store: Path, live_calibration: Path) -> None:
    with pytest.raises(ServiceError, match="calibrate_s"):
        config(live_calibration, live_store, calibrate_s=-1)
    with pytest.raises(ServiceError, match="calibrate_s"):
        config(live_calibration, live_store, calibrate_s="2 s")
