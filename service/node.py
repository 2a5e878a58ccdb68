"""The camera node of the live service: frames in, one marker packet per frame out (UDP).

A node runs beside one camera of the capture stage. For every frame it finds the bright
blobs (`samba.markers.detection`), keeps the 8 marker labels on them
(`samba.markers.tracking`, started from the standard pose the subject holds when capture
begins) and sends the labelled pixels to the server as one `samba.service.packet.MarkerPacket`:
camera id, frame sequence, capture timestamp, 8 x (u, v) with NaN for missing, and the
blobs its tracker left unlabelled (at most `MAX_BLOBS`), from which a server that labels
the markers itself finds lost labels again.

Frames come from a feed, each frame a `Capture` with its capture time:

- `FileFeed`: a video file or a folder of images (`samba.cameras.frame_source`), played in real
  time at its frame rate (the timestamp is the clock when the frame is taken) or as fast
  as possible (timestamp start + index / fps);
- `WebcamFeed`: an OpenCV camera (timestamp: the clock when the frame is grabbed);
- `SyntheticFeed`: one camera of the synthetic rig filming a built-in motion
  (`samba.synthetic.motions`) or a C3D file's real markers (`samba.service.marker_motion`)
  after the standing lead-in (`samba.markers.lead_in`), rendered on the fly
  (`samba.markers.render`). Its frames are captured on a wall-clock grid, frame i at
  `start_at + i / fps`, and stamped with exactly that time, so that nodes of the same rig
  started separately with the same motion, seed and start time film the same subject at
  the same instants (no start time: `START_DELAY_SECONDS` after the node asks for its
  first frame, when its start-up is done).

`run_node` drives a `CameraNode` with a feed and a `PacketSender` until the feed ends or
Ctrl-C, and returns a `NodeSummary`. Timestamps are UNIX seconds (`time.time`).
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Literal, Protocol, TextIO

import cv2
import numpy as np

from samba.base import InputError
from samba.body import N_JOINTS, N_MARKERS
from samba.cameras import Camera, FrameSource, open_video
from samba.markers import (
    EMPTY_STAGE_FRAMES,
    LeadIn,
    MarkerTracker,
    RenderOptions,
    detect_markers,
    film_empty_stage,
    render_camera,
    standing_lead_in,
    static_mask,
)
from samba.service.node_summary import NodeSummary, NodeTally
from samba.service.packet import MAX_BLOBS, MarkerPacket, PosePacket, encode, random_epoch
from samba.synthetic import generate

DEFAULT_PORT = 9870
"""The UDP port the server (`samba serve`) listens on for camera packets by default."""
DEFAULT_FPS = 30.0
"""Frame rate of image folders and of the synthetic rig when none is given."""
RENDER_CHUNK_FRAMES = 4
"""Frames the synthetic rig renders at once: few, so that rendering never stalls a
real-time feed by more than a frame interval (about 20 ms at 640x480)."""
START_DELAY_SECONDS = 0.5
"""How far ahead of the first frame's request a wall-clock grid starts when no start time
is given."""

_SEQUENCE_MODULUS = 2**32


@dataclass(frozen=True, eq=False)
class Capture:
    """One frame of a feed.

    `frame` (H, W) grey or (H, W, 3) BGR image; `timestamp` its capture time, UNIX
    seconds; `deadline` when its packet must be out for the node to keep up with real
    time (the next frame's capture time), None for a feed played as fast as possible;
    `first` True for the first frame of the feed and of every repetition of a looped
    feed, where the subject stands in the standard pose again; `name` names the frame in
    error messages (a file, or the feed and frame number).
    """

    frame: np.ndarray
    timestamp: float
    deadline: float | None
    first: bool
    name: str


@dataclass(frozen=True)
class SubjectStart:
    """Where the subject stands in the standard pose when capture begins: hip midpoint at
    (`x`, `z`) meters on the floor, facing +Z turned by `heading_deg` about +Y (towards
    +X), `height` meters tall."""

    x: float = 0.0
    z: float = 0.0
    heading_deg: float = 0.0
    height: float = 1.70

    @classmethod
    def of(cls, lead_in: LeadIn) -> SubjectStart:
        """The start of a synthetic take's standing lead-in."""
        x, z = lead_in.position
        return cls(x, z, lead_in.heading_deg, lead_in.height)


class Node(Protocol):
    """What `run_node` drives: a frame (H, W) or (H, W, 3) in, the values to send out
    ((8, 2) markers, (13, 3) pose, or None: nothing yet) and the frame's unlabelled
    blobs (n, 2) pixels; `MISSING` says what its summary's missing rate counts."""

    MISSING: str

    def restart(self) -> None: ...

    def process(self, frame: np.ndarray, name: str = "frame") -> np.ndarray | None: ...

    def unlabelled(self) -> np.ndarray: ...


class CameraNode:
    """One camera's frame-to-markers pipeline: detection, then the 8-label tracker.

    `camera` is the calibrated camera the frames come from (its image size is checked);
    `start` where the subject stands when capture begins; `mask` bool (H, W), True =
    static bright pixels to ignore, or None; `threshold` a fixed intensity or "auto"
    (see `samba.markers.detection.detect_markers`). No label is sent on a blob that looks
    like two markers merged (`Blobs.merged`).
    """

    def __init__(
        self,
        camera: Camera,
        start: SubjectStart,
        mask: np.ndarray | None = None,
        threshold: float | Literal["auto"] = "auto",
    ) -> None:
        self.camera = camera
        self.start = start
        self.mask = mask
        self.threshold = threshold
        self.restart()

    MISSING = "markers missing"
    """What `NodeSummary.missing_rate` counts for this node: (frame, marker) pairs."""

    def restart(self) -> None:
        """Start the labels again from the standard pose at `start` (a new take)."""
        self._tracker = MarkerTracker.from_standard_pose(
            self.camera,
            (self.start.x, self.start.z),
            self.start.heading_deg,
            self.start.height,
        )

    def process(self, frame: np.ndarray, name: str = "frame") -> np.ndarray:
        """The 8 labelled markers (8, 2) pixels in this frame, NaN = missing.

        Frames must be passed in order. InputError naming `name` when the frame's size
        differs from the camera's or the frame is not an image.
        """
        width, height = self.camera.size
        shape = getattr(frame, "shape", ())
        if tuple(shape[:2]) != (height, width):
            got = f"{shape[1]}x{shape[0]}" if len(shape) >= 2 else f"shape {shape}"
            raise InputError(
                name, f"frame is {got} but camera {self.camera.name!r} is {width}x{height}"
            )
        blobs = detect_markers(frame, threshold=self.threshold, mask=self.mask, name=name)
        return self._tracker.step(blobs.centroids, blobs.merged())

    def unlabelled(self) -> np.ndarray:
        """The blobs (n, 2) pixels of the last frame no label took, the first `MAX_BLOBS`."""
        return self._tracker.anonymous_blobs[:MAX_BLOBS]


class PacketSender:
    """A UDP socket sending each frame's markers to the server as one `MarkerPacket`.

    `host`, `port`: the server; `camera` 0..65535 and `session` go into every packet,
    with the sender's `epoch`, drawn at random when it is made (`new_epoch` draws
    another); `key` (None: unsigned) signs them with an HMAC tag. A send that fails
    (server not listening, network unreachable, buffer full) is counted in `errors`
    and never raises. InputError when `host` cannot be resolved; ValueError for a bad
    camera or session (see `MarkerPacket`). Use as a context manager or call `close`.
    """

    def __init__(
        self, host: str, port: int, camera: int, session: str = "", key: bytes | None = None
    ) -> None:
        MarkerPacket(camera, 0, 0.0, np.full((N_MARKERS, 2), np.nan), session)  # validates
        self.camera, self.session, self.key = camera, session, key
        self.epoch = random_epoch()
        """The epoch put in every packet: this run of the node."""
        self.sent = 0
        """Packets handed to the network."""
        self.errors = 0
        """Packets that could not be sent."""
        self.last_error = ""
        """The last send failure, for status lines ("" if none)."""
        try:
            family, kind, protocol, _, address = socket.getaddrinfo(
                host, port, type=socket.SOCK_DGRAM
            )[0]
        except (OSError, UnicodeError) as exc:
            raise InputError(f"{host}:{port}", f"cannot resolve the server: {exc}") from None
        self._socket = socket.socket(family, kind, protocol)
        self._socket.setblocking(False)
        try:
            # connected: the kernel reports a refused port on the next send
            self._socket.connect(address)
        except OSError as exc:
            self._socket.close()
            raise InputError(f"{host}:{port}", f"cannot reach the server: {exc}") from None

    def new_epoch(self) -> None:
        """Draw a new epoch for the packets from now on (before the sequence wraps)."""
        self.epoch = random_epoch()

    def send(
        self,
        sequence: int,
        timestamp: float,
        values: np.ndarray,
        blobs: np.ndarray | None = None,
    ) -> int:
        """Send one frame: `sequence` 0..2^32 - 1, capture `timestamp` seconds, and
        either the markers (8, 2) pixels, NaN = missing, with up to `MAX_BLOBS`
        unlabelled `blobs` (n, 2) pixels (a `MarkerPacket`) or a pose (13, 3) world
        meters (a `PosePacket`, from a markerless node; `blobs` must be None or empty).
        Returns the bytes sent, 0 if the send failed."""
        header = (self.camera, sequence, timestamp)
        if np.shape(values) == (N_JOINTS, 3):
            if blobs is not None and len(blobs):
                raise ValueError("a pose packet carries no blobs")
            packet: MarkerPacket | PosePacket = PosePacket(
                *header, values, self.session, self.epoch
            )
        else:
            extra = np.zeros((0, 2)) if blobs is None else blobs
            packet = MarkerPacket(*header, values, self.session, extra, self.epoch)
        data = encode(packet, self.key)
        try:
            sent = self._socket.send(data)
        except OSError as exc:
            self.errors += 1
            self.last_error = exc.strerror or str(exc)
            return 0
        self.sent += 1
        return sent

    def close(self) -> None:
        """Close the socket."""
        self._socket.close()

    def __enter__(self) -> PacketSender:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


class FileFeed:
    """The frames of a video file or an image folder (`samba.cameras.frame_source.open_frames`).

    `fps`: the frame rate (None: the video's own, `DEFAULT_FPS` for images). With `pace`
    frame k is taken at start + k / fps on the clock (sleeping until then) and stamped
    with the clock when taken; without, frames come as fast as they decode, stamped start
    + k / fps. `loop` plays the frames again and again. InputError when a video cannot be
    opened or gives no frame rate and none is given.
    """

    def __init__(
        self, source: FrameSource, fps: float | None = None, pace: bool = True, loop: bool = False
    ) -> None:
        if fps is None:
            fps = _video_fps(source.path) if source.is_video else DEFAULT_FPS
        self.source, self.fps, self.pace, self.loop = source, fps, pace, loop

    def captures(self) -> Iterator[Capture]:
        """The frames with their capture times, in order (endless when looping)."""
        period = 1.0 / self.fps
        start, index = time.time(), 0
        while True:
            for number, image in self.source.frames():
                due = start + index * period
                if self.pace:
                    _sleep_until(due)
                stamp = time.time() if self.pace else due
                deadline = due + period if self.pace else None
                yield Capture(image, stamp, deadline, number == 0, self._frame_name(number))
                index += 1
            if not self.loop:
                return

    def _frame_name(self, number: int) -> str:
        if self.source.is_video:
            return f"{self.source.path} frame {number}"
        return str(self.source.images[number])


class WebcamFeed:
    """Frames of an OpenCV camera (`cv2.VideoCapture(index)`), stamped when grabbed.

    `fps` is requested from the camera and sets the deadlines; None takes the rate the
    camera reports (no deadlines if it reports none). InputError naming the webcam when
    it cannot be opened, stops delivering frames or a frame cannot be decoded.
    """

    def __init__(self, index: int, fps: float | None = None) -> None:
        self.name = f"webcam {index}"
        quiet = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        try:
            self._capture = cv2.VideoCapture(index)
        finally:
            cv2.utils.logging.setLogLevel(quiet)
        if not self._capture.isOpened():
            raise InputError(self.name, "cannot be opened (no such camera, or it is in use)")
        if fps is not None:
            self._capture.set(cv2.CAP_PROP_FPS, fps)
        reported = self._capture.get(cv2.CAP_PROP_FPS)
        self.fps = fps if fps is not None else (reported if reported > 0 else None)

    def captures(self) -> Iterator[Capture]:
        """The camera's frames as they come, until it stops (then InputError)."""
        try:
            index = 0
            while True:
                if not self._capture.grab():
                    raise InputError(self.name, f"stopped delivering frames after {index}")
                stamp = time.time()
                ok, frame = self._capture.retrieve()
                if not ok:
                    raise InputError(self.name, f"frame {index} cannot be decoded")
                deadline = stamp + 1.0 / self.fps if self.fps else None
                yield Capture(frame, stamp, deadline, index == 0, f"{self.name} frame {index}")
                index += 1
        finally:
            self._capture.release()


def synthetic_lead_in(motion: str, seconds: float, fps: float, seed: int) -> LeadIn:
    """The take the synthetic rig films: `samba.synthetic.motions.generate(motion, seconds, fps,
    seed)` after the standing lead-in (1 s: 0.5 s held, 0.5 s into the first pose).
    ValueError for an unknown motion or a take without frames."""
    return standing_lead_in(generate(motion, seconds, fps, seed).poses, fps)


class SyntheticFeed:
    """One camera of the synthetic rig filming a take live, on a wall-clock grid.

    `camera` films `lead_in` (`synthetic_lead_in`, or a marker take's
    `samba.service.marker_motion.MarkerMotion.lead_in`) at `fps`; frame i (counted over
    repetitions when looping) is captured at `start_at + i / fps` UNIX seconds (None:
    see `grid_captures`) and stamped with exactly that time. With `pace` the feed
    sleeps until then; without it frames come as fast as they render. Noise derives
    from `seed` and `camera_id`, so every run renders the same frames. Before the
    subject steps in the camera films the empty stage: `mask` holds what is bright
    there (`static_mask`).
    """

    def __init__(
        self,
        camera: Camera,
        camera_id: int,
        lead_in: LeadIn,
        fps: float,
        seed: int,
        start_at: float | None,
        pace: bool = True,
        loop: bool = False,
        options: RenderOptions | None = None,
    ) -> None:
        self.camera, self.lead_in, self.fps = camera, lead_in, fps
        self.start_at, self.pace, self.loop = start_at, pace, loop
        self.options = options or RenderOptions()
        self.name = f"synthetic camera {camera_id}"
        self._rng = np.random.default_rng([seed, camera_id])
        self.mask = static_mask(
            film_empty_stage(camera, self.options, EMPTY_STAGE_FRAMES, self._rng)
        )

    def frames(self) -> Iterator[np.ndarray]:
        """One pass over the take's frames (H, W) uint8, rendered `RENDER_CHUNK_FRAMES`
        at a time; the noise continues from pass to pass."""
        poses = self.lead_in.poses
        for first in range(0, len(poses), RENDER_CHUNK_FRAMES):
            chunk = poses[first : first + RENDER_CHUNK_FRAMES]
            yield from render_camera(chunk, self.camera, self.options, self._rng).frames

    def captures(self) -> Iterator[Capture]:
        """The frames stamped with their grid times, in order (endless when looping)."""
        return grid_captures(self.frames, self.fps, self.start_at, self.pace, self.loop, self.name)


def grid_captures(
    frames: Callable[[], Iterable[np.ndarray]],
    fps: float,
    start_at: float | None,
    pace: bool,
    loop: bool,
    name: str,
) -> Iterator[Capture]:
    """Captures of the frames of `frames()` on a wall-clock grid: frame i (counted over
    repetitions when looping) is captured at `start_at + i / fps` UNIX seconds and
    stamped with exactly that time; with `pace` it waits until then, and its deadline is
    the next grid time. `start_at` None starts the grid `START_DELAY_SECONDS` after the
    first capture is asked for, so that whatever the node did before (loading, opening,
    rendering the empty stage) does not make its first frames late. `frames()` is called
    again for every repetition."""
    period = 1.0 / fps
    if start_at is None:
        start_at = time.time() + START_DELAY_SECONDS
    index = 0
    while True:
        for number, frame in enumerate(frames()):
            at = start_at + index * period
            if pace:
                _sleep_until(at)
            deadline = at + period if pace else None
            yield Capture(frame, at, deadline, number == 0, f"{name} frame {index}")
            index += 1
        if not loop:
            return


def run_node(
    node: Node,
    captures: Iterable[Capture],
    sender: PacketSender,
    start_sequence: int = 0,
    status: TextIO | None = None,
) -> NodeSummary:
    """Process and send every capture until the feed ends or Ctrl-C; returns the summary.

    `node` is a `CameraNode` (markers) or a `samba.service.silhouette_node.SilhouetteNode`
    (poses; a frame it has no pose for yet is counted, not sent). Packets carry
    sequence numbers from `start_sequence`, one per frame, wrapping from 2^32 - 1 to 0,
    where the sender draws a new epoch (the sequence only increases within one).
    The node's tracker restarts on every capture marked `first`. With a
    `status` stream, a one-line status goes there every `node_summary.STATUS_SECONDS`. InputError
    from the feed or the frames (wrong size, unreadable) propagates.
    """
    sequence = start_sequence % _SEQUENCE_MODULUS
    tally = NodeTally(sender, node.MISSING)
    interrupted = False
    try:
        for capture in captures:
            if capture.first:
                node.restart()
            tic = time.perf_counter()
            values = node.process(capture.frame, capture.name)
            tally.process_s += time.perf_counter() - tic
            if values is not None:
                sender.send(sequence, capture.timestamp, values, node.unlabelled())
            tally.count(values, capture.deadline)
            sequence = (sequence + 1) % _SEQUENCE_MODULUS
            if sequence == 0:
                sender.new_epoch()
            if status is not None and tally.status_due():
                print(tally.status_line(), file=status, flush=True)
    except KeyboardInterrupt:
        interrupted = True
    return tally.summary(interrupted)


def _video_fps(path: Path) -> float:
    """The frame rate a video file gives; InputError when it cannot be opened or has none."""
    capture = open_video(path)
    try:
        fps = capture.get(cv2.CAP_PROP_FPS)
    finally:
        capture.release()
    if not (fps > 0 and math.isfinite(fps)):
        raise InputError(str(path), "the video does not give its frame rate: pass --fps")
    return float(fps)


def _sleep_until(when: float) -> None:
    """Sleep until the clock (`time.time`) reaches `when` UNIX seconds."""
    delay = when - time.time()
    if delay > 0:
        time.sleep(delay)
