"""Synthetic articulated creatures of cylinders, for testing model-free volume capture.

Chu, Jenkins & Mataric (CVPR 2003, section 2) test their capture on volume sequences
of synthetic "articulated 3D geometry with arbitrary kinematics". An
`ArticulatedFigure` is such a creature: a tree of joints whose links (parent joint to
joint) are capsules (cylinders with round caps) of known radius. `positions` poses it
by forward kinematics, `voxelize` scan-converts poses into a `VoxelGrid`, and
`creature_motion` makes smooth joint-angle trajectories that visibly bend every joint.
`quadruped` and `long_chain` are built-in creatures. World frame: +Y up, meters.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from samba.base import InputError
from samba.body import segment_distances
from samba.volume.voxel_grid import VoxelGrid

BEND_RANGE_DEG = (35.0, 65.0)
"""Range from which `creature_motion` draws each joint's bend amplitude, degrees."""
CYCLES = (1, 2)
"""Numbers of full swings over a motion `creature_motion` draws from, per joint."""
CLEARANCE = 0.05
"""Gap (m) `creature_motion` keeps between capsules that do not meet at a joint."""
MAX_TRIES = 200
"""Draws `creature_motion` makes per joint before it gives up."""


@dataclass(frozen=True, eq=False)
class ArticulatedFigure:
    """A tree of J joints whose J - 1 links are capsules.

    `names` (J,) name the joints; `parents` (J,) give each joint's parent index, -1 for
    the root (joint 0 only), parents before children. `offsets` (J, 3) m is each joint's
    rest vector from its parent joint (the root's: its rest position). `radii` (J,) m is
    the radius of the link from each joint's parent to it (the root's is unused). In
    the rest pose every joint rotation is zero and the offsets are world vectors.
    Invalid values raise `InputError` naming the field.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    radii: np.ndarray

    def __post_init__(self) -> None:
        names, parents = tuple(self.names), tuple(int(p) for p in self.parents)
        count = len(names)
        if count < 2 or len(set(names)) != count:
            raise InputError("names", f"need two or more unique joint names, got {names!r}")
        if len(parents) != count or parents[0] != -1:
            raise InputError("parents", f"need {count} parents, -1 first, got {parents!r}")
        for joint, parent in enumerate(parents[1:], start=1):
            if not 0 <= parent < joint:
                raise InputError("parents", f"joint {names[joint]!r}: parent {parent} not earlier")
        offsets = np.array(self.offsets, dtype=np.float64)
        if offsets.shape != (count, 3) or not np.isfinite(offsets).all():
            raise InputError("offsets", f"need ({count}, 3) finite meters, got {offsets.shape}")
        if (np.linalg.norm(offsets[1:], axis=1) == 0).any():
            raise InputError("offsets", "a link has zero length")
        radii = np.array(self.radii, dtype=np.float64)
        if radii.shape != (count,) or not (np.isfinite(radii[1:]) & (radii[1:] > 0)).all():
            raise InputError("radii", f"need ({count},) radii > 0 m, got {self.radii!r}")
        for name, value in (("names", names), ("parents", parents)):
            object.__setattr__(self, name, value)
        for name, array in (("offsets", offsets), ("radii", radii)):
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    @property
    def link_count(self) -> int:
        """Number of links (capsules), J - 1."""
        return len(self.names) - 1

    @property
    def branch_count(self) -> int:
        """Number of leaf joints (joints without children): the ends of the branches."""
        return len(self.leaves)

    @cached_property
    def children(self) -> tuple[tuple[int, ...], ...]:
        """Per joint (J,), the indices of its children, in order."""
        return tuple(
            tuple(j for j, p in enumerate(self.parents) if p == joint)
            for joint in range(len(self.names))
        )

    @property
    def leaves(self) -> tuple[int, ...]:
        """Indices of the joints without children."""
        return tuple(j for j, kids in enumerate(self.children) if not kids)

    @property
    def link_lengths(self) -> np.ndarray:
        """Length (J - 1,) m of each link, joint 1 .. J - 1 from its parent."""
        return np.linalg.norm(self.offsets[1:], axis=1)

    def positions(self, rotations: np.ndarray, translation: np.ndarray | None = None) -> np.ndarray:
        """Joint positions (n, J, 3) m by forward kinematics.

        `rotations` (n, J, 3) are local rotation vectors (radians): joint j's rotates
        the links to its children (and so their whole subtrees) about joint j, in the
        frame its parent's rotations leave it in; the root's turns the whole figure.
        `translation` (n, 3) m, optional, moves the root from its rest position.
        """
        rotations = np.array(rotations, dtype=np.float64)  # scipy rejects read-only input
        count = len(self.names)
        if rotations.ndim != 3 or rotations.shape[1:] != (count, 3):
            raise InputError("rotations", f"need (n, {count}, 3), got {rotations.shape}")
        frames = len(rotations)
        shift = np.zeros((frames, 3)) if translation is None else np.asarray(translation, float)
        if shift.shape != (frames, 3) or not np.isfinite(shift).all():
            raise InputError("translation", f"need ({frames}, 3) finite meters, got {shift.shape}")
        if not np.isfinite(rotations).all():
            raise InputError("rotations", "rotations hold NaN or infinity")
        local = Rotation.from_rotvec(rotations.reshape(-1, 3)).as_matrix()
        local = local.reshape(frames, count, 3, 3)
        turned = np.empty_like(local)
        points = np.empty((frames, count, 3))
        turned[:, 0], points[:, 0] = local[:, 0], self.offsets[0] + shift
        for joint in range(1, count):
            parent = self.parents[joint]
            points[:, joint] = points[:, parent] + turned[:, parent] @ self.offsets[joint]
            turned[:, joint] = turned[:, parent] @ local[:, joint]
        return points

    def bounds(self, positions: np.ndarray) -> np.ndarray:
        """The box (2, 3) m (low, high corner) holding every capsule in `positions` (n, J, 3)."""
        starts, ends = self._links(positions)
        radii = self.radii[1:, None]
        low = np.minimum(starts, ends) - radii
        high = np.maximum(starts, ends) + radii
        return np.stack([low.min(axis=(0, 1)), high.max(axis=(0, 1))])

    def voxelize(self, positions: np.ndarray, grid: VoxelGrid) -> np.ndarray:
        """Scan-convert poses (n, J, 3) m into occupancies (n, nx, ny, nz) bool of `grid`.

        A voxel is occupied when its centre lies within a link's radius of the link's
        segment (parent joint to joint), i.e. inside the capsule. Each capsule tests
        only the voxels of its bounding box; parts outside the grid are clipped.
        """
        starts, ends = self._links(positions)
        shape = np.array(grid.shape)
        volumes = np.zeros((len(starts), *grid.shape), dtype=bool)
        for frame, volume in enumerate(volumes):
            for start, end, radius in zip(starts[frame], ends[frame], self.radii[1:], strict=True):
                low = np.minimum(start, end) - radius - grid.origin
                high = np.maximum(start, end) + radius - grid.origin
                first = np.clip(np.ceil(low / grid.voxel), 0, shape).astype(int)
                last = np.clip(np.floor(high / grid.voxel) + 1, 0, shape).astype(int)
                if (first < last).all():
                    box = tuple(slice(f, e) for f, e in zip(first, last, strict=True))
                    volume[box] |= _in_capsule(grid, box, start, end, radius)
        return volumes

    def _links(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Link start (parent joint) and end (joint) points, each (n, J - 1, 3) m."""
        positions = np.asarray(positions, dtype=np.float64)
        count = len(self.names)
        if positions.ndim != 3 or positions.shape[1:] != (count, 3):
            raise InputError("positions", f"need (n, {count}, 3), got {positions.shape}")
        if not np.isfinite(positions).all():
            raise InputError("positions", "positions hold NaN or infinity")
        return positions[:, list(self.parents[1:])], positions[:, 1:]


def _in_capsule(
    grid: VoxelGrid, box: tuple[slice, ...], start: np.ndarray, end: np.ndarray, radius: float
) -> np.ndarray:
    """Whether the centres of the voxels `box` (3 index slices) of `grid` lie in a capsule.

    The capsule runs from `start` to `end` (3,) m with `radius` m; returns a bool block
    of the box's shape. The squared distance to the segment, |r|^2 - 2 s (r . d) +
    s^2 |d|^2 with r the offset from `start`, d = end - start and s the clamped
    position along d, is built from per-axis terms broadcast over the block.
    """
    axis = end - start
    offsets = np.meshgrid(
        *(
            grid.origin[a] + grid.voxel * np.arange(box[a].start, box[a].stop) - start[a]
            for a in range(3)
        ),
        indexing="ij",
        sparse=True,
    )
    along = sum(offset * d for offset, d in zip(offsets, axis, strict=True))
    squared = sum(offset * offset for offset in offsets)
    length2 = float(axis @ axis)
    s = np.clip(along / max(length2, 1e-18), 0.0, 1.0)  # a point when length2 is 0
    return squared - 2.0 * s * along + s * s * length2 <= radius * radius


def quadruped() -> ArticulatedFigure:
    """A four-legged creature of 13 links, standing on the floor (y = 0), facing +Z.

    Root at the pelvis, 0.55 m up; a horizontal body of two links (0.8 m, radius 0.1 m)
    to the withers; a neck and a head (radii 0.06, 0.08 m) rising forward from the
    withers; four legs of two links (0.27 + 0.26 m, radii 0.06, 0.05 m) hanging from the
    withers and the pelvis, splayed 0.12 m sideways; a tail (0.32 m, radius 0.04 m)
    rising back from the pelvis. Six branch ends: the head, four feet and the tail.
    """
    joints = (
        # name, parent, offset from parent (m), radius of the link to it (m)
        ("pelvis", -1, (0.0, 0.55, -0.4), 0.0),
        ("spine", 0, (0.0, 0.0, 0.4), 0.1),
        ("withers", 1, (0.0, 0.0, 0.4), 0.1),
        ("neck", 2, (0.0, 0.25, 0.15), 0.06),
        ("head", 3, (0.0, 0.05, 0.2), 0.08),
        ("front_left_knee", 2, (0.12, -0.24, 0.0), 0.06),
        ("front_left_foot", 5, (0.0, -0.26, 0.0), 0.05),
        ("front_right_knee", 2, (-0.12, -0.24, 0.0), 0.06),
        ("front_right_foot", 7, (0.0, -0.26, 0.0), 0.05),
        ("hind_left_knee", 0, (0.12, -0.24, 0.0), 0.06),
        ("hind_left_foot", 9, (0.0, -0.26, 0.0), 0.05),
        ("hind_right_knee", 0, (-0.12, -0.24, 0.0), 0.06),
        ("hind_right_foot", 11, (0.0, -0.26, 0.0), 0.05),
        ("tail", 0, (0.0, 0.1, -0.3), 0.04),
    )
    names, parents, offsets, radii = zip(*joints, strict=True)
    return ArticulatedFigure(names, parents, np.array(offsets), np.array(radii))


def long_chain(links: int = 6) -> ArticulatedFigure:
    """A snake: `links` (>= 1) links of 0.25 m, radius 0.05 m, lying along +Z on the floor.

    The root is the tail end; the chain is centred on x = z = 0 with its axis 0.05 m up,
    so it rests on the floor (y = 0). One branch end: the head.
    """
    if not isinstance(links, int) or links < 1:
        raise InputError("links", f"need an integer >= 1, got {links!r}")
    offsets = np.tile([0.0, 0.0, 0.25], (links + 1, 1))
    offsets[0] = [0.0, 0.05, -0.125 * links]
    names = ("tail", *(f"link_{i}" for i in range(1, links)), "head")
    return ArticulatedFigure(names, tuple(range(-1, links)), offsets, np.full(links + 1, 0.05))


def creature_motion(
    figure: ArticulatedFigure,
    frames: int,
    seed: int = 0,
    bounds: np.ndarray | None = None,
) -> np.ndarray:
    """Smooth joint rotations (frames, J, 3), radians, that visibly bend every joint.

    The root stays at its rest position and orientation; leaf joints (nothing to turn)
    stay at zero. Every other joint, parents first, swings about a fixed axis (in its
    parent's frame) perpendicular to its mean rest direction to its children, so each
    child link bends away from the straight line: angle(t) = amplitude * sin(2 pi k t
    / frames + phase), with the amplitude drawn from `BEND_RANGE_DEG`, k full swings
    from `CYCLES` (the motion loops), a uniform phase, and the axis either the one
    nearest the vertical (a sideways sweep for a horizontal link) or the one across.
    A draw is kept only when, with the joints drawn so far, no two capsules that do
    not share a joint come closer than `CLEARANCE` m, no capsule's far end comes that
    close to a capsule sharing its joint, and, when `bounds` (2, 3) m (low, high
    corner) is given, every capsule stays inside that box at every frame; otherwise
    it is drawn again, up to `MAX_TRIES` times (then `InputError`). Deterministic for
    `seed`. Pass the capture volume as `bounds` to keep the creature in it (its low y
    as the floor keeps `long_chain` from bending down through the floor).

    Over a dozen frames or more each bending joint turns by 35 to 65 degrees at its
    extreme; a child link perpendicular to the axis (every link of a chain) bends by
    as much, one at a slant by less.
    """
    if not isinstance(frames, int) or frames < 2:
        raise InputError("frames", f"need an integer >= 2, got {frames!r}")
    box = None if bounds is None else np.asarray(bounds, dtype=np.float64)
    if box is not None and (box.shape != (2, 3) or not (box[1] > box[0]).all()):
        raise InputError("bounds", f"need (2, 3) low and high corners, got {bounds!r}")
    rng = np.random.default_rng(seed)
    clear = _Clearance(figure, box)
    rotations = np.zeros((frames, len(figure.names), 3))
    if not clear(figure.positions(rotations[:1])):
        raise InputError("figure", "capsules touch, or leave the bounds, in the rest pose")
    sweep = 2.0 * np.pi * np.arange(frames) / frames
    for joint, kids in enumerate(figure.children[1:], start=1):
        if not kids:
            continue
        axes = _bend_axes(figure.offsets[list(kids)])
        for _ in range(MAX_TRIES):
            amplitude = np.radians(rng.uniform(*BEND_RANGE_DEG))
            cycles = rng.integers(CYCLES[0], CYCLES[1] + 1)
            phase = rng.uniform(0.0, 2.0 * np.pi)
            angle = amplitude * np.sin(cycles * sweep + phase)
            rotations[:, joint] = angle[:, None] * axes[rng.integers(2)]
            if clear(figure.positions(rotations)):
                break
        else:
            raise InputError(
                "figure",
                f"no bend of joint {figure.names[joint]!r} keeps the links clear and in bounds",
            )
    return rotations


def _bend_axes(directions: np.ndarray) -> np.ndarray:
    """Two unit axes (2, 3) perpendicular to the mean of `directions` (k, 3) and each other.

    The first is the direction perpendicular to the mean that is nearest the vertical
    (+Y); for a vertical mean, +X.
    """
    mean = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).sum(axis=0)
    mean /= np.linalg.norm(mean)
    upright = np.array([0.0, 1.0, 0.0]) - mean[1] * mean
    if np.linalg.norm(upright) < 1e-6:
        upright = np.array([1.0, 0.0, 0.0]) - mean[0] * mean
    upright /= np.linalg.norm(upright)
    return np.stack([upright, np.cross(mean, upright)])


class _Clearance:
    """Whether poses keep the capsules of a figure apart (and inside a box).

    Links that share no joint must keep `CLEARANCE` m between their capsules; of two
    links meeting at a joint, each one's far end must keep as far from the other's
    capsule (so a bend never folds a link onto its neighbour).
    """

    def __init__(self, figure: ArticulatedFigure, box: np.ndarray | None) -> None:
        """Pair up the links of `figure`; `box` (2, 3) m (low, high corner) or None."""
        links = np.stack([np.array(figure.parents[1:]), np.arange(1, len(figure.names))], 1)
        first, second = np.triu_indices(len(links), k=1)
        same = links[first, :, None] == links[second, None, :]  # (pairs, end, end)
        meet = same.any(axis=(1, 2))
        self.figure, self.box, self.links = figure, box, links
        self.apart = first[~meet], second[~meet]
        one, other = first[meet], second[meet]
        one_far = links[one, 1 - same[meet].any(axis=2).argmax(axis=1)]
        other_far = links[other, 1 - same[meet].any(axis=1).argmax(axis=1)]
        self.meeting = one, other, one_far, other_far

    def __call__(self, positions: np.ndarray) -> bool:
        """Whether every pose of `positions` (n, J, 3) m keeps the capsules clear."""
        radii = self.figure.radii[self.links[:, 1]]
        start, end = positions[:, self.links[:, 0]], positions[:, self.links[:, 1]]
        a, b = self.apart
        gaps = segment_distances(start[:, a], end[:, a], start[:, b], end[:, b])
        if (gaps <= radii[a] + radii[b] + CLEARANCE).any():
            return False
        a, b, a_far, b_far = self.meeting
        tip_a, tip_b = positions[:, a_far], positions[:, b_far]
        reach = radii[a] + radii[b] + CLEARANCE
        if (segment_distances(tip_a, tip_a, start[:, b], end[:, b]) <= reach).any():
            return False
        if (segment_distances(tip_b, tip_b, start[:, a], end[:, a]) <= reach).any():
            return False
        if self.box is None:
            return True
        low, high = self.figure.bounds(positions)
        return bool((low >= self.box[0]).all() and (high <= self.box[1]).all())
