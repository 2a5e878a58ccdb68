"""Where the sessions' `FramePipeline`s run: in the event loop, or in worker processes.

Both runners take frames with `submit` and report each computed frame, in the order of
submission per session, as a `FrameDone` to the `deliver` callable given at
construction:

* `InlinePipelines` computes in the caller's thread, before `submit` returns (or at
  the end of a `together()` block);
* `WorkerPipelines` spreads the sessions over up to `workers` processes (a session
  always runs in the same process, its reconstruction carries state from frame to
  frame) and calls `deliver` from a reader thread per process as results come back;
  the server hands them to its event loop. The event loop then only reads datagrams,
  assembles frames and records, while the reconstruction of several sessions uses
  several cores — the Python interpreter runs one thread at a time.

Frames submitted inside a runner's `together()` block are held to its end and computed
together (`samba.service.frame_pipeline.process_together`: one batch for the sessions that
share their reconstruction, which sessions on one database do through the runner's
`SessionIndexes`); the server wraps each read of its socket in one.

A worker that dies is restarted and its sessions re-opened; each frame it had in
flight is reported lost (a `FrameDone` with an `error`). A worker exits when its
pipe to the server closes, so killing the server (even with kill -9) ends them too.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import signal
import threading
from collections import Counter
from collections.abc import Callable, Hashable, Iterator
from concurrent.futures import Future
from contextlib import AbstractContextManager
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any, Generic, TypeVar

from threadpoolctl import threadpool_limits

from samba.base import InputError
from samba.service.errors import ServiceError
from samba.service.frame_pipeline import (
    FrameInput,
    FrameOutput,
    FramePipeline,
    PosePipeline,
    open_pipeline,
    process_together,
)
from samba.service.session_config import SessionConfig
from samba.service.session_indexes import SessionIndexes

LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class FrameDone:
    """What became of frame `sequence` of `session`: its `output`, or the `error` (a
    one-line reason) that stopped it."""

    session: str
    sequence: int
    output: FrameOutput | None = None
    error: str | None = None


Deliver = Callable[[FrameDone], None]
_Frame = tuple[str, int, FrameInput, float, float]
"""A submitted frame: (session, sequence, values, frame_time, arrival)."""
_Item = TypeVar("_Item")


class _Hold(Generic[_Item]):
    """Items held while a `block` runs and handed to `release` together when it ends."""

    def __init__(self, release: Callable[[list[_Item]], None]) -> None:
        self._release = release
        self._items: list[_Item] | None = None

    def keep(self, item: _Item) -> bool:
        """Hold `item` while a block runs (True); False when none runs."""
        if self._items is None:
            return False
        self._items.append(item)
        return True

    @contextlib.contextmanager
    def block(self) -> Iterator[None]:
        """Hold the items kept inside; a block inside another ends with the outer one."""
        if self._items is not None:
            yield
            return
        self._items = []
        try:
            yield
        finally:
            items, self._items = self._items, None
            self._release(items)


class InlinePipelines:
    """Runs every session's pipeline in the caller's thread; see the module docstring."""

    def __init__(self, deliver: Deliver) -> None:
        self._deliver = deliver
        self._pipelines: dict[str, FramePipeline | PosePipeline] = {}
        self._indexes = SessionIndexes()
        self._hold: _Hold[_Frame] = _Hold(self._deliver_computed)

    def open(self, config: SessionConfig, clock_zero: float) -> int:
        """Open the session's pipeline (`open_pipeline`); returns its database size."""
        pipeline = open_pipeline(config, clock_zero, self._indexes)
        self._pipelines[config.name] = pipeline
        return pipeline.database_poses

    def submit(
        self, session: str, sequence: int, values: FrameInput, frame_time: float, arrival: float
    ) -> None:
        """Compute frame `sequence` of `session` now (`FramePipeline.process`), or at the
        end of the `together` block it is submitted in."""
        frame = (session, sequence, values, frame_time, arrival)
        if not self._hold.keep(frame):
            self._deliver_computed([frame])

    def together(self) -> AbstractContextManager[None]:
        """Hold the frames submitted in the block and compute them together at its end:
        those of sessions that share their reconstruction in one batch
        (`samba.service.frame_pipeline.process_together`)."""
        return self._hold.block()

    def _deliver_computed(self, frames: list[_Frame]) -> None:
        for done in _compute(self._pipelines, frames):
            self._deliver(done)

    def close_session(self, session: str) -> None:
        """Close the session's pipeline."""
        pipeline = self._pipelines.pop(session, None)
        if pipeline is not None:
            pipeline.close()

    def worker_pids(self) -> list[int]:
        """No worker processes: an empty list."""
        return []

    def shutdown(self) -> None:
        """Close every pipeline."""
        for name in list(self._pipelines):
            self.close_session(name)


class WorkerPipelines:
    """Runs the sessions' pipelines in up to `workers` processes; see the module docstring.

    Processes start when sessions need them (a new session goes to a new process while
    fewer than `workers` run, else to the one with the fewest sessions).
    """

    def __init__(self, workers: int, deliver: Deliver) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self._limit = workers
        self._deliver = deliver
        self._context = multiprocessing.get_context("spawn")
        self._workers: list[_Worker] = []
        self._owner: dict[str, _Worker] = {}
        self._lock = threading.Lock()
        self._closing = False
        self._hold: _Hold[tuple[_Worker, _Frame]] = _Hold(self._send_held)
        self.restarts = 0

    def open(self, config: SessionConfig, clock_zero: float) -> int:
        """Open the session's pipeline in a worker and wait until it is ready; returns its
        database size. Raises `ServiceError` with the worker's reason (a bad file ...)."""
        with self._lock:
            worker = self._place()
            future = worker.expect(config.name)
        worker.send(("open", config, clock_zero))
        poses = future.result()
        with self._lock:
            worker.sessions[config.name] = (config, clock_zero)
            self._owner[config.name] = worker
        return poses

    def _place(self) -> _Worker:
        if len(self._workers) < self._limit:
            worker = _Worker(self._context, self._read)
            self._workers.append(worker)
            return worker
        return min(self._workers, key=lambda w: len(w.sessions) + len(w.replies))

    def submit(
        self, session: str, sequence: int, values: FrameInput, frame_time: float, arrival: float
    ) -> None:
        """Send frame `sequence` of `session` to its worker; the result comes to `deliver`."""
        worker = self._owner.get(session)
        if worker is None:
            self._deliver(FrameDone(session, sequence, error="the session is not open"))
            return
        worker.in_flight[session, sequence] = None
        frame = (session, sequence, values, frame_time, arrival)
        if not self._hold.keep((worker, frame)):
            self._send_frames(worker, [frame])

    def together(self) -> AbstractContextManager[None]:
        """Hold the frames submitted in the block and send them at its end, one message
        per worker, which computes them together: those of sessions that share their
        reconstruction in one batch (`samba.service.frame_pipeline.process_together`)."""
        return self._hold.block()

    def _send_held(self, held: list[tuple[_Worker, _Frame]]) -> None:
        frames: dict[_Worker, list[_Frame]] = {}
        for worker, frame in held:
            frames.setdefault(worker, []).append(frame)
        for worker, mine in frames.items():
            self._send_frames(worker, mine)

    def _send_frames(self, worker: _Worker, frames: list[_Frame]) -> None:
        try:
            worker.send(("frames", frames))
        except OSError as exc:
            for session, sequence, *_ in frames:
                if (session, sequence) in worker.in_flight:  # else reported with the worker
                    del worker.in_flight[session, sequence]
                    self._deliver(FrameDone(session, sequence, error=f"worker unavailable: {exc}"))

    def close_session(self, session: str) -> None:
        """Close the session's pipeline in its worker (its VMC socket with it)."""
        with self._lock:
            worker = self._owner.pop(session, None)
            if worker is not None:
                worker.sessions.pop(session, None)
        if worker is not None:
            with contextlib.suppress(OSError):  # a worker that is gone took it along
                worker.send(("close", session))

    def worker_pids(self) -> list[int]:
        """Process ids of the running workers."""
        return [w.process.pid for w in self._workers if w.process.pid is not None]

    def shutdown(self) -> None:
        """Stop every worker (each closes its pipelines) and wait for it to exit."""
        self._closing = True
        for worker in self._workers:
            worker.stop()
        self._workers.clear()
        self._owner.clear()

    def _read(self, worker: _Worker) -> None:
        """The reader thread of `worker`: hand its messages on until its pipe closes."""
        while True:
            try:
                message = worker.connection.recv()
            except (EOFError, OSError):
                break
            kind = message[0]
            if kind in ("frame", "failed"):
                worker.in_flight.pop((message[1], message[2]), None)
            if kind == "frame":
                self._deliver(FrameDone(message[1], message[2], output=message[3]))
            elif kind == "failed":
                self._deliver(FrameDone(message[1], message[2], error=message[3]))
            else:
                worker.answer(kind, *message[1:])
        if not self._closing:
            self._replace(worker)

    def _replace(self, dead: _Worker) -> None:
        dead.process.join(timeout=5)
        reason = f"worker process {dead.process.pid} exited with code {dead.process.exitcode}"
        LOG.error("%s; restarting it with its sessions %s", reason, sorted(dead.sessions))
        dead.fail_replies(reason)
        with self._lock:
            if self._closing or dead not in self._workers:
                return
            fresh = _Worker(self._context, self._read)
            self._workers[self._workers.index(dead)] = fresh
            self.restarts += 1
            opening = []
            for name, (config, clock_zero) in dead.sessions.items():
                opening.append((name, fresh.expect(name)))  # frames sent from now on
                fresh.send(("open", config, clock_zero))  # queue behind the opening
                fresh.sessions[name] = (config, clock_zero)
                self._owner[name] = fresh
        for session, sequence in list(dead.in_flight):
            self._deliver(FrameDone(session, sequence, error=reason))
        for name, future in opening:
            try:
                future.result()
            except ServiceError as exc:
                LOG.error("session %s could not be re-opened: %s", name, exc)


class _Worker:
    """One worker process, its pipe, its sessions and the replies the server awaits."""

    def __init__(self, context: Any, read: Callable[[_Worker], None]) -> None:
        connection, child = context.Pipe()
        self.process = context.Process(
            target=_serve_pipelines, args=(child,), name="samba-pipeline", daemon=True
        )
        self.process.start()
        child.close()
        self.connection: Connection = connection
        self.sessions: dict[str, tuple[SessionConfig, float]] = {}
        self.replies: dict[str, Future[int]] = {}
        self.in_flight: dict[tuple[str, int], None] = {}
        """(session, sequence) of the frames sent and not answered, in order."""
        self._send_lock = threading.Lock()
        self._reader = threading.Thread(
            target=read, args=(self,), name="samba-pipeline-reader", daemon=True
        )
        self._reader.start()

    def expect(self, session: str) -> Future[int]:
        """A future for the worker's answer to opening `session`."""
        future: Future[int] = Future()
        self.replies[session] = future
        return future

    def answer(self, kind: str, session: str, *values: Any) -> None:
        """Settle the future of `session` with the worker's answer."""
        future = self.replies.pop(session, None)
        if future is None:
            return
        if kind == "opened":
            future.set_result(values[0])
        else:
            future.set_exception(ServiceError(*values))

    def fail_replies(self, reason: str) -> None:
        """Fail every awaited answer: the worker is gone."""
        for session, future in list(self.replies.items()):
            future.set_exception(ServiceError(session, reason))
        self.replies.clear()

    def send(self, message: tuple[Any, ...]) -> None:
        """Send one message (pickled) to the worker; `OSError` when it is gone."""
        with self._send_lock:
            self.connection.send(message)

    def stop(self) -> None:
        """Ask the worker to close its pipelines and exit, wait for it (and its reader
        thread), and close the pipe."""
        with contextlib.suppress(OSError):
            self.send(("stop",))
        self.process.join(timeout=10)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self._reader.join(timeout=10)
        self.connection.close()


def _compute(
    pipelines: dict[str, FramePipeline | PosePipeline], frames: list[_Frame]
) -> list[FrameDone]:
    """What became of each of `frames`, in order. The frames of marker sessions whose
    pipelines share a `reconstruction_key` are computed together (`process_together`), a
    session's second frame with the others' second frames, after its first. An exception
    fails its frame (in a frame's own steps) or the frames computed with it (in the
    batched steps), and the sessions go on."""
    done: dict[int, FrameDone] = {}
    groups: dict[Hashable, list[int]] = {}
    seen: Counter[str] = Counter()
    for i, (session, sequence, *_) in enumerate(frames):
        pipeline = pipelines.get(session)
        seen[session] += 1
        if pipeline is None:
            done[i] = FrameDone(session, sequence, error="the session is not open")
        elif isinstance(pipeline, FramePipeline):
            groups.setdefault((pipeline.reconstruction_key, seen[session]), []).append(i)
        else:
            groups[i] = [i]
    for rows in groups.values():
        try:
            outputs = _outputs(pipelines, [frames[i] for i in rows])
        except Exception as exc:  # a bug in one frame must not stop the session
            sessions = sorted({frames[i][0] for i in rows})
            LOG.exception("sessions %s: %d frames failed", ", ".join(sessions), len(rows))
            for i in rows:
                done[i] = FrameDone(
                    frames[i][0], frames[i][1], error=f"{type(exc).__name__}: {exc}"
                )
        else:
            for i, output in zip(rows, outputs, strict=True):
                session, sequence = frames[i][:2]
                if isinstance(output, Exception):
                    LOG.error("session %s: frame %d failed", session, sequence, exc_info=output)
                    error = f"{type(output).__name__}: {output}"
                    done[i] = FrameDone(session, sequence, error=error)
                else:
                    done[i] = FrameDone(session, sequence, output=output)
    return [done[i] for i in range(len(frames))]


def _outputs(
    pipelines: dict[str, FramePipeline | PosePipeline], frames: list[_Frame]
) -> list[FrameOutput | Exception]:
    """The outputs of one group of `_compute`: a pose session's frame, or marker frames."""
    first = pipelines[frames[0][0]]
    if isinstance(first, PosePipeline):
        _, _, pose, frame_time, arrival = frames[0]
        return [first.process(pose, frame_time, arrival)]
    return process_together(
        [(pipelines[session], values, t, arrival) for session, _, values, t, arrival in frames]
    )


def _serve_pipelines(connection: Connection) -> None:
    """A worker process: open, compute and close pipelines as the server asks, until the
    pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the server's to handle
    pipelines: dict[str, FramePipeline | PosePipeline] = {}
    indexes = SessionIndexes()
    with threadpool_limits(1):
        try:
            while True:
                try:
                    message = connection.recv()
                except (EOFError, OSError):
                    return
                kind = message[0]
                if kind == "frames":
                    answers = [
                        ("frame", d.session, d.sequence, d.output)
                        if d.output is not None
                        else ("failed", d.session, d.sequence, d.error)
                        for d in _compute(pipelines, message[1])
                    ]
                elif kind == "open":
                    answers = [_open(pipelines, indexes, *message[1:])]
                elif kind == "close":
                    if message[1] in pipelines:
                        pipelines.pop(message[1]).close()
                    continue
                else:  # "stop"
                    return
                try:
                    for answer in answers:
                        connection.send(answer)
                except OSError:  # the server is gone
                    return
        finally:
            for pipeline in pipelines.values():
                pipeline.close()


def _open(
    pipelines: dict[str, FramePipeline | PosePipeline],
    indexes: SessionIndexes,
    config: SessionConfig,
    clock_zero: float,
) -> tuple[Any, ...]:
    try:
        pipeline = open_pipeline(config, clock_zero, indexes)
    except InputError as exc:
        return ("refused", config.name, exc.source, exc.problem, exc.line)
    except Exception as exc:
        LOG.exception("session %s could not be opened", config.name)
        return ("refused", config.name, config.name, f"{type(exc).__name__}: {exc}", None)
    pipelines[config.name] = pipeline
    return ("opened", config.name, pipeline.database_poses)
