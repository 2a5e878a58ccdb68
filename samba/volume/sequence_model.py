"""Passes 2 and 3 of model and motion capture (Chu, Jenkins, Matarić 2003, Section 4):
one kinematic model common to a whole volume sequence, fitted to every frame.

Pass 2 aligns the frames' models. The common topology has the most end branches seen
in at least `BRANCH_SUPPORT` of the frames: a thin limb (a tail, an arm held against
the body) merges with the body in many frames and is its own branch in the others,
while refinement has already removed each frame's noise branches. Of the frames with
that many ends, the branch tree seen most often is the common topology, and the first
frame that has it is the reference. Walking from there to both ends of the sequence,
each frame's branches are matched to the model's branches as last seen (one-to-one, by
the Hungarian method, minimising the summed squared distance between the two branches
resampled at the same fractions of their length: the distance of their parents, their
directions and their lengths in one number).
Where the root starts the trunk's two halves, it moves to where the trunk bends
(`_root_at_bend`): the shells' centre is the middle of the volume, not a joint.
Then, per model branch, the joint fractions the skewness test placed in the matched
frames form a 1-D sample; the branch gets the number of joints its matches have most
often (`_joint_count`), placed at the highest peaks of the sample's density (which
settle the two ends below), and the mean length of its matches. A branch that carries
others ends at its last joint instead of the branching node when that joint lies within
`JUNCTION` of the branch's radius of the node (`_junction`): the two are one joint. A
leaf branch drops a last joint that would leave it a last link shorter than `TIP_LINK`
of its radius (`_off_the_tip`). Last, the joints go where the branch bends over the
sequence (`_bent`): with the joints as breakpoints shared by every frame, each link is a
straight segment in every frame, and the fit's cost is the squared distance of the
matched curves, sampled at `SAMPLES` of their length, from those segments. For each
number of joints up to the count the best breakpoints are found exactly (dynamic
programming over the samples); the count is lowered while one joint fewer raises the
best fit's cost by less than `STRAIGHT` squared per sample and frame (the skewness test
cut a straight link in enough frames to carry the count), and the joints sit at the best
fit's breakpoints. The skewness test fires where the volume around the curve has already
stopped being linear, a little past the bend: a 6-link chain's joints lay 2.4-3.5 voxels
out from the true ones at the density's peaks and 0.3-0.7 at the breakpoints
(`bench/bench_volume.py`, seeds 31, 33 and 3).

Pass 3 places the model's joints on every frame's matched branches at those
fractions, and each leaf branch's end where the frame's branch puts it, about one
local radius inside the volume's tip (`Branch.end`), but no nearer its last joint than
halfway from there to the curve's end, so that no link loses its length. Joints of
branches a frame lacks are interpolated in time between the frames that have them
(held at the ends of the sequence).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import gaussian_kde

from samba.base import InputError
from samba.body import point_segment_distances
from samba.volume.frame_kinematics import Branch, FrameModel, arc_lengths, points_along

RESAMPLE = np.linspace(0.0, 1.0, 6)
"""Fractions of arc length at which two branches are compared."""
MATCH_GATE = 0.5
"""RMS distance (m) of resampled points above which two branches do not match. At the
paper's 10 Hz an arm of a jumping jack moves farther than 0.25 m between frames; with
that gate its frames went unmatched and were interpolated in time, 13 cm off at the
wrists (`bench/bench_volume.py`, seeds 11-13; 0.35 to 1.0 m fit the training seeds
1-5 alike)."""
BRANCH_SUPPORT = 0.4
"""Share of the frames in which an end-branch count must be seen to be the model's (the
largest such count is). The quadruped's tail is its own branch in 43-63% of the frames
of seeds 1-3, the most frequent tree shape then had 5 ends in two of them. Human takes
of seeds 1-3 show a sixth end in at most a third of their frames, but for one natural
wave whose model is not human either way (6 ends before, 7 with this rule). The cost:
a take whose frames split evenly between five ends and a spurious sixth gets the sixth
(the first second of the natural wave of seed 11: 5 and 5 frames, human before)."""
BANDWIDTH = 0.04
"""Kernel width (fraction of the branch) of the joint-fraction density."""
JUNCTION = 0.6
"""Share of a carrying branch's radius (`Branch.radius`, m) within which its last joint
stands for the branching node it ends at. The skewness test fires where a trunk's
voxels start to bulge into the limbs it carries, one or two curve points before the
node where the curve branches, and that node lies off the trunk's axis, inside the
limbs' roots. On the quadruped of `bench/bench_volume.py` (seeds 1-5) both trunk
branches had such a last joint, 0.33-0.46 radii (about 1.5 voxels) from the node, the
next joint at least 1.46 radii away; the joint lay 1.6-2.6 voxels from the true pelvis
or withers, the node 3.0-3.5. Ending the trunk's branches there took 2 links off every
take with the same true joints within 2 voxels; any share from 0.5 to 1.2 did so. The
human takes of seeds 1-5 moved by +0.05 cm on average at 0.6 (single takes -0.6 to
+0.8 cm), +0.01 cm at 1.0 (-1.3 to +1.2 cm): the smaller share moves fewer human
branch starts, which `samba.volume.humanoid` was fitted to. Only the last joint
counts: ending a human's trunk branch at the first of two such joints instead moved
the crotch up 9 cm in one held-out take (the exaggerated jumping jacks of seed 11,
+1.8 cm; no take of seeds 1-5 changed)."""
TIP_LINK = 1.0
"""Shortest last link of a leaf branch, in radii of the branch (`Branch.radius`): a last
joint nearer the branch's end than that lies in the volume's round tip (a capsule's
cap is one radius long), where the skewness test fires as the volume narrows, and is
dropped. On the quadruped of `bench/bench_volume.py` (seeds 1-5) the tail's or a leg's
last joint sat 0.2-1.4 voxels before the end in three takes; dropping it took 1 link off
each with the same true joints within 2 voxels (0.5 radii took 2, 1.5 took 4; the
human takes of seeds 1-5 moved by +0.02 to +0.03 cm on average at 0.5 to 1.5)."""
ROOT_STEP = 0.005
"""Spacing (m) of the root positions `_root_at_bend` tries along the trunk."""
ROOT_TRIM = 0.5
"""Share of a trunk half's radius (`Branch.radius`, m) at its far end that
`_root_at_bend` leaves out of its two-line fit: the branching node there lies off the
trunk's axis, inside the limbs' roots, and pulls a line anchored at it. On the
quadruped of `bench/bench_volume.py` the spine stands 0.063-0.068 m along the trunk
from the middle of the volume; in the two takes where it bends least (36 degrees at
most) two links anchored at the nodes, and two free lines over every sample, chose
offsets of 0.02-0.03 m; with this trim, 0.05-0.055 m."""
ROOT_STEADY = 0.2
"""Largest spread (standard deviation over mean) of a trunk half's length over the
frames for the root to move (`_root_at_bend`): one offset along the trunk stands for
one place on the body only when the halves keep their lengths. The quadruped's halves
spread 0.02-0.11; the legs of a human's jumping jacks part from the trunk at heights
that vary from frame to frame (the lower half 0.19-0.59 m long, spread 0.35)."""
ROOT_BEND = 0.003
"""RMS distance (m) that moving the root to the trunk's bend must take off the trunk's
two-line fit (per sample and frame) for the root to move (`_root_at_bend`). The
quadruped's spine, bent 36-64 degrees at most over a take, took 3.3-9.5 mm off."""
FRAME_CHUNK = 64
"""Frames whose straight-link distances `_link_costs` computes at once (memory: about
12,000 sample-link pairs per frame)."""
SAMPLES = np.linspace(0.0, 1.0, 41)
"""Fractions of a branch's length at which its matched curves are fitted by straight
links (`_bent`): 1.5 cm apart on a quadruped's 0.6 m leg, under a voxel."""
LINK_CAP = 1.0
"""Distance, in radii of the branch (`Branch.radius`; no cap where it is 0, unknown),
beyond which a sample of a matched curve costs the straight-link fit (`_bent`) no more:
a frame whose match is another limb (two legs fused into one branch, or crossed) then
costs every placement of the joints alike instead of pulling them. On the quadruped of
`bench/bench_volume.py` (seeds 1-5, 11-13, 31-34) one front knee sat 2.6 voxels off
without the cap, matched to the other leg in 7 of 30 frames and to a fused branch in
4; with it, all but one of the 12 takes have every true joint within 2 voxels (the
withers of one 2.0 voxels off) and 14 links (one take had 15 without it).
Two radii did the same on the creatures; the human takes moved by 0.01 cm on average
either way."""
STRAIGHT = 0.014
"""RMS distance (m) from a branch's straight links that a joint must take off its
matched curves (per sample and frame, over the whole branch) to stay (`_bent`). On the
quadruped of `bench/bench_volume.py` (seeds 1-5, 25 mm voxels) every take kept a second
joint in a straight stretch of a leg, the tail or the neck (where the skewness test
cuts a link in many frames). With the joints at the density's peaks (before the best
breakpoints placed them), dropping joints worth less than 8, 10, 12, 14 and 16 mm
took the 94 links of the five takes to 90, 88, 86, 84 and 83, with the same true
joints within 2 voxels and the chain's 6 links and joints; 18 mm took one true joint
off quadruped-2 and a link off chain-3. The human takes of seeds 1-5 (30 mm voxels)
went from 9.53 cm on average to 9.44-9.49 cm. Whether a bend moves over the take does
not tell joints apart here: a human's shoulder, wrist and ankle bends hardly move in
the synthetic takes (their angle spreads 5-8 degrees over a take, the quadruped's
tail's fixed bend out of the body 3-5), and dropping the joints whose angle spread
less than 8 degrees raised the human takes' error by 0.8 cm."""


@dataclass(frozen=True)
class CommonModel:
    """The kinematic model of a sequence.

    `parents` (B,): parent branch of each branch, -1 at the root; `lengths` (B,) mean
    arc length, meters, to the branch's end (a branching node or the joint standing
    for it, `_junction`); `joints`: per branch, the fractions (0..1, increasing) of
    that length where its interior joints sit. `signature` is the branch tree's canonical
    shape (`FrameModel.signature`).
    """

    parents: tuple[int, ...]
    lengths: np.ndarray
    joints: tuple[np.ndarray, ...]
    signature: str

    @property
    def branch_count(self) -> int:
        """Branches that carry no other branch (ends of the skeleton)."""
        return sum(1 for b in range(len(self.parents)) if b not in self.parents)

    @property
    def link_count(self) -> int:
        """Kinematic links: one per branch plus one per interior joint."""
        return len(self.parents) + sum(len(j) for j in self.joints)


@dataclass(frozen=True)
class SequenceFit:
    """The common model and its fit: `model`, `matches` (n, B) the frame branch matched
    to each model branch (-1 where none), `root` (n, 3) and `branch_points` (n, B,
    J_b + 1, 3) per branch the interior joints then the end, meters (a list of arrays,
    one per branch)."""

    model: CommonModel
    matches: np.ndarray
    root: np.ndarray
    branch_points: tuple[np.ndarray, ...]

    @property
    def complete(self) -> np.ndarray:
        """(n,) bool: frames in which every model branch was matched."""
        return (self.matches >= 0).all(axis=1)


def fit_sequence(frames: list[FrameModel]) -> SequenceFit:
    """Passes 2 and 3 over the per-frame models of a sequence (see the module)."""
    if not frames:
        raise InputError("volume sequence", "no frames to build a model from")
    ends = np.array([f.leaf_count for f in frames])
    options, frequency = np.unique(ends, return_counts=True)
    supported = options[frequency >= BRANCH_SUPPORT * len(frames)]
    chosen = supported.max() if len(supported) else options[np.argmax(frequency)]
    signatures = [f.signature() if e == chosen else "" for f, e in zip(frames, ends, strict=True)]
    values, counts = np.unique([s for s in signatures if s], return_counts=True)
    signature = str(values[np.argmax(counts)])
    reference = signatures.index(signature)
    base = frames[reference]
    n, count = len(frames), len(base.branches)
    matches = np.full((n, count), -1, dtype=np.int64)
    matches[reference] = np.arange(count)
    for direction in (1, -1):
        last = [b.points for b in base.branches]
        for t in range(reference + direction, n if direction > 0 else -1, direction):
            matches[t] = _match(last, frames[t].branches)
            for b, found in enumerate(matches[t]):
                if found >= 0:
                    last[b] = frames[t].branches[found].points
    parents = tuple(b.parent for b in base.branches)
    frames = _root_at_bend(frames, matches, parents)
    joints, lengths, stops = [], np.zeros(count), np.ones(count)
    for b in range(count):
        matched = [frames[t].branches[matches[t, b]] for t in range(n) if matches[t, b] >= 0]
        length = float(np.mean([m.length for m in matched]))
        peaks = _joint_peaks(matched)
        radius = float(np.mean([m.radius for m in matched]))
        if b in parents:
            peaks, stops[b] = _junction(peaks, length, radius)
        else:
            end = float(np.mean([m.end for m in matched]))
            peaks = _off_the_tip(peaks, end, length, radius)
        joints.append(_bent(len(peaks), matched, stops[b]))
        lengths[b] = length * stops[b]
    model = CommonModel(
        parents=parents,
        lengths=lengths,
        joints=tuple(joints),
        signature=signature,
    )
    root = np.stack([f.root for f in frames])
    points = []
    for b in range(count):
        placed = np.full((n, len(model.joints[b]) + 1, 3), np.nan)
        for t in range(n):
            if matches[t, b] >= 0:
                branch = frames[t].branches[matches[t, b]]
                end = 1.0 if b in model.parents else _leaf_end(branch.end, model.joints[b])
                placed[t] = branch.at(np.append(model.joints[b], end) * stops[b])
        points.append(_fill_in_time(placed))
    return SequenceFit(model=model, matches=matches, root=root, branch_points=tuple(points))


def _root_at_bend(
    frames: list[FrameModel], matches: np.ndarray, parents: tuple[int, ...]
) -> list[FrameModel]:
    """The frames with the root moved along the trunk to where it bends, when the
    model's root starts two branches that both carry others (the trunk's halves).

    Every frame with both halves matched (`matches` (n, B)) gives the trunk's curve from
    one half's end through the root to the other's; one offset from the root (m of arc,
    into either half, at most halfway along the shorter of each half, in `ROOT_STEP`
    steps) is chosen for all of them: the one at which the curves' `SAMPLES` points,
    but those within `ROOT_TRIM` of a half's radius of its far end, lie nearest two
    straight lines, one on each side (summed squared distance, `_two_line_residuals`),
    when it takes at least `ROOT_BEND` squared per sample and frame off the fit with the
    root where it is, and when neither half's length varies over those frames by more
    than `ROOT_STEADY` of its mean. Those frames' halves are cut again there, their
    skewness joints kept where they fall but within `JUNCTION` of the half's radius of
    the new root, which stands for them; a frame lacking a half keeps its root.
    """
    halves = [b for b, parent in enumerate(parents) if parent < 0]
    if len(halves) != 2 or not set(halves) <= set(parents):
        return frames
    seen = np.flatnonzero((matches[:, halves] >= 0).all(axis=1))
    if len(seen) == 0:
        return frames
    pairs = [[frames[t].branches[matches[t, h]] for h in halves] for t in seen]
    lengths = np.array([[one.length, two.length] for one, two in pairs])
    if (lengths.std(axis=0) > ROOT_STEADY * lengths.mean(axis=0)).any():
        return frames
    curves = [np.concatenate([one.points[::-1], two.points[1:]]) for one, two in pairs]
    roots = lengths[:, 0]
    arcs = [arc_lengths(curve) for curve in curves]
    totals = np.array([arc[-1] for arc in arcs])
    reach = np.array([roots.min(), (totals - roots).min()]) / 2.0
    offsets = ROOT_STEP * np.arange(-int(reach[0] / ROOT_STEP), int(reach[1] / ROOT_STEP) + 1)
    cost = np.zeros(len(offsets))
    for (one, two), curve, root, total in zip(pairs, curves, roots, totals, strict=True):
        along = SAMPLES * total
        inner = (along > ROOT_TRIM * one.radius) & (along < total - ROOT_TRIM * two.radius)
        cuts = np.searchsorted(along[inner], root + offsets)
        cost += _two_line_residuals(points_along(curve, SAMPLES[inner]), cuts)
    if cost[offsets == 0.0][0] - cost.min() < ROOT_BEND**2 * len(curves) * len(SAMPLES):
        return frames
    offset = float(offsets[np.argmin(cost)])
    out = list(frames)
    for t, (one, two), curve, arc, root in zip(seen, pairs, curves, arcs, roots, strict=True):
        cut, total = root + offset, arc[-1]
        bend = points_along(curve, np.array([cut / total]))
        along = np.concatenate([root * (1.0 - one.joints), root + two.joints * two.length])
        near = JUNCTION * np.where(along < cut, one.radius, two.radius)
        along = along[np.abs(along - cut) >= near]
        branches = list(frames[t].branches)
        branches[matches[t, halves[0]]] = replace(
            one,
            points=np.concatenate([bend, curve[arc < cut][::-1]]),
            joints=np.sort((cut - along[along < cut]) / cut),
        )
        branches[matches[t, halves[1]]] = replace(
            two,
            points=np.concatenate([bend, curve[arc > cut]]),
            joints=np.sort((along[along > cut] - cut) / (total - cut)),
        )
        out[t] = FrameModel(root=bend[0], branches=tuple(branches))
    return out


def _two_line_residuals(points: np.ndarray, cuts: np.ndarray) -> np.ndarray:
    """(C,) m^2: for each of `cuts` (C,), the summed squared distance of `points` (P, 3)
    m from two least-squares lines, one through points[:cut] and one through
    points[cut:] (a side of fewer than two points costs 0)."""
    count = np.arange(len(points) + 1, dtype=np.float64)
    first = np.concatenate([np.zeros((1, 3)), np.cumsum(points, axis=0)])
    second = np.concatenate(
        [np.zeros((1, 3, 3)), np.cumsum(points[:, :, None] * points[:, None], axis=0)]
    )
    total = np.zeros(len(cuts))
    for n, sums, squares in (
        (count[cuts], first[cuts], second[cuts]),
        (count[-1] - count[cuts], first[-1] - first[cuts], second[-1] - second[cuts]),
    ):
        scatter = squares - sums[:, :, None] * sums[:, None] / np.maximum(n, 1.0)[:, None, None]
        spread = np.linalg.eigvalsh(scatter)
        total += np.where(n >= 2, spread[:, 0] + spread[:, 1], 0.0)
    return total


def _match(last: list[np.ndarray], branches: tuple[Branch, ...]) -> np.ndarray:
    """Frame branch (B,) matched to each model branch last seen as curves `last`."""
    out = np.full(len(last), -1, dtype=np.int64)
    if not branches:
        return out
    model = np.stack([points_along(points, RESAMPLE) for points in last])
    frame = np.stack([b.at(RESAMPLE) for b in branches])
    cost = np.sqrt(((model[:, None] - frame[None]) ** 2).sum(-1).mean(-1))
    rows, cols = linear_sum_assignment(cost)
    good = cost[rows, cols] <= MATCH_GATE
    out[rows[good]] = cols[good]
    return out


def _joint_peaks(matched: list[Branch]) -> np.ndarray:
    """The model's joint fractions of a branch from its matches in every frame."""
    count = _joint_count(matched)
    sample = np.concatenate([m.joints for m in matched])
    if count == 0 or len(sample) == 0:
        return np.zeros(0)
    grid = np.linspace(0.0, 1.0, 201)
    if np.ptp(sample) == 0:
        return np.full(min(count, 1), sample[0])
    density = gaussian_kde(sample, bw_method=BANDWIDTH / sample.std())(grid)
    peak = np.flatnonzero((density[1:-1] >= density[:-2]) & (density[1:-1] > density[2:])) + 1
    best = peak[np.argsort(density[peak])[::-1][:count]]
    return np.sort(grid[best])


def _junction(peaks: np.ndarray, length: float, radius: float) -> tuple[np.ndarray, float]:
    """The joints (k,) of a carrying branch of `length` and `radius` (m) with joints at
    `peaks` (k + 1 or k,) that lie before its end, and that end (fraction of its curve):
    at its last joint when within `JUNCTION` of the radius of the branching node (which
    it then stands for), at the node (1) otherwise."""
    if len(peaks) == 0 or (1.0 - peaks[-1]) * length >= JUNCTION * radius:
        return peaks, 1.0
    return peaks[:-1], float(peaks[-1])


def _off_the_tip(peaks: np.ndarray, end: float, length: float, radius: float) -> np.ndarray:
    """The joint fractions `peaks` (k,) of a leaf branch of `length` and `radius` (m)
    whose end lies at fraction `end`, without its last joint when that leaves a last
    link (to `_leaf_end`) shorter than `TIP_LINK` radii."""
    if len(peaks) and (_leaf_end(end, peaks) - peaks[-1]) * length < TIP_LINK * radius:
        return peaks[:-1]
    return peaks


def _bent(count: int, matched: list[Branch], stop: float) -> np.ndarray:
    """The fractions (k,), k <= `count`, of the `matched` branches' curves up to `stop`
    at which they bend: the breakpoints of the best straight-link fit with k joints
    (`_best_fits`, each curve's samples counted at most `LINK_CAP` of the branches'
    radius from a link), k lowered from `count` while one joint fewer raises that fit's
    cost by less than `STRAIGHT` squared per sample and frame."""
    count = min(count, len(SAMPLES) - 2)
    curves = np.stack([m.at(SAMPLES * stop) for m in matched])
    radius = float(np.mean([m.radius for m in matched]))
    fits = _best_fits(_link_costs(curves, LINK_CAP * radius if radius > 0 else np.inf), count)
    floor = STRAIGHT**2 * curves.shape[0] * curves.shape[1]
    while count > 0 and fits[count - 1][0] - fits[count][0] < floor:
        count -= 1
    return fits[count][1] / (len(SAMPLES) - 1)


def _link_costs(curves: np.ndarray, cap: float = np.inf) -> np.ndarray:
    """(s, s) m^2: for samples a < c of curves (n, s, 3) m, the summed squared distance,
    over the frames, of samples a..c from the segment between samples a and c (a link
    straight in every frame), each distance counted at most `cap` m; 0 on and below the
    diagonal."""
    count = curves.shape[1]
    first, last = np.triu_indices(count, k=1)
    link, sample = np.nonzero(
        (np.arange(count) >= first[:, None]) & (np.arange(count) <= last[:, None])
    )
    total = np.zeros(len(first))
    for chunk in range(0, len(curves), FRAME_CHUNK):
        part = curves[chunk : chunk + FRAME_CHUNK]
        distance = point_segment_distances(
            part[:, sample], part[:, first[link]], part[:, last[link]]
        )
        total += np.bincount(link, (np.minimum(distance, cap) ** 2).sum(axis=0), len(first))
    costs = np.zeros((count, count))
    costs[first, last] = total
    return costs


def _best_fits(costs: np.ndarray, most: int) -> list[tuple[float, np.ndarray]]:
    """For k = 0..`most` joints, the cheapest straight links from the first sample to
    the last: (cost m^2, the k samples (k,) where the links meet), by dynamic
    programming over the link costs `costs` (s, s) (`_link_costs`)."""
    count = len(costs)
    links = np.where(np.triu(np.ones((count, count), dtype=bool), k=1), costs, np.inf)
    best = links[0]
    paths = np.zeros((count, 0), dtype=np.int64)
    fits = [(float(best[-1]), paths[-1])]
    for _ in range(most):
        total = best[:, None] + links
        previous = np.argmin(total, axis=0)
        best = total[previous, np.arange(count)]
        paths = np.column_stack([paths[previous], previous])
        fits.append((float(best[-1]), paths[-1]))
    return fits


def _leaf_end(end: float, joints: np.ndarray) -> float:
    """Where a leaf branch with `joints` (k,) (fractions of its curve) ends: at `end` (the
    fraction one radius inside the volume's tip, `Branch.end`), but no nearer its last
    joint than halfway from there to the curve's end, so that no link loses its length."""
    last = joints[-1] if len(joints) else 0.0
    return max(end, (1.0 + last) / 2.0)


def _joint_count(matched: list[Branch]) -> int:
    """The number of joints a branch's matches have most often (the fewest on a tie).

    The paper rounds the mean. The skewness test cuts a straight link at random in a
    few frames, sometimes many times over (a quadruped's leg: 1-2 joints in most
    frames, 5-10 in a few), which pulls the mean up but not the mode. On the
    quadruped of `bench/bench_volume.py` (13 links; seeds 1-5, 11-13, 31-34) the
    common model went from 25-31 links to 19-24, with one true joint fewer within 2
    voxels in 4 of the 12 takes (73% -> 70%; none on seeds 11-13); the 6-link chain
    kept its 6 links and its joints. Rounding the mean down or taking the lower
    quartile cut the chain to 4 links; the median left the quadruped at 23-29 links
    (seeds 1-5).
    """
    return int(np.bincount([len(m.joints) for m in matched]).argmax())


def _fill_in_time(placed: np.ndarray) -> np.ndarray:
    """(n, k, 3) positions with NaN frames linearly interpolated in time between the
    known frames, held at the ends; all NaN stays NaN."""
    known = np.flatnonzero(np.isfinite(placed[:, 0, 0]))
    if len(known) == 0 or len(known) == len(placed):
        return placed
    t = np.arange(len(placed))
    flat = placed[known].reshape(len(known), -1)
    filled = np.stack([np.interp(t, known, flat[:, i]) for i in range(flat.shape[1])], axis=1)
    return filled.reshape(placed.shape)
