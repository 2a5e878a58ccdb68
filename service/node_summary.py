"""What a camera node's run did: `NodeTally` counts frames as `samba.service.node.run_node`
sends them (missing markers, late frames, the start-up's frames, send errors) and makes
the status lines and the `NodeSummary` of them. Times are seconds."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from samba.body import N_MARKERS

STATUS_SECONDS = 5.0
"""Interval of the status lines `run_node` prints when asked."""


class SenderCounts(Protocol):
    """What the tally reads of a `PacketSender`: its camera, its send errors so far and
    the last one's text."""

    camera: int
    errors: int
    last_error: str


@dataclass(frozen=True)
class NodeSummary:
    """What a node run did: `frames` sent (or attempted), `missing_rate` the fraction of
    (frame, marker) reported missing, `send_errors` packets that could not be sent,
    `late_frames` frames whose packet went out after their deadline once the node had
    kept one (of `paced_frames` that had one), `startup_frames` the late frames before
    the first on time (the node's start-up: a grid started before it was ready, the
    first frame's compiling), `seconds` of wall time, `process_ms` mean detection +
    tracking time per frame, `interrupted` whether Ctrl-C ended it, `missing_what` what
    the missing rate counts, for people."""

    camera: int
    frames: int
    missing_rate: float
    send_errors: int
    late_frames: int
    paced_frames: int
    seconds: float
    process_ms: float
    interrupted: bool
    missing_what: str = "markers missing"
    startup_frames: int = 0

    @property
    def kept_up(self) -> bool:
        """Whether every frame with a deadline after the start-up was sent in time."""
        return self.late_frames == 0

    def describe(self) -> str:
        """One line for people."""
        if self.paced_frames:
            on_time = self.paced_frames - self.late_frames - self.startup_frames
            starting = (
                f", the first {self.startup_frames} late while the node started"
                if self.startup_frames
                else ""
            )
            pace = (
                f"kept up with real time ({on_time} frames on time{starting})"
                if self.kept_up
                else f"fell behind real time: {self.late_frames} of {self.paced_frames} frames "
                f"late{starting}"
            )
        else:
            pace = "not paced"
        ended = "interrupted; " if self.interrupted else ""
        return (
            f"camera {self.camera}: {ended}{self.frames} frames in {self.seconds:.1f} s, "
            f"{100 * self.missing_rate:.1f}% {self.missing_what}, {self.send_errors} send errors, "
            f"{pace}, {self.process_ms:.2f} ms per frame detecting and tracking"
        )


class NodeTally:
    """The running counts of a node run, and the status lines and summary made of them."""

    def __init__(self, sender: SenderCounts, missing_what: str) -> None:
        self.sender = sender
        self.missing_what = missing_what
        self.began = time.monotonic()
        self.frames = self.missing = self.late = self.paced = self.startup = 0
        self.process_s = 0.0
        self._mark = (self.began, 0, 0)
        """Clock, frames and send errors at the last status line (or the first frame)."""

    def count(self, values: np.ndarray | None, deadline: float | None) -> None:
        """Count one frame sent now: its markers (8, 2) or pose (13, 3), None when
        nothing was sent, and its deadline (None: unpaced)."""
        if self.frames == 0:
            self._mark = (time.monotonic(), 0, self.sender.errors)
        self.frames += 1
        self.missing += N_MARKERS if values is None else int(np.isnan(values[:, 0]).sum())
        if deadline is not None:
            late = time.time() > deadline
            starting = self.paced == self.startup  # no frame on time yet
            self.paced += 1
            if late and starting:
                self.startup += 1
            else:
                self.late += late

    def status_due(self) -> bool:
        """Whether `STATUS_SECONDS` have passed since the last status line."""
        return time.monotonic() >= self._mark[0] + STATUS_SECONDS

    def status_line(self) -> str:
        """How the node is doing since the last status line, as one line."""
        now, (since, frames, errors) = time.monotonic(), self._mark
        self._mark = (now, self.frames, self.sender.errors)
        errors = self.sender.errors - errors
        return (
            f"camera {self.sender.camera}: frame {self.frames}, "
            f"{(self.frames - frames) / max(now - since, 1e-9):.1f} fps, "
            f"{self.late} late so far, {errors} send errors in the last {now - since:.1f} s"
            + (f" ({self.sender.last_error})" if errors else "")
        )

    def summary(self, interrupted: bool) -> NodeSummary:
        """The run's summary, now."""
        return NodeSummary(
            camera=self.sender.camera,
            frames=self.frames,
            missing_rate=self.missing / (N_MARKERS * self.frames) if self.frames else math.nan,
            send_errors=self.sender.errors,
            late_frames=self.late,
            paced_frames=self.paced,
            seconds=time.monotonic() - self.began,
            process_ms=1000.0 * self.process_s / self.frames if self.frames else math.nan,
            interrupted=interrupted,
            missing_what=self.missing_what,
            startup_frames=self.startup,
        )
