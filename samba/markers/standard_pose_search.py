"""Finding the subject from scratch: the 8 markers of the standard pose among every
camera's blobs, anywhere on the stage.

Trackers and the cross-view labeller follow markers from where they were; once every
camera has lost the subject (it left the stage, or something blocked the views) no label
has a place to search near. Capture starts with the subject in the standard pose, and
this is how it starts again: the subject stands in that pose anywhere on the stage,
facing the stage's front as at the start, and `StandardPoseSearch.find` labels the
markers. The A-pose looks the same from behind, so the heading tells left from right:
it must be within `heading_tolerance_deg` of `heading_deg`.

1. Points: every pair of blobs of two cameras is triangulated (DLT) and kept when both
   views reproject within `epipolar_px`; the blob of another camera near its projection
   (the only one within twice that) joins it when every view of the point triangulated
   again reprojects within `epipolar_px`. Markers level with each other (both shoulders,
   knees, feet) pair up both ways in cameras at their height, so a blob may be in
   several points: the placements below decide, each using a blob once.
2. Placements: every pair of points at shoulder height (`shoulder_heights_m`), level
   within `level_m` and `shoulder_widths_m` apart, ordered left and right so that the
   subject faces the front, places the standard pose of the body whose shoulders are
   that high, facing that way, between them. In that body's frame the knees and feet
   are expected at their places, the wrists at arm's length from their shoulders at any
   angle in the frontal plane; the six take the points of the smallest total distance
   (normalised by `SPREAD_M`, each within `MAX_COST`) that share no blob. The pose is
   flat, so points of the other pairing of a level pair, off its plane, stand out.
3. Each camera that has a point in its image but no blob for it adds `UNSEEN_COST`.
   The placement whose 8 markers all find a point, at the smallest mean cost (then
   with the most views), wins, unless another complete placement puts a blob under
   another label at a cost within `RIVAL_FACTOR` of it: then nothing is found in this
   frame. A marker stays unlabelled in a camera whose image it projects outside (a
   bright spot at the edge took its place), where another projects within
   `epipolar_px` of it (their blobs may have merged, or paired the other way), where
   its blob has another blob no marker took within twice that, or where another point
   fits it nearly as well naming another blob.

Pixels are raw (distorted); `epipolar_px` is in pixels of a 160-pixel-wide, 60-degree
camera (`samba.markers.tracking.REFERENCE_FOCAL_PX`), scaled per camera.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from samba.base import InputError
from samba.body import N_MARKERS, Body, markers_of, standard_pose
from samba.cameras import CameraGroup, triangulate
from samba.markers.tracking import REFERENCE_FOCAL_PX

SHOULDERS = (0, 1)
"""Marker indices of the left and right shoulder."""
WRISTS = (2, 3)
"""Marker indices of the left and right wrist."""
OTHERS = (2, 3, 4, 5, 6, 7)
"""The markers placed relative to the shoulders: wrists, knees, feet."""
REFERENCE_HEIGHT = 1.70
"""Body height (m) whose standard pose scales to the subject's shoulder height."""
_SHOULDER_Y = float(standard_pose(REFERENCE_HEIGHT)[1, 1])
"""Shoulder height (m) of the reference body's standard pose."""
SPREAD_M = (0.10, 0.06, 0.05)
"""How far (m, one standard deviation) a marker may stand from the standard pose in
the body's frame: sideways (stance, and a wrist's reach), up, and forward (the pose is
flat: markers of other pairings, off its plane, stand out)."""
MAX_COST = 9.0
"""Largest squared normalised distance (three standard deviations) a marker may have."""
OPTIONS = 4
"""Points tried per marker (its cheapest) when choosing points that share no blob."""
UNSEEN_COST = 1.0
"""Cost added per camera that has a point in its image but no blob for it: a pairing of
blobs of other markers or bright spots is seen by two cameras, a marker by all (unless
hidden or merged)."""
RIVAL_FACTOR = 1.5
"""A second complete placement that puts a blob under another label, at a mean cost
within this factor of the best one's (plus `RIVAL_SLACK`), makes the search fail; a
point within it of a marker's chosen one leaves that marker unlabelled."""
RIVAL_SLACK = 0.5
"""The cost added to `RIVAL_FACTOR` times the best one's."""


def heading_of(shoulders: np.ndarray) -> float:
    """The heading in degrees of a body whose left and right shoulder are at `shoulders`
    (2, 3) meters: how far it faces from +Z turned about +Y (towards +X), as
    `samba.body.skeleton.standing_pose` turns it."""
    line = shoulders[0] - shoulders[1]
    return float(np.degrees(np.arctan2(-line[2], line[0])))


@dataclass(frozen=True)
class FoundPose:
    """The subject found in the standard pose: `points` (8, 3) meters, marker order (from
    every view of the chosen points, unlabelled ones included: fewer views triangulate
    worse), and `labels` (c, 8, 2) raw pixels per camera (NaN where a camera did not
    see it or it is left unlabelled there)."""

    points: np.ndarray
    labels: np.ndarray


@dataclass(frozen=True)
class StandardPoseSearch:
    """Finds the 8 markers of a subject in the standard pose; see the module docstring.

    `cameras` the calibrated cameras; `heading_deg` the stage's front: the subject faces
    +Z turned by it about +Y (as `samba.body.skeleton.standing_pose`). Distances in meters,
    `epipolar_px` in reference pixels.
    """

    cameras: CameraGroup
    heading_deg: float = 0.0
    heading_tolerance_deg: float = 60.0
    epipolar_px: float = 1.5
    shoulder_heights_m: tuple[float, float] = (1.0, 1.75)
    shoulder_widths_m: tuple[float, float] = (0.2, 0.55)
    level_m: float = 0.12

    def __post_init__(self) -> None:
        if len(self.cameras) < 2:
            raise InputError("cameras", f"need at least 2, got {len(self.cameras)}")
        if not 0.0 < self.heading_tolerance_deg < 90.0:
            raise InputError(
                "heading_tolerance_deg",
                f"must be in (0, 90) degrees (the pose looks alike from behind), "
                f"got {self.heading_tolerance_deg}",
            )

    def find(self, blobs: Sequence[np.ndarray | None]) -> FoundPose | None:
        """The subject's markers among every camera's blob centroids (m_c, 2) raw pixels
        (None: no frame from that camera), or None when no placement stands."""
        if len(blobs) != len(self.cameras):
            raise InputError("blobs", f"need one array (or None) per camera ({len(self.cameras)})")
        pixels = [
            np.zeros((0, 2)) if b is None else np.asarray(b, dtype=np.float64).reshape(-1, 2)
            for b in blobs
        ]
        points, views = self._points(pixels)
        if len(points) < N_MARKERS:
            return None
        placement = self._placement(points, views, pixels)
        if placement is None:
            return None
        chosen, blobs_of = placement
        labels = np.full((len(self.cameras), N_MARKERS, 2), np.nan)
        for camera, row in enumerate(blobs_of):
            seen = row >= 0
            labels[camera, seen] = pixels[camera][row[seen]]
        return FoundPose(points[chosen], labels)

    def _apart(self, points: np.ndarray, views: np.ndarray, pixels: list[np.ndarray]) -> np.ndarray:
        """Blob indices `views` (c, 8) of a placement's `points` (8, 3) with -1 for the
        markers that project outside a camera's image or within `epipolar_px` of another
        marker, and for the blobs with another blob of `pixels` no marker took within
        twice that."""
        tolerance = self._tolerance()
        projected = self.cameras.project(points)  # (c, 8, 2)
        gaps = np.linalg.norm(projected[:, :, None] - projected[:, None], axis=-1)
        gaps[:, np.arange(N_MARKERS), np.arange(N_MARKERS)] = np.inf
        inside = np.stack([c.in_image(uv) for c, uv in zip(self.cameras, projected, strict=True)])
        merged = (gaps <= tolerance[:, None, None]).any(axis=-1)
        out = np.where(merged | ~inside, -1, views)
        for camera, (row, blobs) in enumerate(zip(views, pixels, strict=True)):
            spare = np.ones(len(blobs), dtype=bool)
            spare[row[row >= 0]] = False
            taken = np.flatnonzero(row >= 0)
            near = np.linalg.norm(blobs[row[taken]][:, None] - blobs[spare][None], axis=-1)
            out[camera, taken[(near <= 2 * tolerance[camera]).any(axis=1)]] = -1
        return out

    def _tolerance(self) -> np.ndarray:
        """`epipolar_px` in each camera's pixels (c,)."""
        focal = np.array([camera.matrix[0, 0] for camera in self.cameras])
        return self.epipolar_px * focal / REFERENCE_FOCAL_PX

    def _points(self, pixels: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Candidate marker points (p, 3) meters and their views (c, p): the blob index
        each camera saw the point as, -1 for none. A blob may be in several candidates
        (markers level with each other pair up both ways); a placement uses it once."""
        c = len(self.cameras)
        tolerance = self._tolerance()
        undistorted = [cam.undistort(p) for cam, p in zip(self.cameras, pixels, strict=True)]
        candidates = []
        for a, b in combinations(range(c), 2):
            ia, ib = np.divmod(np.arange(len(pixels[a]) * len(pixels[b])), len(pixels[b]))
            if not len(ia):
                continue
            views = np.full((c, len(ia)), -1)
            views[a], views[b] = ia, ib
            world, error = self._triangulated(views, undistorted, pixels)
            fits = (error[[a, b]] <= tolerance[[a, b], None]).all(axis=0)
            pair, world = views[:, fits], world[fits]
            views = pair.copy()
            for other in set(range(c)) - {a, b}:
                if not len(pixels[other]):
                    continue
                projected = self.cameras[other].project(world)  # (m, 2)
                gaps = np.linalg.norm(projected[:, None] - pixels[other][None], axis=-1)
                near = gaps <= 2 * tolerance[other]
                joins = near.sum(axis=1) == 1  # one blob near enough, and only one
                views[other, joins] = np.argmax(near[joins], axis=1)
            _, error = self._triangulated(views, undistorted, pixels)
            fits = ((error <= tolerance[:, None]) | (views < 0)).all(axis=0)
            candidates.append(np.where(fits, views, pair))
        if not candidates:
            return np.zeros((0, 3)), np.zeros((c, 0), dtype=np.int64)
        views = np.unique(np.concatenate(candidates, axis=1), axis=1)  # pairs repeat points
        return self._triangulated(views, undistorted, pixels)[0], views

    def _triangulated(
        self, views: np.ndarray, undistorted: list[np.ndarray], pixels: list[np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Points (m, 3) from the blobs `views` (c, m) names, and every view's
        reprojection error (c, m) raw pixels (inf where the camera has no view)."""
        c, m = views.shape
        uv = np.full((c, m, 2), np.nan)
        raw = np.full((c, m, 2), np.nan)
        for camera in range(c):
            seen = views[camera] >= 0
            uv[camera, seen] = undistorted[camera][views[camera, seen]]
            raw[camera, seen] = pixels[camera][views[camera, seen]]
        world = triangulate(self.cameras.projections, uv)
        error = np.linalg.norm(self.cameras.project(world) - raw, axis=-1)
        return world, np.where(np.isnan(error), np.inf, error)

    def _placement(
        self, points: np.ndarray, views: np.ndarray, pixels: list[np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The best standing placement whose points share no blob (`views` (c, p) of
        `pixels`, as `_points` gives): each marker's point index (8,) and the blobs
        (c, 8) to label (-1: none), or None."""
        low, high = self.shoulder_heights_m
        level = np.flatnonzero((points[:, 1] >= low) & (points[:, 1] <= high))
        projected = self.cameras.project(points)  # (c, p, 2)
        inside = np.stack(
            [cam.in_image(uv) for cam, uv in zip(self.cameras, projected, strict=True)]
        )
        unseen = UNSEEN_COST * (inside & (views < 0)).sum(axis=0)  # (p,)
        blobs = [{(c, int(b)) for c, b in enumerate(column) if b >= 0} for column in views.T]
        results: list[tuple[float, int, np.ndarray, np.ndarray]] = []
        for i, j in combinations(level, 2):
            line = points[i] - points[j]
            width = np.hypot(line[0], line[2])
            if (
                abs(line[1]) > self.level_m
                or not self.shoulder_widths_m[0] <= width <= self.shoulder_widths_m[1]
                or blobs[i] & blobs[j]
            ):
                continue
            yaw = heading_of(points[[i, j]])  # i as the left shoulder
            if abs(_wrapped(yaw - self.heading_deg)) > 90.0:
                i, j, yaw = j, i, yaw + 180.0
            if abs(_wrapped(yaw - self.heading_deg)) > self.heading_tolerance_deg:
                continue
            cost = _marker_costs(points, points[i], points[j], yaw) + unseen  # (6, p)
            assigned = _assign(cost, (int(i), int(j)), blobs)
            if assigned is not None:
                total = cost[np.arange(len(OTHERS)), assigned[list(OTHERS)]].sum()
                mean = float((total + unseen[i] + unseen[j]) / N_MARKERS)
                results.append((mean, -int((views[:, assigned] >= 0).sum()), assigned, cost))
        if not results:
            return None
        results.sort(key=lambda r: r[:2])
        best_cost, _, best, cost = results[0]
        mine = self._apart(points[best], views[:, best], pixels)
        for other_cost, _, other, _ in results[1:]:
            if (  # clearing views only removes conflicts: the raw ones are checked first
                other_cost <= RIVAL_FACTOR * best_cost + RIVAL_SLACK
                and _conflict(views[:, best], views[:, other])
                and _conflict(mine, self._apart(points[other], views[:, other], pixels))
            ):
                return None
        return best, _unambiguous(mine, cost, best, views)


def _unambiguous(
    mine: np.ndarray, cost: np.ndarray, assigned: np.ndarray, views: np.ndarray
) -> np.ndarray:
    """A placement's blob indices `mine` (c, 8) with -1 where another point (blob
    indices `views` (c, p)) fits the marker nearly as well (`cost` (6, p), within
    `RIVAL_FACTOR` and `RIVAL_SLACK` of the chosen point's): in the cameras where it
    names another blob when the two share one (the same marker, paired otherwise), in
    every camera when they share none (another marker altogether)."""
    out = mine.copy()
    for row, marker in enumerate(OTHERS):
        chosen = assigned[marker]
        near = cost[row] <= RIVAL_FACTOR * cost[row, chosen] + RIVAL_SLACK
        near[chosen] = False
        for rival in np.flatnonzero(near):
            both = (views[:, chosen] >= 0) & (views[:, rival] >= 0)
            if (views[both, chosen] == views[both, rival]).any():
                out[both & (views[:, chosen] != views[:, rival]), marker] = -1
            else:
                out[:, marker] = -1
    return out


def _marker_costs(
    points: np.ndarray, left: np.ndarray, right: np.ndarray, yaw_deg: float
) -> np.ndarray:
    """Squared normalised distances (6, p) of every point from where each of `OTHERS`
    stands in the standard pose of the body whose shoulders are at `left` and `right`
    (3,) meters, facing +Z turned by `yaw_deg`: in the body's frame, the knees and feet
    at their place (`SPREAD_M`), the wrists anywhere at arm's length from their shoulder
    in the frontal plane, on their own side."""
    middle = (left + right) / 2
    body = Body.from_height(REFERENCE_HEIGHT * middle[1] / _SHOULDER_Y)
    standard = markers_of(body.standard_pose())
    standard -= standard[list(SHOULDERS)].mean(axis=0)
    turn = np.radians(yaw_deg)
    c, s = np.cos(turn), np.sin(turn)
    moved = points - middle
    # Into the body frame (x: towards the left shoulder, y: up, z: forward).
    local = np.stack(
        [c * moved[:, 0] - s * moved[:, 2], moved[:, 1], s * moved[:, 0] + c * moved[:, 2]], -1
    )
    spread = np.array(SPREAD_M)
    cost = np.empty((len(OTHERS), len(points)))
    for row, marker in enumerate(OTHERS):
        if marker in WRISTS:
            shoulder = standard[SHOULDERS[WRISTS.index(marker)]]
            arm = body.upper_arm + body.forearm
            reach = np.linalg.norm(local - shoulder, axis=-1) - arm
            outward = (local[:, 0] - shoulder[0]) * np.sign(shoulder[0])
            cost[row] = (reach / spread[0]) ** 2 + (local[:, 2] / spread[2]) ** 2
            cost[row, outward < -spread[0]] = np.inf
        else:
            cost[row] = (((local - standard[marker]) / spread) ** 2).sum(axis=-1)
    return cost


def _assign(
    cost: np.ndarray, shoulders: tuple[int, int], blobs: list[set[tuple[int, int]]]
) -> np.ndarray | None:
    """Point indices (8,) of the markers: the `shoulders` given, `OTHERS` the points of
    the smallest total `cost` (6, p) that share no blob (each point's (camera, blob)
    pairs `blobs`) with each other or the shoulders, each within `MAX_COST` and among its
    `OPTIONS` cheapest; None when there are none."""
    cost = cost.copy()
    cost[:, list(shoulders)] = np.inf
    options = []
    for row in cost:
        allowed = np.flatnonzero(row <= MAX_COST)
        options.append(allowed[np.argsort(row[allowed])][:OPTIONS])
    best: list = [np.inf, None]

    def visit(row: int, chosen: list[int], total: float, used: set) -> None:
        if total >= best[0]:
            return
        if row == len(OTHERS):
            best[:] = [total, chosen]
            return
        for point in options[row]:
            if point not in chosen and not blobs[point] & used:
                visit(row + 1, [*chosen, int(point)], total + cost[row, point], used | blobs[point])

    visit(0, [], 0.0, blobs[shoulders[0]] | blobs[shoulders[1]])
    if best[1] is None:
        return None
    assigned = np.empty(N_MARKERS, dtype=np.int64)
    assigned[list(SHOULDERS)] = shoulders
    assigned[list(OTHERS)] = best[1]
    return assigned


def _conflict(first: np.ndarray, second: np.ndarray) -> bool:
    """Whether two placements' blob indices (c, 8) (-1: none) disagree: a camera gives
    a marker different blobs, or one blob to different markers."""
    both = (first >= 0) & (second >= 0)
    if (first[both] != second[both]).any():
        return True
    for a, b in zip(first, second, strict=True):
        shared = np.intersect1d(a[a >= 0], b[b >= 0])
        for blob in shared:
            if (a == blob).nonzero()[0][0] != (b == blob).nonzero()[0][0]:
                return True
    return False


def _wrapped(degrees: float) -> float:
    """An angle in degrees brought into [-180, 180)."""
    return (degrees + 180.0) % 360.0 - 180.0
