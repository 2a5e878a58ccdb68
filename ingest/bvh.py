"""BVH reader: the whole grammar, strict errors with line numbers, batched kinematics.

Shaped like the `mcap` package's reader: `read_bvh(path)` / `parse_bvh(text)` return a
`BvhFile` record; malformed input raises `samba.ingest.errors.BvhError` naming the file and
line. Accepted: any channel order per joint, position channels on any joint, End Sites,
several ROOTs, tabs / CRLF / blank lines / scientific notation, `Frames:` with or
without tabs. Position channels replace the matching component of the joint's OFFSET
(the MotionBuilder convention); rotation channels compose in the listed order
(intrinsic), e.g. `Zrotation Xrotation Yrotation` is Rz @ Rx @ Ry, in degrees.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.base import kernels_enabled
from samba.body import (
    euler_to_quaternions,
    forward_kinematics,
    sample_linear,
    sample_rotations,
    whole_fps,
)
from samba.ingest.errors import BvhError
from samba.ingest.input_files import MAX_FILE_BYTES, quoted, read_input
from samba.ingest.motion_table import PLAIN_NUMBER, compiled_reader, read_frames, read_table
from samba.ingest.resolver import SkeletonTree

_CHANNELS = {f"{axis}{kind}": (kind, axis) for axis in "XYZ" for kind in ("position", "rotation")}
_TOKEN = re.compile(r"[{}]|[^\s{}]+")
_LONE_CR = re.compile(r"\r(?!\n)")
_MOTION = re.compile(r"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE | re.IGNORECASE)
_MOTION_BYTES = re.compile(rb"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE | re.IGNORECASE)
_HEAD_WINDOW = 4096
"""Bytes after the MOTION line in which `_parse_plain` looks for 'Frames:' and 'Frame
Time:' (the full path reads files that put them further)."""
MAX_DEPTH = 256
"""Deepest nesting of joints read (a full-body rig with fingers nests about 30 deep)."""
MAX_JOINTS = 10_000
"""Most joints (End Sites included) a hierarchy may declare."""
MAX_NAME_CHARS = 200
"""Longest joint name read."""
MAX_OFFSET = 1e7
"""Largest OFFSET component read: 10 km in millimetres (beyond, a broken file)."""
_MAX_CHANNELS = 6
"""Most channels of one joint: three positions and three rotations."""
_MAX_FRAME_DIGITS = 18
"""Most digits of 'Frames:' (a count beyond them is no count of frames a file holds)."""
_CACHED_HEADER_CHARS = 1_000_000
"""Longest hierarchy text whose parse is kept for the next file of the rig."""


@dataclass(frozen=True)
class BvhJoint:
    """One joint of the hierarchy; End Sites are joints named '<parent>_end' with no channels.

    `offset` (3,) is in the file's length unit; `channels` are normalised names such as
    'Xposition' and 'Zrotation'; `first_channel` is the joint's first column in the
    motion array.
    """

    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    first_channel: int
    end_site: bool
    line: int


@dataclass(frozen=True)
class BvhFile:
    """A parsed BVH file: `joints` (parents first), `n_frames` frames of motion, and
    `motion` (rows, channels) float64: every frame, or the frames `held` only (ascending
    frame indices (rows,) int64), when `parse_bvh` was asked for some (its `sample`)."""

    source: str
    joints: tuple[BvhJoint, ...]
    frame_time: float
    motion: np.ndarray
    n_frames: int
    held: np.ndarray | None = None

    @property
    def fps(self) -> float:
        """Frames per second, 1 / frame time, taken as the whole number it lies within
        0.01% of (`samba.body.whole_fps`: a frame time of 0.0166670 s is 60 fps)."""
        return whole_fps(1.0 / self.frame_time)

    @property
    def names(self) -> tuple[str, ...]:
        """Joint names in hierarchy order (End Sites included)."""
        return tuple(j.name for j in self.joints)

    def frames(self) -> np.ndarray:
        """The frame indices (rows,) int64 of the rows of `motion`."""
        return np.arange(self.n_frames) if self.held is None else self.held

    def skeleton(self) -> SkeletonTree:
        """The joint tree as the humanoid resolver reads it, posed as in the first frame
        (file units): a BVH's rest offsets need not be a pose (Character Creator lays its
        rest skeleton along one axis and turns it upright in every frame)."""
        everything = list(range(len(self.joints)))
        parents, rotations, translations = self.local_transforms(everything, np.array([0]))
        positions = forward_kinematics(parents, rotations, translations)[0]
        return SkeletonTree(self.names, tuple(int(p) for p in parents), positions)

    def ancestry(self, wanted: list[int]) -> list[int]:
        """The joints in `wanted` plus all their ancestors, in hierarchy order."""
        keep: set[int] = set()
        for j in wanted:
            while j >= 0 and j not in keep:
                keep.add(j)
                j = self.joints[j].parent
        return sorted(keep)

    def local_transforms(
        self, subset: list[int], frames: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Local transforms of a parent-closed joint subset over the held `frames` (frame
        indices; default: all held).

        Returns (parents (J,) indices into the subset, rotations (n, J, 4) quaternions,
        translations (n, J, 3) in file units).
        """
        motion = self.motion if frames is None else self.motion[self._rows(frames)]
        layout = self._layout(subset)
        rotations = np.zeros((len(motion), len(subset), 4))
        rotations[..., 3] = 1.0
        translations = np.repeat(layout.offsets[None], len(motion), axis=0)
        by_order: dict[str, tuple[list[int], list[np.ndarray]]] = {}
        for i in range(len(subset)):
            for axis, column in enumerate(layout.position_columns[i]):
                if column >= 0:
                    translations[:, i, axis] = motion[:, column]
            columns = layout.rotation_columns[i][layout.rotation_columns[i] >= 0]
            if len(columns):
                axes = "".join("XYZ"[a] for a in layout.rotation_axes[i][: len(columns)])
                members, cols = by_order.setdefault(axes, ([], []))
                members.append(i)
                cols.append(columns)
        for axes, (members, cols) in by_order.items():
            rotations[:, members] = euler_to_quaternions(axes, motion[:, cols])
        return layout.parents, rotations, translations

    def positions(self, joints: list[int]) -> np.ndarray:
        """World positions (rows, len(joints), 3) of the given joint indices in the held
        frames, in file units."""
        return self.sampled_positions(joints, self.frames().astype(np.float64))

    def sampled_positions(self, joints: list[int], times: np.ndarray) -> np.ndarray:
        """World positions (m, len(joints), 3), in file units, of the joint indices
        `joints` at fractional frames `times` (m,) (0 is the first frame; the frames either
        side of each, `frames_either_side`, must be held): rotations interpolated as
        quaternions on the shorter arc (normalised lerp), translations linearly.

        Computed by `samba.ingest.kernels.sampled_positions_kernel` when kernels are on,
        else by its numpy reference: `local_transforms`, then `sample_rotations`,
        `sample_linear` and `forward_kinematics` (`samba.body`).
        """
        subset = self.ancestry(joints)
        before, after, fractions = frames_either_side(times, self.n_frames)
        if kernels_enabled():
            layout = self._layout(subset)
            world = compiled_reader().sampled_positions_kernel(
                self.motion,
                layout.parents,
                layout.offsets,
                layout.rotation_columns,
                layout.rotation_axes,
                layout.position_columns,
                self._rows(before),
                self._rows(after),
                fractions,
            )
        else:
            needed = np.union1d(before, after)
            parents, rotations, translations = self.local_transforms(subset, needed)
            local_times = np.searchsorted(needed, before) + fractions
            world = forward_kinematics(
                parents,
                sample_rotations(rotations, local_times),
                sample_linear(translations, local_times),
            )
        return world[:, [subset.index(j) for j in joints]]

    def _rows(self, frames: np.ndarray) -> np.ndarray:
        """The rows (n,) of `motion` that hold the frames `frames` (n,) int; ValueError
        for a frame not held."""
        frames = np.asarray(frames, dtype=np.int64)
        if self.held is None:
            rows = frames
            held = (frames >= 0) & (frames < self.n_frames)
        else:
            rows = np.minimum(np.searchsorted(self.held, frames), len(self.held) - 1)
            held = self.held[rows] == frames
        if not held.all():
            raise ValueError(f"{self.source}: frame {frames[~held][0]} was not read")
        return rows

    def _layout(self, subset: list[int]) -> _ChannelLayout:
        """How the channels of a parent-closed joint subset drive it (`_ChannelLayout`)."""
        position_in = {j: i for i, j in enumerate(subset)}
        layout = _ChannelLayout(
            parents=np.array([position_in.get(self.joints[j].parent, -1) for j in subset]),
            offsets=np.array([self.joints[j].offset for j in subset], dtype=np.float64),
            rotation_columns=np.full((len(subset), 3), -1),
            rotation_axes=np.zeros((len(subset), 3), dtype=np.int64),
            position_columns=np.full((len(subset), 3), -1),
        )
        for i, j in enumerate(subset):
            joint = self.joints[j]
            turns = 0
            for c, name in enumerate(joint.channels):
                kind, axis = _CHANNELS[name]
                if kind == "position":
                    layout.position_columns[i, "XYZ".index(axis)] = joint.first_channel + c
                else:
                    layout.rotation_columns[i, turns] = joint.first_channel + c
                    layout.rotation_axes[i, turns] = "XYZ".index(axis)
                    turns += 1
        return layout


@dataclass(frozen=True)
class _ChannelLayout:
    """The channels of J joints as arrays (`samba.ingest.kernels.sampled_positions_kernel`):
    `parents` (J,) indices among them (-1 for a root), rest `offsets` (J, 3) in file units,
    `rotation_columns` (J, 3) the motion columns of the rotations in order (-1 past the
    last) about `rotation_axes` (J, 3) (0, 1, 2 for X, Y, Z), `position_columns` (J, 3) the
    column replacing each component of the offset (-1 for none)."""

    parents: np.ndarray
    offsets: np.ndarray
    rotation_columns: np.ndarray
    rotation_axes: np.ndarray
    position_columns: np.ndarray


def frames_either_side(
    times: np.ndarray, n_frames: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frames (m,) int64 before and after each fractional frame of `times` (m,),
    clipped to the `n_frames` frames, and the fraction (m,) of the way between them: a time
    within 1e-9 of a whole frame is that frame (before = after, fraction 0)."""
    times = np.clip(np.asarray(times, dtype=np.float64), 0.0, n_frames - 1)
    before = np.minimum(np.floor(times + 1e-9).astype(np.int64), n_frames - 1)
    fractions = np.clip(times - before, 0.0, 1.0)
    fractions[fractions <= 1e-9] = 0.0
    after = np.where(fractions > 0, np.minimum(before + 1, n_frames - 1), before)
    return before, after, fractions


def read_bvh(path: str | Path, max_bytes: int = MAX_FILE_BYTES) -> BvhFile:
    """Read and validate a BVH file (a regular file of at most `max_bytes` bytes,
    `samba.ingest.input_files.read_input`); raises `BvhError` naming the file and line."""
    return parse_bvh(read_input(path, max_bytes, BvhError), source=str(path))


SampleTimes = Callable[[int, float], np.ndarray]
"""What a reader will sample of a file of n frames at f frames per second: (n, f) ->
fractional frame indices (m,) (`parse_bvh`'s `sample`)."""


def parse_bvh(
    data: bytes | str, source: str = "<bvh>", sample: SampleTimes | None = None
) -> BvhFile:
    """Parse BVH text (bytes or str); `source` names it in error messages.

    With `sample`, only the frames it needs are converted to numbers: the first, and the
    frames either side of each of its times (`frames_either_side`), which the result
    holds (`BvhFile.held`); every other frame is checked for its count of values and its
    characters (`samba.ingest.motion_table`).
    """
    if isinstance(data, bytes):
        plain = _parse_plain(data, source, sample)
        if plain is not None:
            return plain
        if b"\x00" in data:
            line = _byte_line(data, data.index(b"\x00"))
            raise BvhError(source, "binary data, not a BVH text file", line)
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise BvhError(
                source,
                f"not UTF-8 / ASCII text (byte {exc.start})",
                _byte_line(data, exc.start),
            ) from exc
    else:
        text = data
    if not text or text.isspace():
        raise BvhError(source, "empty file")
    if "\r" in text and _LONE_CR.search(text):
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    motion = _MOTION.search(text)
    if motion is None:
        lines = [ln.rstrip("\r") for ln in text.rstrip().split("\n")]
        _parse_hierarchy(lines, source)  # names the first thing that is not hierarchy
        raise BvhError(source, "no MOTION section (file truncated or not BVH)", len(lines))
    header = text[: motion.start()]
    joints = _hierarchy(header, source)
    n_channels = sum(len(j.channels) for j in joints)
    frames, frame_time, offset, first_line = _parse_motion_header(
        text, motion.end(), header.count("\n") + 1, source
    )
    held = _held_frames(sample, frames, frame_time)
    motion_data = read_frames(text[offset:], first_line, frames, n_channels, source, held)
    return BvhFile(source, joints, frame_time, motion_data, frames, held)


def _held_frames(sample: SampleTimes | None, frames: int, frame_time: float) -> np.ndarray | None:
    """The frames (ascending int64) of `frames` that `sample` needs, with the first; None
    (all) without `sample`."""
    if sample is None:
        return None
    times = sample(frames, whole_fps(1.0 / frame_time))
    return np.union1d(np.concatenate(frames_either_side(times, frames)[:2]), [0])


def _parse_plain(data: bytes, source: str, sample: SampleTimes | None) -> BvhFile | None:
    """`data` parsed without decoding or copying its motion section, for the usual file:
    ASCII, LF or CRLF line ends, a sound hierarchy and header, frames of plain numbers
    that the compiled reader reads (`read_table`), `sample` as in `parse_bvh`. None for
    anything else, which `parse_bvh`'s full path then parses or names the problem of (with
    the line)."""
    if not kernels_enabled() or not data.isascii():
        return None
    motion = _MOTION_BYTES.search(data)
    if motion is None:
        return None
    head = data[: motion.end() + _HEAD_WINDOW].decode("ascii")
    if head.count("\r") != head.count("\r\n"):
        return None  # a lone CR ends a line: the full path rewrites them
    try:
        joints = _hierarchy(head[: motion.start()], source)
        motion_line = head.count("\n", 0, motion.start()) + 1
        frames, frame_time, offset, _ = _parse_motion_header(
            head, motion.end(), motion_line, source
        )
    except BvhError:
        return None
    if offset >= len(head) and len(head) < len(data):
        return None  # 'Frame Time:' may go on past the window
    n_channels = sum(len(j.channels) for j in joints)
    if not n_channels:
        return None
    held = _held_frames(sample, frames, frame_time)
    buffer = np.frombuffer(data, dtype=np.uint8, offset=offset)
    table = read_table(buffer, frames, n_channels, held)
    if table is None:
        return None
    return BvhFile(source, joints, frame_time, table, frames, held)


def _hierarchy(header: str, source: str) -> tuple[BvhJoint, ...]:
    """The joints declared by the text before MOTION; files of one rig share the parse
    (of a header up to `_CACHED_HEADER_CHARS` long)."""
    try:
        if len(header) > _CACHED_HEADER_CHARS:
            return _joints_of(header)
        return _parsed_hierarchy(header)
    except BvhError as exc:
        raise BvhError(source, exc.problem, exc.line) from None


@functools.lru_cache(maxsize=16)
def _parsed_hierarchy(header: str) -> tuple[BvhJoint, ...]:
    return _joints_of(header)


def _joints_of(header: str) -> tuple[BvhJoint, ...]:
    lines = [ln.rstrip("\r") for ln in header.split("\n")]
    return tuple(_parse_hierarchy(lines, source=""))


def _byte_line(data: bytes, offset: int) -> int:
    """1-based line number of byte `offset` of `data` (LF, CRLF or CR line ends)."""
    return data[:offset].replace(b"\r\n", b"\n").replace(b"\r", b"\n").count(b"\n") + 1


class _Tokens:
    """The tokens of the hierarchy's lines with their line numbers, read one at a time
    (the text is not split into a list of tokens)."""

    def __init__(self, lines: list[str], source: str) -> None:
        self._stream = (
            (match.group(), n + 1)
            for n, line in enumerate(lines)
            for match in _TOKEN.finditer(line)
        )
        self._next = next(self._stream, None)
        self.source = source
        self.last_line = max(len(lines), 1)

    def peek(self) -> str | None:
        return None if self._next is None else self._next[0]

    @property
    def line(self) -> int:
        return self.last_line if self._next is None else self._next[1]

    def take(self, what: str) -> str:
        if self._next is None:
            raise BvhError(self.source, f"hierarchy ends early, expected {what}", self.line)
        token = self._next[0]
        self._next = next(self._stream, None)
        return token

    def expect(self, literal: str) -> None:
        line = self.line
        token = self.take(repr(literal))
        if token.upper() != literal.upper():
            raise BvhError(self.source, f"expected {literal!r}, found {quoted(token)}", line)

    def number(self, what: str, limit: float = math.inf) -> float:
        line = self.line
        token = self.take(what)
        if not PLAIN_NUMBER.match(token):
            raise BvhError(self.source, f"{what}: {quoted(token)} is not a number", line)
        value = float(token)
        if not math.isfinite(value) or abs(value) > limit:
            raise BvhError(self.source, f"{what}: {quoted(token)} is out of range", line)
        return value


def _parse_hierarchy(lines: list[str], source: str) -> list[BvhJoint]:
    tokens = _Tokens(lines, source)
    tokens.expect("HIERARCHY")
    joints: list[BvhJoint] = []
    if tokens.peek() is None or tokens.peek().upper() != "ROOT":
        raise BvhError(source, "expected ROOT after HIERARCHY", tokens.line)
    while tokens.peek() is not None:
        line = tokens.line
        keyword = tokens.take("ROOT")
        if keyword.upper() != "ROOT":
            raise BvhError(source, f"expected ROOT or MOTION, found {quoted(keyword)}", line)
        _parse_tree(tokens, joints)
    first_line: dict[str, int] = {}
    for joint in joints:
        if joint.name in first_line:
            raise BvhError(
                source,
                f"duplicate joint name {joint.name!r} (first on line {first_line[joint.name]})",
                joint.line,
            )
        first_line[joint.name] = joint.line
    return joints


def _parse_tree(tokens: _Tokens, joints: list[BvhJoint]) -> None:
    """The joints of one ROOT (its keyword read) and all below it, appended to `joints`:
    read without recursion, the open joints on a stack at most `MAX_DEPTH` deep."""
    open_joints = [_open_joint(tokens, joints, parent=-1, end_site=False)]
    while open_joints:
        joint = joints[open_joints[-1]]
        line = tokens.line
        token = tokens.take("'}' closing " + joint.name)
        upper = token.upper()
        if token == "}":
            open_joints.pop()
        elif joint.end_site:
            raise BvhError(tokens.source, f"unexpected {quoted(token)} inside End Site", line)
        elif upper not in ("JOINT", "END"):
            raise BvhError(tokens.source, f"unexpected {quoted(token)} in joint {joint.name}", line)
        elif len(open_joints) >= MAX_DEPTH:
            raise BvhError(tokens.source, f"joints nest deeper than {MAX_DEPTH} levels", line)
        else:
            end_site = upper == "END"
            open_joints.append(_open_joint(tokens, joints, open_joints[-1], end_site))


def _open_joint(tokens: _Tokens, joints: list[BvhJoint], parent: int, end_site: bool) -> int:
    """Read a joint's name (after its JOINT / ROOT / End keyword), '{', OFFSET and
    CHANNELS; append it to `joints` and return its index (its children and '}' follow)."""
    line = tokens.line
    if len(joints) >= MAX_JOINTS:
        raise BvhError(tokens.source, f"more than {MAX_JOINTS:,} joints", line)
    if end_site:
        tokens.expect("Site")
        name = f"{joints[parent].name}_end"
    else:
        name = tokens.take("a joint name")
        if name in "{}":
            raise BvhError(tokens.source, "joint without a name", line)
        if len(name) > MAX_NAME_CHARS:
            raise BvhError(
                tokens.source,
                f"joint name {quoted(name)} is longer than {MAX_NAME_CHARS} characters",
                line,
            )
    tokens.expect("{")
    tokens.expect("OFFSET")
    offset = np.array([tokens.number(f"OFFSET of {name}", MAX_OFFSET) for _ in range(3)])
    offset.flags.writeable = False  # parsed hierarchies are shared between files
    channels: tuple[str, ...] = ()
    if tokens.peek() is not None and tokens.peek().upper() == "CHANNELS":
        if end_site:
            raise BvhError(tokens.source, "an End Site cannot have CHANNELS", tokens.line)
        channels = _parse_channels(tokens, name)
    first = joints[-1].first_channel + len(joints[-1].channels) if joints else 0
    joints.append(BvhJoint(name, parent, offset, channels, first, end_site, line))
    return len(joints) - 1


def _parse_channels(tokens: _Tokens, joint: str) -> tuple[str, ...]:
    tokens.take("CHANNELS")
    line = tokens.line
    count_token = tokens.take("a channel count")
    if not (count_token.isascii() and count_token.isdigit()):
        raise BvhError(
            tokens.source,
            f"channel count {quoted(count_token)} of {joint} is not an integer",
            line,
        )
    if len(count_token) > 2 or int(count_token) > _MAX_CHANNELS:
        raise BvhError(
            tokens.source,
            f"{joint} declares {quoted(count_token)} channels; a joint has at most {_MAX_CHANNELS}",
            line,
        )
    count = int(count_token)
    names = []
    for _ in range(count):  # errors name the CHANNELS line
        token = tokens.take(f"{count} channel names for {joint}")
        normal = token[0].upper() + token[1:].lower() if token else token
        if normal not in _CHANNELS:
            raise BvhError(
                tokens.source,
                f"{joint} declares {count} channels but {quoted(token)} is not a channel name",
                line,
            )
        names.append(normal)
    if len(set(names)) != len(names):
        raise BvhError(tokens.source, f"{joint} repeats a channel: {' '.join(names)}", line)
    return tuple(names)


def _parse_motion_header(
    text: str, pos: int, motion_line: int, source: str
) -> tuple[int, float, int, int]:
    """Read 'Frames:' and 'Frame Time:' after MOTION; returns them, the data offset and line."""
    line_no = motion_line - 1  # the first line read is the rest of the MOTION line
    values: dict[str, tuple[str, int]] = {}
    for key in ("frames", "frame time"):
        while True:
            end = text.find("\n", pos)
            end = len(text) if end < 0 else end
            line = text[pos:end].strip()
            pos = end + 1
            line_no += 1
            if line:
                break
            if end >= len(text):
                last = text.rstrip().count("\n") + 1  # the last line with content
                raise BvhError(source, f"file ends before '{key.title()}:'", last)
        label, sep, value = line.partition(":")
        if not sep or " ".join(label.split()).lower() != key:
            raise BvhError(source, f"expected '{key.title()}: ...', found {quoted(line)}", line_no)
        values[key] = (value.strip(), line_no)
    (frames_text, frames_line), (time_text, time_line) = values["frames"], values["frame time"]
    if not (frames_text.isascii() and frames_text.isdigit()):
        raise BvhError(
            source,
            f"frame count {quoted(frames_text)} is not a whole number of frames",
            frames_line,
        )
    if len(frames_text.lstrip("0")) > _MAX_FRAME_DIGITS:
        raise BvhError(source, f"frame count {quoted(frames_text)} is beyond any file", frames_line)
    frames = int(frames_text)
    if frames <= 0:
        raise BvhError(source, "the file has no frames (Frames: 0)", frames_line)
    if not PLAIN_NUMBER.match(time_text) or not 1e-6 <= float(time_text) < 10:
        raise BvhError(
            source,
            f"frame time {quoted(time_text)} is not a duration in seconds (1e-6 up to 10)",
            time_line,
        )
    return frames, float(time_text), min(pos, len(text)), line_no + 1
